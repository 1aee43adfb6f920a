"""The measurement designed before the machine moves (``compgen plan``).

The set-ups searched are the ones compgen can write and check: each path of the machine file
with the ball where the advice may put it (as now, higher, lower, nearer the axis or farther
out), run one way or there and back, on a head with a longer nest, and each with every 2nd
or 4th of its poses. Each is written as ``measure-program`` writes it and moved through the
motion check, which also times it; what fails is not offered.

What a set of set-ups will tell is the covariance the fit will report on its data: the exact
Jacobian of the rotary axes' location errors at every pose, each mounting's ball offset (and
each nest's other than the machine file's) fitted beside them as ``identify`` does, under
white noise of ``noise_um`` per reading, or AR(1) noise of correlation ``rho`` within each
run for the plan chosen (the fit's sandwich covariance, ``noise.ar1_covariance``). The
search is a beam over sets of set-ups (``BEAM`` kept at each size), each set's information
the Schur complement of its set-ups' small products, for the least worst σ, each σ scaled by
its ``[limits]`` (offset_um for an offset, tilt_arcsec for a tilt), within the minutes; the
sets it met give the front of worst σ against minutes. A ball moved to another place is a
new mounting: it costs ``mount_minutes`` more, and its offset is fitted anew. ``checked``
runs a plan written before against the machine file as it is now.

Among the sets met, the plan is the one of least worst σ that tells apart every pair of the
named effects (``--effects``; default ``apart.common_effects``) the machine file's own paths
tell apart, by the advice's margin (``apart.py``); plan.json gives each pair's sizes, and the
condition of the location errors, for the plan and for the default.

A probe's plan (``device="probe"``) searches the probing programs instead (each path's poses
thinned to ``[probe] poses``, timed by the motion check as ``check-program`` times them);
``noise_um`` is then the trigger's noise per touch, and each pose's centre weighs as its
touches make it: information NᵀN per unit noise, N the touches' directions (``weights``).

Not built: the ball's positions beyond the advice's places, a reversal among the effects
told apart."""

from __future__ import annotations

import json
import shlex
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .. import me
from ..configuration.session import reload
from ..controllers.checking import check_file
from ..controllers.probing import probe_program
from ..controllers.programs import checked_program, measure_program, program_name
from ..controllers.registry import controller
from ..data.probe import need_probe, touch_directions
from ..data.rtest import Measurements, read_poses
from ..errors import CompgenError
from ..files import read_text
from ..model.effects import Effect, effect_of_param, location_model, resolve
from ..model.kinematics import Model
from ..model.machine import Machine
from ..model.poses import Poses, runs
from ..model.sides import NEST, SETUP, FreeConstants
from ..statistics.device import FORM
from ..statistics.noise import ar1_covariance
from ..statistics.results import load_fit
from ..statistics.separation import TELLS_APART
from ..units import DISPLAY
from .advice import MODE, Proposal, proposals
from .apart import Apart, common_effects, holds, separations

MOUNT_MINUTES = 5.0      # taking the ball off its place and mounting it at another, checked
BEAM = 40                # sets kept at each size of the search
THIN = (2, 4)            # a path also with every 2nd and every 4th of its poses (first and last kept)
FORMAT = "compgen.plan/1"
FRONT_STEP = 0.95
FRONT_MINUTES = 0.1      # points of the front closer in time than this are one: the better


@dataclass(frozen=True, eq=False)
class Setup:
    """One set-up of a plan: the advice's proposal and its minutes (the motion check's time
    of its program); with the products of its Jacobian, of the rotary axes' location errors
    (J), the ball's offset (G) and the nest's (N) at its poses, from which any set's
    information follows without walking the chains again."""

    proposal: Proposal
    minutes: float
    products: dict

    @property
    def ball(self) -> tuple[float, ...]:
        return self.proposal.ball


@dataclass(frozen=True)
class Plan:
    """A plan: its set-ups in the order to run them, its minutes (the programs' and each
    mounting's), each location error's predicted σ (mm or rad, the ball's offset left out:
    each mounting has its own) and the worst scaled σ; the front of worst scaled σ against
    minutes among the sets searched; and the same figures for the machine file's own paths
    (``default``)."""

    setups: tuple[Setup, ...]
    minutes: float
    sigma: dict[str, float]
    worst: float
    front: tuple[tuple[float, float], ...]
    default: tuple[float, dict[str, float], float]       # minutes, σ, worst
    noise_um: float
    rho: float
    told: Told | None = None            # what the plan tells: its condition and separations
    default_told: Told | None = None    # the same of the machine file's own paths
    told_kept: bool = True              # it tells apart every pair the default does, as well
    after: str = ""                     # a follow-up: the fit whose data it follows (``default``:
                                        # those data alone)
    device: str = "rtest"               # "probe": a touch probe's plan, noise_um per touch


@dataclass(frozen=True)
class Told:
    """What a set of set-ups tells beyond σ: the condition number of its location errors'
    Jacobian (columns scaled to unit norm), which named effects it sees beyond them, and
    each pair's separation (``apart.py``)."""

    condition: float
    seen: dict[str, bool]
    apart: tuple[Apart, ...]


def told_by(info: np.ndarray, p: int, effects: Sequence[Effect], noise_um: float) -> Told:
    loc = info[:p, :p]
    d = np.sqrt(np.clip(np.diag(loc), 1e-300, None))
    condition = float(np.sqrt(np.linalg.cond(loc / np.outer(d, d)))) if _identifies(loc) else np.inf
    spans, at = {}, p
    for e in effects:
        spans[e.name] = slice(at, at + len(e.params))
        at += len(e.params)
    seen, apart = separations(info, p, spans, noise_um)
    return Told(condition, seen, tuple(apart))


def judged(machine: Machine) -> list[str]:
    """The location errors a plan is judged by: the rotary axes' (each mounting of the ball
    has its own offset)."""
    return [n for n in location_model(machine) if n not in SETUP]


def scales(machine: Machine, names: Sequence[str]) -> np.ndarray:
    """Each location error's ``[limits]``, mm or rad: the unit of the worst scaled σ."""
    return np.array([machine.limits.offset_um * 1e-3 if effect_of_param(machine, n).unit == "mm"
                     else np.radians(machine.limits.tilt_arcsec / 3600) for n in names])


def weights(machine: Machine, poses: Poses, device: str) -> np.ndarray | None:
    """Per pose of a probe's plan, U (3 × 3) with UᵀU = NᵀN, N the directions of its touches
    (``probe.touch_directions``): its centre's information per unit touch noise, as the
    log's reader weighs it (covariance σ²(NᵀN)⁻¹); None for an R-test (σ per reading)."""
    if device != "probe":
        return None
    n = touch_directions(machine, poses, need_probe(machine))
    return np.linalg.cholesky(np.einsum("nmi,nmj->nij", n, n)).transpose(0, 2, 1)


def _weighed(weight: np.ndarray | None, J: np.ndarray) -> np.ndarray:
    return J if weight is None else np.einsum("nij,nj...->ni...", weight, J)


def covariance(machine: Machine, poses: Poses, noise_um: float, rho: float = 0.0,
               device: str = "rtest") -> np.ndarray:
    """The covariance of the rotary axes' location errors (``judged``) a fit of readings at
    ``poses`` reports (mm, rad), every mounting's and later nest's offset fitted beside them;
    infinite where the poses do not identify them. Under AR(1) noise of ``rho`` within each
    run, the fit's sandwich covariance; a probe's centres each weighed by its touches."""
    names = [*SETUP, *judged(machine)]
    p = len(names)
    J = fitted_columns(machine, poses, names, weights(machine, poses, device))
    flat = J.reshape(-1, p)
    G = flat.T @ flat
    if not _identifies(G):
        return np.full((p - 3, p - 3), np.inf)
    sigma = noise_um * 1e-3
    if rho:
        n = len(poses)
        cov = ar1_covariance(np.moveaxis(J, 2, 0), np.full((n, 3), sigma), runs(poses), np.full((n, 3), rho),
                             3 * n)
    else:
        cov = sigma**2 * np.linalg.inv(G)
    return cov[3:, 3:]


def fitted_columns(machine: Machine, poses: Poses, names: Sequence[str],
                   weight: np.ndarray | None = None) -> np.ndarray:
    """The Jacobian (n, 3, p) of ``names`` at ``poses`` as a fit of them has it: each later
    mounting's and nest's offset projected out (``FreeConstants``), as ``identify`` does;
    each pose weighed by ``weight`` (``weights``) where given."""
    J = _weighed(weight, Model(machine, names).linearise(poses)[1].copy())
    project = FreeConstants(machine, names, poses).projector(
        None if weight is None else lambda idx, a: _weighed(weight[idx], a))
    return J if project is None else project(J)


def _products(machine: Machine, poses: Poses, effects: Sequence[Effect] = (), device: str = "rtest") -> dict:
    """The small products of one set-up's columns: the location errors (``judged``) and the
    ``effects``' parameters after them (J), the ball's offset (G) and the nest's (N)."""
    names = [*judged(machine), *(n for e in effects for n in e.params)]
    w = weights(machine, poses, device)
    J = _weighed(w, Model(machine, names).linearise(poses)[1]).reshape(-1, len(names))
    G = _weighed(w, Model(machine, list(SETUP)).linearise(poses)[1]).reshape(-1, 3)
    N = _weighed(w, Model(machine, list(NEST)).linearise(poses)[1]).reshape(-1, 3)
    return {"JJ": J.T @ J, "JG": J.T @ G, "GG": G.T @ G, "JN": J.T @ N, "GN": G.T @ N, "NN": N.T @ N}


def _information(setups: Sequence[Setup], p: int) -> np.ndarray:
    """The information (per unit noise) of ``setups`` over the columns of their products,
    the rotary axes' location errors first (``p`` of them, and any effects' after): each ball
    mounting's offset and each nest other than the machine file's fitted beside them (a
    Schur complement of the small products)."""
    p = setups[0].products["JJ"].shape[0] if setups else p
    balls = list(dict.fromkeys(s.ball for s in setups))
    nests = list(dict.fromkeys(s.proposal.nest for s in setups if s.proposal.nest is not None))
    k = 3 * (len(balls) + len(nests))
    A, B, D = np.zeros((p, p)), np.zeros((p, k)), np.zeros((k, k))
    for s in setups:
        x, b = s.products, 3 * balls.index(s.ball)
        A += x["JJ"]
        B[:, b:b + 3] += x["JG"]
        D[b:b + 3, b:b + 3] += x["GG"]
        if s.proposal.nest is not None:
            m = 3 * (len(balls) + nests.index(s.proposal.nest))
            B[:, m:m + 3] += x["JN"]
            D[m:m + 3, m:m + 3] += x["NN"]
            D[b:b + 3, m:m + 3] += x["GN"]
            D[m:m + 3, b:b + 3] += x["GN"].T
    return A - B @ np.linalg.pinv(D, rcond=1e-10) @ B.T


def _identifies(G: np.ndarray) -> bool:
    """Whether normal equations ``G`` determine every parameter (columns scaled to unit norm,
    condition at most 1e12)."""
    norm = np.sqrt(np.clip(np.diag(G), 0.0, None))
    return bool((norm > 0).all()) and np.linalg.cond(G / np.outer(norm, norm)) <= 1e12


def worst_scaled(cov: np.ndarray, unit: np.ndarray) -> float:
    """The worst σ of a covariance over each parameter's ``[limits]``."""
    return float((np.sqrt(np.diag(cov)) / unit).max())


def _worst(info: np.ndarray, noise_um: float, unit: np.ndarray) -> float:
    """The worst scaled σ of the rotary axes' information (per unit noise; the first
    ``len(unit)`` columns of ``info``: the effects after them are not fitted)."""
    info = info[:len(unit), :len(unit)]
    if not _identifies(info):
        return np.inf
    var = np.diag(np.linalg.inv(info))
    if not (var > 0).all():          # rounding past what _identifies let through: not identified
        return np.inf
    return float((noise_um * 1e-3 * np.sqrt(var) / unit).max())


def candidates(machine: Machine, effects: Sequence[Effect] = (), device: str = "rtest") -> list[Setup]:
    """Every set-up the machine can run, timed by the motion check, its products holding
    the ``effects``' columns too: an R-test's programs, or a probe's (its poses thinned by
    ``[probe] poses`` already: each is offered whole)."""
    out = []
    offered = proposals(machine, None, device)
    for m in (v for p in offered for v in (_thinned(p) if device == "rtest" else [p])):
        try:
            seconds = _seconds(machine, m, device)
        except CompgenError:
            continue
        out.append(Setup(m, seconds / 60.0, _products(machine, m.poses, effects, device)))
    return out


def _seconds(machine: Machine, m: Proposal, device: str) -> float:
    """The program's time as the motion check counts it (a refusal raises)."""
    if device == "rtest":
        return checked_program(machine, m.poses, m.path, machine.controller, MODE, "PLAN", "", "").seconds
    ctl = controller(machine.controller)
    text = probe_program(machine, m.poses, m.path, ctl.name, "PLAN", "", "").files[ctl.program_ext]
    return check_file(machine, ctl, text, "PLAN").result.seconds


def _thinned(m: Proposal):
    """``m``, and ``m`` with every k-th of its poses (``THIN``): the same span in less time."""
    yield m
    if m.back:                    # a reversal needs each turn's poses as they come
        return
    n = len(m.poses)
    for k in THIN:
        idx = np.unique(np.r_[np.arange(0, n, k), n - 1])
        yield replace(m, label=f"{m.label}, every {k}{'nd' if k == 2 else 'th'} pose", name=f"{m.name}_E{k}",
                      poses=m.poses.take(idx))


def _ordered(setups: Sequence[Setup]) -> list[Setup]:
    """One mounting after the other: the set-ups at the first ball, then the next ball's."""
    balls = list(dict.fromkeys(s.ball for s in setups))
    return [s for b in balls for s in setups if s.ball == b]


def _minutes(setups: Sequence[Setup], mount_minutes: float) -> float:
    return sum(s.minutes for s in setups) + mount_minutes * max(len({s.ball for s in setups}) - 1, 0)


def _poses(setups: Sequence[Setup]) -> Poses:
    return Poses.concat([s.proposal.poses for s in _ordered(setups)])


def plan(machine: Machine, minutes: float, noise_um: float, rho: float = 0.0,
         mount_minutes: float = MOUNT_MINUTES, effects: Sequence[str] | None = None,
         device: str = "rtest") -> Plan:
    """The set-ups with the least worst scaled σ within ``minutes`` (a beam search over sets
    of the set-ups the machine can run, ``BEAM`` kept at each size) that tell apart every
    pair of ``effects`` (default ``common_effects``) the machine file's own paths tell apart
    (``apart.holds``); where no set within the minutes does, the least worst σ, and
    ``told_kept`` false."""
    if not minutes > 0:
        raise CompgenError(f"--minutes {minutes:g}: give the minutes the machine is yours for")
    if machine.program is None:
        raise CompgenError(f"machine file {machine.source} has no [program] section: a plan's set-ups are "
                           "its programs", hint="add tool, feed, dwell and clearance (see the bundled "
                                                "machines)")
    names = judged(machine)
    unit = scales(machine, names)
    named = common_effects(machine) if effects is None else \
        list({e.name: e for e in (resolve(machine, n) for n in effects)}.values())     # each once
    if len(named) < 2:
        raise CompgenError(f"--effects {','.join(effects or ())}: name two different effects or more to tell "
                           "apart", hint=f"the catalogue: {me()} effects --machine "
                                         f"{shlex.quote(machine.source)}")
    reversal = next((e.name for e in named if e.basis.kind == "r"), None)
    if reversal is not None:
        raise CompgenError(f"--effects {reversal}: a reversal's start sides are free constants a plan's "
                           "information does not hold yet", hint="leave it out; diagnose's advice on data "
                                                                  "tells a reversal apart")
    if device == "probe" and rho:
        raise CompgenError(f"--rho {rho:g}: a probe's touches are each their own trigger, not a series",
                           hint="leave --rho out for a probe's plan")
    offered = candidates(machine, named, device)
    own = [s for s in offered if s.proposal.label in machine.paths]
    if not own:
        raise CompgenError(f"no path of {machine.source} can be measured on this machine",
                           hint=f"check the paths with measure-program --machine {machine.source}")
    default_cov = covariance(machine, _poses(own), noise_um, rho, device)
    default = (_minutes(own, mount_minutes), sigmas_of(names, default_cov), worst_scaled(default_cov, unit))
    default_told = told_by(_information(own, len(names)), len(names), named, noise_um)

    level: list[frozenset] = [frozenset()]          # sets of set-ups, by their index in ``offered``
    seen: dict[frozenset, tuple[float, float]] = {}
    while level:
        grown = {}
        for base in level:
            for i in range(len(offered)):
                key = base | {i}
                if i in base or key in grown or key in seen:
                    continue
                sets = [*(offered[j] for j in sorted(base)), offered[i]]
                spent = _minutes(sets, mount_minutes)
                if spent <= minutes + 1e-9:
                    grown[key] = (_worst(_information(sets, len(names)), noise_um, unit), spent)
        seen |= grown
        level = [key for key in sorted(grown, key=lambda k: grown[k])[:BEAM]
                 if np.isfinite(grown[key][0]) or len(key) < len(names)]
    finite = {k: v for k, v in seen.items() if np.isfinite(v[0])}
    if not finite:
        raise CompgenError(f"no set of set-ups within {minutes:g} minutes identifies the location errors: "
                           f"the machine file's own paths take {default[0]:.1f}", hint="give more --minutes")
    best, told, kept = None, None, False
    for key in sorted(finite, key=lambda k: finite[k]):       # the least worst σ that tells apart
        sets = [offered[i] for i in sorted(key)]
        now = told_by(_information(sets, len(names)), len(names), named, noise_um)
        if best is None:
            best, told = key, now
        if holds(now.apart, default_told.apart):
            best, told, kept = key, now, True
            break
    chosen = _ordered([offered[i] for i in sorted(best)])
    cov = covariance(machine, _poses(chosen), noise_um, rho, device)
    front, low = [], np.inf
    for w, spent in sorted(finite.values(), key=lambda v: (v[1], v[0])):
        if w < FRONT_STEP * low:         # a point that buys a worst σ 5 % lower or more
            if front and spent - front[-1][0] < FRONT_MINUTES:
                front.pop()              # within a few seconds of the last: the better of the two
            front.append((spent, w))
            low = w
    return Plan(tuple(chosen), _minutes(chosen, mount_minutes), sigmas_of(names, cov),
                worst_scaled(cov, unit), tuple(front), default, noise_um, rho, told, default_told, kept,
                device=device)


def sigmas_of(names: Sequence[str], cov: np.ndarray) -> dict[str, float]:
    return {n: float(np.sqrt(max(cov[i, i], 0.0))) for i, n in enumerate(names)}


def _shown(names: Sequence[str], machine: Machine, sigma: dict[str, float]) -> dict:
    out = {}
    for n in names:
        unit, factor = DISPLAY[effect_of_param(machine, n).unit]
        out[n] = {"value": round(sigma[n] * factor, 6), "unit": unit}
    return out


def files(machine: Machine, p: Plan, folder: Path, version: str, date: str) -> dict[Path, str]:
    """The plan's files in ``folder``: each set-up's program and pose list, as
    ``measure-program`` writes them (each checked), and ``plan.json``."""
    ctl = controller(machine.controller)
    out: dict[Path, str] = {}
    setups = []
    for i, s in enumerate(p.setups, 1):
        m = s.proposal
        name = program_name(f"P{i}_{m.name}", room=4, most=ctl.name_max)
        probe = p.device == "probe"
        emitted = (probe_program(machine, m.poses, m.path, ctl.name, name, version, date) if probe
                   else measure_program(machine, m.poses, m.path, ctl.name, MODE, name, version, date))
        out |= emitted.paths(folder / f"{name}{ctl.program_ext}", name, ctl.program_ext)
        setups.append({"label": m.label, "path": m.path, "ball": [round(v, 4) for v in m.ball],
                       "probe_length": m.nest if m.nest is not None else machine.probe_length,
                       "there_and_back": m.back, "poses": f"{name}.poses.csv",
                       "program": f"{name}{ctl.program_ext}", "minutes": round(s.minutes, 2)})
    names = judged(machine)
    doc = {"format": FORMAT, "machine": machine.name, "controller": ctl.name, "device": p.device,
           "noise": {"noise_um": p.noise_um, "rho": p.rho, "per": {"probe": "touch"}.get(p.device, "reading"),
                     "model": "AR(1) within each run" if p.rho else "white"},
           "minutes": round(p.minutes, 2), "sigma": _shown(names, machine, p.sigma),
           "worst_scaled_sigma": p.worst, "scaled_by": {"offset_um": machine.limits.offset_um,
                                                          "tilt_arcsec": machine.limits.tilt_arcsec},
           "setups": setups, "mount_minutes": MOUNT_MINUTES,
           "front": [{"minutes": round(m, 2), "worst_scaled_sigma": w} for m, w in p.front],
           # a follow-up is set beside the data it follows; a plan beside the machine file's paths
           ("measured" if p.after else "default"): {
               **({"fit": p.after} if p.after else {"paths": list(machine.paths),
                                                    "minutes": round(p.default[0], 2)}),
               "sigma": _shown(names, machine, p.default[1]), "worst_scaled_sigma": p.default[2],
               **_told_doc(machine, p.default_told)},
           **_told_doc(machine, p.told),
           **({} if p.after else {"separations_as_default": p.told_kept}),
           "not_built": ["ball positions beyond the advice's places",
                         "backlash among the effects told apart (its start sides are free constants)"]}
    out[folder / "plan.json"] = json.dumps(doc, indent=2, ensure_ascii=False) + "\n"
    return out


def _told_doc(machine: Machine, told: Told | None) -> dict:
    """``condition`` and ``separations`` as plan.json holds them: each pair with the size of
    each effect above which it is told from the other (null: no size is), and the effects
    the location errors absorb whole."""
    if told is None:
        return {}

    def size(name: str, v: float):
        unit, factor = DISPLAY["mm" if name.startswith(FORM) else resolve(machine, name).unit]   # form: mm
        return {"value": round(v * factor, 4), "unit": unit} if np.isfinite(v) else None

    return {"condition": round(told.condition, 2) if np.isfinite(told.condition) else None,
            "separations": {"margin": f"{TELLS_APART:g} sigma^2 of misfit (5 sigma), as diagnose's advice",
                            "unseen": [n for n, ok in told.seen.items() if not ok],
                            "pairs": [{"pair": list(x.pair), "told_apart_above": {
                                n: size(n, v) for n, v in zip(x.pair, x.above, strict=True)}}
                                for x in told.apart]}}


def text(machine: Machine, p: Plan) -> str:
    """What ``compgen plan`` prints: the plan against the machine file's own paths, its set-ups
    in order, and the front."""
    unit_of = {n: DISPLAY[effect_of_param(machine, n).unit] for n in p.sigma}
    worst = max(p.sigma, key=lambda n: p.sigma[n] / scales(machine, [n])[0])
    plan, beside = ("with it ", "the data's") if p.after else ("plan    ", "the default's")
    lines = [f"compgen plan: {machine.name}; noise {p.noise_um:g} µm per "
             f"{'touch (a probe)' if p.device == 'probe' else 'reading'}"
             + (f", AR(1) ρ {p.rho:g} within each run" if p.rho else " (white)"),
             f"  {plan}{p.minutes:6.1f} min: worst σ {p.worst:.4f} of its [limits] "
             f"({worst} ±{p.sigma[worst] * unit_of[worst][1]:.3f} {unit_of[worst][0]})",
             f"  measured        : worst σ {p.default[2]:.4f} of its [limits] (the data of {p.after})"
             if p.after else f"  default {p.default[0]:6.1f} min: worst σ {p.default[2]:.4f} of its [limits] "
                             f"(the machine file's paths {', '.join(machine.paths)})",
             f"  ratio   {p.worst / p.default[2]:.2f} of {beside} worst σ", "", "  set-ups, in order:"]
    lines += [f"    {i}. {s.proposal.label:<58} {s.minutes:5.1f} min" for i, s in enumerate(p.setups, 1)]
    lines += _told_text(machine, p)
    if p.front:
        lines += ["", "  what more minutes buy (worst σ of its [limits]):"]
        lines += [f"    {m:6.1f} min  {w:.4f}" for m, w in p.front]
    return "\n".join(lines) + "\n"


def _told_text(machine: Machine, p: Plan) -> list[str]:
    """The condition and separations in a few lines: how many pairs each tells apart, and
    the pair the plan tells apart least well against the default's."""
    if p.told is None or p.default_told is None:
        return []

    def count(t: Told) -> int:
        return sum(all(np.isfinite(x.above)) for x in t.apart)

    was = "the data alone" if p.after else "default"
    out = ["", f"  condition {p.told.condition:.1f} ({was} {p.default_told.condition:.1f}); of "
           f"{len(p.told.apart)} pairs of {len(p.told.seen)} effects, told apart at some size: "
           f"{count(p.told)} ({was} {count(p.default_told)})"]
    if not p.told_kept:
        out.append("  no set within these minutes tells apart every pair the default does: this one has the "
                   "least worst σ (plan.json: separations)")
    unseen = [n for n, ok in p.told.seen.items() if not ok]
    if unseen:
        out.append(f"  absorbed by the location errors whole, on this plan: {', '.join(unseen)}")
    return out


def checked(machine: Machine, folder: Path) -> tuple[list[str], bool, dict]:
    """A plan written before, against ``machine`` as its file is now: each set-up's program
    through the motion check, and each σ from the pose lists the plan wrote; the lines to
    print, whether the plan holds (every program passes, every σ within 5 % of the plan's),
    and what it was made for (minutes, noise_um, rho)."""
    where = folder / "plan.json"
    try:
        doc = json.loads(read_text(where, "plan")[0])
    except (ValueError, RecursionError) as e:
        raise CompgenError(f"not a plan: {str(e)[:120]}", where=str(where)) from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or not isinstance(doc.get("setups"), list):
        raise CompgenError(f"not a plan compgen wrote ({FORMAT})", where=str(where))
    noise = doc.get("noise") if isinstance(doc.get("noise"), dict) else {}
    noise_um, rho = noise.get("noise_um"), noise.get("rho", 0.0)
    if not (_number(noise_um) and noise_um > 0 and _number(rho) and 0 <= rho < 1):
        raise CompgenError("the plan names no noise it was made for (noise_um, rho)", where=str(where))
    device = doc.get("device", "rtest")
    if device not in ("rtest", "probe"):
        raise CompgenError(f"a plan for the device {str(device)[:40]!r}: rtest or probe", where=str(where))
    made = {"minutes": doc.get("minutes") if _number(doc.get("minutes")) else None, "noise_um": noise_um,
            "rho": rho, "device": device}
    ctl = controller(machine.controller)
    lines, ok, poses = [], True, []
    for s in doc["setups"]:
        if not isinstance(s, dict) or not all(isinstance(s.get(k), str) for k in ("program", "poses")):
            raise CompgenError("a set-up without its program and pose list", where=str(where))
        program = folder / Path(s["program"]).name
        result = check_file(machine, ctl, read_text(program, "program", ansi_ok=True)[0], str(program)).result
        ok &= not result.findings
        lines.append(f"  {program.name}: " + (result.first(program.name) if result.findings else
                                              f"OK, about {result.seconds / 60:.1f} min"))
        listed = folder / Path(s["poses"]).name
        try:
            poses.append(read_poses(str(listed), machine))
        except CompgenError as e:          # a pose list this machine file no longer takes
            ok, poses = False, [*poses, None]
            lines.append(f"  {listed.name}: {e}")
    if any(p is None for p in poses):
        return [*lines, "  σ not evaluated: a pose list is not this machine file's"], False, made
    follows = doc.get("measured").get("fit") if isinstance(doc.get("measured"), dict) else None
    if isinstance(follows, str):      # a follow-up: its σ is the fit's data and it together
        try:
            data = reload(load_fit(follows), machine.source)[1]
        except CompgenError as e:
            return [*lines, f"  σ not evaluated: the data it follows: {e}"], False, made
        before = Measurements.concat(data).poses
        poses = [before, *(p.with_setup(int(before.setup[-1])) for p in poses)]
    cov = covariance(machine, Poses.concat(poses), noise_um, rho, device)
    now = _shown(judged(machine), machine, sigmas_of(judged(machine), cov))
    for n, was in (doc.get("sigma") if isinstance(doc.get("sigma"), dict) else {}).items():
        got = now.get(n)
        planned = was.get("value") if isinstance(was, dict) else None
        same = got is not None and _number(planned) and abs(got["value"] - planned) <= 0.05 * abs(planned)
        ok &= same
        lines.append(f"  {n:<6} σ {planned if _number(planned) else float('nan'):.4f} → "
                     + (f"{got['value']:.4f} {got['unit']}" if got else "not a location error now")
                     + ("" if same else "  (changed)"))
    return lines, ok, made


def _number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v)
