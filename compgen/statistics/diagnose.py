"""Where the model fails, and which physical effect would explain it.

For every catalogue effect not in the model: its first-order signature c on the measured
poses (``signature.py``), the part c⊥ that the model's parameters cannot absorb, the
residual sum of squares it would remove, an F test, and Bonferroni's correction for the
number of effects tried (``significance.py``). An effect whose signature the model absorbs
entirely (‖c⊥‖/‖c‖ below ``VISIBLE``), or that ``fit --add`` would refuse on these data
(one rule: ``significance.condition``), is never "found": it is reported with the
measurement that would separate it, and only measurements the machine can make are named
(an advisor the caller passes in: ``advice.Advisor``, which writes and checks their
programs). The words are ``diagnose_text.py``'s.

References: ``docs/diagnose.md`` (visibility, bias, F and score tests).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np

from ..data.rtest import Measurements, RTestData
from ..errors import CompgenError
from ..model.effects import IN_TIME, Effect, catalogue, effect_of_param, one_error_in_time, resolve
from ..model.frames import sensor_axes
from ..model.kinematics import Model
from ..model.machine import Machine
from ..model.poses import Poses, runs
from ..model.sides import FreeConstants, same_pose
from ..units import shown
from .advising import Advising, Proposal
from .device import (
    TRIGGER,
    blamed_device,
    device_columns,
    form_columns,
    tested_devices,
    told_beside,
    trigger_columns,
)
from .diagnosis import REPEATS_TRIED, Candidate, Diagnosis, _outside_line, _unexplained, turn_for
from .noise import Lazy, ar1, outliers, repeats
from .ranking import Row, Whitening, effect_columns, rank, started_reversals
from .results import FitResult
from .separation import Measured, separating, telling_apart
from .setup_step import setup_step
from .signature import products
from .significance import (
    ALPHA,
    MARGINAL,
    VISIBLE,
    beside,
    lack_of_fit,
    p_value,
    paired,
    rival_margin,
    rivals,
    still_significant,
    tall_qr,
)
from .spectrum import strongest_lines
from .timeconstant import refined

# Beyond this many poses the first pass carries the best it expects, found on about this
# many of them: step 5 then needs no pass of its own (5 of 27 s at 720 000 readings)
SCREEN_POSES = 20_000
# The tests whiten at ρ̂ plus this many of its standard errors: a ρ̂ below ρ leaves the low
# frequencies a smooth candidate lives in louder than the rest (((1 − ρ̂)/(1 − ρ))², 1.2 at
# one s.e. for ρ 0.9 on K4 + K1 + K2), one above quieter, and the family's tail is convex in
# that: at ρ̂ itself 10 of 200 clean AR(1) ρ 0.9 sessions were flagged, at ρ 3 (α 0.01)
RHO_MARGIN_SE = 1.0
# The second effects a gain is told beside, strongest first, as poses × effects walked: each
# takes a walk of the poses (0.3–1 s at 241 000 poses, where this allows 8; on a K4 + K1 + K2
# of 723 poses, 2766). Where more stay significant, no gain is judged in that round: it is
# told, never called significant
SECOND_WALKS = 2_000_000
PAIRED = 8               # second effects a misfit-left rival is paired with


@dataclass(frozen=True, eq=False)
class _Residual:
    """The fit's residual on its data without the outlying readings (step 1): the poses, the
    runs they form, the residual r (3n,) beyond the model's span and its start sides, and
    the Q (start sides first) and R of the model's Jacobian."""

    poses: Poses
    seg: np.ndarray
    r: np.ndarray
    r3: np.ndarray      # (n, 3) the residual as the fit left it (before Q's projection)
    pred: np.ndarray    # (n, 3) the fit's prediction of the readings
    rtest: np.ndarray   # (n,) the reading is an R-test's (not a probe's sphere centre)
    axes: np.ndarray | None   # (n, 3, 3) the nest's sensor axes where a head turns them, else None
    Q: np.ndarray
    R: np.ndarray
    bad: np.ndarray
    size: np.ndarray

    @property
    def rss(self) -> float:
        return float(self.r @ self.r)

    @property
    def dof(self) -> int:
        return self.r.size - self.Q.shape[1]


def diagnose(machine: Machine, data: Sequence[RTestData], fit: FitResult,
             candidates: Sequence[str] | None = None, alpha: float = ALPHA,
             fit_file: str = "", advisor: Callable[..., Advising] | None = None,
             noise_um: float | None = None) -> Diagnosis:
    """Rank the effects not in ``fit``'s model by how much of its residual they explain.

    Outlying readings are listed and left out; the tests are made on the readings made white
    by their segments' AR(1) correlation (``noise.py``), estimated from the residual once the
    best candidate is added (the misfit of a missing effect is not noise). With an
    ``advisor`` (``advisor(machine, poses, device, runs)``: ``advice.Advisor``), the measurements
    that would separate what these data cannot are searched for among those the machine can
    make (each names the machine file as its command prints it). ``noise_um`` is the R-test's
    own noise (default: the machine file's ``[rtest] noise_um``): with it,
    the residual is tested against it per path and direction, and what no catalogue effect
    accounts for is called unexplained."""
    joined = Measurements.concat(data)
    kind = joined.device
    device, device_dof = _device_noise(machine, joined, noise_um)
    res = _residual(machine, joined, fit)
    poses, r, rss, dof = res.poses, res.r, res.rss, res.dof
    # no noise given: what the data repeat says it, where they repeat enough
    said = repeats(same_pose(machine, poses, res.seg), res.r3, res.seg) if device is None else None
    device, device_dof = (said.sigma_um, said.dof) if said is not None else (device, device_dof)

    effects, notes = _to_try(machine, fit, candidates, poses)
    effects, ranked, noise, made, carried = _ranked(machine, fit, effects, res, alpha)
    rss_w = noise.rss(r)
    # the device (the R-test's sensors, the ball's form) beside the machine, in one Bonferroni family
    columns = (device_columns(res.pred, res.rtest, res.axes) | trigger_columns(joined.lobes, res.bad)
               | form_columns(machine, poses, res.rtest, res.axes))      # the sensors' axes walked once
    devices, tested = tested_devices(res, columns, ranked, noise, rss_w, dof, alpha)
    out = _candidates(effects, ranked, rss, r.size, rss_w, dof, tested, alpha)
    model_effects = list(dict.fromkeys(effect_of_param(machine, n) for n in fit.free))
    advising = advisor(machine, poses, kind, res.seg) if advisor is not None else None
    if advising is not None and advising.unable:      # said, never taken for "none would tell"
        notes, advising = (*notes, f"  {advising.unable}."), None
    bias, units, signature_um = _bias(fit, res, effects, ranked)

    significant = [c for c in out if c.significant]
    best = ranked[significant[0].effect] if significant else None
    step = setup_step(machine, res.poses, np.delete(joined.set_of, res.bad), joined.sets, res.r, noise,
                      (best.drop_w, best.k_eff) if best is not None else None, rss_w, dof, alpha)
    # the best machine effect's whitened columns: its rivals and second effects are tested
    # beside it, and so are the gains with them
    first = noise.white(_columns(machine, res, made, significant[0].effect)) if significant else None
    blamed, form_rival = blamed_device(devices, best, rss_w / dof, alpha)
    turned, spun = _turns(advising, poses, joined, form_rival, blamed)
    if blamed is not None:
        devices = told_beside(devices, columns, np.empty((r.size, 0)), res, noise, alpha, blamed)
    seen = [d for d in devices if d.significant]
    best_sum_sq = max([ranked[c.effect].drop for c in significant[:1]] + [d.drop for d in seen], default=0.0)
    misfit, share = _misfit(res, noise, device, best_sum_sq, alpha, device_dof)
    lines = strongest_lines(machine, poses, r.reshape(-1, 3), res.Q)
    unexplained = _unexplained(misfit, bool(significant or seen), share,
                               _outside_line(lines, device, misfit, alpha, best_sum_sq))

    # rivals of a curve that fits a little of an unexplained misfit by chance: not pursued
    rival = _rivals(machine, res, [] if unexplained else significant, first, out, ranked, noise, made,
                    carried, alpha)
    out, rival = _advised(machine, res, out, ranked, rival, model_effects, advising, alpha)
    if blamed is None and first is not None:     # beside the machine's best and its second effects
        told = max(1, SECOND_WALKS // len(poses))
        seconds = [noise.white(_columns(machine, res, made, e)) for e in rival["after_best"][:told]]
        devices = told_beside(devices, columns, np.column_stack([first, *seconds]), res, noise,
                               alpha if len(rival["after_best"]) <= told else 0.0)
    return Diagnosis(
        machine=machine.name, fit_file=fit_file, model=fit.model,
        rms_um=float(np.sqrt(rss / r.size)) * 1e3, sigma_um=float(np.sqrt(rss / dof)) * 1e3,
        readings=int(r.size), per_path=fit.residual["per_path"],
        per_axis=_per_axis(machine, poses, r.reshape(-1, 3)),
        candidates=tuple(out), bias=bias, bias_units=units, signature_um=signature_um,
        tested=tested, alpha=alpha, **rival,
        carries=_carries(fit, out, ranked, rival["rivals"]),
        outliers=_outlier_rows(data, res.bad, res.size), noise=_noise_summary(res.seg, noise.rho, poses.path),
        searched=advising is not None, device_noise_um=device,
        repeats=said, misfit=misfit,
        lines=lines, best_share_of_excess=share, best_sum_sq=best_sum_sq, notes=notes,
        data_device=kind, devices=tuple(devices), device_blamed=blamed, form_rival=form_rival,
        form_turned=turned, probe_turned=spun, setup_step=step)


def _candidates(effects: Sequence[Effect], ranked: dict[str, Row], rss: float, readings: int, rss_w: float,
                dof: int, tested: int, alpha: float) -> list[Candidate]:
    """Step 4: each effect tried as a candidate, its p in the family of ``tested``, the
    visible ones first, most of the residual removed first."""
    out = []
    for e in effects:
        row = ranked[e.name]
        p = p_value(row.drop_w, row.k_eff, rss_w, dof, tested) if row.k_eff else 1.0
        out.append(Candidate(
            effect=e.name, description=e.words, cause=e.cause, visibility=row.vis,
            rms_after_um=float(np.sqrt(max(rss - row.drop, 0.0) / readings)) * 1e3, p_value=p,
            significant=bool(row.k_eff and p < alpha), confounded_with=row.names,
            amplitude=tuple(shown(a, e.unit)[0] for a in row.amp), unit=shown(1.0, e.unit)[1],
            silent=row.silent, share=row.share, condition=row.cond))
    out.sort(key=lambda c: (not c.visible, -c.share))
    return out


def _device_noise(machine: Machine, joined: Measurements, noise_um: float | None
                  ) -> tuple[float | None, int | None]:
    """The device's noise (µm) and the degrees of freedom it is estimated with (None: known,
    as given by --noise-um or the machine file from the device's calibration); a probe's
    centres carry theirs from the log's pooled touches."""
    if noise_um is not None or joined.device != "probe":
        return (noise_um if noise_um is not None else machine.noise_um), None
    cov = joined.covariance(np.zeros((3, 3)))
    dofs = [d.cov_dof for d in joined.sets]
    return (float(np.sqrt(np.einsum("nii->", cov) / (3 * len(cov)))) * 1e3,
            sum(dofs) if None not in dofs else None)


def _misfit(res: _Residual, noise: Whitening, device: float | None, best_sum_sq: float,
            alpha: float, device_dof: int | None = None) -> tuple[tuple, float | None]:
    """Against the device's noise (where known; estimated with ``device_dof`` degrees of
    freedom, or None where given): each path and direction whose residual exceeds it, and
    the share of the excess the best explanation removes."""
    if device is None:
        return (), None
    free = 1.0 - np.einsum("ij,ij->i", res.Q, res.Q).reshape(-1, 3)     # 1 − each reading's leverage
    misfit = tuple(lack_of_fit(res.r.reshape(-1, 3), res.poses.path, device, noise.rho, free, alpha,
                               device_dof))
    excess = res.rss - res.dof * (device * 1e-3) ** 2
    share = min(1.0, best_sum_sq / excess) if best_sum_sq > 0 and excess > 0 else None
    return misfit, share


def _columns(machine: Machine, res: _Residual, made: dict[str, np.ndarray], name: str) -> np.ndarray:
    """A candidate's columns: those step 3 made (a reversal's carry its start sides), or a walk."""
    return made[name] if name in made else effect_columns(machine, res.poses, resolve(machine, name))


def _residual(machine: Machine, joined: Measurements, fit: FitResult) -> _Residual:
    """Step 1: the fit's residual, each path's start side fitted as fit fits it, outlying
    readings (``noise.outliers``) left out. Only Q and R of the model's Jacobian are kept:
    J's column norms are R's. Free start sides (``FreeConstants``) come first in Q, and R is
    that of J without them, as fit has it."""
    poses = joined.poses
    model = Model(machine, fit.model)
    x = fit.values
    free = [model.names.index(n) for n in fit.free]
    pred, J = model.linearise(poses, x)              # one walk of the chains for both
    r3 = joined.deviation - pred
    rtest = joined.rtest
    starts = FreeConstants(machine, fit.model, poses).projector()
    if starts is not None:
        r3 = starts.remove(r3)
    seg = runs(poses, joined.set_of)
    bad, size = outliers(r3 * 1e3, seg)
    if bad.size:
        keep = np.ones(len(poses), bool)
        keep[bad] = False
        poses, r3, seg, pred, rtest = poses.take(keep), r3[keep], seg[keep], pred[keep], rtest[keep]
        starts = FreeConstants(machine, fit.model, poses).projector()
        J = J[keep]
    r = r3.ravel()
    if free != list(range(J.shape[2])):             # indexed by a list: a copy, projected in place
        J = J[:, :, free]                           # (else linearise's own, (p, n, 3) underneath)
    Q, R = tall_qr((J if starts is None else starts(J)).reshape(r.size, -1))
    if starts is not None:
        Q = np.hstack([starts.basis(len(poses)), Q])
    return _Residual(poses, seg, r - Q @ (Q.T @ r), r3, pred, rtest, sensor_axes(machine, poses.q), Q, R, bad,
                     size)


def _to_try(machine: Machine, fit: FitResult, candidates: Sequence[str] | None,
            poses: Poses) -> tuple[list[Effect], tuple[str, ...]]:
    """Step 2: the effects to try (the catalogue's, or those named) not in the model, and a
    note on those the data cannot carry."""
    in_model = {effect_of_param(machine, n).name for n in fit.model}
    effects = [e for e in (catalogue(machine) if candidates is None
                           else [resolve(machine, c) for c in candidates]) if e.name not in in_model]
    notes = ()
    if candidates is None and np.isnan(poses.t).any():   # a drift needs the time of every reading
        timed = [e.name for e in effects if e.carrier == "time" or e.basis.kind in IN_TIME]
        effects = [e for e in effects if e.name not in timed]
        if timed:
            notes = (f"  not tried: {', '.join(timed)} (they need the time t of every reading; "
                     "these data do not give it)",)
    if not effects:
        raise CompgenError("no candidate effect left to try: the model holds them all")
    return effects, notes


def _ranked(machine: Machine, fit: FitResult, effects: Sequence[Effect], res: _Residual,
            alpha: float) -> tuple[list[Effect], dict[str, Row], Whitening, dict[str, np.ndarray], tuple]:
    """Step 3: every candidate's numbers (``ranking.rank``). ρ̂ from the residual once the
    best candidate (least squares) is added: the misfit of a missing effect is not noise;
    then, if the noise is correlated, ranked again whitened. Returns the numbers, the
    whitening, the columns made on the way (the reversals with start sides, the best), and
    (best, products) where the last pass carried the best's columns beside the model's:
    what step 5 needs of the others, without a pass of its own. A saturating best has its
    τ fitted (``timeconstant``): the effects come back with it.

    The first pass carries the best it expects: on a dense session (beyond
    ``SCREEN_POSES``), the best on every k-th pose; where that is not the best of all
    poses, step 5 makes its own pass (only time is lost)."""
    poses, r, Q, seg = res.poses, res.r, res.Q, res.seg
    noise = Whitening(seg, np.zeros((len(poses), 3)), Q)
    started = started_reversals(machine, poses, effects)
    walked = [e for e in effects if e.name not in started]     # the others: from one walk
    made = dict(started)
    guess = _screened(machine, fit, effects, res, walked, started)
    if guess is not None and guess.name not in made:
        made[guess.name] = effect_columns(machine, poses, guess)
    carry = () if guess is None else (made[guess.name],)
    p = Q.shape[1]
    both = products(machine, poses, walked, (Q, *carry), r)
    plain = {e: (cc, qx[:p], cr) for e, (cc, qx, cr) in both.items()}
    plain |= {e: (C.T @ C, Q.T @ C, C.T @ r) for e, C in started.items()}
    ranked = rank(effects, fit.free, res.R, r, noise, plain)
    best = max(ranked.values(), key=lambda row: (row.vis >= VISIBLE, row.share))
    c = made.get(best.effect.name)
    c = effect_columns(machine, poses, best.effect) if c is None else c
    carried = (best.effect.name, both) if guess is not None and guess.name == best.effect.name else ()
    u, sv, _ = np.linalg.svd(c - Q @ (Q.T @ c), full_matrices=False)
    beyond = u[:, sv > 1e-9 * sv.max()] if sv.size and sv.max() > 0 else u[:, :0]   # c's span beyond Q
    rest = r - beyond @ (beyond.T @ r)
    taken = Lazy(Q.shape[1] + beyond.shape[1], lambda: (Q, beyond))
    rho = ar1(rest.reshape(-1, 3), seg, taken, RHO_MARGIN_SE)
    if rho.any():
        noise = Whitening(seg, rho, Q)
        rw = noise.residual(r)
        both = products(machine, poses, walked, (noise.Q, noise.white(c)), rw, (seg, rho))
        white = {e: (cc, qx[:p], cr) for e, (cc, qx, cr) in both.items()}
        white |= {e: (Cw.T @ Cw, noise.Q.T @ Cw, Cw.T @ rw)
                  for e, Cw in ((e, noise.white(C)) for e, C in started.items())}
        ranked = rank(effects, fit.free, res.R, r, noise, plain, white)
        carried = (best.effect.name, both)
    effects, ranked, more = refined(machine, effects, ranked, res, noise, fit.free, alpha)
    return effects, ranked, noise, started | {best.effect.name: c} | more, carried


def _screened(machine: Machine, fit: FitResult, effects: Sequence[Effect], res: _Residual,
              walked: Sequence[Effect], started: dict[str, np.ndarray]) -> Effect | None:
    """The best candidate on every k-th pose of a session beyond ``SCREEN_POSES`` (about
    ``SCREEN_POSES`` of them), or None on a smaller one: what the first pass carries."""
    n = len(res.poses)
    if n <= SCREEN_POSES:
        return None
    every = -(-n // SCREEN_POSES)
    at = np.arange(0, n, every)
    rows = (3 * at[:, None] + np.arange(3)).ravel()
    Qs, R2 = tall_qr(res.Q[rows])
    rs = res.r[rows] - Qs @ (Qs.T @ res.r[rows])
    sub = products(machine, res.poses.take(at), walked, Qs, rs)
    sub |= {e: (C[rows].T @ C[rows], Qs.T @ C[rows], C[rows].T @ rs) for e, C in started.items()}
    s = res.Q.shape[1] - res.R.shape[0]          # Q's start sides come first: J's R beyond them
    try:
        ranked = rank(effects, fit.free, R2[s:, s:] @ res.R, rs,
                      Whitening(res.seg[at], np.zeros((len(at), 3)), Qs), sub)
    except np.linalg.LinAlgError:               # the subset cannot hold the model: no guess
        return None
    return max(ranked.values(), key=lambda row: (row.vis >= VISIBLE, row.share)).effect


def _bias(fit: FitResult, res: _Residual, effects: Sequence[Effect], ranked: dict[str, Row]):
    """Step 4: data holding a unit of candidate parameter j shift the fitted parameters by
    (J⁺C)ᵢⱼ, first order; kept in shown units (µm or ″ per µm or ″ of j). Returns the
    shifts, every parameter's shown unit, and each candidate parameter's RMS signature."""
    bias = {n: {} for n in fit.free}
    units = {n: shown(1.0, fit.parameters[n].unit)[1] for n in fit.free}
    signature_um = {}
    for e in effects:
        row = ranked[e.name]
        for j, pname in enumerate(e.params):
            units[pname] = shown(1.0, e.unit)[1]
            per_shown = shown(1.0, e.unit)[0]
            signature_um[pname] = float(row.norms[j] / np.sqrt(len(res.poses))) * 1e3 / per_shown
            for i, n in enumerate(fit.free):
                bias[n][pname] = float(row.absorbed[i, j] * shown(1.0, fit.parameters[n].unit)[0]
                                       / per_shown)
    return bias, units, signature_um


def _rivals(machine: Machine, res: _Residual, significant: list[Candidate], first: np.ndarray | None,
            out: list[Candidate], ranked: dict[str, Row], noise: Whitening, made: dict[str, np.ndarray],
            carried: tuple, alpha: float) -> dict:
    """Step 5: which significant candidates stay so once the best is added (a second
    effect, never a rival: the data tell it from the best), and which are the best's rivals
    (the data cannot tell them apart): the ``Diagnosis`` fields. ``made``: the columns step
    3 made (the reversals with start sides, and its best); ``carried``: (best, products) of
    step 3's last pass, its columns beside the model's, if it carried them; ``first``: the
    best's whitened columns."""
    poses, r = res.poses, res.r
    after_best, rival_names = (), ()
    if len(significant) > 1:
        # the others' products with the model, the best and the residual from one walk of
        # the poses (their columns would take a walk each); a reversal with start sides,
        # whose columns carry them, from the columns step 3 made
        best = significant[0].effect
        others = [resolve(machine, c.effect) for c in significant[1:]]
        rw = noise.residual(r)
        walked = [e for e in others if e.name not in made]
        prods = ({e.name: carried[1][e.name] for e in walked} if carried and carried[0] == best else
                 products(machine, poses, walked, (noise.Q, first), rw,
                          (res.seg, noise.rho) if noise.rho.any() else None))
        prods |= {e.name: beside(noise.white(made[e.name]), noise, first, rw)
                  for e in others if e.name in made}
        kept = still_significant(noise.Q, first, rw, prods, alpha)
        after_best = tuple(e.name for e in others if e.name in kept)
    if significant:
        best = ranked[significant[0].effect]
        rival_names = rivals((best.drop_w, best.k_eff), {
            c.effect: (ranked[c.effect].drop_w, ranked[c.effect].k_eff)
            for c in out if c.visible and c.effect != best.effect.name},
            noise.rss(r) / res.dof, alpha, bool(after_best))
        rival_names = tuple(n for n in rival_names if n not in after_best)
        sigma2 = noise.rss(r) / res.dof
        alike = rivals((best.drop_w, best.k_eff),
                       {n: (ranked[n].drop_w, ranked[n].k_eff) for n in rival_names}, sigma2, alpha, False)
        pending = {n: noise.white(_columns(machine, res, made, n)) for n in rival_names if n not in alike}
        if pending:       # rivals by the misfit the best leaves: judged beside what explains it
            # those significant beside the best, then the others by rank: a rival's own second
            # may be absorbed by the best (the second drift beside the wrong curve)
            # (the rivals too: two effects at once may each be the other's rival)
            seconds = list(dict.fromkeys([*after_best, *(c.effect for c in significant[1:])])
                           )[:min(PAIRED, max(1, SECOND_WALKS // len(poses)))]
            seconds = [noise.white(_columns(machine, res, made, e)) for e in seconds]
            kept = paired(first, pending, seconds, noise.residual(r), noise.off,
                          rival_margin(best.k_eff, sigma2, alpha))
            rival_names = tuple(n for n in rival_names if n in alike or n in kept)
    return {"after_best": after_best, "rivals": rival_names}


def _turns(advising: Advising | None, poses: Poses, joined: Measurements, form_rival: str | None,
           blamed: str | None) -> tuple[Proposal | None, Proposal | None]:
    """What tells the device from the machine, as a measurement: the last path with the ball
    turned on its stem where its form ties with the machine's best, with the probe turned in
    the spindle where the probe's trigger is blamed (the ball stays where it is)."""
    if advising is None:
        return None, None
    at = (str(poses.path[-1]), tuple(poses.ball[-1]))
    ball = None if form_rival is None else advising.turned(*at, sum(1 for d in joined.sets if d.turned),
                                                          turn_for(form_rival))
    spun = None if blamed is None or not blamed.startswith(TRIGGER) else advising.spindle_turned(
        *at, sum(1 for d in joined.sets if d.spindle), turn_for(blamed))
    return ball, spun


def _advised(machine: Machine, res: _Residual, out: list[Candidate], ranked: dict[str, Row], rival: dict,
             model_effects: Sequence[Effect], advising: Advising | None,
             alpha: float) -> tuple[list[Candidate], dict]:
    """Step 6: what would separate what these data cannot (``separation.py``, one R factor of
    the measured poses for both): a candidate the model absorbs, or a part of it (fit --add
    refuses it), and the best's rivals. Equivalent rivals reordered. Rivals no set-up parts
    at their sizes get the repeat right after the data: one error's shapes in time grow apart
    with more minutes, and a tie that is marginal (its best passes the family's ``alpha`` but
    not ``MARGINAL`` of it) is asked again before any is named: a chance misfit fades when
    measured again, a real one grows. Returns the candidates and ``rival`` with what tells
    the rivals apart."""
    rival_names, separated_by, left_open, same = rival["rivals"], (), {}, ()
    best = next((ranked[c.effect] for c in out if c.significant), None)
    group = [best, *(ranked[e] for e in rival_names)] if rival_names else []
    # seen, but not to be added as a whole: a part of it the model absorbs, so the
    # measurement that shows that part is what to advise
    unseen = [resolve(machine, c.effect) for c in out if not c.visible or (c.significant and not c.separable)]
    if advising is not None and (unseen or group):
        measured = Measured(machine, model_effects, res.poses, [*unseen, *(row.effect for row in group)])
        seen = separating(measured, unseen, advising) if unseen else {}
        out = [replace(c, separated_by=seen[c.effect]) if c.effect in seen else c for c in out]
        if group:
            by_rival, separated_by, left_open, same = telling_apart(measured, group, res.rss / res.dof,
                                                                    advising)
            out = [replace(c, separated_by=by_rival[c.effect]) if c.effect in by_rival else c for c in out]
            names = [row.effect.name for row in group]
            lead = next(c for c in out if c.significant)
            if not separated_by and (one_error_in_time(names) or lead.p_value > MARGINAL * alpha):
                separated_by = advising.runnable([m for m in advising.candidates if m.again], 1)
                left_open = {m.label: list(combinations(names, 2)) for m in separated_by}
    exhausted = tuple(m.run_label for m in separated_by
                      if m.again and _times_measured(machine, res.poses, res.seg, m) >= REPEATS_TRIED)
    if rival_names and not separated_by:
        # equivalent everywhere: put first the one the location errors absorb least, so
        # that adding it leaves them where an effect without that absorbed part has them.
        # (Not the one that moves them least: that keeps the bias of the fit without it,
        # and a compound the model absorbs a part of would come last.) No order makes the
        # choice right: what each carries is printed, and a fit's σ holds the spread.
        named = (best.effect.name, *rival_names)
        first = max((c for c in out if c.significant and c.effect in named), key=lambda c: c.visibility)
        if first.effect != best.effect.name:
            out.remove(first)
            out.insert(out.index(next(c for c in out if c.effect == best.effect.name)), first)
            rival_names = tuple(c.effect for c in out if c.effect in named and c is not first)
    one = {best.effect.name, *same} if same else set()      # one column: whichever leads
    same = tuple(n for n in rival_names if n in one)
    return out, {**rival, "rivals": rival_names, "rivals_separated_by": separated_by,
                 "rivals_open": left_open, "exhausted": exhausted, "equivalents": same}




def _times_measured(machine: Machine, poses: Poses, run: np.ndarray, m: Proposal) -> int:
    """How many runs of ``poses`` (``run``: numbered with each pose's file, as a repeat in a
    file of its own continues the last one's path and clock) are ``m``'s: its path, its
    ball, its nest."""
    first = np.flatnonzero(np.r_[True, run[1:] != run[:-1]])
    nest = np.where(np.isnan(poses.nest), machine.probe_length, poses.nest)
    want = machine.probe_length if m.nest is None else m.nest
    return sum(1 for i in first if str(poses.path[i]) == m.path and abs(nest[i] - want) < 1e-3
               and np.allclose(poses.ball[i], m.ball, atol=1e-3))


def _carries(fit: FitResult, out: Sequence[Candidate], ranked: dict[str, Row],
             rival_names: tuple[str, ...]) -> dict[str, dict[str, float]]:
    """Step 6: what each rival, added, takes back from the fitted parameters (first order:
    the part of it they absorbed, J⁺c·a): where rivals are equivalent, the choice moves these."""
    carries = {}
    first = next((c.effect for c in out if c.significant), None)     # after any reordering
    for name in ((first, *rival_names) if rival_names else ()):
        row = ranked[name]
        shift = -(row.absorbed @ row.amp)
        carries[name] = {n: float(shift[i] * shown(1.0, fit.parameters[n].unit)[0])
                         for i, n in enumerate(fit.free)}
    return carries


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
