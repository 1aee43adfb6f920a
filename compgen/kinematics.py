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

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .effects import (
    POLY_SCALE_MM,
    ROT_OF,
    ROTATIONS,
    TIME_SCALE_S,
    TRANSLATIONS,
    Effect,
    canonical,
    effect_of_param,
)
from .errors import CompgenError
from .machine import Axis, Machine
from .transforms import UNIT, apply, rot_axis, rot_exact, trans

SLOT_INDEX = {d: i for i, d in enumerate(TRANSLATIONS + ROTATIONS)}
FD_STEP = 1e-6   # mm or rad: central differences exact to ~1e-9 relative at these levers


@dataclass(frozen=True, eq=False)
class Poses:
    """Commanded poses of one or more R-test sessions.

    q : (n, k) commanded axis positions, mm and rad, columns in ``machine.axis_names`` order
    ball : (n, 3) nominal ball centre in the table frame, mm
    t : (n,) time since the start of the session, s (NaN where not recorded)
    path : (n,) path label of each pose
    """

    q: np.ndarray
    ball: np.ndarray
    t: np.ndarray
    path: np.ndarray

    def __post_init__(self):
        for field in ("q", "ball", "t", "path"):
            a = np.array(getattr(self, field))   # a copy: freezing must not touch the caller's
            a.setflags(write=False)
            object.__setattr__(self, field, a)

    def __len__(self) -> int:
        return len(self.q)

    def take(self, index) -> Poses:
        return Poses(self.q[index], self.ball[index], self.t[index], self.path[index])

    @staticmethod
    def at(q: np.ndarray, ball) -> Poses:
        """Poses with no time and no path label: ``ball`` (3,) or (n, 3) mm."""
        n = len(q)
        return Poses(q, np.broadcast_to(np.asarray(ball, float), (n, 3)), np.full(n, np.nan),
                     np.full(n, "", dtype=object))

    @staticmethod
    def concat(items: Sequence[Poses]) -> Poses:
        return Poses(*(np.concatenate([getattr(p, f) for p in items])
                       for f in ("q", "ball", "t", "path")))


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
        self._nominal: tuple[Poses | None, np.ndarray | None] = (None, None)

    def _slots(self, poses: Poses, values: np.ndarray) -> dict[tuple[str, str], np.ndarray]:
        n, slots = len(poses), {}
        for name, effect, value in zip(self.names, self.effects, values, strict=True):
            if value == 0.0:
                continue
            term = effect.params.index(name)
            x = coordinate(self.machine, effect, poses)
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
        """Frame of axis ``chain[i]`` just before its own motion, machine frame, (n, 4, 4)."""
        slots = self._slots(poses, np.asarray(values, float))
        zero = np.zeros((len(poses), 6))
        T = _chain(self.machine, chain[:i], poses, slots, zero)
        axis = chain[i]
        q = poses.q[:, self.machine.index(axis.name)]
        return T @ _link(axis, q, slots.get((axis.name, "loc"), zero),
                         slots.get((axis.name, "comp"), zero), motion=False)

    def deviation(self, poses: Poses, values: np.ndarray) -> np.ndarray:
        """Predicted R-test reading minus its nominal value, (n, 3) mm."""
        if self._nominal[0] is not poses:   # poses are frozen: the nominal vector is too
            self._nominal = (poses, self.relative(poses))
        return self.relative(poses, values) - self._nominal[1]

    def jacobian(self, poses: Poses, values: np.ndarray | None = None) -> np.ndarray:
        """∂ deviation / ∂ parameters at ``values``, (n, 3, p), mm per mm or per rad.

        At ``values = 0`` these are the first-order error gains (seed Table 2).
        """
        values = np.zeros(len(self.names)) if values is None else np.asarray(values, float)
        J = np.empty((len(poses), 3, len(self.names)))
        for i in range(len(self.names)):
            step = np.zeros_like(values)
            step[i] = FD_STEP
            J[:, :, i] = (self.relative(poses, values + step)
                          - self.relative(poses, values - step)) / (2 * FD_STEP)
        return J


def coordinate(machine: Machine, effect: Effect, poses: Poses) -> np.ndarray:
    """The coordinate an effect's basis runs in: rad, position per 1000 mm, or hours."""
    if effect.carrier == "time" or effect.basis.kind == "e":
        if np.isnan(poses.t).any():
            raise CompgenError(f"{effect.name} needs the time column t in every data row")
        return poses.t / TIME_SCALE_S
    if effect.basis.kind == "const":
        return np.zeros(len(poses))
    axis = machine.axis(effect.carrier)
    q = poses.q[:, machine.index(axis.name)]
    if effect.basis.kind == "r":
        return motion_direction(q, runs(poses))
    return q if axis.rotary else q / POLY_SCALE_MM


def runs(poses: Poses, source: np.ndarray | None = None) -> np.ndarray:
    """A number per pose that changes where one continuous run of a path ends: at a new path
    label, a new ball position, where the session time goes back (a new file), or where
    ``source`` (the file of each pose, when known) changes."""
    new = np.ones(len(poses), bool)
    back = np.diff(poses.t) <= 0                # NaN (no time column) compares False
    new[1:] = (poses.path[1:] != poses.path[:-1]) | np.any(poses.ball[1:] != poses.ball[:-1], axis=1) | back
    if source is not None:
        new[1:] |= source[1:] != source[:-1]
    return np.cumsum(new)


def motion_direction(q: np.ndarray, run: np.ndarray) -> np.ndarray:
    """The side of a reversal each pose is on: ±1 by the direction the axis moved to reach
    it (poses in the order taken; standing still keeps the last direction, the first pose
    takes its path's first move), less the path's mean. How the axis reached a path's start
    is not known, so only the change within a path counts: a path in which the axis never
    turns back is 0 throughout, and its side of the backlash stays with the location errors.
    """
    out = np.zeros(len(q))
    starts = np.flatnonzero(np.r_[True, run[1:] != run[:-1]])
    for a, b in zip(starts, [*starts[1:], len(q)], strict=True):
        step = np.sign(np.diff(q[a:b]))
        if not ((step > 0).any() and (step < 0).any()):
            continue
        # standing still keeps the last move's sign: index of the last move up to each step
        last = np.maximum.accumulate(np.where(step != 0, np.arange(len(step)), -1))
        first = step[np.flatnonzero(step)[0]]
        d = np.r_[first, np.where(last >= 0, step[np.maximum(last, 0)], first)]
        out[a:b] = d - d.mean()
    return out


BLOCK = 16384            # poses per evaluation of the chain


def relative(machine: Machine, poses: Poses, slots: Mapping[tuple[str, str], np.ndarray],
             lines: Mapping[str, tuple] | None = None) -> np.ndarray:
    """Nest minus ball, (n, 3) mm, for errors given as slots: (carrier, "loc" | "comp") →
    (n, 6) translations (mm) and rotations (rad) in ``TRANSLATIONS + ROTATIONS`` order.
    Evaluated in blocks of ``BLOCK`` poses: the chain's (n, 4, 4) temporaries of a whole
    dense session would be fresh memory at every link."""
    if len(poses) > BLOCK:
        return np.concatenate([relative(machine, poses.take(slice(a, a + BLOCK)),
                                        {k: v[a:a + BLOCK] for k, v in slots.items()}, lines)
                               for a in range(0, len(poses), BLOCK)])
    zero = np.zeros((len(poses), 6))
    table = _chain(machine, machine.workpiece, poses, slots, zero, lines)
    # the tool side's frames sit at the spindle gauge line, probe_length above the nest
    # centre (q is the nest centre: the tool length compensated), so an angular error of a
    # tool-side carriage turns the nest with the tool length as its lever
    gauge = np.array([0.0, 0.0, machine.probe_length])
    spindle = trans(gauge) @ _chain(machine, machine.tool, poses, slots, zero, lines)
    ball = apply(table, poses.ball + slots.get(("ball", "loc"), zero)[:, :3])
    nest = apply(spindle, -gauge + slots.get(("nest", "loc"), zero)[:, :3])
    return nest - ball + slots.get(("time", "loc"), zero)[:, :3]


class SlotGains:
    """First-order gains at zero of a unit error in a slot (carrier, slot, direction):
    ``gains(key)`` is (n, 3) mm per mm or per rad. Any effect's Jacobian column at zero is
    its basis values times the gain of its slot.

    Analytic, from one nominal evaluation of each chain: a unit translation e in a frame F
    moves the chain's end point P by R_F e, a unit rotation by R_F e × (P − o_F); the ball
    is the workpiece chain's end (its motion counts negatively: nest minus ball), the nest
    the tool chain's. A squareness turns the line of motion, moving P by q·(e × line).
    Only the frames are held, (n, 3, 3) and two (n, 3) an axis; a gain is made when asked.
    (``tests/test_kinematics.py`` checks every slot against central differences.)
    """

    def __init__(self, machine: Machine, poses: Poses):
        n = len(poses)
        zero = np.zeros((n, 6))
        self.n, self.frames = n, {}
        # the tool side's end is the nest, probe_length below its frames (see ``relative``)
        for chain, end, sign in ((machine.workpiece, poses.ball, -1.0),
                                 (machine.tool, np.broadcast_to([0.0, 0.0, -machine.probe_length], (n, 3)),
                                  1.0)):
            T = np.broadcast_to(np.eye(4), (n, 4, 4))
            before = []
            for axis in chain:
                q = poses.q[:, machine.index(axis.name)]
                # where a slot acts: the axis's reference point; a linear axis's carriage
                # (its component rotations) sits where its motion took it
                at = np.broadcast_to(np.asarray(axis.offset, float), (n, 3))
                if not axis.rotary:
                    at = at + (axis.sense * q)[:, None] * UNIT[axis.direction]
                before.append((axis, q, T[:, :3, :3].copy(), apply(T, at)))
                T = T @ _link(axis, q, zero, zero)
            P = apply(T, end)
            for axis, q, R, origin in before:
                self.frames[axis.name] = (sign, R, P - origin, axis, q)
            self.frames["ball" if chain is machine.workpiece else "nest"] = (sign, T[:, :3, :3].copy())

    def __call__(self, key: tuple[str, str, str]) -> np.ndarray:
        carrier, slot, direction = key
        k = SLOT_INDEX[direction]
        e = UNIT["xyz"[k % 3]]
        if carrier == "time":
            return np.broadcast_to(e * (k < 3), (self.n, 3)).copy()
        if carrier in ("ball", "nest"):
            sign, R = self.frames[carrier]
            return sign * (R @ e) * (k < 3)
        sign, R, lever, axis, q = self.frames[carrier]
        if k < 3:
            return sign * (R @ e)
        if not axis.rotary and slot == "loc":   # squareness: the line of motion turns
            return sign * (axis.sense * q)[:, None] * (R @ np.cross(e, UNIT[axis.direction]))
        return sign * np.cross(R @ e, lever)


def slot_gains(machine: Machine, poses: Poses, keys) -> dict[tuple[str, str, str], np.ndarray]:
    """``SlotGains`` of each key, as a dict."""
    gains = SlotGains(machine, poses)
    return {key: gains(key) for key in keys}


def _link(axis: Axis, q: np.ndarray, loc: np.ndarray, comp: np.ndarray, motion: bool = True,
          line: tuple | None = None) -> np.ndarray:
    """Transform of one axis frame in its parent, (n, 4, 4) (seed eqs. 1 and 2).

    Factors that are exactly zero are skipped: the model is evaluated ~2p times per
    Jacobian, and most parameters are zero in most slots. ``motion=False`` stops before the
    axis's own motion. ``line`` (offset, tilt) turns a rotary axis about that line instead:
    ``Trans(t)·Rot(r)·R(θ)·Rot(r)⁻¹·Trans(−t)``, the form a controller's kinematics holds.
    """
    offset = np.asarray(axis.offset)
    if axis.rotary:
        own = SLOT_INDEX[ROT_OF[axis.direction]]
        tilt = comp[:, 3:].copy()
        tilt[:, own - 3] = 0.0
        T = trans(offset + loc[:, :3])
        for factor, build in ((loc[:, 3:], rot_exact), (comp[:, :3], trans), (tilt, rot_exact)):
            if factor.any():
                T = T @ build(factor)
        if not motion:
            return T
        turn = rot_axis(axis.direction, axis.sense * q + comp[:, own])
        if line is not None:
            t, r = (np.asarray(v, float) for v in line)
            place = trans(t) @ rot_exact(r)
            turn = place @ turn @ np.linalg.inv(place)
        return T @ turn
    # squareness tilts the line of motion; the carriage itself turns only by its own
    # angular error motions
    line_dir = np.broadcast_to(UNIT[axis.direction], loc[:, :3].shape)
    if loc[:, 3:].any():
        line_dir = apply(rot_exact(loc[:, 3:]), line_dir)
    T = trans(offset + loc[:, :3] + comp[:, :3] + (axis.sense * q * motion)[:, None] * line_dir)
    return T @ rot_exact(comp[:, 3:]) if comp[:, 3:].any() else T


def _chain(machine: Machine, axes: Sequence[Axis], poses: Poses, slots: Mapping,
           zero: np.ndarray, lines: Mapping[str, tuple] | None = None) -> np.ndarray:
    T = np.broadcast_to(np.eye(4), (len(poses), 4, 4))
    for axis in axes:
        q = poses.q[:, machine.index(axis.name)]
        T = T @ _link(axis, q, slots.get((axis.name, "loc"), zero),
                      slots.get((axis.name, "comp"), zero), line=(lines or {}).get(axis.name))
    return T


def inverse(machine: Machine, rotary_rad: np.ndarray, ball: np.ndarray,
            lines: Mapping[str, tuple] | None = None,
            params: Mapping[str, float] | None = None) -> np.ndarray:
    """Nominal inverse kinematics, as a controller's TCPM/TRAORI would compute it.

    Parameters
    ----------
    rotary_rad : (n, r) rotary axis positions in ``machine.rotary_axes`` order, rad
    ball : (n, 3) or (3,) ball centre in the table frame, mm

    Returns
    -------
    q : (n, k) full commanded poses (mm, rad) that put the nest centre on the ball centre.

    For fixed rotary angles the nest-minus-ball vector is affine in the linear axes, so
    three unit steps give its matrix exactly, whatever the chain. ``lines`` gives the
    rotary axis lines a controller holds (``lines.py``), ``params`` (name → mm, rad) any
    constant errors it holds too, such as squareness: its TCPM solution.
    """
    rotary_rad = np.atleast_2d(np.asarray(rotary_rad, float))
    n = len(rotary_rad)
    ball = np.broadcast_to(np.asarray(ball, float), (n, 3))
    q = np.zeros((n, len(machine.axes)))
    linear = [i for i, a in enumerate(machine.axes) if not a.rotary]
    q[:, [i for i, a in enumerate(machine.axes) if a.rotary]] = rotary_rad
    held = Model(machine, list(params or {}))
    values = np.array(list((params or {}).values()))

    def rel(qq):
        return held.relative(Poses.at(qq, ball), values, lines=lines)

    r0 = rel(q)
    M = np.empty((n, 3, 3))
    for j, i in enumerate(linear):
        qi = q.copy()
        qi[:, i] += 1.0
        M[:, :, j] = rel(qi) - r0
    q[:, linear] = np.linalg.solve(M, -r0[..., None])[..., 0]
    return q
