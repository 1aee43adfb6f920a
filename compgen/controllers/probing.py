"""Probing programs: a touch probe on the calibration sphere at each pose of K1, K2, K4,
writing the probe log v1 (``docs/probe-log.md``) on the control.

Every pose: the rotary axes turn at the safe height; the stylus comes down above the
sphere; each touch starts ``approach`` from the surface on the line from the sphere's
centre, probes radially inwards to ``overtravel`` beyond it, logs the tip centre the
control latched, and goes back the way it came; between touches the stylus rises to the
height of the first (from above), so it never crosses the sphere. Positions are machine
axes from compgen's inverse kinematics (no TCP): the log's X, Y, Z are then the frame the
log's contract names. The program is run through the motion check (``Controller.check``)
with the probe in the set-up before it is returned.

Per control, what writes the log: LinuxCNC ``G38.2`` with ``(LOGOPEN,…)``/``(LOG,…)`` and
the probe result parameters #5061–#5063 (LinuxCNC's ``interp_parameter_def.hh``: "5061-5069
Coordinates of a G38 probe result … in the coordinate system in which the G38 took
place"); SINUMERIK ``MEAS=1`` and ``WRITE``; HEIDENHAIN touch-probe cycle 4 and ``FN 16:
F-PRINT``. What no source read so far confirms is marked in ``templates/unconfirmed.j2``.
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from ..data.probe import DIRECTION, MAGIC, need_probe, touch_directions
from ..data.rtest import BALL
from ..errors import CompgenError
from ..model.frames import safe_height
from ..model.kinematics import inverse
from ..model.machine import Machine, ProbeSetup, check_travel
from ..model.poses import Poses
from . import Emitted, ascii_text, render
from .base import Controller
from .programs import ANGLE_DECIMALS, BALL_HEADER, LINEAR_DECIMALS, at_ball, pose_list
from .registry import for_machine


def with_sphere(machine: Machine) -> Machine:
    """The machine with its set-up's ball the probe's calibration sphere."""
    setup = need_probe(machine)
    return replace(machine, setup=replace(machine.setup, ball_diameter=setup.sphere_diameter))


def probe_program(machine: Machine, poses: Poses, label: str, controller_name: str, name: str,
                  version: str, date: str) -> Emitted:
    """The probing program (and, for HEIDENHAIN, its F-PRINT format files), checked with the
    probe in the set-up. ``poses``: one ball position, the rotary axes of each pose."""
    ctl = for_machine(controller_name, machine)
    setup = need_probe(machine)
    balls = np.unique(np.round(np.asarray(poses.ball, float), 6), axis=0)
    if len(balls) > 1:
        raise CompgenError(f"a program probes one sphere position; these poses hold {len(balls)}",
                           hint="write one program per sphere position")
    ctl.check_tool(setup.tool, "[probe] tool", machine.source)
    if machine.program is None:
        raise CompgenError(f"machine file {machine.source} has no [program] section",
                           hint="it gives the work offset the program's positions are in")
    machine = with_sphere(at_ball(machine, balls[0]))
    rotary = [machine.index(a.name) for a in machine.rotary_axes]
    linear = [machine.index(c) for c in "XYZ"]
    angles = np.radians(np.round(np.degrees(poses.q[:, rotary]), ANGLE_DECIMALS))
    poses = Poses(inverse(machine, angles, poses.ball), poses.ball, poses.t, poses.path)
    check_travel(machine, poses.q, label)
    safe = safe_height(machine)
    names = [a.name for a in machine.rotary_axes]
    steps, count, reach = _touch_steps(machine, poses, setup, rotary, linear, names, safe)
    q = np.repeat(poses.q, setup.touches * 3, axis=0)
    q[:, linear] = np.array(reach)
    check_travel(machine, q, f"{label} (the touches' start and end points)")
    before: dict[str, float] = {}
    for s in steps:
        if "axes" in s:
            s["words"] = " ".join(ctl.axis_word(n, v, before.get(n), s["kind"] != "rapid",
                                                ANGLE_DECIMALS if n in names else LINEAR_DECIMALS, machine)
                                  for n, v in s["axes"].items())
            before.update(s["axes"])
    log_name = name[:ctl.name_max - 4] + "_LOG"     # a name the control keeps, one per program
    header = _probe_header(machine, ctl, setup, poses, label, log_name, safe, version, date)
    log_head = [MAGIC, f"# sphere_diameter = {setup.sphere_diameter:.4f}",
                f"# stylus_diameter = {setup.stylus_diameter:.4f}",
                *([f"# machine = {machine.name}"] if _loggable(machine.name) else []),
                ",".join(["path", "pose", *names, "X", "Y", "Z", *DIRECTION, *BALL])]
    # where the sphere stood, on every touch's line (the contract's bx, by, bz): a log of the
    # sphere moved as a diagnosis advised is fitted where it was, not where the machine file has it
    ball = ",".join(f"{v:.4f}" for v in poses.ball[0])
    text = render(f"{ctl.family}/probe{ctl.program_ext}.j2", name=name, header=header, steps=steps,
                  tool=ctl.tool_word(setup.tool), feed=f"{setup.feed:g}", probe_feed=f"{setup.probe_feed:g}",
                  work_offset=machine.program.work_offset, log_name=log_name, log_head=log_head,
                  rotary=names, number=ctl.number, retract=ctl.number(setup.approach, 4), ball=ball,
                  **ctl.program_context(machine))
    named = {**ctl.message_files(name, [s["note"] for s in steps if s["kind"] == "stop"]),
             **ctl.log_files(log_head, list(count), names, ball)}
    files = {ctl.program_ext: text, ".poses.csv": pose_list(machine, poses), **named}
    result = ctl.check(machine, ctl.blocks(text, "axes"), probe=setup)
    if result.findings:     # nothing unsafe leaves this function
        raise CompgenError(f"the machine cannot probe {label} with the sphere at "
                           f"{', '.join(f'{v:g}' for v in poses.ball[0])} mm: {result.first(name)}",
                           hint="move the sphere, change [probe] (elevation, approach, stylus_length) or "
                                "choose another path")
    return Emitted(files, named=frozenset(named))


def _touch_steps(machine: Machine, poses: Poses, setup: ProbeSetup, rotary: list[int], linear: list[int],
                 names: list[str], safe: float) -> tuple[list[dict], dict[str, int], list]:
    """Each pose's steps: the turn at the safe height, then each touch from its start out on
    the line from the centre, probing inwards, logged, and back the way it came; the poses
    counted per path, and every point the stylus goes to (for the travel check)."""
    rho = (setup.sphere_diameter + setup.stylus_diameter) / 2
    hub = rho + setup.approach                # above the centre: the start of the touch from above
    u = touch_directions(machine, poses, setup)
    steps: list[dict] = [{"kind": "rapid", "axes": {"Z": safe}, "note": "up to the safe height"}]
    count: dict[str, int] = {}
    reach = []                                 # every point the stylus goes to, for the travel check
    for i in range(len(poses)):
        path = ascii_text(str(poses.path[i]))
        if not LOG_WORD.fullmatch(path):
            raise CompgenError(f"path label {path!r} cannot stand in the control's log lines",
                               hint="name paths with letters, digits, _ and - (e.g. K4)")
        count[path] = count.get(path, 0) + 1
        c = poses.q[i, linear]
        turn = {n: float(np.degrees(poses.q[i, j])) for n, j in zip(names, rotary, strict=True)}
        steps.append({"kind": "comment", "note": f"---- {path} pose {count[path]}: "
                      + " ".join(f"{n}{v:.4f}" for n, v in turn.items())})
        steps.append({"kind": "rapid", "axes": turn, "note": "turn at the safe height"})
        steps.append({"kind": "rapid", "axes": {"X": c[0], "Y": c[1]}, "note": "above the sphere"})
        for j, direction in enumerate(u[i]):
            start = c + (rho + setup.approach) * direction
            over = start if j == 0 else np.array([start[0], start[1], c[2] + hub])
            target = c + (rho - setup.overtravel) * direction
            if j:
                steps.append({"kind": "feed", "axes": dict(zip("XYZ", over, strict=True))})
            steps.append({"kind": "feed", "axes": dict(zip("XYZ", start, strict=True))})
            if i == j == 0:       # the preset and the sphere, seen before the first touch
                steps.append({"kind": "stop",
                              "note": PROBE_PRESET_CHECK.format(approach=f"{setup.approach:g}")})
            steps.append({"kind": "probe", "axes": dict(zip("XYZ", target, strict=True)),
                          "direction": -direction, "distance": setup.approach + setup.overtravel})
            steps.append({"kind": "log", "path": path, "pose": count[path], "turn": turn,
                          "n": [f"{v:.6f}" for v in -direction]})
            steps.append({"kind": "feed", "axes": dict(zip("XYZ", start, strict=True)), "note": "back off"})
            if j:
                steps.append({"kind": "feed", "axes": dict(zip("XYZ", over, strict=True))})
            reach += [start, over, target]
        steps.append({"kind": "rapid", "axes": {"Z": safe}, "note": "up to the safe height"})
    return steps, count, reach


def _probe_header(machine: Machine, ctl: Controller, setup: ProbeSetup, poses: Poses, label: str,
                  log_name: str, safe: float, version: str, date: str) -> list[str]:
    """The probing program's header lines: what it is, its mode, its log, the sphere, the probe."""
    return [
        f"compgen {version} probing program, {date}",
        f"machine: {ascii_text(machine.name)}; controller: {ctl.label(machine)}",
        "mode AXES: X Y Z from compgen's inverse kinematics; no TCP",
        f"path {ascii_text(label)}: {len(poses)} poses, {setup.touches} touches each; the log: {log_name}",
        f"{BALL_HEADER} " + " ".join(f"{c}{ctl.number(v, LINEAR_DECIMALS)}"
                                     for c, v in zip("XYZ", poses.ball[0], strict=True)) + " mm",
        f"probe: tool {setup.tool}, length {setup.length:g} mm to the stylus tip centre; sphere "
        f"{setup.sphere_diameter:g} mm, stylus tip {setup.stylus_diameter:g} mm (as calibrated)",
        "active preset: the machine file's origin (nominal intersection of the rotary axes)",
        f"each touch: {setup.approach:g} mm out, probing {setup.probe_feed:g} mm/min up to "
        f"{setup.overtravel:g} mm in; positioning {setup.feed:g} mm/min; safe height Z {safe:g} mm",
        "first run: single block, feed override low, the probe's stylus clear of the sphere",
    ]


# what every control's log line carries as written: LinuxCNC expands "#" (a parameter) in a
# LOG comment, which ends at ")"; a SINUMERIK string ends at '"'; HEIDENHAIN's FN 16 format
# reads "%" as a format and "\"" as the text's end; ";" starts a comment in two of them
LOG_WORD = re.compile(r"[A-Za-z0-9_][A-Za-z0-9 _.,:+/-]*")
LOGGED_MAX = 200        # a free text on a log line: "(LOG,# machine = ...)" within LinuxCNC's 255
# the operator sees, before the stylus first goes down, that the sphere is where the preset
# puts it (one line under the 124 characters a SINUMERIK message shows)
PROBE_PRESET_CHECK = ("PRESET CHECK: the stylus tip is {approach} mm above the sphere and the sphere must be "
                      "centred under it. Start to go on")


def _loggable(text: str) -> bool:
    """Whether every control's log line carries ``text`` as written (else it is left out):
    its characters, and its length within LinuxCNC's 255 characters of a line."""
    return LOG_WORD.fullmatch(text) is not None and len(text) <= LOGGED_MAX
