"""Inclined axes: the nutating reference machine, a B head turning the tool
about (0, 1, 1)/√2 through its pivot over a C table. compgen's chain against the geometry
written out by hand from that description, fits at the Cramér-Rao bound, a ball never
measured predicted, a hidden 2/rev of C found, and what each control can hold of it; and an
inclined table (a B/C table with B at 45°), its chain, fit and SINUMERIK record likewise."""


import numpy as np
import pytest
from conftest import (
    ARCSEC,
    NUTATING_MACHINE,
    ROOT,
    UM,
    carr_edit_is,
    fitted_at_the_bound,
    hidden_2_per_rev_is_found,
    run,
)
from scipy.spatial.transform import Rotation

from compgen.configuration.machine_file import load_machine
from compgen.controllers.correction import lines_text, plan
from compgen.data.rtest import commanded, format_rtest
from compgen.data.simulate import simulate
from compgen.model.effects import effect_of_param, location_model
from compgen.model.kinematics import Model, SlotGains
from compgen.model.lines import axis_lines
from compgen.model.paths import generate
from compgen.statistics.identify import identify

GAUGE, PIVOT = 120.0, 150.0         # the file's probe_length and the head's pivot length, mm
S = np.sqrt(0.5)
N = np.array([0.0, S, S])           # B's line, (0, 1, 1)/√2
EX, EZ = np.array([1.0, 0, 0]), np.array([0.0, -S, S])   # B's own x and z, across it
NOISE_UM = 0.5
TRUTH = {"XOW": 3 * UM, "YOW": -5 * UM, "ZOW": 4 * UM, "XOC": 6 * UM, "YOC": -8 * UM, "AOC": 5 * ARCSEC,
         "BOC": -4 * ARCSEC, "XOB": 10 * UM, "ZOB": -7 * UM, "AOB": 6 * ARCSEC, "COB": -8 * ARCSEC}


def _rot(w) -> np.ndarray:
    return Rotation.from_rotvec(w).as_matrix()


def _nutating(q, ball, v):
    """Nest minus ball written from the description: B turns the tool right-handed about N
    through the pivot (150 mm above the gauge line, the nest 120 mm below it), its line moved
    by XOB along B's own x and ZOB along its z and turned by AOB, COB about them; C turns
    the table about +Z, its location errors as the seed places a table's frame."""
    X, Y, Z, C, B = q.T
    pivot = np.column_stack([X, Y, Z + GAUGE + PIVOT])
    t = v["XOB"] * EX + v["ZOB"] * EZ
    r = _rot(v["AOB"] * EX + v["COB"] * EZ)
    M = r @ _rot(np.outer(B, N)) @ r.T
    nest = pivot + t + np.einsum("nij,j->ni", M, np.array([0, 0, -GAUGE - PIVOT]) - t)
    w = ball + [v["XOW"], v["YOW"], v["ZOW"]]
    table = np.einsum("ij,njk,nk->ni", _rot([v["AOC"], v["BOC"], 0]), _rot(np.outer(C, [0, 0, 1])), w)
    return nest - (table + [v["XOC"], v["YOC"], 0])


def _deviation(poses, values):
    return _nutating(poses.q, poses.ball, values) - _nutating(poses.q, poses.ball, dict.fromkeys(TRUTH, 0.0))


@pytest.fixture(scope="module")
def nutating():
    machine = load_machine(NUTATING_MACHINE)
    return machine, generate(machine, list(machine.paths))


def test_the_machine_file_reads_the_inclined_axis_as_described(nutating):
    """B is B's letter y turned 45° about X; B = 0 points the tool along −Z, B = 180° along
    −Y; its location errors are the two offsets and two tilts across its own line."""
    machine, _ = nutating
    b = machine.axis("B")
    assert b.direction == "y" and b.inclined
    np.testing.assert_allclose(b.unit, N, atol=1e-15)
    np.testing.assert_allclose(b.frame, np.column_stack([EX, N, EZ]), atol=1e-15)
    q = np.zeros((2, len(machine.axes)))
    q[1, machine.index("B")] = np.pi
    nest = commanded(machine, q)[:, :3]            # where the nest stands, TCP coordinates
    np.testing.assert_allclose(nest[0], [0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(nest[1], [0, -(GAUGE + PIVOT), GAUGE + PIVOT], atol=1e-9)
    assert location_model(machine) == ("XOW", "YOW", "ZOW", "XOC", "YOC", "AOC", "BOC",
                                       "XOB", "ZOB", "AOB", "COB")
    assert effect_of_param(machine, "XOB").words == "B axis line offset along B's own x (1, 0, 0)"
    assert effect_of_param(machine, "COB").words == "B axis line tilt about B's own z (0, -0.7071, 0.7071)"


def test_the_chain_is_the_nutating_head_as_described(nutating, rng):
    """Every location error alone and all at once (100× a real machine's) against the
    hand-written geometry, to 1e-9 mm; the nominal chain puts the nest on the ball."""
    machine, poses = nutating
    names = list(location_model(machine))
    model = Model(machine, names)
    for trial in [*np.eye(len(names)) * 1e-3, rng.uniform(-3e-3, 3e-3, len(names))]:
        values = dict(zip(names, trial, strict=True))
        np.testing.assert_allclose(model.deviation(poses, trial), _deviation(poses, values),
                                   rtol=0, atol=1e-9)
    assert np.abs(_nutating(poses.q, poses.ball, dict.fromkeys(TRUTH, 0.0))).max() < 1e-9


@pytest.mark.parametrize("loaded", [False, True], ids=["nominal", "loaded"])
def test_the_inclined_axis_gains_equal_central_differences(nutating, loaded):
    """Every slot of B and C, on the nominal machine and on one carrying large errors: the
    analytic gains through B's own frame are the exact model's derivative."""
    machine, poses = nutating
    poses = poses.take(slice(0, 603, 7))
    names = list(location_model(machine)) + ["EXB:h1c", "ECB:h1s", "EYC:h2c"]
    values = np.full(len(names), 2e-3) if loaded else np.zeros(len(names))
    model = Model(machine, names)
    J = model.jacobian(poses, values)
    h = 1e-7
    for i, name in enumerate(names):
        up, down = values.copy(), values.copy()
        up[i] += h
        down[i] -= h
        numeric = (model.deviation(poses, up) - model.deviation(poses, down)) / (2 * h)
        np.testing.assert_allclose(J[:, :, i], numeric, rtol=0, atol=2e-6, err_msg=name)
    assert SlotGains(machine, poses)(("B", "loc", "z")).any()


def test_a_session_is_fitted_at_the_cramer_rao_bound(nutating):
    """Location errors only, white noise of 0.5 µm: each estimate within 5 σ of the truth,
    σ the bound the hand-written geometry gives, and the fit's own σ that bound to 2 %."""
    machine, poses = nutating
    fitted_at_the_bound(machine, TRUTH, poses, _deviation, NOISE_UM, 69)


def test_a_ball_never_measured_is_predicted_to_the_noise(nutating):
    """The fitted machine (its ball offsets left behind: a new mounting) predicts every path
    at a ball 200 mm away on the other side of the table, against the hand-written geometry
    there, within the noise of one reading."""
    machine, poses = nutating
    names = list(location_model(machine))
    fit = identify(machine, [simulate(machine, TRUTH, poses, NOISE_UM, np.random.default_rng(7))], names)
    other = generate(machine, list(machine.paths), ball=(-60.0, 100.0, 120.0))
    machine_only = {n: (0.0 if n.endswith("OW") else v) for n, v in TRUTH.items()}
    fitted = np.array([0.0 if n.endswith("OW") else fit.parameters[n].value for n in names])
    got = Model(machine, names).deviation(other, fitted)
    miss = np.abs(got - _deviation(other, machine_only)).max()
    assert miss < NOISE_UM * UM, miss / UM
    assert np.abs(_deviation(other, machine_only)).max() > 20 * UM      # there is something to predict


def test_a_hidden_2_per_rev_of_c_is_named_found(nutating):
    """C's radial motion at 2/rev hidden (3 and −2 µm): diagnose names it found; added, the fit
    reaches the noise with every location error within 4 σ of the truth."""
    machine, poses = nutating
    hidden_2_per_rev_is_found(machine, TRUTH, poses, NOISE_UM)


def test_sinumerik_holds_the_inclined_line_against_a_hand_computed_record(nutating, tmp_path):
    """A kind M record (axis 1 the head's B, axis 2 the table's C): B's pivot moves by its
    offsets along its own x and z (l2 = t1, l1 = −l2), its vector (0, 1, 1)/√2 turns by its
    tilts about them; C as on the swivel head. The edit writes exactly those, reads back as
    the fitted lines, and its sign check passes check-program."""
    machine, poses = nutating
    truth = {"XOB": 10 * UM, "ZOB": 20 * UM, "AOB": 5 * ARCSEC, "COB": -6 * ARCSEC,
             "XOC": 5 * UM, "YOC": -7 * UM, "BOC": 7 * ARCSEC}
    held = (list(N), [0, 0, -1])
    t1 = 10 * UM * EX + 20 * UM * EZ
    t2 = np.array([5, -7, 0]) * UM
    fine = {"l2": t1, "l1": -t1, "l3": t2, "l4": -t2}
    v1 = _rot((5 * EX - 6 * EZ) * ARCSEC) @ N
    v2 = _rot([0, 7 * ARCSEC, 0]) @ [0, 0, -1]
    fit = identify(machine, [simulate(machine, truth, poses, 0.0, np.random.default_rng(0))],
                   location_model(machine))
    carr_edit_is(machine, fit, held, fine, v1, v2, tmp_path)
    line = axis_lines(machine, truth)["B"]
    np.testing.assert_allclose(line.direction, v1, atol=1e-12)


def test_a_control_with_no_place_for_an_inclined_axis_refuses_in_one_line(nutating, tmp_path):
    """compgen writes no HEIDENHAIN rows nor LinuxCNC module for an inclined axis (how a TNC
    table turns into B's frame is in no source read: UNCONFIRMED U24): one line that says so
    and where to go, nothing written. The fit's words name B's own directions."""
    machine, poses = nutating
    data = tmp_path / "s.csv"
    session = simulate(machine, TRUTH, poses, NOISE_UM, np.random.default_rng(3))
    data.write_text(format_rtest(machine, session))
    fit = tmp_path / "f.json"
    code, out, err = run("fit", "--machine", NUTATING_MACHINE, data, "-o", fit)
    assert code == 0 and "B axis line offset along B's own z (0, -0.7071, 0.7071)" in out, err
    for ctl in ("tnc640", "itnc530", "linuxcnc"):
        code, _, err = run("kinematics", "--from", fit, "--controller", ctl, "-o", tmp_path / "KIN")
        assert code == 2 and "inclined axis" in err and "U24" in err and err.count("\n") == 1, err
        assert sorted(p.name for p in tmp_path.iterdir()) == ["f.json", "s.csv"]


def test_its_programs_run_on_every_control_that_holds_its_kinematics(tmp_path):
    """Every path in one program under TCPM on both HEIDENHAIN controls (the SINUMERIK one is
    the bundled machine's own: test_bundled), passed by check-program with the head's body;
    LinuxCNC has no module for a nutating head (maxkins turns about +Y): refused in one line."""
    for ctl in ("tnc640", "itnc530"):
        out = tmp_path / f"ALL_{ctl}.H"
        code, _, err = run("measure-program", "--machine", NUTATING_MACHINE, "--path", "all",
                           "--controller", ctl, "-o", out)
        assert code == 0, err
        text = out.read_text()
        assert "FUNCTION TCPM" in text
        assert "B is inclined: it turns about (0.000000, 0.707107, 0.707107)" in text
        code, said, err = run("check-program", "--machine", NUTATING_MACHINE, "--controller", ctl, out)
        assert code == 0 and "OK" in said, err
    out = tmp_path / "ALL.ngc"
    code, _, err = run("measure-program", "--machine", NUTATING_MACHINE, "--path", "K2",
                       "--controller", "linuxcnc", "-o", out)
    assert code == 2 and "does not write LinuxCNC" in err and err.count("\n") == 1 and not out.exists(), err


def test_the_edit_says_the_inclined_line_in_its_own_frame(nutating):
    """The header's words name B's offsets and tilts along its own x and z, the fit's
    parameters to rounding, not machine X and Z (which would drop B's Y part)."""
    machine, poses = nutating
    truth = {"XOB": 10 * UM, "ZOB": -7 * UM, "AOB": 4 * ARCSEC, "COB": 8 * ARCSEC}
    fit = identify(machine, [simulate(machine, truth, poses, 0.0, np.random.default_rng(0))],
                   location_model(machine))
    words = next(w for w in lines_text(plan(machine, fit)) if w.startswith("B line"))
    assert words == ("B line at its pivot: offset B's own X +10.00 um, B's own Z -7.00 um; "
                     "tilt about B's own X +4.00 arcsec, about B's own Z +8.00 arcsec"), words


TABLE_TRUTH = {"XOW": 3 * UM, "YOW": -5 * UM, "ZOW": 4 * UM, "XOB": 10 * UM, "ZOB": -5 * UM,
               "AOB": 4 * ARCSEC, "COB": 6 * ARCSEC, "XOC": -6 * UM, "YOC": 7 * UM, "AOC": -5 * ARCSEC,
               "BOC": 3 * ARCSEC}


@pytest.fixture(scope="module")
def inclined_table(tmp_path_factory):
    """The B/C table machine with its B inclined 45° (as on a DMG eVo's table): B turns the
    table about N through the origin, C (45 mm above) about the B-carried +Z; the record
    holds B's vector reversed, as the control holds a table's."""
    path = tmp_path_factory.mktemp("evo") / "evo.toml"
    path.write_text((ROOT / "machines" / "bc-table-sinumerik840d.toml").read_text()
                    .replace('direction = "y"        # right-handed about +Y', "direction = [0.0, 1.0, 1.0]")
                    .replace("B = [0.0, -1.0, 0.0]", f"B = [0.0, {-S:.16f}, {-S:.16f}]"))
    machine = load_machine(path)
    assert machine.axis("B").inclined
    return machine, generate(machine, list(machine.paths))


def _table_deviation(poses, v):
    """Nest minus ball on the inclined table written from its description, less its nominal:
    the ball in C's frame carried by C (its line moved and turned by its errors) 45 mm above
    B's pivot, B's line moved along its own x and z and turned about them, the nest where
    the linear axes put it (table errors move the ball only)."""
    def ball(values):
        B, C = poses.q[:, 3], poses.q[:, 4]
        w = poses.ball + [values["XOW"], values["YOW"], values["ZOW"]]
        c_line = _rot([values["AOC"], values["BOC"], 0])
        in_c = np.einsum("ij,njk,nk->ni", c_line, _rot(np.outer(C, [0, 0, 1])), w)
        in_b = np.array([0, 0, 45.0]) + [values["XOC"], values["YOC"], 0] + in_c
        b_line = _rot(values["AOB"] * EX + values["COB"] * EZ)
        turned = np.einsum("ij,njk,nk->ni", b_line, _rot(np.outer(B, N)), in_b)
        return values["XOB"] * EX + values["ZOB"] * EZ + turned
    return -(ball(v) - ball(dict.fromkeys(v, 0.0)))


def test_an_inclined_table_is_the_table_as_described_and_fitted_at_the_bound(inclined_table):
    """The inclined table's chain against the hand-written one (every error alone and all at
    once, 1e-9 mm), and its fit at the Cramér–Rao bound of that geometry."""
    machine, poses = inclined_table
    assert machine.axis_names[3:] == ("B", "C")
    names = list(location_model(machine))
    assert sorted(names) == sorted(TABLE_TRUTH)
    model = Model(machine, names)
    for trial in [*np.eye(len(names)) * 1e-3, np.linspace(-3e-3, 3e-3, len(names))]:
        want = _table_deviation(poses, dict(zip(names, trial, strict=True)))
        np.testing.assert_allclose(model.deviation(poses, trial), want, rtol=0, atol=1e-9)
    fitted_at_the_bound(machine, TABLE_TRUTH, poses, _table_deviation, NOISE_UM, 5)


def test_sinumerik_holds_an_inclined_table_against_a_hand_computed_record(inclined_table, tmp_path):
    """A kind P record (axis 1 B carrying axis 2 C): l2 = t1 (B's pivot moved along its own x
    and z), l3 = t2 − t1, l4 = −t2 (C's pivot, B's move included: C is carried); B's vector,
    held reversed, turned by COB about B's own z, and C's with it (B's tilt turns what it
    carries: v2 is C's direction with B at zero)."""
    machine, poses = inclined_table
    truth = {"XOB": 10 * UM, "ZOB": -5 * UM, "COB": 6 * ARCSEC}
    fit = identify(machine, [simulate(machine, truth, poses, 0.0, np.random.default_rng(0))],
                   location_model(machine))
    t1 = 10 * UM * EX - 5 * UM * EZ
    # C's line at B = 0: its pivot 45 mm up, moved and turned with B's line; where it crosses
    # the plane through the nominal pivot square to +Z
    turn, pivot = _rot(6 * ARCSEC * EZ), np.array([0, 0, 45.0])
    point, d = t1 + turn @ pivot, turn @ [0, 0, 1]
    t2 = point - (point - pivot)[2] / d[2] * d - pivot
    v1, v2 = -(_rot(6 * ARCSEC * EZ) @ N), -(_rot(6 * ARCSEC * EZ) @ [0, 0, 1])
    fine = {"l2": t1, "l3": t2 - t1, "l4": -t2}
    carr_edit_is(machine, fit, ([0, -S, -S], [0, 0, -1]), fine, v1, v2, tmp_path)


def test_the_tables_turn_is_its_chains_on_every_bundled_machine(inclined_table):
    """``table_turn`` (the table's rotary axes' turns alone) against the whole chain's walk,
    on every bundled machine and on the B/C table with B inclined at 45°."""
    from pathlib import Path

    from compgen.configuration.machine_file import load_machine
    from compgen.model.frames import table_turn
    from compgen.model.kinematics import chain_transform
    from compgen.model.poses import Poses
    machines = [load_machine(f) for f in sorted(Path(__file__).parents[2].glob("machines/*.toml"))]
    for machine in [*machines, inclined_table[0]]:
        q = np.random.default_rng(0).uniform(-3, 3, (50, len(machine.axes)))
        walked = chain_transform(machine, machine.workpiece, Poses.at(q, np.zeros(3)), {}, np.zeros((50, 6)))
        np.testing.assert_allclose(table_turn(machine, q), walked[:, :3, :3], atol=1e-12,
                                   err_msg=machine.name)
