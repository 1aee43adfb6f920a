"""What a kinematics edit will achieve, and whether it did.

Prediction, honest by construction: the fitted machine is driven the way the control will
drive it after the edit (TCPM with the corrected axis lines, plus the CEC tables a SINUMERIK
holds), and the part of the readings the model never explained (its residual) is added
back. What the control cannot express is simply not in its model, so it stays. The ball's
place on the table is set-up, not a machine error: a set-up-only fit (XOW YOW ZOW) removes
it from every figure here, before and after alike, and it is named as left out.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..controllers.correction import plan
from ..controllers.kinematics import nothing_to_correct
from ..controllers.registry import controller
from ..data.rtest import Measurements, RTestData
from ..errors import CompgenError
from ..model.kinematics import Model
from ..model.machine import Machine
from ..model.poses import Poses
from ..statistics.diagnose import diagnose
from ..statistics.identify import beyond_setup, identify
from ..statistics.results import FitResult

AS_PREDICTED = (1.25, 0.2)   # measured RMS within 1.25 × predicted + 0.2 µm counts as predicted


@dataclass(frozen=True, eq=False)
class Comparison:
    """Measured against predicted: each path's RMS and range before the edit, as predicted after
    it (``predicted_post``) and, with post data, as measured (µm, beyond the set-up); what the
    edit cannot compensate, what it takes as done besides loading its files (``assumes``), the
    warnings the prediction itself gives, and "nothing to correct" where the edit would write
    noise. ``to_dict`` is ``compare --json``."""

    controller: str
    before: dict
    predicted_post: dict
    not_compensated: tuple[str, ...]
    setup: tuple[str, ...]
    measured_post: dict | None = None
    warnings: tuple[str, ...] = ()      # what the prediction says against the edit
    assumes: tuple[str, ...] = ()       # what the prediction takes as done besides loading files
    tolerances: dict = field(default_factory=dict)   # path → largest range allowed, µm
    nothing: str = ""                   # "nothing to correct: ...", where the edit would write noise

    def to_dict(self) -> dict:
        out = {"format": "compgen.compare/1", "controller": self.controller, "before": self.before,
               "predicted_post": self.predicted_post, "not_compensated": list(self.not_compensated),
               "setup_left_out": list(self.setup), "warnings": list(self.warnings),
               "assumes": list(self.assumes), "nothing_to_correct": self.nothing}
        if self.measured_post is not None:
            out["measured_post"] = self.measured_post
        return out

    def rows(self) -> list[dict]:
        """Per path: RMS before, predicted and measured (µm, over dX dY dZ), the predicted
        range per direction and the verdict: what every view of the comparison shows."""
        out = []
        for name, pred in self.predicted_post["per_path"].items():
            meas = self.measured_post["per_path"].get(name) if self.measured_post else None
            tol = self.tolerances.get(name)
            out.append({"path": name, "before": _rms(self.before["per_path"].get(name)),
                        "predicted": _rms(pred), "measured": _rms(meas) if meas else None,
                        "range": pred["range_um"], "tolerance": tol,
                        "predicted_verdict": "" if tol is None else (
                            "within" if max(pred["range_um"]) <= tol else "BEYOND"),
                        "verdict": (self.measured_post["verdicts"].get(name, "(none in machine file)")
                                    if self.measured_post else "")})
        return out

    def report(self) -> str:
        ctl = controller(self.controller).words
        lines = [f"compgen compare: after the kinematics edit for {ctl}",
                 *([f"  {self.nothing}: kinematics writes no edit (--anyway writes it)"]
                   if self.nothing else []),
                 "  misfit beyond the set-up (the ball's offset XOW YOW ZOW fitted out at each of its "
                 "mountings, and each later nest's), µm:", "",
                 f"  {'path':<8}{'before RMS':>11}{'predicted':>11}"
                 + (f"{'measured':>10}" if self.measured_post else "")
                 + "   predicted range dX dY dZ" + ("   tolerance" if self.measured_post else "")]
        for r in self.rows():
            row = f"  {r['path']:<8}{r['before']:>11.3f}{r['predicted']:>11.3f}"
            if self.measured_post:
                row += f"{r['measured']:>10.3f}" if r["measured"] is not None else f"{'-':>10}"
            row += "   " + " ".join(f"{v:5.2f}" for v in r["range"])
            if self.measured_post:
                row += f"   {r['verdict']}"
            lines.append(row)
        lines.append(f"  {'all':<8}{self.before['rms_um']:>11.3f}{self.predicted_post['rms_um']:>11.3f}"
                     + (f"{self.measured_post['rms_um']:>10.3f}" if self.measured_post else ""))
        if self.not_compensated:
            lines += ["", f"  stays in the prediction, {ctl} cannot hold it from compgen's files: "
                          + ", ".join(self.not_compensated)]
        lines.append(f"  left out, set-up not machine: {', '.join(self.setup)}")
        lines += [f"  assumes: {a}" for a in self.assumes]
        lines += [f"  WARNING: {w}" for w in self.warnings]
        if self.measured_post:
            m = self.measured_post
            lines += ["", "  " + m["statement"]]
            if m.get("diagnose"):
                lines.append("  diagnose on the post data: " + m["diagnose"])
        return "\n".join(lines) + "\n"


def _rms(stats: dict | None) -> float:
    return float(np.sqrt(np.mean(np.square(stats["rms_um"])))) if stats else float("nan")


def compare(machine: Machine, data: Sequence[RTestData], fit: FitResult, controller_name: str,
            post: Sequence[RTestData] = ()) -> Comparison:
    ctl = controller(controller_name)
    joined = Measurements.concat(data)
    poses, y = joined.poses, joined.deviation
    residual = y - fit.evaluate(machine, poses)
    p = plan(machine, fit, force=True)   # predict even what the limits would refuse to write
    not_held = ctl.not_held(machine, p)
    after = Poses(ctl.holds(machine, p).drive(machine, poses), poses.ball, poses.t, poses.path,
                  nest=poses.nest)
    predicted = Model(machine, fit.model).relative(after, fit.values) + residual
    before = beyond_setup(machine, poses, y)
    pred = beyond_setup(machine, after, predicted)
    measured = _measured(machine, fit, post, pred) if post else None
    # the tables the edit writes: a head's own error motions get none (they stay, not_held)
    by_hand = [t.effect for t in ctl.tables(machine, p)] if ctl.tables_by_hand else []
    assumes = ((f"the compensation values of the edit's .comp.csv ({', '.join(by_hand)}) are entered "
                f"into the {ctl.words}'s compensation tables by hand",) if by_hand else ())
    if machine.heads and not ctl.edits_head(machine):   # compgen's model of the control, no file
        assumes += (f"no edit is written for a head yet: the prediction is for the fitted location errors "
                    f"entered by hand into the {ctl.words}'s kinematics, as compgen models it for a table",)
    return Comparison(ctl.name, before, pred, tuple(not_held), tuple(p.setup), measured,
                      tuple(_warnings(machine, fit, pred)), assumes, dict(machine.tolerances),
                      nothing_to_correct(machine, fit, controller_name) or "")


def _warnings(machine: Machine, fit: FitResult, pred: dict) -> list[str]:
    """Where the prediction itself says the edit will not do: the fit leaves more than an
    R-test's noise, or a path stays out of its tolerance even as predicted."""
    from ..statistics.gate import SIGMA_PLAUSIBLE_UM
    out = []
    if not fit.residual["sigma_um"] <= SIGMA_PLAUSIBLE_UM:
        out.append(f"the fit leaves σ̂ = {fit.residual['sigma_um']:.2f} µm, above the "
                   f"{SIGMA_PLAUSIBLE_UM:g} µm an R-test's noise allows: the prediction inherits what the "
                   "model misses (run diagnose)")
    for name, stats in pred["per_path"].items():
        tol = machine.tolerances.get(name)
        if tol is not None and max(stats["range_um"]) > tol:
            out.append(f"{name} is predicted at {max(stats['range_um']):.2f} µm range, beyond its tolerance "
                       f"{tol:g} µm: this edit alone cannot bring it into tolerance")
    return out


def _measured(machine: Machine, fit: FitResult, post: Sequence[RTestData], predicted: dict) -> dict:
    joined = Measurements.concat(post)
    poses, y = joined.poses, joined.deviation
    got = beyond_setup(machine, poses, y)
    tolerances = machine.tolerances
    verdicts = {}
    for name, stats in got["per_path"].items():
        if name in tolerances:
            worst = max(stats["range_um"])
            verdicts[name] = (f"PASS {worst:.2f} <= {tolerances[name]:g}" if worst <= tolerances[name]
                              else f"FAIL {worst:.2f} > {tolerances[name]:g}")
    factor, floor = AS_PREDICTED
    ok = got["rms_um"] <= factor * predicted["rms_um"] + floor
    out = {**got, "verdicts": verdicts, "as_predicted": bool(ok)}
    if ok:
        out["statement"] = (f"The machine improved as predicted: {got['rms_um']:.3f} µm measured, "
                            f"{predicted['rms_um']:.3f} µm predicted.")
    else:
        out["statement"] = (f"The machine did NOT improve as predicted: {got['rms_um']:.3f} µm measured "
                            f"against {predicted['rms_um']:.3f} µm predicted. Check that the edit was "
                            "loaded with the right sign (sign check) and that the set-up did not change.")
        try:
            refit = identify(machine, list(post), fit.model)
            found = diagnose(machine, list(post), refit)
            best = found.candidates[0]
            out["diagnose"] = (f"{best.effect} ({best.description}) would leave "
                               f"{best.rms_after_um:.3f} µm of {found.rms_um:.3f} µm"
                               + ("" if best.significant else "; nothing significant"))
        except CompgenError as exc:   # the post data may not support the model: say so
            out["diagnose"] = f"not possible on these post data: {exc}"
    return out
