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

from collections.abc import Callable, Sequence
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


@dataclass(frozen=True)
class Lazy:
    """A basis of ``columns`` columns (in total, blocks side by side) made when called: what
    ``ar1`` need not make where the noise is white beyond any basis of that size."""

    columns: int
    make: Callable[[], np.ndarray | Span | Sequence[np.ndarray | Span]]

    def __call__(self):
        return self.make()


@dataclass(frozen=True)
class Span:
    """Orthonormal columns held as ``X @ T`` (X (3n, k) as it is, T (k, k)): a fit's Jacobian
    and the factor that makes its columns orthonormal. ``ar1`` needs only k × k products of
    them, so the product, a second matrix of J's size (190 MB at 723 000 readings), is never
    made."""

    X: np.ndarray
    T: np.ndarray


def _previous(x: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """x shifted one reading later within each segment; zero at a segment's first reading."""
    prev = np.empty_like(x)
    prev[1:] = x[:-1]                    # a whole copy, then the few segments' starts: a
    prev[0] = 0.0                        # boolean mask over every reading copies twice
    prev[1:][seg[1:] != seg[:-1]] = 0.0
    return prev


def ar1(r: np.ndarray, seg: np.ndarray,
        basis: np.ndarray | Span | Sequence[np.ndarray | Span] | Lazy | None = None,
        margin: float = 0.0) -> np.ndarray:
    """ρ̂ of each reading's segment and direction, (n, 3), from residuals r (n, 3).

    ``basis`` (3n, k), orthonormal (an array or a ``Span``), or such blocks side by side
    (never copied whole), spans what the fit took out of r (rows reading by reading, X Y Z):
    r's lag-1 sum and energy are then matched to what they are expected to be beyond that
    span (``_matched``). It may be a ``Lazy`` of k columns, made only where some ρ̂ could reach the floor. The
    fit's smooth columns take low frequencies, and so correlation, with them: at ρ 0.9 on
    K4 + K1 + K2 (fit's residual, 200 sessions) Kendall's correction for a segment's mean
    alone leaves ρ̂ 0.894 on average, matched 0.898. Beside diagnose's best candidate,
    chosen among some 200 for fitting the residual best (so taking more of the noise than a
    fixed column would), 0.892: what the tests' ``margin`` covers. Without a basis, Kendall's (1 + 3ρ̂)/n.

    Each direction's segments share one ρ̂ where their own estimates agree within their
    errors (χ² test of one common value, ``SAME_RHO_P``; each segment counts by its length):
    one device read the same way throughout. Whitening by ρ̂ is what the F tests rest on,
    and near 1 a small error in it is a large one in the low-frequency variance a smooth
    candidate is tested against (((1 − ρ)/(1 − ρ̂))²: 0.44 for ρ̂ 0.85 at ρ 0.9), so the
    estimate from all the segments, with about √(segments) less error, flags fewer clean
    sessions (AR(1) ρ 0.9 on K4 + K1 + K2, 200 sessions: 15 flagged with a ρ̂ per segment,
    8 pooled, 3 with the true ρ; see docs/benchmarks.md). Segments whose estimates differ
    (paths read at different rates) keep their own.

    ``margin``: that many standard errors, √((1 − ρ̂²)/n) with n the readings behind the
    estimate, added to every ρ̂ kept: diagnose's tests whiten there (``RHO_MARGIN_SE``)."""
    lag = r * _previous(r, seg)
    segs, at_seg = np.unique(seg, return_inverse=True)
    n = np.bincount(at_seg, minlength=len(segs)).astype(float)
    energy = np.stack([np.bincount(at_seg, r[:, d] ** 2, len(segs)) for d in range(3)], axis=1)
    lags = np.stack([np.bincount(at_seg, lag[:, d], len(segs)) for d in range(3)], axis=1)
    raw = np.divide(lags, energy, out=np.zeros_like(lags), where=energy > 0)
    est = raw + (1 + 3 * raw) / n[:, None]       # the lag-1 estimate's bias (Kendall, 1954)
    if callable(basis):
        if _white_beyond_any(raw, n, basis):     # no ρ̂ the basis could lift to the floor:
            return np.zeros_like(r)              # not made, not matched (1.7 s at 723 000 readings)
        basis = basis()
    parts = [] if basis is None else [basis] if isinstance(basis, np.ndarray | Span) else list(basis)
    parts = [b if isinstance(b, Span) else Span(b, np.eye(b.shape[1])) for b in parts]
    parts = [Span(b.X.reshape(len(r), 3, -1), b.T) for b in parts if b.X.shape[1]]
    if parts:
        est = _matched(raw, est, energy, parts, at_seg, n)
    size = np.repeat(n[:, None], 3, axis=1)
    for d in range(3):
        live = energy[:, d] > 0
        if live.sum() > 1:
            # one ρ: each run's estimate has variance (1 − ρ²)/n, so runs count by their length
            # (weights from each one's own ρ̂ would favour the runs that came out high)
            common = float(n[live] @ est[live, d] / n[live].sum())
            w = n[live] / max(1 - min(common, RHO_MAX) ** 2, 1 - RHO_MAX**2)       # 1/σ²
            if chi2_sf(float(w @ (est[live, d] - common) ** 2), int(live.sum()) - 1) >= SAME_RHO_P:
                est[live, d], size[live, d] = common, n[live].sum()
    keep = est > np.maximum(2 / np.sqrt(np.maximum(size, 1)), RHO_FLOOR)
    est = est + margin * np.sqrt(np.clip(1 - est**2, 0.0, 1.0) / np.maximum(size, 1))
    return np.where(keep, np.minimum(est, RHO_MAX), 0.0)[at_seg]


def _white_beyond_any(raw: np.ndarray, n: np.ndarray, basis) -> bool:
    """Whether every segment's ρ̂ stays below ``RHO_FLOOR`` whatever a basis of ``basis.columns``
    columns does to it: matching moves the raw lag-1 ratio by what the basis takes of the lag
    sum, at most its columns' energy in the segment over what is left, k/(m − k) (Cauchy–
    Schwarz, each column of unit norm), and the ratio's own bias 2ρ/m; twice that bounds it.
    At streaming size (m ~ 10⁵, k ~ 15) white noise is told at once; a run of 121 readings
    never is (the bound is 0.25)."""
    k = getattr(basis, "columns", None)
    if k is None or not len(n) or n.min() <= k:
        return False
    return bool((raw + 2 * (k + 3) / (n[:, None] - k) < RHO_FLOOR).all())


MATCH_ROUNDS = 2        # the second moves ρ̂ by < 1e-4 on K4 + K1 + K2 at ρ 0.5–0.95
DIRECT_RHO = 1e-3       # below this ``_filtered`` makes Pc whole: its division by ρ would cost 1e-13·(1e-3/ρ)


def _matched(raw: np.ndarray, est: np.ndarray, energy: np.ndarray, B: list[Span], at_seg: np.ndarray,
             n: np.ndarray) -> np.ndarray:
    """ρ per segment and direction whose expected lag-1 ratio beyond the basis B ((n, 3, k)
    blocks side by side) is the one observed (``raw``): with M = I − BBᵀ and the noise's
    covariance Σ(ρ) (AR(1) in each segment and direction, each its own variance),
    E[rᵀLr] = tr(L M Σ M) for the lag-1 sum L of a block and E[rᵀr] = tr(D M Σ M) for its
    energy, each a trace of k × k products (B's columns filtered by the AR(1) correlation,
    ``_filtered``); 2ρ/n more for the ratio's own bias (its numerator and denominator
    correlate). Blocks the basis leaves (almost) nothing of keep ``est``; it starts the
    rounds. Unbiased within 0.002 at ρ 0–0.95 on simulated segments of 80 readings, 15
    columns (Kendall: −0.01 to −0.05). Every product is of the blocks' X, turned by T at
    k × k: a block of X is a view, copied only while it is worked on."""
    T = np.zeros(np.sum([b.T.shape for b in B], axis=0))      # the parts' T, block-diagonal
    i = j = 0
    for b in B:
        T[i:i + b.T.shape[0], j:j + b.T.shape[1]] = b.T
        i, j = i + b.T.shape[0], j + b.T.shape[1]
    blocks = []
    for s, at in enumerate(_segments(at_seg, len(n))):
        for d in range(3):
            if energy[s, d] > 0:
                x = B[0].X[at, d] if len(B) == 1 else np.concatenate([b.X[at, d] for b in B], axis=1)
                whole = np.ascontiguousarray(x)              # for BLAS; dropped after
                xx, lag = whole.T @ whole, whole[1:].T @ whole[:-1]
                lag = (lag + lag.T) / 2                      # xᵀLx, L's symmetric part
                blocks.append((s, d, x, energy[s, d] / len(x), xx, lag, T.T @ xx @ T, T.T @ lag @ T))
    out = est.copy()
    for _ in range(MATCH_ROUNDS):
        q = np.clip(out, 0.0, RHO_MAX)
        G, traces = 0.0, []              # BᵀΣB; each block's tr(cᵀPc), tr(cᵀ(L + Lᵀ)Pc), c = xT
        for s, d, x, v, xx, lag, *_ in blocks:
            xpx, lag_px = _filtered(x, float(q[s, d]), xx, lag)
            cpc = T.T @ xpx @ T
            G = G + v * cpc
            traces.append((np.trace(cpc), np.trace(T.T @ lag_px @ T)))
        for (s, d, x, v, *_, cc, lag_cc), (own, lag_pc) in zip(blocks, traces, strict=True):
            m, qs = len(x), float(q[s, d])
            lag = v * (qs * (m - 1) - lag_pc) + np.vdot(lag_cc, G)
            size = v * (m - 2 * own) + np.vdot(cc, G)
            if size > 1e-3 * v * m:
                out[s, d] = raw[s, d] + qs - lag / size + 2 * qs / m
    return out


def _segments(at_seg: np.ndarray, count: int) -> list[slice | np.ndarray]:
    """Each segment's readings: a slice where they are consecutive (as a run's are: a view,
    where an index array gathers a copy of every column, 0.5 s at 723 000 readings), else
    their indices."""
    out: list[slice | np.ndarray] = []
    for s in range(count):
        at = np.flatnonzero(at_seg == s)
        whole = len(at) and at[-1] - at[0] + 1 == len(at)
        out.append(slice(int(at[0]), int(at[-1]) + 1) if whole else at)
    return out


def _filtered(c: np.ndarray, rho: float, cc: np.ndarray, lag_cc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cᵀPc and cᵀ(L + Lᵀ)Pc for P the AR(1) correlation ρ^|i−j| of one run, L its lag,
    given cᵀc and cᵀ(L + Lᵀ)c / 2: one pass of ``_suffix`` where Pc itself takes two.
    P = (1 − ρ²)·W⁻¹W⁻ᵀ (W the Prais–Winsten transform) gives cᵀPc = (1 − ρ²)·zᵀz, z = W⁻ᵀc;
    P⁻¹'s three diagonals give (L + Lᵀ)Pc = ((1 + ρ²)Pc − (1 − ρ²)c)/ρ less ρ at the two
    ends, where (Pc)₀ = Σ ρʲcⱼ and (Pc)ₘ₋₁ = Σ ρ^(m−1−j)cⱼ. Below ``DIRECT_RHO`` the division
    by ρ would cost digits: Pc is made whole."""
    if rho == 0:
        return cc, 2 * lag_cc
    if rho < DIRECT_RHO:
        c = np.ascontiguousarray(c)
        pc = _suffix(c, rho) + _suffix(c[::-1], rho)[::-1] - c
        return c.T @ pc, c[:-1].T @ pc[1:] + c[1:].T @ pc[:-1]
    z = _inverse_transpose(c, rho)
    cpc = (1 - rho * rho) * (z.T @ z)
    powers = rho ** np.arange(min(len(c), int(np.log(1e-17) / np.log(rho)) + 1))   # beyond: below a double
    ends = np.outer(c[0], powers @ c[:len(powers)]) + np.outer(c[-1], powers @ c[::-1][:len(powers)])
    return cpc, ((1 + rho * rho) * cpc - (1 - rho * rho) * cc) / rho - rho * ends


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
    segs, at_seg = np.unique(seg, return_inverse=True)
    for at in _segments(at_seg, len(segs)):
        for d in range(3):
            X = J[:, at, d].T
            sigma2 = float(r[at, d] @ r[at, d]) / len(X) * scale
            q = float(rho[at][0, d])
            if q:
                X = _inverse_transpose(X, q)
                sigma2 *= 1 - q * q
            else:
                X = np.ascontiguousarray(X)            # for BLAS
            B += sigma2 * (X.T @ X)
    Ainv = np.linalg.inv(A)
    return Ainv @ B @ Ainv


def _inverse_transpose(x: np.ndarray, rho: float) -> np.ndarray:
    """W⁻ᵀx along axis 0 for the Prais–Winsten W of one run: z_i = Σ_{k≥i} ρ^(k−i) x_k,
    z_0 divided by √(1 − ρ²)."""
    z = _suffix(x, rho)
    z[0] /= np.sqrt(1 - rho * rho)
    return z


def _suffix(x: np.ndarray, rho: float) -> np.ndarray:
    """z_i = Σ_{k≥i} ρ^(k−i) x_k along axis 0, by doubling: after the pass with shift h each
    z_i holds the 2h terms from x_i, and passes stop where ρ^h is below a double's precision
    (9 passes at ρ 0.9, 4 at 0.01, 1 below 1e-9), whatever the run's length."""
    z = np.array(x, dtype=float)
    coef, shift = rho, 1
    while shift < len(z) and coef > 1e-17:
        z[:-shift] += coef * z[shift:]
        coef, shift = coef * coef, 2 * shift
    return z


def outliers(r_um: np.ndarray, seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Readings that stand apart from their neighbours: their indices and how far, µm.
    Their steps from their neighbours are found a step of ``ROWS_A_STEP`` readings at a time,
    each with its neighbours either side: the neighbours of every reading at once would be
    200 MB of new memory at 723 000 readings."""
    n = len(r_um)
    step, alone = np.zeros_like(r_um), np.zeros(n, bool)
    for lo in range(0, n, ROWS_A_STEP):
        a, hi = max(lo - NEIGHBOURS, 0), min(lo + ROWS_A_STEP, n)
        part, lone = _steps(r_um[a:hi + NEIGHBOURS], seg[a:hi + NEIGHBOURS])
        step[lo:hi], alone[lo:hi] = part[lo - a:hi - a], lone[lo - a:hi - a]
    scale = 1.4826 * np.median(np.abs(step[~alone]), axis=0) if (~alone).any() else np.zeros(3)
    z = np.abs(step) / np.maximum(scale, 1e-9)
    size = np.linalg.norm(step, axis=1)
    bad = np.flatnonzero((z > OUTLIER_Z).any(axis=1) & (size > OUTLIER_MIN_UM))
    return bad, size[bad]


ROWS_A_STEP = 1 << 16       # readings whose steps ``outliers`` finds at once


def _steps(r_um: np.ndarray, seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each reading's step from the median of its neighbours in its segment, and whether it
    has none."""
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
    return step, alone


@dataclass(frozen=True)
class Repeats:
    """The noise as the data repeat it: the scatter of readings of one pose, reached the same
    way (``sides.same_pose``), pooled over every pose read more than once."""

    sigma_um: float     # per reading and direction
    readings: int       # readings of repeated poses
    poses: int          # poses read more than once
    dwell: int          # of those, read only one reading after another (a dwell's samples)

    @property
    def dof(self) -> int:
        """The degrees of freedom of ``sigma_um``: each repeat beyond a pose's first, in three
        directions."""
        return 3 * (self.readings - self.poses)

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
