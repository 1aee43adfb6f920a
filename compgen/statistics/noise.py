"""What R-test noise really is: ordered in time, partly correlated, now and then a bad reading.

Readings come in *segments*: one run of a path (``kinematics.runs``), in the order they
were taken. Within a segment the noise of each direction is taken as AR(1),
e[i] = ρ·e[i−1] + white (a drift of the set-up between readings does this); its ρ is
estimated from the residual, and a linear model of the readings is made white (and so an
F test honest) by the Prais–Winsten transform x'[0] = √(1−ρ²)·x[0],
x'[i] = x[i] − ρ·x[i−1] (generalised least squares). A ρ̂ within two standard errors of
zero (2/√n), or below ``RHO_FLOOR``, is taken as zero: white noise is left as it is.

A reading is an *outlier* when it stands apart from its neighbours in the segment (two each
side): beyond ``OUTLIER_Z`` robust standard deviations of that difference, and beyond
``OUTLIER_MIN_UM``. A smooth error of any size follows its neighbours and is never one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .significance import chi2_sf

RHO_MAX = 0.99          # beyond this the noise is a random walk: whitening would divide by ~0
RHO_FLOOR = 0.02        # below this a variance changes by < 4 % ((1 + ρ)/(1 − ρ)): at 10⁵ readings a run,
                        # where 2/√n is 0.006, chance would otherwise whiten one session in five
OUTLIER_Z = 8.0         # robust s.d. of the step from the neighbours' median
OUTLIER_MIN_UM = 1.0    # a step below this is noise on any R-test (0.5–1 µm repeatability)
NEIGHBOURS = 2          # each side
SAME_RHO_P = 0.05       # segments' ρ̂ differing at this level are not one device's
REPEATS_MIN = 30        # readings beyond the first of each repeated pose, before they say what the noise is


def _previous(x: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """x shifted one reading later within each segment; zero at a segment's first reading."""
    prev = np.empty_like(x)
    prev[1:] = x[:-1]                    # a whole copy, then the few segments' starts: a
    prev[0] = 0.0                        # boolean mask over every reading copies twice
    prev[1:][seg[1:] != seg[:-1]] = 0.0
    return prev


def ar1(r: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """ρ̂ of each reading's segment and direction, (n, 3), from residuals r (n, 3).

    Each direction's segments share one ρ̂ where their own estimates agree within their
    errors (χ² test of one common value, ``SAME_RHO_P``): one device read the same way
    throughout. Whitening by ρ̂ is what the F tests rest on, and near 1 a small error in it
    is a large one in the low-frequency variance a smooth candidate is tested against
    (((1 − ρ)/(1 − ρ̂))²: 0.44 for ρ̂ 0.85 at ρ 0.9), so the estimate from all the segments,
    with about √(segments) less error, flags fewer clean sessions (AR(1) ρ 0.9 on K4 + K1 + K2,
    200 sessions: 15 flagged with a ρ̂ per segment, 8 pooled, 3 with the true ρ; see
    docs/benchmarks.md). Segments whose estimates differ (paths read at different rates)
    keep their own."""
    lag = r * _previous(r, seg)
    segs, at_seg = np.unique(seg, return_inverse=True)
    n = np.bincount(at_seg, minlength=len(segs)).astype(float)
    energy = np.stack([np.bincount(at_seg, r[:, d] ** 2, len(segs)) for d in range(3)], axis=1)
    lags = np.stack([np.bincount(at_seg, lag[:, d], len(segs)) for d in range(3)], axis=1)
    est = np.divide(lags, energy, out=np.zeros_like(lags), where=energy > 0)
    est = est + (1 + 3 * est) / n[:, None]       # the lag-1 estimate's bias (Kendall, 1954)
    size = np.repeat(n[:, None], 3, axis=1)
    for d in range(3):
        live = energy[:, d] > 0
        if live.sum() > 1:
            w = n[live] / np.maximum(1 - np.minimum(est[live, d], RHO_MAX) ** 2, 1 - RHO_MAX**2)  # 1/σ²
            common = float(w @ est[live, d] / w.sum())
            if chi2_sf(float(w @ (est[live, d] - common) ** 2), int(live.sum()) - 1) >= SAME_RHO_P:
                est[live, d], size[live, d] = common, n[live].sum()
    keep = est > np.maximum(2 / np.sqrt(np.maximum(size, 1)), RHO_FLOOR)
    return np.where(keep, np.minimum(est, RHO_MAX), 0.0)[at_seg]


def whiten(x: np.ndarray, seg: np.ndarray, rho: np.ndarray, before: tuple | None = None) -> np.ndarray:
    """The Prais–Winsten transform of x, (n, 3) or (n, 3, k), with ρ (n, 3) per reading.
    ``before`` = (x's row before these, its segment): x continues a series taken in parts."""
    r = rho if x.ndim == 2 else rho[:, :, None]
    first = np.ones(len(seg), bool)
    first[1:] = seg[1:] != seg[:-1]
    prev = _previous(x, seg)
    if before is not None and len(seg) and before[1] == seg[0]:
        prev[0], first[0] = before[0], False
    out = x - r * prev
    out[first] = np.sqrt(1 - r[first] ** 2) * x[first]
    return out


def ar1_covariance(J: np.ndarray, r: np.ndarray, seg: np.ndarray, rho: np.ndarray, dof: int) -> np.ndarray:
    """The covariance of least-squares estimates when the noise is AR(1) within each run and
    direction (ρ (n, 3) per reading, as ``ar1`` gives): (JᵀJ)⁻¹ JᵀΣJ (JᵀJ)⁻¹, Σ block by
    block σ²·ρ^|i−j|, σ² each run and direction's own residual variance (scaled to ``dof``).
    With ρ = 0 throughout this is the white-noise covariance σ²(JᵀJ)⁻¹ up to each group's
    own σ². J is (p, n, 3) (a parameter's column as a block), r (n, 3).

    Exact, not the large-sample factor (1 + ρ)/(1 − ρ): with the correlation matrix P,
    JᵀPJ = (1 − ρ²)·ZᵀZ, Z = W⁻ᵀJ, W the Prais–Winsten transform (``whiten``)."""
    p, n = J.shape[:2]
    A = np.einsum("pnd,qnd->pq", J, J)
    B = np.zeros((p, p))
    scale = n * 3 / dof
    for s in np.unique(seg):
        at = np.flatnonzero(seg == s)
        for d in range(3):
            X = J[:, at, d].T
            sigma2 = float(r[at, d] @ r[at, d]) / len(at) * scale
            q = float(rho[at[0], d])
            if q:
                X = _inverse_transpose(X, q)
                sigma2 *= 1 - q * q
            B += sigma2 * (X.T @ X)
    Ainv = np.linalg.inv(A)
    return Ainv @ B @ Ainv


def _inverse_transpose(x: np.ndarray, rho: float) -> np.ndarray:
    """W⁻ᵀx along axis 0 for the Prais–Winsten W of one run: z_i = Σ_{k≥i} ρ^(k−i) x_k,
    z_0 divided by √(1 − ρ²). A backward recursion, done as scaled suffix sums in blocks
    short enough that ρ^length stays a normal double, the blocks joined by their carry."""
    length = len(x)
    block = max(1, int(250 / max(-np.log10(rho), 1e-12)))
    z = np.empty_like(x, dtype=float)
    carry = np.zeros(x.shape[1:])
    for b in range(length, 0, -block):
        a = max(0, b - block)
        w = rho ** np.arange(b - a, dtype=float)[:, None]      # ρ^(k−a)
        suffix = np.cumsum((w * x[a:b])[::-1], axis=0)[::-1]
        z[a:b] = suffix / w + rho ** (b - a - np.arange(b - a))[:, None] * carry
        carry = z[a]
    z[0] /= np.sqrt(1 - rho * rho)
    return z


def outliers(r_um: np.ndarray, seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Readings that stand apart from their neighbours: their indices and how far, µm."""
    n = len(r_um)
    near = np.full((n, 2 * NEIGHBOURS, 3), np.nan)
    for k, shift in enumerate((*range(-NEIGHBOURS, 0), *range(1, NEIGHBOURS + 1))):
        src = np.arange(n) + shift
        ok = (src >= 0) & (src < n)
        ok[ok] = seg[src[ok]] == seg[ok]
        near[ok, k] = r_um[src[ok]]
    alone = np.isnan(near).all(axis=(1, 2))
    whole = ~np.isnan(near).any(axis=(1, 2))    # all but a segment's ends: the middle two of
    edge = ~alone & ~whole                      # 2N sorted, 1/10 of nanmedian's time (masked)
    step = np.zeros_like(r_um)
    middle = np.sort(near[whole], axis=1)[:, NEIGHBOURS - 1:NEIGHBOURS + 1]
    step[whole] = r_um[whole] - (middle[:, 0] + middle[:, 1]) / 2
    step[edge] = r_um[edge] - np.nanmedian(near[edge], axis=1)
    scale = 1.4826 * np.median(np.abs(step[~alone]), axis=0) if (~alone).any() else np.zeros(3)
    z = np.abs(step) / np.maximum(scale, 1e-9)
    size = np.linalg.norm(step, axis=1)
    bad = np.flatnonzero((z > OUTLIER_Z).any(axis=1) & (size > OUTLIER_MIN_UM))
    return bad, size[bad]


@dataclass(frozen=True)
class Repeats:
    """The noise as the data repeat it: the scatter of readings of one pose, reached the same
    way (``sides.same_pose``), pooled over every pose read more than once."""

    sigma_um: float     # per reading and direction
    readings: int       # readings of repeated poses
    poses: int          # poses read more than once
    dwell: int          # of those, read only one reading after another (a dwell's samples)

    def words(self) -> str:
        told = f"{self.readings} readings of {self.poses} poses read more than once"
        if self.dwell == self.poses:
            return (f"{told}, each read one reading after another: correlated noise makes this low, "
                    "and it holds nothing of how the machine returns to a pose")
        return told + (f" ({self.dwell} of them in a dwell)" if self.dwell else "")


def repeats(group: np.ndarray, r: np.ndarray, seg: np.ndarray) -> Repeats | None:
    """The noise from readings that repeat a pose (``group``: equal for repeats), residuals r
    (n, 3) mm: the pooled within-pose σ, or None with fewer than ``REPEATS_MIN`` readings
    beyond the first of each pose. What changes between the repeats (a drift of the set-up)
    counts as noise here: the candidates' tests, not this, decide whether it is an effect."""
    counts = np.bincount(group)
    rep = counts[group] > 1
    poses = int((counts > 1).sum())
    dof = int(rep.sum()) - poses
    if dof < REPEATS_MIN:
        return None
    g = group[rep]
    sums = np.column_stack([np.bincount(g, r[rep, d], len(counts)) for d in range(3)])
    mean = sums / np.maximum(counts, 1)[:, None]
    sigma = float(np.sqrt(((r[rep] - mean[g]) ** 2).sum() / (3 * dof))) * 1e3
    index = np.flatnonzero(rep)
    first = np.full(len(counts), len(group))
    last = np.zeros(len(counts), int)
    np.minimum.at(first, g, index)
    np.maximum.at(last, g, index)
    held = counts > 1
    # one reading after another within one run (runs are numbered in order)
    dwell = int(((last - first + 1 == counts)[held] & (seg[first[held]] == seg[last[held]])).sum())
    return Repeats(sigma, int(rep.sum()), poses, dwell)
