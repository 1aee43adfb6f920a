"""What a fit cannot choose. An effect added to the model that these data cannot tell from
others of the catalogue (in its place, each removes the same misfit within the noise) leaves
the other parameters depending on the choice: a sag of A as EZA:h1 or as EYA+EZA:h-1 moves
ZOW and ZOA by tens of their σ. Each equivalent is fitted in its place, and half the range
of each parameter over the choices joins its σ: the reported uncertainty holds whichever of
them is the physical cause (the first-order rule of diagnose's rivals, χ²(k, α)·σ̂²)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from ..data.rtest import RTestData
from ..model.effects import compose, effect_name, location_model, resolve
from ..model.machine import Machine
from .diagnose import diagnose
from .identify import identify
from .results import FitResult
from .significance import ALPHA, chi2_isf


@dataclass(frozen=True)
class Choice:
    """An effect of the model, the catalogue effects these data cannot tell from it, and half
    the range of each other parameter over the fits with each in its place (mm, rad)."""

    effect: str
    equivalents: tuple[str, ...]
    half_range: dict[str, float]

    def to_dict(self) -> dict:
        return {"effect": self.effect, "equivalents": list(self.equivalents), "half_range": self.half_range}


def choices(machine: Machine, data: Sequence[RTestData], fit: FitResult, alpha: float = ALPHA,
            noise_um: float | None = None) -> tuple[Choice, ...]:
    """For every effect of ``fit``'s model beyond the location errors: the candidates that,
    with it left out, remove as much of the misfit within the noise (visible, significant),
    each fitted in its place. An effect no other matches gives no choice."""
    location = set(location_model(machine))
    fixed = {n: e.value for n, e in fit.parameters.items() if e.fixed}
    out = []
    for effect in dict.fromkeys(effect_name(n) for n in fit.free if n not in location):
        rest = compose(machine, fit.model, remove=[effect])
        kept = {n: v for n, v in fixed.items() if n in rest}
        base = identify(machine, data, rest, kept, fit.method, fit.sign)
        found = diagnose(machine, data, base, alpha=alpha, noise_um=noise_um)
        by_name = {c.effect: c for c in found.candidates}
        own = by_name.get(effect)
        if own is None or not own.significant:
            continue
        dof = found.readings - len(base.free)
        band = chi2_isf(alpha, len([n for n in fit.model if effect_name(n) == effect]))
        same = tuple(c.effect for c in found.candidates if c.effect != effect and c.visible
                     and c.significant and c.separable and (own.share - c.share) * dof < band)
        values = [{n: e.value for n, e in fit.parameters.items()}]
        for other in same:
            alt = identify(machine, data, compose(machine, rest, [other]), kept, fit.method, fit.sign)
            values.append({n: e.value for n, e in alt.parameters.items()})
        times = _times(machine, data, fit, rest, kept, effect, band)
        same, values = same + tuple(times), values + list(times.values())
        if not same:
            continue
        shared = [n for n in rest if n in fit.free]
        out.append(Choice(effect, same, {n: (max(v[n] for v in values) - min(v[n] for v in values)) / 2
                                         for n in shared}))
    return tuple(out)


def with_choices(machine: Machine, data: Sequence[RTestData], fit: FitResult, alpha: float = ALPHA,
                 noise_um: float | None = None) -> FitResult:
    """``fit`` with each parameter's σ widened by what the choices it cannot make move it
    (``choices``; independent choices add in quadrature), the choices recorded."""
    made = choices(machine, data, fit, alpha, noise_um)
    if not made:
        return fit
    extra = {n: math.sqrt(sum(c.half_range.get(n, 0.0) ** 2 for c in made)) for n in fit.parameters}
    return fit.widened(extra, choices=tuple(c.to_dict() for c in made))


TAU_STEPS = (0.6, 0.7, 0.8, 0.9, 1.1, 1.25, 1.4, 1.6)    # a warming's τ tried about its own


def _times(machine: Machine, data: Sequence[RTestData], fit: FitResult, rest: list[str], kept: dict,
           effect: str, band: float) -> dict[str, dict[str, float]]:
    """A warming (``eN``) at the time constants these data do not tell from its own: each in its
    place, its residual within the band of the fit's (χ²(k, α)·σ̂²); their values. The τ is
    the data's estimate (``timeconstant``), and a location error that shares the warming's
    direction moves with it (XOC by 3σ a minute on the fork head)."""
    e = resolve(machine, effect)
    if e.basis.kind != "e":
        return {}
    rss = fit.residual["sigma_um"] ** 2 * fit.residual["dof"]
    out = {}
    for k in TAU_STEPS:
        other = f"{e.symbol}:e{max(1, min(999, round(e.basis.order * k)))}"
        if other == effect or other in out:
            continue
        alt = identify(machine, data, compose(machine, rest, [other]), kept, fit.method, fit.sign)
        if alt.residual["sigma_um"] ** 2 * alt.residual["dof"] - rss < band * fit.residual["sigma_um"] ** 2:
            out[other] = {n: e.value for n, e in alt.parameters.items()}
    return out
