"""A short measurement against the last accepted calibration: pass or fail per location
error, and what to do next."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from .. import me
from ..controllers.kinematics import nothing_to_correct
from ..controllers.registry import controller
from ..data.rtest import Measurements, device_of
from ..errors import CompgenError, one_line
from ..model.effects import effect_of_param
from ..model.machine import Machine
from ..statistics.results import FitResult
from ..units import shown
from .drift import Entry, Flag, flags, limit_of, machine_params
from .ledger import file_ref, lookup_machine, machine_key, session_and_fit
from .store import Store, now


@dataclass(frozen=True)
class Change:
    """One location error in a check: its machine value now minus at the calibration (mm or rad)
    ± σ, its limit, and "pass", "fail" or "unsure" (beyond the limit, not beyond k σ)."""

    param: str
    change: float          # machine value now minus at the calibration (mm, rad)
    std: float
    unit: str
    limit: float
    status: str            # "pass", "fail", or "unsure" (beyond the limit, but not beyond k σ)
    words: str

    def text(self) -> str:
        v, u = shown(self.change, self.unit)
        s, _ = shown(self.std, self.unit)
        lim, _ = shown(self.limit, self.unit)
        return (f"  {self.param:<6}{v:>+9.2f} ± {s:.2f} {u:<7}limit {lim:g} {u:<7}"
                f"{self.status.upper():<7}{self.words}")


@dataclass(frozen=True)
class CheckModel:
    """What a check fitted beyond the location errors: the calibration's own effects (an
    error motion it added, a declared shape), and how: "refitted" from the check's data, or
    "held" at the calibration's values."""
    effects: tuple[str, ...] = ()
    how: str = ""

    def words(self) -> str:
        if not self.effects:
            return "the calibration's model: location errors and set-up"
        how = ("refitted from these data" if self.how == "refitted" else
               "held at the calibration's values (these data do not determine them as well as the "
               "location errors need)")
        return f"the calibration's model: location errors, set-up and {', '.join(self.effects)}, {how}"


def fit_as_calibrated(machine: Machine, data, calibration: FitResult, advisor=None) -> tuple[FitResult,
                                                                                              CheckModel]:
    """A check is the calibration's model measured again: the same parameters, those the
    calibration held held at its values, its added effects refitted where the check's data
    determine them without costing the location errors (each one's σ at most twice what it
    is with the effects held), else held at the calibration's values. Fitted with the
    location errors alone, a check of an unchanged machine read the effect as location
    errors moved (6σ on the example's 1.5 µm 2/rev) and flagged drifts."""
    from ..statistics.identify import identify

    model = list(calibration.model)
    held_then = {n: calibration.parameters[n].value for n in model if n not in calibration.free}
    effects = [n for n in model if effect_of_param(machine, n).basis.kind != "const" and n not in held_then]
    base = [n for n in model if n not in effects and n not in held_then]
    at_calibration = {n: calibration.parameters[n].value for n in effects}
    held = identify(machine, data, base, {**held_then, **at_calibration}, advisor=advisor)
    if not effects:
        return held, CheckModel()
    try:
        free = identify(machine, data, [n for n in model if n not in held_then], held_then)
    except CompgenError:
        return held, CheckModel(tuple(effects), "held")
    located = [n for n in machine_params(machine, base) if n in held.free]
    if all(free.parameters[n].std <= 2 * held.parameters[n].std for n in located):
        return free, CheckModel(tuple(effects), "refitted")
    return held, CheckModel(tuple(effects), "held")


@dataclass(frozen=True)
class CheckResult:
    """A check against the last accepted calibration: each location error's change
    (``changes``), each path against its tolerance, the drifts flagged, the advice, and what the
    check fitted beyond the location errors (``model``); ``passed`` is the verdict."""

    machine: str
    serial: str
    against: Entry
    marker: str
    taken: str
    changes: list[Change]
    sigma_um: float
    paths: dict[str, str]          # path → PASS/FAIL against [tolerances]
    flags: list[Flag]
    advice: list[str]
    machine_changed: bool = False    # checked with another machine file than the calibration's
    model: CheckModel = CheckModel()
    nothing: str = ""                # "nothing to correct: ...", where an edit of this check would be noise
    accepted: str = ""               # how the calibration's "accepted" stands (``calibration_accepted``)
    ranges: dict = field(default_factory=dict)   # path → its largest deviation range beyond the set-up, µm

    @property
    def passed(self) -> bool:
        """Every location error within its limit and every path within its tolerance; a
        change too uncertain to judge does not pass (a drift within limits does, with advice)."""
        return (all(c.status == "pass" for c in self.changes)
                and not any(v.startswith("FAIL") for v in self.paths.values()))

    def summary(self) -> dict:
        return {"format": "compgen.check/1", "machine": self.machine, "serial": self.serial,
                "passed": self.passed, "taken": self.taken, "fit": self.marker,
                "against": {"fit": self.against.marker, "taken": self.against.taken},
                "sigma_um": self.sigma_um, "paths": self.paths,
                "changes": [{"parameter": c.param, "change": c.change, "std": c.std, "unit": c.unit,
                             "limit": c.limit, "status": c.status} for c in self.changes],
                "flags": [f.text() for f in self.flags], "advice": self.advice,
                "machine_file_changed": self.machine_changed,
                "model": {"effects": list(self.model.effects), "effects_were": self.model.how},
                "nothing_to_correct": self.nothing, "calibration_accepted": self.accepted,
                "path_ranges_um": self.ranges,
                **({"recorded_by": self.against.recorded_by} if self.against.recorded_by else {})}

    def text(self) -> str:
        who = f", recorded by {one_line(self.against.recorded_by)}" if self.against.recorded_by else ""
        serial = f" ({one_line(self.serial)})" if self.serial else ""
        lines = [f"compgen check: {one_line(self.machine)}{serial}, "
                 f"measured {self.taken[:16]}",
                 f"  against the calibration of {self.against.taken[:16]} ({self.against.marker}{who}), "
                 "corrections written since counted"]
        lines.append(f"  fitted with {self.model.words()}")
        if self.accepted:
            lines.append(f"  that calibration's verdict: {self.accepted}")
        if self.machine_changed:
            lines.append("  with a machine file changed since that calibration (--machine-changed)")
        lines += ["", f"  {'param':<6}{'change':>9}   {'σ':<12}{'':<16}{'status':<7}"]
        lines += [c.text() for c in self.changes]
        lines.append(f"\n  residual σ̂ {self.sigma_um:.3f} µm (the calibration's "
                     f"{self.against.sigma_um:.3f} µm)")
        lines += [f"  {p}: {v} µm range beyond the set-up" for p, v in self.paths.items()]
        lines += [f"  flagged: {f.text()}" for f in self.flags]
        lines += ["", "PASS: the machine is where its last calibration left it" if self.passed else "FAIL"]
        if self.nothing:
            lines.append(f"  {self.nothing}: an edit from this check would write noise")
        lines += [f"  next: {a}" for a in self.advice]
        return "\n".join(lines) + "\n"


def calibration_accepted(machine: Machine, calibration: Entry, fit: FitResult) -> str:
    """The calibration's "accepted", recomputed: compgen's fit gate run again on the
    calibration's own data where its files are at hand (each by its checksum). A row whose
    gate refuses its own fit (a writer can append one) is refused; else how the verdict
    stands, in words: recomputed, or as recorded where its data are not here."""
    from ..configuration.session import reload
    from ..statistics.gate import fit_gate
    try:
        _, data = reload(fit, machine.source)
    except CompgenError as exc:
        return f"accepted as recorded (its data are not here to recompute it: {one_line(exc.message)})"
    reasons = fit_gate(machine, data, fit)
    if reasons:
        who = f", recorded by {one_line(calibration.recorded_by)}" if calibration.recorded_by else ""
        raise CompgenError(f"the last calibration marked accepted (fit #{calibration.id}, "
                           f"{one_line(calibration.marker)}, {calibration.taken[:16]}{who}) fails compgen's "
                           f"fit gate on its own data: {reasons[0]}; the row's verdict is not compgen's",
                           hint="calibrate again, and record the fit compgen accepts")
    return "accepted, recomputed on its own data"


def check(machine: Machine, fit: FitResult, data, calibration: Entry, entries: Sequence[Entry],
          edits: Sequence[dict], taken: str, serial: str | None = None,
          machine_changed: bool = False, model: CheckModel = CheckModel(), accepted: str = "") -> CheckResult:
    """A short measurement's fit against the last accepted calibration: each location
    error's change (machine values: the corrections written since are counted) with its σ,
    the paths against ``[tolerances]``, and a drift or step it completes. A machine file
    other than the calibration's is refused: its nominal geometry, limits or tolerances may
    differ, and the changes would be measured against another machine; ``machine_changed``
    checks anyway and says so."""
    name, serial = machine_key(machine, serial)
    changed = bool(calibration.machine_sha256) and calibration.machine_sha256 != machine.sha256
    if changed and not machine_changed:
        raise CompgenError(f"the machine file changed since the calibration of {calibration.taken[:16]} "
                           f"(SHA-256 {calibration.machine_sha256[:12]}… then, {machine.sha256[:12]}… now)",
                           where=machine.source,
                           hint="check with the machine file of then; or, if the change is known (a "
                                "tolerance, a limit), add --machine-changed; after a change of geometry, "
                                "calibrate again")
    now_entry, names, changes = _changes(machine, fit, calibration, edits, taken)
    paths, ranges = _paths(machine, data)
    series = [e for e in entries if e.taken <= taken] + [now_entry]
    new_flags = [f for f in flags(machine, series, names) if f.taken == taken]
    advice = _advice(machine, fit, calibration, edits, changes, paths, new_flags, model)
    nothing = nothing_to_correct(machine, fit, machine.controller) or ""
    return CheckResult(name, serial, calibration, fit.marker, taken, changes, fit.residual["sigma_um"],
                       paths, new_flags, advice, changed, model, nothing, accepted, ranges)


def _changes(machine: Machine, fit: FitResult, calibration: Entry, edits: Sequence[dict],
             taken: str) -> tuple[Entry, list[str], list[Change]]:
    """The check as an entry of the history (the corrections written since counted), the
    location errors both hold, and each one's change against the calibration."""
    k = machine.drift.k_sigma
    corrected: dict[str, float] = {}
    for e in edits:
        if e["taken"] <= taken:
            for n, v in e["corrects"].items():
                corrected[n] = corrected.get(n, 0.0) + v
    now_entry = Entry(0, taken, fit.marker, "check", "rtest", "", fit.residual["sigma_um"],
                      {n: e.value for n, e in fit.parameters.items()},
                      {n: e.std for n, e in fit.parameters.items()},
                      {n: e.unit for n, e in fit.parameters.items()}, corrected)
    names = [n for n in machine_params(machine, fit.model) if n in calibration.values]
    changes = []
    for n in names:
        change = now_entry.machine_value(n) - calibration.machine_value(n)
        std = math.hypot(now_entry.std[n], calibration.std[n])
        limit = limit_of(machine, now_entry.units[n], name=n)
        status = "pass" if abs(change) <= limit else ("fail" if abs(change) > k * std else "unsure")
        changes.append(Change(n, change, std, now_entry.units[n], limit, status,
                              effect_of_param(machine, n).words))
    return now_entry, names, changes


def _paths(machine: Machine, data) -> tuple[dict[str, str], dict[str, float]]:
    """Each path's largest deviation range beyond the set-up (µm), and against its
    ``[tolerances]`` its verdict."""
    from ..statistics.identify import beyond_setup

    joined = Measurements.concat(data)
    got = beyond_setup(machine, joined.poses, joined.deviation)
    ranges = {p: float(max(stats["range_um"])) for p, stats in got["per_path"].items()}
    paths = {}
    for p, worst in ranges.items():
        if p in machine.tolerances:
            tol = machine.tolerances[p]
            paths[p] = f"PASS {worst:.2f} <= {tol:g}" if worst <= tol else f"FAIL {worst:.2f} > {tol:g}"
    return paths, ranges


def _advice(machine: Machine, fit: FitResult, calibration: Entry, edits: Sequence[dict],
            changes: list[Change], paths: dict[str, str], new_flags: list[Flag],
            model: CheckModel) -> list[str]:
    """What to do next, from what failed, what is unsure, the residual and the drifts."""
    advice = []
    failed = [c for c in changes if c.status == "fail"]
    if failed:
        worst = max(failed, key=lambda c: abs(c.change) / c.limit)
        advice.append(f"re-calibrate: {', '.join(c.param for c in failed)} moved beyond its limit "
                      f"({worst.param}, {worst.words}, most); measure all paths ({me()} measure-program "
                      f"--machine {file_ref(machine)} --path all -o calibration"
                      f"{controller(machine.controller).program_ext}), fit, and write the edit with "
                      "kinematics")
        axes = {c.param[-1] for c in failed}      # ISO 230 symbols end with the axis they locate
        if len(axes) == 1:
            axis = axes.pop()
            advice.append(f"look at axis {axis} first: a location error of one axis moving alone points "
                          "to a collision, a loosened clamp or a bearing, not to temperature")
    if any(c.status == "unsure" for c in changes):
        advice.append("measure more (all paths, or the check path twice): "
                      + ", ".join(c.param for c in changes if c.status == "unsure")
                      + " may have moved beyond its limit, but its σ is too large to say")
    if fit.residual["sigma_um"] > 2.0 * calibration.sigma_um and fit.residual["sigma_um"] > 1.0:
        advice.append(f"check the set-up: the residual σ̂ is {fit.residual['sigma_um']:.2f} µm against the "
                      f"calibration's {calibration.sigma_um:.2f} µm (ball stem, nest, temperature, a loose "
                      "magnet base)")
    if any(v.startswith("FAIL") for v in paths.values()):
        if failed:
            advice.append("a path is beyond its tolerance: re-calibrate, then compare the predicted residual")
        elif any(e.get("marker") == calibration.marker for e in edits):
            # the edit is loaded: what stays is what no edit of this control corrects
            advice.append("the location errors are where the last calibration left them and its edit is "
                          "recorded, but a path is beyond its tolerance: what the edit could not correct"
                          + (f" ({', '.join(model.effects)}, which the calibration found)" if model.effects
                             else "") + "; compare, on the calibration's fit.json, says what stays "
                          "uncompensable, and diagnose whether the model misses an effect")
        else:
            advice.append("the location errors are where the last calibration found them, but a path "
                          f"is beyond its tolerance: that calibration ({calibration.marker}, "
                          f"{calibration.taken[:10]}) is not corrected on the control; write the edit from "
                          "its fit.json with kinematics, and load it")
    for f in new_flags:
        if f.kind == "drift":
            advice.append(f"{f.param} drifts steadily ({f.text().split('  ', 1)[1]}): plan the next "
                          "calibration before it reaches its limit, and look for its cause (warm-up, season)")
    return advice


def record_check(store: Store, result: CheckResult, fit: FitResult, machine: Machine, *,
                 serial: str | None = None, operator: str = "") -> int:
    """The check's session, its fit and its verdict, in one transaction."""
    name, serial = machine_key(machine, serial)
    with store.writing():
        mid = lookup_machine(store, name, serial, create=False)
        fid = session_and_fit(store, mid, fit, machine, result.taken, device_of(fit.data), operator, {},
                               "check",
                               "check passed" if result.passed else "check failed")
        return store.insert("checks", {"machine_id": mid, "fit_id": fid, "against_fit_id": result.against.id,
                                       "passed": int(result.passed), "summary": result.summary(),
                                       "recorded": now()})
