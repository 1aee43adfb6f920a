"""What a diagnosis found: each candidate effect's numbers (``Candidate``) and the
diagnosis as a whole (``Diagnosis``): its verdict in one word, what is found, the rivals and
what tells them apart, what no catalogue effect explains. ``diagnose`` makes it; its words
are ``diagnose_text``'s."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .advising import Proposal
from .device import FORM, TRIGGER, DeviceCandidate
from .noise import Repeats
from .setup_step import SetupStep
from .significance import ALPHA, COND_LIMIT, VISIBLE
from .spectrum import Line

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

# A repeat advised to tell rivals apart, found in the data this often (the first run and two
# repeats made as advised) with the rivals still tied: measuring it again would not end the
# loop. What moves with them is outside the shapes tried (two effects drifting at once, say).
REPEATS_TRIED = 3


def turn_for(form: str) -> float:
    """Degrees to turn a ball of ``form`` (``ball_lobes{k}``) on its stem, or a probe whose
    trigger has k lobes (``probe_lobes{k}``) in the spindle, to tell them from the machine:
    180°/k, where the k lobes read the other way round."""
    return 180.0 / int(form.removeprefix(FORM).removeprefix(TRIGGER))


@dataclass(frozen=True)
class Candidate:
    """An effect not in the fit's model, tried against its residual: how visible it is on these
    poses, the RMS it would leave, its p-value (Bonferroni) and whether it is significant, its
    first-order amplitude, what it is confounded with, and the measurements that would show it
    (``separated_by``)."""

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
    separated_by: tuple[Proposal, ...] = ()
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
    """What diagnose found in one fit's residual: the candidates ranked; the verdict in one
    word (``verdict``: found, rivals, unexplained, not separable, noise unknown, explained,
    device); the rivals and what tells them apart; the misfit against the device's noise and
    where that noise came from; the device's own candidates; the residual per path and per
    axis. ``diagnose_text.report`` words it; ``to_dict`` is ``diagnose --json``."""

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
    rivals_separated_by: tuple[Proposal, ...] = ()
    equivalents: tuple[str, ...] = ()   # rivals that are one column with the best on every set-up
    alpha: float = ALPHA
    notes: tuple[str, ...] = field(default_factory=tuple)
    outliers: tuple[dict, ...] = ()     # {"file", "line", "path", "size_um"}: left out of the tests
    noise: dict = field(default_factory=dict)   # path → AR(1) ρ̂ per direction used by the tests
    rivals_open: dict = field(default_factory=dict)   # label → pairs of rivals it leaves apart
    searched: bool = False  # which measurements would tell more was searched (an advisor was given)
    device_noise_um: float | None = None   # the R-test's own noise, when given; a probe's, from its touches
    repeats: Repeats | None = None         # device_noise_um estimated from readings that repeat a pose
    data_device: str = "rtest"             # "probe": the data are sphere centres from probe logs
    misfit: tuple[dict, ...] = ()   # (path, direction) whose residual exceeds that noise, worst first
    lines: tuple[Line, ...] = ()    # the residual's strongest periodic line against each coordinate
    best_share_of_excess: float | None = None   # of the residual beyond the noise, the best removes
    best_sum_sq: float = 0.0        # the residual sum of squares the best significant candidate removes, mm²
    devices: tuple[DeviceCandidate, ...] = ()   # the R-test's own parameters, tested beside the machine's
    device_blamed: str | None = None    # the one that explains the misfit as well as the machine's best
    form_rival: str | None = None       # the ball's form, explaining it as the machine's best does
    form_turned: Proposal | None = None  # the measurement that tells them apart: a path, the ball turned
    probe_turned: Proposal | None = None  # where the probe's trigger is blamed: a path, the probe turned
    setup_step: SetupStep | None = None   # a set-up event between two files, against the best
    # for rivals: what adding each puts into the fitted parameters, first order, shown units
    carries: dict[str, dict[str, float]] = field(default_factory=dict)
    # the repeats that were to tell the rivals apart, made REPEATS_TRIED times, leaving them
    # tied: the loop ends unexplained
    exhausted: tuple[str, ...] = ()

    @property
    def unexplained(self) -> bool:
        """No catalogue effect accounts for the misfit (``_unexplained``)."""
        return bool(self.exhausted) or _unexplained(
            self.misfit, bool(self.significant or self.significant_devices), self.best_share_of_excess,
            self.outside_line)

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
        return (not self.significant and not self.misfit and not self.unexplained
                and not self.significant_devices)

    @property
    def significant(self) -> tuple[Candidate, ...]:
        return tuple(c for c in self.candidates if c.significant)

    @property
    def turn_degrees(self) -> float | None:
        """How far to turn the ball on its stem to tell its form from the machine: 180°/k,
        where its k lobes read the other way round."""
        return None if self.form_rival is None else turn_for(self.form_rival)

    @property
    def significant_devices(self) -> tuple[DeviceCandidate, ...]:
        return tuple(d for d in self.devices if d.significant)

    @property
    def blamed(self) -> DeviceCandidate | None:
        """The device parameter blamed for the misfit (``_blamed``), if any."""
        return next((d for d in self.devices if d.effect == self.device_blamed), None)

    @property
    def next_measurement(self) -> tuple[Proposal | None, tuple[str, ...]]:
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
    def verdict(self) -> str:
        """The conclusion in one word, as the text's first line says it: "device" (the R-test's
        own parameter explains the misfit), "found", "rivals" (not told apart), "unexplained",
        "set-up step" (a set-up event between two files explains them as well as the best),
        "not separable" (the best is seen but not separable whole), "noise unknown" (a best
        candidate, but no noise to test what it leaves against), or "explained" (to the
        noise, or to these data's own scatter where the noise is unknown)."""
        best = self.significant[0] if self.significant else None
        if self.device_blamed is not None:
            return "device"
        if self.form_rival is not None:
            return "rivals"
        if self.step_rivals:
            return "set-up step"
        if self.found is not None:
            return "found"
        if self.rivals and not self.exhausted:
            return "rivals"
        if self.unexplained:
            return "unexplained"
        if best is not None and not best.separable:
            return "not separable"
        if best is not None or self.misfit or self.significant_devices:
            return "noise unknown" if self.device_noise_um is None else "unexplained"
        return "explained"

    @property
    def found(self) -> str | None:
        """The effect named as missing: significant, first, with no rival, one that ``fit
        --add`` accepts on these data, and not a small part of an unexplained misfit, which
        needs the device's noise: without it the residual is judged only against σ̂ of the
        data themselves, and an effect outside the catalogue would pass for the best
        candidate (an A encoder's 4/rev was named EZA:h2)."""
        best = self.significant[0] if self.significant else None
        apart = set(self.rivals) - set(self.equivalents)     # an exact equivalent is the best, renamed
        named = (best is not None and not apart and best.separable and not self.unexplained
                 and self.device_noise_um is not None and self.device_blamed is None and not self.step_rivals
                 and self.form_rival is None)
        return best.effect if named else None

    @property
    def step_rivals(self) -> bool:
        """A set-up event between two files explains these data as well as the machine's best
        candidate: the best is not named found (a step is never read as a warming)."""
        return bool(self.significant and self.setup_step is not None and self.setup_step.rival)

    def to_dict(self) -> dict:
        return {
            "format": "compgen.diagnose/1", "machine": self.machine, "fit": self.fit_file,
            "model": list(self.model), "rms_um": self.rms_um, "sigma_um": self.sigma_um,
            "readings": self.readings, "tested": self.tested, "alpha": self.alpha,
            "verdict": self.verdict, "explained_to_noise": self.explained_to_noise,
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
            "equivalents_of_best": list(self.equivalents),
            "found": self.found,
            "device_blamed": self.device_blamed,
            "form_rival": self.form_rival,
            "form_turned_by": None if self.form_turned is None else {
                **self.form_turned.to_dict(), "degrees": self.turn_degrees},
            "probe_turned_by": None if self.probe_turned is None else self.probe_turned.to_dict(),
            "device_effects": [d.to_dict() for d in self.devices],
            "setup_step": self.setup_step.to_dict() if self.setup_step is not None else None,
            "rivals_equivalent": bool(self.rivals and not self.rivals_separated_by),
            "rivals_exhausted_by": list(self.exhausted),
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


