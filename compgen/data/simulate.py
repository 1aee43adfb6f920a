"""Simulated R-test sessions: the project's own source of data with hidden effects."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..errors import CompgenError
from ..files import read_json
from ..model.effects import effect_of_param
from ..model.kinematics import Model
from ..model.machine import Machine
from ..model.poses import Poses
from ..units import to_inside
from .rtest import RTestData


def ar1_noise(n: int, rho: float, sigma_um: float, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) mm of AR(1) noise along the readings, e[i] = ρ·e[i−1] + white, stationary σ."""
    if rho == 0:
        return rng.normal(0.0, sigma_um * 1e-3, (n, 3))
    e = rng.normal(0.0, sigma_um * np.sqrt(1 - rho**2), (n, 3))
    out = np.empty((n, 3))
    out[0] = rng.normal(0.0, sigma_um, 3)
    for i in range(1, n):
        out[i] = rho * out[i - 1] + e[i]
    return out * 1e-3


def simulate(machine: Machine, truth: Mapping[str, float], poses: Poses, noise_um: float = 0.0,
             rng: np.random.Generator | None = None, drive=None, rho: float = 0.0) -> RTestData:
    """Readings of the exact model with ``truth`` (name → mm or rad) plus noise of σ
    ``noise_um``, white or, with ``rho``, correlated from reading to reading (AR(1)).

    ``drive`` (poses → commanded axes, mm and rad) is the control's kinematics after an
    edit: the machine goes where the control sends it, the R-test reads the true machine
    there, and the file records the nominal poses, as a real session would.
    """
    if not (math.isfinite(noise_um) and noise_um >= 0):
        raise CompgenError(f"noise must be a finite σ ≥ 0 µm, not {noise_um}")
    if not 0 <= rho < 1:
        raise CompgenError(f"the noise's correlation ρ must be in [0, 1), not {rho}")
    model = Model(machine, list(truth))
    values = np.array(list(truth.values()), dtype=float)
    if drive is None:
        dev = model.deviation(poses, values)
    else:
        actual = Poses(drive(poses), poses.ball, poses.t, poses.path, poses.side, poses.nest)
        dev = model.relative(actual, values) - Model(machine, ()).relative(poses)
    if noise_um:
        rng = rng or np.random.default_rng()
        dev = dev + ar1_noise(len(dev), rho, noise_um, rng)
    return RTestData(poses, dev)


def read_truth(path: str | Path, machine: Machine) -> dict[str, float]:
    """Parameters from a truth file or a fit.json: ``{"parameters": {NAME: {"value": v,
    "unit": u}}}`` → {canonical name: value in mm or rad}."""
    where = str(path)
    params = read_json(path, "truth file").get("parameters")
    if not isinstance(params, dict):
        raise CompgenError('needs an object "parameters": {NAME: {"value": v, "unit": u}}',
                           where=where)
    out = {}
    for name, p in params.items():
        at = f"{where}: parameters.{name}"
        effect = effect_of_param(machine, name)
        if not isinstance(p, dict) or not isinstance(p.get("value"), int | float) \
                or isinstance(p.get("value"), bool) or not isinstance(p.get("unit"), str):
            raise CompgenError('must be {"value": number, "unit": text}', where=at)
        canonical = Model(machine, [name]).names[0]
        if canonical in out:
            raise CompgenError("parameter given twice (under two spellings)", where=at)
        out[canonical] = to_inside(float(p["value"]), p["unit"], effect.unit, at)
    return out
