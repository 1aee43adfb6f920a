"""Identification: first-order least squares (the seed's method), then Gauss–Newton on the
exact model, with uncertainties from the residual and the Jacobian, and an identifiability
check that refuses what the data cannot separate.

References: seed report §3 (eq. 26); ``shared/research/identification.md`` §1.9 and §3.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .. import __version__
from ..data.rtest import Measurements, RTestData, refuse_twice
from ..errors import CompgenError
from ..model.effects import canonical, effect_of_param, location_model
from ..model.kinematics import Model
from ..model.machine import Machine
from ..model.poses import Poses, runs
from ..model.sides import NEST, SETUP, FreeConstants, both_sides, continues, set_ups
from ..units import parse_quantity, shown
from .noise import Lazy, Span, ar1, ar1_covariance
from .results import DataRef, Estimate, FitResult
from .significance import COND_LIMIT, condition, tall_qr

MAX_ITER = 30
STEP_TOL_SHOWN = 1e-7     # µm or arcsec: Gauss–Newton has converged below this step


def identify(machine: Machine, data: Sequence[RTestData], model: Sequence[str] | None = None,
             fixed: Mapping[str, float] | None = None, method: str = "exact",
             sign: str = "nest-minus-ball", advisor=None) -> FitResult:
    """Identify the parameters of ``model`` from R-test data.

    Parameters
    ----------
    model : parameter names; default the seed's 11 generalised (``location_model``)
    fixed : name → value (mm, rad) held fixed; names not in ``model`` are added to it
    method : ``"exact"`` (first-order start, then Gauss–Newton on the exact model) or
        ``"linear"`` (first-order only, as the seed)
    advisor : what makes the measurements a machine can add, ``advisor(machine, measured)``
        with ``.candidates`` and ``.runnable(ms, most)`` (``advice.Advisor``, which writes and
        checks their programs: the controllers' layer, so the caller passes it in). With it, a
        refusal names those that would separate what these data cannot.
    """
    if method not in ("exact", "linear"):
        raise CompgenError(f"method must be 'exact' or 'linear', not {method!r}")
    if not data:
        raise CompgenError("no data to fit")
    refuse_twice(data)
    fixed = dict(fixed or {})
    names = list(model or location_model(machine))
    names += [n for n in fixed if n not in names]
    m = Model(machine, names)
    free = [i for i, n in enumerate(names) if n not in fixed]
    if not free:
        raise CompgenError("every parameter is fixed: nothing to fit")
    joined = Measurements.concat(data)
    poses, y = joined.poses, joined.deviation
    readings, p = y.size, len(free)
    _enough(poses, readings, p)

    x = np.array([fixed.get(n, 0.0) for n in names])
    weights = Weights(data)
    # where the data do not say which side a path started on, one free constant per path
    # (``FreeConstants``), projected out of readings and Jacobian alike: the joint fit's
    # estimates without carrying the constants (Frisch–Waugh–Lovell)
    starts = FreeConstants(machine, names, poses)
    constants = starts.projector(weights.apply_at)
    project = constants or (lambda v: v)
    _enough(poses, readings, p, starts)

    buffer = np.empty((len(names), len(poses), 3))

    def linearise(x):
        """The raw residual (n, 3) mm, and the whitened residual and Jacobian of the free
        parameters (flat), from one walk of the model's chains. The Jacobian lives in
        ``buffer``: each call overwrites the last one's, which is never used again."""
        dev, J = m.linearise(poses, x, out=buffer)
        raw = y - dev
        J = project(weights.apply(J if len(free) == len(names) else J[:, :, free]))
        return Step(raw, project(np.array(weights.apply(raw))).ravel(),     # a copy: raw stays raw
                    Normal(np.moveaxis(J, 2, 0).reshape(p, readings).T))

    def solve(x, at):
        # first order about here (seed eq. 26): y − dev(x) ≈ J Δa
        x = x.copy()
        x[free] += at.normal.solve(at.r)
        at, iterations = linearise(x), 0
        if method == "exact":
            x, at, iterations = _gauss_newton(linearise, x, at, free, m)
        return x, at, iterations

    at = linearise(x)
    check_identifiable(machine, m, free, at.normal, poses, advisor)
    x, at, iterations = solve(x, at)
    # devices of unknown relative noise: their variances are estimated with the fit
    while weights.estimated and weights.rescale(at.r, at.normal):
        x, at, more = solve(x, linearise(x))
        iterations += more

    raw, r, normal = at
    if starts.count:            # the residual the joint fit leaves, constants fitted
        raw = project.remove(raw, weights.apply(raw))
    dof = readings - p - (constants.rank if constants is not None else 0)
    sigma2 = float(r @ r) / dof
    std, corr, sv, rho = _uncertainty(poses, data, project, starts, normal, r, dof, sigma2, p)
    return _fit_result(machine, data, m, names, free, x, (std, corr, sv),
                       residual_stats(poses, raw, dof, rho), method, iterations, sign, starts.mounts)


def _fit_result(machine: Machine, data: Sequence[RTestData], m: Model, names: list[str], free: list[int],
                x: np.ndarray, spread: tuple, residual: dict, method: str, iterations: int, sign: str,
                mounts: int) -> FitResult:
    """The fit as fit.json keeps it: each parameter's value and σ (a fixed one's σ 0), their
    correlation and singular values (``spread``), what was fitted to what, and how."""
    std, corr, sv = spread
    params = {}
    for i, n in enumerate(names):
        e = m.effects[i]
        k = free.index(i) if i in free else None
        params[n] = Estimate(float(x[i]), 0.0 if k is None else float(std[k]), e.unit, k is None)
    return FitResult(
        machine={"name": machine.name, "file": machine.bundled or _absolute(machine.source),
                 "sha256": machine.sha256, **({"bundled": True} if machine.bundled else {})},
        data=tuple(DataRef(_absolute(d.source), d.sha256, len(d), _counts(d.poses.path), d.device, d.said,
                     d.turned)
                   for d in data),
        model=tuple(names), parameters=params, free=tuple(names[i] for i in free),
        correlation=np.clip(corr, -1.0, 1.0), singular_values=sv,
        residual=residual,
        method=method, iterations=iterations, sign=sign, version=__version__,
        descriptions={n: e.words + (f", at the first of the ball's {mounts + 1} mountings"
                                    if mounts and n in SETUP else "")
                      for n, e in zip(names, m.effects, strict=True)})


def _uncertainty(poses: Poses, data: Sequence[RTestData], project, starts: FreeConstants, normal: Normal,
                 r: np.ndarray, dof: int, sigma2: float, p: int) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                          np.ndarray]:
    """Each estimate's σ, their correlation, the singular values, and the noise's AR(1) ρ
    per run and direction."""
    # readings taken close together (an R-test sampling at 100 Hz, or a set-up drifting
    # between poses) are not independent: the noise's AR(1) ρ of each run and direction
    # from the residual (``noise.ar1``: zero unless significant), and where it is not zero
    # the estimates' covariance under that noise; white noise keeps σ²(JᵀJ)⁻¹
    seg = runs(poses, np.concatenate([np.full(len(d), k) for k, d in enumerate(data)]))
    # what the fit took out of r (its start sides, J's span): ρ̂ is matched beyond it
    basis = Lazy(starts.count + p, lambda: (*((project.basis(len(poses)),) if starts.count else ()),
                                              normal.basis()))
    rho = ar1(r.reshape(-1, 3), seg, basis)
    if rho.any():
        cov = ar1_covariance(normal.J.T.reshape(p, len(poses), 3), r.reshape(-1, 3), seg, rho, dof)
    else:
        cov = normal.inverse() * sigma2
    std = np.sqrt(np.diag(cov))
    corr = cov / np.outer(std, std) if np.all(std > 0) else np.eye(p)
    sv = normal.singular_values()

    return std, corr, sv, rho


def _enough(poses: Poses, readings: int, p: int, free: FreeConstants | None = None) -> None:
    """Refuse readings too few for ``p`` parameters (and the ``free`` constants beside them)."""
    count = free.count if free is not None else 0
    if readings <= p + count:
        ball, nest = (free.ball * free.mounts, len(NEST) * free.nests) if count else (0, 0)
        parts = [f"{len(free.labels)} start sides" if count and free.labels else "",
                 f"{ball} offsets of the ball's {free.mounts} later mountings" if ball else "",
                 f"{nest} offsets of {free.nests} later nests" if nest else ""]
        moves = [w for w, k in (("ball position (bx, by, bz)", ball), ("nest length", nest)) if k]
        raise CompgenError(
            f"{len(poses)} poses give {readings} readings for {p} parameters"
            + (f" and {count} free constants ({', '.join(filter(None, parts))})" if count else ""),
            hint=f"each change of the {' or '.join(moves)} between readings is a mounting with an offset "
                 f"of its own: give the rows of one mounting one {' and one '.join(moves)}" if moves
            else "measure more poses: a K4 path has 241")


def fitted(machine: Machine, fit: FitResult, data: Sequence[RTestData]) -> np.ndarray:
    """The readings (n, 3) mm the fit's model gives at the data's poses, with each path's
    start side where the data do not record it (``FreeConstants``, fitted to these readings as
    ``identify`` fits them; readings unweighted): what the fit's residual is taken from."""
    joined = Measurements.concat(data)
    poses, y = joined.poses, joined.deviation
    dev = fit.evaluate(machine, poses)
    starts = FreeConstants(machine, fit.model, poses).projector()
    return dev if starts is None else y - starts.remove(y - dev)


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
        joined = Measurements.concat(data)
        self.base, self.group = joined.covariance(prior), joined.cov_known
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

    def apply_at(self, idx: np.ndarray, a: np.ndarray) -> np.ndarray:
        """``apply`` for the rows ``idx`` of the readings only: ``a`` is (len(idx), 3, …)."""
        if not self.active:
            return a
        return np.einsum("nij,nj...->ni...", self.L[idx], a)

    def rescale(self, r: np.ndarray, normal: Normal) -> bool:
        """New variance factors from the residual (whitened, flat) and the Jacobian's normal
        equations; True if they moved by more than 1 % and the fit should be redone."""
        if not self.estimated or self.rounds >= self.ROUNDS:
            return False
        self.rounds += 1
        # each reading's leverage: the diagonal of J (JᵀJ)⁻¹ Jᵀ
        leverage = np.einsum("ij,ij->i", normal.J @ normal.inverse(), normal.J).reshape(-1, 3).sum(axis=1)
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


class Normal:
    """A Jacobian J (readings, p; best column-major) and its normal equations, formed once:
    a dense session's J is 10⁶ rows of a few columns, where an SVD or QR costs seconds and
    JᵀJ milliseconds. Columns are scaled to unit norm first, so the Gram matrix's condition
    is that of the scaled J squared — at most COND_LIMIT² where a fit goes on (a solve
    exact to ~1e-12) — and a Gauss–Newton step corrects what little a solve leaves. The
    exact singular values come from J itself only on the way to a refusal."""

    def __init__(self, J: np.ndarray):
        self.J = J
        self.norm = np.sqrt(np.einsum("ij,ij->j", J, J))
        self.scale = np.where(self.norm > 0, self.norm, 1.0)      # a dead column stays 0
        self.G = (J.T @ J) / np.outer(self.scale, self.scale)

    def solve(self, r: np.ndarray) -> np.ndarray:
        """The least-squares step: argmin |J dx − r|."""
        return np.linalg.solve(self.G, (self.J.T @ r) / self.scale) / self.scale

    def inverse(self) -> np.ndarray:
        """(JᵀJ)⁻¹."""
        return np.linalg.inv(self.G) / np.outer(self.scale, self.scale)

    def basis(self) -> Span:
        """Orthonormal columns spanning J's: J's unit-norm columns times L⁻ᵀ, L the Cholesky
        factor of their Gram matrix, held as J and that factor (``noise.Span``: never
        multiplied out, where a QR of J makes three matrices of its size: 630 MB more of
        fit's peak at 723 000 readings); a QR where G is singular."""
        try:
            L = np.linalg.cholesky(self.G)
        except np.linalg.LinAlgError:
            Q = tall_qr(self.J)[0]
            return Span(Q, np.eye(Q.shape[1]))
        return Span(self.J, np.linalg.inv(L).T / self.scale[:, None])

    def singular_values(self) -> np.ndarray:
        """Singular values of J with unit-norm columns, largest first, from JᵀJ: exact to
        ~1e-8 of the largest (an SVD of J itself, for a refusal, in ``check_identifiable``)."""
        return np.sqrt(np.clip(np.linalg.eigvalsh(self.G), 0.0, None))[::-1]


class Step(NamedTuple):
    """The fit at one point: the raw residual (n, 3) mm, the whitened residual (flat) and
    the normal equations of the whitened Jacobian of the free parameters."""

    raw: np.ndarray
    r: np.ndarray
    normal: Normal


def _gauss_newton(linearise, x, at, free, m):
    """Gauss–Newton on the exact model, with step halving.

    Each iteration walks the model's chains once (``Model.linearise``: the exact residual
    and the exact analytic Jacobian together), so it converges quadratically: R-test errors
    are µm and µrad, the first-order start is within ~1e-5 of the answer and two steps
    later the step is below STEP_TOL_SHOWN. The result satisfies the exact model's normal
    equations (J*ᵀr = 0) to that step, and the covariance uses J* there. (A
    Levenberg–Marquardt safeguard was never needed: the problem is mildly non-linear and
    well started by the first-order solution.) At the minimum the cost's rounding (1e-11 of it
    on a small probe session) can exceed what a step just above the tolerance lowers it by:
    where halving finds no lower cost before the step is below the tolerance, the fit has
    converged (it had gone on to MAX_ITER and refused 4 of 100 such sessions).
    """
    def size(dx):
        return max(abs(shown(v, m.effects[i].unit)[0]) for i, v in zip(free, dx, strict=True))

    cost = float(at.r @ at.r)
    for it in range(1, MAX_ITER + 1):
        dx = at.normal.solve(at.r)
        if size(dx) < STEP_TOL_SHOWN:
            return x, at, it - 1
        for _ in range(30):
            trial = x.copy()
            trial[free] += dx
            at_trial = linearise(trial)
            new = float(at_trial.r @ at_trial.r)
            if new <= cost * (1 + 1e-12):
                break
            dx /= 2
            if size(dx) < STEP_TOL_SHOWN:      # no step the tolerance counts lowers the cost
                return x, at, it - 1
        x, at, cost = trial, at_trial, new
    raise CompgenError(f"the exact fit did not converge in {MAX_ITER} iterations",
                       hint="the errors may be too large for this model; try --method linear "
                            "to see the first-order estimate")


def check_identifiable(machine: Machine, m: Model, free: list[int], J: np.ndarray | Normal,
                       measured: Poses | None = None, advisor=None) -> None:
    """Refuse a rank-deficient or badly conditioned problem, naming what cannot be separated
    and, with an ``advisor`` (``identify``'s), which of the machine's paths, or a second ball
    position, not ``measured`` already, would separate it."""
    normal = J if isinstance(J, Normal) else Normal(J)
    J, norm = normal.J, normal.norm
    names = [m.names[i] for i in free]
    dead = [names[k] for k in np.flatnonzero(norm == 0)]
    if dead:
        reversal = any(m.effects[free[k]].basis.kind == "r" for k in np.flatnonzero(norm == 0))
        raise CompgenError(f"{', '.join(dead)} do{'es' if len(dead) == 1 else ''} not change any "
                           f"reading on these poses", hint="fix it with --fix NAME=0 or measure a "
                           + ("path there and back (measure-program --there-and-back): a reversal "
                              "shows only where its axis turns back" if reversal else
                              "path that moves its axis"))
    s = normal.singular_values()
    if s[-1] >= 1.01 * s[0] / COND_LIMIT:     # clear of the limit: JᵀJ's rounding cannot matter
        return
    _, s, Vt = np.linalg.svd(J / norm, full_matrices=False)
    weak = np.flatnonzero(s < s[0] / COND_LIMIT)
    if not weak.size:
        return
    combos = []
    for v in _sparse_basis(Vt[weak]) / norm:   # physical directions the readings do not see
        big = np.flatnonzero(np.abs(v * norm) >= 0.15 * np.abs(v * norm).max())
        scale = 1.0 / shown(v[big[0]], m.effects[free[big[0]]].unit)[0]    # the first named: +1
        combos.append(" together with ".join(
            f"{names[j]} by {shown(v[j] * scale, m.effects[free[j]].unit)[0]:+.2f} "
            f"{shown(1, m.effects[free[j]].unit)[1]}" for j in big))
    # below 1e-12 of the largest, a singular value is rounding: the problem is singular
    cond = "singular" if s[-1] <= s[0] * 1e-12 else f"condition number {s[0] / s[-1]:.3g}"
    raise CompgenError(
        f"these data cannot separate the parameters ({cond}): moving "
        + "; or ".join(combos) + " changes the readings by less than 1/"
        + f"{COND_LIMIT:g} of the best-seen combination",
        hint=("" if advisor is None else _separating_measurements(machine, m, free, J, measured, advisor(
            machine, measured)) + "; or ") + "hold one parameter of each combination with --fix NAME=VALUE")


def _sparse_basis(V: np.ndarray) -> np.ndarray:
    """Rows spanning the same space as the orthonormal rows ``V``, each with as few
    parameters as elimination allows (reduced row echelon form, largest pivot first): a
    space of several unseen combinations has no preferred orthonormal basis (an exactly
    singular one is rotated by rounding), while the pairs a machine builder recognises —
    YOW with COA, BOA with BOC — are each one row here."""
    V = V.copy()
    for row in range(len(V)):
        col = int(np.argmax(np.abs(V[row:]).max(axis=0)))
        pivot = row + int(np.argmax(np.abs(V[row:, col])))
        V[[row, pivot]] = V[[pivot, row]]
        V[row] /= V[row, col]
        others = np.arange(len(V)) != row
        V[others] -= np.outer(V[others, col], V[row])
    V[np.abs(V) < 1e-9] = 0.0
    return V


def _separating_measurements(machine: Machine, m: Model, free: list[int], J: np.ndarray,
                             measured: Poses | None, advisor) -> str:
    if advisor.unable:
        return advisor.unable
    options = []
    # a reversal seen from one side only is its axis's zero offset, not its backlash
    reversals = {m.effects[j].carrier for j in free if m.effects[j].basis.kind == "r"}
    for i, extra in enumerate(advisor.candidates):    # the ball as it stands first, then moved
        if measured is not None and not all(both_sides(machine, a, measured, extra.poses) for a in reversals):
            continue
        cond = condition(_with_extra(machine, m, free, J, measured, extra.poses))
        if cond < COND_LIMIT:
            options.append((round(cond), i, extra.label, extra))
    runnable = advisor.runnable([o[-1] for o in sorted(options, key=lambda o: o[:2])], most=3)
    if not runnable:
        return "no single path or ball position of the machine file separates them"
    cond = {o[2]: o[0] for o in options}
    best = ", ".join(f"{m.label} (condition {cond[m.label]:.0f})" for m in runnable)
    return f"adding one of these measurements would: {best}"


def _with_extra(machine: Machine, m: Model, free: list[int], J: np.ndarray, measured: Poses | None,
                poses: Poses) -> np.ndarray:
    """The free parameters' Jacobian ``J`` (3n, p) of the ``measured`` poses, as the fit
    takes it (each later mounting's and nest's offset projected out, ``FreeConstants``),
    with the rows of an extra measurement at ``poses`` as the fit would add them: where the
    ball must be mounted again for it (another position), or another nest put in, less what
    that mounting's own offset fits. One that continues a later mounting or nest shares its
    offset with the data's rows of it: then the whole is taken again, unweighted, as the
    fit would take the data with it."""
    jac = m.jacobian(poses)
    rows = jac[:, :, free].reshape(-1, len(free))
    at = [m.names.index(n) for n in SETUP if n in m.names]
    if measured is None:                # where the ball stood is not known: mounted again
        same_ball, same_nest, later = False, True, (0, 0)
    else:
        same_ball, same_nest = continues(machine, measured, poses)
        later = tuple(int(k[-1]) for k in set_ups(machine, measured)) \
            if at else (0, 0)                # no ball offset in the model: no set-up's constants
    if (same_ball and later[0]) or (same_nest and later[1]):
        both = Poses.concat([measured, poses.with_setup(int(measured.setup[-1]))])   # it continues
        whole = m.jacobian(both)
        project = FreeConstants(machine, m.names, both).projector()
        return (whole if project is None else project(whole))[:, :, free].reshape(-1, len(free))
    offsets = ([jac[:, :, at].reshape(-1, len(at))] if at and not same_ball else []) \
        + ([Model(machine, NEST).jacobian(poses).reshape(-1, len(NEST))] if at and not same_nest else [])
    if offsets:
        B = np.hstack(offsets)
        rows = rows - B @ np.linalg.lstsq(B, rows, rcond=None)[0]
    return np.vstack([J, rows])


def residual_stats(poses: Poses, r: np.ndarray, dof: int, rho: np.ndarray | None = None) -> dict:
    """RMS and ISO 10791-6 style range per path and per direction, µm; r (n, 3) mm. With
    the noise's AR(1) ρ of each reading (n, 3), the largest of each path's runs too, and
    which noise the uncertainties assume."""
    r_um = r * 1e3
    per_path = {}
    for label in dict.fromkeys(poses.path):
        at = poses.path == label
        rp = r_um[at]
        per_path[label or "(unlabelled)"] = {
            "n": int(len(rp)), "rms_um": np.sqrt((rp**2).mean(axis=0)).tolist(),
            "range_um": (rp.max(axis=0) - rp.min(axis=0)).tolist(),
            "max_abs_um": np.abs(rp).max(axis=0).tolist(),
            **({"ar1_rho": rho[at].max(axis=0).round(3).tolist()} if rho is not None else {})}
    return {**({"noise": "ar1" if rho.any() else "white"} if rho is not None else {}),
            "rms_um": float(np.sqrt((r_um**2).mean())),
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


def mountings_note(machine: Machine, names: Sequence[str], *poses: Poses) -> str | None:
    """What a fit of ``names`` reports of a ball mounted more than once, or of more than one
    nest, said once, or None: the first ball mounting's offset (``SETUP``); each later
    mounting and each later nest has an offset of its own, fitted beside the parameters and
    not reported (``sides.FreeConstants``)."""
    held = [n for n in SETUP if n in names]
    ball = np.concatenate([p.ball for p in poses])
    if not held or not len(ball):       # no ball offset in the model: no set-up's constants
        return None
    joined = Poses.concat(poses)
    mount, nests = (int(k[-1]) for k in set_ups(machine, joined))
    again = " or where it was said mounted again" if joined.setup.any() else ""
    said = []
    if mount:
        said.append(f"the ball at {mount + 1} mountings (a new one wherever its position changes{again})")
    if nests:
        said.append(f"{nests + 1} nests (a new one wherever the nest's length changes{again})")
    if not said:
        return None
    first = ball[0]
    return (f"these data hold {' and '.join(said)}: each later one's offset is fitted beside the "
            "parameters and not reported" + (f"; {' '.join(held)} are the first's (ball at {first[0]:g}, "
                                             f"{first[1]:g}, {first[2]:g} mm)" if mount else ""))


def beyond_setup(machine: Machine, poses: Poses, reading: np.ndarray) -> dict:
    """RMS and per-path figures of ``reading`` (n, 3) mm beyond the set-up terms alone:
    what an edit leaves, or a check measures, whatever the ball's offset at each of its
    mountings (``mountings``: a ball moved is a ball mounted again).

    ``identify``'s fit of XOW YOW ZOW (each later mounting's, and each later nest's offset,
    projected out as ``identify`` does: ``FreeConstants``), in closed form: the ball's
    offset is a translation at the workpiece chain's end, turned by the frames before it,
    so the readings are exactly linear in it and one walk of the chains gives the answer
    Gauss–Newton converges to in three; the same refusal, the same residual figures and ρ̂
    (``tests/reports/test_compare.py``)."""
    free = FreeConstants(machine, SETUP, poses)       # each later ball's and nest's offset
    _enough(poses, reading.size, len(SETUP))
    _enough(poses, reading.size, len(SETUP), free)     # as identify refuses
    m = Model(machine, list(SETUP))
    dev, J = m.linearise(poses)
    raw = reading - dev
    project = free.projector()
    if project is not None:
        J, raw = project(J), project(raw)
    normal = Normal(np.moveaxis(J, 2, 0).reshape(len(SETUP), -1).T)
    check_identifiable(machine, m, list(range(len(SETUP))), normal, poses)
    raw = raw - (normal.J @ normal.solve(raw.ravel())).reshape(-1, 3)
    taken = (*((project.basis(len(poses)),) if project is not None else ()), normal.basis())
    rho = ar1(raw, runs(poses), taken)
    dof = reading.size - len(SETUP) - (project.rank if project is not None else 0)
    stats = residual_stats(poses, raw, dof, rho)
    return {"rms_um": stats["rms_um"], "per_path": stats["per_path"]}
