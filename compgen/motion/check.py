"""What a program makes the machine do, block by block, against the R-test set-up.

Each controller module turns its program text into ``Block``s with the control's own
meaning of each word (machine or workpiece coordinates, TCP on or off, tool and length
compensation, dwell, feed). This module moves the machine model through them, sampled at
≤ 1 mm and ≤ 0.5°, and reports what would hit: the nest housing or the spindle entering the
ball, its stem or the table; an axis leaving its travel (between blocks too); a feed above
an axis's ``feed_max``; motion without the tool called and its length compensated.

Geometry (table frame, mm): the ball a sphere; the stem a cylinder from the table top to the
ball; the table a disc about the last rotary axis; the nest housing and the spindle spheres
along the tool axis (a capsule each, conservative at their ends). The nest may surround
the ball and stem where it measures: while its axis passes within ``nest_range`` of the
ball's centre (the measuring poses and the straight approach along the nest's axis).

Positions are compgen's: the preset at the nominal intersection of the rotary axes, X Y Z
of the nest centre with the tool length compensated. A block in machine coordinates (M91,
SUPA, G53) cannot be placed against the set-up, since no machine file says where the
machine datum lies; it is a finding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CompgenError
from ..model.frames import frames, from_world, head_pivots, safe_height, world
from ..model.machine import Machine, ProbeSetup
from ..search import golden_least
from .blocks import Block

STEP_MM, STEP_DEG = 1.0, 0.5
SEARCH_MM = 0.01         # the closest point along housing and spindle axes, found to this
TOUCH_MM = 1e-3          # a probing stylus tip this far into the sphere: rounding, not a crash
ONLY_TURNS_MM = 1e-9     # X Y Z travel at or below this (rounding): the block only turns
OVER_FEED = 1 + 1e-9     # a speed this much over feed_max is rounding of the feed, not over it


@dataclass(frozen=True)
class Finding:
    """What the motion check found at a program line: the rule broken, in words, the axes'
    positions there, and how deep a part enters a solid (0: not a collision)."""

    line: int
    rule: str
    detail: str
    axes: str
    depth_mm: float = 0.0        # how far a part enters a solid; 0: the finding is not a collision

    def text(self, where: str) -> str:
        depth = f" by {self.depth_mm:.1f} mm" if self.depth_mm > 0 else ""
        return f"{where}:{self.line}: {self.rule}{depth}: {self.detail} (at {self.axes})"


@dataclass(frozen=True)
class Check:
    """A program moved through the set-up: its blocks, its time (s), the closest approach of
    the moving parts outside the measuring exemption (mm, and where), and every finding."""

    blocks: int
    seconds: float
    closest_mm: float            # smallest clearance outside the measuring exemption
    closest_at: str
    findings: tuple[Finding, ...]

    def first(self, where: str) -> str:
        """The first finding's text, and how many more there are."""
        more = len(self.findings) - 1
        return self.findings[0].text(where) + (f" (and {more} more)" if more else "")


def tooling(machine: Machine,
            probe: ProbeSetup | None = None) -> dict[str, tuple[float, float, float, float]]:
    """The parts of what the spindle holds, along the tool axis from the tool point (nest or
    stylus tip centre), mm: part → (from, to, radius, margin kept to the set-up). A probe's
    stylus comes within a few mm of the sphere by design: its parts keep ``[probe] margin``."""
    s = machine.setup
    if probe is None:
        return {"housing": (-s.nest_below, machine.probe_length, s.nest_radius, s.margin),
                "spindle": (machine.probe_length, machine.probe_length + s.spindle_length, s.spindle_radius,
                            s.margin)}
    tip = probe.stylus_diameter / 2
    return {"stylus tip": (0.0, 0.0, tip, probe.margin),
            "stylus": (tip, probe.stylus_length, probe.shaft_diameter / 2, probe.margin),
            "probe body": (probe.stylus_length, probe.length, probe.body_diameter / 2, s.margin),
            "spindle": (probe.length, probe.length + s.spindle_length, s.spindle_radius, s.margin)}


def clearances(machine: Machine, q: np.ndarray,
               probe: ProbeSetup | None = None) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Per pose: the clearance (mm, negative = inside) of each pair (housing or spindle
    against ball, stem, table), and whether the nest is measuring there (its axis within
    ``nest_range`` of the ball's centre, the nest on the ball or above it).

    Housing and spindle are capsules about the tool axis. Ball and stem (a point and a
    segment, each with a radius) are at the least distance of two segments, in closed form;
    the table is a convex solid, so the signed distance from it is convex along the axis:
    its least value over the part is found by golden-section search, to ``SEARCH_MM``."""
    s = machine.setup
    _, nest, axis = frames(machine, q)                                      # table frame
    ball = np.asarray(machine.ball)
    rb = s.ball_diameter / 2
    stem_top = ball[2] - rb
    top, bottom = s.table_top, s.table_top - s.table_thickness

    def to_table(p):
        radial, z = np.hypot(p[..., 0], p[..., 1]), p[..., 2]
        dz = np.maximum(np.maximum(z - top, bottom - z), 0.0)
        dr = np.maximum(radial - s.table_radius, 0.0)
        depth = np.minimum(np.minimum(top - z, z - bottom), s.table_radius - radial)
        return np.where((dz == 0) & (dr == 0), -depth, np.hypot(dz, dr))

    stem = (np.array([ball[0], ball[1], top]), np.array([ball[0], ball[1], stem_top]))
    out = {}
    for part, (lo, hi, radius, _) in tooling(machine, probe).items():
        start, end = nest + lo * axis, nest + hi * axis
        out[f"{part} / ball"] = _to_segment(start, end, ball, ball) - rb - radius
        out[f"{part} / stem"] = _to_segment(start, end, *stem) - s.stem_diameter / 2 - radius
        out[f"{part} / table"] = _least_along(to_table, nest, axis, lo, hi) - radius
    if machine.heads:       # the head's body about each pivot: it swings as the head turns
        if not s.head_radius:
            raise CompgenError("the head's body is not in the machine file: the motion check cannot see "
                               "what the head sweeps", where=f"{machine.source}: [rtest] head_radius",
                               hint="give head_radius, mm: a sphere about its pivot that holds its body")
        for k, pivot in enumerate(np.moveaxis(head_pivots(machine, q), 1, 0)):
            part = f"head {machine.heads[k].name}"
            out[f"{part} / ball"] = np.linalg.norm(pivot - ball, axis=1) - rb - s.head_radius
            out[f"{part} / stem"] = _to_segment(pivot, pivot, *stem) - s.stem_diameter / 2 - s.head_radius
            out[f"{part} / table"] = to_table(pivot) - s.head_radius
    off_axis = np.linalg.norm(np.cross(ball - nest, axis), axis=1)
    above = np.einsum("ni,ni->n", nest - ball, axis) > -s.nest_range
    return out, (off_axis <= s.nest_range) & above


def _to_segment(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Per row, the distance between the segments p0–p1 (n, 3) and q0–q1 (3,; a point if
    q0 = q1), in closed form (Ericson, Real-Time Collision Detection, 5.1.9): the closest
    pair's parameters, each clamped to its segment in turn."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e = np.einsum("ni,ni->n", d1, d1), float(d2 @ d2)
    b, c, f = d1 @ d2, np.einsum("ni,ni->n", d1, r), r @ d2
    denom = a * e - b * b
    a_ = np.where(a > 0, a, 1.0)          # p a point (a stylus tip): u = 0 wherever it is divided
    if e == 0:                                               # q is a point
        u, t = np.clip(-c / a_, 0, 1), np.zeros_like(a)
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            # parallel (denom 0): any point of p's segment will do before t is clamped
            u = np.where(denom > 1e-12 * a * e, np.clip((b * f - c * e) / denom, 0, 1), 0.0)
        t = (b * u + f) / e
        u = np.where(t < 0, np.clip(-c / a_, 0, 1), np.where(t > 1, np.clip((b - c) / a_, 0, 1), u))
        t = np.clip(t, 0, 1)
    return np.linalg.norm(r + u[:, None] * d1 - t[:, None] * d2, axis=1)


def _least_along(dist, nest: np.ndarray, axis: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """The least of a convex ``dist`` over the points ``nest + t·axis``, lo ≤ t ≤ hi, per pose."""
    n = len(nest)
    return golden_least(lambda t: dist(nest + t[:, None] * axis), np.full(n, lo), np.full(n, hi),
                        SEARCH_MM)[1]


@dataclass
class _Segment:
    block: Block
    tcp: bool
    start: np.ndarray        # machine pose (axes mode) or TCP xyz + rotary (rad)
    end: np.ndarray
    blind: bool              # some axis came from an unknown place
    probing: bool = False    # a probing move, or the retract from its touch
    path: np.ndarray | None = None


def run(machine: Machine, blocks: list[Block], modulo: tuple[str, ...] = (),
        sense: dict[str, int] | None = None, probe: ProbeSetup | None = None) -> Check:
    """Move the machine model through ``blocks`` and check every sample. The blocks are
    walked once to find each move's ends (TCP moves in TCP coordinates); the samples of
    all moves are then converted and checked together. ``modulo``: the rotary axes the
    control positions modulo 360° (``Controller.modulo_axes``); ``sense``: per rotary axis,
    ±1, how the control's words turn it against the machine file (``Controller.angle_sense``).
    ``probe``: the program holds probing moves made with this probe (the machine's set-up
    ball is its sphere); each stops where the stylus tip meets the sphere."""
    walk = _Walk(machine, modulo, sense or {}, probe)
    _frame(machine, blocks)
    walk.through(blocks)
    return _checked(machine, walk.segments, walk.seconds, walk.findings, probe)


class _Walk:
    """The blocks walked once: where each move starts and ends (a machine pose, or TCP
    coordinates while TCP is on and known), the dwells' time, and what is found on the way."""

    def __init__(self, machine: Machine, modulo: tuple[str, ...], sense: dict[str, int],
                 probe: ProbeSetup | None):
        self.machine, self.modulo, self.sense, self.probe = machine, modulo, sense, probe
        self.linear = [machine.index(c) for c in "XYZ"]
        self.rotary = [machine.index(a.name) for a in machine.rotary_axes]
        self.letters = {a.name: machine.index(a.name) for a in machine.axes}
        self.q = np.full(len(machine.axes), np.nan)   # machine pose; under TCP, valid only where w is None
        self.w = None                  # TCP coordinates while TCP is on and known
        self.tcp = self.tool = self.length = False
        self.seconds, self.findings, self.segments = 0.0, [], []

    def sensed(self, letter: str, v: float) -> float:     # a word's angle as the machine file turns it
        return -v if self.sense.get(letter) == -1 else v

    def settle(self) -> None:          # the machine pose behind the TCP coordinates
        if self.w is not None:
            self.q = from_world(self.machine, self.w[None, :3], self.w[None, 3:])[0]

    def through(self, blocks: list[Block]) -> None:
        """Every block in order; a move the check cannot place ends the walk (its finding said)."""
        for b in blocks:
            if b.kind == "require":      # the program stops unless these axes are at these values
                self.settle()
                self.w = None
                missing = sorted(set(b.target) - set(self.letters))
                if missing:
                    raise CompgenError(f"line {b.line}: the guard reads {', '.join(missing)}, which this "
                                       "machine lacks", hint="the program was written for another machine")
                for letter, v in b.target.items():
                    i = self.letters[letter]
                    self.q[i] = np.radians(self.sensed(letter, v)) if i in self.rotary else v
            elif b.kind == "tcp":
                self.settle()
                self.w, self.tcp = None, b.on
            elif b.kind == "tool":
                self.tool = True
            elif b.kind == "length":
                self.length = b.on
            elif b.kind == "dwell":
                self.seconds += b.seconds
            if b.kind == "move" and not self.move(b):
                break

    def move(self, b: Block) -> bool:
        """One move's segment; False where the walk cannot go on from it."""
        if not self.plc_holds(b):
            return False
        q, linear, rotary = self.q, self.linear, self.rotary
        if b.machine_coords:
            self.findings.append(Finding(b.line, "machine coordinates", "the machine file does not say where "
                                         "the machine datum lies against the set-up: this move cannot be "
                                         "checked", b.text.strip()))
            return True
        if not (self.tool and self.length):
            self.findings.append(Finding(b.line, "no tool call or length compensation", "the nest's length "
                                         "is not active: every position would be off by its length",
                                         b.text.strip()))
            return False
        unknown_axes = sorted(set(b.target) - set(self.letters))
        if unknown_axes:
            raise CompgenError(f"line {b.line} moves {', '.join(unknown_axes)}, which this machine lacks")
        # with the rotary axes at zero, TCP coordinates are machine coordinates
        zero_turn = self.w is None and not np.isnan(q[rotary]).any() and not q[rotary].any()
        if self.tcp and not (zero_turn and np.isnan(q[linear]).any()):
            return self.tcp_move(b)
        self.settle()
        q, self.w = self.q, None
        end = q.copy()
        for letter, v in b.target.items():
            i = self.letters[letter]
            end[i] = (np.radians(_turned(self.modulo, b, letter, self.sensed(letter, v), np.degrees(q[i])))
                      if i in rotary else v)
        if b.probe:
            end = _touch(self.machine, self.probe, b, q, end, self.findings)
            if end is None:
                return False
        after_touch = bool(self.segments) and self.segments[-1].block.probe
        self.segments.append(_Segment(b, False, q, end, bool((np.isnan(q) & ~np.isnan(end)).any()),
                                      probing=b.probe or after_touch))
        self.q = end
        return True

    def plc_holds(self, b: Block) -> bool:
        """An axis the PLC positions turns only by its M-function (never an NC word), with TCP
        off (the control does not hold the nest while the PLC turns it) (U26)."""
        if not (b.plc or self.machine.plc_axes):        # every move of every program: nothing to hold
            return True
        axes = {a.name: a for a in self.machine.rotary_axes}
        for letter in b.target:
            a = axes.get(letter)
            if b.plc and (a is None or a.m_function is None or b.name not in ("", f"M{a.m_function}")):
                self.findings.append(Finding(b.line, "not the axis's M-function",
                                             f"{b.name or 'the stop'} turns {letter}, which the machine file "
                                             f"does not position by {b.name or 'an M-function'}",
                                             b.text.strip()))
                return False
            if not b.plc and a is not None and a.m_function is not None:
                self.findings.append(Finding(b.line, "an NC move of an axis the PLC positions",
                                             f"{letter} is turned by the OEM's M-function M{a.m_function}, "
                                             "not by the NC", b.text.strip()))
                return False
        if b.plc and self.tcp:
            self.findings.append(Finding(b.line, "the PLC turns an axis under TCP", "the control does not "
                                         "hold the nest while the PLC turns the axis", b.text.strip()))
            return False
        return True

    def tcp_move(self, b: Block) -> bool:
        """A move in TCP coordinates (its ends in TCP xyz and the rotary axes); a probing move
        (a head's, under TCP) stops where the stylus tip meets the sphere."""
        if self.w is None:
            if np.isnan(self.q).any():
                self.findings.append(Finding(b.line, "TCP before positioning", "TCP is on before every axis "
                                             "has been positioned", b.text.strip()))
                return False
            self.w = np.concatenate([world(self.machine, self.q[None])[0], self.q[self.rotary]])
        w, end = self.w, self.w.copy()
        for letter, v in b.target.items():
            i = self.letters[letter]
            if i in self.linear:
                end[self.linear.index(i)] = v
            else:
                now = w[3 + self.rotary.index(i)]
                v = _turned(self.modulo, b, letter, self.sensed(letter, v), np.degrees(now))
                end[3 + self.rotary.index(i)] = np.radians(v)
        if b.probe:       # where it stops: found on the machine poses, given back in TCP coordinates
            m = self.machine
            ends = from_world(m, np.array([w[:3], end[:3]]), np.array([w[3:], end[3:]]))
            stop = _touch(m, self.probe, b, ends[0], ends[1], self.findings)
            if stop is None:
                return False
            end = np.concatenate([world(m, stop[None])[0], stop[self.rotary]])
        after_touch = bool(self.segments) and self.segments[-1].block.probe
        self.segments.append(_Segment(b, True, w, end, False, probing=b.probe or after_touch))
        self.w = end
        return True


def _checked(machine: Machine, segments: list[_Segment], seconds: float, findings: list[Finding],
             probe: ProbeSetup | None) -> Check:
    """The segments sampled and checked together: travel, feeds and time, moves from
    unknown places, and every collision; the closest approach."""
    linear = [machine.index(c) for c in "XYZ"]
    rotary = [machine.index(a.name) for a in machine.rotary_axes]
    safe = safe_height(machine)
    _paths(machine, segments, linear, rotary)
    closest = (np.inf, "")
    checkable = []
    moved, fastest, outside = _per_segment(machine, segments)
    took_s = _seconds(machine, segments, moved, fastest, linear, rotary, findings)
    for seg, took, out in zip(segments, took_s, outside, strict=True):
        b, path = seg.block, seg.path
        seconds += took
        if out.any():
            _check_travel(machine, b, path, out, findings)
        # an axis whose start is unknown (the program's first moves) is safe only where
        # nothing can be touched: at the safe height
        if seg.blind or np.isnan(path).any():
            z = path[:, linear[2]]
            if np.isnan(z).any() or z.min() < safe:
                findings.append(Finding(b.line, "axes positioned from an unknown place below the safe height",
                                        f"the nest is below Z {safe:g} before every axis has been positioned "
                                        "there", b.text.strip()))
            # the moves after it start from known places: they are checked all the same
        else:
            checkable.append(seg)
    if checkable:
        closest = _check_collisions(machine, checkable, findings, probe)
    findings.sort(key=lambda f: f.line)
    return Check(len(segments), seconds, closest[0], closest[1], tuple(findings))


def _touch(machine: Machine, probe: ProbeSetup | None, b: Block, q: np.ndarray, end: np.ndarray,
           findings: list) -> np.ndarray | None:
    """Where a probing move stops: the first point where the stylus tip meets the sphere
    (the set-up's ball) on the way from ``q`` to ``end``; None, with a finding, if it never
    does (the control stops the program with an error) or starts inside it."""
    if probe is None:
        raise CompgenError(f"line {b.line}: a probing move, and the machine file has no [probe]",
                           hint="describe the probe in [probe] (see the bundled machines)")
    if np.isnan(q).any():
        findings.append(Finding(b.line, "probing from an unknown place", "an axis has not been positioned "
                                "before the probing move", b.text.strip()))
        return None
    _, ends, _ = frames(machine, np.array([q, end]))
    ball = np.asarray(machine.ball)
    rho = (machine.setup.ball_diameter + probe.stylus_diameter) / 2
    p0, d = ends[0] - ball, ends[1] - ends[0]
    a, half_b, c = d @ d, p0 @ d, p0 @ p0 - rho**2
    disc = half_b**2 - a * c
    t = (-half_b - np.sqrt(disc)) / a if a > 0 and disc >= 0 else np.nan    # NaN: its line passes by
    if c < 0 or not 0 <= t <= 1:
        what = ("starts inside the sphere" if c < 0 else
                f"ends {np.sqrt(max(c + 2 * half_b + a, 0.0) + rho**2) - rho:.2f} mm short of it" if t > 1
                else "misses it")
        findings.append(Finding(b.line, "probing move does not touch the sphere",
                                f"the stylus tip {what}; the "
                                "control stops the program with an error", b.text.strip()))
        return None
    return q + t * (end - q)


def _frame(machine: Machine, blocks: list[Block]) -> None:
    """What a program must say for its moves to mean what the check takes them to: its unit
    (mm) before the first move, the machine file's work offset, an end, nothing after it."""
    units = ended = moves = False
    for b in blocks:
        if ended:
            raise CompgenError(f"line {b.line}: {b.text.strip()!r} after the program's end", hint="a control "
                               "does not run it; a program with blocks after its end was edited")
        if b.kind == "units":
            units = True
        elif b.kind == "end":
            ended = True
        elif b.kind == "offset" and b.name != machine.program.work_offset:
            raise CompgenError(f"line {b.line}: {b.text.strip()!r} selects {b.name}; the machine file's work "
                               f"offset is {machine.program.work_offset}", hint="compgen's positions are in "
                               "the machine file's work offset ([program] work_offset)")
        elif b.kind == "move":
            moves = True
            if not units:
                raise CompgenError(f"line {b.line}: a move before the program says its unit (mm)",
                                   hint="check-program reads programs in millimetres that say so, as compgen "
                                        "writes them")
    if not moves:
        raise CompgenError("the program has no move: there is nothing to check",
                           hint="give the program compgen wrote")
    if not ended:
        raise CompgenError("the program has no end block (END PGM, M30 or M2): it may have been cut short",
                           hint="give the whole program")


def _turned(modulo: tuple[str, ...], b: Block, letter: str, value: float, now: float) -> float:
    """Where a rotary axis ends (deg, unwrapped) for the written ``value``. An axis the
    control positions modulo 360° goes to ``value`` mod 360 the way the block says — "+" and
    "-" turn that way, "short" the shorter way — from where it is (``now``, NaN: unknown, then
    to the value itself). A plain word on such an axis turns the way the control's machine
    data say: not modelled, refused."""
    if letter not in modulo:
        if letter in b.turn:
            raise CompgenError(f"line {b.line}: {b.text.strip()!r} turns {letter} as a modulo axis; the "
                               f"machine file does not declare {letter} modulo",
                               hint="declare it in the control's section of the machine file (modulo), "
                                    "or write a plain position")
        return value
    ahead = (value - now) % 360.0
    if min(ahead, 360.0 - ahead) < 1e-6:    # where it is (to rounding): no turn
        ahead = 0.0
    if letter not in b.turn:
        if ahead == 0.0:                   # where it is: no turn, whichever way the data say
            return now
        raise CompgenError(f"line {b.line}: {b.text.strip()!r}: {letter} is a 360° modulo axis, and a plain "
                           f"position turns it the way the control's machine data say: not checked",
                           hint="write the direction in the block (e.g. SINUMERIK ACP, ACN or DC)")
    if np.isnan(now):
        return value % 360.0
    how = b.turn[letter]
    if how == "+":
        return now + ahead
    if how == "-":
        return now - (360.0 - ahead) % 360.0
    return now + (ahead - 360.0 if ahead > 180.0 else ahead)


def _paths(machine: Machine, segments: list[_Segment], linear, rotary) -> None:
    """Every move's samples (≤ 1 mm, ≤ 0.5°) as machine poses; TCP moves interpolate in TCP
    coordinates and are converted together. All moves of a kind at once: a program is
    hundreds of short moves, and a move at a time was a sixth of the check."""
    for tcp in (True, False):
        own = [seg for seg in segments if seg.tcp == tcp]
        if not own:
            continue
        start, end = np.array([seg.start for seg in own]), np.array([seg.end for seg in own])
        unknown = np.isnan(start)                # an axis not positioned yet goes straight there
        delta = end - start if tcp else np.where(unknown, 0.0, end - start)
        mm, turn = (delta[:, :3], delta[:, 3:]) if tcp else (delta[:, linear], delta[:, rotary])
        n = _samples(np.abs(mm).max(axis=1), np.degrees(np.abs(turn)).max(axis=1))
        move = np.repeat(np.arange(len(own)), n + 1)
        first = np.cumsum(n + 1) - (n + 1)
        # each move's fractions as np.linspace(0, 1, n + 1) makes them: j·(1/n), the last 1
        f = (np.arange(len(move)) - first[move]) * (1.0 / n)[move]
        f[first + n] = 1.0
        path = start[move] + f[:, None] * delta[move]
        if tcp:
            path = from_world(machine, path[:, :3], path[:, 3:])
        else:
            path = np.where(unknown[move], end[move], path)
        for seg, a, k in zip(own, first, n, strict=True):
            seg.path = path[a:a + k + 1]


def _samples(mm: np.ndarray, deg: np.ndarray) -> np.ndarray:
    """Samples of each move (≥ 1 step): its steps of ``STEP_MM`` and ``STEP_DEG``."""
    return np.maximum(1, np.ceil(np.maximum(mm / STEP_MM, deg / STEP_DEG))).astype(int)


def _axes_text(machine: Machine, q: np.ndarray) -> str:
    return " ".join(f"{a.name}{np.degrees(v) if a.rotary else v:+.3f}"
                    for a, v in zip(machine.axes, q, strict=True))


def _per_segment(machine: Machine, segments: list[_Segment]) -> tuple[np.ndarray, np.ndarray, list]:
    """For every move at once (mm and deg): each axis's distance moved and its largest step
    between samples, and per move, which of its samples leave which axis's travel."""
    k = len(machine.axes)
    if not segments:
        return np.zeros((0, k)), np.zeros((0, k)), []
    scale = np.array([180 / np.pi if a.rotary else 1.0 for a in machine.axes])
    paths = np.concatenate([seg.path for seg in segments]) * scale
    starts = np.cumsum([0] + [len(seg.path) for seg in segments[:-1]])
    step = np.nan_to_num(np.abs(np.diff(paths, axis=0)))
    step[starts[1:] - 1] = 0.0                   # from one move's end to the next's start
    # every path has two samples or more (``_samples``): each move owns one step or more
    moved, fastest = np.add.reduceat(step, starts, axis=0), np.maximum.reduceat(step, starts, axis=0)
    lo, hi = np.array([a.travel for a in machine.axes]).T
    bad = (paths < lo - 1e-9) | (paths > hi + 1e-9)      # a limit itself, to rounding, is in travel
    return moved, fastest, np.split(bad, starts[1:])


def feed_minutes(travel_mm, turn_deg, feed: float):
    """Minutes a fed move takes at F: along the nest's path in its active frame (mm), or,
    where the block only turns, F as deg/min on the axis turning furthest (``turn_deg``):
    LinuxCNC's meaning and, unconfirmed (U9), the others'. Elementwise over arrays: the
    motion check and measure-program's feed check judge a block by this one rule."""
    return np.where(np.asarray(travel_mm) > ONLY_TURNS_MM, travel_mm, turn_deg) / feed


def _seconds(machine: Machine, segments: list[_Segment], moved: np.ndarray, fastest: np.ndarray, linear,
             rotary, findings: list) -> list[float]:
    """Time of each move (``moved``, ``fastest``: ``_per_segment``'s), and a finding where
    an axis would exceed its feed_max: every move at once, the findings in their order."""
    if not segments:
        return []
    limits = np.array([a.feed_max for a in machine.axes])
    ends = np.array([(seg.path[0], seg.path[-1]) for seg in segments])
    delta = np.nan_to_num(ends[:, 1] - ends[:, 0])
    # the nest's travel in its active frame: a TCP move's in TCP coordinates
    frame = delta[:, linear]
    tcp = np.array([seg.tcp for seg in segments])
    if tcp.any():
        frame[tcp] = [seg.end[:3] - seg.start[:3] for seg in segments if seg.tcp]
    travel_mm = np.linalg.norm(frame, axis=1)
    turn_deg = np.degrees(np.abs(delta[:, rotary])).max(axis=1)      # a machine has a rotary axis
    feed = np.array([np.nan if seg.block.rapid or seg.block.feed is None else seg.block.feed
                     for seg in segments])
    fed = ~np.isnan(feed)
    with np.errstate(invalid="ignore", divide="ignore"):
        minutes = np.where(fed, feed_minutes(travel_mm, turn_deg, np.where(fed, feed, 1.0)), 0.0)
        rapid = np.where(moved.any(axis=1), (moved / limits).max(axis=1) * 60.0, 0.0)
        steps = np.array([len(seg.path) - 1 for seg in segments])
        speed = fastest * (steps / minutes)[:, None]
    took = np.where(fed, np.where(minutes > 0, minutes * 60.0, 0.0), rapid)
    over = fed & (minutes > 0) & (speed > limits * OVER_FEED).any(axis=1)
    for m in np.flatnonzero(over):
        axes = np.flatnonzero(speed[m] > limits * OVER_FEED)
        i = axes[int(np.argmax(speed[m, axes] / limits[axes]))]
        unit = "deg" if machine.axes[i].rotary else "mm"
        findings.append(Finding(segments[m].block.line, "feed above feed_max",
                                f"{machine.axes[i].name} would move at {speed[m, i]:.0f} {unit}/min, its "
                                f"feed_max is {limits[i]:g}", _axes_text(machine, segments[m].path[-1])))
    return took.tolist()


def _check_travel(machine: Machine, b: Block, path: np.ndarray, out: np.ndarray, findings: list) -> None:
    """The first axis that leaves its travel in a move (``out``: per sample and axis)."""
    i = int(np.flatnonzero(out.any(axis=0))[0])
    j = int(np.flatnonzero(out[:, i])[0])
    a = machine.axes[i]
    v = np.degrees(path[j, i]) if a.rotary else path[j, i]
    findings.append(Finding(b.line, "outside travel", f"{a.name} reaches {v:.3f}, travel "
                            f"{a.travel[0]:g}..{a.travel[1]:g}", _axes_text(machine, path[j])))


def _check_collisions(machine: Machine, segments: list[_Segment], findings: list,
                      probe: ProbeSetup | None = None):
    """Clearances of all samples at once; the closest approach of each pair in each block
    that comes nearer than its part's margin (or into it) is a finding. Returns the closest
    approach outside the exemptions: the nest where it measures; the stylus tip on the
    sphere while it probes and retracts (there it may touch, not enter)."""
    parts = tooling(machine, probe)
    paths = np.concatenate([seg.path for seg in segments])
    owner = np.concatenate([np.full(len(seg.path), i) for i, seg in enumerate(segments)])
    probing = np.concatenate([np.full(len(seg.path), seg.probing) for seg in segments])
    pairs, measuring = clearances(machine, paths, probe)
    closest = (np.inf, "")
    for pair, c in pairs.items():
        part = pair.split(" / ")[0]     # a head's body keeps the set-up's margin
        margin = np.full(len(c), parts[part][3] if part in parts else machine.setup.margin)
        if probe is None and pair in ("housing / ball", "housing / stem"):
            c = np.where(measuring, np.inf, c)
        if pair == "stylus tip / ball":       # probing, the tip touches: only entering counts
            c = np.where(probing & (c >= -TOUCH_MM), np.inf, c)
        j = int(np.argmin(c))
        if c[j] < closest[0]:
            closest = (float(c[j]), f"{pair}, line {segments[owner[j]].block.line}")
        near = c < margin
        for i in np.unique(owner[near]):
            j = int(np.flatnonzero((owner == i) & near)[np.argmin(c[(owner == i) & near])])
            b = segments[i].block
            part, thing = pair.split(" / ")
            what = (f"{part} enters the {thing}" if c[j] < 0 else
                    f"{part} within {c[j]:.1f} mm of the {thing} (margin {margin[j]:g} mm)")
            findings.append(Finding(b.line, what, b.text.strip(), _axes_text(machine, paths[j]),
                                    max(float(-c[j]), 0.0)))
    return closest
