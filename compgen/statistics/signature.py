"""First-order signatures of effects on poses: what a unit of each effect's parameters does
to every reading (basis × the gain of its slot in the chain), and the triangular factors of
their columns, stacked over poses a chunk at a time so that memory stays as fit's."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..model.effects import Effect
from ..model.kinematics import Poses, SlotGains, coordinate, effect_gains, fill_gains
from ..model.machine import Machine
from .noise import whiten

CHUNK_BYTES = 8 << 20  # the columns of every candidate held at once: ~800 poses of ~400 columns
BLOCK = 4096           # poses a walk of the chain serves: its slots' gains (~250 × 96 kB) held
BAND = 3              # cᵀc of effects of up to BAND parameters from C's rows' products with the next ones


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


def products(machine: Machine, poses: Poses, effects: Sequence[Effect], Q: np.ndarray | Sequence[np.ndarray],
             r: np.ndarray,
             noise: tuple[np.ndarray, np.ndarray] | None = None) -> dict[str, tuple]:
    """Each effect's first-order signature c, reduced to what diagnose needs of it: cᵀc
    (k × k), Qᵀc (p × k) and cᵀr (k), over blocks of poses: a dense session's columns are
    millions of rows, made a block at a time (the chain walked once a block, for every
    effect) and never held whole. ``Q`` (3n, p), or blocks of it side by side ([Q | more]
    without a copy of Q: 240 MB at 720 000 readings), and ``r`` (3n,) are in (n, 3) reading
    order. With ``noise`` = (segments, ρ (n, 3)), the columns are made white first
    (Prais–Winsten, carried from one block to the next), as Q and r must already be.

    A block's columns of every effect are made side by side, so that Qᵀc and cᵀr are one
    matrix product each (per effect they were memory-bound: 8 of diagnose's 36 s at 720 000
    readings), and a basis's values are made once for every effect sharing them."""
    def where(e):            # what an effect's coordinate depends on
        return (e.carrier, e.basis.kind) if e.basis.kind != "e" else ("time", "e")

    if not effects:          # every one's columns made before (diagnose's step 3): none to walk
        return {}
    coords: dict = {}
    for e in effects:        # on the whole session: a reversal's side depends on its run
        if where(e) not in coords:
            coords[where(e)] = coordinate(machine, e, poses)
    edges = np.cumsum([0, *(len(e.params) for e in effects)])
    K = int(edges[-1])
    Qs = [Q] if isinstance(Q, np.ndarray) else list(Q)     # [Q | more] without copying Q
    qc, cr = np.zeros((sum(q.shape[1] for q in Qs), K)), np.zeros(K)
    chunk = max(64, CHUNK_BYTES // (24 * max(K, 1)))
    band = np.zeros((BAND, K))          # Σ cᵢ·cᵢ₊d: cᵀc of every effect of up to BAND params
    wide = {i: 0.0 for i, e in enumerate(effects) if len(e.params) > BAND}   # the others' own
    carry = None
    n = len(poses)
    for a in range(0, n, BLOCK):
        gains, made = SlotGains(machine, poses.take(slice(a, min(a + BLOCK, n)))), {}
        for b in range(a, min(a + BLOCK, n), chunk):     # columns a chunk at a time: memory
            at = slice(b, min(b + chunk, n, a + BLOCK))
            local = slice(at.start - a, at.stop - a)
            C = np.empty((K, at.stop - at.start, 3))     # an effect's columns side by side
            values: dict = {}
            for e, lo, hi in zip(effects, edges[:-1], edges[1:], strict=True):
                key = (where(e), e.basis)
                if key not in values:
                    values[key] = e.basis.values(coords[where(e)][at])
                fill_gains(C[lo:hi], gains, e, values[key], made, local)
            if noise is not None:
                seg, rho = noise
                before, carry = carry, (C[:, -1].T.copy(), seg[at.stop - 1])
                C = np.ascontiguousarray(whiten(C.transpose(1, 2, 0), seg[at], rho[at], before)
                                         .transpose(2, 0, 1))
            C = C.reshape(K, -1)
            rows = slice(3 * at.start, 3 * at.stop)
            qc += np.vstack([(C @ q[rows]).T for q in Qs])
            cr += C @ r[rows]
            for d in range(BAND):
                band[d, :K - d] += np.einsum("ij,ij->i", C[:K - d], C[d:])
            for i in wide:
                lo, hi = edges[i], edges[i + 1]
                wide[i] = wide[i] + C[lo:hi] @ C[lo:hi].T
    out = {}
    for i, (e, lo, hi) in enumerate(zip(effects, edges[:-1], edges[1:], strict=True)):
        cc = wide.get(i)
        if cc is None:
            k = hi - lo
            cc = np.zeros((k, k))
            for d in range(k):          # the d-th diagonal above and below
                i_, j_ = np.arange(k - d), np.arange(d, k)
                cc[i_, j_] = cc[j_, i_] = band[d, lo:hi - d]
        out[e.name] = (np.asarray(cc), qc[:, lo:hi], cr[lo:hi])
    return out
