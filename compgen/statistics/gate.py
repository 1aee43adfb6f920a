"""Whether a fit may reach a controller: what a user must settle first."""

from __future__ import annotations

from collections.abc import Sequence

from .. import me
from ..data.rtest import Measurements, RTestData
from ..errors import CompgenError
from ..model.machine import Machine
from .diagnose import diagnose
from .diagnosis import Diagnosis
from .results import FitResult

# An R-test's sphere-centre repeatability is 0.5–1 µm and drift adds a few µm over a run
# (docs/diagnose.md, "Noise of R-test sensors"): a fit leaving more than this has missed
# something physical, or the data are not what they claim.
SIGMA_PLAUSIBLE_UM = 3.0
# Below this spread the readings cannot be µm of a real machine (mm given as µm, say)
SPREAD_PLAUSIBLE_UM = 0.5


def unit_suspicion(data: Sequence[RTestData]) -> str | None:
    """Why the readings look like another unit than µm, or None."""
    y = Measurements.concat(data).deviation * 1e3
    spread = float((y.max(axis=0) - y.min(axis=0)).max()) if y.size else 0.0
    if spread < SPREAD_PLAUSIBLE_UM:
        return (f"the readings spread over {spread:.3g} µm at most, far below any R-test's noise "
                f"(0.5–1 µm): they are likely in mm, not µm")
    return None


def fit_gate(machine: Machine, data: Sequence[RTestData], fit: FitResult) -> list[str]:
    """Why this fit should not reach a controller: what a user must settle first (empty when
    the fit explains its data to an R-test's noise with nothing significant missing)."""
    return gate_reasons(data, fit, diagnose(machine, data, fit))


def gate_reasons(data: Sequence[RTestData], fit: FitResult, found: Diagnosis) -> list[str]:
    """``fit_gate``'s reasons from a diagnosis of ``fit`` already made (``found``)."""
    reasons = []
    device = "the probe" if found.data_device == "probe" else "the R-test"   # whose noise, whose error
    suspicion = unit_suspicion(data)
    if suspicion:
        reasons.append(suspicion + "; check the CSV's dX dY dZ unit")
    sigma = fit.residual["sigma_um"]
    if not sigma <= SIGMA_PLAUSIBLE_UM:
        reasons.append(f"the fit leaves σ̂ = {sigma:.2f} µm, above the {SIGMA_PLAUSIBLE_UM:g} µm an R-test's "
                       "noise allows: the model misses an effect, or the data are wrong (columns "
                       "swapped, a sign, a mismatched machine file)")
    if found.unexplained:
        where = (f"the residual exceeds {device}'s noise ({found.misfit[0]['direction']} of "
                 f"{found.misfit[0]['path']}: {found.misfit[0]['rms_um']:.2f} µm against "
                 f"{found.misfit[0]['noise_um']:.2f} µm)" if found.misfit else
                 f"the residual holds a periodic line no catalogue effect has ({found.outside_line.text()})")
        reasons.append(f"{where} and no catalogue effect explains it (run diagnose: it shows where and its "
                       "shape, and how to declare it)")
    elif (c := found.blamed) and c.form:
        reasons.append(f"the ball's form explains the misfit as well as any machine effect ({c.text()}): "
                       "measure again on a round ball, or one whose form is known")
    elif c := found.blamed:
        reasons.append(f"{device} itself explains the misfit as well as any machine effect ({c.text()}): "
                       "calibrate the device and measure again")
    elif found.form_rival:
        reasons.append(f"the ball's form ({found.form_rival}) explains the misfit as well as "
                       f"{found.significant[0].effect}: turn the ball on its stem and measure again (run "
                       "diagnose: it prints how)")
    elif found.step_rivals:
        reasons.append(f"{found.setup_step.text()} explains the misfit as well as "
                       f"{found.significant[0].effect}: measure again without touching the set-up, and fit "
                       "the data of one mounting")
    elif found.significant:
        reasons.append("diagnose finds effects the model misses: "
                       + ", ".join(c.effect for c in found.significant[:3])
                       + " (run diagnose, add the effect with fit --add, and refit)")
        if found.significant_devices:       # a second cause, the device's: no refit removes it
            reasons.append(f"{device}'s own " + ", ".join(c.text() for c in found.significant_devices)
                           + " stays significant beside them: calibrate the device and measure again")
    return reasons


def gate_edit(machine: Machine, data: Sequence[RTestData], fit: FitResult, fit_file: str,
              despite: bool = False) -> tuple[str, ...]:
    """The gate before an edit: the fit's reasons not to reach a control, refused unless
    written ``despite`` them (then returned, for the edit's header and the history)."""
    reasons = tuple(fit_gate(machine, data, fit))
    if reasons and not despite:
        raise CompgenError("this fit should not reach the control: " + "; ".join(reasons),
                           hint=f"settle that first (see {me()} diagnose --from {fit_file}); --despite-gate "
                                "writes the edit anyway")
    return reasons
