"""Identification: first-order least squares (the seed's method), then Gauss–Newton on the
exact model, with uncertainties from the residual and the Jacobian, and an identifiability
check that refuses what the data cannot separate.

References: seed report §3 (eq. 26); ``shared/research/identification.md`` §1.9 and §3.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from . import __version__
from .advice import Advisor
from .effects import canonical, effect_of_param, location_model
from .errors import CompgenError
from .kinematics import Model, Poses
from .machine import Machine
from .results import DataRef, Estimate, FitResult
from .rtest import RTestData
from .significance import COND_LIMIT, condition
from .units import parse_quantity, shown

MAX_ITER = 30
STEP_TOL_SHOWN = 1e-7     # µm or arcsec: Gauss–Newton has converged below this step


def identify(machine: Machine, data: Sequence[RTestData], model: Sequence[str] | None = None,
             fixed: Mapping[str, float] | None = None, method: str = "exact",
             sign: str = "nest-minus-ball") -> FitResult:
    """Identify the parameters of ``model`` from R-test data.

    Parameters
    ----------
    model : parameter names; default the seed's 11 generalised (``location_model``)
    fixed : name → value (mm, rad) held fixed; names not in ``model`` are added to it
    method : ``"exact"`` (first-order start, then Gauss–Newton on the exact model) or
        ``"linear"`` (first-order only, as the seed)
    """
    if method not in ("exact", "linear"):
        raise CompgenError(f"method must be 'exact' or 'linear', not {method!r}")
    if not data:
        raise CompgenError("no data to fit")
    fixed = dict(fixed or {})
    names = list(model or location_model(machine))
    names += [n for n in fixed if n not in names]
    m = Model(machine, names)
    free = [i for i, n in enumerate(names) if n not in fixed]
    if not free:
        raise CompgenError("every parameter is fixed: nothing to fit")
    poses = Poses.concat([d.poses for d in data])
    y = np.concatenate([d.deviation for d in data])
    readings, p = y.size, len(free)
    if readings <= p:
        raise CompgenError(f"{len(poses)} poses give {readings} readings for {p} parameters",
                           hint="measure more poses: a K4 path has 241")

    x = np.array([fixed.get(n, 0.0) for n in names])
    weights = Weights(data)

    def residual(x):
        return weights.apply(y - m.deviation(poses, x)).ravel()

    def jac(x):
        return weights.apply(m.jacobian(poses, x)[:, :, free]).reshape(readings, p)

    def solve(x, J):
        # first order about here (seed eq. 26): y − dev(x) ≈ J Δa
        x = x.copy()
        x[free] += np.linalg.lstsq(J, residual(x), rcond=None)[0]
        iterations = 0
        if method == "exact":
            x, J, iterations = _gauss_newton(residual, jac, x, J, free, m)
        return x, J, iterations

    J = jac(x)
    check_identifiable(machine, m, free, J, poses)
    x, J, iterations = solve(x, J)
    # devices of unknown relative noise: their variances are estimated with the fit
    while weights.estimated and weights.rescale(residual(x), J):
        x, J, more = solve(x, jac(x))
        iterations += more

    raw = y - m.deviation(poses, x)
    r = weights.apply(raw).ravel()
    dof = readings - p
    sigma2 = float(r @ r) / dof
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    cov = (Vt.T / s**2) @ Vt * sigma2
    std = np.sqrt(np.diag(cov))
    corr = cov / np.outer(std, std) if np.all(std > 0) else np.eye(p)
    norm = np.linalg.norm(J, axis=0)
    sv = np.linalg.svd(J / norm, compute_uv=False)

    params = {}
    for i, n in enumerate(names):
        e = m.effects[i]
        k = free.index(i) if i in free else None
        params[n] = Estimate(float(x[i]), 0.0 if k is None else float(std[k]), e.unit, k is None)
    return FitResult(
        machine={"name": machine.name, "file": machine.bundled or _absolute(machine.source),
                 "sha256": machine.sha256, **({"bundled": True} if machine.bundled else {})},
        data=tuple(DataRef(_absolute(d.source), d.sha256, len(d), _counts(d.poses.path), d.device)
                   for d in data),
        model=tuple(names), parameters=params, free=tuple(names[i] for i in free),
        correlation=np.clip(corr, -1.0, 1.0), singular_values=sv,
        residual=residual_stats(poses, raw, dof),
        method=method, iterations=iterations, sign=sign, version=__version__,
        descriptions={n: e.words for n, e in zip(names, m.effects, strict=True)})


class Weights:
    """How each reading counts. R-test readings alone: equally (ordinary least squares, the
    seed's). Sphere centres from a probe log carry their own covariance, so every reading
    is whitened by it; R-test readings fitted beside them get a variance of their own,
    estimated with the fit from each device's share of the residual (variance component
    estimation), since neither device's noise is known against the other's beforehand."""

    ROUNDS = 10
    PRIOR_UM = 1.0      # an R-test reading's σ before it is estimated

    def __init__(self, data: Sequence[RTestData]):
        self.active = any(d.cov is not None for d in data)
        self.estimated = False
        if not self.active:
            return
        prior = np.eye(3) * (self.PRIOR_UM * 1e-3) ** 2
        self.base = np.concatenate([d.cov if d.cov is not None else np.broadcast_to(prior, (len(d), 3, 3))
                                    for d in data])
        self.group = np.concatenate([np.full(len(d), d.cov is not None) for d in data])
        self.factor = {g: 1.0 for g in np.unique(self.group).tolist()}
        self.estimated = len(self.factor) > 1      # two devices: each one's variance is estimated
        self.rounds = 0
        self._whiten()

    def _whiten(self) -> None:
        scale = np.array([self.factor[g] for g in self.group.tolist()])
        self.L = np.linalg.inv(np.linalg.cholesky(self.base * scale[:, None, None]))

    def apply(self, a: np.ndarray) -> np.ndarray:
        """Readings (n, 3) or their Jacobian (n, 3, p), whitened."""
        if not self.active:
            return a
        return np.einsum("nij,nj...->ni...", self.L, a)

    def rescale(self, r: np.ndarray, J: np.ndarray) -> bool:
        """New variance factors from the residual (whitened, flat) and Jacobian; True if
        they moved by more than 1 % and the fit should be redone."""
        if not self.estimated or self.rounds >= self.ROUNDS:
            return False
        self.rounds += 1
        Q, _ = np.linalg.qr(J)
        leverage = (Q**2).sum(axis=1).reshape(-1, 3).sum(axis=1)
        rr = (r.reshape(-1, 3) ** 2).sum(axis=1)
        moved = False
        for g in self.factor:
            at = self.group == g
            redundancy = 3 * at.sum() - leverage[at].sum()
            if redundancy <= 0:
                return False
            f = self.factor[g] * rr[at].sum() / redundancy
            moved |= abs(f / self.factor[g] - 1) > 0.01
            self.factor[g] = f
        self._whiten()
        return moved


def _gauss_newton(residual, jac, x, J, free, m):
    """Gauss–Newton with step halving, renewing the Jacobian only when it must.

    R-test errors are µm and µrad, so J changes by about 1e-5 of itself over a step and the
    first-order J still gains about five digits an iteration (the chord method): each
    iteration costs one model evaluation instead of 2p. J is renewed when the steps stop
    shrinking tenfold and once they stop; the steps then go on with the renewed J until
    they stop again, so the result satisfies the exact model's normal equations
    (J*ᵀr = 0, not only J₀ᵀr = 0) and the covariance uses J*. (A Levenberg–Marquardt
    safeguard was never needed: the problem is mildly non-linear and well started by the
    first-order solution.)
    """
    r = residual(x)
    cost = float(r @ r)
    converged_once, previous = False, np.inf
    for it in range(1, MAX_ITER + 1):
        dx = np.linalg.lstsq(J, r, rcond=None)[0]
        for _ in range(30):
            trial = x.copy()
            trial[free] += dx
            r_trial = residual(trial)
            new = float(r_trial @ r_trial)
            if new <= cost * (1 + 1e-12):
                break
            dx /= 2
        x, r, cost = trial, r_trial, new
        step = max(abs(shown(v, m.effects[i].unit)[0]) for i, v in zip(free, dx, strict=True))
        if step < STEP_TOL_SHOWN:
            if converged_once:    # J was computed within a few steps below 1e-5 µm of here
                return x, J, it
            J, converged_once, step = jac(x), True, np.inf
        elif step > 0.1 * previous:   # the held J no longer converges fast: renew it
            J, step = jac(x), np.inf
        previous = step
    raise CompgenError(f"the exact fit did not converge in {MAX_ITER} iterations",
                       hint="the errors may be too large for this model; try --method linear "
                            "to see the first-order estimate")


def check_identifiable(machine: Machine, m: Model, free: list[int], J: np.ndarray,
                       measured: Poses | None = None) -> None:
    """Refuse a rank-deficient or badly conditioned problem, naming what cannot be separated
    and which of the machine's paths, or a second ball position, not ``measured`` already,
    would separate it."""
    norm = np.linalg.norm(J, axis=0)
    names = [m.names[i] for i in free]
    dead = [names[k] for k in np.flatnonzero(norm == 0)]
    if dead:
        reversal = any(m.effects[free[k]].basis.kind == "r" for k in np.flatnonzero(norm == 0))
        raise CompgenError(f"{', '.join(dead)} do{'es' if len(dead) == 1 else ''} not change any "
                           f"reading on these poses", hint="fix it with --fix NAME=0 or measure a "
                           + ("path there and back (measure-program --there-and-back): a reversal "
                              "shows only where its axis turns back" if reversal else
                              "path that moves its axis"))
    _, s, Vt = np.linalg.svd(J / norm, full_matrices=False)
    weak = np.flatnonzero(s < s[0] / COND_LIMIT)
    if not weak.size:
        return
    combos = []
    for k in weak:
        v = Vt[k] / norm                  # a physical direction the readings do not see
        big = np.flatnonzero(np.abs(v * norm) >= 0.15 * np.abs(v * norm).max())
        scale = 1.0 / abs(shown(v[big[0]], m.effects[free[big[0]]].unit)[0])
        combos.append(" together with ".join(
            f"{names[j]} by {shown(v[j] * scale, m.effects[free[j]].unit)[0]:+.2f} "
            f"{shown(1, m.effects[free[j]].unit)[1]}" for j in big))
    # below 1e-12 of the largest, a singular value is rounding: the problem is singular
    cond = "singular" if s[-1] <= s[0] * 1e-12 else f"condition number {s[0] / s[-1]:.3g}"
    raise CompgenError(
        f"these data cannot separate the parameters ({cond}): moving "
        + "; or ".join(combos) + " changes the readings by less than 1/"
        + f"{COND_LIMIT:g} of the best-seen combination",
        hint=_separating_measurements(machine, m, free, J, measured) +
             "; or hold one parameter of each combination with --fix NAME=VALUE")


def _separating_measurements(machine: Machine, m: Model, free: list[int], J: np.ndarray,
                             measured: Poses | None) -> str:
    advisor = Advisor(machine, measured)
    options = []
    for i, extra in enumerate(advisor.candidates):    # the ball as it stands first, then moved
        cond = condition(np.vstack([J, m.jacobian(extra.poses)[:, :, free].reshape(-1, len(free))]))
        if cond < COND_LIMIT:
            options.append((round(cond), i, extra.label, extra))
    runnable = advisor.runnable([o[-1] for o in sorted(options, key=lambda o: o[:2])], most=3)
    if not runnable:
        return "no single path or ball position of the machine file separates them"
    cond = {o[2]: o[0] for o in options}
    best = ", ".join(f"{m.label} (condition {cond[m.label]:.0f})" for m in runnable)
    return f"adding one of these measurements would: {best}"


def residual_stats(poses: Poses, r: np.ndarray, dof: int) -> dict:
    """RMS and ISO 10791-6 style range per path and per direction, µm; r (n, 3) mm."""
    r_um = r * 1e3
    per_path = {}
    for label in dict.fromkeys(poses.path):
        rp = r_um[poses.path == label]
        per_path[label or "(unlabelled)"] = {
            "n": int(len(rp)), "rms_um": np.sqrt((rp**2).mean(axis=0)).tolist(),
            "range_um": (rp.max(axis=0) - rp.min(axis=0)).tolist(),
            "max_abs_um": np.abs(rp).max(axis=0).tolist()}
    return {"rms_um": float(np.sqrt((r_um**2).mean())),
            "sigma_um": float(np.sqrt((r_um**2).sum() / dof)),
            "readings": int(r.size), "dof": int(dof),
            "per_direction_rms_um": dict(zip(("dX", "dY", "dZ"),
                                             np.sqrt((r_um**2).mean(axis=0)).tolist(), strict=True)),
            "per_path": per_path}


def _absolute(path: str) -> str:
    """Where later commands (diagnose, kinematics) find the file again, whatever their cwd."""
    return str(Path(path).resolve()) if path else path


def _counts(labels: np.ndarray) -> dict[str, int]:
    return {str(k) or "(unlabelled)": int((labels == k).sum()) for k in dict.fromkeys(labels)}


def parse_fixed(machine: Machine, items: Sequence[str]) -> dict[str, float]:
    """``["ZOW=0", "BOA=12.3arcsec"]`` → {name: value in mm or rad}."""
    out = {}
    for item in items:
        name, eq, value = item.partition("=")
        if not eq:
            raise CompgenError(f"--fix takes NAME=VALUE, not {item!r}", hint="e.g. --fix ZOW=0")
        effect = effect_of_param(machine, name.strip())
        out[canonical(name)] = parse_quantity(value, effect.unit, where=f"--fix {item}")
    return out
