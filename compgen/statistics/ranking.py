"""Each candidate's numbers on one diagnosis's data: its first-order columns (with the
start sides ``fit --add`` would fit with a reversal), what the model absorbs of it, the
residual it removes, plain and made white, and the condition of the model with it.

Everything is computed from the columns' products with the model's Q and the residual
(``signature.products``), never from the stacked Jacobian: see ``docs/diagnose.md``."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..model.effects import Effect
from ..model.machine import Machine
from ..model.poses import Poses
from ..model.sides import FreeConstants
from .noise import whiten
from .signature import columns
from .significance import VISIBLE, condition, explained, gram_factor

ABSORBS = 0.25        # share of an effect's signature a parameter must take to be named
SILENT_UM = 1e-9      # µm per unit over all readings: the effect moves nothing at all


def beyond_starts(cc: np.ndarray, qc: np.ndarray, m: int) -> np.ndarray:
    """The visibility of a reversal's own m columns beyond the model and its start sides (the
    columns after them), from products: ‖c⊥‖/‖c‖ with c⊥ orthogonal to both. A reversal
    whose side is the same throughout is its axis's zero offset: its constants and the
    location errors take it whole, whatever its columns alone would show."""
    P = cc - qc.T @ qc
    S = P[:m, :m] - P[:m, m:] @ np.linalg.lstsq(P[m:, m:], P[m:, :m], rcond=None)[0]
    norms = np.sqrt(np.diag(cc)[:m])
    return np.where(norms > 0, np.sqrt(np.clip(np.diag(S), 0, None)) / np.where(norms > 0, norms, 1), 0.0)


def without_b(R: np.ndarray, qj: np.ndarray, cc: np.ndarray, m: int) -> np.ndarray:
    """The Gram matrix of X = [J | c] less its part along a candidate's start sides B, from
    products alone: J = Q_J R and C = [c | B] with qj = Q_Jᵀ C, cc = CᵀC."""
    XX = np.block([[R.T @ R, R.T @ qj[:, :m]], [qj[:, :m].T @ R, cc[:m, :m]]])
    XB = np.vstack([R.T @ qj[:, m:], cc[:m, m:]])
    return XX - XB @ np.linalg.lstsq(cc[m:, m:], XB.T, rcond=None)[0]


def started_reversals(machine: Machine, poses: Poses, effects: Sequence[Effect]) -> dict[str, np.ndarray]:
    """The reversal candidates that come with start sides on these poses (data without the
    axis's side), by name: their columns as ``effect_columns`` makes them, from one walk of
    the chains for all of them (``signature.columns``)."""
    sides = {e.name: FreeConstants(machine, e.params, poses) for e in effects if e.basis.kind == "r"}
    started = [e for e in effects if e.name in sides and sides[e.name].count]
    if not started:
        return {}
    at = np.cumsum([len(e.params) for e in started])[:-1]
    made = np.split(columns(machine, poses, started), at, axis=1)
    return {e.name: np.hstack([c, sides[e.name].projector().basis(len(poses))])
            for e, c in zip(started, made, strict=True)}


def effect_columns(machine: Machine, poses: Poses, e: Effect) -> np.ndarray:
    """An effect's first-order columns (3n, m); for a reversal on data that do not say each
    pose's side, followed by the start sides ``fit --add`` fits with it (``FreeConstants``): so
    what diagnose tries is what fit would fit."""
    c = columns(machine, poses, [e])
    starts = FreeConstants(machine, e.params, poses).projector() if e.basis.kind == "r" else None
    return c if starts is None else np.hstack([c, starts.basis(len(poses))])



@dataclass(frozen=True)
class Row:
    """One candidate's numbers: unwhitened (visibility, what the model absorbs, RMS after,
    the condition of the model with it) and whitened (what the test and the ranking use)."""

    effect: Effect
    vis: float
    drop: float
    drop_w: float
    share: float
    k_eff: int
    amp: np.ndarray
    names: tuple[str, ...]
    silent: bool
    norms: np.ndarray
    absorbed: np.ndarray
    cond: float


class Whitening:
    """The whitening of one diagnosis: segments, ρ per reading and direction, and the Q of
    the model's whitened Jacobian (QR). With ρ = 0 everywhere it is the identity."""

    def __init__(self, seg: np.ndarray, rho: np.ndarray, Q: np.ndarray):
        self.seg, self.rho = seg, rho
        self.Q = np.linalg.qr(self.white(Q))[0] if rho.any() else Q     # whitening keeps the span
        self._made: tuple = (None, None)

    def white(self, x: np.ndarray) -> np.ndarray:
        """(3n,) or (3n, k), readings in (n, 3) order, made white."""
        if not self.rho.any():
            return x
        return whiten(x.reshape(len(self.seg), 3, *x.shape[1:]), self.seg, self.rho).reshape(x.shape)

    def off(self, v: np.ndarray) -> np.ndarray:
        """What the whitened model cannot absorb of whitened v."""
        return v - self.Q @ (self.Q.T @ v)

    def residual(self, r: np.ndarray) -> np.ndarray:
        """r made white and off the whitened model: a diagnosis tests every candidate against
        its one residual, so the last one asked for is kept (0.05 s a time at 723 000 readings)."""
        if self._made[0] is not r:
            self._made = (r, self.off(self.white(r)))
        return self._made[1]

    def rss(self, r: np.ndarray) -> float:
        rw = self.residual(r)
        return float(rw @ rw)


def rank(effects: Sequence[Effect], free: Sequence[str], R: np.ndarray, r: np.ndarray, noise: Whitening,
          plain: dict, white: dict | None = None) -> dict[str, Row]:
    """Every candidate's numbers from its columns' products (``signature.products``):
    ``plain`` with the model's Q and the residual, ``white`` the same made white (with
    the whitened model's Q and residual) when the noise is correlated."""
    J_norm = np.linalg.norm(R, axis=0)
    rw = noise.residual(r)
    rss_w = float(rw @ rw)
    out = {}
    for e in effects:
        cc, qc, cr = plain[e.name]
        m = len(e.params)           # columns beyond them: a reversal's start sides (``effect_columns``)
        norms = np.sqrt(np.diag(cc))
        vis_cols, drop, amp = explained(cc, qc, cr)
        keep = vis_cols >= VISIBLE
        starts = np.zeros(len(cr), bool)
        if len(cr) > m:        # a reversal is seen only beyond the model and its start sides
            vis_cols[:m] = beyond_starts(cc, qc, m)
            keep = (vis_cols >= VISIBLE) & bool((vis_cols[:m] >= VISIBLE).any())
            _, drop, amp = explained(cc, qc, cr, keep)
            starts[m:] = keep[m:]
        drop_w = drop
        if white is not None and keep.any():
            _, drop_w, _ = explained(*white[e.name], keep)
        if starts.any():
            # tested on its own columns: what the start sides' free constants remove alone (a
            # set-up or a drift that steps from path to path) is no reversal of the axis
            drop_w -= explained(*(white[e.name] if white is not None else (cc, qc, cr)), starts)[1]
            drop_w = max(drop_w, 0.0)
        qj = qc[len(qc) - len(R):]                    # Q's columns of J (start sides first)
        absorbed = np.linalg.solve(R, qj[:, :m])      # J⁺c: what each parameter takes
        vis_cols, amp, norms = vis_cols[:m], amp[:m], norms[:m]
        size = max(float(np.linalg.norm(norms)), 1e-300)
        share = np.sqrt(np.sum((absorbed * J_norm[:, None]) ** 2, axis=1)) / size
        names = tuple(free[i] for i in np.argsort(-share) if share[i] >= ABSORBS)
        # R of [J | c] is [[R, Qᵀc], [0, R of c⊥]]: fit --add's condition number, cheaply;
        # with start sides B, that of [J | c] without its part along B, as fit projects them
        joined = np.block([[R, qj], [np.zeros((m, R.shape[1])), gram_factor(cc - qc.T @ qc)]]) \
            if len(cr) == m else gram_factor(without_b(R, qj, cc, m))
        out[e.name] = Row(e, float(vis_cols.max()), drop, drop_w, drop_w / max(rss_w, 1e-300),
                           int(keep[:m].sum()), amp, names, bool(np.all(norms * 1e3 < SILENT_UM)),
                           norms, absorbed, condition(joined))
    return out
