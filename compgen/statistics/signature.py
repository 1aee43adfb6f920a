"""First-order signatures of effects on poses: what a unit of each effect's parameters does
to every reading (basis × the gain of its slot in the chain), and the triangular factors of
their columns, stacked over poses a chunk at a time so that memory stays as fit's."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..model.effects import Effect
from ..model.kinematics import BLOCK, Poses, SlotGains, coordinate, effect_gains
from ..model.machine import Machine
from .noise import whiten


def signatures(machine: Machine, poses: Poses, effects: Sequence[Effect]):
    """Each effect with its first-order signature, (3n, its params) mm per unit, one at a
    time, so that only the chain's frames and one effect's columns are held."""
    gains, made = SlotGains(machine, poses), {}
    for e in effects:
        yield e, effect_gains(gains, e, coordinate(machine, e, poses), made).reshape(-1, len(e.params))


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


def products(machine: Machine, poses: Poses, effects: Sequence[Effect], Q: np.ndarray, r: np.ndarray,
             noise: tuple[np.ndarray, np.ndarray] | None = None) -> dict[str, tuple]:
    """Each effect's first-order signature c, reduced to what diagnose needs of it: cᵀc
    (k × k), Qᵀc (p × k) and cᵀr (k), over blocks of poses: a dense session's columns are
    millions of rows, made a block at a time (the chain walked once a block, for every
    effect) and never held whole. ``Q`` (3n, p) and ``r`` (3n,) are in (n, 3) reading
    order. With ``noise`` = (segments, ρ (n, 3)), the columns are made white first
    (Prais–Winsten, carried from one block to the next), as Q and r must already be."""
    def where(e):            # what an effect's coordinate depends on
        return (e.carrier, e.basis.kind) if e.basis.kind != "e" else ("time", "e")

    coords: dict = {}
    for e in effects:        # on the whole session: a reversal's side depends on its run
        if where(e) not in coords:
            coords[where(e)] = coordinate(machine, e, poses)
    out = {e.name: [0.0, 0.0, 0.0] for e in effects}
    carry: dict = {}
    n = len(poses)
    for a in range(0, n, BLOCK):
        at = slice(a, min(a + BLOCK, n))
        gains, made = SlotGains(machine, poses.take(at)), {}
        rows = slice(3 * at.start, 3 * at.stop)
        Qb, rb = Q[rows], r[rows]
        for e in effects:
            c = effect_gains(gains, e, coords[where(e)][at], made)
            if noise is not None:
                seg, rho = noise
                before = carry.get(e.name)
                carry[e.name] = (c[-1].copy(), seg[at.stop - 1])
                c = whiten(c, seg[at], rho[at], before)
            c = c.reshape(-1, len(e.params))
            acc = out[e.name]
            acc[0] = acc[0] + c.T @ c
            acc[1] = acc[1] + Qb.T @ c
            acc[2] = acc[2] + c.T @ rb
    return {name: tuple(np.asarray(v) for v in acc) for name, acc in out.items()}
