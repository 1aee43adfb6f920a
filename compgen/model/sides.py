"""Which side each pose reached each rotary axis from: what a reversal (backlash) effect
needs. The sides the data record, the side each pose takes from its path's moves where
they do not (``FreeConstants``: one free constant for a path that holds an axis, beside
one offset for each mounting of the ball and each nest after the first), the sides
compgen's programs approach from, and whether an axis was seen from both."""

from __future__ import annotations

from collections.abc import Iterable
from functools import partial

import numpy as np

from .effects import Effect, effect_of_param
from .kinematics import SlotGains, effect_gains
from .machine import Machine
from .poses import Poses, last_moves, motion_direction, runs

SETUP = ("XOW", "YOW", "ZOW")      # the ball's offset: what every mounting of the ball has anew
NEST = ("nest_X", "nest_Y", "nest_Z")   # the nest's offset: what every nest put in the spindle has anew


def mountings(ball: np.ndarray, setup: np.ndarray | None = None) -> np.ndarray:
    """The mounting of the ball each pose was measured in (``ball``: the nominal centre per
    pose, (n, 3) mm, as ``Poses.ball``): 0 for the first, one more wherever the ball's
    position changes in the order taken (a ball moved is a ball mounted again, and one
    moved back is mounted again too), and wherever ``setup`` (``Poses.setup``) says it was
    mounted again. Poses at one position in a row share it, across files too, unless the
    user says otherwise: the ball was not touched between them."""
    new = np.any(ball[1:] != ball[:-1], axis=1)
    if setup is not None:
        new = new | (setup[1:] != setup[:-1])
    return np.cumsum(np.r_[False, new])


def nest_mountings(machine: Machine, nest: np.ndarray, setup: np.ndarray | None = None) -> np.ndarray:
    """The nest each pose was measured with (``nest``: its length per pose, NaN for the
    machine file's ``probe_length``, as ``Poses.nest``): 0 for the first, one more wherever
    the length changes in the order taken, or ``setup`` says the set-up was mounted again.
    A nest of another length is another nest, or the same on another holder: put in the
    spindle again, off the spindle's axis by what that clamping left."""
    length = np.where(np.isnan(nest), machine.probe_length, nest)
    new = length[1:] != length[:-1]
    if setup is not None:
        new = new | (setup[1:] != setup[:-1])
    return np.cumsum(np.r_[False, new])


def set_ups(machine: Machine, poses: Poses) -> tuple[np.ndarray, np.ndarray]:
    """The ball's mounting and the nest each pose was measured in (``mountings``,
    ``nest_mountings``), with the set-up events said of its files (``Poses.setup``)."""
    return mountings(poses.ball, poses.setup), nest_mountings(machine, poses.nest, poses.setup)


def continues(machine: Machine, before: Poses, after: Poses) -> tuple[bool, bool]:
    """Whether a measurement at ``after`` continues the last mounting of the ball and the
    last nest of ``before``, as ``mountings`` and ``nest_mountings`` number them: the ball
    where it was left, a nest of the same length."""
    return (bool(np.array_equal(after.ball[0], before.ball[-1])),
            not nest_mountings(machine, np.r_[before.nest[-1], after.nest[0]])[-1])


class FreeConstants:
    """The constants a fit carries beside its parameters and never reports:

    - each later mounting's ball offset (``mountings``): a ball mounted again sits off its
      nominal centre by whatever that mounting left, so where ``names`` hold the ball's
      offset (``SETUP``), the first mounting's is the parameter and each later one has its
      own, a translation of the table frame on that mounting's poses alone;
    - each later nest's offset (``nest_mountings``), a translation of the tool frame on its
      poses alone, where ``names`` hold the ball's offset too (a set-up's constants come with
      the set-up's parameters: a candidate's start sides alone bring none): the first
      nest's is in the location errors (or the model's ``NEST``);
    - the side of each run that holds an axis, where the data do not record it (no
      ``A_side`` column): for every reversal (backlash) effect among ``names`` and every run
      that never moves its axis, the effect's value there, ± half the reversal as the
      unknown approach left it.

    They are fitted beside the parameters (projected out, ``projector``: the estimates and
    their uncertainties are the joint fit's), so a path that holds an axis leaves no offset
    of its own behind, where it would look like drift, and a ball or nest mounted again
    leaves none that would look like an error motion."""

    def __init__(self, machine: Machine, names: Iterable[str], poses: Poses):
        self.machine, self.poses = machine, poses
        run = runs(poses)
        effects = list(dict.fromkeys(effect_of_param(machine, n) for n in names))
        self.labels: list[tuple[str, str]] = []            # (axis, path) per start side
        entries: list[tuple[Effect, np.ndarray]] = []
        for e in effects:
            if e.basis.kind != "r":
                continue
            j = machine.index(e.carrier)
            at = np.flatnonzero(np.isnan(poses.side[:, j]) & (motion_direction(poses.q[:, j], run) == 0))
            for idx in np.split(at, np.flatnonzero(np.diff(run[at])) + 1) if at.size else ():
                entries.append((e, idx))
                self.labels.append((e.carrier, str(poses.path[idx[0]])))
        ball = [e for e in effects if e.name in SETUP and e.basis.kind == "const"]
        nest = [effect_of_param(machine, n) for n in NEST] if ball else []
        self.mounts = self.nests = 0
        if ball and len(poses):
            mount, held = set_ups(machine, poses)
            self.mounts, self.nests = int(mount[-1]), int(held[-1])
            entries += [(e, np.flatnonzero(mount == k)) for k in range(1, self.mounts + 1) for e in ball]
            entries += [(e, np.flatnonzero(held == k)) for k in range(1, self.nests + 1) for e in nest]
        self.ball = len(ball)
        self.blocks = _disjoint(entries, len(poses))

    @property
    def count(self) -> int:
        return len(self.labels) + self.ball * self.mounts + len(NEST) * self.nests

    def projector(self, whiten=None) -> _Projector | None:
        """Removes from readings (n, 3) or their Jacobian (n, 3, p) what the constants would
        fit; ``whiten(idx, a)``, if given, whitens the rows ``idx`` of an (m, 3, …) array as
        the fit whitens its readings. None where there is no constant."""
        if not self.blocks:
            return None
        parts = []
        for block in self.blocks:
            idx = np.unique(np.concatenate([i for _, i in block]))
            gains, made = SlotGains(self.machine, self.poses.take(idx)), {}
            masks = [np.isin(idx, i).astype(float) for _, i in block]
            # a constant's column is its gain on its own rows only (a block holds the rows of
            # every constant that shares one with another)
            G = np.stack([effect_gains(gains, e, mask, made)[:, :, 0] * mask[:, None]
                          for (e, _), mask in zip(block, masks, strict=True)], axis=-1)     # (m, 3, c)
            Gw = (G if whiten is None else whiten(idx, G)).reshape(-1, G.shape[-1])
            parts.append((idx, G, span(Gw), Gw))
        return _Projector(parts)


def _disjoint(entries: list[tuple[Effect, np.ndarray]], n: int) -> list[list[tuple[Effect, np.ndarray]]]:
    """The constants (effect, rows) in blocks that share no row, those that share one in the
    same block (the projector takes block after block: only blocks apart make that the
    projection onto all the constants' columns at once), in the order of their first rows."""
    owner, groups = np.full(n, -1), {}
    for k, (_, idx) in enumerate(entries):
        joined = [k]
        for g in np.unique(owner[idx]).tolist():
            if g >= 0:
                joined += groups.pop(g)
        groups[k] = joined
        for m in joined:
            owner[entries[m][1]] = k
    blocks = [[entries[m] for m in sorted(members)] for members in groups.values()]
    return sorted(blocks, key=lambda block: min(int(i[0]) for _, i in block))


def span(G: np.ndarray) -> np.ndarray:
    """Orthonormal columns spanning G's (m, c) column space, to its rank (singular values
    above ``RANK_TOL`` of the largest), where columns may coincide in part: a ball's and a
    nest's offsets on a path where one axis turns (a translation along it is the same in the
    table's frame and the machine's), two of diagnose's effects. A QR factor would keep a
    column of rounding for each such direction."""
    U, s, _ = np.linalg.svd(G, full_matrices=False)
    return U[:, s > RANK_TOL * s[0]] if s.size and s[0] > 0 else G[:, :0]


RANK_TOL = 1e-9        # a singular value below this share of the largest is rounding


class _Projector:
    def __init__(self, parts):
        self.parts = parts

    @property
    def rank(self) -> int:
        """How many independent constants: what the fit's degrees of freedom lose."""
        return sum(Q.shape[1] for _, _, Q, _ in self.parts)

    def __call__(self, v: np.ndarray) -> np.ndarray:
        """``v`` (n, 3, …) whitened, less its part along the constants' columns (in place)."""
        for idx, _, Q, _ in self.parts:
            b = v[idx].reshape(len(idx) * 3, -1)
            v[idx] = (b - Q @ (Q.T @ b)).reshape(v[idx].shape)
        return v

    def basis(self, n: int) -> np.ndarray:
        """The constants' orthonormal columns over all ``n`` readings, (3n, k) in (n, 3) order."""
        out = np.zeros((n, 3, sum(Q.shape[1] for *_, Q, _ in self.parts)))
        k = 0
        for idx, _, Q, _ in self.parts:
            out[idx, :, k:k + Q.shape[1]] = Q.reshape(len(idx), 3, -1)
            k += Q.shape[1]
        return out.reshape(3 * n, -1)

    def remove(self, raw: np.ndarray, white: np.ndarray | None = None) -> np.ndarray:
        """The raw residual (n, 3) less the constants fitted to it (to ``white``, its whitened
        form, where readings are weighted): what the joint fit leaves."""
        out = raw.copy()
        white = raw if white is None else white
        for idx, G, _, Gw in self.parts:
            c = np.linalg.lstsq(Gw, white[idx].ravel(), rcond=RANK_TOL)[0]     # G c is unique, c need not be
            out[idx] -= G @ c
        return out


def same_pose(machine: Machine, poses: Poses, run: np.ndarray) -> np.ndarray:
    """A number per pose, equal for poses that repeat one another: the same commanded axes
    (to 1e-6 mm and 1e-6 deg, the CSV's resolution) and ball, every axis reached from the same
    side, so that no backlash counts as a repeat's scatter: the recorded side, else the move
    of its run (``run``, as ``runs`` numbers them) that reached it; a pose that no move of its
    run has reached yet repeats only poses of its own run. A pose measured after the set-up was
    said mounted again, or the ball turned on its stem, repeats only poses of that mounting."""
    scale = np.array([180.0 / np.pi if a.rotary else 1.0 for a in machine.axes])
    side = poses.side.copy()
    starts = np.flatnonzero(np.r_[True, run[1:] != run[:-1]])
    for j in range(len(machine.axes)):
        unknown = np.isnan(side[:, j])
        if not unknown.any():
            continue
        reached = np.empty(len(poses))
        for a, b in zip(starts, [*starts[1:], len(poses)], strict=True):
            reached[a:b] = last_moves(np.sign(np.diff(poses.q[a:b, j])), np.nan)
        side[:, j] = np.where(unknown, np.where(np.isnan(reached), 2.0 + run, reached), side[:, j])
    return _groups([*np.round(poses.q * scale * 1e6).T, *np.round(poses.ball * 1e6).T,
                    np.round(np.nan_to_num(poses.nest, nan=-1e-6) * 1e6), *side.T, poses.setup,
                    np.round(poses.turn * 1e6)])


def _groups(columns) -> np.ndarray:
    """A number per row, equal for rows equal in every column: each column's values numbered
    and the numbers combined, renumbered before they could overflow: a unique of the rows,
    each as one value, would sort a copy of them all (250 MB of new memory at 723 000 poses,
    this 50 MB)."""
    code, count = None, 1
    for c in columns:
        values, number = np.unique(c, return_inverse=True)
        if code is None:
            code, count = number.ravel().astype(np.int64), len(values)
            continue
        if count * len(values) >= 2**62:
            seen, code = np.unique(code, return_inverse=True)
            count = len(seen)
        code, count = code * len(values) + number.ravel(), count * len(values)
    return np.unique(code, return_inverse=True)[1].ravel()


def program_sides(machine: Machine, q: np.ndarray, run: np.ndarray) -> np.ndarray:
    """(n, k): the side of each rotary axis's backlash at each pose as compgen's programs
    take the poses (NaN for linear axes): a path's first pose is approached in the direction
    the axis first moves in the path (+ where it never moves; the other way where that
    approach would leave the travel), every later pose by the move that reached it
    (standing still keeps the side)."""
    out = np.full(q.shape, np.nan)
    starts = np.flatnonzero(np.r_[True, run[1:] != run[:-1]])
    for a in machine.rotary_axes:
        j = machine.index(a.name)
        lo, hi = np.radians(a.travel)
        for s, e in zip(starts, [*starts[1:], len(q)], strict=True):
            step = np.sign(np.diff(q[s:e, j]))
            moved = np.flatnonzero(step)
            first = step[moved[0]] if moved.size else 1.0
            if not lo <= q[s, j] - first * np.radians(APPROACH_DEG) <= hi:
                first = -first
            out[s:e, j] = last_moves(step, first)
    return out


def unknown_sides(machine: Machine, names: Iterable[str], *poses: Poses) -> str | None:
    """What a reversal (backlash) effect among the parameters ``names`` cannot use in these
    poses (each data set's, looked at where it is), said once: the axes whose side the data
    do not give at some pose (no ``A_side`` column), and the free constants that stand in
    for it (``FreeConstants``), or None."""
    reversals = [n for n in names if effect_of_param(machine, n).basis.kind == "r"]
    axes = sorted({e.carrier for e in map(partial(effect_of_param, machine), reversals)
                   if any(np.isnan(p.side[:, machine.index(e.carrier)]).any() for p in poses)})
    held = [lab for p in poses for lab in FreeConstants(machine, reversals, p).labels]
    # a linear axis's side no column can give: worth a word only where a path holds the
    # axis and a free constant stands in for it (elsewhere the moves say every side)
    # only a rotary axis's side has a column: compgen's reader takes it and its pose lists carry it
    rotary = [a for a in axes if a in {r.name for r in machine.rotary_axes}]
    linear = [a for a in axes if a not in rotary and any(b == a for b, _ in held)]
    axes = rotary + linear
    if not rotary:        # a linear axis's side alone: nothing the user can act on
        return None
    held = [(b, path) for b, path in held if b in axes]
    where = "; ".join(f"{a}: {', '.join(dict.fromkeys(path or '(no label)' for b, path in held if b == a))}"
                      for a in axes if any(b == a for b, _ in held))
    count = f"{len(held)} constant{'s' if len(held) != 1 else ''} ({where})" if held else "none here"
    cols = ", ".join(f"{a}_side" for a in rotary)
    asks = [f"measure with compgen's programs (their pose lists carry {cols}), or add the column"] \
        if rotary else []
    if linear:
        asks.append(f"no column records the side of {' or '.join(linear)} (a linear axis: compgen reads "
                    "none and its pose lists carry none), so its reversal rests on each path's moves")
    return (f"the data do not say from which side {' and '.join(axes)} reached each pose"
            + (f" (no {cols} column)" if rotary else "")
            + ": each pose takes the side of the move that reached it (a path's first poses, "
            f"that of its first move), and a path that holds the axis gets a free constant for its "
            f"side — {count}. " + "; ".join(asks)[:1].upper() + "; ".join(asks)[1:])


def unpredicted_sides(machine: Machine, names: Iterable[str], poses: Poses) -> str | None:
    """What ``predict`` cannot say at poses with no recorded side: paths that hold an axis
    are predicted without the model's reversal of it (its sign there is the unknown
    approach's), or None."""
    starts = FreeConstants(machine, names, poses)
    if not starts.labels:
        return None
    at = np.unique(np.concatenate([i for block in starts.blocks for e, i in block if e.basis.kind == "r"]))
    axes = " and ".join(dict.fromkeys(a for a, _ in starts.labels))
    paths = ", ".join(dict.fromkeys(p or "(no label)" for _, p in starts.labels))
    return (f"the pose list does not say from which side {axes} reached each pose: {len(at)} poses of "
            f"paths that hold it ({paths}) are predicted without the reversal (backlash) the fit "
            f"holds, whose sign there only the approach decides. compgen's pose lists "
            f"(measure-program) carry the sides")


def both_sides(machine: Machine, axis: str, *poses: Poses) -> bool:
    """Whether ``axis`` reaches poses from both directions in these poses together (where
    the data do not say, a path that turns the axis back within it shows both)."""
    j = machine.index(axis)
    seen = set()
    for p in poses:
        side = p.side[:, j]
        seen |= set(np.unique(side[~np.isnan(side)]).tolist())
        unknown = np.isnan(side)
        if unknown.any():
            d = motion_direction(p.q[:, j], runs(p))[unknown]
            seen |= set(np.unique(d[d != 0]).tolist())
    return {1.0, -1.0} <= seen


APPROACH_DEG = 1.0       # a program's approach to a path's first pose: far beyond any backlash
