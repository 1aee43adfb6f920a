"""The commanded poses of R-test and probe sessions (``Poses``), and the runs they fall into:
where one continuous run of a path ends, and which way each axis last moved in it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

FIELDS = ("q", "ball", "t", "path", "side", "nest", "setup", "turn")     # Poses' arrays, one row per pose


def _frozen(a) -> bool:
    """Whether nobody can change ``a``: an array read-only, and every array it views as well
    (another Poses' field, or a view of one, is taken as it is, not copied: a session's
    poses are 100 MB at 723 000 readings)."""
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        a = a.base
    return a is None


@dataclass(frozen=True, eq=False)
class Poses:
    """Commanded poses of one or more R-test sessions.

    q : (n, k) commanded axis positions, mm and rad, columns in ``machine.axis_names`` order
    ball : (n, 3) nominal ball centre in the table frame, mm
    t : (n,) time since the start of the session, s (NaN where not recorded)
    path : (n,) path label of each pose
    side : (n, k) per axis, the direction it last moved before the pose was taken (+1, −1):
        the side of its backlash; NaN where the data do not say (default: nowhere)
    nest : (n,) the nest centre's distance below the spindle's gauge line, mm, where a
        session used another nest than the machine file's ``probe_length`` (NaN: that one).
        On a head it is the lever of the head's angles: two lengths tell an angle at the
        pivot from a translation (a head's sag)
    setup : (n,) int, a count of the set-up events said of the poses' files: where it changes
        the ball and the nest were taken off and mounted again (at the same place too), as a
        user says it (``fit --mounted-again``); 0 throughout where nothing was said
    turn : (n,) rad, how far the ball was turned on its stem since the first of the poses'
        files, as a user says it (``fit --ball-turned``): its form turns with it, the machine
        does not
    """

    q: np.ndarray
    ball: np.ndarray
    t: np.ndarray
    path: np.ndarray
    side: np.ndarray | None = None
    nest: np.ndarray | None = None
    setup: np.ndarray | None = None
    turn: np.ndarray | None = None

    def __post_init__(self):
        if self.side is None:
            object.__setattr__(self, "side", np.full(np.shape(self.q), np.nan))
        if self.nest is None:
            object.__setattr__(self, "nest", np.full(len(self.q), np.nan))
        if self.setup is None:
            object.__setattr__(self, "setup", np.zeros(len(self.q), int))
        if self.turn is None:
            object.__setattr__(self, "turn", np.zeros(len(self.q)))
        for field in FIELDS:
            a = getattr(self, field)
            if not _frozen(a):
                a = np.array(a)                  # a copy: freezing must not touch the caller's
                a.setflags(write=False)
            object.__setattr__(self, field, a)

    def __len__(self) -> int:
        return len(self.q)

    def take(self, index) -> Poses:
        # the fields are frozen: a slice of them is a frozen view, fancy indexing a fresh
        # array; neither needs the copy the constructor makes of a caller's arrays (copying
        # the path labels was a tenth of predict's time at a million poses)
        out = object.__new__(Poses)
        for field in FIELDS:
            a = getattr(self, field)[index]
            a.setflags(write=False)
            object.__setattr__(out, field, a)
        return out

    def starting_at(self, t0: float) -> Poses:
        """These poses with their clock moved so that the first is read at ``t0`` s: a
        measurement made after others, the R-test's clock running on."""
        return Poses(self.q, self.ball, self.t - self.t[0] + t0, self.path, self.side, self.nest, self.setup,
                     self.turn)

    @staticmethod
    def at(q: np.ndarray, ball, nest: np.ndarray | None = None) -> Poses:
        """Poses with no time and no path label: ``ball`` (3,) or (n, 3) mm."""
        n = len(q)
        return Poses(q, np.broadcast_to(np.asarray(ball, float), (n, 3)), np.full(n, np.nan),
                     np.full(n, "", dtype=object), nest=nest)

    def with_setup(self, count: int, turn: float = 0.0) -> Poses:
        """These poses with ``count`` set-up events said before them (``setup``), the ball
        turned ``turn`` rad on its stem since the first file (``turn``)."""
        return Poses(self.q, self.ball, self.t, self.path, self.side, self.nest, np.full(len(self), count),
                     np.full(len(self), turn))

    @staticmethod
    def concat(items: Sequence[Poses]) -> Poses:
        if len(items) == 1:      # the same poses: what is known of them (their nominal) holds
            return items[0]
        return Poses(*(np.concatenate([getattr(p, f) for p in items]) for f in FIELDS))


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


def last_moves(step: np.ndarray, first: float) -> np.ndarray:
    """Per pose of a run, the sign of the last move that reached it (``step``: the signs of
    its n − 1 moves); ``first`` before any move. Standing still keeps the last move's sign."""
    last = np.maximum.accumulate(np.where(step != 0, np.arange(len(step)), -1))
    return np.r_[first, np.where(last >= 0, step[np.maximum(last, 0)], first)]


def motion_direction(q: np.ndarray, run: np.ndarray) -> np.ndarray:
    """The side of a reversal each pose is on, by the motion that reached it: ±1 by the
    direction the axis last moved within its run (poses in the order taken; standing still
    keeps it); the poses before its first move take that move's direction, as a program
    approaches a path's start (compgen's do: ``program_sides``); 0 throughout a run that
    never moves the axis, whose side only the approach decides: one free constant per such
    run (``FreeConstants``)."""
    out = np.zeros(len(q))
    starts = np.flatnonzero(np.r_[True, run[1:] != run[:-1]])
    for a, b in zip(starts, [*starts[1:], len(q)], strict=True):
        step = np.sign(np.diff(q[a:b]))
        moved = np.flatnonzero(step)
        if moved.size:
            out[a:b] = last_moves(step, step[moved[0]])
    return out
