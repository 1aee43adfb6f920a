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
from contextlib import contextmanager
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from ..data.rtest import BALL, NEST, axis_cells, side_columns
from ..errors import CompgenError
from ..model.frames import along_tool, at_height, safe_height, world
from ..model.kinematics import head_offset, inverse
from ..model.machine import Machine, at_nest, check_ball, check_travel
from ..model.poses import Poses
from ..model.sides import APPROACH_DEG, program_sides
from ..motion import check as motion
from ..units import number
from . import Emitted, ascii_text, render
from .base import Controller
from .plc import check_plc, index_steps, plc_lines, plc_runs
from .registry import for_machine

MODES = ("tcpm", "axes")
LINEAR_DECIMALS = 4       # 0.1 µm
ANGLE_DECIMALS = 4        # 0.0001°


NAME_MAX = 24      # characters of a program name every control here keeps
# The header line that carries the program's set-up: check-program reads the ball from it
BALL_HEADER = "ball centre in the table frame:"
_BALL_LINE = re.compile(re.escape(BALL_HEADER) + r" X([-+]?\d+(?:\.\d+)?) Y([-+]?\d+(?:\.\d+)?) "
                        r"Z([-+]?\d+(?:\.\d+)?) mm")
NEST_HEADER = "mm below the gauge line"     # the nest's length, where not the machine file's
# the length as the control's numbers write it (HEIDENHAIN signs it: +150.0000)
_NEST_LINE = re.compile(r"(?:nest|stylus tip) on tool \S+, ([-+]?\d+(?:\.\d+)?) " + re.escape(NEST_HEADER))


def program_nest(text: str) -> float | None:
    """The nest's length below the gauge line (mm) a compgen program was written for, where
    its header names one (a session with another nest than the machine file's), else None."""
    found = {float(m[1]) for m in _NEST_LINE.finditer(text)}
    if len(found) > 1:
        raise CompgenError(f"the program's header names {len(found)} nest lengths",
                           hint="give the one it was written for with --probe-length MM")
    return found.pop() if found else None


@contextmanager
def lines_of(source: str):
    """Refusals of a program's readers (its header, the controls' blocks) placed at
    ``source``:line: the readers count lines, not files ("line 49: …" named no program)."""
    try:
        yield
    except CompgenError as e:
        said = re.fullmatch(r"line (\d+): (.*)", e.message, re.S)
        if e.where is None and said:
            raise CompgenError(said[2], where=f"{source}:{said[1]}", hint=e.hint) from None
        raise


def program_ball(text: str) -> tuple[float, float, float] | None:
    """The ball a compgen program was written for (mm, table frame), from its header; None
    for a program without that line. Two different balls in one header are refused, and so
    is a header line naming the ball that does not read as one: it is not replaced by the
    machine file's ball without a word."""
    for k, line in enumerate(text.splitlines(), start=1):
        if BALL_HEADER in line and _BALL_LINE.search(line) is None:
            said = line.split(BALL_HEADER, 1)[1].strip()
            raise CompgenError(f"line {k}: the header names the ball as {said!r}, not as X… Y… Z… mm: which "
                               "ball the program was written for is unknown",
                               hint="give it with --ball X,Y,Z, or the program compgen wrote")
    found = {tuple(float(v) for v in m.groups()) for m in _BALL_LINE.finditer(text)}
    if len(found) > 1:
        raise CompgenError(f"the program's header names {len(found)} ball positions",
                           hint="give the one it was written for with --ball X,Y,Z")
    return found.pop() if found else None


def at_ball(machine: Machine, ball) -> Machine:
    """The machine with its R-test ball at ``ball`` (mm, table frame), for everything that
    checks a program: the datum, the safe height and the set-up's solids."""
    ball = tuple(float(v) for v in ball)
    check_ball(machine.setup, ball, "")
    return machine if ball == tuple(machine.ball) else replace(machine, ball=ball)


def program_name(text: str, room: int = 0, most: int = NAME_MAX) -> str:
    """A name every control accepts: upper-case letters, digits, underscore, a letter first.
    A name longer than the control keeps (``most``, its ``Controller.name_max``, less
    ``room`` for a suffix compgen adds) is refused, not cut: two cut names could be one
    program and one pose list."""
    name = re.sub(r"[^A-Z0-9_]", "_", text.upper()) or "RTEST"
    name = name if name[0].isalpha() else f"P{name}"
    if len(name) > most - room:
        raise CompgenError(f"program name {name} is {len(name)} characters; the control keeps "
                           f"{most - room}", hint="give a shorter output file name")
    return name


def measure_program(machine: Machine, poses: Poses, label: str, controller_name: str, mode: str,
                    name: str, version: str, date: str, list_name: str | None = None,
                    notes: tuple[str, ...] = ()) -> Emitted:
    """The program text and its pose list (CSV v1 without readings), checked for safety.
    ``list_name`` is the pose list's file stem, as the user gave it (default ``name``);
    ``notes``: more lines for the program's header.

    Each path label is a segment with its own approach and retract along machine Z, so a
    program may chain paths whose ends are far apart.
    """
    text, machine, poses, stops, _ = checked_program(machine, poses, label, controller_name, mode, name,
                                                     version, date, list_name, notes)
    ctl = for_machine(controller_name, machine)
    messages = ctl.message_files(name, stops)
    return Emitted({ctl.program_ext: text, ".poses.csv": pose_list(machine, poses), **messages},
                   named=frozenset(messages))


class Checked(NamedTuple):
    """A program written and checked: its text, the machine at its ball and nest, the poses
    as solved, the notes of its stops, and its time as the motion check counts it (s)."""

    text: str
    machine: Machine
    poses: Poses
    stops: list[str]
    seconds: float


def checked_program(machine: Machine, poses: Poses, label: str, controller_name: str, mode: str,
                    name: str, version: str, date: str, list_name: str | None = None,
                    notes: tuple[str, ...] = ()) -> Checked:
    """``measure_program``'s program text, every check made (a refusal raises): with the
    machine at its ball and nest, the poses as solved, and the notes of its stops. The
    advice asks only this of each measurement it offers (the files beside it are not
    refusals)."""
    ctl = for_machine(controller_name, machine)
    if mode not in MODES:
        raise CompgenError(f"mode must be one of {', '.join(MODES)}, not {mode!r}")
    if machine.heads and mode != "tcpm":
        raise CompgenError("a head's programs are written for its control's kinematics only (mode tcpm): "
                           "in axes the nest swings about the pivot between poses", hint="leave --mode out")
    setup = machine.program
    if setup is None:
        raise CompgenError(f"machine file {machine.source} has no [program] section",
                           hint="add tool, feed, dwell and clearance (see the bundled machines)")
    ctl.check_setup(machine)
    balls = np.unique(np.round(np.asarray(poses.ball, float), 6), axis=0)
    if len(balls) > 1:
        raise CompgenError(f"a program measures one ball position; these poses hold {len(balls)}",
                           hint="write one program per ball position")
    nests = np.unique(poses.nest)
    if len(nests) > 1:
        raise CompgenError(f"a program measures with one nest; these poses hold {len(nests)} nest lengths",
                           hint="write one program per nest length")
    file_nest = machine.probe_length
    nest = None if np.isnan(nests[0]) else float(nests[0])
    # travel, safe height and motion check with the nest the session uses, the ball where it is
    machine = at_ball(at_nest(machine, nest), balls[0])
    linear = [machine.index(c) for c in "XYZ"]
    rotary = [machine.index(a.name) for a in machine.rotary_axes]
    # the machine executes the angles as written (0.0001 deg): solve X Y Z at exactly those,
    # or a 300 mm lever would put the nest up to 0.3 µm off the ball
    angles = np.radians(np.round(np.degrees(poses.q[:, rotary]), ANGLE_DECIMALS))
    _check_hirth(machine, np.degrees(angles), label)
    q = inverse(machine, angles, poses.ball)
    # the program runs the poses in the pose list's order (the R-test's readings come in it),
    # one segment, with its own approach and retract, per run of one path label (and of one
    # position of each axis the PLC turns)
    check_plc(machine, ctl)
    segments = plc_runs(machine, poses.path, angles)
    run = np.repeat(np.arange(len(segments)), list(map(len, segments)))
    poses = Poses(q, poses.ball, poses.t, poses.path, program_sides(machine, q, run), poses.nest)
    check_travel(machine, poses.q, label)
    check_travel(machine, along_tool(machine, poses.q, setup.clearance),
                 f"{label} (clearance {setup.clearance:g} mm off the ball)")
    for seg in segments:
        part = poses.take(seg)
        _check_steps(machine, part, str(part.path[0]) or label)
        _check_feed(machine, part, setup.feed, str(part.path[0]) or label, mode)
    safe = safe_height(machine)
    up = np.zeros(len(machine.axes))
    up[linear[2]] = safe
    check_travel(machine, up[None], f"the safe height Z {safe:g} above the rotary axes")
    steps = _steps(machine, poses, segments, mode, ctl.tcp_switchable, safe, setup.clearance, label)
    write_words(ctl, machine, steps)
    ball = poses.ball[0]
    header = _program_header(machine, ctl, poses, label, mode, list_name or name, nest, file_nest, safe,
                             version, date, notes)
    text = render(f"{ctl.family}/program{ctl.program_ext}.j2", name=name, header=header, mode=mode,
                  tool=ctl.tool_word(setup.tool), feed=f"{setup.feed:g}",
                  dwell=f"{setup.dwell:g}" if setup.dwell else "",
                  work_offset=setup.work_offset, max_step=f"{machine.limits.max_step_deg:g}",
                  steps=steps, rotary=[a.name for a in machine.rotary_axes], turns_tool=bool(machine.heads),
                  indexes=bool(machine.hirth_axes), plc=bool(machine.plc_axes),
                  **ctl.program_context(machine))
    result = ctl.check(machine, ctl.blocks(text, mode))
    if result.findings:     # compgen's own safety net: nothing unsafe leaves this function
        at = ", ".join(f"{v:g}" for v in ball)
        raise CompgenError(f"the machine cannot run {label} with the ball at {at} mm: {result.first(name)}",
                           hint="put the ball higher on its stem or nearer the rotary axes, or choose "
                                "another path; the set-up's solids are the machine file's [rtest]")
    return Checked(text, machine, poses, [s["note"] for s in steps if s["kind"] == "stop"], result.seconds)


def held_turn(machine: Machine, q: np.ndarray, target: np.ndarray, tcp: bool) -> list[np.ndarray]:
    """The poses of a turn of the rotary axes from ``q`` to ``target``'s at the safe height:
    one move, or under TCP steps of TURN_STEP_DEG (none where they are there already) with
    the tool point kept where it is (``machine.probe_length`` down the tool: a head's turn is
    taken off its linear axes); a Hirth axis's steps on its teeth."""
    rotary = [machine.index(a.name) for a in machine.rotary_axes]
    linear = [machine.index(c) for c in "XYZ"]
    delta = np.degrees(np.abs(target[rotary] - q[rotary])).max()
    n = int(np.ceil(delta / TURN_STEP_DEG)) if tcp else 1
    point = q[linear] + head_offset(machine, q[None, rotary])[0] if tcp else None
    out = []
    for k in range(1, n + 1):
        step = q.copy()
        step[rotary] = q[rotary] + (target[rotary] - q[rotary]) * k / n
        step[rotary] = [np.radians(a.on_grid(np.degrees(v)))            # a Hirth axis: its teeth
                        for a, v in zip(machine.rotary_axes, step[rotary], strict=True)]
        if tcp:
            step[linear] = point - head_offset(machine, step[None, rotary])[0]
        out.append(step)
    return out


def write_words(ctl: Controller, machine: Machine, steps: list[dict]) -> None:
    """Each step's axis words as ``ctl`` writes them (``Controller.axis_word``: a move's
    feed, the block before's value), and a PLC turn's target in the sense those words have."""
    before: dict[str, float] = {}
    for step in steps:
        if step["kind"] == "index":
            step["value"] *= ctl.angle_sense(machine).get(step["axis"], 1)
            step["word"] = ctl.number(step["value"], ANGLE_DECIMALS)
        if "axes" in step:
            step["words"] = " ".join(ctl.axis_word(n, v, before.get(n), step["kind"] != "rapid",
                                                   ANGLE_DECIMALS if n in ROT else LINEAR_DECIMALS, machine)
                                     for n, v in step["axes"].items())
            before.update(step["axes"])


def _check_hirth(machine: Machine, deg: np.ndarray, label: str) -> None:
    """Every position of a Hirth-coupled axis on its grid: between its teeth it cannot rest."""
    for k, a in enumerate(machine.rotary_axes):
        if a.hirth_deg is not None:
            off = np.abs(deg[:, k] - a.on_grid(deg[:, k]))
            if (off > 1e-6).any():
                i = int(np.argmax(off > 1e-6))
                raise CompgenError(f"{label}: pose {i + 1} puts {a.name} at {deg[i, k]:.4f} deg, between the "
                                   f"teeth of its Hirth coupling ({a.hirth_deg:g} deg grid)",
                                   hint=f"round {a.name} to its grid (compgen's paths are written on it)")


def _program_header(machine: Machine, ctl: Controller, poses: Poses, label: str, mode: str, list_name: str,
                    nest: float | None, file_nest: float, safe: float, version: str, date: str,
                    notes: tuple[str, ...]) -> list[str]:
    """A measurement program's header: what it is, its mode, its poses and ball, the nest,
    the preset, feeds and heights, the travel checked, and how to run it the first time."""
    setup, fmt, ball = machine.program, ctl.number, poses.ball[0]
    linear = [machine.index(c) for c in "XYZ"]
    rotary = [machine.index(a.name) for a in machine.rotary_axes]
    span = {c: (poses.q[:, j].min(), poses.q[:, j].max()) for c, j in zip("XYZ", linear, strict=True)}
    return [
        f"compgen {version} R-test measurement program, {date}",
        f"machine: {ascii_text(machine.name)}; controller: {ctl.label(machine)}",
        (f"mode TCPM: {ctl.tcp_label(machine)}, the control's kinematics moves X Y Z (tests the control)"
         if mode == "tcpm" else
         "mode AXES: X Y Z from compgen's inverse kinematics (tests compgen's nominal model)"),
        f"path {ascii_text(label)}: {len(poses)} poses; pose list "
        f"{ascii_text(list_name)}.poses.csv, same order",
        f"{BALL_HEADER} "
        + " ".join(f"{c}{fmt(v, LINEAR_DECIMALS)}" for c, v in zip("XYZ", ball, strict=True))
        + f" mm; nest on tool {setup.tool}"
        + (f", {fmt(nest, LINEAR_DECIMALS)} {NEST_HEADER} (not the machine file's {file_nest:g} mm: "
           "the tool's length must say so)" if nest is not None and nest != file_nest else ""),
        "active preset: the machine file's origin (nominal intersection of the rotary axes)",
        f"feed {setup.feed:g} mm/min; dwell {setup.dwell:g} s per pose; clearance "
        f"{setup.clearance:g} mm; safe height Z {safe:g} mm above the rotary axes (from the set-up)",
        "travel checked: " + ", ".join(f"{c} {lo:.3f}..{hi:.3f}" for c, (lo, hi) in span.items())
        + " mm; " + ", ".join(f"{a.name} {np.degrees(poses.q[:, j].min()):.3f}.."
                              f"{np.degrees(poses.q[:, j].max()):.3f}"
                              for a, j in zip(machine.rotary_axes, rotary, strict=True)) + " deg",
        "rotary axes turn only at the safe height; the nest moves onto and off the ball along its axis",
        *([f"head: {ctl.tcp_words} on from the first turn to the last; the control's kinematics must place "
           f"{' and '.join(a.name for a in machine.heads)} as the machine file does (this program cannot "
           "read them), the nest's length in the tool table (U22)"] if machine.heads and ctl.tcp_switchable
          else []),
        *[f"{a.name} is inclined: it turns about {a.unit_text}, as the control's "
          "kinematics must hold it" for a in machine.rotary_axes if a.inclined],
        *[f"{a.name} is Hirth-coupled ({a.hirth_deg:g} deg grid): every position on it; the nest leaves the "
          f"ball before {a.name} indexes, the control releases and clamps it (U23)"
          for a in machine.hirth_axes],
        *plc_lines(machine, ctl, "nest"),
        "first run: single block, feed override low, nest and ball clear of clamps",
        *(ascii_text(n) for n in notes),
    ]

ROT = set("ABC")
# The programs trust the active preset; before the nest first goes down, the operator sees
# that the ball is where the preset puts it (one line, no ";" or parentheses, under the 124
# characters a SINUMERIK message shows: every control shows it as a message)
PRESET_CHECK = ("PRESET CHECK: the nest is {clearance} mm above the ball centre and the ball must be "
                "centred under it. Start to go on")
HEAD_PRESET_CHECK = ("PRESET CHECK: the nest is {clearance} mm off the ball centre along its axis, the "
                     "ball centred on that axis. Start to go on")
TURN_STEP_DEG = 2.0     # rotary steps at the safe height under TCP: the nest keeps within 0.1 mm


def _steps(machine: Machine, poses: Poses, segments, mode: str, switchable: bool, safe: float,
           clearance: float, label: str) -> list[dict]:
    """The program as steps any control's template lays out: rapid and feed moves (axis →
    mm or deg), TCP on and off, dwells, pose markers.

    Rotary axes turn only with the nest at ``safe`` above their intersection; the nest goes
    onto and off the ball along its own axis. On a table machine, a control that switches
    TCP in the program does all this with TCP off, in machine axes, and switches it on for
    each run's poses; one whose TCP is its configuration (LinuxCNC's kinematics modules)
    gets every point in TCP coordinates, with turns in small steps so that the nest stays
    where it is. A head's program runs under TCP throughout on every control (off it, the
    tool length of a tilted head is not along the axis a move names): the switching control
    lifts the nest and turns the rotary axes to zero at the safe height with TCP off, then
    switches it on once, and off at the end.
    """
    w = _Steps(machine, mode == "tcpm" and (not switchable or bool(machine.heads)), safe, clearance,
               switches=switchable and mode == "tcpm")
    w.start()
    for seg in segments:
        w.segment(poses, seg, mode, label, first_segment=seg is segments[0])
    return w.finish()


class _Steps:
    """The steps being laid out, and where the nest stands after the last (``q``)."""

    def __init__(self, machine: Machine, tcp_always: bool, safe: float, clearance: float, switches: bool):
        self.machine, self.tcp_always, self.safe = machine, tcp_always, safe
        self.switches = switches          # the program switches TCP on and off itself
        self.linear = [machine.index(c) for c in "XYZ"]
        self.rotary = [machine.index(a.name) for a in machine.rotary_axes]
        self.names = [a.name for a in machine.rotary_axes]
        self.steps: list[dict] = []
        self.q = None
        # a head tilts the nest's axis: off the ball along it, the housing's end must clear the
        # ball before the nest moves across its axis (a tool that never tilts only goes up)
        s = machine.setup
        self.approach = max(clearance, s.nest_below + s.ball_diameter / 2 + s.nest_radius + s.margin) \
            if machine.heads else clearance
        self.origin = np.zeros(len(machine.axes))
        self.origin[self.linear[2]] = safe

    def at(self, q, rapid=True, note="", pose=None, tcp=None):
        """A move to the machine pose ``q`` (nest centre), written in the active frame (TCP
        coordinates are filled in at the end, all at once)."""
        tcp = self.tcp_always if tcp is None else tcp
        axes = {**dict(zip("XYZ", q[self.linear], strict=True)),
                **{n: np.degrees(q[i]) for n, i in zip(self.names, self.rotary, strict=True)}}
        for a in index_steps(self.machine, self.steps, self.q, axes):
            del axes[a]
        self.steps.append({"kind": "rapid" if rapid else "feed", "axes": axes, "note": note, "pose": pose,
                           "q": q if tcp else None})
        self.q = q

    def lifted(self, q, z):          # the nest at height z, the rotary axes held
        return at_height(self.machine, q[None], z)[0]

    def off(self, q):                # the nest off the ball along its own axis
        return along_tool(self.machine, q[None], self.approach)[0]

    def turn_to(self, target):
        """At the safe height: turn the rotary axes to ``target``'s, the nest kept in place."""
        turn = held_turn(self.machine, self.q, target, self.tcp_always)
        for k, step in enumerate(turn, 1):
            self.at(step, note="turn at the safe height" if k == len(turn) else "")

    def start(self) -> None:
        if self.tcp_always and not self.switches:   # TCP coordinates equal machine ones only with
            self.steps.append({"kind": "require_zero", "axes": {}})     # the rotary axes at zero
        self.steps.append({"kind": "rapid", "axes": {"Z": self.safe},
                           "note": "nest up along its axis to the safe height"})
        self.q = self.origin.copy()
        self.q[self.linear[:2]] = np.nan
        self.q[[self.machine.index(a.name) for a in self.machine.plc_axes]] = np.nan   # not known: indexed
        if self.tcp_always and self.switches:       # a head under a switching control's TCP
            self.steps.append({"kind": "rapid", "axes": dict.fromkeys(self.names, 0.0),
                               "note": "rotary axes to zero at the safe height"})
            self.steps.append({"kind": "tcp_on"})
        if self.tcp_always:
            self.at(self.origin, note="above the rotary axes")

    def segment(self, poses: Poses, seg, mode: str, label: str, first_segment: bool) -> None:
        """One run of one path: approached from its declared sides, the nest onto the ball,
        each pose with its dwell, and off it."""
        machine, rotary, linear, steps = self.machine, self.rotary, self.linear, self.steps
        first, last = poses.q[seg[0]], poses.q[seg[-1]]
        steps.append({"kind": "comment", "note": f"---- {ascii_text(str(poses.path[seg[0]]) or label)}: "
                                                 f"poses {seg[0] + 1} to {seg[-1] + 1}"})
        # every rotary axis reaches the first pose from the side the pose list declares
        # (sides.program_sides): where each axis's backlash is at every pose is known
        before = first.copy()
        # (a Hirth axis has no backlash to take up: its teeth place it, and it rests only on them)
        # (nor one the PLC positions: the NC does not choose the side it comes from)
        loose = np.array([a not in machine.at_rest_axes for a in machine.rotary_axes])
        before[rotary] -= poses.side[seg[0], rotary] * np.radians(APPROACH_DEG) * loose
        for target, note in ((before, f"approach from {APPROACH_DEG:g} deg before"), (first, "")):
            if not np.isnan(self.q[linear[:2]]).any():
                self.turn_to(target)
            else:                        # XY not yet known: turn in place at the safe height
                turn = {n: np.degrees(target[i]) for n, i in zip(self.names, rotary, strict=True)}
                for a in index_steps(machine, steps, self.q, turn):
                    del turn[a]
                if turn:
                    steps.append({"kind": "rapid", "axes": turn, "note": note or "turn at the safe height"})
                self.q = self.q.copy()
                self.q[rotary] = target[rotary]
        self.at(self.lifted(self.off(first), self.safe), note="above the first pose")
        self.at(self.off(first))
        if first_segment:      # the preset and the ball, seen before the nest goes down
            steps.append({"kind": "stop", "note": (HEAD_PRESET_CHECK if machine.heads else PRESET_CHECK)
                          .format(clearance=f"{self.approach:g}")})
        self.at(first, rapid=False, note="nest onto the ball, along its axis")
        each_run = self.switches and not self.tcp_always      # TCP on for the poses alone
        if each_run:
            steps.append({"kind": "tcp_on"})
        hirth = [machine.index(a.name) for a in machine.hirth_axes]
        for k, i in enumerate(seg):
            if k and hirth and (poses.q[i, hirth] != poses.q[seg[k - 1], hirth]).any():
                # a Hirth axis is lifted out of its teeth to index (U23): the nest off the ball first
                self.at(self.off(poses.q[seg[k - 1]]), rapid=False, tcp=mode == "tcpm",
                        note="nest off the ball: a Hirth axis indexes")
                self.at(self.off(poses.q[i]), tcp=mode == "tcpm")
            self.at(poses.q[i], rapid=False, pose=f"pose {i + 1} {ascii_text(str(poses.path[i]))}",
                    tcp=mode == "tcpm")    # the ball centre in TCP coordinates
            steps.append({"kind": "dwell"})
        if each_run:
            steps.append({"kind": "tcp_off"})
        self.at(self.off(last), rapid=False, note="nest off the ball, along its axis")
        self.at(self.lifted(self.off(last), self.safe))
        if self.tcp_always:
            above = last.copy()
            above[linear] = self.origin[linear]
            self.at(above, note="above the rotary axes")

    def finish(self) -> list[dict]:
        """The rotary axes back to zero under TCP, and every TCP point in TCP coordinates."""
        if self.tcp_always:
            zero = self.q.copy()
            zero[self.rotary] = 0.0
            self.turn_to(zero)
            if self.switches:
                self.steps.append({"kind": "tcp_off"})
        tcp = [s for s in self.steps if s.get("q") is not None]
        if tcp:
            xyz = world(self.machine, np.array([s["q"] for s in tcp]))
            for s, w in zip(tcp, xyz, strict=True):
                s["axes"].update(zip("XYZ", w, strict=True))
        return self.steps


def pose_list(machine: Machine, poses: Poses) -> str:
    """CSV v1 columns without readings: add dX dY dZ from the R-test and it is fit input.
    Each rotary axis's side at each pose (``A_side``: the direction it last moved, as the
    program runs the poses) tells fit where its backlash was; ``probe_length``, where the
    session's nest is not the machine file's, its length (``machine`` is the one at that nest)."""
    # a side is +1 or -1, or its column is left out (a probing program's poses have none): the
    # readers take nothing else, as format_rtest writes them
    sides = {name: machine.index(axis) for name, axis in side_columns(machine).items()
             if not np.isnan(poses.side[:, machine.index(axis)]).any()}
    nest = not np.isnan(poses.nest).all()
    head = ["path", *machine.axis_names, *BALL, *[NEST] * nest, *sides]
    lines = [",".join(head)]
    for i in range(len(poses)):
        lines.append(",".join([ascii_text(str(poses.path[i])), *axis_cells(machine, poses.q[i]),
                               *(f"{v:.6f}" for v in poses.ball[i]),
                               *[f"{machine.probe_length:.6f}"] * nest,
                               *(f"{poses.side[i, j]:+.0f}" for j in sides.values())]))
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


def _check_feed(machine: Machine, poses: Poses, feed: float, label: str, mode: str) -> None:
    """The axes' speeds between poses at the program's feed. In TCPM mode a pose block keeps
    the nest where it is in the workpiece and only turns: F is then deg/min (U9), whatever
    the linear axes do beneath; in axes mode F is along X Y Z, and a turn rides on it."""
    for a in machine.axes:
        if not a.rotary and feed > a.feed_max:
            raise CompgenError(f"[program] feed {feed:g} mm/min exceeds {a.name}'s feed_max {a.feed_max:g}")
    if mode == "tcpm":
        for a in machine.rotary_axes:
            if feed > a.feed_max:
                raise CompgenError(f"[program] feed {feed:g} (deg/min where a TCPM pose block only turns) "
                                   f"exceeds {a.name}'s feed_max {a.feed_max:g}", hint="lower [program] feed")
        return
    linear = [machine.index(c) for c in "XYZ"]
    rotary = [machine.index(a.name) for a in machine.rotary_axes]
    turns = np.abs(np.diff(np.degrees(poses.q[:, rotary]), axis=0))
    minutes = motion.feed_minutes(np.linalg.norm(np.diff(poses.q[:, linear], axis=0), axis=1),
                                  turns.max(axis=1, initial=0.0), feed)
    for k, a in enumerate(machine.rotary_axes):
        with np.errstate(divide="ignore", invalid="ignore"):    # no move at all: no speed
            speed = np.where(turns[:, k] > 0, turns[:, k] / minutes, 0.0)
        if speed.size and speed.max() > a.feed_max * motion.OVER_FEED:
            i = int(speed.argmax())
            raise CompgenError(f"{label}: at feed {feed:g} mm/min, {a.name} would turn at "
                               f"{speed[i]:.0f} deg/min between poses {i + 1} and {i + 2}, above "
                               f"its feed_max {a.feed_max:g}", hint="lower [program] feed, or measure in "
                               "tcpm mode (a pose block then only turns, at F deg/min)")


def read_program(text: str, machine: Machine, controller_name: str) -> tuple[str, np.ndarray, np.ndarray]:
    """Parse an emitted program back: (mode, X Y Z per pose (n, 3) mm, rotary (n, r) deg).

    In TCPM mode X Y Z are workpiece coordinates; in axes mode machine-axis positions.
    """
    ctl = for_machine(controller_name, machine)
    tcpm = ctl.tcpm_on.search(text) is not None
    xyz, rot, numbers = [], [], []
    names = [a.name for a in machine.rotary_axes]
    for line in text.splitlines():
        m = ctl.pose_line.match(line)
        if not m:
            continue
        sense = ctl.angle_sense(machine)
        words = {w[0]: sense.get(w[0], 1) * number(re.sub(r"^=(?:ACP|ACN|DC)\((.*)\)$", r"\1", w[1:]),
                                                   f"pose {m[5]}'s {w[0]}", "program")
                 for w in m[4].split()}
        if sorted(words) != sorted(names):
            raise CompgenError(f"pose {m[5]} names rotary axes {sorted(words)}, the machine {names}")
        xyz.append([number(m[i], f"pose {m[5]}'s {'XYZ'[i - 1]}", "program") for i in (1, 2, 3)])
        rot.append([words[a] for a in names])
        numbers.append(int(m[5]))
    if not xyz:
        raise CompgenError("no pose blocks found: not a compgen measurement program")
    if numbers != list(range(1, len(numbers) + 1)):
        raise CompgenError("pose numbers are not 1, 2, 3, …: the program was edited")
    return ("tcpm" if tcpm else "axes"), np.array(xyz), np.array(rot)
