"""R-test measurement programs (K1/K2/K4 or any pose list) for HEIDENHAIN and SINUMERIK.

``mode="tcpm"`` programs the ball centre in workpiece coordinates under FUNCTION TCPM /
TRAORI, so the control's own kinematics moves the linear axes: this tests the control.
``mode="axes"`` programs machine-axis positions from compgen's inverse kinematics: this
tests compgen's nominal model. Either way the machine goes to the inverse-kinematics poses,
and those are checked against travel, step size and feed before anything is written.

References: ``shared/research/controllers.md`` §2 (Klartext), §3.8 (SINUMERIK), §7.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import CompgenError
from ..kinematics import Poses, inverse
from ..machine import Machine
from ..paths import check_travel
from ..rtest import BALL, axis_cells
from . import Emitted, ascii_text, render
from .registry import controller

MODES = ("tcpm", "axes")
LINEAR_DECIMALS = 4       # 0.1 µm
ANGLE_DECIMALS = 4        # 0.0001°


def program_name(text: str) -> str:
    """A name both controls accept: upper-case letters, digits, underscore, a letter first."""
    name = re.sub(r"[^A-Z0-9_]", "_", text.upper())[:24] or "RTEST"
    return name if name[0].isalpha() else f"P{name}"[:24]


def measure_program(machine: Machine, poses: Poses, label: str, controller_name: str, mode: str,
                    name: str, version: str, date: str) -> Emitted:
    """The program text and its pose list (CSV v1 without readings), checked for safety.

    Each path label is a segment with its own approach and retract along machine Z, so a
    program may chain paths whose ends are far apart.
    """
    ctl = controller(controller_name)
    if mode not in MODES:
        raise CompgenError(f"mode must be one of {', '.join(MODES)}, not {mode!r}")
    setup = machine.program
    if setup is None:
        raise CompgenError(f"machine file {machine.source} has no [program] section",
                           hint="add tool, feed, dwell, clearance and safe_z (see the bundled machines)")
    ctl.check_setup(machine)
    linear = [machine.index(c) for c in "XYZ"]
    rotary = [machine.index(a.name) for a in machine.rotary_axes]
    # the machine executes the angles as written (0.0001 deg): solve X Y Z at exactly those,
    # or a 300 mm lever would put the nest up to 0.3 µm off the ball
    angles = np.radians(np.round(np.degrees(poses.q[:, rotary]), ANGLE_DECIMALS))
    poses = Poses(inverse(machine, angles, poses.ball), poses.ball, poses.t, poses.path)
    lift = np.zeros(len(machine.axes))
    lift[linear[2]] = setup.clearance
    check_travel(machine, poses.q, label)
    check_travel(machine, poses.q + lift, f"{label} (clearance {setup.clearance:g} mm above)")
    segments = [np.flatnonzero(poses.path == p) for p in dict.fromkeys(poses.path)]
    for seg in segments:
        part = poses.take(seg)
        _check_steps(machine, part, str(part.path[0]) or label)
        _check_feed(machine, part, setup.feed, str(part.path[0]) or label)
    if mode == "tcpm":   # the ball centre in workpiece coordinates: the pose with rotary axes at 0
        xyz = inverse(machine, np.zeros((len(poses), len(rotary))), poses.ball)[:, linear]
    else:
        xyz = poses.q[:, linear]
    fmt = ctl.number

    def rot(i):
        return " ".join(f"{a.name}{fmt(np.degrees(poses.q[i, j]), ANGLE_DECIMALS)}"
                        for a, j in zip(machine.rotary_axes, rotary, strict=True))

    rows = [{"k": i + 1, "path": ascii_text(str(poses.path[i])), "rotary": rot(i),
             **{c: fmt(xyz[i, j], LINEAR_DECIMALS) for j, c in enumerate("XYZ")}}
            for i in range(len(poses))]

    def end(i):
        z = poses.q[i, linear[2]]
        return {"rotary": rot(i), "X": fmt(poses.q[i, linear[0]], LINEAR_DECIMALS),
                "Y": fmt(poses.q[i, linear[1]], LINEAR_DECIMALS), "Z": fmt(z, LINEAR_DECIMALS),
                "Z_clear": fmt(z + setup.clearance, LINEAR_DECIMALS)}

    parts = [{"label": ascii_text(str(poses.path[seg[0]]) or label), "first": end(seg[0]),
              "last": end(seg[-1]), "poses": [rows[i] for i in seg]}
             for seg in segments]
    span = {c: (poses.q[:, j].min(), poses.q[:, j].max()) for c, j in zip("XYZ", linear, strict=True)}
    ball = poses.ball[0]
    header = [
        f"compgen {version} R-test measurement program, {date}",
        f"machine: {ascii_text(machine.name)}; controller: {ctl.words}",
        (f"mode TCPM: {ctl.tcp_words}, the control's kinematics moves X Y Z (tests the control)"
         if mode == "tcpm" else
         "mode AXES: X Y Z from compgen's inverse kinematics (tests compgen's nominal model)"),
        f"path {ascii_text(label)}: {len(poses)} poses; pose list {name}.poses.csv, same order",
        "ball centre in the table frame: "
        + " ".join(f"{c}{fmt(v, 3)}" for c, v in zip("XYZ", ball, strict=True))
        + f" mm; nest on tool {setup.tool}",
        "active preset: the machine file's origin (nominal intersection of the rotary axes)",
        f"feed {setup.feed:g} mm/min; dwell {setup.dwell:g} s per pose; clearance "
        f"{setup.clearance:g} mm; safe Z {setup.safe_z:g} mm (machine)",
        "travel checked: " + ", ".join(f"{c} {lo:.3f}..{hi:.3f}" for c, (lo, hi) in span.items())
        + " mm; " + ", ".join(f"{a.name} {np.degrees(poses.q[:, j].min()):.3f}.."
                              f"{np.degrees(poses.q[:, j].max()):.3f}"
                              for a, j in zip(machine.rotary_axes, rotary, strict=True)) + " deg",
        "first run: single block, feed override low, nest and ball clear of clamps",
    ]
    text = render(f"{ctl.family}/program{ctl.program_ext}.j2", name=name, header=header, mode=mode,
                  tool=setup.tool, feed=f"{setup.feed:g}", dwell=f"{setup.dwell:g}" if setup.dwell else "",
                  safe_z=fmt(setup.safe_z, 3), work_offset=setup.work_offset,
                  max_step=f"{machine.limits.max_step_deg:g}", segments=parts)
    return Emitted({ctl.program_ext: text, ".poses.csv": pose_list(machine, poses)})


def pose_list(machine: Machine, poses: Poses) -> str:
    """CSV v1 columns without readings: add dX dY dZ from the R-test and it is fit input."""
    head = ["path", *machine.axis_names, *BALL]
    lines = [",".join(head)]
    for i in range(len(poses)):
        lines.append(",".join([ascii_text(str(poses.path[i])), *axis_cells(machine, poses.q[i]),
                               *(f"{v:.6f}" for v in poses.ball[i])]))
    return "\n".join(lines) + "\n"


def _check_steps(machine: Machine, poses: Poses, label: str) -> None:
    limit = machine.limits.max_step_deg
    for a in machine.rotary_axes:
        step = np.abs(np.diff(np.degrees(poses.q[:, machine.index(a.name)])))
        if step.size and step.max() > limit:
            i = int(step.argmax())
            raise CompgenError(f"{label}: {a.name} jumps {step[i]:.2f} deg between poses {i + 1} and "
                               f"{i + 2}, more than max_step_deg = {limit:g}",
                               hint="add intermediate poses, or raise [limits] max_step_deg")


def _check_feed(machine: Machine, poses: Poses, feed: float, label: str) -> None:
    for a in machine.axes:
        if not a.rotary and feed > a.feed_max:
            raise CompgenError(f"[program] feed {feed:g} mm/min exceeds {a.name}'s feed_max {a.feed_max:g}")
    linear = [machine.index(c) for c in "XYZ"]
    seconds = np.linalg.norm(np.diff(poses.q[:, linear], axis=0), axis=1) / feed * 60.0
    for a in machine.rotary_axes:
        turn = np.abs(np.diff(np.degrees(poses.q[:, machine.index(a.name)])))
        with np.errstate(divide="ignore", invalid="ignore"):
            speed = np.where(turn > 0, turn / seconds * 60.0, 0.0)
        if speed.size and speed.max() > a.feed_max:
            i = int(speed.argmax())
            raise CompgenError(f"{label}: at feed {feed:g} mm/min, {a.name} would turn at "
                               f"{speed[i]:.0f} deg/min between poses {i + 1} and {i + 2}, above "
                               f"its feed_max {a.feed_max:g}", hint="lower [program] feed")


def read_program(text: str, machine: Machine, controller_name: str) -> tuple[str, np.ndarray, np.ndarray]:
    """Parse an emitted program back: (mode, X Y Z per pose (n, 3) mm, rotary (n, r) deg).

    In TCPM mode X Y Z are workpiece coordinates; in axes mode machine-axis positions.
    """
    ctl = controller(controller_name)
    tcpm = ctl.tcpm_on.search(text) is not None
    xyz, rot, numbers = [], [], []
    names = [a.name for a in machine.rotary_axes]
    for line in text.splitlines():
        m = ctl.pose_line.match(line)
        if not m:
            continue
        words = dict((w[0], float(w[1:])) for w in m[4].split())
        if sorted(words) != sorted(names):
            raise CompgenError(f"pose {m[5]} names rotary axes {sorted(words)}, the machine {names}")
        xyz.append([float(m[i]) for i in (1, 2, 3)])
        rot.append([words[a] for a in names])
        numbers.append(int(m[5]))
    if not xyz:
        raise CompgenError("no pose blocks found: not a compgen measurement program")
    if numbers != list(range(1, len(numbers) + 1)):
        raise CompgenError("pose numbers are not 1, 2, 3, …: the program was edited")
    return ("tcpm" if tcpm else "axes"), np.array(xyz), np.array(rot)
