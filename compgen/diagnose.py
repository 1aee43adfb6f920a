"""Where the model fails, and which physical effect would explain it.

For every catalogue effect not in the model: its first-order signature c on the measured
poses (basis × slot gain), the part c⊥ that the model's parameters cannot absorb, the
residual sum of squares it would remove, an F test, and Bonferroni's correction for the
number of effects tried. An effect whose signature the model absorbs entirely (‖c⊥‖/‖c‖
below ``VISIBLE``) is never "found": it is reported as confounded, with the measurement that
would separate it.

References: ``shared/research/identification.md`` §2 (visibility, bias, F and score tests).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from . import me
from .effects import Effect, catalogue, effect_name, effect_of_param, resolve
from .errors import CompgenError
from .kinematics import Model, Poses, SlotGains, coordinate, runs
from .machine import Machine
from .noise import ar1, outliers, whiten
from .paths import Measurement, alternative_measurements
from .results import FitResult
from .rtest import RTestData
from .units import shown, three, three_header

ALPHA = 0.01          # family-wise false-alarm rate over all effects tried
VISIBLE = 0.01        # ‖c⊥‖/‖c‖ below this: the model absorbs the effect entirely
SEPARATES = 0.05      # visibility an extra measurement must give to count as separating
ABSORBS = 0.25        # share of an effect's signature a parameter must take to be named
SILENT_UM = 1e-9      # µm per unit over all readings: the effect moves nothing at all
RIVAL = 0.9           # removing this share of what the best removes makes a rival (misfit left)
TELLS_APART = 25.0    # σ̂² of misfit a measurement must add between two rivals (5 σ)


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

    @property
    def visible(self) -> bool:
        return self.visibility >= VISIBLE


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
            if not c.visible:
                for m in c.separated_by:
                    shows.setdefault(m.label, []).append(c.effect)
                    by_label[m.label] = m
        if not shows:
            return None, ()
        best = max(shows, key=lambda k: (len(shows[k]), -len(by_label[k].poses)))
        return by_label[best], tuple(shows[best])

    @property
    def found(self) -> str | None:
        """The effect named as missing: significant, first, and with no rival."""
        return self.significant[0].effect if self.significant and not self.rivals else None

    def to_dict(self) -> dict:
        return {
            "format": "compgen.diagnose/1", "machine": self.machine, "fit": self.fit_file,
            "model": list(self.model), "rms_um": self.rms_um, "sigma_um": self.sigma_um,
            "readings": self.readings, "tested": self.tested, "alpha": self.alpha,
            "explained_to_noise": not self.significant,
            "still_significant_after_best": list(self.after_best),
            "rivals_of_best": list(self.rivals),
            "found": self.found,
            "rivals_equivalent": bool(self.rivals and not self.rivals_separated_by),
            "next_measurement": None if self.next_measurement[0] is None else {
                **self.next_measurement[0].to_dict(), "would_show": list(self.next_measurement[1])},
            "rivals_separated_by": [m.to_dict() for m in self.rivals_separated_by],
            "outliers": list(self.outliers),
            "noise_ar1_rho": self.noise,
            "per_path": self.per_path, "per_axis": self.per_axis,
            "candidates": [{
                "effect": c.effect, "significant": c.significant, "visible": c.visible,
                "visibility": c.visibility, "rms_after_um": c.rms_after_um,
                "p_value": c.p_value, "share_explained": c.share, "confounded_with": list(c.confounded_with),
                "separated_by": [m.to_dict() for m in c.separated_by], "silent": c.silent,
                "amplitude": list(c.amplitude),
                "amplitude_unit": c.unit, "description": c.description, "cause": c.cause}
                for c in self.candidates],
            "bias_sensitivity": {"units": self.bias_units, "shift_per_unit": self.bias,
                                 "signature_rms_um_per_unit": self.signature_um},
        }

    def report(self, fit_path: str = "fit.json", top: int = 8) -> str:
        lines = [f"compgen diagnose: {self.machine}", f"  fit {self.fit_file}: {len(self.model)} "
                 f"parameters; residual RMS {self.rms_um:.3f} µm (σ̂ {self.sigma_um:.3f} µm) over "
                 f"{self.readings} readings", "",
                 f"  {'residual per path (µm)':<24}{three_header(('RMS dX', 'dY', 'dZ'))}"]
        for name, p in self.per_path.items():
            lines.append(f"    {name:<22}{three(p['rms_um'])}")
        if self.outliers:
            lines += ["", f"  {len(self.outliers)} outlying reading{'s' if len(self.outliers) > 1 else ''} "
                          "(a step from their neighbours), left out of the tests below; check them, "
                          "and delete their rows to leave them out of the fit too:"]
            lines += [f"    {o['file']}:{o['line'] or '?'}  path {o['path'] or '(unlabelled)'}  "
                      f"{o['size_um']:.1f} µm" for o in self.outliers]
        if any(any(v) for v in self.noise.values()):
            lines += ["", "  the noise is correlated from reading to reading: AR(1) ρ̂ per path (dX dY dZ): "
                      + "; ".join(f"{k} {' '.join(f'{v:.2f}' for v in p)}" for k, p in self.noise.items()),
                      "  the tests below are made on readings made white with it (generalised least squares)"]
        lines += ["", "  residual against axis position (µm, amplitude in dX dY dZ)"]
        for axis, a in self.per_axis.items():
            for term, amp in a.items():
                lines.append(f"    {axis:<3}{term:<19}{three(amp)}")
        visible = [c for c in self.candidates if c.visible]
        lines += ["", f"  candidate effects, most residual removed first ({self.tested} tried; F test, "
                      f"Bonferroni-corrected, α = {self.alpha:g}):"]
        for i, c in enumerate(visible[:top], 1):
            amp = " ".join(f"{a:+.2f}" for a in c.amplitude)
            verdict = "SIGNIFICANT" if c.significant else "not significant"
            p = f"p = {c.p_value:.2g}" if c.p_value > 0 else "p < 1e-300"
            lines.append(f"  {i:>2}. {c.effect:<12} RMS → {c.rms_after_um:.3f} µm   {p}  {verdict}")
            lines.append(f"      {c.description} (≈ {amp} {c.unit}); likely cause: {c.cause}")
            if c.confounded_with:
                lines.append(f"      partly absorbed by {', '.join(c.confounded_with)}")
            if self.rivals and (c.effect in self.rivals or c is self.significant[0]):
                lines.append("      not told apart from the others marked so: see below")
            elif c.significant:
                lines.append(f"      add it: {me()} fit --from {fit_path} --add {c.effect} -o "
                             f"{_next_name(fit_path)}")
        if self.rivals:
            best = self.significant[0].effect
            verb = "explains" if len(self.rivals) == 1 else "explain"
            lines += ["", f"  Not told apart: {', '.join(self.rivals)} {verb} these data as well as "
                          f"{best}, within their noise; no one of them is named as found."]
            if self.rivals_separated_by:
                lines.append("  Measuring one of these would tell them apart (shortest first):")
                for m in self.rivals_separated_by[:3]:
                    lines.append(f"    {m.label}: {me()} measure-program {m.command()} -o <program>")
                lines.append("  then fit the new CSV together with these, and diagnose again.")
            else:
                lines += ["  No path or ball position of the machine file tells them apart: for every "
                          "set-up compgen can measure they predict the same readings (they differ by "
                          "what the location errors absorb). Any one of them models the misfit: "
                          f"{me()} fit --from {fit_path} --add {best} -o {_next_name(fit_path)};",
                          "  which of them is the physical cause stays open (it needs another "
                          "reference), and the location errors written to a control depend on the "
                          "choice."]
        if not self.significant:
            lines += ["", "  No candidate is significant: the model explains these data to the "
                          "noise level."]
        elif len(self.significant) > 1:
            best = self.significant[0].effect
            lines += ["", f"  Effects share misfit: once {best} is added, "
                          + (f"still significant: {', '.join(self.after_best)}." if self.after_best
                             else "no other candidate stays significant.")
                          + " Add one effect at a time and diagnose again."]
        hidden = [c for c in self.candidates if not c.visible and (not c.silent or c.separated_by)]
        if hidden:
            lines += ["", "  not visible in these data (never reported as found; the fit absorbs them):"]
            for c in hidden:
                where = (f"would be seen with {' or '.join(m.label for m in c.separated_by[:3])}"
                         if c.separated_by
                         else "no path or ball position of this machine file separates it: it needs "
                              "an independent reference")
                what = "moves no reading here" if c.silent else f"absorbed by {', '.join(c.confounded_with)}"
                lines.append(f"    {c.effect:<12} {c.description}: {what}; {where}")
            m, shows = self.next_measurement
            if m is not None:
                lines.append(f"  to look for them, {m.label} would show the most ({len(shows)}: "
                             f"{', '.join(shows[:6])}{', …' if len(shows) > 6 else ''}): "
                             f"{me()} measure-program {m.command()} -o <program>")
        silent = [c.effect for c in self.candidates if c.silent and not c.separated_by]
        if silent:
            lines += ["", "  no effect on any reading here (no lever arm to the nest or ball in this "
                          "machine file): " + ", ".join(silent)]
        lines += ["", "  fragile parameters: largest shift per µm (RMS over the poses) of an effect "
                      "not in the model"]
        for name, row in self.bias.items():
            per_um = {k: v / self.signature_um[k] for k, v in row.items() if self.signature_um[k] > 0}
            worst = max(per_um, key=lambda k: abs(per_um[k]), default=None)
            if worst is not None:
                lines.append(f"    {name:<6} {per_um[worst]:+6.2f} {self.bias_units[name]} per µm of "
                             f"{effect_name(worst)}")
        return "\n".join([*lines, *self.notes]) + "\n"


def _next_name(path: str) -> str:
    stem = path[:-5] if path.endswith(".json") else path
    return f"{stem}+1.json"


# An R-test's sphere-centre repeatability is 0.5–1 µm and drift adds a few µm over a run
# (shared/research/identification.md, "Noise of R-test sensors"): a fit leaving more than
# this has missed something physical, or the data are not what they claim.
SIGMA_PLAUSIBLE_UM = 3.0
# Below this spread the readings cannot be µm of a real machine (mm given as µm, say)
SPREAD_PLAUSIBLE_UM = 0.5


def unit_suspicion(data: Sequence[RTestData]) -> str | None:
    """Why the readings look like another unit than µm, or None."""
    y = np.concatenate([d.deviation for d in data]) * 1e3
    spread = float((y.max(axis=0) - y.min(axis=0)).max()) if y.size else 0.0
    if spread < SPREAD_PLAUSIBLE_UM:
        return (f"the readings spread over {spread:.3g} µm at most, far below any R-test's noise "
                f"(0.5–1 µm): they are likely in mm, not µm")
    return None


def fit_gate(machine: Machine, data: Sequence[RTestData], fit: FitResult) -> list[str]:
    """Why this fit should not reach a controller: what a user must settle first (empty when
    the fit explains its data to an R-test's noise with nothing significant missing)."""
    reasons = []
    suspicion = unit_suspicion(data)
    if suspicion:
        reasons.append(suspicion + "; check the CSV's dX dY dZ unit")
    sigma = fit.residual["sigma_um"]
    if not sigma <= SIGMA_PLAUSIBLE_UM:
        reasons.append(f"the fit leaves σ̂ = {sigma:.2f} µm, above the {SIGMA_PLAUSIBLE_UM:g} µm an R-test's "
                       "noise allows: the model misses an effect, or the data are wrong (columns "
                       "swapped, a sign, a mismatched machine file)")
    found = diagnose(machine, data, fit)
    if found.significant:
        reasons.append("diagnose finds effects the model misses: "
                       + ", ".join(c.effect for c in found.significant[:3])
                       + " (run diagnose, add the effect with fit --add, and refit)")
    return reasons


def diagnose(machine: Machine, data: Sequence[RTestData], fit: FitResult,
             candidates: Sequence[str] | None = None, alpha: float = ALPHA,
             fit_file: str = "") -> Diagnosis:
    """Rank the effects not in ``fit``'s model by how much of its residual they explain.

    Outlying readings are listed and left out; the tests are made on the readings made white
    by their segments' AR(1) correlation (``noise.py``), estimated from the residual once the
    best candidate is added (the misfit of a missing effect is not noise)."""
    poses = Poses.concat([d.poses for d in data])
    y = np.concatenate([d.deviation for d in data])
    model = Model(machine, fit.model)
    x = np.array([fit.parameters[n].value for n in fit.model])
    free = [model.names.index(n) for n in fit.free]
    r3 = y - model.deviation(poses, x)
    seg = runs(poses, np.repeat(np.arange(len(data)), [len(d) for d in data]))
    bad, size = outliers(r3 * 1e3, seg)
    if bad.size:
        keep = np.ones(len(poses), bool)
        keep[bad] = False
        poses, r3, seg = poses.take(keep), r3[keep], seg[keep]
    r = r3.ravel()
    # only Q and R of the model's Jacobian are kept: J's column norms are R's
    Q, R = np.linalg.qr(model.jacobian(poses, x)[:, :, free].reshape(r.size, -1))
    r = r - Q @ (Q.T @ r)             # the fit's residual without the outliers
    rss, dof = float(r @ r), r.size - len(free)

    in_model = {effect_of_param(machine, n).name for n in fit.model}
    effects = [e for e in (catalogue(machine) if candidates is None
                           else [resolve(machine, c) for c in candidates]) if e.name not in in_model]
    if not effects:
        raise CompgenError("no candidate effect left to try: the model holds them all")
    # ρ̂ from the residual once the best candidate (least squares) is added: the misfit of
    # a missing effect is not noise; then, if the noise is correlated, rank again whitened
    noise = _Noise(seg, np.zeros_like(r3), Q, R)
    ranked = _rank(machine, poses, effects, fit.free, Q, R, r, noise)
    best = max(ranked.values(), key=lambda row: (row.vis >= VISIBLE, row.share))
    c = _columns(machine, poses, [best.effect])
    rest = r - c @ np.linalg.lstsq(c - Q @ (Q.T @ c), r, rcond=None)[0]
    rho = ar1((rest - Q @ (Q.T @ rest)).reshape(-1, 3), seg)
    if rho.any():
        noise = _Noise(seg, rho, Q, R)
        ranked = _rank(machine, poses, effects, fit.free, Q, R, r, noise)
    rss_w = noise.rss(r)

    tested = sum(1 for row in ranked.values() if row.k_eff)
    out = []
    for e in effects:
        row = ranked[e.name]
        p = _p_value(row.drop_w, row.k_eff, rss_w, dof, tested) if row.k_eff else 1.0
        out.append(Candidate(
            effect=e.name, description=e.words, cause=e.cause, visibility=row.vis,
            rms_after_um=float(np.sqrt(max(rss - row.drop, 0.0) / r.size)) * 1e3, p_value=p,
            significant=bool(row.k_eff and p < alpha), confounded_with=row.names,
            amplitude=tuple(shown(a, e.unit)[0] for a in row.amp), unit=shown(1.0, e.unit)[1],
            silent=row.silent, share=row.share))
    out.sort(key=lambda c: (not c.visible, -c.share))
    hidden = [c for c in out if not c.visible]
    model_effects = list(dict.fromkeys(effect_of_param(machine, n) for n in fit.free))
    extras = alternative_measurements(machine, poses)
    seen = (_separating(machine, model_effects, poses, [resolve(machine, c.effect) for c in hidden], extras)
            if hidden else {})
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

    after_best, rivals, rivals_separated_by = (), (), ()
    significant = [c for c in out if c.significant]
    if len(significant) > 1:
        best = noise.white(_columns(machine, poses, [resolve(machine, significant[0].effect)]))
        others = [resolve(machine, c.effect) for c in significant[1:]]
        kept = _still_significant(noise.Q, best, noise.white(r), (
            (e, noise.white(c)) for e, c in _signatures(machine, poses, others)), alpha)
        after_best = tuple(e.name for e in others if e.name in kept)
    if significant:
        best = ranked[significant[0].effect]
        rivals = _rivals(best, [ranked[c.effect] for c in out if c.visible and c.effect != best.effect.name],
                         rss_w / dof,
                         alpha, bool(after_best))
        by_rival = {e: _telling_apart(machine, model_effects, poses, best, ranked[e], rss / dof, extras)
                    for e in rivals}
        out = [replace(c, separated_by=by_rival[c.effect]) if c.effect in by_rival else c for c in out]
        rivals_separated_by = tuple(sorted({m.label: m for ms in by_rival.values() for m in ms}.values(),
                                           key=lambda m: len(m.poses)))
        if rivals and not rivals_separated_by:
            # equivalent everywhere: put first the one the location errors absorb least, so
            # that adding it leaves them where an effect without that absorbed part has them
            group = [c for c in out if c.significant and c.effect in (best.effect.name, *rivals)]
            first = max(group, key=lambda c: c.visibility)
            if first.effect != best.effect.name:
                out.remove(first)
                out.insert(out.index(next(c for c in out if c.effect == best.effect.name)), first)
                rivals = tuple(c.effect for c in out if c.effect in (best.effect.name, *rivals)
                               and c is not first)

    return Diagnosis(
        machine=machine.name, fit_file=fit_file, model=fit.model,
        rms_um=float(np.sqrt(rss / r.size)) * 1e3, sigma_um=float(np.sqrt(rss / dof)) * 1e3,
        readings=int(r.size), per_path=fit.residual["per_path"],
        per_axis=_per_axis(machine, poses, r.reshape(-1, 3)),
        candidates=tuple(out), bias=bias, bias_units=units, signature_um=signature_um,
        tested=tested, alpha=alpha,
        after_best=after_best, rivals=rivals, rivals_separated_by=rivals_separated_by,
        outliers=_outlier_rows(data, bad, size), noise=_noise_summary(seg, noise.rho, poses.path))


@dataclass(frozen=True)
class _Row:
    """One candidate's numbers: unwhitened (visibility, what the model absorbs, RMS after)
    and whitened (what the test and the ranking use)."""

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


class _Noise:
    """The whitening of one diagnosis: segments, ρ per reading and direction, and the Q of
    the model's whitened Jacobian (QR). With ρ = 0 everywhere it is the identity."""

    def __init__(self, seg: np.ndarray, rho: np.ndarray, Q: np.ndarray, R: np.ndarray):
        self.seg, self.rho = seg, rho
        self.Q = np.linalg.qr(self.white(Q @ R))[0] if rho.any() else Q

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


def _rank(machine: Machine, poses: Poses, effects: Sequence[Effect], free: Sequence[str],
          Q: np.ndarray, R: np.ndarray, r: np.ndarray, noise: _Noise) -> dict[str, _Row]:
    """Every candidate's numbers, one effect at a time (memory as fit's)."""
    J_norm = np.linalg.norm(R, axis=0)
    rw = noise.off(noise.white(r))
    rss_w = float(rw @ rw)
    out = {}
    for e, c in _signatures(machine, poses, effects):
        norms = np.linalg.norm(c, axis=0)
        qc = Q.T @ c
        vis_cols, drop, amp = _explained(c, c - Q @ qc, r)   # c − QQᵀc: what the model cannot absorb
        keep = vis_cols >= VISIBLE
        drop_w = drop
        if noise.rho.any() and keep.any():
            cw = noise.white(c)
            _, drop_w, _ = _explained(cw, noise.off(cw), rw, keep)
        absorbed = np.linalg.solve(R, qc)             # J⁺c: what each parameter takes
        share = np.sqrt(np.sum((absorbed * J_norm[:, None]) ** 2, axis=1)) / max(np.linalg.norm(c), 1e-300)
        names = tuple(free[i] for i in np.argsort(-share) if share[i] >= ABSORBS)
        out[e.name] = _Row(e, float(vis_cols.max()), drop, drop_w, drop_w / max(rss_w, 1e-300),
                           int(keep.sum()), amp, names, bool(np.all(norms * 1e3 < SILENT_UM)),
                           norms, absorbed)
    return out


def rival_curves(machine: Machine, poses: Poses, fit: FitResult, found: Diagnosis,
                 extra: Measurement) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """For the best candidate and each rival at its fitted size: the misfit (µm, (n, 3)) the
    fit's model leaves of it on the measured poses, and the misfit it would leave on
    ``extra`` once that is measured too (first order): alike on the first, apart on the
    second when ``extra`` tells them apart."""
    model_effects = list(dict.fromkeys(effect_of_param(machine, n) for n in fit.free))
    both = Poses.concat([poses, extra.poses])
    J = _columns(machine, both, model_effects)
    Q_now = np.linalg.qr(J[:3 * len(poses)])[0]
    Q_both = np.linalg.qr(J)[0]
    out = {}
    for c in found.candidates:
        if c.effect not in (found.significant[0].effect, *found.rivals):
            continue
        e = resolve(machine, c.effect)
        v = _columns(machine, both, [e]) @ (np.array(c.amplitude) / shown(1.0, e.unit)[0])
        now = v[:3 * len(poses)] - Q_now @ (Q_now.T @ v[:3 * len(poses)])
        after = (v - Q_both @ (Q_both.T @ v))[3 * len(poses):]
        out[c.effect] = (now.reshape(-1, 3) * 1e3, after.reshape(-1, 3) * 1e3)
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


def _signatures(machine: Machine, poses: Poses, effects: Sequence[Effect]):
    """Each effect with its first-order signature, (3n, its params) mm per unit, one at a
    time, so that only the chain's frames and one effect's columns are held."""
    gains = SlotGains(machine, poses)
    for e in effects:
        c = 0.0
        for direction, b in e.parts(coordinate(machine, e, poses)):
            c = c + gains((e.carrier, e.slot, direction))[:, :, None] * b[:, None, :]
        yield e, c.reshape(-1, len(e.params))


def _columns(machine: Machine, poses: Poses, effects: Sequence[Effect]) -> np.ndarray:
    """First-order signatures of the effects' parameters, (3n, Σ params), mm per unit, in
    the order of ``effects``."""
    return np.column_stack([c for _, c in _signatures(machine, poses, effects)])


def _separating(machine: Machine, model_effects: Sequence[Effect], poses: Poses, effects: Sequence[Effect],
                extras: Sequence[Measurement]) -> dict[str, tuple[Measurement, ...]]:
    """For effects these data cannot tell from ``model_effects``: which of the ``extras``,
    added to them, would.

    With R the triangular factor of [model columns | effect columns] over all poses, an
    effect column's part that the model cannot absorb has the norm of its column below the
    model's rows of R; R of stacked data is R of the stacked R factors, so the measured
    poses are reduced once, in chunks, and each extra measurement adds only its own rows.
    """
    found: dict[str, list[Measurement]] = {e.name: [] for e in effects}
    both = [*model_effects, *effects]
    p = sum(len(e.params) for e in model_effects)
    R0 = _r_factor(machine, poses, both)
    for extra in extras:
        R = _r_factor(machine, extra.poses, both, R0)
        vis = np.linalg.norm(R[p:, p:], axis=0) / np.maximum(np.linalg.norm(R[:, p:], axis=0), 1e-300)
        col = 0
        for e in effects:
            if vis[col:col + len(e.params)].max() >= SEPARATES:
                found[e.name].append(extra)
            col += len(e.params)
    return {k: tuple(sorted(v, key=lambda m: len(m.poses))) for k, v in found.items()}


def _rivals(best: _Row, others: Sequence[_Row], sigma2_w: float, alpha: float,
            misfit_left: bool) -> tuple[str, ...]:
    """The candidates these data cannot tell from the best: each removes as much of the
    (whitened) residual within the noise, χ²(k, α)·σ̂², whatever its rank; and while the
    best leaves misfit (it is not the whole story), also those removing ``RIVAL`` of it."""
    from scipy.special import chdtri

    within = chdtri(max(best.k_eff, 1), alpha) * sigma2_w
    return tuple(o.effect.name for o in others if o.k_eff and (
        best.drop_w - o.drop_w < within or (misfit_left and o.drop_w >= RIVAL * best.drop_w)))


def _telling_apart(machine: Machine, model_effects: Sequence[Effect], poses: Poses, best: _Row,
                   rival: _Row, sigma2: float, extras: Sequence[Measurement]) -> tuple[Measurement, ...]:
    """The measurements, not made yet, after which the best and a rival at their fitted
    sizes differ by ``TELLS_APART`` σ̂² more than now, shortest first: each hypothesis, were
    it true, would leave that much misfit in a fit of the other (first order)."""
    orders = ([*model_effects, rival.effect, best.effect], [*model_effects, best.effect, rival.effect])
    amps = (best.amp, rival.amp)

    def apart(Rs):
        return min(float(np.sum((R[-len(a):, -len(a):] @ a) ** 2)) for R, a in zip(Rs, amps, strict=True))

    R0 = [_r_factor(machine, poses, o) for o in orders]
    now = apart(R0)
    found = []
    for extra in extras:
        gain = apart([_r_factor(machine, extra.poses, o, R) for o, R in zip(orders, R0, strict=True)]) - now
        if gain >= TELLS_APART * sigma2:
            found.append((len(extra.poses), -gain, extra.label, extra))
    return tuple(f[-1] for f in sorted(found))


def _r_factor(machine: Machine, poses: Poses, effects: Sequence[Effect],
              start: np.ndarray | None = None, chunk: int = 4096) -> np.ndarray:
    """R of the QR factorisation of the effects' columns on ``poses`` stacked under ``start``."""
    R = start
    for i in range(0, len(poses), chunk):
        block = _columns(machine, poses.take(slice(i, i + chunk)), effects)
        R = np.linalg.qr(block if R is None else np.vstack([R, block]), mode="r")
    return R


def _still_significant(Q: np.ndarray, added: np.ndarray, r: np.ndarray, signatures,
                       alpha: float) -> set[str]:
    """Which effects of ``signatures`` ((effect, columns) pairs) stay significant once the
    model (orthonormal columns ``Q``) is joined by the columns ``added``, first order;
    Bonferroni over all of them. Only the added columns are orthogonalised anew."""
    Qa, _ = np.linalg.qr(added - Q @ (Q.T @ added))

    def off(v):   # what the joined model cannot absorb
        return v - Q @ (Q.T @ v) - Qa @ (Qa.T @ v)

    r1 = off(r)
    rss, dof = float(r1 @ r1), r.size - Q.shape[1] - added.shape[1]
    drops = []
    for e, c in signatures:
        vis_cols, drop, _ = _explained(c, off(c), r1)
        drops.append((e.name, drop, int((vis_cols >= VISIBLE).sum())))
    return {name for name, drop, k in drops if k and _p_value(drop, k, rss, dof, len(drops)) < alpha}


def _explained(c: np.ndarray, cp: np.ndarray, r: np.ndarray, keep: np.ndarray | None = None
               ) -> tuple[np.ndarray, float, np.ndarray]:
    """For an effect's columns ``c`` and the part ``cp`` the model cannot absorb: each
    column's visibility, the residual sum of squares its visible columns (or ``keep``)
    remove, and their first-order amplitudes (0 for the invisible)."""
    norms = np.linalg.norm(c, axis=0)
    vis = np.where(norms > 0, np.linalg.norm(cp, axis=0) / np.where(norms > 0, norms, 1), 0.0)
    keep = vis >= VISIBLE if keep is None else keep
    amp = np.zeros(c.shape[1])
    if not keep.any():
        return vis, 0.0, amp
    amp[keep] = np.linalg.lstsq(cp[:, keep], r, rcond=None)[0]
    return vis, float(np.sum((cp[:, keep] @ amp[keep]) ** 2)), amp


def _p_value(drop: float, k: int, rss: float, dof: int, tried: int) -> float:
    """F test of ``k`` added columns removing ``drop`` of ``rss``, Bonferroni over ``tried``."""
    from scipy.special import fdtrc  # 0.3 s of import: only when a test is made

    F = (drop / k) / max((rss - drop) / (dof - k), 1e-300)
    return min(1.0, float(fdtrc(k, dof - k, F)) * tried)


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
