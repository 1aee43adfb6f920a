"""The exact model against truth compgen did not write: the shared vectors (an independent
simulator) and the seed report's Table 2 gain formulas."""

import csv

import numpy as np
import pytest
from conftest import ARCSEC, TABLE4, UM, vector

from compgen.data.rtest import read_rtest
from compgen.model.effects import catalogue
from compgen.model.kinematics import SLOT_INDEX, Model, SlotGains, inverse, relative, slot_gains
from compgen.model.paths import generate
from compgen.model.poses import Poses
from compgen.transforms import rot_exact

ATOL_VECTORS_UM = 1e-4   # contract: shared vectors (issue 2)
ATOL_GAIN = 1e-6         # central differences vs Table 2 formulas, µm per µm (or per rad·1e-3)
ATOL_FD_REL = 1e-7       # analytic gains vs central differences, relative to the largest gain
# mm or rad: central differences; rounding ~1e-8 of ~1000 mm positions, truncation h²·lever/6 ~ 5e-9
FD_STEP = 1e-5


def _rows(name):
    with open(vector(name), newline="") as f:
        return list(csv.DictReader(f))


def _pose(machine, row):
    q = [float(row[k]) for k in ("X", "Y", "Z")] + [np.radians(float(row[a])) for a in ("A", "C")]
    return Poses(np.array([q]), np.array([machine.ball]), np.array([np.nan]),
                 np.array([""], dtype=object))


def test_single_error_vectors(seed_machine):
    rows = _rows("single-errors.csv")
    assert len(rows) == 88
    for row in rows:
        value = float(row["value"]) * (UM if row["unit"] == "um" else ARCSEC)
        got = Model(seed_machine, [row["error"]]).deviation(_pose(seed_machine, row),
                                                           np.array([value]))[0] / UM
        want = np.array([float(row[k]) for k in ("dX", "dY", "dZ")])
        np.testing.assert_allclose(got, want, rtol=0, atol=ATOL_VECTORS_UM, err_msg=row["error"])


@pytest.mark.parametrize("name, scale", [("seed-table4-noiseless.csv", 1),
                                         ("seed-table4x30-noiseless.csv", 30)])
def test_session_vectors(seed_machine, name, scale):
    data = read_rtest(vector(name), seed_machine)
    # The file rounds A and C to 1e-4 deg (8.7e-7 rad), which at 30x the errors moves a
    # reading by up to 1e-3 µm; the machine file's path definitions give the exact poses.
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    assert list(poses.path) == list(data.poses.path)
    np.testing.assert_allclose(poses.q[:, :3], data.poses.q[:, :3], rtol=0, atol=5.01e-5)  # mm
    np.testing.assert_allclose(poses.q[:, 3:], data.poses.q[:, 3:], rtol=0,
                               atol=np.radians(5.01e-5))
    got = Model(seed_machine, TABLE4).deviation(poses, scale * np.array(list(TABLE4.values())))
    # the file's readings have four decimals in µm: 5e-5 µm of rounding
    np.testing.assert_allclose(got / UM, data.deviation / UM, rtol=0, atol=ATOL_VECTORS_UM)


def table2(A, C, Xw, Yw, Zw, Zc):
    """Seed report Table 2, typed from the report: first-order gains, columns dX dY dZ."""
    Ca, Sa, Cc, Sc = np.cos(A), np.sin(A), np.cos(C), np.sin(C)
    z, one = np.zeros_like(A), np.ones_like(A)
    return {
        "XOW": (-Cc, -Ca * Sc, -Sa * Sc),
        "YOW": (Sc, -Ca * Cc, -Sa * Cc),
        "ZOW": (z, Sa, -Ca),
        "YOA": (z, -one, z),
        "ZOA": (z, z, -one),
        "BOA": (-Ca * (Zw + Zc) - Sa * Sc * Xw - Sa * Cc * Yw, z, -Sc * Yw + Cc * Xw),
        "COA": (-Sa * (Zw + Zc) + Ca * Sc * Xw + Ca * Cc * Yw, -Cc * Xw + Sc * Yw, z),
        "XOC": (-one, z, z),
        "YOC": (z, -Ca, -Sa),
        "AOC": (z, Sc * Sa * Xw + Cc * Sa * Yw + Ca * Zw, -Cc * Ca * Yw + Sa * Zw - Sc * Ca * Xw),
        "BOC": (-Zw, -Cc * Sa * Xw + Sc * Sa * Yw, -Sc * Ca * Yw + Cc * Ca * Xw),
    }


def test_first_order_gains_equal_seed_table2(seed_machine):
    data = read_rtest(vector("seed-table4-noiseless.csv"), seed_machine)
    A, C = data.poses.q[:, 3], data.poses.q[:, 4]
    want = table2(A, C, *seed_machine.ball, seed_machine.axis("C").offset[2])
    J = Model(seed_machine, list(want)).jacobian(data.poses)
    for i, name in enumerate(want):
        expected = np.column_stack(np.broadcast_arrays(*want[name], A))[:, :3]
        np.testing.assert_allclose(J[:, :, i], expected, rtol=0,
                                   atol=ATOL_GAIN * (1 if name[0] in "XYZ" else 1e3), err_msg=name)


@pytest.mark.parametrize("machine_name", ["seed_machine", "bc_machine", "head_machine"])
def test_inverse_puts_nest_on_ball(machine_name, request, rng):
    machine = request.getfixturevalue(machine_name)
    rot = np.radians(rng.uniform(-90, 90, (50, len(machine.rotary_axes))))
    ball = rng.uniform(-200, 200, (50, 3))
    q = inverse(machine, rot, ball)
    poses = Poses(q, ball, np.full(50, np.nan), np.full(50, "", dtype=object))
    assert np.abs(Model(machine, ()).relative(poses)).max() < 1e-9   # mm


def test_inverse_matches_vector_pose(seed_machine):
    row = _rows("single-errors.csv")[1]
    q = inverse(seed_machine, np.radians([[float(row["A"]), float(row["C"])]]), seed_machine.ball)
    np.testing.assert_allclose(q[0, :3], [float(row[k]) for k in "XYZ"], atol=5e-5)  # 4 decimals


def test_rot_exact_matches_scipy(rng):
    from scipy.spatial.transform import Rotation

    w = rng.normal(size=(40, 3)) * np.repeat([1, 1e-3, 1e-7, 1e-10, 0], 8)[:, None]
    np.testing.assert_allclose(rot_exact(w)[:, :3, :3], Rotation.from_rotvec(w).as_matrix(),
                               rtol=0, atol=1e-15)


def test_the_axis_a_rotation_turns_about_is_its_left_jacobian_at_every_size(rng):
    """J(w) e is the axis about which R(w) turns as w moves along e: R(w + h e) R(w)ᵀ =
    exp([h J(w) e]×) to first order (central differences of scipy's rotations; large
    rotations take the closed form). Near θ = 1e-3, where the series takes over, both
    agree with J's coefficients in forms free of cancellation, 2 sin²(θ/2)/θ² and the
    series of (θ − sin θ)/θ³ to θ⁴, within 1e-12 (the closed form's cancellation leaves
    ~1e-13 just above the switch; the series' next term at the switch is 1e-11)."""
    from scipy.spatial.transform import Rotation

    from compgen.model.kinematics import _left_jacobian
    e = np.eye(3)[rng.integers(0, 3, 24)] + 0.3 * rng.normal(size=(24, 3))
    for theta in (0.05, 0.3, 1.0, 2.5):
        w = rng.normal(size=(24, 3))
        w *= theta / np.linalg.norm(w, axis=1)[:, None]
        h = 1e-6
        turn = (Rotation.from_rotvec(w + h * e) * Rotation.from_rotvec(w - h * e).inv()).as_rotvec() / (2 * h)
        np.testing.assert_allclose(_left_jacobian(w, e), turn, rtol=0, atol=1e-8)
    for theta in (2e-4, 9.99e-4, 1.001e-3, 3e-3):
        w = rng.normal(size=(24, 3))
        w *= theta / np.linalg.norm(w, axis=1)[:, None]
        b = 2 * np.sin(theta / 2) ** 2 / theta**2
        c = 1 / 6 - theta**2 / 120 + theta**4 / 5040
        we = np.cross(w, e)
        np.testing.assert_allclose(_left_jacobian(w, e), e + b * we + c * np.cross(w, we), rtol=0, atol=1e-12)


@pytest.mark.parametrize("machine_name", ["seed_machine", "bc_machine", "head_machine"])
@pytest.mark.parametrize("loaded", [False, True], ids=["nominal", "loaded"])
def test_analytic_slot_gains_equal_central_differences_of_the_exact_model(machine_name, loaded, request):
    """Every slot of the catalogue (and the ball turned about its centre, which moves no
    reading), on both machines (both chain layouts, linear axes on
    either side, squareness among them), against the exact model moved by ±1e-6: on the
    nominal machine, and on one carrying errors in every slot at once (up to 0.05 mm and
    3 mrad, 100× a real machine's: far enough from zero that gains taken at zero would
    miss by ~1e-3 and fail)."""
    machine = request.getfixturevalue(machine_name)
    poses = generate(machine, list(machine.paths))
    keys = sorted({(e.carrier, e.slot, d) for e in catalogue(machine) for d in e.direction}
                  | {("ball", "loc", d) for d in "abc"})     # a ball's tilt: its centre stays
    rng = np.random.default_rng(3)
    base = {}
    if loaded:
        for carrier, slot, _ in keys:
            base[(carrier, slot)] = np.concatenate([rng.uniform(-0.05, 0.05, 3), rng.uniform(-3e-3, 3e-3, 3)]
                                                   ) * np.ones((len(poses), 1))
    gains, moved = SlotGains(machine, poses, base), []
    for carrier, slot, direction in keys:
        step = np.zeros((len(poses), 6))
        step[:, SLOT_INDEX[direction]] = FD_STEP
        held = base.get((carrier, slot), np.zeros((len(poses), 6)))
        numeric = (relative(machine, poses, {**base, (carrier, slot): held + step})
                   - relative(machine, poses, {**base, (carrier, slot): held - step})) / (2 * FD_STEP)
        scale = max(np.abs(numeric).max(), 1.0)   # mm per mm, or mm per rad (levers ~300 mm)
        # central differences of 1e-5 on ~1000 mm carry ~1e-8 of rounding
        np.testing.assert_allclose(gains((carrier, slot, direction)), numeric, rtol=0,
                                   atol=ATOL_FD_REL * scale, err_msg=f"{carrier} {slot} {direction}")
        nominal = slot_gains(machine, poses, [(carrier, slot, direction)])[(carrier, slot, direction)]
        moved.append(np.abs(nominal - numeric).max() > 100 * ATOL_FD_REL * scale)
    # loaded, the errors matter: most gains taken at zero would miss (a translation at the
    # chain's start does not move with the errors after it)
    assert (np.mean(moved) > 0.5) == loaded, np.mean(moved)


def test_a_parameter_of_exactly_one_is_not_taken_for_zero(seed_machine):
    """The model skips parameters that are exactly zero: one of exactly 1 mm must count.
    A ball 1 mm off along the table's X reads 1 mm in every pose (the table only turns it)."""
    poses = generate(seed_machine, ["K4"])
    dev = Model(seed_machine, ["XOW"]).deviation(poses, np.array([1.0]))
    np.testing.assert_allclose(np.linalg.norm(dev, axis=1), 1.0, rtol=1e-9)


def test_the_side_of_a_reversal_by_hand():
    """±1 by the direction of the move that reached the pose, standing still keeps it; the
    poses before the first move take its direction (a program approaches a path's start
    so); 0 throughout a run that never moves the axis; runs end at a new label."""
    from compgen.model.poses import motion_direction
    q = np.array([0.0, 1, 2, 2, 1, 0, 5, 5, 4, 3, 3, 3, 3, 4])
    run = np.array([0, 0, 0, 0, 0, 0, 1, 1, 1, 2, 2, 3, 3, 3])
    np.testing.assert_allclose(motion_direction(q, run), [1, 1, 1, 1, -1, -1, -1, -1, -1, 0, 0, 1, 1, 1])


def test_a_free_constant_stands_for_the_side_of_a_path_that_holds_the_axis(seed_machine):
    """Without A_side: one constant for K2 (A held), fitted with the model (the readings'
    part along the effect's gain there is removed); none for K4 and K1, which move A; none
    where the data carry the side, none without a reversal in the model."""
    from compgen.model.kinematics import Model
    from compgen.model.paths import generate
    from compgen.model.sides import FreeConstants
    p = generate(seed_machine, ["K4", "K1", "K2"])
    blind = Poses(p.q, p.ball, p.t, p.path)
    starts = FreeConstants(seed_machine, ["XOC", "EAA:r1"], blind)
    assert starts.labels == [("A", "K2")]
    assert [len(i) for (_, i), in starts.blocks] == [int((p.path == "K2").sum())]
    assert FreeConstants(seed_machine, ["XOC", "EAA:r1"], p).count == 0       # sides recorded
    assert FreeConstants(seed_machine, ["XOC", "ECC:h2c"], blind).count == 0    # no reversal
    # a reading that is A standing 3″ off on K2 alone is removed whole; one on K1 is not
    sided = Poses(p.q, p.ball, p.t, p.path, np.ones_like(p.q))
    gain = Model(seed_machine, ["EAA:r1"]).jacobian(sided)[:, :, 0]
    held = (p.path == "K2")[:, None] * gain * 3 * np.pi / 648000
    project = starts.projector()
    np.testing.assert_allclose(project.remove(held), 0.0, atol=1e-15)
    np.testing.assert_allclose(project(held.copy()), 0.0, atol=1e-15)
    one_way = (p.path == "K1")[:, None] * gain * 3 * np.pi / 648000
    np.testing.assert_array_equal(project.remove(one_way), one_way)
    Q = project.basis(len(p))
    np.testing.assert_allclose(Q.T @ Q, np.eye(1), atol=1e-12)


def test_runs_end_at_a_new_file_ball_or_label():
    from compgen.model.poses import runs
    p = Poses.concat([Poses(np.zeros((3, 5)), np.zeros((3, 3)), np.arange(3.0),
                            np.full(3, "K2", dtype=object))] * 2)
    assert runs(p).tolist() == [1, 1, 1, 2, 2, 2]                     # the time starts again
    moved = Poses(p.q, p.ball + np.array([[0, 0, 0]] * 3 + [[0, 0, 1]] * 3), np.arange(6.0), p.path)
    assert runs(moved).tolist() == [1, 1, 1, 2, 2, 2]


def test_the_nominal_reading_at_poses_inverse_solved_is_zero_as_walked(seed_machine, tmp_path):
    """read_poses marks its poses as inverse's solution (``solved``): their nominal reading
    is taken as zero, not walked. Walking it anyway gives zero to rounding, at the seed
    ball and elsewhere, with the table turned every way."""
    from compgen.data.rtest import read_poses
    from compgen.model.kinematics import nominal
    m = seed_machine
    rng = np.random.default_rng(4)
    rows = "\n".join(f"P,{a:.4f},{c:.4f},{bx:.3f},{by:.3f},{bz:.3f}" for a, c, bx, by, bz in zip(
        rng.uniform(-90, 90, 200), rng.uniform(-360, 360, 200), rng.uniform(-100, 100, 200),
        rng.uniform(-100, 100, 200), rng.uniform(30, 200, 200), strict=True))
    (tmp_path / "p.csv").write_text("path,A,C,bx,by,bz\n" + rows + "\n")
    poses = read_poses(tmp_path / "p.csv", m)
    assert not nominal(m, poses).any()                    # taken as zero
    copy = Poses(poses.q, poses.ball, poses.t, poses.path)   # the same poses, not marked
    walked = relative(m, copy, {})
    assert np.abs(walked).max() < 1e-11                   # mm


def test_no_poses_give_no_readings_of_three_directions(seed_machine):
    """The chain of no poses: (0, 3), as a library caller concatenating sessions expects."""
    none = generate(seed_machine, ["K4"]).take(slice(0, 0))
    assert relative(seed_machine, none, {}).shape == (0, 3)
    assert np.concatenate([relative(seed_machine, none, {}),
                           relative(seed_machine, generate(seed_machine, ["K4"]), {})]).shape == (241, 3)


def test_in_halves_threads_only_a_dense_session_and_keeps_the_order():
    import threading

    from compgen.model.kinematics import THREADED, in_halves

    def work(starts):
        return [(a, threading.get_ident()) for a in starts]

    small = in_halves(work, range(0, THREADED - 1, 1024))
    assert {ident for half in small for _, ident in half} == {threading.get_ident()}
    assert [a for half in small for a, _ in half] == list(range(0, THREADED - 1, 1024))
    dense = in_halves(work, range(0, THREADED, 1024))
    # in the pool (a thread may take both halves when the first is done before the second)
    assert len(dense) == 2 and threading.get_ident() not in {ident for half in dense for _, ident in half}
    assert [a for half in dense for a, _ in half] == list(range(0, THREADED, 1024))


def test_each_later_mounting_of_the_ball_has_an_offset_of_its_own_beside_the_start_sides(seed_machine):
    """K2 without A_side at the ball, at another position, and back at the first: three
    mountings (a ball moved back is mounted again too). With the ball's offset in the model,
    each later mounting gets its own three constants beside each run's start side, and the
    projector removes their span exactly: what it leaves is orthogonal to every later
    mounting's offset columns (the gains of XOW YOW ZOW on its rows, from the model here) and
    to the start sides, though a mounting's offset and the runs in it share rows (projected
    one after the other, their blocks would leave a part along the first)."""
    from compgen.model.kinematics import Model
    from compgen.model.paths import generate
    from compgen.model.sides import SETUP, FreeConstants, mountings
    moved = np.add(seed_machine.ball, [20.0, 10.0, -30.0])
    parts = [generate(seed_machine, ["K2"], ball=b) for b in (None, moved, None)]
    p = Poses.concat([Poses(q.q, q.ball, q.t, q.path) for q in parts])
    n = [len(q) for q in parts]
    assert mountings(p.ball).tolist() == [0] * n[0] + [1] * n[1] + [2] * n[2]
    constants = FreeConstants(seed_machine, [*SETUP, "YOC", "EAA:r1"], p)
    assert constants.labels == [("A", "K2")] * 3 and constants.count == 3 + 2 * 3
    assert FreeConstants(seed_machine, ["YOC", "EAA:r1"], p).count == 3      # no ball offset: no mounting's
    v = np.random.default_rng(2).normal(size=(len(p), 3))
    left = constants.projector()(v.copy())
    gains = Model(seed_machine, SETUP).jacobian(p)
    for k in (1, 2):
        cols = (gains * (mountings(p.ball) == k)[:, None, None]).reshape(-1, 3)
        assert np.abs(cols.T @ left.ravel()).max() < 1e-9 * np.linalg.norm(cols) * np.linalg.norm(v)
    sides = FreeConstants(seed_machine, ["EAA:r1"], p).projector()
    np.testing.assert_allclose(sides(left.copy()), left, atol=1e-12)
    np.testing.assert_allclose(constants.projector()(v - left), 0.0, atol=1e-12)   # v − left in the span


def test_a_nest_of_another_length_has_an_offset_of_its_own_and_coinciding_offsets_count_once(seed_machine):
    """K2 at the ball; K2 with the ball moved (its second mounting); K1 there with a longer
    nest (the second nest: the ball stays); K1 back at the ball with the first length (a
    third mounting and a third nest at once). The projector leaves what is orthogonal to
    every later mounting's and nest's offset columns (from the model here), though they
    share rows across stretches, and counts the independent ones: on K1, where only C
    turns, a table-frame Z and a machine-frame Z are one translation, so the last
    stretch's six offsets span five dimensions, the rank the explicit design has. Only a
    model holding the ball's offset brings these constants."""
    from compgen.model.kinematics import Model
    from compgen.model.paths import generate
    from compgen.model.sides import NEST, SETUP, FreeConstants, nest_mountings
    moved = np.add(seed_machine.ball, [20.0, 10.0, -30.0])

    def measure(path, ball=None, nest=np.nan):
        p = generate(seed_machine, [path], ball=ball)
        return Poses(p.q, p.ball, p.t, p.path, p.side, np.full(len(p), nest))

    parts = [measure("K2"), measure("K2", moved), measure("K1", moved, 150.0), measure("K1")]
    p = Poses.concat(parts)
    n = np.cumsum([0, *map(len, parts)])
    held = nest_mountings(seed_machine, p.nest)
    assert held.tolist() == [0] * n[2] + [1] * len(parts[2]) + [2] * len(parts[3])
    constants = FreeConstants(seed_machine, [*SETUP, "YOC"], p)
    assert constants.count == 3 * 2 + 3 * 2 and len(constants.blocks) == 2     # the last stretch apart
    # a set-up's constants come with the set-up's parameters: a reversal candidate alone (its
    # sides recorded here) or a model without the ball's offset brings none
    assert FreeConstants(seed_machine, ["EAA:r1"], p).count == 0
    assert FreeConstants(seed_machine, ["YOC"], p).count == 0
    project = constants.projector()
    ball, nest = Model(seed_machine, SETUP).jacobian(p), Model(seed_machine, NEST).jacobian(p)
    rows = lambda a, b: (np.arange(len(p)) >= n[a]) & (np.arange(len(p)) < n[b])     # noqa: E731
    design = np.concatenate([ball * rows(1, 3)[:, None, None], ball * rows(3, 4)[:, None, None],
                             nest * rows(2, 3)[:, None, None], nest * rows(3, 4)[:, None, None]], axis=2)
    design = design.reshape(-1, design.shape[2])
    assert project.rank == np.linalg.matrix_rank(design) == constants.count - 1
    v = np.random.default_rng(3).normal(size=(len(p), 3))
    left = project(v.copy())
    assert np.abs(design.T @ left.ravel()).max() < 1e-9 * np.linalg.norm(design) * np.linalg.norm(v)
    np.testing.assert_allclose(project(v - left), 0.0, atol=1e-12)          # v − left in their span
