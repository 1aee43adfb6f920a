"""The plots read back against what they claim to draw: every series in the unit its axis
names, on the panel its title and legend sit on, thinned evenly, in compgen's look; the
trend's band and marks where the history puts them."""

from datetime import datetime, timedelta
from types import SimpleNamespace

import matplotlib
import matplotlib.dates
import matplotlib.pyplot as plt
import numpy as np
import pytest

from compgen.controllers import template_dir
from compgen.data.simulate import simulate
from compgen.errors import CompgenError, one_line
from compgen.history.drift import Entry
from compgen.model.paths import generate
from compgen.reports import plots
from compgen.statistics.identify import fitted, identify
from compgen.statistics.spectrum import MIN_PITCH_MM

UM = 1e-3
TRUTH = {"XOC": 8 * UM, "YOC": -5 * UM, "AOC": np.radians(6 / 3600), "YOA": 4 * UM}


@pytest.fixture(scope="module")
def session(seed_machine):
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    data = [simulate(seed_machine, TRUTH, poses, 0.5, np.random.default_rng(11))]
    return (data, identify(seed_machine, data),
            identify(seed_machine, data, model=["XOC", "YOC"]))


def _drawn(seed_machine, session, found=None):
    data, fit, before = session
    figs = plots.drawings(seed_machine, data, fit, before, found)
    return figs, data[0], fit, before


def _series(ax, label):
    line = next(x for x in ax.get_lines() if x.get_label() == label)
    return line.get_xdata(), line.get_ydata()


def _close(figs):
    for f in figs.values():
        plt.close(f)


def test_measured_and_model_are_drawn_in_micrometres_per_path(seed_machine, session):
    figs, data, fit, before = _drawn(seed_machine, session)
    try:
        dev, model = data.deviation * 1e3, fitted(seed_machine, fit, [data]) * 1e3
        earlier = fitted(seed_machine, before, [data]) * 1e3
        for path in ("K4", "K1", "K2"):
            axes = figs[f"measured-vs-model-{path}.png"].axes
            sel = np.flatnonzero(data.poses.path == path)
            for k, ax in enumerate(axes):
                assert ax.get_ylabel() == f"{plots.DIRECTIONS[k]} (µm)"
                x, y = _series(ax, "measured")
                np.testing.assert_array_equal(x, np.arange(len(sel)))
                np.testing.assert_allclose(y, dev[sel, k], rtol=0, atol=1e-12)
                np.testing.assert_allclose(_series(ax, f"model ({len(fit.model)} parameters)")[1],
                                           model[sel, k], atol=1e-12)
                np.testing.assert_allclose(_series(ax, f"before ({len(before.model)} parameters)")[1],
                                           earlier[sel, k], atol=1e-12)
            # the title and legend on the top panel, the pose axis named on the bottom one
            assert axes[0].get_title().startswith(f"{path}: measured vs model, {seed_machine.name}")
            assert [ax.get_legend() is not None for ax in axes] == [True, False, False]
            assert [ax.get_xlabel() for ax in axes] == ["", "", "pose"]
    finally:
        _close(figs)


def test_the_residual_against_each_axis_is_measured_less_model_at_the_axis_position(seed_machine, session):
    figs, data, fit, before = _drawn(seed_machine, session)
    try:
        residual = data.deviation * 1e3 - fitted(seed_machine, fit, [data]) * 1e3
        earlier = data.deviation * 1e3 - fitted(seed_machine, before, [data]) * 1e3
        q = data.poses.q
        for axis in seed_machine.axes:
            where = q[:, seed_machine.index(axis.name)]
            name = f"residual-vs-{axis.name}.png"
            if not axis.rotary and np.ptp(where) < MIN_PITCH_MM:
                assert name not in figs
                continue
            where = np.degrees(where) if axis.rotary else where
            axes = figs[name].axes
            for k, ax in enumerate(axes):
                x, y = _series(ax, f"before: RMS {before.residual['rms_um']:.2f} µm")
                np.testing.assert_allclose(x, where, atol=1e-12)
                np.testing.assert_allclose(y, earlier[:, k], atol=1e-12)
                for path in ("K4", "K1", "K2"):
                    sel = np.flatnonzero(data.poses.path == path)
                    rms = np.sqrt((residual[sel, k] ** 2).mean())
                    x, y = _series(ax, f"{path}: RMS {rms:.2f} µm")
                    np.testing.assert_allclose(x, where[sel], atol=1e-12)
                    np.testing.assert_allclose(y, residual[sel, k], atol=1e-12)
            assert axes[0].get_title().startswith(f"residual against {axis.name} per path")
            assert [ax.get_legend() is not None for ax in axes] == [True, False, False]
            assert axes[-1].get_xlabel() == f"{axis.name} ({'deg' if axis.rotary else 'mm'})"
            assert axes[0].get_xlabel() == ""
        assert {"residual-vs-A.png", "residual-vs-C.png"} <= set(figs)
    finally:
        _close(figs)


def test_the_figures_take_compgens_look_from_its_style_sheet(seed_machine, session):
    sheet = matplotlib.rc_params_from_file(template_dir() / plots.STYLE, use_default_template=False)
    figs, *_ = _drawn(seed_machine, session)
    try:
        for fig in figs.values():
            assert fig.dpi == sheet["figure.dpi"]
            np.testing.assert_allclose(fig.get_size_inches(), sheet["figure.figsize"])
    finally:
        _close(figs)
    assert plt.rcParams["figure.dpi"] != sheet["figure.dpi"]      # outside the plots, the user's look


@pytest.mark.parametrize("n", [3, plots.DRAWN, plots.DRAWN + 1, 2 * plots.DRAWN, 3 * plots.DRAWN + 7])
def test_a_dense_series_is_thinned_evenly_from_its_first_reading(n):
    index = np.arange(n) + 10
    drawn = plots._drawn(index)
    step = -(-n // plots.DRAWN)                        # the least step that draws ≤ DRAWN
    assert len(drawn) <= plots.DRAWN and drawn[0] == 10
    assert set(np.diff(drawn)) <= {step} and len(drawn) == -(-n // step)
    assert plots._thinned(n) == (f" (every {step}th of {n} readings drawn)" if n > plots.DRAWN else "")


def test_plots_are_written_whole_into_a_new_folder_and_a_file_in_the_way_is_refused(seed_machine, session,
                                                                                     tmp_path):
    data, fit, before = session
    written = plots.write_plots(tmp_path / "a" / "b", seed_machine, data, fit)
    assert sorted(p.name for p in written) == sorted(p.name for p in (tmp_path / "a" / "b").iterdir())
    assert "measured-vs-model-K4.png" in {p.name for p in written}
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in written)
    (tmp_path / "file").write_text("x")
    with pytest.raises(CompgenError, match="cannot make the plot folder"):
        plots.write_plots(tmp_path / "file" / "plots", seed_machine, data, fit)


def test_rivals_are_drawn_on_the_residual_and_said_equal_only_within_a_hundredth_um(seed_machine, session,
                                                                                    monkeypatch):
    """With rivals, the residual (measured less model, µm) beside each rival's curves; a rival
    within ON_EACH_OTHER_UM of another on the advised measurement is labelled as equal."""
    data, fit, _ = session
    n, m = len(data[0].poses), 40
    base = np.linspace(-1, 1, 3 * m).reshape(m, 3)
    curves = {"A": (np.zeros((n, 3)), base), "B": (np.zeros((n, 3)), base + 0.005),   # µm
              "C": (np.zeros((n, 3)), base - 0.015)}
    monkeypatch.setattr(plots, "rival_curves", lambda *a: curves)
    extra = SimpleNamespace(label="K4 at half its radius")
    found = SimpleNamespace(lines=(), rivals=("B", "C"), rivals_separated_by=(extra,))
    figs = plots.drawings(seed_machine, data, fit, None, found)
    try:
        axes = figs["rivals.png"].axes
        # three directions, each with the measured poses three times the width of the advised
        assert len(axes) == 6
        assert axes[0].get_position().width / axes[1].get_position().width == pytest.approx(3)
        residual = data[0].deviation * 1e3 - fitted(seed_machine, fit, data) * 1e3
        for k in range(3):
            np.testing.assert_allclose(_series(axes[2 * k], "residual")[1], residual[:, k], atol=1e-12)
        labels = [x.get_label() for x in axes[1].get_lines()]
        assert labels == ["A", "B (= A on K4 at half its radius)", "C"], labels
        assert axes[0].get_legend() is not None and axes[2].get_legend() is None
        assert axes[-2].get_xlabel() == "pose (measured)" and axes[-1].get_xlabel() == "pose (to measure)"
        assert [ax.get_ylabel() for ax in axes] == ["dX (µm)", "", "dY (µm)", "", "dZ (µm)", ""]
        assert axes[1].get_title() == "K4 at half its radius:\nwhat each would leave" \
            and axes[0].get_title().startswith("measured")
    finally:
        _close(figs)


@pytest.mark.parametrize("count", [2, 7, 11])
def test_no_two_rivals_put_a_marker_on_the_same_pose(seed_machine, session, monkeypatch, count):
    """Rival curves lie on each other where the data cannot tell them apart: each is told by
    its marker, so no two curves mark the same pose, however many rivals (diagnose names up
    to ten), and each marks some pose of every panel."""
    data, fit, _ = session
    n, m = len(data[0].poses), 40
    curves = {f"R{i}": (np.zeros((n, 3)), np.zeros((m, 3))) for i in range(count)}
    monkeypatch.setattr(plots, "rival_curves", lambda *a: curves)
    found = SimpleNamespace(lines=(), rivals=tuple(curves)[1:],
                            rivals_separated_by=(SimpleNamespace(label="K4 at half its radius"),))
    figs = plots.drawings(seed_machine, data, fit, None, found)
    try:
        for ax in figs["rivals.png"].axes:
            marked = []
            for line in ax.get_lines():
                if line.get_label() == "residual":
                    continue
                start, step = line.get_markevery()
                marked.append(set(range(start, len(line.get_xdata()), step)))
            assert len(marked) == count and all(marked), [len(x) for x in marked]
            assert all(not (a & b) for i, a in enumerate(marked) for b in marked[i + 1:]), ax.get_title()
    finally:
        _close(figs)


def test_the_rivals_curves_are_what_a_fit_of_the_model_leaves_of_each(seed_machine, session):
    """Each rival's two curves against the exact model fitted anew: data holding only the
    effect at its size (µm, as diagnose gives it), the fit's own model fitted to the measured
    poses leaves the first curve; fitted to those and the advised poses together, it leaves
    the second on the advised ones. The plot's are first order: equal to 0.2 % of the curve."""
    from compgen.model.effects import resolve
    from compgen.units import shown
    data, fit, _ = session
    poses = data[0].poses
    extra = SimpleNamespace(poses=generate(seed_machine, ["K2"]).take(slice(0, 200, 2)), label="K2")
    rivals = (SimpleNamespace(effect="ECC:h2", amplitude=(2.0, -1.0)),       # ″
              SimpleNamespace(effect="EXC:h3", amplitude=(1.5, 1.0)))       # µm
    found = SimpleNamespace(candidates=rivals, significant=rivals[:1], rivals=("EXC:h3",))
    curves = plots.rival_curves(seed_machine, poses, fit, found, extra)
    assert set(curves) == {"ECC:h2", "EXC:h3"}
    for c in rivals:
        e = resolve(seed_machine, c.effect)
        truth = dict(zip(e.params, np.array(c.amplitude) / shown(1.0, e.unit)[0], strict=True))
        now, after = curves[c.effect]
        alone = simulate(seed_machine, truth, poses)
        refit = identify(seed_machine, [alone], fit.free)
        left = (alone.deviation - fitted(seed_machine, refit, [alone])) * 1e3
        both = [alone, simulate(seed_machine, truth, extra.poses)]
        refit = identify(seed_machine, both, fit.free)
        left_after = (both[1].deviation - fitted(seed_machine, refit, both[1:])) * 1e3
        assert np.abs(left).max() > 0.3 and np.abs(left_after).max() > 0.3      # µm: curves to see
        np.testing.assert_allclose(now, left, atol=2e-3 * np.abs(left).max())
        np.testing.assert_allclose(after, left_after, atol=2e-3 * np.abs(left_after).max())


def test_the_trend_draws_each_value_with_its_two_sigma_band_edits_and_flags(seed_machine):
    """Two parameters (mm and rad), three fits a week apart, an edit between the second and
    the third, the third fit flagged for XOC only."""
    t0 = datetime(2026, 11, 2, 8, 0)
    when = [(t0 + timedelta(days=7 * i)).isoformat() for i in range(3)]
    entries = [Entry(i, w, f"m{i}", "rtest", "rtest", "accepted", 0.5,
                     values={"XOC": (5 + i) * UM, "AOC": np.radians((2 - i) / 3600)},
                     std={"XOC": 0.4 * UM, "AOC": np.radians(0.5 / 3600)}, units={"XOC": "mm", "AOC": "rad"},
                     corrected={"XOC": 1 * UM}) for i, w in enumerate(when)]
    edit = (t0 + timedelta(days=10)).isoformat()
    t = SimpleNamespace(machine="m\nsecond line", params=("XOC", "AOC"), entries=entries,
                        edits=[{"taken": edit}], flags=[SimpleNamespace(param="XOC", taken=when[2])])
    fig = plots.trend_figure(t)
    try:
        axes = fig.axes
        assert [ax.get_ylabel() for ax in axes] == ["XOC (µm)", "AOC (″)"]
        days = matplotlib.dates.date2num([datetime.fromisoformat(w) for w in when])
        for ax, v, s in ((axes[0], [6, 7, 8], 0.4), (axes[1], [2, 1, 0], 0.5)):
            values = next(x for x in ax.get_lines() if x.get_marker() == "o" and x.get_linestyle() == "-")
            np.testing.assert_allclose(values.get_ydata(), v, atol=1e-9)
            band = ax.collections[0].get_paths()[0].vertices
            for d, value in zip(days, v, strict=True):
                ys = band[np.isclose(band[:, 0], d), 1]
                assert ys.min() == pytest.approx(value - 2 * s) and ys.max() == pytest.approx(value + 2 * s)
            edits = [x for x in ax.get_lines() if x.get_linestyle() == "--"]
            assert [x.get_xdata()[0] for x in edits] == [datetime.fromisoformat(edit)]
        flagged = [x for x in axes[0].get_lines() if x.get_markeredgecolor() == "red"]
        assert len(flagged) == 1 and list(flagged[0].get_ydata()) == pytest.approx([8])
        assert not [x for x in axes[1].get_lines() if x.get_markeredgecolor() == "red"]
        # a line break in a machine's name is written out, never a second title line
        assert "\n" not in axes[0].get_title() and axes[0].get_title().startswith(one_line(t.machine))
        # as wide as every figure of the style sheet, taller with each parameter
        sheet = matplotlib.rc_params_from_file(template_dir() / plots.STYLE, use_default_template=False)
        assert fig.get_size_inches()[0] == pytest.approx(sheet["figure.figsize"][0])
    finally:
        plt.close(fig)


def test_the_trend_draws_the_drift_limit_about_the_last_calibration(seed_machine):
    """The band a check judges against: the last accepted calibration's machine value ± the
    [drift] limit of the parameter's class, a step at each calibration (it drew ±2σ only)."""
    t0 = datetime(2026, 11, 2, 8, 0)
    when = [(t0 + timedelta(days=7 * i)).isoformat() for i in range(4)]
    kinds = ("calibration", "check", "calibration", "check")
    entries = [Entry(i, w, f"m{i}", kind, "rtest", "accepted", 0.5, values={"XOC": (5 + i) * UM},
                     std={"XOC": 0.4 * UM}, units={"XOC": "mm"}, corrected={})
               for i, (w, kind) in enumerate(zip(when, kinds, strict=True))]
    t = SimpleNamespace(machine="m", params=("XOC",), entries=entries, edits=[], flags=[])
    fig = plots.trend_figure(t, {"XOC": 5 * UM})
    try:
        ax = fig.axes[0]
        dotted = [x for x in ax.get_lines() if x.get_linestyle() == ":"]
        assert len(dotted) == 2 and "dotted: the [drift] limit" in ax.get_title()
        low, high = sorted(dotted, key=lambda x: float(np.nanmean(x.get_ydata())))
        # references 5, 5, 7, 7 µm: ± 5 µm
        np.testing.assert_allclose(low.get_ydata(), [0, 0, 2, 2], atol=1e-9)
        np.testing.assert_allclose(high.get_ydata(), [10, 10, 12, 12], atol=1e-9)
    finally:
        plt.close(fig)


def test_the_trend_draws_each_checked_paths_range_against_its_tolerance(seed_machine):
    """A panel per path the checks measured: its largest deviation range at each check, and
    the [tolerances] line it is judged against (the trend drew the location errors only)."""
    t0 = datetime(2026, 11, 2, 8, 0)
    when = [(t0 + timedelta(days=7 * i)).isoformat() for i in range(3)]
    entries = [Entry(i, w, f"m{i}", "check", "rtest", "check passed", 0.5, values={"XOC": 5 * UM},
                     std={"XOC": 0.4 * UM}, units={"XOC": "mm"}, corrected={}) for i, w in enumerate(when)]
    ranges = [(w, {"K4": 6.0 + i, "K2": 3.0}) for i, w in enumerate(when)]
    t = SimpleNamespace(machine="m", params=("XOC",), entries=entries, edits=[], flags=[], ranges=ranges)
    fig = plots.trend_figure(t, None, {"K4": 10.0, "K1": 8.0})
    try:
        assert [ax.get_ylabel() for ax in fig.axes] == ["XOC (µm)", "K4 range (µm)"]   # K1: never checked
        ax = fig.axes[1]
        checked = next(x for x in ax.get_lines() if x.get_marker() == "s")
        np.testing.assert_allclose(checked.get_ydata(), [6, 7, 8])
        tolerance = next(x for x in ax.get_lines() if x.get_linestyle() == ":")
        assert list(tolerance.get_ydata()) == [10.0, 10.0]
        assert "[tolerances]" in fig.axes[0].get_title()
    finally:
        plt.close(fig)
