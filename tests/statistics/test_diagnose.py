"""Model discovery on data with a hidden effect the base fit does not know (the scikit-rf
way: hide a known error, expect it found), on clean data, and on invisible effects."""

import json
import re
from itertools import combinations

import numpy as np
import pytest
from conftest import ARCSEC, SEED_MACHINE, TABLE4, UM, pasted, run

from compgen import me
from compgen.configuration.machine_file import load_machine
from compgen.data.rtest import RTestData, format_rtest
from compgen.data.simulate import ar1_noise, simulate
from compgen.model.effects import compose, location_model
from compgen.model.paths import generate
from compgen.planning.advice import Advisor
from compgen.statistics.choice import with_choices
from compgen.statistics.diagnose import _per_axis, diagnose
from compgen.statistics.diagnose_text import report
from compgen.statistics.identify import fitted, identify
from compgen.statistics.results import FitResult

NOISE_UM = 0.5
RMS_AFTER_TOLERANCE = 0.25   # issue 3: after adding the effect, RMS within 25 % of the noise

HIDDEN = {   # name: parameters, at amplitudes a service engineer meets (1–5 µm at the ball)
    "ECC:h2": {"ECC:h2c": 2 * ARCSEC, "ECC:h2s": -1 * ARCSEC},    # C worm / 2/rev positioning
    "EXC:h3": {"EXC:h3c": 1.5 * UM, "EXC:h3s": 1 * UM},          # C radial, 3/rev
    "EAC:h2": {"EAC:h2c": 2 * ARCSEC, "EAC:h2s": 1 * ARCSEC},     # C tilt wobble, 2/rev
    "EAA:p1": {"EAA:p1": 3 * ARCSEC},                             # A positioning, per rad
    "EBA:p1": {"EBA:p1": 3 * ARCSEC},                             # A tilt, per rad of A
    "EYA:p2": {"EYA:p2": 2 * UM},                                 # A radial, quadratic in A
    "COX": {"COX": 5 * ARCSEC},                                   # squareness X to Y
    "BOZ": {"BOZ": 5 * ARCSEC},                                   # squareness Z to X
    "AOZ": {"AOZ": 5 * ARCSEC},                                   # squareness Z to Y
    "EYY:p1": {"EYY:p1": 10 * UM},                                # Y scale, 10 µm/m
    "EZZ:p1": {"EZZ:p1": 10 * UM},                                # Z scale, 10 µm/m
    "drift_Z:t1": {"drift_Z:t1": 4 * UM},                         # 4 µm/h thermal drift
    "drift_X:t1": {"drift_X:t1": 4 * UM},
}


@pytest.fixture(scope="module")
def poses(seed_machine):
    return generate(seed_machine, ["K4", "K1", "K2"])


def _session(machine, poses, hidden, seed=7):
    return simulate(machine, {**TABLE4, **hidden}, poses, NOISE_UM, np.random.default_rng(seed))


@pytest.mark.parametrize("name", HIDDEN)
def test_hidden_effect_is_named_first_and_adding_it_brings_rms_to_noise(seed_machine, poses, name):
    data = [_session(seed_machine, poses, HIDDEN[name])]
    base = identify(seed_machine, data)
    found = diagnose(seed_machine, data, base, advisor=Advisor)
    best = found.candidates[0]
    # a squareness of Z (BOZ, AOZ) and an angular error of the Z carriage growing with Z
    # (EBZ:p1, EAZ:p1) both move the nest by the tool length times an angle ∝ Z: with one
    # nest length no R-test path separates them, and diagnose must say so, not choose
    assert best.significant and (best.effect == name or name in found.rivals), \
        ([c.effect for c in found.candidates[:3]], found.rivals)
    assert base.residual["rms_um"] > 1.05 * NOISE_UM      # the misfit was there to be found
    best = next(c for c in found.candidates if c.effect == name)
    refit = identify(seed_machine, data, compose(seed_machine, base.model, [best.effect]))
    assert abs(refit.residual["rms_um"] - NOISE_UM) < RMS_AFTER_TOLERANCE * NOISE_UM
    assert abs(refit.residual["rms_um"] - best.rms_after_um) < 0.02   # first order predicted it


def test_ambiguous_scale_is_reported_with_the_measurement_that_resolves_it(seed_machine, poses, monkeypatch):
    # On these paths X ≈ x_ball·cos C: an X scale error looks like a 1/rev radial motion of C.
    hidden = {"EXX:p1": 10 * UM}
    data = [_session(seed_machine, poses, hidden)]
    found = diagnose(seed_machine, data, identify(seed_machine, data), advisor=Advisor)
    named = [found.significant[0].effect, *found.rivals]
    assert "EXX:p1" in named and len(named) > 1
    advice = [m for m in found.rivals_separated_by if "half its radius" in m.label]
    assert advice
    # what the plots draw: alike on the measured poses, apart on the advised measurement
    from compgen.reports import plots
    from compgen.reports.plots import _png as plots_png
    from compgen.reports.plots import figures, rival_curves
    fit = identify(seed_machine, data)
    curves = rival_curves(seed_machine, poses, fit, found, found.rivals_separated_by[0])
    best, scale = curves[found.significant[0].effect], curves["EXX:p1"]
    assert np.sqrt(((scale[0] - best[0]) ** 2).mean()) < 0.05 * np.sqrt((best[0] ** 2).mean())
    apart = float(((scale[1] - best[1]) ** 2).sum())                  # µm² over the readings
    assert apart >= 25 * NOISE_UM**2, apart                           # TELLS_APART σ²
    drawn = []                                     # the figures as drawn, before their PNG
    monkeypatch.setattr(plots, "_png", lambda fig: drawn.append(fig) or plots_png(fig))
    assert "rivals.png" in figures(seed_machine, data, fit, None, found)
    rivals = next(f for f in drawn if f.axes[0].get_title().startswith("measured: the rivals"))
    widths = [line.get_linewidth() for line in rivals.axes[0].get_lines()[1:]]   # after the residual
    assert len(widths) == len(curves) and all(np.diff(widths) < 0), widths
    assert widths[-1] >= 1 and widths[0] <= 4      # each beneath shows round the one on it; none blots
    # follow the advice: add K4 with the ball at half its radius, and the tie is broken
    half = generate(seed_machine, ["K4"], ball=np.asarray(seed_machine.ball) * [0.5, 0.5, 1.0])
    data.append(_session(seed_machine, half, hidden, seed=8))
    found = diagnose(seed_machine, data, identify(seed_machine, data), advisor=Advisor)
    assert found.candidates[0].effect == "EXX:p1" and found.candidates[0].significant
    assert "EXX:p1" not in found.rivals


def test_clean_data_flag_nothing(seed_machine, poses):
    data = [_session(seed_machine, poses, {})]
    found = diagnose(seed_machine, data, identify(seed_machine, data), advisor=Advisor)
    assert not found.significant
    assert found.to_dict()["explained_to_noise"]
    assert "explains these data to the noise level" in report(found)


def test_invisible_effects_are_never_found_and_their_confounding_is_reported(seed_machine, poses):
    hidden = {"nest_X": 5 * UM, "EZC:h1c": 3 * UM}   # nest set-up offset; axial 1/rev of C
    data = [_session(seed_machine, poses, hidden)]
    base = identify(seed_machine, data)
    found = diagnose(seed_machine, data, base, advisor=Advisor)
    assert not found.significant
    by_name = {c.effect: c for c in found.candidates}
    for name in ("nest_X", "EZC:h1"):
        assert not by_name[name].visible and not by_name[name].significant
        assert by_name[name].confounded_with
    assert by_name["nest_X"].confounded_with[0] == "XOC" and not by_name["nest_X"].separated_by
    assert any("ball" in m.label for m in by_name["EZC:h1"].separated_by)
    # the invisible effects bias the parameters without a trace in the residual
    assert abs(base.parameters["XOC"].value - TABLE4["XOC"]) > 4 * UM
    assert base.residual["rms_um"] < 1.05 * NOISE_UM


def test_bias_sensitivity_predicts_the_shift_a_hidden_effect_causes(seed_machine, poses):
    amplitude_um = 2.0
    hidden = {"EXC:h2c": amplitude_um * UM}
    clean, biased = (identify(seed_machine, [simulate(seed_machine, {**TABLE4, **h}, poses)])
                     for h in ({}, hidden))
    found = diagnose(seed_machine, [simulate(seed_machine, TABLE4, poses)], clean, advisor=Advisor)
    for name in TABLE4:
        shift = (biased.parameters[name].value - clean.parameters[name].value)
        shift_shown = shift / (UM if name[0] in "XYZ" else ARCSEC)
        predicted = found.bias[name]["EXC:h2c"] * amplitude_um
        assert shift_shown == pytest.approx(predicted, abs=0.01), name   # first order, 2 µm


def test_json_contract(seed_machine, poses):
    data = [_session(seed_machine, poses, HIDDEN["ECC:h2"])]
    d = diagnose(seed_machine, data, identify(seed_machine, data), advisor=Advisor).to_dict()
    assert isinstance(d["rms_um"], float)
    first = d["candidates"][0]
    assert {"effect", "significant", "rms_after_um", "confounded_with", "description"} <= set(first)
    assert first["effect"] == "ECC:h2" and first["significant"] is True
    rms = [c["rms_after_um"] for c in d["candidates"] if c["visible"]]
    assert rms == sorted(rms)                                 # best first
    for c in d["candidates"]:                                 # every name is one --add takes
        compose(seed_machine, ["XOC"], [c["effect"]])
    # the figures read back against their definitions: RMS over every reading as the fit has
    # it, units as a person reads them, a turning axis's terms 1 to 4 per revolution
    fit = identify(seed_machine, data)
    assert d["rms_um"] == pytest.approx(fit.residual["rms_um"], rel=1e-9)
    assert d["sigma_um"] == pytest.approx(fit.residual["sigma_um"], rel=1e-9)
    assert d["readings"] == 3 * len(data[0].poses)
    assert set(d["bias_sensitivity"]["units"].values()) <= {"µm", "″"}
    assert set(d["per_axis"]["C"]) == {"1/rev", "2/rev", "3/rev", "4/rev"}


def test_the_residual_against_an_axis_is_told_in_micrometres(seed_machine):
    """A 3/rev radial error of C of 1.8 µm (1.5 cos, 1 sin), K4 alone (C turns a whole turn;
    the location errors hold no 3/rev): diagnose's per-axis table reads it back in dX at
    C 3/rev, within 3 σ of the least-squares amplitude (σ ≈ 0.5 µm·√(2/241) = 0.05 µm)."""
    k4 = generate(seed_machine, ["K4"])
    data = [_session(seed_machine, k4, HIDDEN["EXC:h3"])]
    c = diagnose(seed_machine, data, identify(seed_machine, data)).per_axis["C"]
    sigma = NOISE_UM * np.sqrt(2 / len(k4))
    assert c["3/rev"][0] == pytest.approx(np.hypot(1.5, 1.0), abs=3 * sigma)
    assert max(c["3/rev"][1:]) < 3 * sigma


def test_diagnose_whole_catalogue_on_the_bc_machine(bc_machine):
    poses = generate(bc_machine, ["K4", "K1", "K2"])
    hidden = {"ECB:p1": 4 * ARCSEC}                           # B tilt about Z, per rad of B
    data = [simulate(bc_machine, hidden, poses, NOISE_UM, np.random.default_rng(3))]
    found = diagnose(bc_machine, data, identify(bc_machine, data), advisor=Advisor)
    assert found.candidates[0].effect == "ECB:p1" and found.candidates[0].significant


def _with_noise(machine, poses, hidden, noise_mm):
    dev = simulate(machine, {**TABLE4, **hidden}, poses).deviation
    return RTestData(poses, dev + noise_mm, "s.csv", "", tuple(range(2, len(poses) + 2)))


def _ar1_mm(n, rho, rng):
    return ar1_noise(n, rho, NOISE_UM, rng)


def _predicts_unmeasured_balls(machine, truth, fit):
    """RMS (µm, a constant per set-up aside) of the fitted model against the truth on K4 at
    two ball positions never measured."""
    worst = 0.0
    for ball in ([-150.0, 120.0, 180.0], [120.0, -100.0, 260.0]):
        poses = generate(machine, ["K4"], ball=ball)
        err = (simulate(machine, {n: fit.parameters[n].value for n in fit.model}, poses).deviation
               - simulate(machine, truth, poses).deviation)
        worst = max(worst, float(np.sqrt(((err - err.mean(axis=0)) ** 2).mean())) * 1e3)
    return worst


def test_outliers_are_listed_where_the_user_finds_them_and_flag_nothing(seed_machine, poses):
    rng = np.random.default_rng(21)
    noise = rng.normal(0, NOISE_UM * 1e-3, (len(poses), 3))
    bad = [40, 300, 650]
    noise[bad] += [[0.02, 0, 0], [0, -0.02, 0], [0, 0, 0.02]]
    data = [_with_noise(seed_machine, poses, {}, noise)]
    fit = identify(seed_machine, data)
    assert fit.residual["sigma_um"] > 1.3 * NOISE_UM            # the fit itself is inflated
    found = diagnose(seed_machine, data, fit, advisor=Advisor)
    assert [(o["file"], o["line"], o["path"]) for o in found.outliers] == \
        [("s.csv", i + 2, poses.path[i]) for i in bad]
    assert all(abs(o["size_um"] - 20) < 3 for o in found.outliers)
    assert not found.significant
    assert found.to_dict()["outliers"] == list(found.outliers)
    assert "s.csv:42  path K4" in report(found)


def test_correlated_noise_flags_nothing_because_it_is_whitened(seed_machine, poses, monkeypatch):
    """AR(1) noise, ρ = 0.8 between consecutive readings: nothing is flagged; the same data
    tested as if the noise were white flag effects (what diagnose did before)."""
    data = [_with_noise(seed_machine, poses, {}, _ar1_mm(len(poses), 0.8, np.random.default_rng(5)))]
    fit = identify(seed_machine, data)
    found = diagnose(seed_machine, data, fit, advisor=Advisor)
    assert not found.significant, [c.effect for c in found.significant]
    assert all(0.6 < rho < 0.95 for rhos in found.noise.values() for rho in rhos), found.noise
    assert all(round(rho, 3) == rho for rhos in found.noise.values() for rho in rhos)    # as documented
    assert "AR(1)" in report(found)
    import compgen.statistics.diagnose as module
    monkeypatch.setattr(module, "ar1", lambda r, seg, basis=None, margin=0.0: np.zeros_like(r))
    assert diagnose(seed_machine, data, fit, advisor=Advisor).significant


def test_two_significant_drifts_whose_second_was_made_before_are_tested_after_the_best(seed_machine, poses):
    """Clean data under AR(1) ρ = 0.8 where chance made two of C's drifts significant when the
    tests whitened at ρ̂ itself: the second's columns were made while ranking, none was left
    to walk after the best, and ``products`` of no effects was an internal error (a reshape of
    no columns) instead of a diagnosis. Whitened one standard error above ρ̂, the session
    flags nothing; products of no effects are none."""
    data = [_with_noise(seed_machine, poses, {}, _ar1_mm(len(poses), 0.8, np.random.default_rng(1129)))]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    assert not found.significant and found.found is None, [c.effect for c in found.significant]
    from compgen.statistics.signature import products
    Q = np.linalg.qr(np.ones((3 * len(poses), 1)))[0]
    assert products(seed_machine, poses, [], Q, np.zeros(3 * len(poses))) == {}


def test_under_correlated_noise_a_real_effect_is_still_found(seed_machine, poses):
    hidden = {"ECC:h2c": 15 * ARCSEC}
    data = [_with_noise(seed_machine, poses, hidden, _ar1_mm(len(poses), 0.8, np.random.default_rng(6)))]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert found.found == "ECC:h2", ([c.effect for c in found.significant[:3]], found.rivals)


def test_a_turning_radial_motion_is_named_after_the_follow_ups_it_advises(seed_machine, poses):
    """The issue's 2/rev radial motion of C turning with C. At one ball it cannot be told
    from others; diagnose advises a measurement it has not got, as {label, path, ball};
    simulated and added, the advice leads to the compound, and the model it completes
    predicts K4 at two ball positions never measured."""
    truth = {**TABLE4, "EXC+EYC:h2c": 3 * UM}
    rng = np.random.default_rng(9)
    data = [_with_noise(seed_machine, poses, truth, rng.normal(0, NOISE_UM * 1e-3, (len(poses), 3)))]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert found.found is None and "EXC+EYC:h2" in (found.significant[0].effect, *found.rivals)
    followed = []
    for _ in range(3):
        if found.found:
            break
        m = found.rivals_separated_by[0]
        advice = found.to_dict()["rivals_separated_by"][0]
        assert advice == {"label": m.label, "path": m.path, "ball": [round(v, 4) for v in m.ball],
                          "there_and_back": m.back, "name": m.name, "right_after": m.again,
                          "leaves_open": [list(p) for p in found.rivals_open.get(m.label, ())]}
        command = m.options().split()                  # what the text tells the user to run
        assert command[command.index("--ball") + 1] == ",".join(f"{v:g}" for v in advice["ball"])
        assert m.label not in followed
        followed.append(m.label)
        extra = generate(seed_machine, [m.path], ball=m.ball, back=m.back)
        data.append(_with_noise(seed_machine, extra, truth, rng.normal(0, NOISE_UM * 1e-3, (len(extra), 3))))
        found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM,
                           advisor=Advisor)
    assert found.found == "EXC+EYC:h2", (followed, found.significant[0].effect, found.rivals)
    fit = identify(seed_machine, data, compose(seed_machine, identify(seed_machine, data).model,
                                               ["EXC+EYC:h2"]))
    assert abs(fit.residual["sigma_um"] - NOISE_UM) < RMS_AFTER_TOLERANCE * NOISE_UM
    assert _predicts_unmeasured_balls(seed_machine, truth, fit) < 1.0


def test_rivals_no_measurement_separates_are_said_to_be_equivalent(seed_machine, poses):
    """ECA = 20″·sin A: its part turning with A acts as location errors, so every shape with
    the same part turning against A (EBA+ECA:h-1, EBA:h1, ECA:h1) reads alike on any set-up.
    diagnose names none as found, says so, and any of them predicts unmeasured set-ups."""
    truth = {**TABLE4, "ECA:h1s": 20 * ARCSEC}
    data = [_session(seed_machine, poses, {"ECA:h1s": 20 * ARCSEC})]
    base = identify(seed_machine, data)
    found = diagnose(seed_machine, data, base, advisor=Advisor)
    named = {found.significant[0].effect, *found.rivals}
    assert found.found is None and {"ECA:h1", "EBA+ECA:h-1"} <= named, named
    assert found.to_dict()["rivals_equivalent"] and not found.rivals_separated_by
    assert "No path or ball position of the machine file tells them apart" in report(found)
    fit = identify(seed_machine, data, compose(seed_machine, base.model, [found.significant[0].effect]))
    assert _predicts_unmeasured_balls(seed_machine, truth, fit) < 1.0


def test_each_advised_place_puts_the_ball_where_its_words_say(seed_machine):
    """The label a user reads ("with the ball 100 mm lower") is where the advised program's
    poses put the ball: heights along Z, radii in X and Y, every path at every place."""
    bx, by, bz = seed_machine.ball
    said = {"": (bx, by, bz), " there and back": (bx, by, bz),
            " with the ball 100 mm higher": (bx, by, bz + 100),
            " with the ball 100 mm lower": (bx, by, bz - 100),
            " with the ball 50 mm higher": (bx, by, bz + 50), " with the ball 50 mm lower": (bx, by, bz - 50),
            " with the ball at half its radius": (bx / 2, by / 2, bz),
            " with the ball at 1.5 times its radius": (1.5 * bx, 1.5 * by, bz)}
    seen = set()
    for m in Advisor(seed_machine).candidates:
        where = m.label[len(m.path):]
        assert m.ball == pytest.approx(said[where]) and (m.poses.ball == m.ball).all(), m.label
        seen.add(where)
    assert seen == set(said)        # on this machine, every place for some path


def test_a_reversal_is_advised_to_be_run_there_and_back_and_then_found(seed_machine, poses):
    """Backlash of C (±5″ by the direction C turns): on paths that turn C one way only it
    acts as a location error and cannot be seen; diagnose says which run there and back would
    show it, and with that run added names it."""
    truth = {"ECC:r1": 5 * ARCSEC}
    data = [_session(seed_machine, poses, truth)]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert not found.significant
    backlash = next(c for c in found.candidates if c.effect == "ECC:r1")
    assert not backlash.visible
    back = [m for m in backlash.separated_by if m.back]
    assert back and all(m.label.endswith("there and back") for m in back)
    assert "ECC:r1 " in report(found) and f"would be seen with {back[0].label}" in report(found)
    data.append(_session(seed_machine, generate(seed_machine, [back[0].path], back=True), truth, seed=8))
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert found.found == "ECC:r1", ([c.effect for c in found.significant[:3]], found.rivals)


def test_of_equivalent_rivals_the_one_leaving_the_location_errors_true_comes_first(seed_machine, poses):
    """A tilt wobble of A turning against A (10″). EBA:h1 and ECA:h1 read alike on every
    set-up, but carry a part turning with A that the location errors absorb: added, they
    would move BOA and BOC by hundreds of σ. The compound is put first; with it the
    location errors stay within 4σ of the truth."""
    hidden = {"EBA+ECA:h-1c": 10 * ARCSEC}
    data = [_session(seed_machine, poses, hidden)]
    base = identify(seed_machine, data)
    found = diagnose(seed_machine, data, base, advisor=Advisor)
    assert found.to_dict()["rivals_equivalent"] and {"EBA:h1", "ECA:h1"} <= set(found.rivals)
    assert found.significant[0].effect == "EBA+ECA:h-1"
    fit = identify(seed_machine, data, compose(seed_machine, base.model, ["EBA+ECA:h-1"]))
    off = {n: (fit.parameters[n].value - v) / fit.parameters[n].std for n, v in TABLE4.items()}
    assert max(abs(v) for v in off.values()) < 4, off
    other = identify(seed_machine, data, compose(seed_machine, base.model, ["EBA:h1"]))
    assert abs(other.parameters["BOA"].value - TABLE4["BOA"]) > 50 * other.parameters["BOA"].std
    # what diagnose says each choice moves is what the refit with it moves (first order)
    assert set(found.carries) == {"EBA+ECA:h-1", *found.rivals}
    for choice, refit in (("EBA+ECA:h-1", fit), ("EBA:h1", other)):
        for n, said in found.carries[choice].items():
            per = 1e3 if base.parameters[n].unit == "mm" else 1 / ARCSEC       # µm, ″
            moved = (refit.parameters[n].value - base.parameters[n].value) * per
            assert said == pytest.approx(moved, abs=0.3), (choice, n, said, moved)
    assert abs(found.carries["EBA:h1"]["BOA"] - found.carries["EBA+ECA:h-1"]["BOA"]) > 5     # ″
    assert "what each, added, moves in the fitted values" in report(found)


# ------------------------------------------------------------------ beyond the catalogue

UNMEASURED_BALLS = ([-150.0, 120.0, 180.0], [120.0, -100.0, 260.0])   # mm, table frame


def _periodic(machine, poses, axis, pitch_mm, amp_um, phase=0.3):
    """A machine compgen's model does not know: ``axis`` off by a sine of its position (a
    ball-screw period), made by moving the nominal machine, not through any effect."""
    from compgen.model.kinematics import Model
    from compgen.model.poses import Poses
    q = poses.q.copy()
    i = machine.index(axis)
    q[:, i] += amp_um * 1e-3 * np.sin(2 * np.pi * q[:, i] / pitch_mm + phase)
    nominal = Model(machine, ())
    return nominal.relative(Poses(q, poses.ball, poses.t, poses.path)) - nominal.relative(poses)


def _outside_session(machine, poses, axis, pitch_mm, seed=3):
    from compgen.model.kinematics import Model
    y = Model(machine, list(TABLE4)).deviation(poses, np.array(list(TABLE4.values())))
    y = y + _periodic(machine, poses, axis, pitch_mm, 2.0)
    rng = np.random.default_rng(seed)
    return RTestData(poses, y + rng.normal(0, NOISE_UM * 1e-3, y.shape), "sim.csv", "",
                     tuple(range(2, len(poses) + 2)))


@pytest.mark.parametrize("axis, pitch", [("X", 5.0), ("Y", 7.3), ("Z", 12.5)])
def test_an_effect_outside_the_catalogue_is_unexplained_never_found(seed_machine, poses, axis, pitch):
    """A periodic error of a linear axis (no catalogue effect has its shape): diagnose names
    no effect found, with or without the R-test's noise; with it, where the residual exceeds
    the noise; and the shape, a line along the axis at its pitch, with the name to declare."""
    data = [_outside_session(seed_machine, poses, axis, pitch)]
    fit = identify(seed_machine, data)
    for noise in (None, NOISE_UM):
        found = diagnose(seed_machine, data, fit, noise_um=noise)
        assert found.unexplained and found.found is None, [c.effect for c in found.significant[:3]]
        assert not found.explained_to_noise and not found.to_dict()["explained_to_noise"]
        line = found.lines[0]
        assert (line.against, line.direction, line.unit) == (axis, f"d{axis}", "mm")
        assert line.period == pytest.approx(pitch, rel=2e-3)          # a fraction of the resolution
        assert line.amplitude_um == pytest.approx(2.0, rel=0.1)
        assert (noise is None) == (found.misfit == ())
        text = report(found)
        # without the noise, the line itself is what no candidate explains; with it, the misfit
        said = ("UNEXPLAINED: a periodic line along a linear axis, a shape no catalogue effect has, "
                "outweighs every candidate" if noise is None else
                f"UNEXPLAINED: the residual exceeds the R-test's noise ({noise:g} µm) and no catalogue "
                "effect accounts for it:")
        assert said in text and f"  its shape: {line.text()}\n" in text, text
        assert f"--add E{axis}{axis}:w{line.period:.3f}" in text and "add it:" not in text
    assert {m["direction"] for m in found.misfit} == {f"d{axis}"}


@pytest.mark.parametrize("axis, pitch", [("X", 5.0), ("Z", 12.5)])
def test_declaring_the_shape_brings_the_residual_to_the_noise_and_predicts_unmeasured_balls(
        seed_machine, poses, axis, pitch):
    from compgen.model.effects import location_model
    from compgen.model.kinematics import Model
    data = [_outside_session(seed_machine, poses, axis, pitch)]
    line = diagnose(seed_machine, data, identify(seed_machine, data)).lines[0]
    declared = f"E{axis}{axis}:w{line.period:.3f}"            # as diagnose prints it
    fit = identify(seed_machine, data, compose(seed_machine, location_model(seed_machine), [declared]))
    assert fit.residual["sigma_um"] == pytest.approx(NOISE_UM, rel=0.05)
    after = diagnose(seed_machine, data, fit, noise_um=NOISE_UM)
    assert not after.unexplained and after.misfit == () and after.explained_to_noise
    x = np.array([fit.parameters[n].value for n in fit.model])
    for ball in UNMEASURED_BALLS:
        p = generate(seed_machine, ["K4"], ball=ball)
        truth = (Model(seed_machine, list(TABLE4)).deviation(p, np.array(list(TABLE4.values())))
                 + _periodic(seed_machine, p, axis, pitch, 2.0))
        err = Model(seed_machine, fit.model).deviation(p, x) - truth
        err -= err.mean(axis=0)                         # a constant per set-up aside
        assert np.sqrt(np.mean(err**2)) * 1e3 < 1.0


def _repeated(machine, periodic=None, seed=3, noise=NOISE_UM):
    """K4, K1, K2 and K4 again (a repeated run): seed Table 4, white noise, and a periodic
    error of a linear axis (axis, pitch mm) the catalogue does not have."""
    from compgen.model.kinematics import Model
    p = generate(machine, ["K4", "K1", "K2", "K4"])
    y = Model(machine, list(TABLE4)).deviation(p, np.array(list(TABLE4.values())))
    if periodic:
        y = y + _periodic(machine, p, *periodic, 2.0)
    y = y + np.random.default_rng(seed).normal(0, noise * 1e-3, y.shape)
    return [RTestData(p, y, "sim.csv", "", tuple(range(2, len(p) + 2)))]


def test_without_a_given_noise_a_repeated_run_says_it_and_an_outside_effect_is_unexplained(seed_machine):
    """No noise in the machine file nor on the command line: the second run of K4 repeats
    every pose of the first, reached the same way, and their scatter is the noise (the
    periodic error repeats with the pose: it is not scatter). Against it, dX fails."""
    data = _repeated(seed_machine, ("X", 5.0))
    found = diagnose(seed_machine, data, identify(seed_machine, data))
    assert found.repeats is not None and found.noise_from == "repeats"
    assert found.device_noise_um == pytest.approx(NOISE_UM, rel=0.1)
    assert found.repeats.poses == 240 and found.repeats.dwell == 0      # K4's first pose: side unknown
    assert found.unexplained and found.found is None and not found.explained_to_noise
    assert {m["direction"] for m in found.misfit} == {"dX"}
    said = found.to_dict()
    assert said["device_noise_from"] == "repeats" and said["repeats"]["readings"] == 480
    assert "the residual exceeds the repeats' (480 readings of 240 poses read more than once)" \
        in report(found)
    clean = _repeated(seed_machine)
    found = diagnose(seed_machine, clean, identify(seed_machine, clean))
    assert found.explained_to_noise and found.misfit == () and found.noise_from == "repeats"
    # a given noise is used as given: repeats are not looked at
    given = diagnose(seed_machine, clean, identify(seed_machine, clean), noise_um=0.7)
    assert given.repeats is None and given.noise_from == "given" and given.device_noise_um == 0.7


def test_repeats_are_poses_reached_the_same_way(seed_machine):
    """A backlash is not scatter: a pose counts as a repeat of another only reached from the
    same side on every axis; a dwell's samples are told as such; too few say nothing."""
    from compgen.model.poses import Poses, runs
    from compgen.model.sides import same_pose
    from compgen.statistics.noise import repeats
    q = np.radians([[0, 0, 0, -10, 0], [0, 0, 0, -20, 0], [0, 0, 0, -10, 0], [0, 0, 0, -20, 0],
                    [0, 0, 0, -10, 0]])
    p = Poses(q, np.zeros((5, 3)), np.arange(5.0), np.array(["P"] * 5))
    group = same_pose(seed_machine, p, runs(p))
    # A reaches the 2nd and 4th pose going down, the 3rd and 5th going up; the 1st: not moved yet
    assert len(set(group)) == 3 and group[1] == group[3] and group[2] == group[4] != group[0]
    sides = np.full((5, 5), np.nan)
    sides[:, 3] = [1, 1, 1, -1, -1]            # as recorded: these win over the moves
    p = Poses(q, np.zeros((5, 3)), np.arange(5.0), np.array(["P"] * 5), sides)
    group = same_pose(seed_machine, p, runs(p))
    assert group[0] == group[2] and group[1] != group[3] and group[4] not in group[:4]
    # a dwell: 40 samples of one pose, one after another; then too few repeats
    q = np.zeros((41, 5))
    q[0, 3] = np.radians(-1)
    p = Poses(q, np.zeros((41, 3)), np.arange(41.0), np.array(["D"] * 41))
    seg = runs(p)
    r = np.random.default_rng(1).normal(0, 1e-3, (41, 3))
    said = repeats(same_pose(seed_machine, p, seg), r, seg)
    assert (said.poses, said.readings, said.dwell) == (1, 40, 1) and "makes this low" in said.words()
    assert said.sigma_um == pytest.approx(np.sqrt(((r[1:] - r[1:].mean(axis=0)) ** 2).sum() / (3 * 39)) * 1e3)
    assert repeats(same_pose(seed_machine, p.take(slice(0, 30)), seg[:30]), r[:30], seg[:30]) is None


def test_with_the_rtest_noise_a_catalogue_effect_is_still_found(seed_machine, poses):
    data = [_session(seed_machine, poses, {"ECC:h2c": 15 * ARCSEC})]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    assert found.found == "ECC:h2" and found.best_share_of_excess > 0.9 and not found.unexplained


def test_clean_data_at_the_rtest_noise_are_explained(seed_machine, poses):
    data = [_session(seed_machine, poses, {})]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    assert found.explained_to_noise and not found.misfit and not found.unexplained
    # a noise claimed too small is caught: the residual exceeds it everywhere
    tight = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=0.3)
    assert len(tight.misfit) == 9 and tight.unexplained


def test_the_residual_is_drawn_against_each_linear_axis_with_its_strongest_line(seed_machine, poses,
                                                                                 monkeypatch):
    """A 5 mm periodic error of X: the plot of the residual against X exists and its title
    names the line diagnose found there (pitch 5.00… mm), as the text and JSON do."""
    import matplotlib.axes

    from compgen.reports.plots import figures
    data = [_outside_session(seed_machine, poses, "X", 5.0)]
    fit = identify(seed_machine, data)
    found = diagnose(seed_machine, data, fit)
    line = next(x for x in found.lines if x.against == "X")
    assert line.unit == "mm" and abs(line.period - 5.0) < 0.01
    titles, title = [], matplotlib.axes.Axes.set_title
    monkeypatch.setattr(matplotlib.axes.Axes, "set_title",
                        lambda self, t, **k: (titles.append(t), title(self, t, **k))[-1])
    images = figures(seed_machine, data, fit, found=found)
    assert {"residual-vs-X.png", "residual-vs-Y.png", "residual-vs-Z.png"} <= set(images)
    against_x = next(t for t in titles if t.startswith("residual against X"))
    assert f"strongest line: {line.text()}" in against_x, against_x


def test_an_effect_declared_in_the_machine_file_is_tried_and_found(tmp_path, poses):
    from conftest import SEED_MACHINE

    from compgen.configuration.machine_file import load_machine
    from compgen.errors import CompgenError
    text = SEED_MACHINE.read_text().replace("[rtest]\n", "[rtest]\nnoise_um = 0.5\n", 1)
    (tmp_path / "m.toml").write_text(text + '\n[effects]\ndeclared = ["EXX:w5"]\n')
    machine = load_machine(tmp_path / "m.toml")
    assert machine.noise_um == 0.5 and machine.declared == ("EXX:w5",)
    data = [_outside_session(machine, poses, "X", 5.0)]
    found = diagnose(machine, data, identify(machine, data))
    assert found.found == "EXX:w5" and found.device_noise_um == 0.5 and not found.unexplained
    (tmp_path / "bad.toml").write_text(text + '\n[effects]\ndeclared = ["ECC:w5"]\n')
    with pytest.raises(CompgenError, match=r"bad.toml: effects: declared\[0\]: .*linear axis"):
        load_machine(tmp_path / "bad.toml")


def test_an_unexplained_misfit_does_not_reach_the_control(seed_machine, poses):
    from compgen.statistics.gate import fit_gate
    data = [_outside_session(seed_machine, poses, "X", 5.0)]
    reasons = fit_gate(seed_machine, data, identify(seed_machine, data))
    shape = "periodic line no catalogue effect has (dX against X: pitch 5.00"
    assert any(shape in r for r in reasons), reasons


@pytest.mark.parametrize("seed", [6, 8, 23])
def test_a_faint_line_in_clean_data_does_not_stop_the_fit(seed):
    """The B/C machine (no declared noise), its model with ECC:h2 and EYY:p1, clean data at
    0.5 µm white noise: the line scan finds lines of 0.14-0.19 µm removing 1 % of the
    residual (these seeds, found by a 40-seed loop); they are not 'unexplained' (0 of 100
    seeds are, with the share rule; 3 of 40 were without it)."""
    from conftest import BC_MACHINE

    from compgen.configuration.machine_file import load_machine
    from compgen.model.kinematics import Model
    from compgen.statistics.gate import fit_gate
    machine = load_machine(BC_MACHINE)
    model = compose(machine, location_model(machine), ["ECC:h2", "EYY:p1"])
    truth = {n: 4e-6 if n.startswith("ECC") else 3e-3 if n.startswith("EYY") else 0.0
             for n in Model(machine, model).names}
    poses = generate(machine, ["K4", "K1", "K2"])
    d = simulate(machine, truth, poses, 0.5, np.random.default_rng(seed))
    data = [RTestData(d.poses, d.deviation, f"s{seed}.csv", "0" * 64, ())]
    assert fit_gate(machine, data, identify(machine, data, model)) == []


def test_noiseless_data_are_not_unexplained(seed_machine, poses):
    """Rounding-level residuals hold 'significant' lines of 1e-10 µm: below what an R-test
    resolves, they are not a finding."""
    data = [RTestData(poses, simulate(seed_machine, TABLE4, poses).deviation, "sim.csv", "", ())]
    found = diagnose(seed_machine, data, identify(seed_machine, data))
    assert not found.unexplained and found.outside_line is None


def test_one_rule_of_separability_for_diagnose_and_fit(seed_machine):
    """K4 and K4 at half the ball's radius: for the best candidates and for those the model
    absorbs, diagnose's 'separable' is exactly whether fit --add accepts the effect on these
    data (the same condition number, the same limit); what diagnose names found, fit takes."""
    from compgen.errors import CompgenError
    half = [seed_machine.ball[0] / 2, seed_machine.ball[1] / 2, seed_machine.ball[2]]
    poses = [generate(seed_machine, ["K4"]), generate(seed_machine, ["K4"], ball=half)]
    seen = set()
    for hidden in ({"EZC:h1c": 3 * UM}, {"EAC+EBC:h2c": 8 * ARCSEC}):
        data = [_session(seed_machine, p, hidden, seed=s) for s, p in enumerate(poses)]
        base = identify(seed_machine, data)
        found = diagnose(seed_machine, data, base)
        visible = [c for c in found.candidates if c.visible][:3]
        absorbed = [c for c in found.candidates if not c.visible and not c.silent][:3]
        for c in visible + absorbed:
            try:
                identify(seed_machine, data, compose(seed_machine, base.model, [c.effect]), method="linear")
                accepted = True
            except CompgenError:
                accepted = False
            assert accepted == c.separable, (c.effect, c.condition)
            seen.add(accepted)
        if found.found:
            assert next(c for c in found.candidates if c.effect == found.found).separable
    assert seen == {True, False}                  # both sides of the rule were tried


def test_backlash_of_a_tilting_axis_is_found_from_the_side_each_pose_was_reached(seed_machine, poses,
                                                                                 tmp_path):
    """Backlash of A (±5″ by the direction A last moved) on K4 (A turns back), K1 (one way)
    and K2 (A held). With the sides compgen's programs declare (A_side, C_side), the model
    knows each path's side: diagnose names EAA:r1, the residual falls to the noise and K4 at
    two ball positions never measured is predicted within 1 µm. The same readings without
    the sides: each pose takes the side of the move that reached it (a path's first, that of
    its first move) and K2, which holds A, a free constant for its side — the same falls to
    the noise and predictions, and fit says so. (Before, only turns within a path counted:
    1.5 µm left, AOC 1.6″ off, predictions 1.7 µm off.)"""
    from conftest import SEED_MACHINE, run

    from compgen.data.rtest import format_rtest
    from compgen.model.poses import Poses
    from compgen.model.sides import unknown_sides

    truth = {"EAA:r1": 5 * ARCSEC}
    a = seed_machine.index("A")

    def drive(p):       # the physics, not the model's effect: A stands 5″ off, to the side it came from
        q = p.q.copy()
        q[:, a] += 5 * ARCSEC * p.side[:, a] * seed_machine.axis("A").sense
        return q

    data = [simulate(seed_machine, TABLE4, poses, NOISE_UM, np.random.default_rng(7), drive=drive)]
    assert not np.isnan(data[0].poses.side[:, 3:]).any()
    base = identify(seed_machine, data)
    found = diagnose(seed_machine, data, base, noise_um=NOISE_UM, advisor=Advisor)
    assert found.found == "EAA:r1", ([c.effect for c in found.significant[:3]], found.rivals)
    fit = identify(seed_machine, data, compose(seed_machine, base.model, ["EAA:r1"]))
    assert abs(fit.residual["sigma_um"] - NOISE_UM) < RMS_AFTER_TOLERANCE * NOISE_UM
    assert abs(fit.parameters["EAA:r1"].value - 5 * ARCSEC) < 3 * fit.parameters["EAA:r1"].std
    assert _predicts_unmeasured_balls(seed_machine, {**TABLE4, **truth}, fit) < 1.0

    p = data[0].poses
    blind = [RTestData(Poses(p.q, p.ball, p.t, p.path), data[0].deviation)]
    blind_base = identify(seed_machine, blind)
    assert diagnose(seed_machine, blind, blind_base, noise_um=NOISE_UM, advisor=Advisor).found == "EAA:r1"
    stays = identify(seed_machine, blind, compose(seed_machine, base.model, ["EAA:r1"]))
    assert abs(stays.residual["sigma_um"] - NOISE_UM) < RMS_AFTER_TOLERANCE * NOISE_UM
    assert abs(stays.parameters["EAA:r1"].value - 5 * ARCSEC) < 3 * stays.parameters["EAA:r1"].std
    assert _predicts_unmeasured_balls(seed_machine, {**TABLE4, **truth}, stays) < 1.0
    res = blind[0].deviation - fitted(seed_machine, stays, blind)       # what plots draw
    dof = res.size - len(stays.free) - 1                                 # K2's constant
    assert np.sqrt((res**2).sum() / dof) * 1e3 == pytest.approx(stays.residual["sigma_um"], rel=1e-6)
    after = diagnose(seed_machine, blind, stays, noise_um=NOISE_UM)
    assert after.explained_to_noise and not after.significant, [c.effect for c in after.significant]
    assert after.sigma_um == pytest.approx(stays.residual["sigma_um"], rel=1e-6)   # the same dof
    said = unknown_sides(seed_machine, stays.model, blind[0].poses)
    assert said.startswith("the data do not say from which side A reached each pose (no A_side column)")
    assert said.endswith("a path that holds the axis gets a free constant for its side — 1 constant (A: K2). "
                         "Measure with compgen's programs (their pose lists carry A_side), or add the "
                         "column"), said
    assert unknown_sides(seed_machine, stays.model, p) is None
    csv = tmp_path / "blind.csv"
    csv.write_text(format_rtest(seed_machine, blind[0]))
    assert "A_side" not in csv.read_text()
    code, _, err = run("fit", "--machine", SEED_MACHINE, csv, "--add", "EAA:r1", "-o", tmp_path / "f.json")
    assert code == 0 and "compgen: warning: the data do not say from which side A reached" in err, err
    assert "1 constant (A: K2)" in err, err
    code, _, err = run("predict", "--from", tmp_path / "f.json", "--poses", csv, "-o", tmp_path / "p.csv")
    k2 = int((p.path == "K2").sum())
    assert code == 0, err
    assert ("compgen: warning: the pose list does not say from which side A reached each pose: "
            f"{k2} poses of paths that hold it (K2) are predicted without the reversal") in err, err


def test_a_reversal_seen_only_through_its_start_sides_is_invisible(seed_machine):
    """K1 (A one way) and K2 (A held) without A_side: A's backlash is +5″ on K1 throughout
    (A's zero offset, which AOC takes) and an unknown side on K2 (its free constant takes
    it). Diagnose judges the reversal beyond the model *and* its constants, as fit --add
    fits it: invisible (its column alone differed between K1 and K2: 0.37 visible), and fit
    refuses it."""
    from compgen.errors import CompgenError
    from compgen.model.poses import Poses
    a = seed_machine.index("A")

    def drive(p):
        q = p.q.copy()
        q[:, a] += 5 * ARCSEC * p.side[:, a] * seed_machine.axis("A").sense
        return q

    d = simulate(seed_machine, TABLE4, generate(seed_machine, ["K1", "K2"]), NOISE_UM,
                 np.random.default_rng(3), drive=drive)
    blind = [RTestData(Poses(d.poses.q, d.poses.ball, d.poses.t, d.poses.path), d.deviation)]
    base = identify(seed_machine, blind)
    c = next(c for c in diagnose(seed_machine, blind, base, noise_um=NOISE_UM).candidates
             if c.effect == "EAA:r1")
    assert not c.visible and not c.separable and not c.significant, c.visibility
    with pytest.raises(CompgenError, match="cannot separate"):
        identify(seed_machine, blind, compose(seed_machine, base.model, ["EAA:r1"]))


# ------------------------------------------------------------------ round 4: compound, orders, sides

def test_a_reversal_is_tested_on_its_own_columns_not_on_its_start_sides(seed_machine):
    """The example session (a hidden 2/rev radial error of C, no X_side column): X's reversal
    with a free constant for the path that holds X came out −0.02 µm and was called
    significant at p ≈ 1e-82, the constant carrying the misfit. Tested on its own columns
    beyond the constant, it is not."""
    from conftest import ROOT

    from compgen.data.rtest import read_rtest
    data = [read_rtest(ROOT / "examples" / "seed-session.csv", seed_machine)]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    x = next(c for c in found.candidates if c.effect == "EXX:r1")
    assert abs(x.amplitude[0]) < 0.05 and not x.significant and x.p_value > 0.5, x
    assert found.found == "EXC:h2"


def test_a_linear_axis_side_is_never_asked_for_as_a_column(seed_machine):
    """compgen reads no X_side column and its pose lists carry none: beside a rotary axis's
    missing column the warning says a linear axis's side rests on the moves, and asks for no
    column; a linear axis's side alone is nothing the user can act on, and is not warned of."""
    from compgen.model.poses import Poses
    from compgen.model.sides import unknown_sides
    made = generate(seed_machine, ["K4", "K1", "K2"])
    poses = Poses(made.q, made.ball, made.t, made.path)          # a foreign program's: no sides
    said = unknown_sides(seed_machine, ["EXX:r1", "ECC:r1"], poses)
    assert "C_side" in said and "X_side" not in said and "no column records the side of X" in said
    assert unknown_sides(seed_machine, ["EXX:r1"], poses) is None
    # Y moves in every path: each side comes from the moves, no constant, nothing to say
    assert unknown_sides(seed_machine, ["EYY:r1"], poses) is None


def test_an_encoder_4_per_rev_of_a_tilting_axis_is_tried_and_found(seed_machine, poses):
    """A's encoder 4/rev (4″): the catalogue offers every harmonic order on a tilting axis
    too, and diagnose names it (it used to stop at 2/rev and name EZA:h2)."""
    data = [_session(seed_machine, poses, {"EAA:h4c": 4 * ARCSEC})]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert found.found == "EAA:h4", ([c.effect for c in found.significant[:3]], found.rivals)


def test_an_effect_still_significant_after_the_best_is_a_second_effect_not_a_rival(seed_machine, poses):
    """Three effects at once (C 2/rev radial, C 1/rev angular, A's sag in Z), followed as a
    user would: what stays significant once the best is added is never called its rival;
    every effect named as found is one of the truth's; the advised measurements tell the
    C rivals apart; the session ends explained to the noise."""
    hidden = {"EXC:h2c": 2 * UM, "ECC:h1c": 8 * ARCSEC, "EZA:h1c": -3 * UM}
    truth = {**TABLE4, **hidden}
    data = [_session(seed_machine, poses, hidden)]
    model, found_named, seed, shared = location_model(seed_machine), [], 7, 0
    for _ in range(8):
        fit = identify(seed_machine, data, model)
        found = diagnose(seed_machine, data, fit, noise_um=NOISE_UM, advisor=Advisor)
        assert not set(found.rivals) & set(found.after_best)
        if len(found.significant) > 1 and not found.unexplained:     # the text names the best added
            shared += 1
            assert f"once {found.significant[0].effect} is added, still significant: " \
                   f"{', '.join(found.after_best)}." in report(found) if found.after_best else \
                   f"once {found.significant[0].effect} is added, no other" in report(found)
        if found.found:
            found_named.append(found.found)
            model = compose(seed_machine, model, [found.found])
        elif found.rivals and found.rivals_separated_by:        # measure what tells them apart
            seed += 1
            data.append(simulate(seed_machine, truth, found.rivals_separated_by[0].poses, NOISE_UM,
                                 np.random.default_rng(seed)))
        elif found.rivals:                   # equivalent on every set-up: any one models it
            model = compose(seed_machine, model, [found.significant[0].effect])
        else:
            break
    assert {"EXC:h2", "ECC:h1"} <= set(found_named) <= {"EXC:h2", "ECC:h1", "EZA:h1"}, found_named
    assert found.explained_to_noise and shared
    # the sag was added as one of four equivalents: the location errors depend on the choice
    # by tens of their σ from the data alone; with the choice in their σ, all hold the truth
    fit = identify(seed_machine, data, model)
    honest = with_choices(seed_machine, data, fit, noise_um=NOISE_UM)
    assert [c["effect"] for c in honest.choices] == ["EYA+EZA:h-1"], honest.choices
    assert {"EYA:h1", "EZA:h1"} <= set(honest.choices[0]["equivalents"])

    def off(f):
        return max(abs(f.parameters[n].value - v) / f.parameters[n].std for n, v in TABLE4.items())
    assert off(fit) > 10 and off(honest) < 3, (off(fit), off(honest))
    again = FitResult.from_dict(json.loads(honest.to_json()))
    assert again.choices == honest.choices, (again.choices, honest.choices)
    told = next(line for line in honest.report().splitlines() if "cannot be told from" in line)
    assert "EYA:h1" in told and "EZA:h1" in told, told
    # what the choice moves: the six largest in their σ, in that order, each in its unit
    text = honest.report().splitlines()
    listed = text[text.index("  the σ above holds what the choice moves (half the range over them):") + 1]
    moved = honest.choices[0]["half_range"]
    want = sorted(moved, key=lambda n: -abs(moved[n]) / honest.parameters[n].std)[:6]
    assert len(moved) > 6 and [w.split()[0] for w in listed.strip().split(", ")] == want, listed
    # what it moves: half the range of each shared parameter over the fits with each
    # equivalent in the sag's place, added to σ in quadrature; the sag's own σ as the data's
    rest = compose(seed_machine, model, remove=["EYA+EZA:h-1"])
    fits = [fit, *(identify(seed_machine, data, compose(seed_machine, rest, [e]))
                   for e in honest.choices[0]["equivalents"])]
    for n, e in honest.parameters.items():
        if n in rest:
            spread = [f.parameters[n].value for f in fits]
            assert moved[n] == pytest.approx((max(spread) - min(spread)) / 2, rel=1e-6), n
            assert e.std == pytest.approx(np.hypot(fit.parameters[n].std, moved[n]), rel=1e-9), n
        else:
            assert n not in moved and e.std == fit.parameters[n].std, n


@pytest.mark.parametrize("seed", [7, 8])
def test_a_ball_stem_warming_is_named_as_the_set_up_not_a_machine_drift(seed_machine, poses, seed):
    """The ball rising 3 µm along its stem (τ = 15 min) after mounting: it moves in the
    table frame, turning with A and C, which a drift of tool to table (drift_Z) does not;
    diagnose names the set-up's own drift, and the location errors hold the truth."""
    hidden = {"ZOW:e15": 3 * UM}
    data = [_session(seed_machine, poses, hidden, seed)]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert found.found == "ZOW:e15", ([c.effect for c in found.significant[:3]], found.rivals)
    assert "stem or clamp warming" in next(c.cause for c in found.candidates if c.effect == "ZOW:e15")
    fit = identify(seed_machine, data, compose(seed_machine, location_model(seed_machine), ["ZOW:e15"]))
    off = {n: abs(fit.parameters[n].value - v) / fit.parameters[n].std for n, v in TABLE4.items()}
    assert max(off.values()) < 4, off


def test_nothing_is_named_found_without_the_devices_noise(seed_machine):
    """Judged only against σ̂ of the data, an effect outside the catalogue passes for the best
    catalogue curve: without the R-test's noise (not given, no repeats) the best candidate
    is listed with its fit --add but not named found, and the report says what is missing;
    with the noise given it is named."""
    from conftest import ROOT

    from compgen.data.rtest import read_rtest
    data = [read_rtest(ROOT / "examples" / "seed-session.csv", seed_machine)]
    base = identify(seed_machine, data)
    blind = diagnose(seed_machine, data, base)
    assert blind.device_noise_um is None and blind.significant[0].effect == "EXC:h2"
    assert blind.found is None and blind.to_dict()["found"] is None
    text = report(blind)
    assert "Not named as found: the R-test's noise is not given" in text and "--add EXC:h2" in text
    told = diagnose(seed_machine, data, base, noise_um=NOISE_UM)
    assert told.found == "EXC:h2" and "Not named as found" not in report(told)


def test_drifts_are_told_apart_by_time_never_by_a_ball_position(seed_machine, poses):
    """YOC and AOC both drifting with τ = 15 min: the data of one session cannot tell AOC's τ
    of 15 from 45 min, and no ball position would (a drift differs only in when the
    readings were made): what tells them apart is a path measured again right after, or
    there and back, its clock running on, the ball where it was. Followed as a user would,
    the two drifts are named with their τ (they were AOC:e45, YOC:e45, AOC:e5, YOC:e5 when
    advice moved only the ball), and the location errors hold the truth within 3 σ."""
    truth = {"YOC:e15": 3 * UM, "AOC:e15": 6 * ARCSEC}
    data, model, named, rng = [_session(seed_machine, poses, truth)], location_model(seed_machine), [], 8
    for _ in range(5):
        found = diagnose(seed_machine, data, identify(seed_machine, data, model), noise_um=NOISE_UM,
                         advisor=Advisor)
        if found.found:
            named.append(found.found)
            model = compose(seed_machine, model, [found.found])
        elif found.rivals:
            m = found.rivals_separated_by[0]
            assert m.ball == tuple(seed_machine.ball), m.label          # in time: never by the ball
            assert m.poses.t.min() > data[-1].poses.t.max()             # measured after them
            rng += 1
            data.append(_session(seed_machine, m.poses, truth, seed=rng))
        else:
            break
    assert named == ["AOC:e15", "YOC:e15"], named
    fit = identify(seed_machine, data, model)
    off = {n: abs(fit.parameters[n].value - {**TABLE4, **truth}[n]) / fit.parameters[n].std
           for n in location_model(seed_machine)}
    assert max(off.values()) < 3, off


@pytest.mark.parametrize("rho", [0.0, 0.8])
def test_the_best_carried_from_a_screen_changes_no_number(seed_machine, poses, monkeypatch, rho):
    """On a dense session the first pass carries the best found on every k-th pose, and the
    step that tests what stays significant after it takes its products from that pass. The
    diagnosis is the same as without the screen; where the noise is white a pass over every
    reading is saved (a pass over every 4th made instead); a screen that guesses wrong
    (forced here) costs the pass back and changes nothing."""
    from compgen.statistics import diagnose as module
    rng = np.random.default_rng(12)
    hidden = {"EXC:h2c": 1.5 * UM, "EXC:h2s": 0.8 * UM}      # one best, clear of the next
    data = [_with_noise(seed_machine, poses, hidden, _ar1_mm(len(poses), rho, rng))]
    fit = identify(seed_machine, data)
    walked = []                       # poses of each pass of the candidates' products
    real = module.products
    monkeypatch.setattr(module, "products", lambda *a, **k: walked.append(len(a[1])) or real(*a, **k))

    def run(screen, guess=None):
        walked.clear()
        monkeypatch.setattr(module, "SCREEN_POSES", screen)
        if guess is not None:
            monkeypatch.setattr(module, "_screened", lambda *a: guess)
        return diagnose(seed_machine, data, fit, noise_um=NOISE_UM).to_dict(), list(walked)

    plain, passes = run(10**9)
    assert len(plain["candidates"]) > 100 and sum(c["significant"] for c in plain["candidates"]) > 1
    screened, with_screen = run(200)                  # 723 poses: the best on every 4th
    assert _same(screened, plain)
    n = len(poses)
    if rho:     # the pass made white carries the best: the screen is one pass over every 4th
        assert with_screen == [181, *passes]
    else:
        assert passes == [n, n] and with_screen == [181, n]
    wrong = next(e for e in module.catalogue(seed_machine) if e.name == "EZA:p1")
    forced, with_wrong = run(200, wrong)
    assert _same(forced, plain) and with_wrong == passes


def _same(a, b, path="diagnosis"):
    """The same diagnosis: every word, flag and count equal, every number equal to rounding.
    The screen's pass and the plain one sum the same terms, but numpy's SIMD sums group
    them by where an array happens to start in memory, so a last bit may differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), path
        return all(_same(a[k], b[k], f"{path}.{k}") for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        assert len(a) == len(b), path
        return all(_same(x, y, f"{path}[{i}]") for i, (x, y) in enumerate(zip(a, b, strict=True)))
    if isinstance(a, float) and isinstance(b, float):
        assert a == pytest.approx(b, rel=1e-9, abs=1e-12), path
        return True
    assert a == b and type(a) is type(b), path
    return True


def test_a_drift_fitted_across_files_whose_clocks_overlap_is_said(seed_machine, poses):
    """A drift is a function of one session's clock: a second file whose t starts at 0
    again (a device that restarts its clock) is taken as read at the session's start, and
    the fit's request says so; a file that continues the clock, or a model with no drift,
    says nothing."""
    from compgen.configuration.session import one_clock
    first = _session(seed_machine, poses, {})
    again = generate(seed_machine, ["K2"])
    restarted = _session(seed_machine, again, {}, seed=8)
    later = _session(seed_machine, again.starting_at(poses.t.max() + 20), {}, seed=8)
    model = compose(seed_machine, location_model(seed_machine), ["YOC:e15"])
    said = one_clock(seed_machine, model, [first, restarted])
    assert said and "YOC:e15" in said and "starts at t = 0 s" in said
    assert one_clock(seed_machine, model, [first, later]) is None
    assert one_clock(seed_machine, location_model(seed_machine), [first, restarted]) is None
    # a file that starts before the earlier one ends, and ends after it, overlaps too
    start = first.poses.t.max() - 100
    overlapping = _session(seed_machine, again.starting_at(start), {}, seed=8)
    assert overlapping.poses.t.max() > first.poses.t.max()
    said = one_clock(seed_machine, model, [first, overlapping])
    assert said and f"starts at t = {start:g} s, before" in said, said
    # every effect in time: a location error linear in it, a scale growing (it said nothing of them)
    for timed in ("YOC:t1", "EAA:g15"):
        said = one_clock(seed_machine, compose(seed_machine, location_model(seed_machine), [timed]),
                         [first, restarted])
        assert said and timed in said, (timed, said)


def _gained(machine, poses, gains, seed, hidden=None, rho=0.0):
    """The seed machine read by an R-test whose sensors read (1 + g) of the displacement."""
    d = simulate(machine, {**TABLE4, **(hidden or {})}, poses)
    rng = np.random.default_rng(seed)
    noise = (ar1_noise(len(poses), rho, NOISE_UM, rng) if rho
             else rng.normal(0, NOISE_UM * 1e-3, (len(poses), 3)))
    return RTestData(d.poses, d.deviation * (1 + np.array(gains)) + noise, "gain.csv", "",
                     tuple(range(2, len(poses) + 2)))


@pytest.mark.parametrize("gains, sensor, size", [((0.015, 0, 0), "X", 1.5), ((0, 0, -0.01), "Z", -1.0)])
@pytest.mark.parametrize("seed", [1, 2])
def test_a_sensor_gain_is_blamed_on_the_device_and_no_machine_effect_found(seed_machine, poses, gains,
                                                                          sensor, size, seed):
    """A 1.5 % X gain (a 1 % Z gain) of the R-test: machine effects fit it too (a C 1/rev, a
    squareness of Z), but the device explains these data as well, so none is named found; the
    gain is told within 3 σ, the gate and the text send the user to calibrate that sensor."""
    from compgen.statistics.gate import fit_gate
    data = [_gained(seed_machine, poses, gains, seed)]
    fit = identify(seed_machine, data)
    d = diagnose(seed_machine, data, fit, noise_um=NOISE_UM)
    assert d.device_blamed == f"gain_{sensor}" and d.found is None and not d.explained_to_noise
    gain = next(c for c in d.devices if c.effect == d.device_blamed)
    assert abs(gain.value - size) < 3 * gain.std and gain.std < 0.3, gain
    assert f"Calibrate the R-test's {sensor} sensor" in report(d)
    assert "fit --from fit.json --add" not in report(d)
    assert any("the R-test itself explains the misfit" in r for r in fit_gate(seed_machine, data, fit))
    assert d.to_dict()["device_blamed"] == d.device_blamed
    # one sensor's gain leaks into another's test alone (X's made Z's −0.62 ± 0.15 %, p 0.006):
    # beside the blamed gain, no other is significant or told, and each reads 0 within 3 σ
    assert [c.effect for c in d.significant_devices] == [d.device_blamed], d.devices
    assert all(abs(c.value) < 3 * c.std for c in d.devices if c is not d.blamed), d.devices
    assert "stays significant beside it" not in report(d)


def test_two_sensor_gains_are_both_told_and_the_strongest_blamed(seed_machine, poses):
    """X +1.5 % and Z −1.5 % at once: the stronger blamed, the other significant beside it,
    each within 3 σ of its truth, and the text asks to calibrate both."""
    data = [_gained(seed_machine, poses, (0.015, 0, -0.015), 1)]
    d = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    assert {c.effect for c in d.significant_devices} == {"gain_X", "gain_Z"}, d.devices
    assert d.blamed is max(d.significant_devices, key=lambda c: c.drop_w)
    for c in d.significant_devices:
        assert abs(c.value - {"gain_X": 1.5, "gain_Z": -1.5}[c.effect]) < 3 * c.std, c
    other = next(c for c in d.significant_devices if c is not d.blamed)
    assert f"{other.effect} {other.value:+.2f}" in report(d) and "calibrate that sensor too" in report(d)


@pytest.mark.parametrize("hidden, rho", [({}, 0.0), ({}, 0.9), ({"EXC+EYC:h2c": 3 * UM}, 0.0),
                                         ({"ECC:h2c": 15 * ARCSEC}, 0.0)])
@pytest.mark.parametrize("seed", [1, 2])
def test_a_calibrated_device_is_not_blamed(seed_machine, poses, hidden, rho, seed):
    """Read by a device without gain errors: on clean data (white and AR(1) ρ 0.9 noise) no
    gain is significant. With a hidden machine effect the gains alone take a part of its
    misfit (the fit without it predicts the readings wrongly: a 15″ 2/rev angle of C made X's
    read −56 ± 1.7 %, p < 1e-300), but told beside the best machine effect none is significant
    and each reads 0 within 3 σ; none is blamed, and once the effect is in the model none is
    significant."""
    data = [_gained(seed_machine, poses, (0, 0, 0), seed, hidden, rho)]
    d = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    assert d.device_blamed is None and bool(d.significant) == bool(hidden)
    assert not d.significant_devices and all(abs(c.value) < 3 * c.std for c in d.devices), d.devices
    assert "The device:" not in report(d)
    if hidden:
        model = compose(seed_machine, location_model(seed_machine), [n[:-1] for n in hidden])
        d = diagnose(seed_machine, data, identify(seed_machine, data, model), noise_um=NOISE_UM)
    assert not any(c.significant for c in d.devices), d.devices


@pytest.mark.parametrize("seed", [1, 2])
def test_a_sensor_gain_beside_a_machine_effect_is_told_beside_it(seed_machine, poses, seed):
    """A −1 % Z gain and an unmodelled 5 µm 2/rev radial motion of C at once: the machine
    effect explains more, so the gain is not blamed; alone it was not significant (the
    misfit it does not cause inflates its test), but told beside the machine's effects it
    is, within 3 σ of its truth, the other sensors read 0 within 3 σ, and the text and the
    gate ask to calibrate the Z sensor before these data correct a control."""
    from compgen.statistics.gate import fit_gate
    data = [_gained(seed_machine, poses, (0, 0, -0.01), seed, {"EXC+EYC:h2c": 5 * UM})]
    fit = identify(seed_machine, data)
    d = diagnose(seed_machine, data, fit, noise_um=NOISE_UM)
    assert d.significant and d.device_blamed is None
    gain = {c.effect: c for c in d.devices}
    assert [c.effect for c in d.significant_devices] == ["gain_Z"], d.devices
    assert abs(gain["gain_Z"].value + 1.0) < 3 * gain["gain_Z"].std < 1.0, gain
    assert 1e-300 < gain["gain_Z"].p_value < d.alpha
    assert all(abs(gain[s].value) < 3 * gain[s].std for s in ("gain_X", "gain_Y")), gain
    z = gain["gain_Z"]
    assert (f"The device: gain_Z {z.value:+.2f} ± {z.std:.2f} % (p = {z.p_value:.2g}) stays significant "
            "beside the machine's effects" in report(d)) and "calibrate the R-test's Z sensor" in report(d)
    assert any(f"the R-test's own gain_Z {z.value:+.2f}" in r for r in fit_gate(seed_machine, data, fit))


def test_no_gain_is_judged_beside_more_second_effects_than_are_told(seed_machine, poses, monkeypatch):
    """Where more second effects stay significant than a gain is told beside (each a walk
    of the poses), the machine's side is far from settled: the gains are told, none called
    significant. Here a −1.5 % Z gain beside a 15″ 2/rev angle of C: judged beside ECC:h2 and
    its twelve second effects (the gain's own look-alikes), it is significant; with fewer of
    them told (a denser session's budget of walks), it is not."""
    from compgen.statistics import diagnose as module
    data = [_gained(seed_machine, poses, (0, 0, -0.015), 2, {"ECC:h2c": 15 * ARCSEC})]
    fit = identify(seed_machine, data)
    d = diagnose(seed_machine, data, fit, noise_um=NOISE_UM)
    assert len(d.after_best) > 1 and d.device_blamed is None
    assert [c.effect for c in d.significant_devices] == ["gain_Z"], d.devices
    monkeypatch.setattr(module, "SECOND_WALKS", len(poses))       # one second effect told
    d = diagnose(seed_machine, data, fit, noise_um=NOISE_UM)
    assert d.after_best and d.device_blamed is None and not d.significant_devices, d.devices
    assert "The device:" not in report(d)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_gain_that_a_second_machine_effect_also_explains_is_left_to_the_next_round(
        seed_machine, poses, seed):
    """A 1.5 % X gain and an unmodelled 15″ 2/rev angle of C: beside ECC:h2 alone the gain
    would be significant, but C's 1/rev radial motion (a second effect beside it) explains
    it as well, so it is not called significant and its σ says so (truth within 3 σ). Once
    ECC:h2 is in the model, the device is blamed (the round a user makes next)."""
    data = [_gained(seed_machine, poses, (0.015, 0, 0), seed, {"ECC:h2c": 15 * ARCSEC})]
    d = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    assert d.found == "ECC:h2" and not d.significant_devices, d.devices
    assert all(abs(c.value - (1.5 if c.effect == "gain_X" else 0)) < 3 * c.std for c in d.devices), d.devices
    model = compose(seed_machine, location_model(seed_machine), ["ECC:h2"])
    d = diagnose(seed_machine, data, identify(seed_machine, data, model), noise_um=NOISE_UM)
    assert d.device_blamed == "gain_X" and d.found is None
    assert abs(d.blamed.value - 1.5) < 3 * d.blamed.std < 1.0, d.blamed


def test_a_gain_s_sigma_is_its_scatter_over_sessions(seed_machine, poses):
    """On clean sessions (a calibrated R-test, nothing missing) each gain is told alone beside
    the model: over 16 noise draws its values scatter as the σ it reports says (within the
    spread 16 draws allow), about 0."""
    told = []
    for seed in range(100, 116):
        data = [_gained(seed_machine, poses, (0, 0, 0), seed)]
        d = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
        assert not d.significant and not d.significant_devices
        told.append([(c.value, c.std) for c in d.devices if not c.form])   # a form's size is ≥ 0
    value, std = np.array(told).transpose(2, 0, 1)
    ratio = value.std(axis=0, ddof=1) / std.mean(axis=0)
    assert np.all((ratio > 0.6) & (ratio < 1.6)), (value, std)
    assert np.all(abs(value.mean(axis=0)) < 3 * std.mean(axis=0) / 4), value
    assert np.all((std > 0.05) & (std < 0.5))       # % of the displacement, as the text prints it


def test_the_bonferroni_family_is_every_candidate_and_gain_the_model_leaves_visible(seed_machine, poses):
    """One family for the machine's candidates and the device's: its size, said in the text
    as "N tried", counts every visible candidate and every visible device parameter (on an
    R-test's data three gains and the ball's three forms)."""
    data = [_session(seed_machine, poses, HIDDEN["ECC:h2"])]
    d = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    visible = [c for c in d.candidates if c.visible]
    assert sorted(g.effect for g in d.devices if g.visibility >= 0.01) == [
        "ball_lobes2", "ball_lobes3", "ball_lobes4", "gain_X", "gain_Y", "gain_Z"]
    assert d.tested == len(visible) + 6, (d.tested, len(visible))
    assert f"({d.tested} tried; F test, Bonferroni-corrected" in report(d)


def test_the_residual_against_a_tilting_axis_is_its_quadratic_trend_in_micrometres(seed_machine):
    """A tilting axis (A, not a whole turn) has no terms per revolution: its row is the RMS
    over the readings of the least-squares quadratic in A, per direction. A residual that is
    exactly such a trend in dX (and nothing in dY, dZ), given in mm as the fit holds it,
    reads back as its own RMS in µm."""
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    a = poses.q[:, seed_machine.index("A")]
    u = (a - a.mean()) / np.ptp(a)
    trend_um = 2.0 * u + 3.0 * (u**2 - (u**2).mean())
    r = np.zeros((len(poses), 3))
    r[:, 0] = trend_um * 1e-3
    row = _per_axis(seed_machine, poses, r)["A"]
    assert set(row) == {"trend"}
    assert row["trend"][0] == pytest.approx(np.sqrt(np.mean(trend_um**2)), rel=1e-9)
    assert row["trend"][1:] == pytest.approx([0, 0], abs=1e-12)


def test_the_text_lists_the_eight_strongest_candidates_with_their_p_values(seed_machine, poses):
    """The report's candidate list is the JSON's visible candidates, strongest first, at most
    eight (the rest are in --json), each with its RMS after, its p-value to two digits (below
    double precision's least, "p < 1e-300") and its verdict."""
    data = [_session(seed_machine, poses, HIDDEN["ECC:h2"])]
    found = diagnose(seed_machine, data, identify(seed_machine, data), advisor=Advisor)
    visible = [c for c in found.to_dict()["candidates"] if c["visible"]]
    listed = re.findall(r"^ +(\d+)\. (\S+) +RMS → ([\d.]+) µm   p (?:= (\S+)|< (1e-300))  "
                        r"(SIGNIFICANT|not significant)$", report(found), re.M)
    assert len(visible) > 8 and len(listed) == 8
    for i, (c, (no, effect, rms, p, floor, verdict)) in enumerate(zip(visible, listed, strict=False), 1):
        assert (int(no), effect, verdict) == (i, c["effect"], "SIGNIFICANT" if c["significant"] else
                                              "not significant")
        assert float(rms) == pytest.approx(c["rms_after_um"], abs=5e-4)
        assert (float(p) == pytest.approx(c["p_value"], rel=0.05) if c["p_value"] >= 1e-300 else floor), c
    assert listed[0][4] and any(row[3] for row in listed)    # both ways of saying p are read


@pytest.mark.parametrize("candidates, verb", [(None, "explain"), (["EXC:h1", "EXX:p1"], "explains")])
def test_rivals_and_the_pairs_the_advised_plan_leaves_open_are_said_as_the_json_has_them(
        seed_machine, poses, candidates, verb):
    """An X scale error's rivals (a 1/rev radial motion of C, …) are listed with the verb their
    number takes, and the pairs the plan leaves open are those every measurement of the plan
    leaves open in the JSON (none: "together they tell every pair apart")."""
    data = [_session(seed_machine, poses, {"EXX:p1": 10 * UM})]
    found = diagnose(seed_machine, data, identify(seed_machine, data), candidates, advisor=Advisor)
    d, text = found.to_dict(), report(found)
    rivals, best = d["rivals_of_best"], found.significant[0].effect
    assert f"Not told apart: {', '.join(rivals)} {verb} these data as well as {best}," in text
    assert (len(rivals) == 1) == (verb == "explains")
    plan = d["rivals_separated_by"]
    numbered = re.findall(r"^   (\d+)\. (.+) \(tells apart (.+)\)$", text, re.M)
    assert [n[:2] for n in numbered] == [(str(i), m["label"]) for i, m in enumerate(plan, 1)], numbered
    def said_pairs(words):            # "A / B, A / C" as the text writes pairs
        return {frozenset(p.split(" / ")) for p in words.split(", ")}
    pairs = {frozenset(p) for p in combinations([best, *rivals], 2)}
    for (*_, told), m in zip(numbered, plan, strict=True):    # each pair of the group it does not leave open
        assert said_pairs(told) == pairs - {frozenset(p) for p in m["leaves_open"]}, told
    open_ = set.intersection(*({frozenset(p) for p in m["leaves_open"]} for m in plan))
    said = re.search(r"together they (?:leave (.+) open|tell every pair apart)$", text, re.M)
    assert said, text
    assert said_pairs(said[1]) == open_ if said[1] else not open_
    assert candidates is not None or open_           # both ways of saying it are read


def test_a_significant_effect_the_fit_cannot_take_whole_is_said_so_with_fit_s_refusal(seed_machine):
    """K4 with the ball 7 mm from C's axis (the location errors barely conditioned: 377) and
    an A sag in Z (EZA 4 µm·(1 − cos A)): the sag is seen but not separable whole, and the
    text says fit --add would refuse it, as it does. (Until each mounting of the ball had an
    offset of its own, this case was K4 at two radii with a 1/rev tilt of A, seen only
    because both radii shared one offset: with an offset each it is absorbed whole.)"""
    from compgen.errors import CompgenError
    near = [seed_machine.ball[0] / 30, seed_machine.ball[1] / 30, seed_machine.ball[2]]
    data = [_session(seed_machine, generate(seed_machine, ["K4"], ball=near), {"EZA:h1c": -4 * UM}, seed=1)]
    base = identify(seed_machine, data)
    found = diagnose(seed_machine, data, base, advisor=Advisor)
    text = report(found, top=len(found.candidates))
    said = re.findall(r"^ +\d+\. (\S+) .*\n.*\n(?:      partly absorbed by .*\n)?"
                      r"      seen, but not separable whole on these data "
                      r"\(fit --add would refuse it: condition ([\d.e+]+)\); (.*)$", text, re.M)
    assert said, text
    for effect, cond, then in said:
        c = next(c for c in found.candidates if c.effect == effect)
        assert c.significant and not c.separable and float(cond) == pytest.approx(c.condition, rel=5e-3)
        assert (then.startswith(f"measure {c.separated_by[0].label} first: ") if c.separated_by else
                then == "no set-up this machine can measure separates it"), then
        with pytest.raises(CompgenError, match="cannot separate"):
            identify(seed_machine, data, compose(seed_machine, base.model, [effect]), method="linear")


def test_rivals_with_no_measurement_searched_say_so_and_what_each_choice_moves(seed_machine, poses):
    """Without an advisor (a library caller; a control compgen writes no programs for) the
    rivals of an X scale error are not sent to a measurement: the text says none was
    searched, gives the best's fit --add, and lists what each choice moves in the location
    errors, 0.2 µm or ″ and more, as the JSON's rivals_carry has them."""
    from compgen import me
    data = [_session(seed_machine, poses, {"EXX:p1": 10 * UM})]
    found = diagnose(seed_machine, data, identify(seed_machine, data))
    d, text = found.to_dict(), report(found)
    assert d["rivals_of_best"] and not d["rivals_separated_by"]
    best = found.significant[0].effect
    assert (f"  Which measurement would tell them apart was not searched. Any one of them models the misfit: "
            f"{me()} fit --from fit.json --add {best} -o fit+1.json; the location errors written to a "
            "control depend on the choice:\n") in text
    carry = d["rivals_carry"]
    assert list(carry["shift_by_choice"]) == [best, *d["rivals_of_best"]]
    assert f"(first order; the first, {best}, is the one the location errors absorb least):" in text
    for name, shift in carry["shift_by_choice"].items():
        row = re.search(rf"^    {re.escape(name)} +(.*)$", text, re.M)[1]
        big = {k: v for k, v in shift.items() if abs(v) >= 0.2}
        listed = dict(re.findall(r"(\w+) ([+-]\d+\.\d\d) (?:µm|″)", row))
        assert {k: float(v) for k, v in listed.items()} == pytest.approx(big, abs=0.005001), (name, row)
        assert big or row == "nothing above 0.2 µm or ″"


@pytest.mark.parametrize("candidates", [["ECC:h2"], ["ECC:h2", "EXX:p1"]])
def test_effects_that_share_misfit_are_said_only_when_more_than_one_is_significant(seed_machine, poses,
                                                                                     candidates):
    """A 2/rev angle of C tried alone is the one significant candidate: nothing is said of
    shared misfit; beside an X scale error that fits a part of it too, both are significant
    and the text says what stays significant once the best is added (here: nothing)."""
    data = [_session(seed_machine, poses, HIDDEN["ECC:h2"])]
    found = diagnose(seed_machine, data, identify(seed_machine, data), candidates, noise_um=NOISE_UM)
    text = report(found)
    assert [c.effect for c in found.significant] == candidates and not found.after_best
    said = ("  Effects share misfit: once ECC:h2 is added, no other candidate stays significant. Add one "
            "effect at a time and diagnose again.")
    assert (said in text) == (len(candidates) > 1), text


def test_the_fragile_parameters_are_the_shift_an_effect_of_1_um_rms_makes(seed_machine, poses):
    """Each fitted parameter's line under "fragile parameters" is the effect that shifts it
    most per µm RMS of its readings: simulated at exactly 1 µm RMS (noiseless) and fitted, it
    shifts that parameter by the figure printed; no effect shifts it more (the JSON's
    shift_per_unit over signature_rms_um_per_unit)."""
    from compgen.model.effects import effect_name, resolve
    data = [simulate(seed_machine, TABLE4, poses)]
    clean = identify(seed_machine, data)
    found = diagnose(seed_machine, data, clean)
    rows = re.findall(r"^    (\w+) +([+-] *\d+\.\d\d) (µm|″) per µm of (\S+)$", report(found), re.M)
    assert [r[0] for r in rows] == list(TABLE4)
    sig = found.signature_um
    for name, value, unit, effect in rows:
        per_um = {k: v / sig[k] for k, v in found.bias[name].items() if sig[k] > 0}
        worst = max(per_um, key=lambda k: abs(per_um[k]))
        assert effect_name(worst) == effect and unit == ("µm" if name[0] in "XYZ" else "″")
        scale = UM if resolve(seed_machine, effect).unit == "mm" else ARCSEC
        moved = identify(seed_machine, [simulate(seed_machine, {**TABLE4, worst: scale / sig[worst]}, poses)])
        shift = moved.parameters[name].value - clean.parameters[name].value
        shift /= UM if unit == "µm" else ARCSEC
        assert float(value.replace(" ", "")) == pytest.approx(shift, rel=0.02, abs=0.01), (name, worst)


def test_an_unexplained_misfit_lists_its_six_worst_path_directions(seed_machine, poses):
    """Clean data against an R-test said to be 2.5 times quieter than it is: all nine path
    directions exceed its noise and no candidate accounts for it; the text lists six, as the
    JSON's misfit has them (worst first), with their RMS and p-values."""
    data = [_session(seed_machine, poses, {})]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM / 2.5)
    misfit = found.to_dict()["misfit"]
    assert found.unexplained and len(misfit) == 9
    text = report(found)
    listed = re.findall(r"^    (d[XYZ]) of (\w+): RMS (\d+\.\d\d) µm \(p = (\S+)\)$", text, re.M)
    # white noise has no shape: no line is significant, and the text says so
    assert not [line for line in found.lines if line.p_value < found.alpha]
    assert "  no periodic line against an axis or time stands out: look at the residual plots" in text
    assert [(d, p) for d, p, *_ in listed] == [(m["direction"], m["path"]) for m in misfit[:6]]
    for (*_, rms, p), m in zip(listed, misfit, strict=False):
        assert float(rms) == pytest.approx(m["rms_um"], abs=0.005) and float(p) == pytest.approx(
            m["p_value"], rel=0.05, abs=1e-300)


@pytest.mark.parametrize("first", [1, 241])
def test_advice_after_timed_readings_starts_after_them_and_offers_the_repeat(seed_machine, poses, first):
    """After readings with their times (one pose, or K4 whole) each advised measurement is
    read after them (the R-test's clock running on, a gap between programs) and what was
    measured is offered again, right after: a drift is told by time."""
    from compgen.model.paths import GAP_S
    measured = poses.take(np.arange(first))
    advised = Advisor(seed_machine, measured).candidates
    assert all(m.poses.t[0] == pytest.approx(measured.t.max() + GAP_S) for m in advised)
    again = [m for m in advised if m.again]
    assert [m.label for m in again] == ["K4 again, right after these data"] and again[0].name == "K4_AGAIN"


def test_a_repeat_in_a_file_of_its_own_is_counted_and_named_by_its_file(seed_machine, poses):
    """K2 measured in the session and twice again, each repeat a file of its own right after
    the last (its clock running on, the same path at the same ball): told apart by file, the
    next repeat is K2_AGAIN_3 and the data hold K2 three times. (By path and clock alone the
    three K2 runs in a row were one run: the third repeat was named K2_AGAIN_2 again, whose
    program and readings existed, and the repeats were never counted to three.)"""
    from compgen.data.rtest import Measurements
    from compgen.model.paths import GAP_S
    from compgen.model.poses import runs
    from compgen.statistics.diagnose import _times_measured
    sets = [_session(seed_machine, poses, {})]
    k2 = generate(seed_machine, ["K2"])
    for seed in (1, 2):
        sets.append(_session(seed_machine, k2.starting_at(sets[-1].poses.t.max() + GAP_S), {}, seed))
    joined = Measurements.concat(sets)
    run = runs(joined.poses, joined.set_of)
    again = [m for m in Advisor(seed_machine, joined.poses, "rtest", run).candidates if m.again]
    named = {m.path: m.name for m in again}
    assert named["K2"] == "K2_AGAIN_3" and named["K4"] == "K4_AGAIN", named
    m = next(m for m in again if m.path == "K2")
    assert _times_measured(seed_machine, joined.poses, run, m) == 3


def _to_a_tenth_um(machine, **more):
    """The machine with its ball's Y given to 0.1 µm (-0.2791 mm), and ``more`` replaced."""
    from dataclasses import replace
    return replace(machine, ball=(machine.ball[0], -0.2791, machine.ball[2]), **more)


def test_the_json_s_ball_is_the_one_the_printed_command_measures_at(seed_machine):
    """A ball given to 0.1 µm (-0.2791 mm) halved has five decimals: the JSON rounds it as the
    command measure-program is given, so a script reading either measures at one place."""
    machine = _to_a_tenth_um(seed_machine)
    for m in Advisor(machine).candidates:
        given = re.search(r"--ball (\S+)", m.command("compgen"))[1]
        assert m.to_dict()["ball"] == [float(v) for v in given.split(",")], m.label


def test_what_was_measured_is_not_advised_as_new(seed_machine):
    """A ball and a nest given to 0.1 µm, K1 and K4 each run there and back: neither is
    advised there and back again, nor as a new measurement at the same place; only as a
    repeat right after (the data are timed). With nothing measured, a measurement's clock
    starts at 0 s, as a path's does."""
    machine = _to_a_tenth_um(seed_machine, probe_length=seed_machine.probe_length + 0.0004)
    measured = generate(machine, ["K1", "K4"], back=True)
    offered = [m.label for m in Advisor(machine, measured).candidates]
    assert not {"K1 there and back", "K4 there and back", "K1", "K4"} & set(offered), offered
    assert {"K1 again, right after these data", "K4 again, right after these data"} <= set(offered)
    assert all(m.poses.t[0] == 0.0 for m in Advisor(machine).candidates)


def test_the_gate_names_the_three_strongest_significant_effects(seed_machine, poses):
    """A 2/rev angle of C not modelled: more than three candidates fit some of it; the gate's
    reason (what kinematics and history add say) names the three strongest, as diagnose
    orders them, and what to do."""
    from compgen.statistics.gate import fit_gate
    data = [_session(seed_machine, poses, HIDDEN["ECC:h2"])]
    fit = identify(seed_machine, data)
    significant = [c["effect"] for c in diagnose(seed_machine, data, fit).to_dict()["candidates"]
                   if c["significant"]]
    assert len(significant) > 3
    assert fit_gate(seed_machine, data, fit) == [
        f"diagnose finds effects the model misses: {', '.join(significant[:3])} (run diagnose, add the "
        "effect with fit --add, and refit)"]


def test_absorbed_by_names_each_parameter_taking_a_quarter_of_the_signature(seed_machine, poses):
    """docs/diagnose.md: a parameter is named as absorbing a candidate when its part of the
    least-squares fit J x = c takes at least a quarter of c (‖J_i‖·‖x_i‖ ≥ ‖c‖/4), largest
    first. Checked against the stacked Jacobian, not the products diagnose uses; shares
    within 0.005 of the quarter are left to rounding."""
    from compgen.model.effects import resolve
    from compgen.model.kinematics import Model
    from compgen.statistics.signature import columns
    data = [_session(seed_machine, poses, {}, seed=3)]
    base = identify(seed_machine, data)
    found = diagnose(seed_machine, data, base)
    J = Model(seed_machine, list(base.model)).jacobian(poses).reshape(3 * len(poses), -1)
    J = J[:, [base.model.index(p) for p in base.free]]
    between = 0
    for c in found.candidates:
        e = resolve(seed_machine, c.effect)
        if e.basis.kind == "r" or c.silent:
            continue
        C = columns(seed_machine, poses, [e])
        x = np.linalg.lstsq(J, C, rcond=None)[0]
        share = np.linalg.norm(J, axis=0) * np.linalg.norm(x, axis=1) / np.linalg.norm(C)
        of = dict(zip(base.free, share, strict=True))
        clear = {p for p, s in of.items() if abs(s - 0.25) > 0.005}
        assert clear & set(c.confounded_with) == {p for p in clear if of[p] > 0.25}, (c.effect, of)
        said = [of[p] for p in c.confounded_with]                       # largest first
        assert all(a > b - 1e-9 for a, b in zip(said[:-1], said[1:], strict=True)), (c.effect, of)
        between += sum(0.3 < of[p] < 0.45 for p in clear)
    assert between > 20             # many parameters take between a quarter and a half


def test_equally_short_measurements_are_advised_by_how_far_they_tell_the_rivals_apart(seed_machine):
    """A positioning error of A growing with its angle and a 1/rev tilt of C, measured on
    K4: K2 as it is and K2 with the ball elsewhere (121 poses each) tell them apart. The
    plan and the rival's own list put first the one after which either, at its fitted
    size, leaves the larger misfit in a fit of the other: computed here by stacked least
    squares on the poses with each measurement added, not by diagnose's R factors."""
    from compgen.model.effects import effect_of_param, resolve
    from compgen.model.poses import Poses
    from compgen.statistics.signature import columns
    from compgen.units import shown
    poses = generate(seed_machine, ["K4"])
    data = [_session(seed_machine, poses, {"EAA:p1": 3 * ARCSEC})]
    fit = identify(seed_machine, data)
    pair = ["EAA:p1", "EBC:h1"]
    found = diagnose(seed_machine, data, fit, pair, advisor=Advisor)
    assert {found.significant[0].effect, *found.rivals} == set(pair)
    model = list(dict.fromkeys(effect_of_param(seed_machine, n) for n in fit.free))
    size = {c.effect: np.array(c.amplitude) / shown(1.0, resolve(seed_machine, c.effect).unit)[0]
            for c in found.candidates if c.effect in pair}

    def apart(P):             # what each, true, leaves in a fit of the other: the lesser
        left = []
        for a, b in (pair, pair[::-1]):
            A = columns(seed_machine, P, [*model, resolve(seed_machine, b)])
            v = columns(seed_machine, P, [resolve(seed_machine, a)]) @ size[a]
            left.append(float(np.sum((v - A @ np.linalg.lstsq(A, v, rcond=None)[0]) ** 2)))
        return min(left)

    advisor = Advisor(seed_machine, poses)
    now, sigma2 = apart(poses), (fit.residual["sigma_um"] * 1e-3) ** 2
    gain = {m.label: apart(Poses.concat([poses, m.poses])) - now for m in advisor.candidates}
    tells = sorted((m for m in advisor.candidates
                    if gain[m.label] >= 25 * sigma2 and advisor.why_not(m) is None),
                   key=lambda m: (len(m.poses), -gain[m.label]))
    shortest = [m.label for m in tells if len(m.poses) == len(tells[0].poses)]
    assert len(shortest) >= 2 and gain[shortest[0]] > 1.1 * gain[shortest[1]], {k: gain[k] for k in shortest}
    assert found.rivals_separated_by[0].label == shortest[0]
    rival = next(c for c in found.candidates if c.effect == found.rivals[0])
    assert [m.label for m in rival.separated_by] == [m.label for m in tells[:3]]


def test_a_1_rev_error_motion_turning_with_a_table_axis_is_sent_to_no_ball_position(seed_machine, poses):
    """A ball moved is mounted again, off by an offset of its own (``sides.mountings``): a
    1/rev radial or tilt error motion turning with C or A is, at every ball position, one
    more table-frame offset of the ball and a change of location errors, so no measurement
    separates it and diagnose says it needs an independent reference (with one offset for
    every position, K2 100 mm lower was said to show EAC+EBC:h1). What offsets cannot take,
    an axial 1/rev of C, another ball position still shows."""
    data = [_session(seed_machine, poses, {"EXC:h2c": 2 * UM})]
    found = diagnose(seed_machine, data, identify(seed_machine, data), advisor=Advisor)
    by = {c.effect: c for c in found.candidates}
    for name in ("EAC+EBC:h1", "EXC+EYC:h1", "EBA+ECA:h1", "EYA+EZA:h1"):
        assert not by[name].visible and not by[name].separated_by, name
    assert "it needs an independent reference" in report(found, top=len(found.candidates))
    assert not by["EZC:h1"].visible and any("ball" in m.label for m in by["EZC:h1"].separated_by)


def test_the_separations_take_each_mounting_of_the_ball_with_its_own_offset(seed_machine):
    """``separation.Measured``: R of the model's and the candidates' columns, with each later
    mounting's ball offset and each later nest's offset a nuisance, and with an extra
    measurement stacked as the fit would add it, continuing the last mounting and nest or
    with its own: RᵀR is the Gram matrix of the whole design with the offsets as explicit
    columns projected out, built here from the model's Jacobian. The data: K4 at the ball,
    K2 with the ball moved, K1 there with a longer nest (the ball's mounting and the nest
    change apart, so their offsets share rows without sharing a stretch)."""
    from types import SimpleNamespace

    from compgen.model.effects import effect_of_param, resolve
    from compgen.model.kinematics import Model
    from compgen.model.poses import Poses
    from compgen.model.sides import NEST, SETUP
    from compgen.statistics.separation import Measured
    names = list(location_model(seed_machine))
    model_effects = list(dict.fromkeys(effect_of_param(seed_machine, n) for n in names))
    candidates = [resolve(seed_machine, "EZC:h1"), resolve(seed_machine, "EXC:h2")]
    params = [*names, *(p for e in candidates for p in e.params)]
    moved = np.add(seed_machine.ball, [30.0, -20.0, 0.0])

    def measure(path, ball=None, nest=None):
        p = generate(seed_machine, [path], ball=ball)
        return Poses(p.q, p.ball, p.t, p.path, p.side, np.full(len(p), np.nan if nest is None else nest))

    data = [(measure("K4"), 0, 0), (measure("K2", moved), 1, 0), (measure("K1", moved, 150.0), 1, 1)]
    measured = Measured(seed_machine, model_effects, Poses.concat([p for p, *_ in data]), candidates)
    at = [names.index(n) for n in SETUP]
    for label, extra in (("continues both", (measure("K2", moved, 150.0), 1, 1)),
                         ("a longer nest", (measure("K4", moved, 200.0), 1, 2)),
                         ("the ball back, the nest back", (measure("K1"), 2, 2))):
        R = measured.with_extra(SimpleNamespace(label=label, poses=extra[0]))
        parts = [*data, extra]
        poses = Poses.concat([p for p, *_ in parts])
        full = Model(seed_machine, params).jacobian(poses)
        nest = Model(seed_machine, NEST).jacobian(poses)
        ball_at = np.concatenate([np.full(len(p), b) for p, b, _ in parts])
        nest_at = np.concatenate([np.full(len(p), k) for p, _, k in parts])
        N = np.concatenate([full[:, :, at] * (ball_at == k)[:, None, None] for k in (1, 2)]
                           + [nest * (nest_at == k)[:, None, None] for k in (1, 2)], axis=2)
        A, N = full.reshape(-1, len(params)), N.reshape(-1, N.shape[2])
        N = N[:, np.abs(N).sum(axis=0) > 0]
        want = A - N @ np.linalg.lstsq(N, A, rcond=None)[0]
        gram = want.T @ want
        np.testing.assert_allclose(R.T @ R, gram, rtol=1e-7, atol=1e-9 * np.abs(gram).max(), err_msg=label)


def test_diagnoses_first_line_is_its_verdict_on_every_kind_of_conclusion(tmp_path):
    """The conclusion first, in one line, the same as the JSON's verdict: on the bundled
    example without the noise (noise unknown: give it), with it (found EXC:h2, the command
    that adds it), once it is added (explained to the noise), K4 alone with a hidden 2/rev
    tilt (rivals, what to measure) and a 5 mm ball-screw period (unexplained)."""
    from conftest import ROOT, run
    session = ROOT / "examples" / "seed-session.csv"
    assert run("fit", "--machine", "ac-trunnion-itnc530", session, "-o", tmp_path / "ex.json")[0] == 0
    assert run("fit", "--from", tmp_path / "ex.json", "--add", "EXC:h2", "-o", tmp_path / "ex2.json")[0] == 0
    machine = load_machine(SEED_MACHINE)
    for name, hidden, paths in (("rivals", {"EAC+EBC:h2c": 8 * ARCSEC}, ["K4"]),
                                ("screw", {"EXX:w5c": 1.2 * UM, "EXX:w5s": -1.6 * UM}, ["K4", "K1", "K2"])):
        d = simulate(machine, {**TABLE4, **hidden}, generate(machine, paths), 0.5, np.random.default_rng(3))
        (tmp_path / f"{name}.csv").write_text(format_rtest(machine, d))
        fitted = tmp_path / f"{name}.json"
        assert run("fit", "--machine", SEED_MACHINE, tmp_path / f"{name}.csv", "-o", fitted)[0] == 0
    cases = [("ex.json", [], "noise unknown", "give --noise-um"),
             ("ex.json", ["--noise-um", "0.5"], "found", "found EXC:h2 (against the given noise 0.5 µm"),
             ("ex2.json", ["--noise-um", "0.5"], "explained", "explained to the noise"),
             ("rivals.json", ["--noise-um", "0.5"], "rivals", "not told apart:"),
             ("screw.json", ["--noise-um", "0.5"], "unexplained", "unexplained:")]
    for fit, more, kind, says in cases:
        code, out, err = run("diagnose", "--from", tmp_path / fit, *more)
        assert code == 0 and out.startswith("VERDICT: ") and says in out.splitlines()[0], (fit, out[:600])
        code, js, err = run("diagnose", "--from", tmp_path / fit, *more, "--json")
        assert json.loads(js)["verdict"] == kind, (fit, json.loads(js)["verdict"])
    found = run("diagnose", "--from", tmp_path / "ex.json", "--noise-um", "0.5")[1]
    assert f"add it: {me()} fit --from " in found.splitlines()[0], found.splitlines()[0]
    assert found.count("add it:") == 2         # the verdict's and the best's; never the others'


@pytest.mark.parametrize("truth, repeats", [
    ({"YOC:t1": 4 * UM, "AOC:t1": 6 * ARCSEC}, ["K1_BACK"]),
    ({"YOC:t1": 4 * UM, "AOC:t1": 6 * ARCSEC, "COA:e15": 3 * ARCSEC}, ["K1_AGAIN", "K1_AGAIN_2"])])
def test_drifts_at_once_are_named_as_the_truth_each_advised_command_pasted(seed_machine, poses, tmp_path,
                                                                         truth, repeats):
    """YOC and AOC drifting linearly (4 µm/h, 6″/h), and with a warming of C's tilt besides.
    Followed as a user would, nothing but the truth is named found; the rivals a second drift
    leaves tied (AOC:t1 against a saturating AOC) are judged beside it once the advised runs
    are in; the loop ends explained to the noise with the location errors within 3σ (with a
    misfit-left rival judged alone it ended unexplained, 10.7σ off). Every advised command
    pastes into bash as printed, each repeat under a file name of its own (a remark in
    parentheses after the command was a syntax error, and a second "K2 again" reused
    K2_AGAIN)."""
    import sys
    from pathlib import Path

    from compgen.statistics.gate import fit_gate
    data, model, rng, verdicts = [_session(seed_machine, poses, truth)], location_model(seed_machine), 8, []
    names, env = [], {"PATH": f"{Path(sys.executable).parent}:/usr/bin:/bin"}
    for _ in range(8):
        fit = identify(seed_machine, data, model)
        found = diagnose(seed_machine, data, fit, noise_um=NOISE_UM, advisor=Advisor)
        verdicts.append(found.verdict)
        if found.found:
            assert found.found in truth, (found.found, verdicts)
            model = compose(seed_machine, model, [found.found])
        elif found.verdict == "rivals":
            m = found.rivals_separated_by[0]
            names.append(m.name)
            # the advised command, as its line prints it (a remark after it is a bash comment),
            # runs pasted into bash: a repeat's program gets a file name of its own each time
            line = next(ln.strip() for ln in report(found).splitlines() if f" -o {m.name}." in ln)
            done = pasted(line, tmp_path, env, timeout=120)
            assert done.returncode == 0, (line, done.stderr)
            rng += 1
            data.append(_session(seed_machine, m.poses, truth, seed=rng))
        else:
            break
    assert names == repeats and set(model[11:]) == set(truth), (names, model, verdicts)
    assert found.explained_to_noise and not fit_gate(seed_machine, data, fit), verdicts
    off = max(abs(fit.parameters[n].value - v) / fit.parameters[n].std for n, v in TABLE4.items())
    assert off < 3, off


def _two_files(machine, first_truth, second_truth, seed):
    """K4 + K1 in a.csv, then, two minutes later, K2 + K4 in b.csv at the same ball position,
    each file with its truth (time runs on from a.csv into b.csv)."""
    from dataclasses import replace
    rng = np.random.default_rng(seed)
    first = generate(machine, ["K4", "K1"])
    then = generate(machine, ["K2", "K4"], start_s=float(np.nanmax(first.t)) + 120.0)
    return [replace(simulate(machine, first_truth, first, NOISE_UM, rng), source="a.csv", sha256="1" * 64),
            replace(simulate(machine, second_truth, then, NOISE_UM, rng), source="b.csv", sha256="2" * 64)]


@pytest.mark.parametrize("seed", range(3))
def test_a_ball_mounted_again_at_its_place_between_two_files_is_never_read_as_a_warming(seed_machine, seed):
    """The ball taken off and put back between a.csv and b.csv, 3, −2, 1.5 µm from where it
    was (the same nominal position: one mounting to the fit). A warming of the ball
    (XOW:e45) fits most of the step and was named found; now the step between the files is
    its rival, said in the first line with its size, and the gate refuses an edit. A real
    warming spanning the two files is still found, and clean data stay explained."""
    from compgen.statistics.gate import gate_reasons
    moved = {**TABLE4, **{n: TABLE4.get(n, 0.0) + v * UM for n, v in zip(("XOW", "YOW", "ZOW"), (3, -2, 1.5),
                                                                          strict=True)}}
    data = _two_files(seed_machine, TABLE4, moved, seed)
    fit = identify(seed_machine, data, location_model(seed_machine))
    d = diagnose(seed_machine, data, fit, noise_um=NOISE_UM)
    assert d.verdict == "set-up step" and d.found is None, (d.verdict, d.found)
    assert d.setup_step.before == "b.csv" and np.allclose(d.setup_step.ball_um, (3, -2, 1.5), atol=0.4), \
        d.setup_step
    text = report(d)
    assert "add it:" not in text and "explains these data as well: not named found" in text, text
    first = text.splitlines()[0]
    assert first.startswith(f"VERDICT: not told apart: {d.significant[0].effect} vs the ball or the nest "
                            "mounted again before b.csv (ball +"), first
    assert any("mounted again before b.csv" in r for r in gate_reasons(data, fit, d))
    assert d.to_dict()["setup_step"]["rivals_best"] is True
    for truth, verdict in (({**TABLE4, "XOW:e45": 4 * UM}, "found"), (TABLE4, "explained")):
        data = _two_files(seed_machine, truth, truth, seed)
        d = diagnose(seed_machine, data, identify(seed_machine, data, location_model(seed_machine)),
                     noise_um=NOISE_UM)
        assert d.verdict == verdict and (verdict != "found" or d.found == "XOW:e45"), (d.verdict, d.found)


@pytest.mark.parametrize("seed", range(3))
def test_a_file_said_mounted_again_has_offsets_of_its_own_and_one_said_untouched_no_step(seed_machine, seed):
    """The same re-mounting (3, −2, 1.5 µm) said by the user (fit --mounted-again b.csv): b.csv's
    readings get the ball's and the nest's offsets of their own, the fit reaches the noise
    with every location error within 3σ of seed Table 4, and diagnose finds nothing to add.
    A warming said untouched across the files is found, with no step tried before b.csv."""
    from compgen.configuration.session import said_of
    moved = {**TABLE4, **{n: TABLE4.get(n, 0.0) + v * UM for n, v in zip(("XOW", "YOW", "ZOW"), (3, -2, 1.5),
                                                                          strict=True)}}
    data = said_of(seed_machine, _two_files(seed_machine, TABLE4, moved, seed), again=["b.csv"])
    fit = identify(seed_machine, data, location_model(seed_machine))
    assert fit.residual["sigma_um"] == pytest.approx(NOISE_UM, rel=0.05)
    off = {n: abs(e.value - TABLE4[n]) / e.std for n, e in fit.parameters.items()}
    assert max(off.values()) < 3, off
    assert fit.data[1].said == "mounted again"
    d = diagnose(seed_machine, data, fit, noise_um=NOISE_UM)
    assert d.verdict == "explained" and d.setup_step is None, (d.verdict, d.found, d.setup_step)
    warm = {**TABLE4, "XOW:e45": 4 * UM}
    data = said_of(seed_machine, _two_files(seed_machine, warm, warm, seed), untouched=["b.csv"])
    fit = identify(seed_machine, data, location_model(seed_machine))
    d = diagnose(seed_machine, data, fit, noise_um=NOISE_UM)
    assert d.found == "XOW:e45" and d.setup_step is None, (d.verdict, d.found, d.setup_step)


def test_what_a_user_says_of_a_file_is_kept_with_the_fit_and_checked(seed_machine, tmp_path):
    """fit --mounted-again b.csv: the fit file keeps it and diagnose --from reads the data so;
    a file said untouched whose ball stands elsewhere, the first file, a file not in the fit,
    and a file said both are each refused in one line, nothing written."""
    rng = np.random.default_rng(4)
    moved = {**TABLE4, "XOW": TABLE4["XOW"] + 3 * UM, "YOW": TABLE4["YOW"] - 2 * UM}
    for name, truth, ball in (("a.csv", TABLE4, None), ("b.csv", moved, None),
                              ("c.csv", TABLE4, (100.0, 0, 50))):
        poses = generate(seed_machine, ["K4", "K2"], ball=ball)
        session = simulate(seed_machine, truth, poses, NOISE_UM, rng)
        (tmp_path / name).write_text(format_rtest(seed_machine, session))
    fit = tmp_path / "f.json"
    code, out, err = run("fit", "--machine", SEED_MACHINE, tmp_path / "a.csv", tmp_path / "b.csv",
                         "--mounted-again", tmp_path / "b.csv", "-o", fit)
    assert code == 0, err
    assert "or where it was said mounted again" in err, err
    assert [x.get("said", "") for x in json.loads(fit.read_text())["data"]] == ["", "mounted again"]
    code, out, err = run("diagnose", "--from", fit, "--noise-um", NOISE_UM)
    assert code == 0 and out.startswith("VERDICT: explained"), out
    a, b, c = (tmp_path / n for n in ("a.csv", "b.csv", "c.csv"))
    for args, said in (((c, "--not-touched", c), "is said not touched, but"),
                       ((b, "--mounted-again", a), "the fit's first data file"),
                       ((b, "--mounted-again", c), "is not among the fit's data"),
                       ((b, "--mounted-again", b, "--not-touched", b), "is said both")):
        code, _, err = run("fit", "--machine", SEED_MACHINE, a, *args, "-o", tmp_path / "g.json")
        assert code == 2 and said in err and err.count("\n") == 1, err
        assert not (tmp_path / "g.json").exists()


def test_exact_equivalents_are_one_candidate_found_under_every_name(head_machine):
    """On a head over a C table the nest growing along the tool's Z (drift_Z) and the ball's
    stem warming (ZOW) are one column at every set-up the machine can measure: found under
    both names, not "not told apart"; the rivals of a hidden 2/rev of C, which a measurement
    tells apart, are no equivalents."""
    truth = {"XOC": 6 * UM, "YOC": -8 * UM, "XOB": 10 * UM, "ZOB": -7 * UM, "drift_Z:e15": 6 * UM}
    poses = generate(head_machine, ["K4", "K1", "K2"])
    data = [simulate(head_machine, truth, poses, NOISE_UM, np.random.default_rng(11))]
    found = diagnose(head_machine, data, identify(head_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert found.verdict == "found" and {found.found, *found.equivalents} == {"drift_Z:e15", "ZOW:e15"}, \
        (found.verdict, found.found, found.rivals, found.equivalents)
    first = report(found).splitlines()[0]
    assert first.startswith(f"VERDICT: found {found.found} ≡ {found.equivalents[0]}, one column"), first
    assert found.to_dict()["equivalents_of_best"] == list(found.equivalents)
    data = [simulate(head_machine, {**truth, "drift_Z:e15": 0.0, "EXC:h2c": 3 * UM}, poses, NOISE_UM,
                     np.random.default_rng(11))]
    found = diagnose(head_machine, data, identify(head_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert found.rivals and found.rivals_separated_by and not found.equivalents, \
        (found.verdict, found.rivals, found.equivalents)


@pytest.mark.parametrize("seed", range(2))
def test_a_ball_mounted_again_in_a_pause_within_one_file_is_a_step_not_a_warming(seed_machine, seed):
    """The re-mounting of the two-file case (3, −2, 1.5 µm), made in a 5-minute pause within
    one file: the step at the pause is the best's rival, named by the time it came; a warming
    across the pause is still found, and clean data with the pause stay explained."""
    from dataclasses import replace

    from compgen.model.poses import Poses
    moved = {**TABLE4, **{n: TABLE4.get(n, 0.0) + v * UM for n, v in zip(("XOW", "YOW", "ZOW"), (3, -2, 1.5),
                                                                          strict=True)}}

    def one_file(first_truth, second_truth):
        a, b = _two_files(seed_machine, first_truth, second_truth, seed)
        late = b.poses.starting_at(float(np.nanmax(a.poses.t)) + 300.0)
        return [replace(a, poses=Poses.concat([a.poses, late]), lines=(),
                        deviation=np.vstack([a.deviation, b.deviation]))]

    warm = {**TABLE4, "XOW:e45": 4 * UM}
    for first, second, verdict in ((TABLE4, moved, "set-up step"), (warm, warm, "found"),
                                   (TABLE4, TABLE4, "explained")):
        data = one_file(first, second)
        d = diagnose(seed_machine, data, identify(seed_machine, data, location_model(seed_machine)),
                     noise_um=NOISE_UM)
        assert d.verdict == verdict, (verdict, d.verdict, d.found, d.setup_step)
        if verdict == "set-up step":
            assert "a.csv at t = " in d.setup_step.before and "s pause)" in d.setup_step.before, d.setup_step
            assert np.allclose(d.setup_step.ball_um, (3, -2, 1.5), atol=0.4), d.setup_step


def test_the_nest_growing_along_a_heads_tool_axis_is_named_as_the_nest(head_machine, seed_machine):
    """The spindle warming: the nest grows along the tool axis (nest_Z in the tool's frame,
    saturating), which a head turns, where a drift of tool to table stays along the
    machine's Z. Its readings are the tool's z times 1 − exp(−t/τ); on a head it is found
    under its own name, not as a drift, and with it added the location errors hold the
    truth; where the tool never turns (the seed's trunnion) it is the drift's column."""
    from compgen.model.frames import sensor_axes
    from compgen.model.kinematics import Model
    poses = generate(head_machine, ["K4", "K1", "K2"])
    grown = Model(head_machine, ["nest_Z:e15"]).deviation(poses, np.array([1.0]))
    rise = 1 - np.exp(-poses.t / (15 * 60.0))
    np.testing.assert_allclose(grown, sensor_axes(head_machine, poses.q)[:, :, 2] * rise[:, None], atol=1e-12)
    assert np.ptp(sensor_axes(head_machine, poses.q)[:, 2, 2]) > 0.1        # the head turns the tool
    truth = {"XOC": 6 * UM, "YOC": -8 * UM, "XOB": 10 * UM, "ZOB": -7 * UM, "nest_Z:e15": 8 * UM}
    data = [simulate(head_machine, truth, poses, NOISE_UM, np.random.default_rng(11))]
    found = diagnose(head_machine, data, identify(head_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    names = {found.found, *found.equivalents}
    assert found.verdict == "found" and "nest_Z:e15" in names and "drift_Z:e15" not in names, \
        (found.verdict, found.found, found.rivals, found.equivalents)
    fit = identify(head_machine, data, compose(head_machine, location_model(head_machine), ["nest_Z:e15"]))
    off = {n: abs(fit.parameters[n].value - v) / fit.parameters[n].std for n, v in truth.items()}
    assert max(off.values()) < 3, off
    seed, one = generate(seed_machine, ["K4", "K1", "K2"]), np.array([1.0])
    np.testing.assert_allclose(Model(seed_machine, ["nest_Z:e15"]).deviation(seed, one),
                               Model(seed_machine, ["drift_Z:e15"]).deviation(seed, one), atol=1e-12)


def test_a_marginal_tie_no_set_up_parts_is_measured_again_before_any_is_named(seed_machine, poses):
    """Clean data (seed 30: the seed's Table 4 alone, 0.5 µm) where chance passes the
    family's 1 %: EBA:h3 at p 0.0095 tied with four shapes no set-up parts at their sizes.
    diagnose said "any one of them models the misfit: add it"; a marginal tie (p above a tenth
    of α) now gets the repeat right after the data, said to be near the noise, and measured
    again as advised the chance misfit fades: explained, nothing named (the discovery
    benchmark's two linear drifts ended so with a third, wrong, name)."""
    data = [_session(seed_machine, poses, {}, seed=30)]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert found.verdict == "rivals" and found.significant[0].p_value > 0.001, found.verdict
    assert [m.label for m in found.rivals_separated_by] == ["K4 again, right after these data"]
    text = report(found)
    assert "the misfit is near the noise (p 0.0095 against the family's 0.01)" in text, text
    assert "add it:" not in text.splitlines()[0] and "Any one of them models the misfit" not in text
    data.append(_session(seed_machine, found.rivals_separated_by[0].poses, {}, seed=31))
    again = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert again.verdict == "explained" and not again.significant, (again.verdict, again.significant[:1])
