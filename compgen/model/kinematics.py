"""Exact forward model of the R-test reading, its Jacobian, and the nominal inverse.

The R-test reads the nest (tool) centre minus the ball (workpiece) centre along the machine
X, Y, Z (contract §1). compgen predicts the *deviation from nominal*: that vector on the
erroneous machine minus the same vector on the nominal machine at the same commanded pose.
On a pose commanded by TCPM or by compgen's inverse kinematics the nominal vector is zero up
to the resolution of the recorded X, Y, Z; subtracting it keeps that rounding (0.05 µm at
four decimals) out of the model.

References: seed report eqs. (1)–(8); ``docs/rtest-csv.md``.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Iterable, Mapping, Sequence

import numpy as np

from ..errors import CompgenError
from ..transforms import UNIT, apply, rodrigues, rot_axis, rot_exact, trans
from .effects import (
    IN_TIME,
    POLY_SCALE_MM,
    ROT_OF,
    ROTATIONS,
    TIME_SCALE_S,
    TRANSLATIONS,
    Effect,
    canonical,
    effect_of_param,
)
from .machine import Axis, Machine
from .poses import Poses, motion_direction, runs

SLOT_INDEX = {d: i for i, d in enumerate(TRANSLATIONS + ROTATIONS)}


class Model:
    """A set of named parameters (an ordered model) on a machine, ready to evaluate.

    >>> m = Model(machine, ["XOC", "ECC:h2c"])        # doctest: +SKIP
    >>> m.deviation(poses, np.array([1e-3, 2e-6]))    # (n, 3) mm
    """

    def __init__(self, machine: Machine, names: Iterable[str]):
        self.machine = machine
        self.names = tuple(canonical(n) for n in names)
        if len(set(self.names)) != len(self.names):
            raise CompgenError(f"a parameter is named twice in the model {list(self.names)}")
        self.effects: tuple[Effect, ...] = tuple(effect_of_param(machine, n) for n in self.names)

    def _slots(self, poses: Poses, values: np.ndarray,
               coordinates: Sequence[np.ndarray] | None = None) -> dict[tuple[str, str], np.ndarray]:
        n, slots = len(poses), {}
        for i, (name, effect, value) in enumerate(zip(self.names, self.effects, values, strict=True)):
            if value == 0.0:
                continue
            term = effect.params.index(name)
            x = coordinate(self.machine, effect, poses) if coordinates is None else coordinates[i]
            slot = slots.setdefault((effect.carrier, effect.slot), np.zeros((n, 6)))
            for direction, b in effect.parts(x):
                slot[:, SLOT_INDEX[direction]] += value * b[:, term]
        return slots

    def relative(self, poses: Poses, values: np.ndarray | None = None,
                 lines: Mapping[str, tuple] | None = None) -> np.ndarray:
        """Nest centre minus ball centre, machine frame, (n, 3) mm. ``lines`` maps a rotary
        axis to (offset mm, tilt rad): it then turns about that line, as a controller's
        kinematics would hold it (``lines.py``)."""
        values = np.zeros(len(self.names)) if values is None else np.asarray(values, float)
        return relative(self.machine, poses, self._slots(poses, values), lines)

    def frame_before_motion(self, poses: Poses, values: np.ndarray, chain, i: int) -> np.ndarray:
        """Frame of axis ``chain[i]`` just before its own motion, machine frame, (n, 4, 4):
        its own frame (turned by its incline, on an inclined axis)."""
        slots = self._slots(poses, np.asarray(values, float))
        zero = np.zeros((len(poses), 6))
        T = chain_transform(self.machine, chain[:i], poses, slots, zero)
        axis = chain[i]
        q = poses.q[:, self.machine.index(axis.name)]
        return T @ _link(axis, q, slots.get((axis.name, "loc"), zero),
                         slots.get((axis.name, "comp"), zero), motion=False)

    def deviation(self, poses: Poses, values: np.ndarray) -> np.ndarray:
        """Predicted R-test reading minus its nominal value, (n, 3) mm."""
        return self.relative(poses, values) - nominal(self.machine, poses)

    def jacobian(self, poses: Poses, values: np.ndarray | None = None) -> np.ndarray:
        """∂ deviation / ∂ parameters at ``values``, (n, 3, p), mm per mm or per rad.

        At ``values = 0`` these are the first-order error gains (seed Table 2).
        """
        return self.linearise(poses, values)[1]

    def linearise(self, poses: Poses, values: np.ndarray | None = None,
                  out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The deviation (n, 3) and its Jacobian (n, 3, p) at ``values``, from one walk of
        the chains per block of poses: analytic (``SlotGains`` on the machine with these
        errors), so a Gauss–Newton step costs one evaluation of the model.

        The Jacobian is a view of a (p, n, 3) array — ``out`` if given, overwritten (a
        dense session's is 200 MB: fresh memory at every step costs a third of a fit in
        page faults) — so each column is written in one piece and ``np.moveaxis(J, 2, 0)``
        is contiguous: a tall fit forms JᵀJ from it without a copy."""
        values = np.zeros(len(self.names)) if values is None else np.asarray(values, float)
        # coordinates on the whole session (a reversal's side depends on the run it is
        # in); the slots a block at a time, as the chains are walked
        x = [coordinate(self.machine, e, poses) for e in self.effects]
        # at zero the walk is the nominal machine's: it gives the nominal readings too
        known = None if not values.any() and _known_nominal(self.machine, poses) is None \
            else nominal(self.machine, poses)
        dev = np.empty((len(poses), 3))
        shape = (len(self.names), len(poses), 3)
        columns = out if out is not None and out.shape == shape else np.empty(shape)
        def part(starts: range) -> None:     # each block writes its own rows
            for a in starts:
                at = slice(a, a + BLOCK)
                block = poses.take(at)
                gains = SlotGains(self.machine, block, self._slots(block, values, [c[at] for c in x]))
                if known is None:
                    dev[at] = gains.relative     # the nominal readings, for now
                else:
                    np.subtract(gains.relative, known[at], out=dev[at])
                made = {}
                for i, (name, effect) in enumerate(zip(self.names, self.effects, strict=True)):
                    own = effect.params.index(name)
                    columns[i, at] = effect_gains(gains, effect, x[i][at], made)[:, :, own]

        in_halves(part, range(0, len(poses), BLOCK))
        if known is None:
            _NOMINALS[poses] = (self.machine, dev)
            dev = np.zeros_like(dev)
        return dev, np.moveaxis(columns, 0, 2)


# the nominal machine's readings at poses already evaluated (poses are frozen: so are
# these), held as long as the poses are: reading a session checks them, a fit needs them
_NOMINALS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _known_nominal(machine: Machine, poses: Poses) -> np.ndarray | None:
    held = _NOMINALS.get(poses)
    return held[1] if held is not None and held[0] is machine else None


def nest_centre(machine: Machine, tool: np.ndarray, nest: np.ndarray | None = None) -> np.ndarray:
    """The nest centre (n, 3) mm in the machine frame, from the tool chain's transform
    ``tool`` (n, 4, 4) (``chain_transform``): its frames start at the gauge line. ``nest``:
    each pose's nest length (``Poses.nest``), if not the machine file's."""
    if not machine.heads:     # the linear axes' position, exactly
        return tool[:, :3, 3]
    gauge, point = lever(machine, nest, len(tool))
    return (tool[:, :3, 3] + _rotate(tool[:, :3, :3], point)) + gauge


def lever(machine: Machine, nest: np.ndarray | None, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The gauge line in the machine frame at the zero pose and the nest centre in the tool
    chain's last frame, (3,) each or (n, 3) where ``nest`` (n,) gives poses their own nest
    length (NaN: the machine file's ``probe_length``)."""
    if nest is None or np.isnan(nest).all():
        return machine.gauge, machine.nest_point
    gauge = np.zeros((n, 3))
    gauge[:, 2] = np.where(np.isnan(nest), machine.probe_length, nest)
    return gauge, machine.nest_point + machine.gauge - gauge


def head_offset(machine: Machine, rotary_rad: np.ndarray, nest: np.ndarray | None = None) -> np.ndarray:
    """Where a head's turn puts the nominal nest centre from the linear axes' position,
    (n, 3) mm at the rotary positions (n, r): what a control adds under TCPM to X, Y, Z
    (the nest's position, the R-test CSV's columns) to drive the axes. Zero without a head."""
    n = len(rotary_rad)
    if not machine.heads:
        return np.zeros((n, 3))
    q = np.zeros((n, len(machine.axes)))
    q[:, [machine.index(a.name) for a in machine.rotary_axes]] = rotary_rad
    zero = np.zeros((n, 6))
    return nest_centre(machine, chain_transform(machine, machine.tool, Poses.at(q, np.zeros(3)), {}, zero),
                       nest)


def solved(machine: Machine, poses: Poses) -> Poses:
    """``poses`` whose axes ``inverse`` solved on this machine: the nominal machine puts the
    nest on the ball there (to rounding, ~1e-13 mm), so their nominal reading is zero and
    is not walked again (a third of predict's time at a million poses)."""
    _NOMINALS[poses] = (machine, np.zeros((len(poses), 3)))
    return poses


def nominal(machine: Machine, poses: Poses) -> np.ndarray:
    """Nest minus ball on the nominal machine, (n, 3) mm: zero where the poses are exactly
    TCPM's, otherwise the recorded X, Y, Z's rounding or offset."""
    known = _known_nominal(machine, poses)
    if known is None:
        known = relative(machine, poses, {})
        _NOMINALS[poses] = (machine, known)
    return known


def coordinate(machine: Machine, effect: Effect, poses: Poses) -> np.ndarray:
    """The coordinate an effect's basis runs in: rad, position per 1000 mm, or hours (a
    drift, and any effect in time: ``e`` and ``t``); a scale in time (``g``), the axis's
    position (rad, per 1000 mm) times its growth 1 − exp(−t/τ)."""
    kind = effect.basis.kind
    timed = effect.carrier == "time" or kind in IN_TIME
    if timed and np.isnan(poses.t).any():
        raise CompgenError(f"{effect.name} needs the time column t in every data row")
    if timed and kind != "g":
        return poses.t / TIME_SCALE_S
    if kind == "const":
        return np.zeros(len(poses))
    axis = machine.axis(effect.carrier)
    q = poses.q[:, machine.index(axis.name)]
    if kind == "r":
        side = poses.side[:, machine.index(axis.name)]
        known = ~np.isnan(side)
        if known.all():
            return side.copy()
        return np.where(known, side, motion_direction(q, runs(poses)))
    position = q if axis.rotary else q / POLY_SCALE_MM
    return position * -np.expm1(-poses.t / (60.0 * effect.basis.order)) if kind == "g" else position


BLOCK = 16384            # poses per evaluation of the chain
THREADED = 1 << 18       # poses from which a pass runs in two halves at once


def in_halves(work: Callable[[range], object], starts: range) -> list:
    """``work`` on the first and the second half of the blocks ``starts``, each on its own
    thread where there are two halves: numpy and LAPACK let go of the GIL in their loops,
    so a dense session's pass takes ~0.6–0.8 of its time on two cores. The halves depend on
    the poses alone and their results come back in order: the same numbers on any machine.
    ``starts`` are the blocks' first poses, ``range(0, n, block)``; below ``THREADED`` poses
    the halves run one after the other: there a second thread's walk and heap cost more
    memory than its time saves (docs/benchmarks.md has the figures)."""
    from concurrent.futures import ThreadPoolExecutor  # here: every command's start-up would pay it

    half = len(starts) // 2
    if not half or starts.stop < THREADED:
        return [work(starts)]
    with ThreadPoolExecutor(2) as pool:
        return list(pool.map(work, (starts[:half], starts[half:])))


def relative(machine: Machine, poses: Poses, slots: Mapping[tuple[str, str], np.ndarray],
             lines: Mapping[str, tuple] | None = None) -> np.ndarray:
    """Nest minus ball, (n, 3) mm, for errors given as slots: (carrier, "loc" | "comp") →
    (n, 6) translations (mm) and rotations (rad) in ``TRANSLATIONS + ROTATIONS`` order.
    Evaluated in blocks of ``BLOCK`` poses: the chain's (n, 4, 4) temporaries of a whole
    dense session would be fresh memory at every link."""
    def part(starts: range) -> list[np.ndarray]:
        return [_walk(machine, poses.take(slice(a, a + BLOCK)), {k: v[a:a + BLOCK] for k, v in slots.items()},
                      lines)[0] for a in starts]

    blocks = [b for half in in_halves(part, range(0, len(poses), BLOCK)) for b in half]
    return np.concatenate(blocks) if blocks else np.zeros((0, 3))


def _walk(machine: Machine, poses: Poses, slots: Mapping, lines: Mapping[str, tuple] | None = None,
          record: bool = False) -> tuple[np.ndarray, dict]:
    """Nest minus ball, (n, 3) mm, by walking both chains factor by factor; with ``record``,
    also each chain's frames before every factor: carrier → [(sign, marks, R, o, P)], the
    frame's rotation and origin and the chain's end point, all in the machine frame."""
    n = len(poses)
    zero = np.zeros((n, 6))
    # the tool side's frames sit at the spindle gauge line, probe_length above the nest
    # centre (q is the nest centre: the tool length compensated), so an angular error of a
    # tool-side carriage turns the nest with the tool length as its lever
    gauge, nest_point = lever(machine, poses.nest, n)
    ends, frames = {}, {}
    for chain, start, sign, carrier, point in ((machine.workpiece, np.zeros(3), -1.0, "ball", poses.ball),
                                               (machine.tool, gauge, 1.0, "nest", nest_point)):
        R, o = np.broadcast_to(np.eye(3), (n, 3, 3)), np.broadcast_to(start, (n, 3))
        held = []
        for axis in chain:
            q = poses.q[:, machine.index(axis.name)]
            for op, marks in _factors(axis, q, slots.get((axis.name, "loc"), zero),
                                      slots.get((axis.name, "comp"), zero),
                                      line=(lines or {}).get(axis.name)):
                if record:
                    held.append((axis.name, marks, R, o))
                if op is not None:
                    R, o = _compose(R, o, op)
        P = o + _rotate(R, point + slots.get((carrier, "loc"), zero)[:, :3])
        ends[carrier] = P
        for name, marks, R_at, o_at in held:
            frames.setdefault(name, []).append((sign, marks, R_at, o_at, P))
        frames[carrier] = [(sign, [("t", "loc")], R, None, P)]
    return ends["nest"] - ends["ball"] + slots.get(("time", "loc"), zero)[:, :3], frames


class SlotGains:
    """First-order gains of a unit error in a slot (carrier, slot, direction), on a machine
    that already carries the errors ``slots`` (none: the nominal machine): ``gains(key)`` is
    (n, 3) mm per mm or per rad, exact (the derivative of ``relative``, not a difference);
    ``gains.relative`` is the reading there, from the same walk of the chains. A model's
    Jacobian column is its basis values times the gain of its slot.

    Analytic, from one evaluation of each chain that keeps the frame before every factor of
    every link: a unit translation e in a frame F moves the chain's end point P by R_F e, a
    unit rotation by R_F ω × (P − o_F), where ω = J(w)e for a factor that already turns by
    the rotation vector w (J the left Jacobian of the rotation group: d exp(w) = [J dw]×
    exp(w); at w = 0, ω = e). The ball is the workpiece chain's end (its motion counts
    negatively: nest minus ball), the nest the tool chain's. A squareness turns the line of
    motion, moving P by q·(R_F J e × line). Only the frames are held; a gain is made when
    asked. (``tests/model/test_kinematics.py`` checks every slot against central differences, on
    the nominal machine and on one with large errors.)
    """

    def __init__(self, machine: Machine, poses: Poses, slots: Mapping | None = None):
        self.n = len(poses)
        self.twice = bool(machine.heads)
        self.relative, self.frames = _walk(machine, poses, slots or {}, record=True)

    def __call__(self, key: tuple[str, str, str]) -> np.ndarray:
        carrier, slot, direction = key
        k = SLOT_INDEX[direction]
        e = UNIT["xyz"[k % 3]]
        if carrier == "time":
            return np.broadcast_to(e * (k < 3), (self.n, 3)).copy()
        total = None
        for sign, marks, R, o, P in self.frames[carrier]:
            for mark in marks:
                kind, at = mark[:2]
                if at != slot:
                    continue
                term = None
                if kind == "t" and k < 3:
                    term = (sign * mark[2] if len(mark) > 2 else sign) * R[:, :, k]
                elif kind == "r" and k >= 3 and k != mark[3]:
                    w = mark[2]
                    if not w.any():
                        axis = R[:, :, k - 3]
                    else:       # a location error turns every pose alike: its J(w)e once
                        axis = _rotate(R, _left_jacobian(w[:1], e)[0] if _same(w) else _left_jacobian(w, e))
                    term = (sign * mark[4] if len(mark) > 4 else sign) * _cross(axis, P - o)
                elif kind == "turn" and k == mark[2]:
                    term = sign * _cross(R[:, :, k - 3], P - o)
                elif kind == "line" and k >= 3:
                    _, _, w, run, line = mark
                    turned = _left_jacobian(w[:1], e)[0] if _same(w) else _left_jacobian(w, e)
                    term = sign * run[:, None] * _rotate(R, _cross(turned, line))
                if term is None:
                    continue
                if not self.twice:       # one factor holds each slot
                    return term
                # a head's location errors act twice, placing its line and undoing it after
                # the turn (scale -1): their gains add
                total = term if total is None else total + term
        return total if total is not None else np.zeros((self.n, 3))   # a ball's tilt: none


def effect_gains(gains: SlotGains, effect: Effect, x: np.ndarray, made: dict | None = None) -> np.ndarray:
    """What a unit of each of ``effect``'s parameters does to every reading, first order:
    (n, 3, len(params)) mm per unit, its basis values at the coordinate ``x`` times the
    gain of its slot (an effect of two directions: the sum of two). ``made`` keeps the
    gains of slots already asked for."""
    made = {} if made is None else made
    out = np.empty((len(x), 3, len(effect.params)))
    for i, (d, v) in enumerate(effect.split(effect.basis.values(x))):
        key = (effect.carrier, effect.slot, d)
        if key not in made:
            made[key] = gains(key)
        term = (made[key][:, :, None], v[:, None, :])
        if i == 0:              # into ``out``: a temporary and an add cost three times as much
            np.multiply(*term, out=out)
        else:                   # a compound's second direction
            out += np.multiply(*term)
    return out


def slot_gains(machine: Machine, poses: Poses, keys) -> dict[tuple[str, str, str], np.ndarray]:
    """``SlotGains`` of each key on the nominal machine, as a dict."""
    gains = SlotGains(machine, poses)
    return {key: gains(key) for key in keys}


def _same(w: np.ndarray) -> bool:
    """Every pose's row of ``w`` (n, 3) is the first's."""
    return len(w) > 0 and bool((w == w[0]).all())


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b for stacks (n, 3): numpy's cross costs several times this at these sizes."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _rotate(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R v for stacks: (n, 3, 3) and (n, 3) or (3,) → (n, 3). A v per pose: einsum (two
    thirds of the time of three scaled columns added); one v for all: its columns."""
    if v.ndim == 2:
        return np.einsum("...ij,...j->...i", R, v)
    return R[:, :, 0] * v[0] + R[:, :, 1] * v[1] + R[:, :, 2] * v[2]


def _left_jacobian(w: np.ndarray, e: np.ndarray) -> np.ndarray:
    """J(w) e, (n, 3): the axis a rotation by w turns about when w moves along e.
    J = I + (1 − cos θ)/θ² K + (θ − sin θ)/θ³ K², K = [w]×; series below θ = 1e-3."""
    theta = np.linalg.norm(w, axis=-1)[:, None]
    safe = np.where(theta < 1e-3, 1.0, theta)
    b = np.where(theta < 1e-3, 0.5 - theta**2 / 24, (1 - np.cos(safe)) / safe**2)
    c = np.where(theta < 1e-3, 1 / 6 - theta**2 / 120, (safe - np.sin(safe)) / safe**3)
    we = _cross(w, e)
    return e + b * we + c * _cross(w, we)


def _factors(axis: Axis, q: np.ndarray, loc: np.ndarray, comp: np.ndarray, motion: bool = True,
             line: tuple | None = None) -> list[tuple[tuple | None, list]]:
    """One axis frame in its parent (seed eqs. 1 and 2) as its factors in order, each an
    operation — ("t", v) a translation, ("w", w) a rotation by the rotation vector w,
    ("q", direction, angle) a turn about a unit axis, ("m", M) any (n, 4, 4) — or None
    where it is exactly the identity, with marks that say which slots act there: ("t",
    slot) translations, ("r", slot, w, own) rotations by w (all components but ``own``),
    ("turn", slot, own) the axis's own angle, ("line", slot, w, run, line) a squareness
    turning the line of motion.

    Factors that are exactly zero are None: most parameters are zero in most slots.
    ``motion=False`` stops before the axis's own motion. ``line`` (offset, tilt) turns a
    rotary axis about that line instead: ``Trans(t)·Rot(r)·R(θ)·Rot(r)⁻¹·Trans(−t)``, the
    form a controller's kinematics holds.
    """
    offset = np.asarray(axis.offset)
    if axis.rotary:
        own = SLOT_INDEX[ROT_OF[axis.direction]]
        tilt = comp[:, 3:].copy()
        tilt[:, own - 3] = 0.0
        # an inclined axis: into its own frame at the pivot, its errors and turn there, and
        # back out, so the frame it carries has its parent's orientation at zero
        incline = (np.broadcast_to(np.asarray(axis.incline, float), loc[:, 3:].shape)
                   if axis.inclined else None)
        if incline is not None and line is not None:     # the line is held in the parent's frame
            line = tuple(np.asarray(v, float) @ axis.frame for v in line)
        out = [] if incline is None else [(("t", offset), []), (("w", incline), [])]
        out += [(("t", loc[:, :3] + (0.0 if incline is not None else offset)), [("t", "loc")]),
               (("w", loc[:, 3:]) if loc[:, 3:].any() else None, [("r", "loc", loc[:, 3:], -1)]),
               (("t", comp[:, :3]) if comp[:, :3].any() else None, [("t", "comp")]),
               (("w", tilt) if tilt.any() else None, [("r", "comp", tilt, own)])]
        if motion:
            turn = ("q", axis.direction, axis.sense * q + comp[:, own])
            if line is not None:
                t, r = (np.asarray(v, float) for v in line)
                place = trans(t) @ rot_exact(r)
                turn = ("m", place @ _matrix(turn) @ np.linalg.inv(place))
            out.append((turn, [("turn", "comp", own)]))
            if axis.side == "tool":
                # a head's location errors place the line it turns about (at its pivot),
                # not its frame: undone after the turn, they move nothing at the zero pose.
                # As a frame (a table's, seed eq. 2) they would shift the nest as the
                # ball's offset and the table's lines do, and could not be told apart
                r, t = -loc[:, 3:], -loc[:, :3]
                out += [(("w", r) if r.any() else None, [("r", "loc", r, -1, -1.0)]),
                        (("t", t) if t.any() else None, [("t", "loc", -1.0)])]
        if incline is not None and motion:     # before its motion: the axis's own frame
            out.append((("w", -incline), []))
        return out
    # squareness tilts the line of motion; the carriage itself turns only by its own
    # angular error motions
    unit = np.broadcast_to(UNIT[axis.direction], loc[:, :3].shape)
    line_dir = apply(rot_exact(loc[:, 3:]), unit) if loc[:, 3:].any() else unit
    run = axis.sense * q * motion
    return [(("t", offset + loc[:, :3] + comp[:, :3] + run[:, None] * line_dir),
             [("t", "loc"), ("t", "comp"), ("line", "loc", loc[:, 3:], run, line_dir)]),
            (("w", comp[:, 3:]) if comp[:, 3:].any() else None, [("r", "comp", comp[:, 3:], -1)])]


def _matrix(op: tuple) -> np.ndarray:
    """A factor as (n, 4, 4)."""
    kind, *a = op
    return {"t": trans, "w": rot_exact, "q": rot_axis, "m": lambda m: m}[kind](*a)


def _compose(R: np.ndarray, o: np.ndarray, op: tuple) -> tuple[np.ndarray, np.ndarray]:
    """The frame (R (n, 3, 3), origin o (n, 3)) followed by one factor, as new arrays (the
    inputs are never written: views of them stay true). Translations and turns about a
    unit axis act on columns: no 4 × 4 products where most entries are 0 or 1."""
    kind, *a = op
    if kind == "t":
        return R, o + _rotate(R, a[0])
    if kind == "w":
        if _same(a[0]):     # a location error turns every pose alike: one 3 × 3, one product
            return (R.reshape(-1, 3) @ rodrigues(a[0][0])).reshape(R.shape), o
        return R @ rodrigues(a[0]), o
    if kind == "q":
        i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[a[0]]
        c, s = np.cos(a[1])[:, None], np.sin(a[1])[:, None]
        out = R.copy()
        out[:, :, i] = c * R[:, :, i] + s * R[:, :, j]
        out[:, :, j] = c * R[:, :, j] - s * R[:, :, i]
        return out, o
    M = a[0]
    return R @ M[:, :3, :3], o + _rotate(R, M[:, :3, 3])


def _link(axis: Axis, q: np.ndarray, loc: np.ndarray, comp: np.ndarray, motion: bool = True,
          line: tuple | None = None) -> np.ndarray:
    """Transform of one axis frame in its parent, (n, 4, 4): the product of its factors."""
    T = None
    for op, _ in _factors(axis, q, loc, comp, motion, line):
        if op is not None:
            T = _matrix(op) if T is None else T @ _matrix(op)
    return T


def chain_transform(machine: Machine, axes: Sequence[Axis], poses: Poses, slots: Mapping,
                    zero: np.ndarray, lines: Mapping[str, tuple] | None = None) -> np.ndarray:
    """The transform (n, 4, 4) of ``axes`` (a chain or its start) at the poses, with the
    errors of ``slots`` (zero: the nominal chain)."""
    T = np.broadcast_to(np.eye(4), (len(poses), 4, 4))
    for axis in axes:
        q = poses.q[:, machine.index(axis.name)]
        T = T @ _link(axis, q, slots.get((axis.name, "loc"), zero),
                      slots.get((axis.name, "comp"), zero), line=(lines or {}).get(axis.name))
    return T


def inverse(machine: Machine, rotary_rad: np.ndarray, ball: np.ndarray,
            lines: Mapping[str, tuple] | None = None,
            params: Mapping[str, float] | None = None, nest: np.ndarray | None = None) -> np.ndarray:
    """Nominal inverse kinematics, as a controller's TCPM/TRAORI would compute it.

    Parameters
    ----------
    rotary_rad : (n, r) rotary axis positions in ``machine.rotary_axes`` order, rad
    ball : (n, 3) or (3,) ball centre in the table frame, mm
    nest : (n,) each pose's nest length, mm (``Poses.nest``), if not the machine file's

    Returns
    -------
    q : (n, k) full commanded poses (mm, rad) that put the nest centre on the ball centre.

    For fixed rotary angles the nest-minus-ball vector is affine in the linear axes: its
    value and its matrix (each linear axis's line of motion, turned by the frames before
    it, from the same walk of the chains) give the solution exactly, whatever the chain.
    ``lines`` gives the rotary axis lines a controller holds (``lines.py``), ``params``
    (name → mm, rad) any constant errors it holds too, such as squareness: its TCPM
    solution.
    """
    rotary_rad = np.atleast_2d(np.asarray(rotary_rad, float))
    n = len(rotary_rad)
    ball = np.broadcast_to(np.asarray(ball, float), (n, 3))
    q = np.zeros((n, len(machine.axes)))
    linear = [i for i, a in enumerate(machine.axes) if not a.rotary]
    q[:, [i for i, a in enumerate(machine.axes) if a.rotary]] = rotary_rad
    held = Model(machine, list(params or {}))
    poses = Poses.at(q, ball, nest)
    slots = held._slots(poses, np.array(list((params or {}).values())))
    r0, M = np.empty((n, 3)), np.empty((n, 3, 3))
    for a in range(0, n, BLOCK):
        at = slice(a, a + BLOCK)
        block = {k: v[at] for k, v in slots.items()}
        r0[at], frames = _walk(machine, poses.take(at), block, lines, record=True)
        for j, i in enumerate(linear):
            axis = machine.axes[i]
            sign, marks, R, _, _ = next(f for f in frames[axis.name] if f[1][-1][0] == "line")
            M[at, :, j] = sign * axis.sense * _rotate(R, marks[-1][4])
    q[:, linear] = np.linalg.solve(M, -r0[..., None])[..., 0]
    return q
