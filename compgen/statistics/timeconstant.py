"""A saturating effect's time constant fitted, not only taken from the catalogue's grid.

The catalogue offers each effect in time that saturates (``eN``: 1 − exp(−t/τ), τ = N min)
at τ = 5, 15 and 45 min (``TAUS_MIN``). A warming whose τ lies between them (8 or 30 min)
is taken by the nearest, or by two of them added as equivalents, and the location errors
can end beyond their σ of the truth. Where diagnose's best candidate is such an effect, its
τ is searched over ``TAU_RANGE_MIN`` on the residual: the effect's columns are its slot's
gain times the time basis, so one walk of the chains serves every τ. Where a τ removes more
than the grid's best τ of that effect by what one more parameter would remove by chance in
fewer than ``alpha`` of data sets (χ²₁ of the whitened residual's variance), τ is the data's:
every saturating candidate is tried at that τ (whole minutes) in place of the grid's, which
are the same effects at a worse τ (and two equivalent at one τ stay told as equivalent)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..model.effects import TAUS_MIN, TIME_SCALE_S, Effect, resolve
from ..model.machine import Machine
from .ranking import Row, Whitening, effect_columns, rank
from .significance import VISIBLE, chi2_sf, explained

TAU_RANGE_MIN = (1.0, 999.0)       # what an effect's name can carry (eN, N whole minutes)
SCAN = 48                          # τ on a log grid over the range, then refined between neighbours


def _basis(t_h: np.ndarray, tau_min: float) -> np.ndarray:
    return 1.0 - np.exp(-t_h * (60.0 / tau_min))


def refined(machine: Machine, effects: Sequence[Effect], ranked: dict[str, Row], res, noise: Whitening,
            free: Sequence[str], alpha: float) -> tuple[list[Effect], dict[str, Row], dict[str, np.ndarray]]:
    """``effects`` and ``ranked`` with the best candidate's τ fitted where it is a saturating
    effect and another τ explains significantly more; with the columns made for it."""
    effects = list(effects)
    best = max(ranked.values(), key=lambda row: (row.vis >= VISIBLE, row.share)).effect
    if best.basis.kind != "e" or np.isnan(res.poses.t).any():
        return effects, ranked, {}
    grid = [e for e in effects if e.symbol == best.symbol and e.basis.kind == "e"]
    t_h = res.poses.t / TIME_SCALE_S
    g = np.repeat(_basis(t_h, best.basis.order), 3)
    c = effect_columns(machine, res.poses, best)
    gain = np.divide(c, g[:, None], out=np.zeros_like(c), where=g[:, None] > 0)   # τ-free
    rw = noise.residual(res.r)

    def drop(tau: float) -> float:
        cw = noise.white(gain * np.repeat(_basis(t_h, tau), 3)[:, None])
        return explained(cw.T @ cw, noise.Q.T @ cw, cw.T @ rw)[1]

    taus = np.geomspace(*TAU_RANGE_MIN, SCAN)
    drops = [drop(tau) for tau in taus]
    k = int(np.argmax(drops))
    lo, hi = np.log(taus[max(k - 1, 0)]), np.log(taus[min(k + 1, SCAN - 1)])
    for _ in range(20):                  # golden section on log τ between the neighbours
        a, b = hi - 0.618 * (hi - lo), lo + 0.618 * (hi - lo)
        lo, hi = (lo, b) if drop(np.exp(a)) >= drop(np.exp(b)) else (a, hi)
    tau = float(np.clip(round(np.exp((lo + hi) / 2)), *TAU_RANGE_MIN))
    on_grid = max(drop(float(e.basis.order)) for e in grid)
    dof = rw.size - noise.Q.shape[1]
    sigma2 = float(rw @ rw) / max(dof, 1)
    if tau in TAUS_MIN or chi2_sf((drop(tau) - on_grid) / max(sigma2, 1e-300), 1) >= alpha:
        return effects, ranked, {}
    # the data's time constant: every saturating candidate at it, in place of the grid's (two
    # effects equivalent at one τ stay equivalent at the other, and are told as such)
    grids: dict[str, list[Effect]] = {}
    for e in effects:
        if e.basis.kind == "e":
            grids.setdefault(e.symbol, []).append(e)
    fitted = [resolve(machine, f"{sym}:e{tau:g}") for sym in grids]
    made = {e.name: effect_columns(machine, res.poses, e) for e in fitted}
    plain = {n: (C.T @ C, res.Q.T @ C, C.T @ res.r) for n, C in made.items()}
    white = None
    if noise.rho.any():
        whitened = {n: noise.white(C) for n, C in made.items()}
        white = {n: (Cw.T @ Cw, noise.Q.T @ Cw, Cw.T @ rw) for n, Cw in whitened.items()}
    rows = rank(fitted, free, res.R, res.r, noise, plain, white)
    first = {sym: effects.index(group[0]) for sym, group in grids.items()}
    out = []
    for i, e in enumerate(effects):
        if e.basis.kind != "e":
            out.append(e)
        elif first[e.symbol] == i:
            out.append(next(f for f in fitted if f.symbol == e.symbol))
    return out, {**ranked, **rows}, made
