"""Correlated noise and bad readings (noise.py) on series whose answers are known."""

import numpy as np
import pytest

from compgen.data.simulate import ar1_noise
from compgen.statistics.noise import OUTLIER_MIN_UM, Lazy, ar1, outliers, whiten


def test_segments_break_at_a_new_file_or_path():
    from compgen.model.poses import Poses, runs
    poses = Poses(np.zeros((6, 5)), np.zeros((6, 3)), np.full(6, np.nan),     # no time column
                  np.array(["K4", "K4", "K1", "K1", "K1", "K1"], dtype=object))
    seg = runs(poses, np.array([0, 0, 0, 0, 1, 1]))
    assert (seg - seg[0]).tolist() == [0, 0, 1, 1, 2, 2]


def test_prais_winsten_by_hand():
    """x'[0] = √(1−ρ²)·x[0], x'[i] = x[i] − ρ·x[i−1], started anew in each segment."""
    x = np.arange(1.0, 16.0).reshape(5, 3)
    seg = np.array([0, 0, 0, 1, 1])
    rho = np.tile([0.5, 0.0, 0.9], (5, 1))
    w = whiten(x, seg, rho)
    for d, p in enumerate((0.5, 0.0, 0.9)):
        c = x[:, d]
        expect = [np.sqrt(1 - p * p) * c[0], c[1] - p * c[0], c[2] - p * c[1],
                  np.sqrt(1 - p * p) * c[3], c[4] - p * c[3]]
        np.testing.assert_allclose(w[:, d], expect, rtol=1e-14)
    cols = whiten(np.stack([x, 2 * x], axis=-1), seg, rho)       # (n, 3, k): each column alike
    np.testing.assert_allclose(cols[..., 1], 2 * w, rtol=1e-14)


def test_ar1_is_estimated_and_white_noise_is_left_white():
    rng = np.random.default_rng(3)
    r = np.vstack([ar1_noise(3000, 0.8, 1e3, rng), rng.normal(size=(3000, 3))])
    seg = np.repeat([0, 1], 3000)
    rho = ar1(r, seg)
    np.testing.assert_allclose(rho[:3000], 0.8, atol=0.03)     # s.e. √((1−ρ²)/n) = 0.011
    assert not rho[3000:].any()                                  # within 2/√n of zero: taken as 0
    # whitened with its own ρ̂, the AR(1) series has no lag-1 correlation left
    w = whiten(r[:3000], seg[:3000], rho[:3000])
    lag = (w[1:] * w[:-1]).sum(axis=0) / (w**2).sum(axis=0)
    assert np.abs(lag).max() < 0.05


def test_segments_of_one_device_share_their_estimate_and_differing_ones_keep_their_own():
    """Three runs as long as the seed session's K4, K1, K2 of one AR(1) ρ = 0.9: each
    direction gets one ρ̂ from all three (its s.e. √((1−ρ²)/723) = 0.016, a run's alone
    0.022–0.040). Runs of ρ 0.3 and 0.9 (paths read at different rates) differ far beyond
    their errors and keep their own."""
    rng = np.random.default_rng(4)
    lens = (241, 361, 121)
    r = np.vstack([ar1_noise(n, 0.9, 1e3, rng) for n in lens])
    rho = ar1(r, np.repeat([0, 1, 2], lens))
    assert (np.ptp(rho, axis=0) == 0).all(), rho[[0, 241, 602]]
    np.testing.assert_allclose(rho[0], 0.9, atol=0.035)
    r = np.vstack([ar1_noise(2000, 0.3, 1e3, rng), ar1_noise(2000, 0.9, 1e3, rng)])
    rho = ar1(r, np.repeat([0, 1], 2000))
    np.testing.assert_allclose(rho[:2000], 0.3, atol=0.05)
    np.testing.assert_allclose(rho[2000:], 0.9, atol=0.02)


@pytest.mark.parametrize("rho", [0.0, 0.8])
def test_the_simulators_noise_has_the_sigma_it_is_given_in_mm(rho):
    """ar1_noise(n, ρ, σ µm) is mm with stationary σ: 0.5 µm over 60 000 readings a direction
    reads 0.5e-3 mm within 3 % (the sample σ's spread under ρ = 0.8 is about 0.5 %)."""
    e = ar1_noise(60_000, rho, 0.5, np.random.default_rng(12))
    np.testing.assert_allclose(e.std(axis=0), 0.5e-3, rtol=0.03)


def test_single_bad_readings_are_found_and_a_smooth_error_is_not():
    rng = np.random.default_rng(4)
    n = 241
    angle = np.linspace(0, 2 * np.pi, n)
    smooth = 20 * np.column_stack([np.cos(2 * angle), np.sin(3 * angle), np.cos(angle)])   # µm
    r = smooth + rng.normal(0, 0.5, (n, 3))
    seg = np.zeros(n, int)
    assert outliers(r, seg)[0].size == 0
    bad = [17, 120, 240]                       # one at the end of the segment too
    r[bad] += [[20, 0, 0], [0, -20, 0], [0, 0, 20]]
    found, size = outliers(r, seg)
    assert found.tolist() == bad
    np.testing.assert_allclose(size, 20, atol=2.5)


def test_an_outlier_on_a_slope_is_measured_from_its_neighbours_median():
    """Readings climbing 0.3 µm a reading (an axis moving through a linear error), 0.05 µm
    noise, one reading 20 µm off: it is found, alone, and its size is its step from the median
    of its four neighbours (the middle two's mean), 20 µm within 3 σ of the step's noise, not
    the 20.3 µm that one side's neighbour would give."""
    rng = np.random.default_rng(11)
    n = 200
    r = rng.normal(0, 0.05, (n, 3))
    r[:, 0] += np.arange(n) * 0.3
    r[100, 0] += 20
    found, size = outliers(r, np.zeros(n, int))
    assert found.tolist() == [100]
    assert size[0] == pytest.approx(20, abs=3 * 0.05 * np.sqrt(1 + 1 / 2))


@pytest.mark.parametrize("step", [0.0, 0.5])
def test_noiseless_data_has_no_outliers(step):
    """With no noise the robust scale is zero: only a step beyond OUTLIER_MIN_UM (1 µm)
    counts."""
    assert OUTLIER_MIN_UM == 1.0
    r = np.zeros((50, 3))
    r[10, 0] = step
    assert outliers(r, np.zeros(50, int))[0].size == 0


@pytest.mark.parametrize("sigma_um", [0.1, 2.0])
def test_the_outlier_threshold_is_in_robust_standard_deviations_of_the_step(sigma_um):
    """At any noise level, a step of 12 robust s.d. from the neighbours' median is an outlier
    and one of 5 is not (OUTLIER_Z = 8); the step's s.d. is estimated from the data."""
    rng = np.random.default_rng(8)
    r = rng.normal(0, sigma_um, (600, 3))
    seg = np.zeros(600, int)
    d = np.array([r[i, 0] - np.median(np.r_[r[i - 2:i, 0], r[i + 1:i + 3, 0]]) for i in range(2, 598)])
    s = 1.4826 * np.median(np.abs(d))                      # the step's robust s.d., here
    r[100, 0] += 12 * s + OUTLIER_MIN_UM
    r[300, 0] += 5 * s
    found, _ = outliers(r, seg)
    assert found.tolist() == [100]


def test_single_readings_have_no_neighbours_and_no_outliers():
    assert outliers(np.full((4, 3), 50.0), np.arange(4))[0].size == 0


def test_a_random_walk_is_held_at_rho_max():
    from compgen.statistics.noise import RHO_MAX
    walk = np.cumsum(np.random.default_rng(9).normal(size=(4000, 3)), axis=0)
    assert (ar1(walk, np.zeros(4000, int)) == RHO_MAX).all()


def test_the_ar1_covariance_is_the_sandwich_with_the_correlation_matrix_written_out():
    """(JᵀJ)⁻¹ JᵀΣJ (JᵀJ)⁻¹ with Σ built entry by entry, σ²·ρ^|i−j| within a run and
    direction, 0 across: two runs of different ρ in each direction, one direction white,
    runs long enough (900) that the recursion is taken in several blocks (ρ = 0.2)."""
    from compgen.statistics.noise import ar1_covariance
    rng = np.random.default_rng(4)
    n, p = 1500, 4
    seg = np.repeat([0, 1], [900, 600])
    rho = np.zeros((n, 3))
    rho[seg == 0] = [0.9, 0.2, 0.0]
    rho[seg == 1] = [0.5, 0.0, 0.97]
    J = rng.normal(size=(p, n, 3)) + np.linspace(0, 3, n)[None, :, None]
    r = rng.normal(size=(n, 3))
    dof = 3 * n - p
    flat = J.reshape(p, -1).T                       # reading k = 3·i + d
    sigma = np.zeros((3 * n, 3 * n))
    for s in (0, 1):
        at = np.flatnonzero(seg == s)
        lag = np.abs(at[:, None] - at[None, :])
        for d in range(3):
            s2 = r[at, d] @ r[at, d] / len(at) * 3 * n / dof
            sigma[np.ix_(3 * at + d, 3 * at + d)] = s2 * rho[at[0], d] ** lag
    inv = np.linalg.inv(flat.T @ flat)
    want = inv @ flat.T @ sigma @ flat @ inv
    np.testing.assert_allclose(ar1_covariance(J, r, seg, rho, dof), want, rtol=1e-9, atol=0)


def test_whitening_in_parts_equals_whitening_whole():
    """A series whitened block by block, each block carrying the row before it, is the
    series whitened at once: across a block's edge inside a run, and where a run starts
    at a block's edge."""
    rng = np.random.default_rng(5)
    x = rng.normal(size=(40, 3, 2))
    seg = np.repeat([0, 1, 2], [17, 10, 13])
    rho = np.where(seg[:, None] == 1, 0.3, 0.8) * np.ones((40, 3))
    whole = whiten(x, seg, rho)
    for edges in ([0, 9, 27, 40], [0, 17, 40], [0, 5, 6, 30, 40]):
        parts, before = [], None
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            parts.append(whiten(x[a:b], seg[a:b], rho[a:b], before))
            before = (x[b - 1], seg[b - 1])
        np.testing.assert_allclose(np.concatenate(parts), whole, rtol=0, atol=1e-15)


def test_the_lag_one_estimate_is_corrected_for_its_bias():
    """1000 runs of 200 readings of AR(1) noise with ρ = 0.6, each less its mean (as a fit's
    residual is): the mean ρ̂ is 0.6 within 0.01. Uncorrected, the lag-1 estimate sits
    (1 + 3ρ)/n = 0.014 low (Kendall); corrected the wrong way, 0.028 low."""
    rng = np.random.default_rng(1)
    runs, n, rho = 1000, 200, 0.6
    e = rng.normal(size=(runs, n, 3))
    x = np.empty_like(e)
    x[:, 0] = e[:, 0] / np.sqrt(1 - rho**2)
    for t in range(1, n):
        x[:, t] = rho * x[:, t - 1] + e[:, t]
    x -= x.mean(axis=1, keepdims=True)
    got = ar1(x.reshape(-1, 3), np.repeat(np.arange(runs), n))[::n]
    assert abs(got.mean() - rho) < 0.01, got.mean()


def test_poses_repeat_only_with_the_same_ball_and_axes_to_the_csvs_resolution(seed_machine):
    """K4 at one ball and again 100 mm higher: the same commanded axes, another ball, so no
    pose repeats one of the other session; K4 run twice at one ball repeats pose for pose,
    but its first; a ball or an X 2 µm off (beyond the CSV's 1e-6 mm) is another pose, 0.4 nm
    off the same; C 2e-6° off (beyond the CSV's 1e-6°) another, 3e-7° off the same."""
    from compgen.model.paths import generate
    from compgen.model.poses import Poses, runs
    from compgen.model.sides import same_pose
    k4 = generate(seed_machine, ["K4"])
    x, c = seed_machine.index("X"), seed_machine.index("C")
    q = k4.q.copy()
    q[:, x] = np.round(q[:, x], 6)             # X and C as a CSV holds them
    q[:, c] = np.radians(np.round(np.degrees(q[:, c]), 6))
    a = Poses(q, k4.ball, k4.t, k4.path)
    for dz, dx, dc, repeated in ((100.0, 0, 0, False), (0.0, 0, 0, True), (0.002, 0, 0, False),
                                 (4e-7, 0, 0, True), (0.0, 4e-7, 0, True), (0.0, 0.002, 0, False),
                                 (0.0, 0, 3e-7, True), (0.0, 0, 2e-6, False)):
        q = a.q.copy()
        q[:, x] += dx
        q[:, c] += np.radians(dc)
        b = Poses(q, a.ball + [0.0, 0.0, dz], a.t, a.path)
        both = Poses.concat([a, b])
        group = same_pose(seed_machine, both, runs(both))
        n = len(a)
        assert len(set(group[:n])) > 0.9 * n          # K4's poses are not one another's repeats
        same = group[:n] == group[n:]
        # (a run's first pose, reached by no move of its run yet, repeats only its own run's)
        assert (same[1:].all() and not same[0]) if repeated else not same.any(), same.sum()


def _three_runs_and_their_fit(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Three runs of n/3 readings and the orthonormal basis of a fit of 15 columns to them:
    each run's constant and two smooth shapes, per direction."""
    seg = np.repeat([0, 1, 2], n // 3)
    t = np.linspace(0, 1, n)
    cols = []
    for d in range(3):
        for shape in [*(seg == s for s in range(3)), np.sin(3 * t), np.cos(5 * t)]:
            c = np.zeros((n, 3))
            c[:, d] = shape
            cols.append(c.ravel())
    return seg, np.linalg.qr(np.array(cols).T)[0]


@pytest.mark.parametrize("rho", [0.5, 0.9])
def test_the_estimate_is_matched_beyond_the_span_the_fit_took_out(rho):
    """400 sessions of three runs of 80 readings, AR(1) noise, less their least-squares fit
    of 15 columns (each run's constant and two smooth shapes, per direction): the smooth
    columns take low frequencies, and so correlation, with them. Given their span, the mean
    ρ̂ is ρ within 0.005 (its own s.e. over 400 sessions: 0.001); Kendall's correction for a
    run's mean alone leaves it 0.02 (at 0.5) to 0.04 (at 0.9) low."""
    rng = np.random.default_rng(7)
    n, sessions = 240, 400
    seg, B = _three_runs_and_their_fit(n)
    matched, kendall = [], []
    for _ in range(sessions):
        e = np.vstack([ar1_noise(n // 3, rho, 1e3, rng) for _ in range(3)]).ravel()
        r = (e - B @ (B.T @ e)).reshape(n, 3)
        matched.append(ar1(r, seg, B).mean())
        kendall.append(ar1(r, seg).mean())
    assert abs(np.mean(matched) - rho) < 0.005, np.mean(matched)
    assert np.mean(kendall) < rho - 0.015, np.mean(kendall)


@pytest.mark.parametrize("n, rho, made", [(150_000, 0.0, False), (150_000, 0.3, True), (240, 0.0, True)])
def test_a_lazy_basis_is_made_only_where_a_rho_could_reach_the_floor(n, rho, made):
    """Three runs less their fit of 15 columns: white noise at streaming size is told white
    without the basis (nothing the basis could do lifts its ρ̂ to the floor); correlated
    noise, and a short run where the bound says nothing, make it. Either way ρ̂ is the one
    the basis given at once gives."""
    rng = np.random.default_rng(3)
    seg, B = _three_runs_and_their_fit(n)
    e = np.vstack([ar1_noise(n // 3, rho, 1e3, rng) for _ in range(3)]).ravel()
    r = (e - B @ (B.T @ e)).reshape(n, 3)
    calls = []
    got = ar1(r, seg, Lazy(B.shape[1], lambda: calls.append(1) or B))
    assert bool(calls) is made
    np.testing.assert_array_equal(got, ar1(r, seg, B))
    assert bool(got.any()) is (rho > 0)
