"""Where the model fails, and which physical effect would explain it.

For every catalogue effect not in the model: its first-order signature c on the measured
poses (``signature.py``), the part c⊥ that the model's parameters cannot absorb, the
residual sum of squares it would remove, an F test, and Bonferroni's correction for the
number of effects tried (``significance.py``). An effect whose signature the model absorbs
entirely (‖c⊥‖/‖c‖ below ``VISIBLE``), or that ``fit --add`` would refuse on these data
(one rule: ``significance.condition``), is never "found": it is reported with the
measurement that would separate it, and only measurements the machine can make are named
(an advisor the caller passes in: ``advice.Advisor``, which writes and checks their
programs). The words are ``diagnose_text.py``'s.

References: ``docs/diagnose.md`` (visibility, bias, F and score tests).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from itertools import combinations
from typing import TYPE_CHECKING

import numpy as np

from .effects import Effect, catalogue, effect_of_param, resolve
from .errors import CompgenError
from .kinematics import Model, Poses, runs
from .machine import Machine
from .noise import Repeats, ar1, outliers, repeats, whiten
from .results import FitResult
from .rtest import RTestData, device_of
from .sides import StartSides, both_sides, same_pose
from .signature import columns, products, r_factor
from .significance import (
    ALPHA,
    COND_LIMIT,
    VISIBLE,
    condition,
    explained,
    gram_factor,
    lack_of_fit,
    p_value,
    rivals,
    still_significant,
)
from .spectrum import Line, strongest_lines
from .units import shown

if TYPE_CHECKING:        # the type only: advice writes programs, a layer above
    from .advice import Advisor, Measurement

SEPARATES = 0.05      # visibility an extra measurement must give to count as separating
ABSORBS = 0.25        # share of an effect's signature a parameter must take to be named
SILENT_UM = 1e-9      # µm per unit over all readings: the effect moves nothing at all
TELLS_APART = 25.0    # σ̂² of misfit a measurement must add between two rivals (5 σ)
ADVISED = 3           # measurements named per effect, shortest first (each written and motion-checked)
# Where the residual exceeds the R-test's own noise, the best candidate must remove this
# share of the excess to be named: a catalogue curve that fits a little of an effect outside
# the catalogue by chance (a 5 mm screw period removed ~10 % as EXC:h3) is not its cause
SHARE_OF_EXCESS = 1 / 3
# Without the R-test's noise: a periodic line along a linear axis (no catalogue effect has
# that shape) removing this many times what the best candidate removes is what is missing
LINE_OVER_BEST = 2.0
# ... and removing at least this share of the residual: a line the scan over a continuum of
# pitches finds in white noise removes ~1 % (3 of 40 clean B/C sessions were called
# unexplained for such lines); a missing periodic error is most of the misfit
LINE_SHARE = 0.1
RESOLVES_UM = 0.1     # an R-test's sensors resolve about this: a smaller line is not a finding


@dataclass(frozen=True)
class Candidate:
    effect: str
    description: str
    cause: str
    visibility: float
    rms_after_um: float
    p_value: float          # Bonferroni-adjusted
    significant: bool
    confounded_with: tuple[str, ...]
    amplitude: tuple[float, ...]     # first-order estimate, in its shown unit
    unit: str
    separated_by: tuple[Measurement, ...] = ()
    silent: bool = False    # moves no reading at all on these poses (no lever arm)
    share: float = 0.0      # of the (whitened) residual sum of squares it removes: the ranking
    condition: float = 0.0  # of the model with it added, as fit --add computes it

    @property
    def visible(self) -> bool:
        return self.visibility >= VISIBLE

    @property
    def separable(self) -> bool:
        """``fit --add`` accepts it with these data (the same rule, the same limit)."""
        return self.condition < COND_LIMIT


@dataclass(frozen=True, eq=False)
class Diagnosis:
    machine: str
    fit_file: str
    model: tuple[str, ...]
    rms_um: float
    sigma_um: float
    readings: int
    per_path: dict
    per_axis: dict
    candidates: tuple[Candidate, ...]   # visible best first, then the invisible
    bias: dict[str, dict[str, float]]   # parameter → {candidate parameter: shift per unit}
    bias_units: dict[str, str]          # shown unit of every parameter and candidate parameter
    signature_um: dict[str, float]      # RMS displacement over the poses per unit, µm
    tested: int
    after_best: tuple[str, ...] = ()    # still significant once the best candidate is added
    rivals: tuple[str, ...] = ()        # explain almost as much as the best: not told apart
    rivals_separated_by: tuple[Measurement, ...] = ()
    alpha: float = ALPHA
    notes: tuple[str, ...] = field(default_factory=tuple)
    outliers: tuple[dict, ...] = ()     # {"file", "line", "path", "size_um"}: left out of the tests
    noise: dict = field(default_factory=dict)   # path → AR(1) ρ̂ per direction used by the tests
    rivals_open: dict = field(default_factory=dict)   # label → pairs of rivals it leaves apart
    machine_ref: str = ""   # how a command names the machine file (--machine)
    program_ext: str = ""   # the suffix of the machine's control's programs
    device_noise_um: float | None = None   # the R-test's own noise, when given; a probe's, from its touches
    repeats: Repeats | None = None         # device_noise_um estimated from readings that repeat a pose
    data_device: str = "rtest"             # "probe": the data are sphere centres from probe logs
    misfit: tuple[dict, ...] = ()   # (path, direction) whose residual exceeds that noise, worst first
    lines: tuple[Line, ...] = ()    # the residual's strongest periodic line against each coordinate
    best_share_of_excess: float | None = None   # of the residual beyond the noise, the best removes
    best_sum_sq: float = 0.0        # the residual sum of squares the best significant candidate removes, mm²
    # for rivals: what adding each puts into the fitted parameters, first order, shown units
    carries: dict[str, dict[str, float]] = field(default_factory=dict)

    @property
    def unexplained(self) -> bool:
        """No catalogue effect accounts for the misfit (``_unexplained``)."""
        return _unexplained(self.misfit, bool(self.significant), self.best_share_of_excess, self.outside_line)

    @property
    def outside_line(self) -> Line | None:
        return _outside_line(self.lines, self.device_noise_um, self.misfit, self.alpha, self.best_sum_sq)

    @property
    def noise_from(self) -> str | None:
        """Where ``device_noise_um`` comes from: "given" (machine file or --noise-um), the
        probe's "touches", or "repeats" of poses in the data."""
        if self.device_noise_um is None:
            return None
        return "touches" if self.data_device == "probe" else "repeats" if self.repeats else "given"

    @property
    def explained_to_noise(self) -> bool:
        return not self.significant and not self.misfit and not self.unexplained

    @property
    def significant(self) -> tuple[Candidate, ...]:
        return tuple(c for c in self.candidates if c.significant)

    @property
    def next_measurement(self) -> tuple[Measurement | None, tuple[str, ...]]:
        """The one measurement that would show the most effects these data cannot see
        (shortest first among equals), and those effects."""
        shows: dict[str, list[str]] = {}
        by_label = {}
        for c in self.candidates:
            if not c.visible or (c.significant and not c.separable):
                for m in c.separated_by:
                    shows.setdefault(m.label, []).append(c.effect)
                    by_label[m.label] = m
        if not shows:
            return None, ()
        best = max(shows, key=lambda k: (len(shows[k]), -len(by_label[k].poses)))
        return by_label[best], tuple(shows[best])

    @property
    def found(self) -> str | None:
        """The effect named as missing: significant, first, with no rival, one that ``fit
        --add`` accepts on these data, and not a small part of an unexplained misfit."""
        best = self.significant[0] if self.significant else None
        named = best is not None and not self.rivals and best.separable and not self.unexplained
        return best.effect if named else None

    def to_dict(self) -> dict:
        return {
            "format": "compgen.diagnose/1", "machine": self.machine, "fit": self.fit_file,
            "model": list(self.model), "rms_um": self.rms_um, "sigma_um": self.sigma_um,
            "readings": self.readings, "tested": self.tested, "alpha": self.alpha,
            "explained_to_noise": self.explained_to_noise,
            "device_noise_um": self.device_noise_um,
            "device_noise_from": self.noise_from,
            "repeats": self.repeats and {**asdict(self.repeats), "words": self.repeats.words()},
            "misfit": list(self.misfit),
            "unexplained": self.unexplained,
            "best_share_of_excess": self.best_share_of_excess,
            "residual_lines": [line.to_dict() for line in self.lines],
            "rivals_carry": {"units": {n: self.bias_units[n] for n in self.model if n in self.bias_units},
                             "shift_by_choice": self.carries},
            "still_significant_after_best": list(self.after_best),
            "rivals_of_best": list(self.rivals),
            "found": self.found,
            "rivals_equivalent": bool(self.rivals and not self.rivals_separated_by),
            "next_measurement": None if self.next_measurement[0] is None else {
                **self.next_measurement[0].to_dict(), "would_show": list(self.next_measurement[1])},
            "rivals_separated_by": [{**m.to_dict(), "leaves_open": [list(p) for p in self.rivals_open.get(
                m.label, ())]} for m in self.rivals_separated_by],
            "outliers": list(self.outliers),
            "noise_ar1_rho": self.noise,
            "per_path": self.per_path, "per_axis": self.per_axis,
            "candidates": [{
                "effect": c.effect, "significant": c.significant, "visible": c.visible,
                "visibility": c.visibility, "rms_after_um": c.rms_after_um,
                "p_value": c.p_value, "share_explained": c.share, "separable": c.separable,
                "condition_with_it": c.condition if np.isfinite(c.condition) else None,
                "confounded_with": list(c.confounded_with),
                "separated_by": [m.to_dict() for m in c.separated_by], "silent": c.silent,
                "amplitude": list(c.amplitude),
                "amplitude_unit": c.unit, "description": c.description, "cause": c.cause}
                for c in self.candidates],
            "bias_sensitivity": {"units": self.bias_units, "shift_per_unit": self.bias,
                                 "signature_rms_um_per_unit": self.signature_um},
        }


def diagnose(machine: Machine, data: Sequence[RTestData], fit: FitResult,
             candidates: Sequence[str] | None = None, alpha: float = ALPHA,
             fit_file: str = "", advisor: Callable[..., Advisor] | None = None, machine_ref: str = "",
             noise_um: float | None = None) -> Diagnosis:
    """Rank the effects not in ``fit``'s model by how much of its residual they explain.

    Outlying readings are listed and left out; the tests are made on the readings made white
    by their segments' AR(1) correlation (``noise.py``), estimated from the residual once the
    best candidate is added (the misfit of a missing effect is not noise). With an
    ``advisor`` (``advisor(machine, poses, device)``: ``advice.Advisor``), the measurements
    that would separate what these data cannot are searched for among those the machine can
    make; ``machine_ref`` is how the commands printed name the machine file. ``noise_um``
    is the R-test's own noise (default: the machine file's ``[rtest] noise_um``): with it,
    the residual is tested against it per path and direction, and what no catalogue effect
    accounts for is called unexplained."""
    kind = device_of(data)
    device = noise_um if noise_um is not None else machine.noise_um
    if kind == "probe" and noise_um is None:   # a probe's centres carry their noise from the touches
        cov = np.concatenate([d.cov for d in data])
        device = float(np.sqrt(np.einsum("nii->", cov) / (3 * len(cov)))) * 1e3
    poses = Poses.concat([d.poses for d in data])
    y = np.concatenate([d.deviation for d in data])
    model = Model(machine, fit.model)
    x = np.array([fit.parameters[n].value for n in fit.model])
    free = [model.names.index(n) for n in fit.free]
    r3 = y - model.deviation(poses, x)
    starts = StartSides(machine, fit.model, poses).projector()
    if starts is not None:       # each path's start side, fitted as fit fits it
        r3 = starts.remove(r3)
    seg = runs(poses, np.repeat(np.arange(len(data)), [len(d) for d in data]))
    bad, size = outliers(r3 * 1e3, seg)
    if bad.size:
        keep = np.ones(len(poses), bool)
        keep[bad] = False
        poses, r3, seg = poses.take(keep), r3[keep], seg[keep]
        starts = StartSides(machine, fit.model, poses).projector()
    # no noise given: what the data repeat says it, where they repeat enough
    said = repeats(same_pose(machine, poses, seg), r3, seg) if device is None else None
    device = said.sigma_um if said is not None else device
    r = r3.ravel()
    # only Q and R of the model's Jacobian are kept: J's column norms are R's. Free start
    # sides (``StartSides``) come first in Q, and R is that of J without them, as fit has it
    J = model.jacobian(poses, x)[:, :, free]        # indexed by a list: a copy, projected in place
    Q, R = np.linalg.qr((J if starts is None else starts(J)).reshape(r.size, -1))
    if starts is not None:
        Q = np.hstack([starts.basis(len(poses)), Q])
    r = r - Q @ (Q.T @ r)             # the fit's residual without the outliers
    rss, dof = float(r @ r), r.size - Q.shape[1]

    in_model = {effect_of_param(machine, n).name for n in fit.model}
    effects = [e for e in (catalogue(machine) if candidates is None
                           else [resolve(machine, c) for c in candidates]) if e.name not in in_model]
    notes = ()
    if candidates is None and np.isnan(poses.t).any():   # a drift needs the time of every reading
        timed = [e.name for e in effects if e.carrier == "time" or e.basis.kind == "e"]
        effects = [e for e in effects if e.name not in timed]
        if timed:
            notes = (f"  not tried: {', '.join(timed)} (they need the time t of every reading; "
                     "these data do not give it)",)
    if not effects:
        raise CompgenError("no candidate effect left to try: the model holds them all")
    # ρ̂ from the residual once the best candidate (least squares) is added: the misfit of
    # a missing effect is not noise; then, if the noise is correlated, rank again whitened
    noise = _Noise(seg, np.zeros_like(r3), Q)
    plain = products(machine, poses, effects, Q, r)
    started = _started(machine, poses, effects)
    plain |= {e: (C.T @ C, Q.T @ C, C.T @ r) for e, C in started.items()}
    ranked = _rank(effects, fit.free, R, r, noise, plain)
    best = max(ranked.values(), key=lambda row: (row.vis >= VISIBLE, row.share))
    c = _columns(machine, poses, best.effect)
    rest = r - c @ np.linalg.lstsq(c - Q @ (Q.T @ c), r, rcond=None)[0]
    rho = ar1((rest - Q @ (Q.T @ rest)).reshape(-1, 3), seg)
    if rho.any():
        noise = _Noise(seg, rho, Q)
        rw = noise.off(noise.white(r))
        white = products(machine, poses, effects, noise.Q, rw, (seg, rho))
        white |= {e: (Cw.T @ Cw, noise.Q.T @ Cw, Cw.T @ rw)
                  for e, Cw in ((e, noise.white(C)) for e, C in started.items())}
        ranked = _rank(effects, fit.free, R, r, noise, plain, white)
    rss_w = noise.rss(r)

    tested = sum(1 for row in ranked.values() if row.k_eff)
    out = []
    for e in effects:
        row = ranked[e.name]
        p = p_value(row.drop_w, row.k_eff, rss_w, dof, tested) if row.k_eff else 1.0
        out.append(Candidate(
            effect=e.name, description=e.words, cause=e.cause, visibility=row.vis,
            rms_after_um=float(np.sqrt(max(rss - row.drop, 0.0) / r.size)) * 1e3, p_value=p,
            significant=bool(row.k_eff and p < alpha), confounded_with=row.names,
            amplitude=tuple(shown(a, e.unit)[0] for a in row.amp), unit=shown(1.0, e.unit)[1],
            silent=row.silent, share=row.share, condition=row.cond))
    out.sort(key=lambda c: (not c.visible, -c.share))
    model_effects = list(dict.fromkeys(effect_of_param(machine, n) for n in fit.free))
    advising = advisor(machine, poses, kind) if advisor is not None else None
    # seen, but not to be added as a whole: a part of it the model absorbs (fit --add
    # refuses it), so the measurement that shows that part is what to advise
    unseen = [c for c in out if not c.visible or (c.significant and not c.separable)]
    if advising is not None and unseen:
        seen = _separating(machine, model_effects, poses, [resolve(machine, c.effect) for c in unseen],
                           advising)
        out = [replace(c, separated_by=seen[c.effect]) if c.effect in seen else c for c in out]

    # bias: data holding a unit of candidate parameter j shift the fitted parameters by
    # (J⁺C)ᵢⱼ, first order; kept in shown units (µm or ″ per µm or ″ of j)
    units_of = {n: model.effects[model.names.index(n)].unit for n in fit.free}
    bias = {n: {} for n in fit.free}
    units = {n: shown(1.0, units_of[n])[1] for n in fit.free}
    signature_um = {}
    for e in effects:
        row = ranked[e.name]
        for j, pname in enumerate(e.params):
            units[pname] = shown(1.0, e.unit)[1]
            per_shown = shown(1.0, e.unit)[0]
            signature_um[pname] = float(row.norms[j] / np.sqrt(len(poses))) * 1e3 / per_shown
            for i, n in enumerate(fit.free):
                bias[n][pname] = float(row.absorbed[i, j] * shown(1.0, units_of[n])[0] / per_shown)

    significant = [c for c in out if c.significant]
    misfit, share = (), None
    if device is not None:
        misfit = tuple(lack_of_fit(r.reshape(-1, 3), poses.path, device, noise.rho, dof / r.size, alpha))
        excess = rss - dof * (device * 1e-3) ** 2
        if significant and excess > 0:
            share = min(1.0, ranked[significant[0].effect].drop / excess)
    lines = strongest_lines(machine, poses, r.reshape(-1, 3), Q)
    best_sum_sq = ranked[significant[0].effect].drop if significant else 0.0
    unexplained = _unexplained(misfit, bool(significant), share,
                               _outside_line(lines, device, misfit, alpha, best_sum_sq))

    # rivals of a curve that fits a little of an unexplained misfit by chance: not pursued
    after_best, rival_names, rivals_separated_by, rivals_open = (), (), (), {}
    if unexplained:
        significant = []
    if len(significant) > 1:
        first = noise.white(_columns(machine, poses, resolve(machine, significant[0].effect)))
        others = [resolve(machine, c.effect) for c in significant[1:]]
        kept = still_significant(noise.Q, first, noise.white(r), (
            (e, noise.white(_columns(machine, poses, e))) for e in others), alpha)
        after_best = tuple(e.name for e in others if e.name in kept)
    if significant:
        best = ranked[significant[0].effect]
        rival_names = rivals((best.drop_w, best.k_eff), {
            c.effect: (ranked[c.effect].drop_w, ranked[c.effect].k_eff)
            for c in out if c.visible and c.effect != best.effect.name}, rss_w / dof, alpha, bool(after_best))
        if rival_names and advising is not None:
            group = [best, *(ranked[e] for e in rival_names)]
            by_rival, rivals_separated_by, rivals_open = _telling_apart(
                machine, model_effects, poses, group, rss / dof, advising)
            out = [replace(c, separated_by=by_rival[c.effect]) if c.effect in by_rival else c for c in out]
        if rival_names and advising is not None and not rivals_separated_by:
            # equivalent everywhere: put first the one the location errors absorb least, so
            # that adding it leaves them where an effect without that absorbed part has them
            group = [c for c in out if c.significant and c.effect in (best.effect.name, *rival_names)]
            first = max(group, key=lambda c: c.visibility)
            if first.effect != best.effect.name:
                out.remove(first)
                out.insert(out.index(next(c for c in out if c.effect == best.effect.name)), first)
                rival_names = tuple(c.effect for c in out if c.effect in (best.effect.name, *rival_names)
                                    and c is not first)

    # what each rival, added, takes back from the fitted parameters (first order: the part
    # of it they absorbed, J⁺c·a): where rivals are equivalent, the choice moves these
    carries = {}
    first = next((c.effect for c in out if c.significant), None)     # after the reordering above
    for name in ((first, *rival_names) if rival_names else ()):
        row = ranked[name]
        shift = -(row.absorbed @ row.amp)
        carries[name] = {n: float(shift[i] * shown(1.0, units_of[n])[0]) for i, n in enumerate(fit.free)}

    return Diagnosis(
        machine=machine.name, fit_file=fit_file, model=fit.model,
        rms_um=float(np.sqrt(rss / r.size)) * 1e3, sigma_um=float(np.sqrt(rss / dof)) * 1e3,
        readings=int(r.size), per_path=fit.residual["per_path"],
        per_axis=_per_axis(machine, poses, r.reshape(-1, 3)),
        candidates=tuple(out), bias=bias, bias_units=units, signature_um=signature_um,
        tested=tested, alpha=alpha,
        after_best=after_best, rivals=rival_names, rivals_separated_by=rivals_separated_by,
        outliers=_outlier_rows(data, bad, size), noise=_noise_summary(seg, noise.rho, poses.path),
        rivals_open=rivals_open, machine_ref=machine_ref or machine.source,
        program_ext=advising.program_ext if advising is not None else "", device_noise_um=device,
        repeats=said, misfit=misfit,
        lines=lines, best_share_of_excess=share, best_sum_sq=best_sum_sq, carries=carries, notes=notes,
        data_device=kind)


def _beyond_starts(cc: np.ndarray, qc: np.ndarray, m: int) -> np.ndarray:
    """The visibility of a reversal's own m columns beyond the model and its start sides (the
    columns after them), from products: ‖c⊥‖/‖c‖ with c⊥ orthogonal to both. A reversal
    whose side is the same throughout is its axis's zero offset: its constants and the
    location errors take it whole, whatever its columns alone would show."""
    P = cc - qc.T @ qc
    S = P[:m, :m] - P[:m, m:] @ np.linalg.lstsq(P[m:, m:], P[m:, :m], rcond=None)[0]
    norms = np.sqrt(np.diag(cc)[:m])
    return np.where(norms > 0, np.sqrt(np.clip(np.diag(S), 0, None)) / np.where(norms > 0, norms, 1), 0.0)


def _without_b(R: np.ndarray, qj: np.ndarray, cc: np.ndarray, m: int) -> np.ndarray:
    """The Gram matrix of X = [J | c] less its part along a candidate's start sides B, from
    products alone: J = Q_J R and C = [c | B] with qj = Q_Jᵀ C, cc = CᵀC."""
    XX = np.block([[R.T @ R, R.T @ qj[:, :m]], [qj[:, :m].T @ R, cc[:m, :m]]])
    XB = np.vstack([R.T @ qj[:, m:], cc[:m, m:]])
    return XX - XB @ np.linalg.lstsq(cc[m:, m:], XB.T, rcond=None)[0]


def _started(machine: Machine, poses: Poses, effects: Sequence[Effect]) -> dict[str, np.ndarray]:
    """The reversal candidates that come with start sides on these poses (data without the
    axis's side), by name: their columns as ``_columns`` makes them."""
    return {e.name: _columns(machine, poses, e) for e in effects
            if e.basis.kind == "r" and StartSides(machine, e.params, poses).count}


def _columns(machine: Machine, poses: Poses, e: Effect) -> np.ndarray:
    """An effect's first-order columns (3n, m); for a reversal on data that do not say each
    pose's side, followed by the start sides ``fit --add`` fits with it (``StartSides``): so
    what diagnose tries is what fit would fit."""
    c = columns(machine, poses, [e])
    starts = StartSides(machine, e.params, poses).projector() if e.basis.kind == "r" else None
    return c if starts is None else np.hstack([c, starts.basis(len(poses))])


def _unexplained(misfit, significant: bool, share: float | None, outside: Line | None) -> bool:
    """No catalogue effect accounts for the misfit: the residual exceeds the R-test's noise
    and none is significant, or the best removes less than ``SHARE_OF_EXCESS`` of the
    excess; or a periodic line along a linear axis outweighs every candidate."""
    by_noise = bool(misfit) and (not significant or (share or 0.0) < SHARE_OF_EXCESS)
    return by_noise or outside is not None


def _outside_line(lines, device: float | None, misfit, alpha: float, best_sum_sq: float) -> Line | None:
    """The strongest periodic line along a linear axis (no catalogue effect has that shape)
    that an R-test resolves, significant over all lines, removing ``LINE_OVER_BEST`` times
    what the best candidate removes and ``LINE_SHARE`` of the residual; judged only where
    the residual is not within the R-test's noise, or that noise is not known."""
    if device is not None and not misfit:
        return None
    return next((line for line in lines if line.unit == "mm" and line.amplitude_um >= RESOLVES_UM
                 and line.p_value < alpha / max(len(lines), 1)
                 and line.sum_sq >= LINE_OVER_BEST * best_sum_sq and line.share >= LINE_SHARE), None)


@dataclass(frozen=True)
class _Row:
    """One candidate's numbers: unwhitened (visibility, what the model absorbs, RMS after,
    the condition of the model with it) and whitened (what the test and the ranking use)."""

    effect: Effect
    vis: float
    drop: float
    drop_w: float
    share: float
    k_eff: int
    amp: np.ndarray
    names: tuple[str, ...]
    silent: bool
    norms: np.ndarray
    absorbed: np.ndarray
    cond: float


class _Noise:
    """The whitening of one diagnosis: segments, ρ per reading and direction, and the Q of
    the model's whitened Jacobian (QR). With ρ = 0 everywhere it is the identity."""

    def __init__(self, seg: np.ndarray, rho: np.ndarray, Q: np.ndarray):
        self.seg, self.rho = seg, rho
        self.Q = np.linalg.qr(self.white(Q))[0] if rho.any() else Q     # whitening keeps the span

    def white(self, x: np.ndarray) -> np.ndarray:
        """(3n,) or (3n, k), readings in (n, 3) order, made white."""
        if not self.rho.any():
            return x
        return whiten(x.reshape(len(self.seg), 3, *x.shape[1:]), self.seg, self.rho).reshape(x.shape)

    def off(self, v: np.ndarray) -> np.ndarray:
        """What the whitened model cannot absorb of whitened v."""
        return v - self.Q @ (self.Q.T @ v)

    def rss(self, r: np.ndarray) -> float:
        rw = self.off(self.white(r))
        return float(rw @ rw)


def _rank(effects: Sequence[Effect], free: Sequence[str], R: np.ndarray, r: np.ndarray, noise: _Noise,
          plain: dict, white: dict | None = None) -> dict[str, _Row]:
    """Every candidate's numbers from its columns' products (``signature.products``):
    ``plain`` with the model's Q and the residual, ``white`` the same made white (with
    the whitened model's Q and residual) when the noise is correlated."""
    J_norm = np.linalg.norm(R, axis=0)
    rw = noise.off(noise.white(r))
    rss_w = float(rw @ rw)
    out = {}
    for e in effects:
        cc, qc, cr = plain[e.name]
        m = len(e.params)           # columns beyond them: a reversal's start sides (``_columns``)
        norms = np.sqrt(np.diag(cc))
        vis_cols, drop, amp = explained(cc, qc, cr)
        keep = vis_cols >= VISIBLE
        if len(cr) > m:        # a reversal is seen only beyond the model and its start sides
            vis_cols[:m] = _beyond_starts(cc, qc, m)
            keep = (vis_cols >= VISIBLE) & bool((vis_cols[:m] >= VISIBLE).any())
            _, drop, amp = explained(cc, qc, cr, keep)
        drop_w = drop
        if white is not None and keep.any():
            _, drop_w, _ = explained(*white[e.name], keep)
        qj = qc[len(qc) - len(R):]                    # Q's columns of J (start sides first)
        absorbed = np.linalg.solve(R, qj[:, :m])      # J⁺c: what each parameter takes
        vis_cols, amp, norms = vis_cols[:m], amp[:m], norms[:m]
        size = max(float(np.linalg.norm(norms)), 1e-300)
        share = np.sqrt(np.sum((absorbed * J_norm[:, None]) ** 2, axis=1)) / size
        names = tuple(free[i] for i in np.argsort(-share) if share[i] >= ABSORBS)
        # R of [J | c] is [[R, Qᵀc], [0, R of c⊥]]: fit --add's condition number, cheaply;
        # with start sides B, that of [J | c] without its part along B, as fit projects them
        joined = np.block([[R, qj], [np.zeros((m, R.shape[1])), gram_factor(cc - qc.T @ qc)]]) \
            if len(cr) == m else gram_factor(_without_b(R, qj, cc, m))
        out[e.name] = _Row(e, float(vis_cols.max()), drop, drop_w, drop_w / max(rss_w, 1e-300),
                           int(keep.sum()), amp, names, bool(np.all(norms * 1e3 < SILENT_UM)),
                           norms, absorbed, condition(joined))
    return out


def _outlier_rows(data: Sequence[RTestData], bad: np.ndarray, size: np.ndarray) -> tuple[dict, ...]:
    """Each outlying reading where a user finds it: its file and CSV line (header = 1)."""
    start = np.cumsum([0, *(len(d) for d in data)])
    rows = []
    for i, s in zip(bad, size, strict=True):
        f = int(np.searchsorted(start, i, side="right") - 1)
        d, k = data[f], int(i - start[f])
        rows.append({"file": d.source or f"data set {f + 1}", "line": d.lines[k] if d.lines else None,
                     "path": str(d.poses.path[k]), "size_um": round(float(s), 3)})
    return tuple(rows)


def _noise_summary(seg: np.ndarray, rho: np.ndarray, path: np.ndarray) -> dict:
    """The largest ρ̂ of each path label, per direction (one path may span several files)."""
    out: dict[str, list[float]] = {}
    for s in np.unique(seg):
        at = np.flatnonzero(seg == s)
        label = str(path[at[0]]) or "(unlabelled)"
        out[label] = np.maximum(out.get(label, [0.0] * 3), rho[at[0]]).round(3).tolist()
    return out


def _per_axis(machine: Machine, poses: Poses, r: np.ndarray) -> dict:
    """Residual structure against each axis: harmonic amplitudes for a full-turn axis,
    the RMS of a quadratic trend otherwise; µm per direction."""
    out = {}
    r_um = r * 1e3
    for axis in machine.axes:
        q = poses.q[:, machine.index(axis.name)]
        if np.ptp(q) < 1e-9:
            continue
        if axis.full_turn:
            terms = {}
            for k in range(1, 5):
                B = np.column_stack([np.cos(k * q), np.sin(k * q)])
                coef = np.linalg.lstsq(B, r_um, rcond=None)[0]
                terms[f"{k}/rev"] = np.hypot(coef[0], coef[1]).tolist()
            out[axis.name] = terms
        else:
            u = (q - q.mean()) / np.ptp(q)
            B = np.column_stack([u, u**2 - (u**2).mean()])
            coef = np.linalg.lstsq(B, r_um, rcond=None)[0]
            out[axis.name] = {"trend": np.sqrt(((B @ coef) ** 2).mean(axis=0)).tolist()}
    return out


def _separating(machine: Machine, model_effects: Sequence[Effect], poses: Poses, effects: Sequence[Effect],
                advisor: Advisor) -> dict[str, tuple[Measurement, ...]]:
    """For effects these data cannot tell from ``model_effects`` (or not whole): the
    measurements the machine can make after which they could, shortest first, at most
    ``ADVISED``: each column then visible (``SEPARATES``) and the model with the effect
    separable as fit --add judges it.

    R of stacked data is R of the stacked R factors, and the R factor of a subset of
    columns is that of the same columns of R: the measured poses are reduced once, each
    extra measurement adds only its own rows, and each effect is judged on small blocks.
    """
    both = [*model_effects, *effects]
    p = sum(len(e.params) for e in model_effects)
    R0 = r_factor(machine, poses, both)
    found: dict[str, list[Measurement]] = {e.name: [] for e in effects}
    for extra in sorted(advisor.candidates, key=lambda m: len(m.poses)):
        R = r_factor(machine, extra.poses, both, R0)
        col = p
        for e in effects:
            k = len(e.params)
            if e.basis.kind == "r" and not both_sides(machine, e.carrier, poses, extra.poses):
                col += k    # one side throughout is the axis's zero offset, not its backlash
                continue
            Re = np.linalg.qr(R[:, [*range(p), *range(col, col + k)]], mode="r")
            vis = np.linalg.norm(Re[p:, p:], axis=0) / np.maximum(np.linalg.norm(Re[:, p:], axis=0), 1e-300)
            if vis.min() >= SEPARATES and condition(Re) < COND_LIMIT:
                found[e.name].append(extra)
            col += k
    return {k: advisor.runnable(v, most=ADVISED) for k, v in found.items()}


def _telling_apart(machine: Machine, model_effects: Sequence[Effect], poses: Poses, group: Sequence[_Row],
                   sigma2: float, advisor: Advisor
                   ) -> tuple[dict[str, tuple[Measurement, ...]], tuple[Measurement, ...], dict]:
    """Which measurements, not made yet and that the machine can make, tell the best
    (``group[0]``) and its rivals apart: a pair is told apart when, at their fitted sizes,
    they would differ by ``TELLS_APART`` σ̂² more than now (each hypothesis, were it true,
    would leave that much misfit in a fit of the other; first order).

    Returns, per rival, what tells it from the best (shortest first); the measurements that
    tell any pair apart, those telling every pair apart first; and per measurement the
    pairs it leaves open. The measurements come as a plan: each tells apart the most pairs
    the ones before it leave open, until every pair is told apart or none is left that
    would."""
    effects = [row.effect for row in group]
    amps = {row.effect.name: row.amp for row in group}
    p = sum(len(e.params) for e in model_effects)
    cols, at = {}, p
    for e in effects:
        cols[e.name] = list(range(at, at + len(e.params)))
        at += len(e.params)

    def misfit(R, a, b):        # a true, fitted with the model and b: what a leaves
        Rs = np.linalg.qr(R[:, [*range(p), *cols[b], *cols[a]]], mode="r")
        k = len(cols[a])
        return float(np.sum((Rs[-k:, -k:] @ amps[a]) ** 2))

    def apart(R, a, b):
        return min(misfit(R, a, b), misfit(R, b, a))

    both = [*model_effects, *effects]
    R0 = r_factor(machine, poses, both)
    pairs = list(combinations([e.name for e in effects], 2))
    now = {pq: apart(R0, *pq) for pq in pairs}
    split = {}
    for extra in advisor.candidates:
        R = r_factor(machine, extra.poses, both, R0)
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
    best = effects[0].name
    by_rival = {}
    for e in effects[1:]:
        pair = (best, e.name)
        tells = sorted((s for s in split.values() if pair in s[1]), key=lambda s: (len(s[0].poses), -s[2]))
        by_rival[e.name] = advisor.runnable([s[0] for s in tells], most=ADVISED)
    return by_rival, ordered, {k: v for k, v in open_.items() if v}
