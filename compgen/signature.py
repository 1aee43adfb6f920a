"""First-order signatures of effects on poses: what a unit of each effect's parameters does
to every reading (basis × the gain of its slot in the chain), and the triangular factors of
their columns, stacked over poses a chunk at a time so that memory stays as fit's."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .effects import Effect
from .kinematics import Poses, SlotGains, coordinate
from .machine import Machine


def signatures(machine: Machine, poses: Poses, effects: Sequence[Effect]):
    """Each effect with its first-order signature, (3n, its params) mm per unit, one at a
    time, so that only the chain's frames and one effect's columns are held."""
    gains = SlotGains(machine, poses)
    for e in effects:
        c = 0.0
        for direction, b in e.parts(coordinate(machine, e, poses)):
            c = c + gains((e.carrier, e.slot, direction))[:, :, None] * b[:, None, :]
        yield e, c.reshape(-1, len(e.params))


def columns(machine: Machine, poses: Poses, effects: Sequence[Effect]) -> np.ndarray:
    """First-order signatures of the effects' parameters, (3n, Σ params), mm per unit, in
    the order of ``effects``."""
    return np.column_stack([c for _, c in signatures(machine, poses, effects)])


def r_factor(machine: Machine, poses: Poses, effects: Sequence[Effect],
              start: np.ndarray | None = None, chunk: int = 4096) -> np.ndarray:
    """R of the QR factorisation of the effects' columns on ``poses`` stacked under ``start``."""
    R = start
    for i in range(0, len(poses), chunk):
        block = columns(machine, poses.take(slice(i, i + chunk)), effects)
        R = np.linalg.qr(block if R is None else np.vstack([R, block]), mode="r")
    return R
