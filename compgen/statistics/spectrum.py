"""The residual's strongest periodic lines: against each linear axis's position (a pitch in
mm: ball-screw and scale periods), each rotary axis's angle (per revolution) and the
session's time. Where no catalogue effect explains what is left, this is its shape, and
the pitch a user declares (``EXX:w5``) comes from here.

Each line is the least-squares sine of one period (two columns and a constant) in one
reading direction, jointly with the model (the part of the sine the model's parameters
would absorb is taken out of its columns, as diagnose does for every candidate), tried over
a grid twice as fine as the data resolve and refined at the best; its F test is
Bonferroni-corrected over the periods the grid resolves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.machine import Machine
from ..model.poses import Poses
from ..search import golden_least
from .significance import f_sf, said_p

MIN_PITCH_MM = 2.0     # shorter periods: below what R-test paths sample along an axis
MIN_PERIOD_S = 60.0    # shorter periods in time: an R-test reads settled poses, not vibration
MAX_ORDER = 36         # per revolution
OVERSAMPLE = 2         # the grid's frequencies per resolved one (the peak is refined after)
CELLS = 500_000        # poses × frequencies evaluated at once (8 MB of complex phasors)
SEEN = 0.1             # a line whose pair the model absorbs beyond 1 − this (of its sum of squares) is
                       # not one: its amplitude would be the model's to take
SCAN_POSES = 12_000    # a denser session is scanned and its peak refined at this many poses, evenly
                       # spread in the order taken; every figure of the line is computed on all


@dataclass(frozen=True)
class Line:
    """A periodic line in the residual: its direction, what it runs against (an axis or time),
    its period and amplitude, the share of the residual it removes and its p-value."""

    against: str          # an axis name, or "time"
    direction: str        # "dX", "dY" or "dZ"
    period: float         # mm (linear axis), an order per revolution (rotary), s (time)
    unit: str             # "mm", "/rev" or "s"
    amplitude_um: float
    share: float          # of the residual sum of squares (all directions) the line removes
    p_value: float        # Bonferroni over the periods the grid resolves
    sum_sq: float = 0.0   # the residual sum of squares it removes, mm²

    def text(self) -> str:
        per = (f"pitch {self.period:.3f} mm" if self.unit == "mm" else
               f"{self.period:g}/rev" if self.unit == "/rev" else f"period {self.period:.0f} s")
        return (f"{self.direction} against {self.against}: {per}, amplitude {self.amplitude_um:.2f} µm, "
                f"removes {self.share:.0%} of the residual ({said_p(self.p_value)})")

    def to_dict(self) -> dict:
        return {"against": self.against, "direction": self.direction, "period": self.period,
                "unit": self.unit, "amplitude_um": self.amplitude_um, "share": self.share,
                "p_value": self.p_value, "sum_sq_um2": self.sum_sq * 1e6}


def strongest_lines(machine: Machine, poses: Poses, r: np.ndarray, Q: np.ndarray | None = None
                    ) -> tuple[Line, ...]:
    """The strongest line against every coordinate (its best direction), strongest share
    first; ``r`` is the residual (n, 3), mm, and ``Q`` (3n, p) the model's orthonormal
    columns, readings in (n, 3) order (the residual is orthogonal to them)."""
    Qd = None if Q is None else Q.reshape(len(r), 3, -1).transpose(1, 0, 2)    # (3, n, p)
    scan = _Scan(r, Qd)
    out = []
    for axis in machine.axes:
        x = poses.q[:, machine.index(axis.name)]
        if axis.rotary:
            if np.ptp(x) > 0:
                out.append(_best(axis.name, x, r, Qd, np.arange(1, MAX_ORDER + 1) / (2 * np.pi), "/rev",
                                 lambda f: f * 2 * np.pi, scan, refine=False))
        elif np.ptp(x) >= 4 * MIN_PITCH_MM:
            span = np.ptp(x)
            grid = np.arange(2 / span, 1 / MIN_PITCH_MM, 1 / (OVERSAMPLE * span))
            out.append(_best(axis.name, x, r, Qd, grid, "mm", lambda f: 1 / f, scan))
    t = poses.t
    if np.isfinite(t).all() and np.ptp(t) > 0:
        span = np.ptp(t)
        grid = np.arange(2 / span, 1 / MIN_PERIOD_S, 1 / (OVERSAMPLE * span))
        if grid.size:
            out.append(_best("time", t, r, Qd, grid, "s", lambda f: 1 / f, scan))
    return tuple(sorted((line for line in out if line is not None), key=lambda line: -line.share))


class _Scan:
    """The poses the grid is scanned at: all of them, or for a dense session ``SCAN_POSES``
    evenly spread, with the model's columns made orthonormal again on them. The scan only
    finds the period; the line's sum of squares, amplitude and p-value use all the poses."""

    def __init__(self, r: np.ndarray, Qd: np.ndarray | None):
        n = len(r)
        self.at = slice(None) if n <= SCAN_POSES else np.unique(np.linspace(0, n - 1, SCAN_POSES).astype(int))
        y = r[self.at]
        self.y = y - y.mean(axis=0)
        self.Qd = None if Qd is None else (
            Qd if n <= SCAN_POSES else np.stack([np.linalg.qr(Qd[d][self.at])[0] for d in range(3)]))
        if Qd is not None and n > SCAN_POSES:    # the residual as the model on these poses leaves it
            y = np.column_stack([self.y[:, d] - self.Qd[d] @ (self.Qd[d].T @ self.y[:, d]) for d in range(3)])
            self.y = y - y.mean(axis=0)


def _best(against: str, x: np.ndarray, r: np.ndarray, Qd: np.ndarray | None, grid: np.ndarray, unit: str,
          period, scan: _Scan, refine: bool = True) -> Line | None:
    if grid.size == 0:
        return None
    y = r - r.mean(axis=0)
    rss = float(np.sum(r**2))
    xs = x[scan.at]
    chunk = max(8, CELLS // len(xs))      # memory as fit's, however dense the session
    drops = np.concatenate([_drops(xs, scan.y, grid[i:i + chunk], scan.Qd)
                            for i in range(0, grid.size, chunk)])
    k, d = np.unravel_index(int(np.argmax(drops)), drops.shape)
    f = grid[k]
    if refine:           # the grid's neighbours bracket the peak: golden-section between them
        Qk = None if scan.Qd is None else scan.Qd[[d]]
        lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
        f = golden_least(lambda v: -_drops(xs, scan.y[:, [d]], v, Qk)[:, 0], np.array([lo]), np.array([hi]),
                         1e-6 * f)[0][0]
    drop, amp = _fit(x, y[:, d], f, None if Qd is None else Qd[d])
    tried = grid.size / OVERSAMPLE if refine else grid.size
    F = (drop / 2) / max((rss - drop) / (r.size - 3), 1e-300)
    return Line(against, f"d{'XYZ'[d]}", float(period(f)), unit, amp * 1e3,
                float(drop / rss) if rss > 0 else 0.0, min(1.0, f_sf(F, 2, r.size - 3) * max(tried, 1)),
                float(drop))


def _drops(x: np.ndarray, y: np.ndarray, f: np.ndarray, Qd: np.ndarray | None) -> np.ndarray:
    """(len(f), y's columns): the sum of squares a centred cos/sin pair of each frequency
    (an evenly spaced run) removes from each column of ``y`` (centred), with the part the
    model's columns ``Qd`` (one (n, p) block per column of y) would absorb taken out."""
    E = np.empty((len(x), len(f)), complex)
    E[:, 0] = np.exp(2j * np.pi * f[0] * x)
    if len(f) > 1:       # the next frequency's phasor is this one's times a fixed step
        E[:, 1:] = np.exp(2j * np.pi * (f[1] - f[0]) * x)[:, None]
    E = np.cumprod(E, axis=1)
    # the centred pair's sums from E's: Σ C² = (n + Re Σ E²)/2, Σ S² = (n − Re Σ E²)/2,
    # Σ CS = Im Σ E²/2, less n × the means' products; y is centred, so Eᵀy needs no centring
    n, mean, sq = len(x), E.mean(axis=0), np.einsum("ij,ij->j", E, E)
    cc = (n + sq.real) / 2 - n * mean.real**2
    ss = (n - sq.real) / 2 - n * mean.imag**2
    cs = sq.imag / 2 - n * mean.real * mean.imag
    whole = cc + ss
    cc, ss, cs = (np.repeat(v[:, None], y.shape[1], axis=1) for v in (cc, ss, cs))
    for j in range(y.shape[1] if Qd is not None else 0):
        QE = Qd[j].T @ E - np.outer(Qd[j].sum(axis=0), mean)         # of the centred pair
        cc[:, j] -= np.sum(QE.real**2, axis=0)
        ss[:, j] -= np.sum(QE.imag**2, axis=0)
        cs[:, j] -= np.sum(QE.real * QE.imag, axis=0)
    ab = E.T @ y
    a, b = ab.real, ab.imag
    det = np.maximum(cc * ss - cs**2, 1e-300)
    alpha = (ss * a - cs * b) / det
    beta = (cc * b - cs * a) / det
    return np.where(cc + ss >= SEEN * whole[:, None], alpha * a + beta * b, 0.0)


def _fit(x: np.ndarray, y: np.ndarray, f: float, Q: np.ndarray | None) -> tuple[float, float]:
    """The sum of squares a sine of frequency ``f`` (with a constant) removes from ``y``,
    jointly with the model's columns ``Q`` (n, p), and its amplitude."""
    B = np.column_stack([np.cos(2 * np.pi * f * x), np.sin(2 * np.pi * f * x), np.ones_like(x)])
    QB = Q.T @ B if Q is not None else None
    G = B.T @ B - (QB.T @ QB if QB is not None else 0.0)
    rhs = B.T @ y
    coef = np.linalg.lstsq(G, rhs, rcond=None)[0]
    return float(coef @ rhs), float(np.hypot(*coef[:2]))
