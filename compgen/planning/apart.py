"""What a plan of measurements tells apart, before the machine moves: for each pair of named
effects, the size above which its readings would tell one from the other by the margin the
advice uses (``separation.TELLS_APART``: were one true, a fit with the other in its place
would leave 25 σ² of misfit, 5 σ), first order, from the plan's information matrix.

The information is per unit noise over the rotary axes' location errors and the effects'
parameters, every mounting's ball offset (and each later nest's) already taken out
(``plan._information``). For effects a and b: with M the location errors and b, the misfit
a of size x leaves is xᵀ S x, S = I_aa − I_aM I_MM⁺ I_Ma; the worst direction of x is S's
least eigenvalue λ, so a is told from b above 5 σ/√λ, whichever way a's parameters point. An
effect whose S against the location errors alone is (numerically) zero is absorbed by them:
no size of it is seen, by this plan."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from ..model.effects import ROT_OF, Effect, resolve, turning_pair
from ..model.machine import Machine
from ..statistics.separation import SEPARATES, TELLS_APART

# what the advice counts as separate: a column visible beyond the others by SEPARATES of its
# norm (``separation.separating``); S's least eigenvalue over its scale is that squared
SEEN = SEPARATES**2


def common_effects(machine: Machine) -> list[Effect]:
    """The catalogue's common effects of each rotary axis: its angular positioning error at
    1/rev and 2/rev, its radial error motion at 2/rev turning with it, and, where it tilts
    (not a whole turn), a sag turning against it (gravity: sin and 1 − cos). Backlash is
    left out: its start sides are free constants a plan's information does not hold."""
    out = []
    for a in machine.rotary_axes:       # (the comment above says why no backlash)
        rot = ROT_OF[a.direction].upper()
        u, w = (t.upper() for t in turning_pair(a.direction))
        names = [f"E{rot}{a.name}:h1", f"E{rot}{a.name}:h2", f"E{u}{a.name}+E{w}{a.name}:h2"]
        names += [] if a.full_turn else [f"E{u}{a.name}+E{w}{a.name}:h-1"]
        out += [resolve(machine, n) for n in names]
    return list({e.name: e for e in out}.values())


@dataclass(frozen=True)
class Apart:
    """One pair of effects: the size of each (in its own inside unit, mm or rad; inf where
    no size would do) above which, were it true, a fit with the other could not mimic it."""

    pair: tuple[str, str]
    above: tuple[float, float]


def _left(info: np.ndarray, a: list[int], beside: list[int]) -> np.ndarray:
    """S = I_aa − I_aM I_MM⁺ I_Ma: what of a's columns the columns ``beside`` leave."""
    Iaa = info[np.ix_(a, a)]
    if not beside:
        return Iaa
    M = info[np.ix_(beside, beside)]
    d = np.sqrt(np.clip(np.diag(M), 1e-300, None))
    B = info[np.ix_(a, beside)] / d
    return Iaa - B @ np.linalg.pinv(M / np.outer(d, d), rcond=1e-12) @ B.T


def separations(info: np.ndarray, p: int, spans: Mapping[str, slice], noise_um: float
                ) -> tuple[dict[str, bool], list[Apart]]:
    """Which effects ``spans`` (their parameters' columns after the ``p`` location errors)
    the information ``info`` (per unit noise) sees beyond the location errors, and each
    pair's ``Apart`` at noise ``noise_um`` per reading."""
    margin = np.sqrt(TELLS_APART) * noise_um * 1e-3
    loc = list(range(p))
    cols = {n: list(range(s.start, s.stop)) for n, s in spans.items()}

    def least(a: str, beside: list[int]) -> float:
        """The least of what ``beside`` leaves of a's columns, 0 where that is below ``SEEN``
        of a's own information (the advice's visibility, squared)."""
        lam = float(np.linalg.eigvalsh(_left(info, cols[a], beside)).min())
        scale = float(np.abs(np.diag(info[np.ix_(cols[a], cols[a])])).max())
        return lam if scale > 0 and lam > SEEN * scale else 0.0

    def above(a: str, b: str) -> float:
        lam = least(a, loc + cols[b])
        return margin / np.sqrt(lam) if lam else np.inf

    seen = {n: least(n, loc) > 0 for n in cols}

    out = [Apart((a, b), (above(a, b), above(b, a))) for a, b in combinations(cols, 2)]
    return seen, out


def holds(plan: Sequence[Apart], default: Sequence[Apart]) -> bool:
    """Whether ``plan`` tells apart, at some size, every pair (each way) ``default`` does:
    what the machine file's own paths can tell, a plan does not give up for σ. (At which
    size is a matter of minutes: both are in plan.json.)"""
    was = {x.pair: x.above for x in default}
    return all(np.isfinite(now) for x in plan for now, then in zip(x.above, was[x.pair], strict=True)
               if np.isfinite(then))
