"""Golden-section search: the least of a function unimodal on an interval, for many
intervals at once (the motion check's clearances, the residual's lines)."""

from __future__ import annotations

import numpy as np

RATIO = (np.sqrt(5.0) - 1) / 2


def golden_least(f, lo: np.ndarray, hi: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Per element, where a unimodal ``f`` (t (n,) → (n,)) is least over lo ≤ t ≤ hi, its
    ends included, to ``tol`` in t; and the least value."""
    a, b = np.asarray(lo, float).copy(), np.asarray(hi, float).copy()
    c, d = b - RATIO * (b - a), a + RATIO * (b - a)
    fc, fd = f(c), f(d)
    while np.max(b - a) > tol:
        left = fc < fd
        b = np.where(left, d, b)
        a = np.where(left, a, c)
        c, d = np.where(left, b - RATIO * (b - a), d), np.where(left, c, a + RATIO * (b - a))
        new = f(np.where(left, c, d))
        fc, fd = np.where(left, new, fd), np.where(left, fc, new)
    ts, values = np.stack([c, d, a, b]), np.stack([fc, fd, f(a), f(b)])
    best = np.argmin(values, axis=0)
    pick = np.arange(ts.shape[1])
    return ts[best, pick], values[best, pick]
