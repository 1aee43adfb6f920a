"""The one screen: per location error, what the fit found and what the control
holds after the edit, each with its σ and its own limit (``[drift]``: its class's, or its
own under ``each``); per path, the deviation range against its tolerance, predicted and,
with data measured after the edit, measured; the RMS predicted after the edit; what stays
uncompensable; and the one next step. KinematicsOpt reduces a run to measured against
optimised dispersion, AxiSet to a pass or fail per axis: this is both, with the σ."""

from __future__ import annotations

import json
import shlex
from collections.abc import Sequence
from dataclasses import dataclass

from .. import me
from ..controllers.kinematics import corrected_by
from ..controllers.registry import controller
from ..data.rtest import RTestData
from ..history.drift import limit_of
from ..model.effects import effect_of_param, location_model
from ..model.machine import Machine
from ..statistics.diagnosis import Diagnosis
from ..statistics.gate import fit_gate, gate_reasons
from ..statistics.results import FitResult
from ..units import shown
from .compare import Comparison, compare

K_SIGMA = 3.0       # an error beyond its limit by less than this many σ of itself is "unsure"


@dataclass(frozen=True)
class Row:
    """A location error: fitted (``before``), held by the control after the edit
    (``after``, None for set-up), σ and limit, in shown units (µm or ″)."""

    name: str
    words: str
    unit: str
    before: float
    std: float
    after: float | None
    limit: float
    held: str        # "corrected", "not held" (the control takes no such value), "set-up"

    @property
    def status(self) -> str:
        if self.after is None:
            return "set-up"
        if abs(self.after) <= self.limit:
            return "within"
        return "BEYOND" if abs(self.after) - self.limit > K_SIGMA * self.std else "unsure"


@dataclass(frozen=True)
class Verdict:
    """The one screen of ``compgen verdict``: each location error before and after the edit with
    its σ and its own limit (``rows``), each path against its tolerance (``comparison``), the
    fit gate's reasons and the next step, a command that runs as printed."""

    machine: str
    controller: str
    fit_file: str
    rows: tuple[Row, ...]
    comparison: Comparison
    gate: tuple[str, ...]
    next_step: str

    def to_dict(self) -> dict:
        return {"format": "compgen.verdict/1", "machine": self.machine, "controller": self.controller,
                "fit": self.fit_file,
                "location_errors": [{"name": r.name, "words": r.words, "unit": r.unit, "fitted": r.before,
                                     "std": r.std, "after_edit": r.after, "limit": r.limit, "held": r.held,
                                     "status": r.status} for r in self.rows],
                "paths": self.comparison.rows(),
                "predicted_post_rms_um": self.comparison.predicted_post["rms_um"],
                "measured_post_rms_um": (self.comparison.measured_post or {}).get("rms_um"),
                "uncompensable": list(self.comparison.not_compensated),
                "gate": list(self.gate), "next": self.next_step}

    def text(self) -> str:
        ctl = controller(self.controller).words
        lines = [f"VERDICT: {self.next_step}",
                 f"compgen verdict: {self.machine}, {ctl}, from {self.fit_file}", "",
                 f"  {'':<5}{'fitted':>18}   {'after the edit':>17}   {'limit':>7}   status   meaning"]
        for r in self.rows:
            after = f"{'set-up':>17}" if r.after is None else f"{r.after:+8.2f} ± {r.std:<4.2f}{r.unit:<2}"
            limit = "" if r.after is None else f"{r.limit:5.1f}{r.unit}"
            lines.append(f"  {r.name:<5}{r.before:+9.2f} ± {r.std:<4.2f}{r.unit:<2}   {after}   "
                         f"{limit:>7}   {r.status:<8} {r.words}"
                         + ("" if r.held != "not held" else " (the control holds no such value)"))
        c = self.comparison
        lines += ["", f"  {'path':<6}{'before RMS':>11}{'predicted':>10}"
                      + (f"{'measured':>10}" if c.measured_post else "") + "   range (µm)   tolerance"]
        for p in c.rows():
            tol = "" if p["tolerance"] is None else (
                p["verdict"] or f"{p['predicted_verdict']} {max(p['range']):.2f} vs {p['tolerance']:g}")
            lines.append(f"  {p['path']:<6}{p['before']:>11.3f}{p['predicted']:>10.3f}"
                         + ((f"{p['measured']:>10.3f}" if p["measured"] is not None else f"{'-':>10}")
                            if c.measured_post else "")
                         + f"   {max(p['range']):9.2f}   {tol or '(none in the machine file)'}")
        lines.append(f"  predicted RMS after the edit {c.predicted_post['rms_um']:.3f} µm"
                     + (f"; measured {c.measured_post['rms_um']:.3f} µm" if c.measured_post else ""))
        if c.not_compensated:
            lines.append(f"  stays uncompensable on {ctl}: {', '.join(c.not_compensated)}")
        lines += [f"  the fit should not reach the control: {g}" for g in self.gate]
        return "\n".join(lines) + "\n"


def verdict(machine: Machine, data: Sequence[RTestData], fit: FitResult, fit_file: str, controller_name: str,
            post: Sequence[RTestData] = (), comparison: Comparison | None = None,
            found: Diagnosis | None = None) -> Verdict:
    """The one screen of ``fit`` (of ``data``, from ``fit_file``) for ``controller_name``,
    with ``post`` (data measured after the edit) where given; ``comparison`` and ``found``
    (its compare and diagnosis) where the caller has made them already."""
    ctl = controller(controller_name)
    c = comparison or compare(machine, data, fit, controller_name, post)
    corrected = corrected_by(machine, fit, ctl)
    rows = []
    for n in location_model(machine):
        if n not in fit.parameters:
            continue
        e = fit.parameters[n]
        value, unit = shown(e.value, e.unit)
        std = shown(e.std, e.unit)[0]
        setup = effect_of_param(machine, n).carrier in ("ball", "nest")
        after = None if setup else shown(e.value - corrected.get(n, 0.0), e.unit)[0]
        limit = shown(limit_of(machine, e.unit, name=n), e.unit)[0]
        rows.append(Row(n, effect_of_param(machine, n).words, unit, value, std, after, limit,
                        "set-up" if setup else "corrected" if n in corrected else "not held"))
    gate = tuple(fit_gate(machine, data, fit) if found is None else gate_reasons(data, fit, found))
    return Verdict(machine.name, ctl.name, fit_file, tuple(rows), c, gate,
                   _next(machine, fit_file, ctl, c, gate, rows))


def _next(machine: Machine, fit_file: str, ctl, c: Comparison, gate: tuple[str, ...], rows) -> str:
    """The one next step, as a command where one does it."""
    f = shlex.quote(fit_file)
    if gate:
        return f"settle the fit first: {me()} diagnose --from {f}"
    if c.nothing:
        return f"{c.nothing}; the machine stays as it is"
    beyond = [r.name for r in rows if r.status == "BEYOND"]
    if not c.measured_post:
        then = "load it, run its sign check, measure again, then add --post to this command"
        if ctl.needs_current:         # the state is the control's file: no command compgen can print
            return (f"write the edit from {ctl.state_files} as the control holds them (kinematics --from "
                    f"{f} with --current); {then}")
        named = f" --controller {ctl.name}" if ctl.name != machine.controller else ""
        return f"write the edit: {me()} kinematics --from {f}{named} -o KIN{ctl.main_suffix(None)}; {then}"
    m = c.measured_post
    failed = [p for p, v in m.get("verdicts", {}).items() if not v.startswith("PASS")]
    if not m.get("as_predicted"):
        return "the machine did not improve as predicted: check the edit's sign and the set-up (sign check)"
    if failed or beyond:
        return ("improved as predicted, but out of limits: " + ", ".join(failed + beyond)
                + f"; see what stays uncompensable, and {me()} diagnose --from {f}")
    return f"sign off: improved as predicted, every path within tolerance; record it: {me()} history add {f}"


def verdict_json(v: Verdict) -> str:
    return json.dumps(v.to_dict(), indent=2, ensure_ascii=False)
