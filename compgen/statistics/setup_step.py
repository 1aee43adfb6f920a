"""A set-up event between two files, as a rival of what the machine's candidates name.

compgen takes a ball at a new position as mounted again (``sides.mountings``): its offset
is fitted anew there. A ball taken off and put back at the same place between two files (or
in a pause within one), or a nest taken out and put back at the same length, is not seen
so: the fit gives both files one offset, and the step between them is left in the residual,
where a warming of
the ball (``XOW:e45``) or a drift fits most of it and would be named found. So each file
that continues the previous one's mounting (same ball position, same nest length) is
tried as a step of the ball's and the nest's offsets on its rows and the rest of that
mounting. Where the best step explains these data as well as the machine's best candidate
(``significance.rivals``), the best is not named found: which of the two happened is told
by measuring again without touching the set-up (a warming goes on, a step does not). A file
the user said was measured after the set-up was mounted again (``fit --mounted-again``) is a
new mounting already; one said not touched (``--not-touched``) is not tried."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..model.effects import resolve
from ..model.machine import Machine
from ..model.poses import Poses
from ..model.sides import NEST, SETUP, set_ups, span
from .ranking import Whitening, effect_columns
from .significance import p_value, rivals


@dataclass(frozen=True)
class SetupStep:
    """The best step of the set-up between two files: before which file (``before``), the
    step of the ball's offset and of the nest's (µm, as fitted beside the model), its
    p-value (Bonferroni over the files tried) and whether it rivals the machine's best."""

    before: str
    ball_um: tuple[float, ...]
    nest_um: tuple[float, ...]
    p_value: float
    significant: bool
    rival: bool

    def text(self) -> str:
        """"the ball or the nest mounted again before b.csv (ball +3.0 -2.0 +1.5 µm)"."""
        parts = [f"{what} {' '.join(f'{v:+.1f}' for v in um)}" for what, um in
                 (("ball", self.ball_um), ("nest", self.nest_um)) if um]
        return f"the ball or the nest mounted again before {self.before} ({', '.join(parts)} µm)"

    def to_dict(self) -> dict:
        return {"before": self.before, "ball_um": list(self.ball_um), "nest_um": list(self.nest_um),
                "p_value": self.p_value, "significant": self.significant, "rivals_best": self.rival}


def setup_step(machine: Machine, poses: Poses, set_of: np.ndarray, sets, r: np.ndarray, noise: Whitening,
               best: tuple[float, int] | None, rss_w: float, dof: int, alpha: float) -> SetupStep | None:
    """The step that removes most of the whitened residual ``r`` among the files (``sets``,
    ``set_of`` their index per pose) that continue the mounting before them; ``best`` the
    machine's best candidate as (whitened sum of squares removed, columns). None where no
    file continues a mounting."""
    names = [Path(d.source).name if d.source else f"file {k + 1}" for k, d in enumerate(sets)]
    mount, held = set_ups(machine, poses)
    ball = [resolve(machine, n) for n in SETUP]
    nest = [resolve(machine, n) for n in NEST]
    rw = noise.residual(r)
    tried = []
    for i0, where in _breaks(poses, set_of, sets, names):
        parts = []
        for effects, group in ((ball, mount), (nest, held)):
            if group[i0] != group[i0 - 1]:       # mounted anew already: fitted so
                parts.append(None)
                continue
            rows = (np.arange(len(poses)) >= i0) & (group == group[i0])
            c = np.hstack([effect_columns(machine, poses, e) for e in effects]).reshape(len(poses), 3, -1)
            parts.append((c * rows[:, None, None]).reshape(3 * len(poses), -1))
        cols = [p for p in parts if p is not None]
        if not cols:
            continue
        C = np.hstack(cols)
        Cw = noise.off(noise.white(C))
        basis = span(Cw)
        if not basis.shape[1]:
            continue
        drop = float(np.sum((basis.T @ rw) ** 2))
        coef = np.linalg.lstsq(Cw, rw, rcond=None)[0] * 1e3
        split = [p.shape[1] if p is not None else 0 for p in parts]
        tried.append((drop, basis.shape[1], where, tuple(coef[:split[0]]),
                      tuple(coef[split[0]:split[0] + split[1]])))
    if not tried:
        return None
    drop, k, before, ball_um, nest_um = max(tried, key=lambda t: t[0])
    p = p_value(drop, k, rss_w, dof, len(tried))
    significant = bool(p < alpha)
    rival = bool(significant and best is not None and (
        drop >= best[0] or rivals(best, {"step": (drop, k)}, rss_w / dof, alpha, False)))
    return SetupStep(before, tuple(map(float, ball_um)), tuple(map(float, nest_um)), p, significant, rival)


PAUSE_S = 120.0      # a break in time within a file this long: time enough to take the ball off


def _breaks(poses: Poses, set_of: np.ndarray, sets, names: list[str]) -> list[tuple[int, str]]:
    """Where a set-up event may have happened, as (first pose after it, how the text names
    it): each file after the first, unless the user said what happened before it; and each
    pause of ``PAUSE_S`` or more within a file (the clock running on)."""
    out = []
    for j in np.unique(set_of)[1:]:
        i0 = int(np.flatnonzero(set_of == j)[0])
        if i0 and not sets[j].said:        # the user said what happened: mounted again, or nothing
            out.append((i0, names[j]))
    gap = np.diff(poses.t)                 # NaN without a time column: no pause is seen
    within = set_of[1:] == set_of[:-1]
    for i in np.flatnonzero(within & (gap >= PAUSE_S)) + 1:
        out.append((int(i), f"{names[set_of[i]]} at t = {poses.t[i]:.0f} s (after a {gap[i - 1]:.0f} s "
                            "pause)"))
    return out
