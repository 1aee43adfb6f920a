"""Probing programs: a touch probe on the calibration sphere at each pose of K1, K2, K4,
writing the probe log v1 (``docs/probe-log.md``) on the control.

Every pose: the rotary axes turn at the safe height; the stylus comes down above the
sphere; each touch starts ``approach`` from the surface on the line from the sphere's
centre, probes radially inwards to ``overtravel`` beyond it, logs the tip centre the
control latched, and goes back the way it came; between touches the stylus rises to the
start of the touch along the stylus, so it never crosses the sphere. Where the tool does not
tilt, positions are machine axes from compgen's inverse kinematics (no TCP): the log's X, Y,
Z are then the frame the log's contract names. A head is probed under TCP, as its measuring
programs run (off it, a tilted head's tool length is not along the axis a move names): the
touches turn with the stylus, and each latched tip is turned from TCP coordinates into the
machine frame by the pose's nominal kinematics before it is logged (U25). The program is run
through the motion check (``Controller.check``) with the probe in the set-up before it is
returned.

Per control, what writes the log: LinuxCNC ``G38.2`` with ``(LOGOPEN,…)``/``(LOG,…)`` and
the probe result parameters #5061–#5063 (LinuxCNC's ``interp_parameter_def.hh``: "5061-5069
Coordinates of a G38 probe result … in the coordinate system in which the G38 took
place"); SINUMERIK ``MEAS=1`` and ``WRITE``; HEIDENHAIN touch-probe cycle 4 and ``FN 16:
F-PRINT``. What no source read so far confirms is marked in ``templates/unconfirmed.j2``.
"""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np

from ..data.probe import DIRECTION, MAGIC, need_probe, stylus_up, tip_centres, touch_directions
from ..data.rtest import BALL
from ..errors import CompgenError
from ..model.frames import from_world, safe_height, world
from ..model.kinematics import inverse
from ..model.machine import Machine, ProbeSetup, at_nest, check_travel
from ..model.poses import Poses
from . import Emitted, ascii_text, render
from .base import Controller
from .plc import check_plc, index_steps, plc_lines
from .programs import (
    ANGLE_DECIMALS,
    BALL_HEADER,
    LINEAR_DECIMALS,
    NEST_HEADER,
    at_ball,
    held_turn,
    pose_list,
    write_words,
)
from .registry import for_machine


def with_sphere(machine: Machine, length: float | None = None) -> Machine:
    """The machine with its set-up's ball the probe's calibration sphere; on a head, the
    stylus tip its tool point, ``length`` below the gauge line (a program's header or
    --probe-length; default ``[probe] length``): the lever the head turns it by."""
    setup = need_probe(machine)
    if machine.heads:
        machine = at_nest(machine, setup.length if length is None else length,
                          f"{machine.source}: [probe] length")
    return replace(machine, setup=replace(machine.setup, ball_diameter=setup.sphere_diameter))


def probe_program(machine: Machine, poses: Poses, label: str, controller_name: str, name: str,
                  version: str, date: str, spindle_deg: float | None = None) -> Emitted:
    """The probing program (and, for HEIDENHAIN, its F-PRINT format files), checked with the
    probe in the set-up. ``poses``: one ball position, the rotary axes of each pose;
    ``spindle_deg``: the spindle oriented there before the first touch (the probe and its
    trigger's lobes turn with it: a second log at another orientation tells them from the
    machine), said in the log's ``spindle_deg``."""
    ctl = for_machine(controller_name, machine)
    setup = need_probe(machine)
    balls = np.unique(np.round(np.asarray(poses.ball, float), 6), axis=0)
    if len(balls) > 1:
        raise CompgenError(f"a program probes one sphere position; these poses hold {len(balls)}",
                           hint="write one program per sphere position")
    check_plc(machine, ctl)
    if not ctl.writes_probing(machine):
        raise CompgenError(f"compgen writes {ctl.words} probing programs for machines whose tool does not "
                           f"tilt: a head is probed under TCP, which {ctl.words} switches in its "
                           "configuration, not in the program",
                           hint="measure this head with an R-test (measure-program), or probe it on a "
                                "HEIDENHAIN or SINUMERIK control (--controller)")
    ctl.check_tool(setup.tool, "[probe] tool", machine.source)
    if machine.program is None:
        raise CompgenError(f"machine file {machine.source} has no [program] section",
                           hint="it gives the work offset the program's positions are in")
    machine = with_sphere(at_ball(machine, balls[0]))
    rotary = [machine.index(a.name) for a in machine.rotary_axes]
    angles = np.radians(np.round(np.degrees(poses.q[:, rotary]), ANGLE_DECIMALS))
    poses = Poses(inverse(machine, angles, poses.ball), poses.ball, poses.t, poses.path)
    check_travel(machine, poses.q, label)
    safe = safe_height(machine)
    names = [a.name for a in machine.rotary_axes]
    steps, count, reach = _touch_steps(machine, poses, setup, names, safe)
    if spindle_deg is not None:
        if not (math.isfinite(spindle_deg) and 0.0 <= spindle_deg < 360.0):
            raise CompgenError(f"--spindle-deg {spindle_deg:g}: the spindle's orientation is 0 to 360 "
                               "degrees")
        steps.insert(0, {"kind": "orient", "deg": f"{spindle_deg:.4f}", "note": "the probe turned with it"})
    check_travel(machine, np.array(reach), f"{label} (the touches' start and end points)")
    write_words(ctl, machine, steps)
    log_name = name[:ctl.name_max - 4] + "_LOG"     # a name the control keeps, one per program
    header = _probe_header(machine, ctl, setup, poses, label, log_name, safe, version, date)
    if spindle_deg is not None:
        header.append(f"the spindle oriented to {spindle_deg:g} deg before the first touch: the probe and "
                      "its trigger turn with it" + ("" if ctl.family == "linuxcnc" else " (U27)"))
    log_head = [MAGIC, f"# sphere_diameter = {setup.sphere_diameter:.4f}",
                f"# stylus_diameter = {setup.stylus_diameter:.4f}",
                *([f"# machine = {machine.name}"] if _loggable(machine.name) else []),
                *([f"# spindle_deg = {spindle_deg:.4f}"] if spindle_deg is not None else []),
                ",".join(["path", "pose", *names, "X", "Y", "Z", *DIRECTION, *BALL])]
    # where the sphere stood, on every touch's line (the contract's bx, by, bz): a log of the
    # sphere moved as a diagnosis advised is fitted where it was, not where the machine file has it
    ball = ",".join(f"{v:.4f}" for v in poses.ball[0])
    text = render(f"{ctl.family}/probe{ctl.program_ext}.j2", name=name, header=header, steps=steps,
                  tool=ctl.tool_word(setup.tool), feed=f"{setup.feed:g}", probe_feed=f"{setup.probe_feed:g}",
                  work_offset=machine.program.work_offset, log_name=log_name, log_head=log_head,
                  rotary=names, number=ctl.number, retract=ctl.number(setup.approach, 4), ball=ball,
                  head_tcp=bool(machine.heads), plc=bool(machine.plc_axes), orient=spindle_deg is not None,
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


def _touch_steps(machine: Machine, poses: Poses, setup: ProbeSetup, names: list[str],
                 safe: float) -> tuple[list[dict], dict[str, int], list]:
    """Each pose's steps: the turn at the safe height, then each touch from its start out on
    the line from the centre, probing inwards, logged, and back the way it came; the poses
    counted per path, and every point the axes go to (for the travel check). Between
    touches the stylus rises along itself to where the touch along it started, so it never
    crosses the sphere. On a head every move runs under TCP (``_Touches``)."""
    w = _Touches(machine, safe)
    rho = (setup.sphere_diameter + setup.stylus_diameter) / 2
    hub = rho + setup.approach                # along the stylus from the centre: the first touch's start
    u = touch_directions(machine, poses, setup)
    up = stylus_up(machine, poses.q)
    tips = tip_centres(machine, poses.q, None)
    count: dict[str, int] = {}
    for i in range(len(poses)):
        path = ascii_text(str(poses.path[i]))
        if not LOG_WORD.fullmatch(path):
            raise CompgenError(f"path label {path!r} cannot stand in the control's log lines",
                               hint="name paths with letters, digits, _ and - (e.g. K4)")
        count[path] = count.get(path, 0) + 1
        c, q = tips[i], poses.q[i]
        turn = {n: float(np.degrees(q[j])) for n, j in zip(names, w.rotary, strict=True)}
        w.steps.append({"kind": "comment", "note": f"---- {path} pose {count[path]}: "
                        + " ".join(f"{n}{v:.4f}" for n, v in turn.items())})
        w.turn(q)
        w.above(q, c + hub * up[i], "above the sphere")
        log_map = w.log_map(q)
        for j, direction in enumerate(u[i]):
            start = c + (rho + setup.approach) * direction
            over = start + (hub - (start - c) @ up[i]) * up[i]     # across the stylus from the first start
            if j:
                w.to(q, over)
            w.to(q, start)
            if i == j == 0:       # the preset and the sphere, seen before the first touch
                w.steps.append({"kind": "stop",
                                "note": PROBE_PRESET_CHECK.format(approach=f"{setup.approach:g}")})
            w.probe(q, c + (rho - setup.overtravel) * direction, -direction,
                    setup.approach + setup.overtravel)
            w.steps.append({"kind": "log", "path": path, "pose": count[path], "turn": turn,
                            "n": [f"{v:.6f}" for v in -direction], "map": log_map})
            w.to(q, start, note="back off")
            if j:
                w.to(q, over)
        w.up(q)
    return w.finish(), count, w.reach


class _Touches:
    """A probing program's moves as the axes make them (``reach``), each a step the
    templates write: machine axes where the tool does not tilt (the tip is the linear
    axes'); on a head, TCP coordinates under the control's TCP, switched on once at the
    safe height with the rotary axes at zero (as a head's measuring program does), the
    turns in small steps that keep the tip where it is, and each log line's tip turned
    from TCP coordinates into the machine frame (``log_map``)."""

    def __init__(self, machine: Machine, safe: float):
        self.machine, self.safe, self.tcp = machine, safe, bool(machine.heads)
        self.linear = [machine.index(c) for c in "XYZ"]
        self.rotary = [machine.index(a.name) for a in machine.rotary_axes]
        self.names = [a.name for a in machine.rotary_axes]
        self.steps: list[dict] = [{"kind": "rapid", "axes": {"Z": safe}, "note": "up to the safe height"}]
        self.reach: list[np.ndarray] = []
        self.q = None          # the machine pose after the last step, where known
        self.tip = None
        if self.tcp:
            self.steps += [{"kind": "rapid", "axes": dict.fromkeys(self.names, 0.0),
                            "note": "rotary axes to zero at the safe height"}, {"kind": "tcp_on"}]
            self.q = np.zeros(len(machine.axes))
            self.q[self.linear[2]] = safe
            self.tip = self.q[self.linear].copy()
            self._step("rapid", self.q, "above the rotary axes")

    def axes(self, q: np.ndarray, tip: np.ndarray) -> np.ndarray:
        """The pose at ``q``'s rotary axes that puts the stylus tip at ``tip``: at fixed
        rotary axes the tip moves as the linear axes do."""
        out = np.array(q, float)
        out[self.linear] = q[self.linear] + tip - tip_centres(self.machine, q[None], None)[0]
        return out

    def _step(self, kind: str, q: np.ndarray, note: str = "", **more) -> dict:
        step = {"kind": kind, "axes": dict(zip("XYZ", q[self.linear], strict=True)), "note": note,
                "q": q if self.tcp else None, **more}
        self.steps.append(step)
        return step

    def turn(self, q: np.ndarray) -> None:
        """The rotary axes to ``q``'s at the safe height: in one move where the tool does not
        tilt; on a head in steps, the tip kept in place (``programs.held_turn``)."""
        if not self.tcp:
            turn = {n: float(np.degrees(q[j])) for n, j in zip(self.names, self.rotary, strict=True)}
            for a in index_steps(self.machine, self.steps, self.q, turn):      # the PLC's (U26)
                del turn[a]
            if turn:
                self.steps.append({"kind": "rapid", "note": "turn at the safe height", "axes": turn})
            self.q = q
            return
        turn = held_turn(self.machine, self.q, q, True)      # the tip held where it is
        for k, self.q in enumerate(turn, 1):
            s = self._step("rapid", self.q, "turn at the safe height" if k == len(turn) else "")
            s["axes"].update({a: np.degrees(self.q[j]) for a, j in zip(self.names, self.rotary, strict=True)})

    def above(self, q: np.ndarray, tip: np.ndarray, note: str) -> None:
        """The stylus tip straight above ``tip`` (machine frame) at the safe height."""
        self.tip = np.array([tip[0], tip[1], self.safe])
        self.q = self.axes(q, self.tip)
        if self.tcp:
            self._step("rapid", self.q, note)
        else:           # the axes are at the safe height and turned already: X and Y alone
            self.steps.append({"kind": "rapid", "axes": {"X": tip[0], "Y": tip[1]}, "note": note})

    def up(self, q: np.ndarray) -> None:
        """The stylus tip up to the safe height (machine Z), the rest held."""
        if self.tcp:
            self.above(q, self.tip, "up to the safe height")
        else:
            self.steps.append({"kind": "rapid", "axes": {"Z": self.safe}, "note": "up to the safe height"})

    def to(self, q: np.ndarray, tip: np.ndarray, note: str = "") -> None:
        """The stylus tip to ``tip`` (machine frame) at ``q``'s rotary axes, at the feed."""
        self.q, self.tip = self.axes(q, tip), tip
        self.reach.append(self.q)
        self._step("feed", self.q, note)

    def probe(self, q: np.ndarray, target: np.ndarray, inwards: np.ndarray, distance: float) -> None:
        """A probing move towards ``target`` (the tip's, machine frame) along ``inwards``."""
        end = self.axes(q, target)
        self.reach.append(end)
        self._step("probe", end, direction=inwards, distance=distance, start=self.q)

    def log_map(self, q: np.ndarray) -> list[list[str]] | None:
        """Each row of the affine map (3 × 4) from the tip's TCP coordinates the control
        latches to the machine frame the log's contract names, at ``q``'s rotary axes, as the
        control's numbers; None where they are one (axes mode, or a head whose TCP
        coordinates are the machine's)."""
        if not self.tcp:
            return None
        corners = np.vstack([np.zeros(3), np.eye(3)])
        tips = tip_centres(self.machine, from_world(self.machine, corners,
                                                    np.repeat(q[None, self.rotary], 4, axis=0)), None)
        A, b = (tips[1:] - tips[0]).T, tips[0]
        if np.abs(A - np.eye(3)).max() < 1e-12 and np.abs(b).max() < 1e-9:
            return None
        return [[f"{round(v, 9) + 0.0:.9f}" for v in row] + [f"{round(o, 6) + 0.0:.6f}"]     # no "-0"
                for row, o in zip(A, b, strict=True)]

    def finish(self) -> list[dict]:
        """On a head: the rotary axes back to zero at the safe height, TCP off, and every
        point in TCP coordinates (each probing direction with it)."""
        if not self.tcp:
            return self.steps
        zero = self.q.copy()
        zero[self.rotary] = 0.0
        self.turn(zero)
        self.steps.append({"kind": "tcp_off"})
        held = [s for s in self.steps if s.get("q") is not None]
        xyz = world(self.machine, np.array([s["q"] for s in held]))
        for s, p in zip(held, xyz, strict=True):
            s["axes"].update(zip("XYZ", p, strict=True))
            if s["kind"] == "probe":
                d = p - world(self.machine, s["start"][None])[0]
                s["direction"] = d / np.linalg.norm(d)
        return self.steps


def _probe_header(machine: Machine, ctl: Controller, setup: ProbeSetup, poses: Poses, label: str,
                  log_name: str, safe: float, version: str, date: str) -> list[str]:
    """The probing program's header lines: what it is, its mode, its log, the sphere, the probe."""
    return [
        f"compgen {version} probing program, {date}",
        f"machine: {ascii_text(machine.name)}; controller: {ctl.label(machine)}",
        (f"mode TCPM: {ctl.tcp_label(machine)} from the first turn to the last, the control's kinematics "
         "moves X Y Z; each logged tip is turned from TCP coordinates into the machine frame (U25)"
         if machine.heads else "mode AXES: X Y Z from compgen's inverse kinematics; no TCP"),
        f"path {ascii_text(label)}: {len(poses)} poses, {setup.touches} touches each; the log: {log_name}",
        f"{BALL_HEADER} " + " ".join(f"{c}{ctl.number(v, LINEAR_DECIMALS)}"
                                     for c, v in zip("XYZ", poses.ball[0], strict=True)) + " mm",
        *([f"stylus tip on tool {setup.tool}, {ctl.number(setup.length, LINEAR_DECIMALS)} {NEST_HEADER}: "
           "the lever the head turns it by, as the control's tool table must hold it (U22)"]
          if machine.heads else []),
        f"probe: tool {setup.tool}, length {setup.length:g} mm to the stylus tip centre; sphere "
        f"{setup.sphere_diameter:g} mm, stylus tip {setup.stylus_diameter:g} mm (as calibrated)",
        "active preset: the machine file's origin (nominal intersection of the rotary axes)",
        *plc_lines(machine, ctl, "stylus"),
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
