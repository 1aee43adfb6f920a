"""The measurements, among those the machine can make, that would separate what a
diagnosis's data cannot: an effect the model absorbs (or part of it), and rivals the data
cannot tell apart. The advisor (``advice.Advisor``) is given by the caller: it writes and
motion-checks each measurement's program, a layer above the statistics."""

from __future__ import annotations

from collections.abc import Sequence
from itertools import combinations

import numpy as np

from ..model.effects import Effect, effect_of_param
from ..model.machine import Machine
from ..model.poses import Poses
from ..model.sides import NEST, SETUP, both_sides, continues, set_ups, span
from .advising import Advising, Proposal
from .ranking import Row
from .signature import r_factor
from .significance import COND_LIMIT, condition

SEPARATES = 0.05      # visibility an extra measurement must give to count as separating
TELLS_APART = 25.0    # σ̂² of misfit a measurement must add between two rivals (5 σ)
EXACT = 1e-8          # what two effects leave of each other, of what each shows: one column
ADVISED = 3           # measurements named per effect, shortest first (each written and motion-checked)


class Measured:
    """R of the model's and the effects' columns on the measured poses, from one walk of
    them for ``separating`` and ``telling_apart`` alike (a walk of 723 000 readings is a
    second), and with each extra measurement's rows, added once: R of stacked data is R
    of the stacked R factors, and the R factor of a subset of columns is that of the same
    columns of R, so each effect is judged on small blocks.

    Each mounting of the ball after the first, and each nest after the first, carries an
    offset of its own (``FreeConstants``), as the fit has it: R is that of the columns less
    what those offsets fit (R of [offsets | columns], its lower right block), so a position
    the ball is moved to, or a longer nest, shows only what no mounting could. The offsets'
    columns are laid out once for all the data: a stretch of readings with one ball
    position and one nest is walked alone, and its R factor's columns are put where its
    offsets are. An extra measurement at the ball's last position continues that mounting,
    with the last nest's length that nest; elsewhere it is a mounting of its own."""

    def __init__(self, machine: Machine, model_effects: Sequence[Effect], poses: Poses,
                 effects: Sequence[Effect]):
        self.machine, self.poses = machine, poses
        effects = list({e.name: e for e in effects}.values())
        self.effects = [*model_effects, *effects]
        self.p = sum(len(e.params) for e in model_effects)
        self.cols, at = {}, self.p
        for e in effects:
            self.cols[e.name] = list(range(at, at + len(e.params)))
            at += len(e.params)
        # the ball's offset as the model holds it (each later mounting has as many columns),
        # and the nest's (three columns for each later nest)
        self.ball = [e for e in model_effects if e.name in SETUP and e.basis.kind == "const"]
        self.nest = [effect_of_param(machine, n) for n in NEST] if self.ball else []
        none = np.zeros(len(poses), int)           # no ball offset in the model: no set-up's constants
        mount, held = set_ups(machine, poses) if self.ball else (none, none)
        self.last = (int(mount[-1]), int(held[-1]))         # the mounting and nest an extra may continue
        self.layout, self.width = self._laid_out([*(("ball", k) for k in range(1, self.last[0] + 1)),
                                                  *(("nest", k) for k in range(1, self.last[1] + 1))])
        ends = [*np.flatnonzero(np.diff(mount) | np.diff(held)) + 1, len(poses)]
        self.full = self._stacked([self._walked(poses.take(slice(a, b)), (int(mount[a]), int(held[a])),
                                                self.layout, self.width)
                                   for a, b in zip([0, *ends[:-1]], ends, strict=True)])
        self.R = self._reduced(self.full, self.width)
        self._with: dict[str, np.ndarray] = {}

    def _laid_out(self, keys) -> tuple[dict[tuple[str, int], int], int]:
        """Where each later mounting's and nest's offset columns start, in the order of
        ``keys``, before the effects', and how many there are."""
        layout, at = {}, 0
        for key in keys:
            layout[key] = at
            at += len(self.ball if key[0] == "ball" else self.nest)
        return layout, at

    def _walked(self, poses: Poses, where: tuple[int, int], layout: dict, width: int) -> np.ndarray:
        """R of one stretch's columns (one ball mounting, one nest), its offsets' columns
        put where ``layout`` has them, zero in the other offsets'."""
        offsets = ((("ball", where[0]), self.ball), (("nest", where[1]), self.nest))
        lead = [(key, group) for key, group in offsets if key[1] > 0 and group]
        R = r_factor(self.machine, poses, [*(e for _, group in lead for e in group), *self.effects])
        out = np.zeros((R.shape[0], width + R.shape[1] - sum(len(g) for _, g in lead)))
        k = 0
        for key, group in lead:
            out[:, layout[key]:layout[key] + len(group)] = R[:, k:k + len(group)]
            k += len(group)
        out[:, width:] = R[:, k:]
        return out

    @staticmethod
    def _reduced(R: np.ndarray, width: int) -> np.ndarray:
        """R of the columns after the first ``width`` (the offsets') less what those fit: their
        span to its rank (a ball's and a nest's offsets may coincide in part on a path), where
        the lower right block of R would carry a column of rounding for each such direction."""
        if not width:
            return R
        U = span(R[:, :width])
        rest = R[:, width:]
        return np.linalg.qr(rest - U @ (U.T @ rest), mode="r")

    @staticmethod
    def _stacked(parts: Sequence[np.ndarray]) -> np.ndarray:
        return parts[0] if len(parts) == 1 else np.linalg.qr(np.vstack(parts), mode="r")

    def with_extra(self, extra: Proposal) -> np.ndarray:
        """R with ``extra``'s poses measured too (a program holds one ball position and one
        nest throughout): its new mounting's and nest's offsets laid out after the data's,
        zero on the data's rows."""
        if extra.label not in self._with:
            same = continues(self.machine, self.poses, extra.poses)
            where = tuple(k if kept else k + 1 for k, kept in zip(self.last, same, strict=True))
            new = [key for key in (("ball", where[0]), ("nest", where[1]))
                   if key[1] > 0 and key not in self.layout and self.ball]
            layout, width = self._laid_out([*self.layout, *new])
            full = np.hstack([self.full[:, :self.width], np.zeros((len(self.full), width - self.width)),
                              self.full[:, self.width:]])
            R = self._stacked([full, self._walked(extra.poses, where, layout, width)])
            self._with[extra.label] = self._reduced(R, width)
        return self._with[extra.label]


def separating(measured: Measured, effects: Sequence[Effect],
               advisor: Advising) -> dict[str, tuple[Proposal, ...]]:
    """For effects these data cannot tell from the model's (or not whole): the
    measurements the machine can make after which they could, shortest first, at most
    ``ADVISED``: each column then visible (``SEPARATES``) and the model with the effect
    separable as fit --add judges it."""
    machine, poses, p = measured.machine, measured.poses, measured.p
    found: dict[str, list[Proposal]] = {e.name: [] for e in effects}
    for extra in sorted(advisor.candidates, key=lambda m: len(m.poses)):
        R = measured.with_extra(extra)
        for e in effects:
            if e.basis.kind == "r" and not both_sides(machine, e.carrier, poses, extra.poses):
                continue    # one side throughout is the axis's zero offset, not its backlash
            Re = np.linalg.qr(R[:, [*range(p), *measured.cols[e.name]]], mode="r")
            vis = np.linalg.norm(Re[p:, p:], axis=0) / np.maximum(np.linalg.norm(Re[:, p:], axis=0), 1e-300)
            if vis.min() >= SEPARATES and condition(Re) < COND_LIMIT:
                found[e.name].append(extra)
    return {k: advisor.runnable(v, most=ADVISED) for k, v in found.items()}


def telling_apart(measured: Measured, group: Sequence[Row], sigma2: float, advisor: Advising
                  ) -> tuple[dict[str, tuple[Proposal, ...]], tuple[Proposal, ...], dict, tuple[str, ...]]:
    """Which measurements, not made yet and that the machine can make, tell the best
    (``group[0]``) and its rivals apart: a pair is told apart when, at their fitted sizes,
    they would differ by ``TELLS_APART`` σ̂² more than now (each hypothesis, were it true,
    would leave that much misfit in a fit of the other; first order).

    Returns, per rival, what tells it from the best (shortest first); the measurements that
    tell any pair apart, those telling every pair apart first; per measurement the pairs it
    leaves open; and the rivals that are the best's exact equivalents: one column with it,
    on these data and with every measurement the machine can make (what either leaves of
    the other below ``EXACT`` of what it shows beyond the model), one candidate under two
    names (``drift_Z:e15`` and ``ZOW:e15`` on a head over a C table). The measurements come
    as a plan: each tells apart the most pairs the ones before it leave open, until every
    pair is told apart or none is left that would."""
    effects = [row.effect for row in group]
    amps = {row.effect.name: row.amp for row in group}
    p, cols = measured.p, measured.cols

    def misfit(R, a, b):        # a true, fitted with the model and b: what a leaves
        Rs = np.linalg.qr(R[:, [*range(p), *cols[b], *cols[a]]], mode="r")
        k = len(cols[a])
        return float(np.sum((Rs[-k:, -k:] @ amps[a]) ** 2))

    def apart(R, a, b):
        return min(misfit(R, a, b), misfit(R, b, a))

    def shown(R, a):            # what a shows beyond the model alone
        Rs = np.linalg.qr(R[:, [*range(p), *cols[a]]], mode="r")
        return float(np.sum((Rs[p:, p:] @ amps[a]) ** 2))

    def one(R, a, b):
        return apart(R, a, b) <= EXACT * min(shown(R, a), shown(R, b))

    best = effects[0].name
    pairs = list(combinations([e.name for e in effects], 2))
    now = {pq: apart(measured.R, *pq) for pq in pairs}
    same = {e.name for e in effects[1:] if one(measured.R, best, e.name)}
    split = {}
    for extra in advisor.candidates:
        R = measured.with_extra(extra)
        same = {b for b in same if one(R, best, b)}
        gains = {pq: apart(R, *pq) - now[pq] for pq in pairs}
        told = {pq for pq, g in gains.items() if g >= TELLS_APART * sigma2}
        if told:
            split[extra.label] = (extra, told, sum(gains.values()))
    # a plan, greedily: each next measurement tells apart the most pairs still open (the
    # shortest among equals); more data never bring two hypotheses closer, so what each
    # tells apart alone, it tells apart in the plan too
    remaining, plan = set(pairs), []
    while remaining:
        ranked = sorted((s for s in split.values() if s[0] not in plan and s[1] & remaining),
                        key=lambda s: (-len(s[1] & remaining), len(s[0].poses), -s[2]))
        step = advisor.runnable([s[0] for s in ranked], most=1)
        if not step:
            break
        plan.append(step[0])
        remaining -= split[step[0].label][1]
    open_ = {m.label: tuple(pq for pq in pairs if pq not in split[m.label][1]) for m in plan}
    ordered = tuple(plan)
    by_rival = {}
    for e in effects[1:]:
        pair = (best, e.name)
        tells = sorted((s for s in split.values() if pair in s[1]), key=lambda s: (len(s[0].poses), -s[2]))
        by_rival[e.name] = advisor.runnable([s[0] for s in tells], most=ADVISED)
    equivalents = tuple(e.name for e in effects if e.name in same)
    return by_rival, ordered, {k: v for k, v in open_.items() if v}, equivalents
