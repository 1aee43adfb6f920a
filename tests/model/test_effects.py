"""The effect catalogue: every entry well-formed and evaluable, rotary component errors
against the seed report's Table 1, and the signs of the non-ISO effects."""

import numpy as np
import pytest
from conftest import SEED_MACHINE

from compgen.configuration.machine_file import load_machine
from compgen.errors import CompgenError
from compgen.model.effects import canonical, catalogue, location_model, resolve
from compgen.model.kinematics import Model
from compgen.model.paths import generate
from compgen.model.poses import Poses

SEED = load_machine(SEED_MACHINE)
ULPS_AT_100_MM = 1e-13   # mm: a few units in the last place of a 100 mm coordinate
POSES = generate(SEED, ["K4", "K1", "K2"])
THERE_AND_BACK = generate(SEED, ["K4", "K1", "K2"], back=True)    # what a reversal needs


@pytest.mark.parametrize("effect", catalogue(SEED), ids=lambda e: e.name)
def test_every_effect_is_well_formed_and_moves_the_readings(effect):
    assert resolve(SEED, effect.name) == effect
    poses = THERE_AND_BACK if effect.basis.kind == "r" else POSES
    J = Model(SEED, effect.params).jacobian(poses)
    assert np.isfinite(J).all()
    assert J.shape == (len(poses), 3, len(effect.params))
    assert effect.words and effect.unit in ("mm", "rad")
    # every column moves the readings, except a turn about the tool axis of a carriage that
    # carries the spindle: its axis passes through the nest, which it cannot move
    about_the_nest = effect.carrier in ("Y", "Z") and effect.direction == "c"
    assert (np.abs(J).max(axis=(0, 1)) > 1e-6).all() != about_the_nest, effect.name


def test_catalogue_names_are_unique_and_hold_the_default_model():
    names = [e.name for e in catalogue(SEED)]
    params = [p for e in catalogue(SEED) for p in e.params]
    assert len(set(names)) == len(names) and len(set(params)) == len(params)
    assert set(location_model(SEED)) <= set(names)
    assert location_model(SEED) == ("XOW", "YOW", "ZOW", "YOA", "ZOA", "BOA", "COA",
                                    "XOC", "YOC", "AOC", "BOC")


def table1_rotary(A, C, Xw, Yw, Zw, Zc):
    """Seed report Table 1, rows of the A and C component errors, columns dX dY dZ."""
    Ca, Sa, Cc, Sc = np.cos(A), np.sin(A), np.cos(C), np.sin(C)
    z, one = np.zeros_like(A), np.ones_like(A)
    return {
        "EXA": (-one, z, z), "EYA": (z, -one, z), "EZA": (z, z, -one),
        "EAA": (z, Sa * Sc * Xw + Sa * Cc * Yw + Ca * (Zw + Zc),
                -Ca * Cc * Yw + Sa * (Zw + Zc) - Ca * Sc * Xw),
        "EBA": (-Ca * (Zw + Zc) - Sa * Sc * Xw - Sa * Cc * Yw, z, -Sc * Yw + Cc * Xw),
        "ECA": (-Sa * (Zw + Zc) + Ca * Sc * Xw + Ca * Cc * Yw, -Cc * Xw + Sc * Yw, z),
        "EXC": (-one, z, z), "EYC": (z, -Ca, -Sa), "EZC": (z, Sa, -Ca),
        "EAC": (z, Sc * Sa * Xw + Cc * Sa * Yw + Ca * Zw, -Cc * Ca * Yw + Sa * Zw - Sc * Ca * Xw),
        "EBC": (-Zw * one, -Cc * Sa * Xw + Sc * Sa * Yw, -Sc * Ca * Yw + Cc * Ca * Xw),
        "ECC": (Sc * Xw + Cc * Yw, -Ca * Cc * Xw + Ca * Sc * Yw, Sa * Sc * Yw - Sa * Cc * Xw),
    }


@pytest.mark.parametrize("symbol", list(table1_rotary(*np.zeros(6))))
def test_rotary_component_error_gains_equal_seed_table1(symbol):
    A, C = POSES.q[:, 3], POSES.q[:, 4]
    want = np.column_stack(np.broadcast_arrays(
        *table1_rotary(A, C, *SEED.ball, SEED.axis("C").offset[2])[symbol], A))[:, :3]
    if symbol.endswith("C"):   # full turn: a unit error at every angle is h1c·cos C + h1s·sin C
        J = Model(SEED, [f"{symbol}:h1c", f"{symbol}:h1s"]).jacobian(POSES)
        got = J[:, :, 0] * np.cos(C)[:, None] + J[:, :, 1] * np.sin(C)[:, None]
    else:                      # tilting: p1 is the error per rad of A
        J = Model(SEED, [f"{symbol}:p1"]).jacobian(POSES)[:, :, 0]
        keep = np.abs(A) > 0.05
        got, want, A = J[keep] / A[keep, None], want[keep], A[keep]
    scale = 1.0 if symbol[1] in "XYZ" else 1e3   # angular gains are in mm per rad
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * scale)


def _one_pose(q, t=0.0):
    return Poses(np.array([q]), np.array([SEED.ball]), np.array([t]), np.array(["x"], dtype=object))


def test_drift_scale_and_nest_signs():
    q = [100.0, 50.0, 200.0, 0.0, 0.0]
    # tool drifts +1 µm/h in Z relative to the table: after an hour nest − ball = +1 µm
    dev = Model(SEED, ["drift_Z:t1"]).deviation(_one_pose(q, 3600.0), np.array([1e-3]))
    np.testing.assert_allclose(dev[0], [0, 0, 1e-3], atol=1e-12)
    # X carries the table; a +10 µm/m scale error of X at X = 100 mm moves the table frame
    # 1 µm further in +x, the ball with it: nest − ball = −1 µm
    dev = Model(SEED, ["EXX:p1"]).deviation(_one_pose(q), np.array([10e-3]))
    np.testing.assert_allclose(dev[0], [-1e-3, 0, 0], atol=1e-12)
    # Y carries the spindle: a +10 µm/m scale error at Y = 50 mm moves the nest +0.5 µm
    dev = Model(SEED, ["EYY:p1"]).deviation(_one_pose(q), np.array([10e-3]))
    np.testing.assert_allclose(dev[0], [0, 0.5e-3, 0], atol=1e-12)
    # nest offset +1 µm in X on a vertical spindle: nest − ball = +1 µm in X
    dev = Model(SEED, ["nest_X"]).deviation(_one_pose(q), np.array([1e-3]))
    np.testing.assert_allclose(dev[0], [1e-3, 0, 0], atol=1e-12)


def test_squareness_of_x_tilts_its_line_only():
    # COX turns X's line about Z by θ. X is a table axis (sense −1): at X = 100 mm the table
    # sits at −100·(cos θ, sin θ), so nest − ball = (−100·(1 − cos θ), 100·sin θ, 0), exactly
    theta = np.radians(10 / 3600)
    dev = Model(SEED, ["COX"]).deviation(_one_pose([100.0, 0, 0, 0, 0]), np.array([theta]))
    np.testing.assert_allclose(dev[0], [-100 * (1 - np.cos(theta)), 100 * np.sin(theta), 0],
                               rtol=0, atol=ULPS_AT_100_MM)
    at_zero = Model(SEED, ["COX"]).deviation(_one_pose([0.0, 0, 0, 0, 0]), np.array([1e-4]))
    np.testing.assert_allclose(at_zero, 0, atol=1e-15)   # the carried frame is not turned


@pytest.mark.parametrize("text, canon", [("X0C", "XOC"), ("E_X0C", "XOC"), ("EX0C", "XOC"),
                                         ("B0A", "BOA"), ("ECC:h2", "ECC:h2"), ("EXX", "EXX")])
def test_aliases(text, canon):
    assert canonical(text) == canon


@pytest.mark.parametrize("name, expected", [("ECC", "needs an order"), ("ECC:p1", "takes hN"),
                                            ("EAA:e5", "takes pN or hN"), ("XOC:h1", "takes"),
                                                ("ECC:h-2", "takes hN"), ("EXC+EYC:h0", r"N < 0 turns"),
                                                ("XOC:e0", "τ = N min"), ("EXC+EYC:p1", "takes hN"),
                                            ("QQQ", "unknown effect"), ("ECC:h0", "N ≥ 1"),
                                            ("EYX:p1", "squareness")])
def test_bad_effect_names_say_what_is_accepted(name, expected):
    with pytest.raises(CompgenError, match=expected):
        resolve(SEED, name)


def test_a_compound_is_its_iso_components_turning_together():
    """The issue's 2/rev radial motion of C turning with C: (EXC, EYC) = r·(cos 2C, sin 2C)
    is EXC:h2c = r with EYC:h2s = r; against C, (r·cos 2C, −r·sin 2C); a vector at phase
    90° (s = r) is (−r·sin 2C, r·cos 2C)."""
    poses = generate(SEED, ["K4"])
    r = 2e-3

    def dev(values):
        return Model(SEED, list(values)).deviation(poses, np.array(list(values.values())))

    for k, turn in ((2, 1), (-2, -1)):
        np.testing.assert_allclose(dev({f"EXC+EYC:h{k}c": r}), dev({"EXC:h2c": r, "EYC:h2s": turn * r}),
                                   atol=1e-12)
    np.testing.assert_allclose(dev({"EXC+EYC:h2s": r}), dev({"EXC:h2s": -r, "EYC:h2c": r}), atol=1e-12)
    np.testing.assert_allclose(dev({"EAC+EBC:h3c": 1e-5}), dev({"EAC:h3c": 1e-5, "EBC:h3s": 1e-5}),
                               atol=1e-12)


def test_tilting_axis_shapes_start_at_zero_and_gravity_turns_with_the_axis():
    """A sag g turning with A, EYA = g·sin A and EZA = g·(1 − cos A), is the compound
    EYA+EZA:h1 at phase −90°; every harmonic of a tilting axis is zero at A = 0."""
    from compgen.model.kinematics import SLOT_INDEX, relative
    poses = generate(SEED, ["K1"])
    A = poses.q[:, SEED.index("A")]
    g = 3e-3
    slot = np.zeros((len(A), 6))                       # the component slot of A, written out
    slot[:, SLOT_INDEX["y"]], slot[:, SLOT_INDEX["z"]] = g * np.sin(A), g * (1 - np.cos(A))
    truth = relative(SEED, poses, {("A", "comp"): slot}) - relative(SEED, poses, {})
    sag = Model(SEED, ["EYA+EZA:h1s"]).deviation(poses, np.array([-g]))
    np.testing.assert_allclose(sag, truth, atol=1e-12)
    parts = Model(SEED, ["EYA:h1s", "EZA:h1c"]).deviation(poses, np.array([g, -g]))   # × (cos A − 1)
    np.testing.assert_allclose(parts, truth, atol=1e-12)
    at_zero = Poses.at(poses.q[np.argmin(np.abs(A))][None], SEED.ball)
    for e in catalogue(SEED):
        if e.carrier == "A" and e.basis.kind == "h":
            x = np.full(len(e.params), 1e-3)
            assert np.abs(Model(SEED, e.params).deviation(at_zero, x)).max() < 1e-12, e.name


def test_diagnose_signatures_are_the_models_first_order_columns():
    """For every catalogue effect (compounds, tilting harmonics, saturating growth among
    them), the analytic signatures diagnose ranks by equal the exact model's central
    differences at zero."""
    from compgen.statistics.signature import columns as _columns
    poses = generate(SEED, ["K4"])
    poses = Poses(poses.q, poses.ball, np.linspace(0, 3600, len(poses)), poses.path)
    for e in catalogue(SEED):
        J = Model(SEED, e.params).jacobian(poses).reshape(-1, len(e.params))
        np.testing.assert_allclose(_columns(SEED, poses, [e]), J, rtol=0,
                                   atol=1e-7 * max(np.abs(J).max(), 1.0), err_msg=e.name)


@pytest.mark.parametrize("sense", [1, -1])
def test_a_radial_vector_turning_with_the_table_at_1_per_rev_is_a_ball_offset(sense):
    """Whatever the sign between C's coordinate and its motion, a radial motion turning with
    the table once a turn moves the ball as an offset on the table does (XOW, YOW), and the
    one turning against it does not."""
    import dataclasses
    machine = dataclasses.replace(SEED, workpiece=tuple(
        dataclasses.replace(a, sense=sense) if a.name == "C" else a for a in SEED.workpiece))
    poses = generate(SEED, ["K4"])
    ball = Model(machine, ["XOW", "YOW"]).jacobian(poses).reshape(-1, 2)

    def unexplained(name):
        c = Model(machine, [f"{name}c", f"{name}s"]).jacobian(poses).reshape(-1, 2)
        return np.linalg.norm(c - ball @ np.linalg.lstsq(ball, c, rcond=None)[0]) / np.linalg.norm(c)

    assert unexplained("EXC+EYC:h1") < 1e-6          # finite differences: ~2e-8
    assert unexplained("EXC+EYC:h-1") > 0.5


def test_words_and_causes_name_the_physics(seed_machine):
    """What a machine builder would say: a tilting axis's radial motion is gravity sag, a
    turning table's is its bearing; axial, radial and tilt are not swapped."""
    from compgen.model.effects import resolve
    words = {n: resolve(seed_machine, n) for n in ("EYA+EZA:h1", "EZA:h1", "EXC+EYC:h2", "EZC:h1",
                                                   "EXC:h2", "EAC:h1", "EXX:p1", "EXX:w5")}
    assert "gravity sag" in words["EYA+EZA:h1"].cause and "gravity sag" in words["EZA:h1"].cause
    assert "gravity" not in words["EXC+EYC:h2"].cause and "bearing" in words["EXC+EYC:h2"].cause
    assert words["EZC:h1"].words.startswith("axial") and words["EXC:h2"].words.startswith("radial")
    assert words["EAC:h1"].words.startswith("tilt") and "scale" in words["EXX:p1"].cause
    assert "pitch of 5 mm" in words["EXX:w5"].words and "ball-screw" in words["EXX:w5"].cause


def test_every_basis_has_the_shape_its_name_says():
    """Each basis kind's values against its formula written out here: harmonics of the angle
    (a tilting axis's from angle 0), polynomials of position per metre and of hours, the
    saturating growth 1 − exp(−t/τ), a period along a linear axis in mm, the side of a
    reversal, a constant."""
    from compgen.model.effects import POLY_SCALE_MM, TIME_SCALE_S, Basis
    x = np.array([-0.7, 0.0, 0.3, 1.9])
    cases = {
        Basis("h", 3): np.column_stack([np.cos(3 * x), np.sin(3 * x)]),
        Basis("h", 2, origin=True): np.column_stack([np.cos(2 * x) - 1, np.sin(2 * x)]),
        Basis("p", 2): (x**2)[:, None],
        Basis("t", 1): x[:, None],
        Basis("r", 1): x[:, None],
        Basis("const"): np.ones((4, 1)),
    }
    for basis, expected in cases.items():
        np.testing.assert_allclose(basis.values(x), expected, rtol=1e-14, atol=0)
    mm = np.array([0.0, 1.25, 2.5, 7.0])                  # X at these mm, pitch 5 mm
    turn = 2 * np.pi * mm / 5.0
    np.testing.assert_allclose(Basis("w", pitch=5.0).values(mm / POLY_SCALE_MM),
                               np.column_stack([np.cos(turn), np.sin(turn)]), atol=1e-12)
    seconds = np.array([0.0, 300.0, 900.0, 3600.0])       # τ = 15 min
    np.testing.assert_allclose(Basis("e", 15).values(seconds / TIME_SCALE_S)[:, 0],
                               1 - np.exp(-seconds / 900.0), rtol=1e-12)


def test_the_catalogue_offers_the_orders_it_says():
    """Per symbol of the seed machine, the orders catalogue() offers: harmonics 1-4 of the
    turning C and of the tilting A (an encoder's 4/rev shows over A's tilt), compounds both
    ways, polynomials 1-3 (a straightness from 2: its order 1 is a squareness), drift in
    hours 1-2 and τ 5, 15, 45 min; a location error in time, linear (t1) or saturating; the
    ball's stem saturating only; a scale (a positioning error linear in position) growing
    with τ 5, 15, 45 min, on the linear axes and the tilting A, never on C's full turn."""
    names = {e.name for e in catalogue(SEED)}
    have = lambda prefix: sorted(n[len(prefix):] for n in names if n.startswith(prefix))  # noqa: E731
    assert have("ECC:") == ["h1", "h2", "h3", "h4", "r1"]
    assert have("ECA:") == ["h1", "h2", "h3", "h4", "p1", "p2", "p3"]
    assert have("EXC+EYC:") == ["h-1", "h-2", "h-3", "h-4", "h1", "h2", "h3", "h4"]
    assert have("EYA+EZA:") == ["h-1", "h-2", "h-3", "h-4", "h1", "h2", "h3", "h4"]
    assert have("EXX:") == ["g15", "g45", "g5", "p1", "p2", "p3", "r1"] and have("EYX:") == ["p2", "p3"]
    assert have("EAA:") == ["g15", "g45", "g5", "h1", "h2", "h3", "h4", "p1", "p2", "p3", "r1"]
    assert have("drift_X:") == ["e15", "e45", "e5", "t1", "t2"]
    assert have("XOC:") == ["e15", "e45", "e5", "t1"] and "XOC" in names
    assert have("ZOW:") == ["e15", "e45", "e5"] and "ZOW" in names      # the ball's stem warming


@pytest.mark.parametrize("name, ok", [("EXX:w0.5", True), ("EXX:w10000", True), ("EXX:w0.4", False),
                                      ("EXX:w10001", False), ("ECC:h99", True), ("ECC:h100", False),
                                      ("drift_X:e999", True), ("EXC+EYC:h-99", True)])
def test_orders_and_pitches_are_taken_within_their_ranges(name, ok):
    if ok:
        assert resolve(SEED, name).name == name
    else:
        with pytest.raises(CompgenError):
            resolve(SEED, name)


def test_a_linear_axis_positioning_error_linear_in_position_is_its_scale():
    assert resolve(SEED, "EXX:p1").words.endswith("(scale: linear in position)")
    assert "scale" not in resolve(SEED, "EXX:p2").words and "scale" not in resolve(SEED, "EYX:p2").words


@pytest.mark.parametrize("name, scale, size", [("EAA:g15", "EAA:p1", np.radians(20 / 3600)),
                                               ("EXX:g5", "EXX:p1", 0.01)])
def test_a_scale_in_time_reads_as_the_scale_grown_to_each_readings_time(name, scale, size):
    """A scale growing in time (EAA:g15: A's angular positioning error linear in A, its slope
    growing as 1 − exp(−t/15 min)) reads at each pose as the plain scale (EAA:p1) of the
    size it has grown to at that pose's time, the chain evaluated pose by pose; and it needs
    every reading's time."""
    poses = generate(SEED, ["K4", "K1"])
    grown = size * -np.expm1(-poses.t / (60.0 * resolve(SEED, name).basis.order))
    got = Model(SEED, [name]).deviation(poses, np.array([size]))
    for i in range(0, len(poses), 17):
        want = Model(SEED, [scale]).deviation(poses.take(np.array([i])), np.array([grown[i]]))[0]
        assert np.abs(got[i] - want).max() < 1e-12, (i, got[i], want)
    assert np.abs(got).max() > 1e-3          # a few µm: seen
    timeless = Poses(poses.q, poses.ball, np.full(len(poses), np.nan), poses.path)
    with pytest.raises(CompgenError, match="needs the time column"):
        Model(SEED, [name]).deviation(timeless, np.array([size]))
