"""The statistics of diagnose: how much of a residual an effect's columns remove, the F
test with Bonferroni's correction, which effects stay significant once another is added,
and which explain the residual as well as the best (rivals).

References: ``docs/diagnose.md`` (visibility, bias, F and score tests).
"""

from __future__ import annotations

import math

import numpy as np

from ..model.sides import span

ALPHA = 0.01          # family-wise false-alarm rate over all effects tried
VISIBLE = 0.01        # ‖c⊥‖/‖c‖ below this: the model absorbs the effect entirely
RIVAL = 0.9           # removing this share of what the best removes makes a rival (misfit left)
# a tie no set-up parts whose best passes the family's α but not this share of it is marginal:
# it is measured again before any is named (1 in 100 clean diagnoses passes α by chance; over a
# loop of five diagnoses that is 1 in 20, where 1 in 1000 passes α/10)
MARGINAL = 0.1


def explained(cc: np.ndarray, qc: np.ndarray, cr: np.ndarray, keep: np.ndarray | None = None
              ) -> tuple[np.ndarray, float, np.ndarray]:
    """For an effect's columns c, from their products alone — cc = cᵀc, qc = Qᵀc (Q the
    model's orthonormal columns), cr = cᵀr (r the residual, orthogonal to Q): each column's
    visibility ‖c⊥‖/‖c‖ (c⊥ = c − QQᵀc, the part the model cannot absorb), the residual
    sum of squares its visible columns (or ``keep``) remove, and their first-order
    amplitudes (0 for the invisible). Products, not the columns: a dense session's columns
    are millions of rows, their products k × k."""
    norms = np.sqrt(np.diag(cc))
    cpcp = cc - qc.T @ qc                           # c⊥ᵀc⊥; c⊥ᵀr = cᵀr, r being orthogonal to Q
    vis = np.where(norms > 0, np.sqrt(np.clip(np.diag(cpcp), 0, None)) / np.where(norms > 0, norms, 1), 0.0)
    keep = vis >= VISIBLE if keep is None else keep
    amp = np.zeros(len(cr))
    if not keep.any():
        return vis, 0.0, amp
    G = cpcp[np.ix_(keep, keep)]
    amp[keep] = np.linalg.lstsq(G, cr[keep], rcond=None)[0]
    return vis, float(amp[keep] @ G @ amp[keep]), amp


def gram_factor(G: np.ndarray) -> np.ndarray:
    """A square F with FᵀF = G (G symmetric, positive semi-definite): what ``condition``
    needs of columns whose products alone are known."""
    w, V = np.linalg.eigh(G)
    return np.sqrt(np.clip(w, 0, None))[:, None] * V.T


def tall_qr(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Q (m, p), R (p, p) of a tall J (m ≫ p): Cholesky QR twice on J's columns scaled to
    unit length (orthogonal to round-off where J scaled is conditioned below ~1e6): four
    passes of matrix products where Householder QR walks J column by column (2.2 s of
    diagnose at 720 000 readings, 0.3 s this way). The scaling and the first factor are
    applied to J as one p × p matrix and the second factor to Q's rows a step at a time, so
    Q is the one matrix of J's size made (each is 190 MB at 723 000 readings). R's diagonal
    is positive; J rank deficient or worse conditioned than that: Householder
    (``numpy.linalg.qr``)."""
    norms = np.linalg.norm(J, axis=0)
    if J.shape[0] > 4 * J.shape[1] and (norms > 0).all():
        try:
            R1 = np.linalg.cholesky((J.T @ J) / np.outer(norms, norms)).T
            if np.linalg.cond(R1) < 1e6:
                Q = J @ (np.linalg.inv(R1) / norms[:, None])
                R2 = np.linalg.cholesky(Q.T @ Q).T
                turn = np.linalg.inv(R2)
                for lo in range(0, len(Q), ROWS_A_STEP):
                    Q[lo:lo + ROWS_A_STEP] = Q[lo:lo + ROWS_A_STEP] @ turn
                return Q, (R2 @ R1) * norms
        except np.linalg.LinAlgError:      # not positive definite: rank deficient
            pass
    return np.linalg.qr(J)


ROWS_A_STEP = 1 << 16       # rows of Q turned at once by ``tall_qr``'s second factor


def p_value(drop: float, k: int, rss: float, dof: int, tried: int) -> float:
    """F test of ``k`` added columns removing ``drop`` of ``rss``, Bonferroni over ``tried``."""
    F = (drop / k) / max((rss - drop) / (dof - k), 1e-300)
    return min(1.0, f_sf(F, k, dof - k) * tried)


def said_p(p: float) -> str:
    """A p-value as the texts write it: two digits, and below double precision's smallest
    normal number (where its digits mean nothing) "p < 1e-300"."""
    return f"p = {p:.2g}" if p >= 1e-300 else "p < 1e-300"


# The two distributions diagnose needs, in the standard library's arithmetic (scipy.special
# alone costs diagnose more start-up than numpy's import; the tests hold these to scipy's).

def f_sf(F: float, k: int, m: int) -> float:
    """P(F(k, m) > F): the regularized incomplete beta I_x(m/2, k/2) at x = m/(m + kF)."""
    return 1.0 if not F > 0 else _betainc(m / 2, k / 2, m / (m + k * F))


def _betainc(a: float, b: float, x: float) -> float:
    """I_x(a, b) by its continued fraction (modified Lentz, Numerical Recipes 6.4), taken on
    the side where it converges fast; exact in log space down to the smallest doubles."""
    if x <= 0.0 or x >= 1.0:
        return 0.0 if x <= 0.0 else 1.0
    if x > (a + 1) / (a + b + 2):
        return 1.0 - _betainc(b, a, 1.0 - x)
    tiny, c, d = 1e-300, 1.0, 1.0 - (a + b) * x / (a + 1)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for n in range(1, 100_000):
        for num in (n * (b - n) * x / ((a + 2 * n - 1) * (a + 2 * n)),
                    -(a + n) * (a + b + n) * x / ((a + 2 * n) * (a + 2 * n + 1))):
            d, c = 1.0 + num * d, 1.0 + num / c
            d, c = 1.0 / (d if abs(d) > tiny else tiny), (c if abs(c) > tiny else tiny)
            h *= d * c
        if abs(d * c - 1.0) < 1e-15:
            break
    log_front = (a * math.log(x) + b * math.log1p(-x) - math.log(a)
                 + math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b))
    return math.exp(log_front) * h


def chi2_sf(x: float, k: int) -> float:
    """P(χ²(k) > x) for whole ``k``, in closed form: a finite sum (and erfc for odd k), its
    terms in log space so that thousands of degrees of freedom neither overflow nor vanish."""
    y = x / 2
    if not y > 0:
        return 1.0
    if k % 2 == 0:
        logs = [j * math.log(y) - math.lgamma(j + 1) for j in range(k // 2)]
        head = 0.0
    else:
        logs = [(j - 0.5) * math.log(y) - math.lgamma(j + 0.5) for j in range(1, (k + 1) // 2)]
        head = math.erfc(math.sqrt(y))
    if not logs:
        return head
    top = max(logs)
    return min(1.0, head + math.exp(top - y) * math.fsum(math.exp(v - top) for v in logs))


def lack_of_fit(r: np.ndarray, groups: np.ndarray, noise_um: float, rho: np.ndarray, free,
                alpha: float, noise_dof: int | None = None) -> list[dict]:
    """Where the residual ``r`` (n, 3; mm) exceeds the R-test's own noise: per group (a path)
    and direction, a χ² test of its sum of squares against ``noise_um``, Bonferroni over the
    groups tested. ``free``: each reading's share the fit left free (1 − its leverage, (n, 3),
    or one share for all): a group's sum of squares is σ² times its sum under noise alone.
    Its degrees of freedom shrink with AR(1) correlation ``rho`` (n, 3) (a sum of squares
    of an AR(1) series varies (1 + ρ²)/(1 − ρ²) times more) and with tails heavier than a
    normal's: a sum of squares varies (κ − 1)/2 times more with the residual's kurtosis κ
    (Box, 1953), which the test takes from the group's own residual where it exceeds a
    normal's 3 (a missing effect's misfit has κ below 3 and keeps the normal's). Where the
    noise is itself estimated with ``noise_dof`` degrees of freedom (a probe's pooled touches,
    a pose's repeats), the ratio of the two estimates is tested as F(k, noise_dof): as a
    known σ, a noise estimated on 72 touches' degrees of freedom called 2 clean probe
    sessions in 30 unexplained. Returns the groups that fail, worst first."""
    out, tests = [], []
    sigma2 = (noise_um * 1e-3) ** 2
    free = np.broadcast_to(np.asarray(free, float), r.shape)
    for g in dict.fromkeys(groups):
        at = groups == g
        for d in range(3):
            rg, rh, fg = r[at, d], np.clip(rho[at, d], -0.99, 0.99), float(free[at, d].sum())
            m2 = float(np.mean(rg**2))
            kurtosis = max(3.0, float(np.mean(rg**4)) / m2**2) if m2 > 0 else 3.0
            k = max(1, int(round(fg * np.mean((1 - rh**2) / (1 + rh**2)) * 2 / (kurtosis - 1))))
            ratio = float(np.sum(rg**2) / fg / sigma2)
            tests.append((g, "XYZ"[d], k, ratio, float(np.sqrt(m2)) * 1e3))
    for g, d, k, ratio, rms in tests:
        tail = chi2_sf(k * ratio, k) if noise_dof is None else f_sf(ratio, k, noise_dof)
        p = min(1.0, tail * len(tests))
        if p < alpha:
            out.append({"path": str(g), "direction": f"d{d}", "rms_um": rms, "noise_um": noise_um,
                        "p_value": p})
    return sorted(out, key=lambda m: -m["rms_um"])


def chi2_isf(alpha: float, k: int) -> float:
    """The x with P(χ²(k) > x) = alpha, by bisection (the tail falls monotonically)."""
    lo, hi = 0.0, max(1.0, 2.0 * k)
    while chi2_sf(hi, k) > alpha:
        lo, hi = hi, 2 * hi
    for _ in range(200):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if chi2_sf(mid, k) > alpha else (lo, mid)
    return (lo + hi) / 2


def still_significant(Q: np.ndarray, added: np.ndarray, r: np.ndarray, prods: dict,
                                alpha: float) -> set[str]:
    """Which effects stay significant once the model (orthonormal columns ``Q``) is joined by
    the columns ``added``, first order; Bonferroni over all of them (``p_beside``)."""
    return {name for name, p in p_beside(Q, added, r, prods).items() if p < alpha}


def beside(C: np.ndarray, noise, added: np.ndarray, rw: np.ndarray, qc: np.ndarray | None = None) -> tuple:
    """Whitened columns ``C`` as ``still_significant`` takes them beside the model and the
    columns ``added``: (CᵀC, [Q | added]ᵀC, Cᵀrw); ``qc``, QᵀC where it is known already (a
    pass over Q less)."""
    return C.T @ C, np.vstack([noise.Q.T @ C if qc is None else qc, added.T @ C]), C.T @ rw


def p_beside(Q: np.ndarray, added: np.ndarray, r: np.ndarray, prods: dict) -> dict[str, float]:
    """Each effect's p-value once the model (orthonormal columns ``Q``) is joined by the
    columns ``added``, first order; Bonferroni over all of them. Each effect is given by
    its products with ``[Q | added]`` and the residual, name → (cᵀc, [Q | added]ᵀc, cᵀr),
    ``r`` orthogonal to Q: what one walk of the poses makes for every effect
    (``signature.products``), where the columns themselves would cost a walk each. Only the
    added columns are orthogonalised anew: Qₐ = (added − QQᵀadded)Rₐ⁻¹, so
    Qₐᵀc = Rₐ⁻ᵀ(addedᵀc − (Qᵀadded)ᵀQᵀc)."""
    p = Q.shape[1]
    QB = Q.T @ added
    Bp = added - Q @ QB
    Qa, Ra = np.linalg.qr(Bp)
    ar = Qa.T @ r
    rss = float(r @ r - ar @ ar)
    dof = r.size - p - added.shape[1]
    drops = []
    for name, (cc, xc, cr) in prods.items():
        qc, bc = xc[:p], xc[p:]
        ac = np.linalg.solve(Ra.T, bc - QB.T @ qc)
        vis_cols, drop, _ = explained(cc, np.vstack([qc, ac]), cr - ac.T @ ar)
        drops.append((name, drop, int((vis_cols >= VISIBLE).sum())))
    return {name: p_value(drop, k, rss, dof, len(drops)) if k else 1.0 for name, drop, k in drops}


def rivals(best: tuple[float, int], others: dict[str, tuple[float, int]], sigma2_w: float, alpha: float,
           misfit_left: bool) -> tuple[str, ...]:
    """The candidates these data cannot tell from the best: each removes as much of the
    (whitened) residual within the noise, χ²(k, α)·σ̂², whatever its rank; and while the
    best leaves misfit (it is not the whole story), also those removing ``RIVAL`` of it.
    ``best`` and each of ``others`` (by name) are (residual sum of squares removed, columns
    tested)."""
    drop, k = best
    within = rival_margin(k, sigma2_w, alpha)
    return tuple(name for name, (d, k_o) in others.items() if k_o and (
        drop - d < within or (misfit_left and d >= RIVAL * drop)))


def rival_margin(k: int, sigma2_w: float, alpha: float) -> float:
    """The sum of squares within which two candidates of ``k`` columns explain a residual
    alike: χ²(k, α)·σ̂²."""
    return chi2_isf(alpha, max(k, 1)) * sigma2_w


def paired(best: np.ndarray, rivals: dict[str, np.ndarray], seconds: list[np.ndarray], rw: np.ndarray,
           off, within: float) -> tuple[str, ...]:
    """The rivals that stay so once the misfit the best leaves is explained as well: each
    candidate (whitened columns) joined in turn by each second effect ``seconds`` (those
    significant beside the best), its best pair's drop of the whitened residual ``rw``
    against the best's best pair; a rival within ``within`` of it stays one. Alone, a
    candidate is judged on a residual a second effect still moves: two drifts in time made
    the best's curve and its rivals remove 0.9 of one another's share over 80 minutes of
    data, where beside the second drift they differed by tens of σ̂²."""
    seconds = [off(s) for s in seconds]      # off the model once each: ``off`` is linear

    def pair(c: np.ndarray) -> float:
        c = off(c)
        return max(float(np.sum((span(np.column_stack([c, s])).T @ rw) ** 2)) for s in seconds)

    top = pair(best)
    return tuple(name for name, c in rivals.items() if top - pair(c) < within)


# One rule of separability, for fit and diagnose alike: the Jacobian's columns, each scaled
# to unit norm, must have a condition number below this (the seed's K4 alone is 27,
# K4+K1+K2 is 6); beyond it fit refuses the model and diagnose names nothing found.
COND_LIMIT = 1000.0


def condition(J: np.ndarray) -> float:
    """The condition number of ``J`` with its columns scaled to unit norm (inf when a column
    is zero or the columns are dependent). ``J`` may be any factor with the same Gram
    matrix, e.g. R of its QR factorisation."""
    norm = np.linalg.norm(J, axis=0)
    if not np.all(norm > 0):
        return np.inf
    s = np.linalg.svd(J / norm, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else np.inf
