"""Continuous sessions: a reading every 1/rate s while the paths run (issue 25)."""

import numpy as np
import pytest
from conftest import SEED_MACHINE, run

from compgen.data.rtest import read_rtest
from compgen.errors import CompgenError
from compgen.model.paths import generate

TRUTH = SEED_MACHINE.parents[1] / "examples" / "truth-table4.json"


def test_a_continuous_path_takes_its_arc_at_the_feed_sampled_at_the_rate(seed_machine):
    """K2 turns C 360° at A = 0: at 720 deg/min that is 30 s, at 50 Hz 1501 readings 20 ms
    apart, C evenly from 0 to 360°."""
    poses = generate(seed_machine, ["K2"], rate_hz=50, feed=720)
    assert len(poses) == 1501
    np.testing.assert_allclose(np.diff(poses.t), 0.02, rtol=1e-12)
    c = np.degrees(poses.q[:, seed_machine.index("C")])
    np.testing.assert_allclose(c, np.linspace(0, 360, 1501), atol=1e-9)


def test_a_feed_below_one_degree_a_minute_is_a_feed(seed_machine):
    """Any finite feed above zero is one: K2's 360° at 0.9 deg/min (a soak) take 400 min,
    sampled at 0.01 Hz 241 readings 100 s apart; zero is refused."""
    poses = generate(seed_machine, ["K2"], rate_hz=0.01, feed=0.9)
    assert len(poses) == 241
    np.testing.assert_allclose(np.diff(poses.t), 100.0, rtol=1e-12)
    with pytest.raises(CompgenError, match="feed must be a finite number > 0 deg/min, not 0"):
        generate(seed_machine, ["K2"], rate_hz=0.01, feed=0.0)


def test_simulate_writes_a_continuous_session_that_reads_back(tmp_path, seed_machine):
    out = tmp_path / "s.csv"
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", TRUTH, "--paths", "K2",
                       "--rate-hz", "100", "--feed", "3600", "--noise-um", "0.5", "--noise-rho", "0.9",
                       "--seed", "1", "-o", out)
    assert code == 0, err
    data = read_rtest(out, seed_machine)
    assert len(data) == 601 and data.poses.t[1] == 0.01


def test_a_feed_the_axis_cannot_reach_is_refused_and_nothing_written(tmp_path):
    """K1 sweeps A 180°: at 6000 deg/min A would pass its feed_max of 5400."""
    out = tmp_path / "s.csv"
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", TRUTH, "--paths", "K1",
                       "--rate-hz", "100", "--feed", "6000", "-o", out)
    assert code == 2 and "A at up to 6000 deg/min, above its feed_max 5400" in err, err
    assert len(err.strip().splitlines()) <= 2 and not out.exists()
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", TRUTH, "--feed", "600", "-o", out)
    assert code == 2 and "--rate-hz" in err and not out.exists(), err


@pytest.mark.parametrize("rate, feed, said", [
    ("0", "600", "finite number > 0 Hz"), ("nan", "600", "'nan' is not a finite number"),
    ("inf", "600", "'inf' is not a finite number"), ("100", "0", "finite number > 0 deg/min"),
    ("1e-9", "600", "fewer than two readings"),               # a rate no path can be sampled at
    ("1e9", "3000", "more than 2796202 readings"),            # a session no data file could hold
])
def test_a_rate_or_feed_that_makes_no_session_is_refused_in_one_line(tmp_path, rate, feed, said):
    out = tmp_path / "s.csv"
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", TRUTH, "--rate-hz", rate,
                       "--feed", feed, "-o", out)
    assert code == 2 and said in err and len(err.strip().splitlines()) == 1 and not out.exists(), err


def test_a_dense_sessions_plots_draw_thinned_series_and_count_every_reading(seed_machine, monkeypatch):
    """A 12 001-pose continuous K2: no series draws more than DRAWN points, the titles say
    so, and the RMS in each legend is that of all the readings (2 µm added in dX to the
    readings that are not drawn makes the two differ)."""
    import matplotlib.axes

    from compgen.data.simulate import simulate
    from compgen.reports import plots
    from compgen.statistics.identify import fitted, identify
    poses = generate(seed_machine, ["K2"], rate_hz=100, feed=180)
    data = simulate(seed_machine, {"XOC": 2e-3}, poses, 0.5, np.random.default_rng(3))
    hidden = np.ones(len(poses), bool)
    hidden[::4] = False
    data.deviation[hidden, 0] += 2e-3
    fit = identify(seed_machine, [data], model=["XOC", "YOC"])
    drawn, labels, titles = [], [], []
    plot, title = matplotlib.axes.Axes.plot, matplotlib.axes.Axes.set_title
    monkeypatch.setattr(matplotlib.axes.Axes, "plot", lambda self, *a, **k: (
        drawn.append(len(a[0])), labels.append(k.get("label", "")), plot(self, *a, **k))[-1])
    monkeypatch.setattr(matplotlib.axes.Axes, "set_title", lambda self, t, **k: (
        titles.append(t), title(self, t, **k))[-1])
    images = plots.figures(seed_machine, [data], fit)
    assert len(poses) == 12001 and max(drawn) <= plots.DRAWN, max(drawn)
    assert all("every 4th of 12001 readings drawn" in t for t in titles), titles
    res = (data.deviation - fitted(seed_machine, fit, [data])) * 1e3
    rms = np.sqrt((res**2).mean(axis=0))
    assert abs(rms[0] - np.sqrt((res[::4, 0] ** 2).mean())) > 0.2
    legends = [f"K2: RMS {v:.2f} µm" for v in rms] * sum(k.startswith("residual-vs-") for k in images)
    assert legends == [x for x in labels if x.startswith("K2: RMS")]


@pytest.mark.parametrize("readings", [2, 3])
def test_a_path_sampled_at_two_or_three_readings_is_a_session_of_that_many(seed_machine, readings):
    """The least a continuous path can be is two readings, its start and its end: a rate
    that gives two or three over K2's run makes a session of exactly that many, from the
    path's first pose to its last."""
    whole = generate(seed_machine, ["K2"], rate_hz=100, feed=600)
    seconds = whole.t[-1] - whole.t[0]
    poses = generate(seed_machine, ["K2"], rate_hz=(readings - 1) / seconds, feed=600)
    assert len(poses) == readings
    np.testing.assert_allclose(poses.q[[0, -1]], whole.q[[0, -1]], atol=1e-9)
