"""A fit's uncertainty budget, in the sense of the GUM: what the data give (``identify``'s
σ), what the choices the data cannot make move (``choice.py``), and what the measuring
device's own calibration allows. An R-test whose sensors' gain is known to a relative
standard uncertainty u ([rtest] gain_u) reads (1 + g)·y with g ~ u in each direction: to
first order the fitted values move by J⁺(g ⊙ y), so each direction adds (u·J⁺(eₐ ⊙ y))² to
every parameter's variance. A gain error within the calibration then stays within the σ
reported; one beyond it is the device out of calibration, which no budget covers."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..data.rtest import Measurements, RTestData
from ..model.kinematics import Model
from ..model.machine import Machine
from ..model.sides import FreeConstants
from .choice import with_choices
from .results import FitResult
from .significance import ALPHA


def gain_sensitivity(machine: Machine, data: Sequence[RTestData], fit: FitResult) -> np.ndarray:
    """(3, p): how far each free parameter moves (mm or rad) per unit gain error of the
    R-test's X, Y and Z sensor (readings of a probe log are sphere centres: no gain)."""
    joined = Measurements.concat(data)
    poses = joined.poses
    rtest = joined.rtest
    model = Model(machine, fit.model)
    free = [model.names.index(n) for n in fit.free]
    J = model.jacobian(poses, fit.values)[:, :, free]
    starts = FreeConstants(machine, fit.model, poses).projector()
    if starts is not None:       # the start sides' constants are fitted too: as fit projects them
        J = starts(J)
    A = J.reshape(-1, len(free))
    out = np.zeros((3, len(free)))
    for k in range(3):
        c = np.zeros((len(poses), 3))
        c[rtest, k] = joined.deviation[rtest, k]
        if starts is not None:
            c = starts.remove(c)
        out[k] = np.linalg.lstsq(A, c.ravel(), rcond=None)[0]
    return out


def with_budget(machine: Machine, data: Sequence[RTestData], fit: FitResult, alpha: float = ALPHA,
                noise_um: float | None = None) -> FitResult:
    """``fit`` with every σ holding its budget: the data, the choices they cannot make
    (``choice.with_choices``), and the R-test's sensor gains as its calibration allows
    (``machine.gain_u``; recorded in ``device_budget``)."""
    fit = with_choices(machine, data, fit, alpha, noise_um)
    if not machine.gain_u or not any(d.device == "rtest" for d in data):
        return fit
    s = gain_sensitivity(machine, data, fit)
    extra = {n: float(machine.gain_u * np.linalg.norm(s[:, i])) for i, n in enumerate(fit.free)}
    return fit.widened(extra, device_budget={"gain_u": machine.gain_u, "std": extra})
