"""diagnose's statistics on inputs whose answers are known in closed form."""

import numpy as np
import pytest

from compgen.statistics.significance import VISIBLE
from compgen.statistics.significance import explained as _explained
from compgen.statistics.significance import p_value as _p_value
from compgen.statistics.significance import still_significant as _still_significant

E = np.eye(6)


def _by_products(c, Q, r):
    """``explained`` takes the columns' products: cᵀc, Qᵀc (Q the model's orthonormal
    columns) and cᵀr (r orthogonal to Q)."""
    return _explained(c.T @ c, Q.T @ c, c.T @ r)


def test_explained_by_hand():
    """Columns e1 (fully visible) and 0.5·e2 + 1e-4·e3 where the model is e3 (it absorbs
    the e3 part): residual 3·e1 + 2·e2 + e4."""
    c = np.column_stack([E[0], 0.5 * E[1] + 1e-4 * E[2]])
    r = 3 * E[0] + 2 * E[1] + 1.0 * E[3]
    vis, drop, amp = _by_products(c, E[2][:, None], r)
    np.testing.assert_allclose(vis, [1.0, 0.5 / np.hypot(0.5, 1e-4)], rtol=1e-12)
    np.testing.assert_allclose(amp, [3.0, 4.0], rtol=1e-12)           # 0.5·4 = 2
    assert drop == pytest.approx(9.0 + 4.0, rel=1e-12)


def test_an_invisible_column_explains_nothing():
    """The second column is e3 but for 0.5·VISIBLE·e2: the model (e3) absorbs all but that."""
    c = np.column_stack([E[0], 0.5 * VISIBLE * E[1] + E[2]])
    vis, drop, amp = _by_products(c, E[2][:, None], 2 * E[0] + 5 * E[1])
    assert vis[1] < VISIBLE and amp[1] == 0.0 and amp[0] == pytest.approx(2.0)
    assert drop == pytest.approx(4.0)
    vis, drop, amp = _by_products(c[:, :1], E[0][:, None], E[3])   # the model absorbs it whole
    assert drop == 0.0 and not amp.any()


def test_p_value_by_the_f_distribution_and_bonferroni():
    # F(2, d) has the closed-form tail (1 + 2F/d)^(−d/2)
    drop, k, rss, dof = 40.0, 2, 540.0, 502
    F = (drop / k) / ((rss - drop) / (dof - k))
    tail = (1 + k * F / (dof - k)) ** (-(dof - k) / 2)
    assert _p_value(drop, k, rss, dof, 1) == pytest.approx(tail, rel=1e-10)
    assert _p_value(drop, k, rss, dof, 7) == pytest.approx(7 * tail, rel=1e-10)
    assert _p_value(1e-9, k, rss, dof, 50) == 1.0                 # never above one
    assert _p_value(400.0, k, 420.0, dof, 1) < 1e-100


def test_still_significant_after_the_best():
    rng = np.random.default_rng(1)
    n = 600
    Q = np.linalg.qr(rng.normal(size=(n, 2)))[0]
    best, other, null = (rng.normal(size=(n, 1)) for _ in range(3))
    r = 4 * best[:, 0] + 3 * other[:, 0] + rng.normal(size=n)
    r -= Q @ (Q.T @ r)

    class Effect:
        def __init__(self, name):
            self.name = name

    sig = [(Effect("other"), other), (Effect("null"), null)]
    assert _still_significant(Q, best, r, _prods(Q, best, r, sig), 0.01) == {"other"}
    both = np.column_stack([best, other])
    assert _still_significant(Q, both, r, _prods(Q, both, r, [(Effect("null"), null)]), 0.01) == set()


def _prods(Q, added, r, signatures):
    """What signature.products gives of each candidate's columns c: cᵀc, [Q | added]ᵀc, cᵀr."""
    X = np.column_stack([Q, added])
    return {e.name: (c.T @ c, X.T @ c, c.T @ r) for e, c in signatures}


def test_still_significant_tests_against_the_joined_model(monkeypatch):
    """The F test after the best: residual and candidates taken off the model AND the added
    columns (projections done here), with n − model − added degrees of freedom."""
    import compgen.statistics.significance as d
    rng = np.random.default_rng(2)
    n = 40
    Q = np.linalg.qr(rng.normal(size=(n, 3)))[0]
    added = rng.normal(size=(n, 2)) + Q @ rng.normal(size=(3, 2))    # not orthogonal to Q
    cand = rng.normal(size=(n, 1))
    r = rng.normal(size=n)
    r -= Q @ (Q.T @ r)             # the residual of the model: orthogonal to it
    seen = []
    monkeypatch.setattr(d, "p_value", lambda *args: seen.append(args) or 1.0)

    class Effect:
        name = "cand"
    d.still_significant(Q, added, r, _prods(Q, added, r, [(Effect(), cand)]), 0.01)
    A = np.column_stack([Q, added])
    P = A @ np.linalg.pinv(A)                    # projector onto the joined model
    r1, c1 = r - P @ r, cand - P @ cand
    amp = (c1[:, 0] @ r1) / (c1[:, 0] @ c1[:, 0])
    drop, k, rss, dof, tried = seen[0]
    assert (k, dof, tried) == (1, n - 3 - 2, 1)
    assert rss == pytest.approx(r1 @ r1, rel=1e-10)
    assert drop == pytest.approx(amp**2 * (c1[:, 0] @ c1[:, 0]), rel=1e-10)


def test_a_column_that_moves_nothing_is_invisible():
    c = np.column_stack([E[0], np.zeros(6)])
    vis, drop, amp = _by_products(c, E[5][:, None], E[0] + E[1])
    assert vis.tolist() == [1.0, 0.0] and amp[1] == 0.0 and drop == pytest.approx(1.0)


def test_products_a_block_at_a_time_equal_those_of_the_whole_columns(seed_machine, monkeypatch):
    """``signature.products`` (blocks of poses, whitening carried across them) against cᵀc,
    Qᵀc and cᵀr of each effect's whole columns, plain and made white with AR(1) ρ."""
    from compgen.model.effects import IN_TIME, Basis, Effect, catalogue, resolve
    from compgen.model.kinematics import Model, SlotGains, coordinate, effect_gains
    from compgen.model.paths import generate
    from compgen.model.poses import runs
    from compgen.statistics import signature
    from compgen.statistics.noise import whiten
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    every = [e for e in catalogue(seed_machine) if e.carrier != "time" and e.basis.kind not in IN_TIME]
    # a spline of five knots (four parameters) on a slot other effects share
    shape = Effect("EXC", "C", "comp", "x", Basis("s", label="bow", at=(-3.0, -1.0, 0.0, 1.0, 3.0)), "test")
    # and three scales in time, on A and on X: position times growth, a coordinate of each τ
    scales = [resolve(seed_machine, n) for n in ("EAA:g15", "EXX:g5", "EXX:g45")]
    effects = [*every[::7], *(e for e in every if len(e.direction) == 2)][:40] + scales + [shape]
    on = [(e.carrier, e.slot, e.direction) for e in effects]
    assert on.count(on[-1]) > 1 and len(set(on)) < len(on) and any(len(e.direction) == 2 for e in effects)
    J = Model(seed_machine, ["XOC", "YOC", "BOA"]).jacobian(poses).reshape(-1, 3)
    Q = np.linalg.qr(J)[0]
    r = np.random.default_rng(2).normal(size=J.shape[0])
    seg = runs(poses)
    rho = np.where(seg[:, None] == seg[0], 0.9, 0.4) * np.ones((len(poses), 3))
    monkeypatch.setattr(signature, "BLOCK", 100)          # several blocks, edges inside runs,
    monkeypatch.setattr(signature, "CHUNK_BYTES", 1)      # chunks of 64 poses: a block's last shorter
    for noise in (None, (seg, rho)):
        got = signature.products(seed_machine, poses, effects, (Q[:, :2], Q[:, 2:]), r, noise)
        # the reference: each effect's columns from one walk of every pose, no blocks
        gains, made = SlotGains(seed_machine, poses), {}
        for e in effects:
            c = effect_gains(gains, e, coordinate(seed_machine, e, poses), made).reshape(-1, len(e.params))
            if noise is not None:
                c = whiten(c.reshape(len(poses), 3, -1), seg, rho).reshape(c.shape)
            cc, qc, cr = got[e.name]
            scale = max(np.abs(c).max() ** 2 * len(c), 1e-300)
            np.testing.assert_allclose(cc, c.T @ c, rtol=0, atol=1e-12 * scale, err_msg=e.name)
            np.testing.assert_allclose(qc, Q.T @ c, rtol=0, atol=1e-12 * np.sqrt(scale), err_msg=e.name)
            np.testing.assert_allclose(cr, c.T @ r, rtol=0, atol=1e-12 * np.sqrt(scale) * 50, err_msg=e.name)


def test_the_r_factor_of_chunks_takes_a_reversal_s_sides_from_the_whole_session(seed_machine):
    """``r_factor`` stacks chunks of poses; a reversal's side at a chunk's first pose is that of
    the move that reached it in the session (as ``products`` and ``columns`` take it), not of
    the chunk's first move: RᵀR is the Gram matrix of the whole columns, where a chunk starts
    at the pose where the axis turns."""
    from dataclasses import replace

    from compgen.model.effects import resolve
    from compgen.model.kinematics import coordinate
    from compgen.model.paths import generate
    from compgen.statistics.signature import columns, r_factor
    k2 = generate(seed_machine, ["K2"], back=True)
    poses = replace(k2, side=np.full_like(k2.side, np.nan))      # data that do not say the side
    effects = [resolve(seed_machine, "ECC:r1"), resolve(seed_machine, "XOC")]
    side = coordinate(seed_machine, effects[0], poses)
    chunk = next(k for k in range(2, len(poses)) if side[k] != side[k + 1])     # the turning pose
    assert coordinate(seed_machine, effects[0], poses.take(slice(chunk, None)))[0] != side[chunk]
    C = columns(seed_machine, poses, effects)
    R = r_factor(seed_machine, poses, effects, chunk=chunk)
    np.testing.assert_allclose(R.T @ R, C.T @ C, rtol=1e-10, atol=1e-12 * np.abs(C.T @ C).max())


def test_the_scans_sums_are_the_least_squares_sines_sum_of_squares():
    """The scan's sum of squares at each frequency (from running phasors) is what the least-
    squares sine with a constant removes, fitted anew; with the model's columns taken out too."""
    from compgen.statistics.spectrum import _drops, _fit

    rng = np.random.default_rng(4)
    x = np.sort(rng.uniform(0, 400, 90))                 # uneven, as poses are: cos and sin correlate
    y = rng.normal(0, 1, (90, 3)) + 0.7 * np.sin(2 * np.pi * x / 37 + np.array([[0.4], [1.0], [2.0]])).T
    y -= y.mean(axis=0)
    grid = np.linspace(1 / 300, 1 / 5, 40)
    # the model's columns as they come: orthonormal, holding a constant (the set-up terms),
    # not centred; one block per direction, and the residual orthogonal to its block
    Qd = np.stack([np.linalg.qr(np.column_stack([np.ones_like(x), x / 400 + d, np.cos(x / (50 + d))]))[0]
                   for d in range(3)])
    for blocks in (None, Qd):
        r = y if blocks is None else np.column_stack([y[:, d] - blocks[d] @ (blocks[d].T @ y[:, d])
                                                      for d in range(3)])
        got = _drops(x, r, grid, blocks)
        for d in range(3):
            want = [_fit(x, r[:, d], f, None if blocks is None else blocks[d])[0] for f in grid]
            np.testing.assert_allclose(got[:, d], want, rtol=1e-7, atol=1e-9)


def test_a_periodic_drift_in_a_dense_session_is_found_at_its_period_in_seconds():
    """13 000 poses (denser than the scan's 12 000: scanned on an even subset, refined and
    judged on all): a 2 µm sine in time of period 900 s is the time line, its period in s."""
    from compgen.configuration.machine_file import load_machine
    from compgen.model.paths import generate
    from compgen.model.poses import Poses
    from compgen.statistics.spectrum import SCAN_POSES, strongest_lines

    machine = load_machine("ac-trunnion-itnc530")
    k4 = generate(machine, ["K4"])
    reps = -(-13_000 // len(k4))
    q = np.tile(k4.q, (reps, 1))[:13_000]
    n = len(q)
    assert n > SCAN_POSES
    t = np.arange(n) * 0.5
    poses = Poses(q, np.tile(k4.ball, (reps, 1))[:n], t, np.array(["K4"] * n))
    rng = np.random.default_rng(2)
    r = rng.normal(0, 0.3e-3, (n, 3))
    r[:, 1] += 2e-3 * np.sin(2 * np.pi * t / 900.0 + 0.3)
    r -= r.mean(axis=0)
    line = next(x for x in strongest_lines(machine, poses, r) if x.against == "time")
    assert line.direction == "dY" and line.period == pytest.approx(900.0, rel=2e-3)
    assert line.amplitude_um == pytest.approx(2.0, rel=0.05) and line.p_value < 1e-6
    # with the model's columns (the residual orthogonal to them), scanned on the subset
    # with those columns made orthonormal there: the same line, every figure on all poses
    from compgen.model.kinematics import Model
    Q = np.linalg.qr(Model(machine, ["XOW", "YOW", "ZOW", "XOC", "YOC", "AOC", "BOC"])
                     .jacobian(poses).reshape(3 * n, -1))[0]
    rq = (r.reshape(-1) - Q @ (Q.T @ r.reshape(-1))).reshape(n, 3)
    with_q = next(x for x in strongest_lines(machine, poses, rq, Q) if x.against == "time")
    assert with_q.direction == "dY" and with_q.period == pytest.approx(900.0, rel=2e-3)
    assert with_q.amplitude_um == pytest.approx(2.0, rel=0.05) and with_q.p_value < 1e-6


def test_each_line_is_the_documented_scan_judged_by_the_joint_least_squares():
    """K4+K1+K2 on the seed machine, the residual orthogonal to the model's 11 columns: a 2.5 mm
    pitch against X in dX, 30/rev against C in dY, a 90 s period in dZ (each inside the
    documented range: pitches from 2 mm, 1–36/rev, periods of a minute and up). Each line's
    period, amplitude, sum of squares, share and p-value against the least-squares fit of a
    sine and a constant in that direction jointly with the model, done here in the 3n
    reading space, and Bonferroni over the periods resolved (span/2 mm − 2 pitches, 36
    orders, span/60 s − 2 periods)."""
    from scipy import stats

    from compgen.configuration.machine_file import load_machine
    from compgen.model.kinematics import Model
    from compgen.model.paths import generate
    from compgen.model.poses import Poses
    from compgen.statistics.spectrum import strongest_lines

    machine = load_machine("ac-trunnion-itnc530")
    g = generate(machine, ["K4", "K1", "K2"])
    n = len(g)
    t = np.arange(n) * 3.0
    poses = Poses(g.q, g.ball, t, g.path)
    x, c = g.q[:, machine.index("X")], g.q[:, machine.index("C")]
    J = Model(machine, ["XOW", "YOW", "ZOW", "YOA", "ZOA", "BOA", "COA", "XOC", "YOC", "AOC", "BOC"]
              ).jacobian(poses).reshape(3 * n, -1)
    Q = np.linalg.qr(J)[0]
    rng = np.random.default_rng(5)
    r = rng.normal(0, 0.2e-3, (n, 3))
    r[:, 0] += 2e-3 * np.sin(2 * np.pi * x / 2.5 + 0.4)
    r[:, 1] += 1.5e-3 * np.cos(30 * c + 1.0)
    r[:, 2] += 1.5e-3 * np.sin(2 * np.pi * t / 90.0 + 2.0)
    r = (r.reshape(-1) - Q @ (Q.T @ r.reshape(-1))).reshape(n, 3)
    lines = {line.against: line for line in strongest_lines(machine, poses, r, Q)}
    rss = float(np.sum(r**2))

    def joint(v, omega, d):
        """The sum of squares a sine of angular frequency omega against v (and a constant)
        in direction d removes from r beyond the model, and its amplitude."""
        B = np.zeros((n, 3, 3))
        B[:, d] = np.column_stack([np.cos(omega * v), np.sin(omega * v), np.ones(n)])
        A = np.column_stack([Q, B.reshape(3 * n, 3)])
        coef = np.linalg.lstsq(A, r.reshape(-1), rcond=None)[0]
        return float(np.sum((A @ coef) ** 2)), float(np.hypot(*coef[-3:-1]))

    for against, v, omega_of, d, want, count in (
            ("X", x, lambda p: 2 * np.pi / p, 0, 2.5, np.ptp(x) / 2.0 - 2),
            ("C", c, lambda p: p, 1, 30.0, 36),                   # orders 1 to 36: exactly 36
            ("time", t, lambda p: 2 * np.pi / p, 2, 90.0, np.ptp(t) / 60.0 - 2)):
        line = lines[against]
        assert line.direction == f"d{'XYZ'[d]}", line
        assert line.period == pytest.approx(want, rel=2e-3), line
        drop, amp = joint(v, omega_of(line.period), d)
        # no period near the found one removes more (the refined peak, not a grid point)
        near = (joint(v, omega_of(line.period * (1 + e)), d)[0] for e in (-1e-3, 1e-3))
        assert max(near) <= drop * (1 + 1e-9)
        assert line.sum_sq == pytest.approx(drop, rel=1e-6, abs=0)
        assert line.amplitude_um == pytest.approx(amp * 1e3, rel=1e-6)
        assert line.share == pytest.approx(drop / rss, rel=1e-6)
        F = (drop / 2) / ((rss - drop) / (r.size - 3))
        assert line.p_value == pytest.approx(min(1.0, stats.f.sf(F, 2, r.size - 3) * count),
                                             rel=(1e-9 if against == "C" else 1.5 / count) + 1e-6,
                                             abs=0), (line, count)


def test_a_rival_removes_within_the_noise_of_the_best_or_while_misfit_is_left_nine_tenths_of_it():
    """χ²(k, α)·σ² is what chance moves a sum of squares by: a candidate removing that
    little less than the best is a rival whatever the misfit; while the best leaves misfit
    (it is not the whole story), one removing RIVAL = 0.9 of what the best removes is too."""
    from scipy import stats

    from compgen.statistics.significance import RIVAL, rivals
    sigma2, alpha = 0.01, 0.01
    within = stats.chi2.isf(alpha, 2) * sigma2                   # 0.092
    best = (100.0, 2)
    others = {"close": (100.0 - 0.9 * within, 2), "far": (100.0 - 1.1 * within, 2),
              "nine_tenths": (90.5, 1), "most": (89.5, 1), "unseen": (99.99, 0)}
    assert RIVAL == 0.9
    assert rivals(best, others, sigma2, alpha, misfit_left=False) == ("close",)
    assert rivals(best, others, sigma2, alpha, misfit_left=True) == ("close", "far", "nine_tenths")


def test_a_rival_by_the_misfit_left_is_judged_beside_the_second_effects():
    """The residual is a line in t plus a second effect s. Alone, a saturating curve e removes
    most of what t removes; beside s, whichever candidate's best pair removes more by the
    noise margin keeps the other only if that other's pair comes within it: t drops e, e
    (had it been ranked first) keeps t, and a rival that is the best's own column stays."""
    from compgen.statistics.significance import paired, rival_margin
    rng = np.random.default_rng(5)
    x = np.linspace(0, 1, 600)
    t, e = x - x.mean(), 1 - np.exp(-x / 3)
    e -= e.mean()
    s = np.sin(9 * x)
    sigma = 0.01
    rw = t + 0.5 * s + rng.normal(0, sigma, x.size)
    within = rival_margin(1, sigma**2, 0.01)
    seconds = [s[:, None], np.cos(5 * x)[:, None]]
    alone = {n: float((c @ rw) ** 2 / (c @ c)) for n, c in (("t", t), ("e", e))}
    assert alone["e"] > 0.9 * alone["t"]            # a rival by the misfit left
    cols = {"t": t[:, None], "e": e[:, None], "same": 2 * t[:, None]}
    assert paired(cols["t"], {"e": cols["e"], "same": cols["same"]}, seconds, rw, lambda v: v, within) \
        == ("same",)
    assert paired(cols["e"], {"t": cols["t"]}, seconds, rw, lambda v: v, within) == ("t",)


def test_lack_of_fit_is_the_chi2_test_of_each_path_and_direction_against_the_noise():
    """Two paths, dY of one at 1.3× the noise and dZ of the other at 1.6×: only they fail,
    the worst first; their RMS and p-values (χ² with n·dof_share degrees of freedom,
    Bonferroni over 2 paths × 3) as defined; AR(1) ρ shrinks the degrees of freedom by
    (1 − ρ²)/(1 + ρ²), a kurtosis κ above a normal's by 2/(κ − 1)."""
    from scipy import stats

    from compgen.statistics.significance import lack_of_fit
    rng = np.random.default_rng(3)
    n, noise_um, share = 400, 1.0, 0.9
    groups = np.repeat(["K4", "K1"], n)
    r = rng.normal(0, noise_um * 1e-3 * np.sqrt(share), (2 * n, 3))
    r[:n, 1] *= 1.3
    r[n:, 2] *= 1.6
    for rho in (0.0, 0.3):
        got = lack_of_fit(r, groups, noise_um, np.full((2 * n, 3), rho), share, 0.01)
        assert [(m["path"], m["direction"]) for m in got] == [("K1", "dZ"), ("K4", "dY")]
        for m, rg in zip(got, (r[n:, 2], r[:n, 1]), strict=True):
            kurtosis = max(3.0, np.mean(rg**4) / np.mean(rg**2) ** 2)
            k = round(n * share * (1 - rho**2) / (1 + rho**2) * 2 / (kurtosis - 1))
            ratio = np.mean(rg**2) / share / (noise_um * 1e-3) ** 2
            assert m["rms_um"] == pytest.approx(np.sqrt(np.mean(rg**2)) * 1e3, rel=1e-12)
            p = stats.chi2.sf(k * ratio, k) * 6
            assert 1e-300 < p < 1e-3 and m["p_value"] == pytest.approx(p, rel=1e-6, abs=0)



def test_heavy_tails_at_the_noise_are_no_misfit_and_a_misfit_beside_them_still_is():
    """Student-t noise (3 dof) at the R-test's σ, no outlier taken out: its sums of squares
    vary far more than a normal's, and a χ² test with a normal's degrees of freedom called a
    group of six misfit in 192 of 400 such sessions; with the kurtosis, 7 of 400 (α 0.01
    holds only for a finite kurtosis, which t(3) has not). A group at 1.3× the noise
    (normal) beside them still fails."""
    from compgen.statistics.significance import lack_of_fit
    n, noise_um = 240, 0.5
    groups, rho = np.repeat(["K4", "K1"], n), np.zeros((2 * n, 3))
    called = 0
    for seed in range(200):
        rng = np.random.default_rng(seed)
        r = rng.standard_t(3, (2 * n, 3)) / np.sqrt(3) * noise_um * 1e-3
        called += bool(lack_of_fit(r, groups, noise_um, rho, 1.0, 0.01))
        if seed < 10:
            r[:n, 0] = rng.normal(0, 1.3 * noise_um * 1e-3, n)
            assert ("K4", "dX") in [(m["path"], m["direction"]) for m in lack_of_fit(
                r, groups, noise_um, rho, 1.0, 0.01)]
    assert called <= 6, called


def test_a_groups_sum_of_squares_is_judged_by_the_share_the_fit_left_free_there():
    """K4's dX readings, where the fit took half of each reading's freedom (leverage 0.5),
    hold half the noise's sum of squares: at 1.3× that they are misfit, judged by their
    own free share; by a share of 1 for all they would pass."""
    from compgen.statistics.significance import lack_of_fit
    n, noise_um = 400, 0.5
    groups, rho = np.repeat(["K4", "K1"], n), np.zeros((2 * n, 3))
    rng = np.random.default_rng(8)
    r = rng.normal(0, noise_um * 1e-3, (2 * n, 3))
    r[:n, 0] *= 1.3 * np.sqrt(0.5)
    free = np.ones((2 * n, 3))
    free[:n, 0] = 0.5
    assert [(m["path"], m["direction"]) for m in lack_of_fit(r, groups, noise_um, rho, free, 0.01)] == \
        [("K4", "dX")]
    assert not lack_of_fit(r, groups, noise_um, rho, 1.0, 0.01)


def test_a_path_whose_correlation_leaves_under_one_degree_of_freedom_is_tested_with_one():
    """Twenty readings at ρ = 0.98 hold 0.2 degrees of freedom by the AR(1) rule: the test
    takes one, so a residual 30× the noise is still named (with p from χ²(1)), and one at
    the noise is not."""
    from scipy import stats

    from compgen.statistics.significance import lack_of_fit
    n, noise_um = 20, 0.5
    rho = np.full((n, 3), 0.98)
    r = np.full((n, 3), noise_um * 1e-3)
    r[:, 0] *= 30
    got = lack_of_fit(r, np.repeat(["K4"], n), noise_um, rho, 1.0, 0.01)
    assert [m["direction"] for m in got] == ["dX"]
    assert got[0]["p_value"] == pytest.approx(stats.chi2.sf(900.0, 1) * 3, rel=1e-6)


def test_a_sine_the_models_columns_hold_is_no_line():
    """Where the model's columns hold the cos/sin pair of a frequency (as a 1/rev term of a
    location error does), the pair's part the model cannot absorb is below SEEN of the
    pair: the scan gives it no sum of squares, however the residual looks there."""
    from compgen.statistics.spectrum import SEEN, _drops

    rng = np.random.default_rng(8)
    x = np.arange(200) * 37.0 / 20       # ten whole periods of 37: cos² and sin² sum alike
    f0 = 1 / 37.0
    pair = np.column_stack([np.ones_like(x), np.cos(2 * np.pi * f0 * x), np.sin(2 * np.pi * f0 * x)])
    Qd = np.stack([np.linalg.qr(pair + 1e-4 * rng.normal(size=pair.shape))[0] for _ in range(3)])
    y = rng.normal(size=(200, 3))
    y = np.column_stack([y[:, d] - Qd[d] @ (Qd[d].T @ y[:, d]) for d in range(3)])
    assert SEEN > 1e-3
    drops = _drops(x, y, np.array([f0, 1 / 11.0]), Qd)
    assert np.all(drops[0] == 0.0) and np.all(drops[1] > 0.0), drops


def test_a_line_along_a_linear_axis_is_outside_the_catalogue_by_each_of_its_rules():
    """Unknown device noise: a pitch line is what is missing when it is significant over all
    lines, resolved (≥ RESOLVES_UM), removes LINE_OVER_BEST = 2× what the best candidate
    removes and LINE_SHARE = 10 % of the residual; each rule alone keeps it out."""
    from dataclasses import replace

    from compgen.statistics.diagnosis import _outside_line
    from compgen.statistics.spectrum import Line
    line = Line("X", "dX", 5.0, "mm", 0.15, 0.15, 1e-6, 3.0)     # 0.15 µm, 15 %, 3.0 against 2 × 1.4
    others = [Line("C", "dY", 2.0, "/rev", 1.0, 0.9, 1e-9, 50.0)]      # a rotary line never counts
    assert _outside_line([line, *others], None, (), 0.01, 1.4) is line
    for changed in (replace(line, share=0.09), replace(line, sum_sq=2.7), replace(line, amplitude_um=0.09),
                    replace(line, p_value=0.006), replace(line, unit="s")):
        assert _outside_line([changed, *others], None, (), 0.01, 1.4) is None, changed
    assert _outside_line([line], 0.5, (), 0.01, 1.4) is None            # within a known noise: not judged


def test_tall_qr_is_householders_qr_and_falls_back_where_cholesky_cannot():
    """Q, R of a tall J with columns from mm to rad scales: QR = J, QᵀQ = I, R upper with
    the diagonal of numpy's up to sign; a rank-deficient J (two equal columns) and one
    conditioned beyond the Cholesky route still give J = QR."""
    from compgen.statistics.significance import tall_qr
    rng = np.random.default_rng(5)
    J = rng.normal(size=(3000, 9)) * np.logspace(-3, 3, 9)
    Q, R = tall_qr(J)
    np.testing.assert_allclose(Q @ R, J, rtol=0, atol=1e-13 * np.abs(J).max())
    np.testing.assert_allclose(Q.T @ Q, np.eye(9), rtol=0, atol=1e-13)
    assert np.allclose(np.tril(R, -1), 0) and (np.diag(R) > 0).all()
    np.testing.assert_allclose(np.abs(np.diag(R)), np.abs(np.diag(np.linalg.qr(J)[1])), rtol=1e-10)
    for bad in (np.column_stack([J, J[:, 0]]),                       # rank deficient
                np.column_stack([J[:, :2], J[:, 0] + 1e-9 * J[:, 1]])):   # cond ~1e9
        Q, R = tall_qr(bad)
        np.testing.assert_allclose(Q @ R, bad, rtol=0, atol=1e-12 * np.abs(bad).max())
        np.testing.assert_allclose(Q.T @ Q, np.eye(bad.shape[1]), rtol=0, atol=1e-12)


def test_a_reversals_visibility_beyond_its_start_sides_does_not_depend_on_its_scale():
    """‖c⊥‖/‖c‖ of a reversal's column beyond the model and its start sides, from products:
    as computed from the columns themselves, and the same for the column at 1/1000 of its
    size (a small sensitivity is no lack of visibility)."""
    from compgen.statistics.ranking import beyond_starts
    rng = np.random.default_rng(5)
    Q = np.linalg.qr(rng.normal(size=(60, 4)))[0]
    c, B = rng.normal(size=(60, 1)), rng.normal(size=(60, 2))      # the reversal, its start sides
    want = np.linalg.norm(c - np.column_stack([Q, B]) @ np.linalg.lstsq(np.column_stack([Q, B]), c,
                                                                         rcond=None)[0]) / np.linalg.norm(c)
    for scale in (1.0, 1e-3):
        C = np.column_stack([c * scale, B])
        got = beyond_starts(C.T @ C, Q.T @ C, 1)
        assert got[0] == pytest.approx(want, rel=1e-9) and 0 < want < 1
    C = np.column_stack([np.zeros(60), B])          # an axis that never reverses: nothing seen
    assert beyond_starts(C.T @ C, Q.T @ C, 1)[0] == 0.0


def test_a_noise_estimated_from_few_degrees_of_freedom_is_tested_as_one():
    """A probe's noise comes from its log's own touches (72 degrees of freedom for K4 + K1 +
    K2): taken as a known σ, a χ² test calls clean groups misfit whenever the estimate came
    out low (34 of 1000 clean sessions of 9 groups of 12 readings, α 0.01). Tested as the
    ratio of two estimates, F(k, 72): 8 of 1000; a group at 1.6× the noise is still named
    in 245 of them (12 readings hold little power)."""
    from compgen.statistics.significance import lack_of_fit
    n, noise_um, nu = 12, 1.0, 72
    groups, rho = np.repeat(["K4", "K1", "K2"], n), np.zeros((3 * n, 3))
    rng = np.random.default_rng(5)
    called = {"chi2": 0, "F": 0}
    named = 0
    for _ in range(1000):
        r = rng.normal(0, noise_um * 1e-3, (3 * n, 3))
        said = noise_um * np.sqrt(rng.chisquare(nu) / nu)          # the noise as the touches estimate it
        called["chi2"] += bool(lack_of_fit(r, groups, said, rho, 1.0, 0.01))
        called["F"] += bool(lack_of_fit(r, groups, said, rho, 1.0, 0.01, nu))
        r[:n, 0] *= 1.6
        named += ("K4", "dX") in [(m["path"], m["direction"]) for m in lack_of_fit(r, groups, said, rho, 1.0,
                                                                                    0.01, nu)]
    assert called["F"] <= 10 < called["chi2"], called
    assert named > 100, named
