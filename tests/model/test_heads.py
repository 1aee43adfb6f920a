"""Machines whose head turns the tool (issue 40's reference machines): compgen's chain against
the geometry written out by hand from the machine's description, fits at the Cramér-Rao
bound; programs and edits on LinuxCNC's head modules, none on other controls yet."""

import json
import re

import numpy as np
import pytest
from conftest import (
    ARCSEC,
    FORK_MACHINE,
    HEAD_MACHINE,
    ROOT,
    SEED_MACHINE,
    UM,
    carr_edit_is,
    carr_record,
    fitted_at_the_bound,
    hidden_2_per_rev_is_found,
    measured_under,
    on_linuxcnc,
    pasted,
    run,
)
from scipy.spatial.transform import Rotation

from compgen.configuration.machine_file import load_machine
from compgen.controllers import linuxcnc
from compgen.controllers.correction import plan
from compgen.controllers.kinematics import corrected_by, kinematics_edit
from compgen.controllers.registry import controller, read_edits
from compgen.data.rtest import RTestData, commanded, format_rtest, read_rtest
from compgen.data.rtest import read_poses as read_rtest_poses
from compgen.data.simulate import simulate
from compgen.errors import CompgenError
from compgen.model.effects import catalogue, compose, location_model
from compgen.model.kinematics import Model, inverse
from compgen.model.lines import controller_inverse
from compgen.model.paths import generate
from compgen.model.poses import Poses
from compgen.planning.advice import Advisor
from compgen.reports.compare import compare
from compgen.statistics.diagnose import diagnose
from compgen.statistics.diagnose_text import report
from compgen.statistics.identify import beyond_setup, identify
from compgen.statistics.results import load_fit

FORK = FORK_MACHINE
GAUGE, PIVOT = 120.0, 150.0       # the files' probe_length and the head's pivot length, mm
NOISE_UM = 0.5
TRUTH = {"XOW": 3 * UM, "YOW": -5 * UM, "ZOW": 4 * UM, "XOC": 6 * UM, "YOC": -8 * UM, "AOC": 5 * ARCSEC,
         "BOC": -4 * ARCSEC, "XOB": 10 * UM, "ZOB": -7 * UM, "AOB": 6 * ARCSEC, "COB": -8 * ARCSEC}


def _rot(w) -> np.ndarray:
    return Rotation.from_rotvec(w).as_matrix()


def _turn(axis: str, angle: np.ndarray) -> np.ndarray:
    return Rotation.from_rotvec(np.outer(angle, {"y": [0, 1, 0], "z": [0, 0, 1]}[axis])).as_matrix()


def _about_line(t, r, R, p):
    """Point(s) p turned by R (n, 3, 3) about a line through t, tilted by the rotation vector
    r: t + Rot(r) R Rot(r)ᵀ (p − t)."""
    M = _rot(r) @ R @ _rot(r).T
    return t + np.einsum("nij,nj->ni", M, np.broadcast_to(p - t, (len(R), 3)))


def _swivel(q, ball, v, gauge=GAUGE):
    """Nest minus ball of the B swivel head on the C table, written from the machine's
    description: B turns the tool about +Y, about a line through the pivot (150 mm above the
    gauge line, the nest 120 mm below it); C turns the table about +Z, its location errors
    as the seed's chain places a table's frame (contract §3)."""
    X, Y, Z, C, B = q.T
    pivot = np.column_stack([X, Y, Z + gauge + PIVOT])
    nest = pivot + _about_line(np.array([v["XOB"], 0, v["ZOB"]]), [v["AOB"], 0, v["COB"]], _turn("y", B),
                               np.array([0, 0, -gauge - PIVOT]))
    w = ball + [v["XOW"], v["YOW"], v["ZOW"]]
    table = np.einsum("ij,njk,nk->ni", _rot([v["AOC"], v["BOC"], 0]), _turn("z", C), w)
    return nest - (table + [v["XOC"], v["YOC"], 0])


def _fork(q, ball, v, gauge=GAUGE):
    """Nest minus ball of the fork head: C turns the head about +Z through the pivot, B
    (carried by C) about the C-carried +Y through the pivot; the ball stands fixed."""
    X, Y, Z, C, B = q.T
    pivot = np.column_stack([X, Y, Z + gauge + PIVOT])
    tip = _about_line(np.array([v["XOB"], 0, v["ZOB"]]), [v["AOB"], 0, v["COB"]], _turn("y", B),
                      np.array([0, 0, -gauge - PIVOT]))
    M = _rot([v["AOC"], v["BOC"], 0]) @ _turn("z", C) @ _rot([v["AOC"], v["BOC"], 0]).T
    t = np.array([v["XOC"], v["YOC"], 0])
    nest = pivot + t + np.einsum("nij,nj->ni", M, tip - t)
    return nest - (ball + [v["XOW"], v["YOW"], v["ZOW"]])


def _nominal_nest(q, hand, gauge=GAUGE):
    """Where the nest centre stands on the nominal machine: below the pivot, turned by the head."""
    X, Y, Z, C, B = q.T
    head = _turn("y", B) if hand is _swivel else _turn("z", C) @ _turn("y", B)
    return np.column_stack([X, Y, Z + gauge + PIVOT]) + head @ [0, 0, -gauge - PIVOT]


@pytest.fixture(scope="module", params=["swivel", "fork"])
def case(request, head_machine):
    machine = head_machine if request.param == "swivel" else load_machine(FORK)
    hand = _swivel if request.param == "swivel" else _fork
    return machine, hand, generate(machine, list(machine.paths))


def _deviation(hand, poses, values):
    zero = dict.fromkeys(TRUTH, 0.0)
    return hand(poses.q, poses.ball, values) - hand(poses.q, poses.ball, zero)


def test_the_chain_is_the_head_as_described(case, rng):
    """Every location error on its own and all at once (100× a real machine's), against the
    hand-written geometry: to 1e-9 mm. Nominally the nest stands on the ball, and the CSV's
    X, Y, Z are where it stands (what a control is given under TCPM), not the axes'."""
    machine, hand, poses = case
    names = list(location_model(machine))
    assert sorted(names) == sorted(TRUTH)
    model = Model(machine, names)
    for trial in [*np.eye(len(names)) * 1e-3, rng.uniform(-3e-3, 3e-3, len(names))]:
        values = dict(zip(names, trial, strict=True))
        np.testing.assert_allclose(model.deviation(poses, trial), _deviation(hand, poses, values),
                                   rtol=0, atol=1e-9)
    assert np.abs(hand(poses.q, poses.ball, dict.fromkeys(TRUTH, 0.0))).max() < 1e-9
    np.testing.assert_allclose(commanded(machine, poses.q)[:, :3], _nominal_nest(poses.q, hand),
                               rtol=0, atol=1e-9)
    assert np.abs(commanded(machine, poses.q)[:, :3] - poses.q[:, :3]).max() > 100   # the head moves it


def test_the_heads_body_is_kept_from_the_ball_and_stem_as_described(case, rng):
    """The motion check's head body is a sphere of head_radius about the pivot (270 mm above
    the nest on the tool axis, the files' description): its clearance to the ball and to the
    ball's stem (a vertical segment from the table top to the ball) and to the table (a disc),
    written here in the table's frame (the swivel's C turns the table, the fork's ball stands
    still), equals compgen's to 1e-9 mm at poses across the travel."""
    from compgen.motion.check import clearances
    machine, hand, poses = case
    s = machine.setup
    q = poses.q[rng.choice(len(poses), 40, replace=False)].copy()
    q[:, :3] += rng.uniform([-150, -150, 0], 150, (40, 3))   # the head anywhere above, not only over the ball
    got, _ = clearances(machine, q)
    X, Y, Z, C, _B = q.T
    pivot = np.column_stack([X, Y, Z + GAUGE + PIVOT])
    if hand is _swivel:                                     # into the C frame the ball is given in
        pivot = np.einsum("nji,nj->ni", _turn("z", C), pivot)
    ball = np.array(machine.ball)
    rb = s.ball_diameter / 2
    head = machine.heads[0].name
    np.testing.assert_allclose(got[f"head {head} / ball"],
                               np.linalg.norm(pivot - ball, axis=1) - rb - s.head_radius, rtol=0, atol=1e-9)
    z = np.clip(pivot[:, 2], s.table_top, ball[2] - rb)    # the stem's nearest point
    stem = np.linalg.norm(pivot - np.column_stack([np.full(40, ball[0]), np.full(40, ball[1]), z]), axis=1)
    np.testing.assert_allclose(got[f"head {head} / stem"], stem - s.stem_diameter / 2 - s.head_radius,
                               rtol=0, atol=1e-9)
    assert (pivot[:, 2] > s.table_top).all()                # above the table: to its top face or rim
    rim = np.maximum(np.hypot(pivot[:, 0], pivot[:, 1]) - s.table_radius, 0)
    table = np.hypot(pivot[:, 2] - s.table_top, rim)
    np.testing.assert_allclose(got[f"head {head} / table"], table - s.head_radius, rtol=0, atol=1e-9)


def test_a_session_is_fitted_at_the_cramer_rao_bound(case):
    """Location errors only, white noise of 0.5 µm: each estimate within 5 σ of the truth,
    where σ is the bound the hand-written geometry gives (its Jacobian by central
    differences), and the fit's own σ that bound to 2 % (its σ̂ for the noise)."""
    machine, hand, poses = case
    fitted_at_the_bound(machine, TRUTH, poses, lambda p, v: _deviation(hand, p, v), NOISE_UM, 40)


@pytest.mark.parametrize("source", [HEAD_MACHINE, FORK_MACHINE], ids=["swivel", "fork"])
def test_a_heads_programs_run_under_tcp_from_the_first_turn_to_the_last(tmp_path, source):
    """On HEIDENHAIN (iTNC 530, TNC 640) and SINUMERIK a head's program lifts the nest and
    turns the rotary axes to zero at the safe height with TCP off, switches TCP on once, and
    off after the last turn (off it, a tilted head's tool length is not along the axis a move
    names); its header names U22. Every path of the machine file, written in one program,
    passes check-program with the head's body."""
    sinumerik = _on_sinumerik(tmp_path, source, "{ B = [0.0, 1.0, 0.0], C = [0.0, 0.0, %s1.0] }"
                              % ("" if source == FORK_MACHINE else "-")).source
    for machine, ctl, name, on, off in [(source, "itnc530", "H1.H", "FUNCTION TCPM F", "FUNCTION RESET TCPM"),
                                        (source, "tnc640", "H2.H", "FUNCTION TCPM F", "FUNCTION RESET TCPM"),
                                        (sinumerik, "sinumerik840d", "S.MPF", "TRAORI", "TRAFOOF")]:
        code, out, err = run("measure-program", "--machine", machine, "--path", "all", "--controller", ctl,
                             "-o", tmp_path / name)
        assert code == 0 and "tcpm mode" in err, err
        text = (tmp_path / name).read_text()
        blocks = [ln.split(" ", 1)[1] if ctl != "sinumerik840d" else ln for ln in text.splitlines()[1:]]
        ons = [i for i, b in enumerate(blocks) if b.startswith(on)]
        offs = [i for i, b in enumerate(blocks) if b.startswith(off)]
        zero = next(i for i, b in enumerate(blocks) if "rotary axes to zero at the safe height" in b)
        poses = [i for i, b in enumerate(blocks) if " ; pose " in b]
        assert len(ons) == 1 and zero < ons[0] < poses[0] and poses[-1] < offs[-1] and offs[-2] < zero, \
            (ctl, ons, offs, zero)
        assert "UNCONFIRMED U22" in text, ctl
        code, out, err = run("check-program", "--machine", machine, tmp_path / name)
        assert code == 0 and "OK" in out, (ctl, err)


def test_a_head_is_probed_only_where_the_program_switches_tcp(tmp_path):
    """A head is probed under TCP (tests/controllers/test_head_probing.py): a control whose TCP
    is its configuration (LinuxCNC) gets no probing program for it, refused in one line before
    any file."""
    code, _, err = run("probe-program", "--machine", HEAD_MACHINE, "--path", "K2", "--controller", "linuxcnc",
                       "-o", tmp_path / "p.ngc")
    assert code == 2 and "a head is probed under TCP" in err and len(err.strip().splitlines()) == 1, err
    assert list(tmp_path.iterdir()) == []


def test_a_linear_axis_carried_by_a_head_is_refused(tmp_path):
    """The fork head with its Z carried by the head (after C and B in [[tool]])."""
    z = ('[[tool]]\naxis = "Z"\ntype = "linear"\ndirection = "z"\ntravel = [-300.0, 1000.0]\n'
         'feed_max = 30000.0\n\n')
    text = FORK.read_text()
    assert z in text
    path = tmp_path / "m.toml"
    path.write_text(text.replace(z, "").replace("\n[rtest]", "\n" + z + "[rtest]", 1))   # the section
    with pytest.raises(CompgenError, match="a linear axis follows the head C"):
        load_machine(path)


def test_a_heads_catalogue_names_its_sag(head_machine, seed_machine):
    words = {e.name: e.cause for e in catalogue(head_machine)}
    assert "the head's sag under its weight" in words["EZB+EXB:h2"]
    assert "sag" in words["EBB:h1"] and "trunnion" not in words["EXB:h1"]
    seed = {e.name: e.cause for e in catalogue(seed_machine)}
    assert "trunnion" in seed["EYA:h1"] and "head" not in seed["EBA:h1"] + seed["EYA:h1"]
    assert seed["EXC:h2"] == "bearing runout, eccentric table"
    fork = {e.name: e.cause for e in catalogue(load_machine(FORK))}      # its C turns, never tilts
    assert fork["EXC:h2"] == "bearing runout, eccentric head" and "sag" not in fork["ECC:h1"]
    assert "sag" in fork["EZB+EXB:h2"]


def test_a_heads_sag_is_not_told_from_its_angle_at_one_nest_length(head_machine):
    """The head's weight bends the tool across its axis (sin 2B across, 1 − cos 2B along it):
    at one nest length exactly what an angular error of B at 1/rev does through the nest's
    lever. diagnose names neither found, says which two it cannot tell apart, and advises
    what tells them apart on the TNC 640: K4 with a longer nest. Where compgen writes no
    program (LinuxCNC, the head fitting no module) no measurement is advised, and none is
    said not to help."""
    poses = generate(head_machine, list(head_machine.paths))
    sag = {**TRUTH, "EXB:h2s": 5 * UM, "EZB:h2c": 5 * UM}
    data = [simulate(head_machine, sag, poses, NOISE_UM, np.random.default_rng(3))]
    found = diagnose(head_machine, data, identify(head_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert found.found is None
    assert {"EBB:h1", "EZB+EXB:h2"} <= {found.significant[0].effect, *(found.rivals or ())}, (
        [c.effect for c in found.significant[:3]], found.rivals)
    assert found.rivals_separated_by and found.rivals_separated_by[0].nest is not None
    assert "measure: K4 with the nest 100 mm longer" in report(found).splitlines()[0]


def test_no_measurement_is_advised_where_no_program_is_written(head_machine, tmp_path):
    path = on_linuxcnc(tmp_path)
    path.write_text(path.read_text().replace("offset = [0.0, 0.0, 150.0]", "offset = [5.0, 0.0, 150.0]"))
    machine = load_machine(path)
    poses = generate(machine, list(machine.paths))
    sag = {**TRUTH, "EXB:h2s": 5 * UM, "EZB:h2c": 5 * UM}
    data = [simulate(machine, sag, poses, NOISE_UM, np.random.default_rng(3))]
    found = diagnose(machine, data, identify(machine, data), noise_um=NOISE_UM, advisor=Advisor)
    text = report(found)
    assert "does not write measuring programs for a head yet" in text and "was not searched" in text
    assert "No path or ball position" not in text and not found.rivals_separated_by


def test_what_an_edit_would_leave_says_no_edit_is_written_for_a_head(head_machine, tmp_path):
    """compare and the report predict what correcting the location errors would leave; for a
    head on a control compgen writes no edit for (LinuxCNC, the head fitting no module: its
    B pivot 5 mm off the tool axis) they say so (the user enters the values by hand)."""
    path = on_linuxcnc(tmp_path)
    path.write_text(path.read_text().replace("offset = [0.0, 0.0, 150.0]", "offset = [5.0, 0.0, 150.0]"))
    machine = load_machine(path)
    data = tmp_path / "d.csv"
    data.write_text(format_rtest(machine, simulate(machine, TRUTH, generate(machine, ["K2"]), NOISE_UM,
                                                   np.random.default_rng(1))))
    fit = tmp_path / "fit.json"
    code, _, err = run("fit", "--machine", path, "--model", "XOW,YOW,ZOW,XOC,YOC", data, "-o", fit)
    assert code == 0, err
    code, out, err = run("compare", "--from", fit, "--controller", "tnc640")
    assert code == 0 and "no edit is written" not in out, err          # HEIDENHAIN: pairs around B
    code, _, err = run("kinematics", "--from", fit, "-o", tmp_path / "k.hal")
    assert code == 2 and "does not write kinematics edits for a head yet" in err and "Traceback" not in err
    assert not (tmp_path / "k.hal").exists() and len(err.strip().splitlines()) <= 2, err
    code, out, err = run("compare", "--from", fit)
    assert code == 0 and "assumes: no edit is written for a head yet" in out, err
    code, _, err = run("report", "--from", fit, "-o", tmp_path / "r.html")
    assert code == 0, err
    assert "Assumes: no edit is written for a head yet" in (tmp_path / "r.html").read_text()


def test_the_checklist_prints_no_command_a_head_would_refuse(head_machine, tmp_path):
    """On the TNC 640 the program step names measure-program and the edit step the command as
    the TNC 640 takes it (no --current: its kinematics are in the configuration editor). On
    LinuxCNC, where the head fits no module, both steps are by hand, and say why."""
    code, out, err = run("checklist", "--machine", "bc-swivel-head-table", "--dir", tmp_path, "--json")
    assert code == 0, err
    assert "measure-program" in out and "kinematics --from" in out and "--current" not in out
    assert out.count("does not write") == 0 and "diagnose --from" in out
    path = on_linuxcnc(tmp_path)
    path.write_text(path.read_text().replace("offset = [0.0, 0.0, 150.0]", "offset = [5.0, 0.0, 150.0]"))
    code, out, err = run("checklist", "--machine", path, "--dir", tmp_path, "--json")
    assert code == 0, err
    assert "measure-program" not in out and "kinematics --" not in out and "edit's header" not in out
    assert out.count("does not write") == 2


def test_a_hidden_2_per_rev_of_c_is_named_found_on_both_heads(case):
    """C's radial motion at 2/rev, hidden (3 and −2 µm): diagnose names it found; added, the
    fit reaches the noise with every location error within 4 σ of the truth."""
    machine, _, _ = case
    hidden_2_per_rev_is_found(machine, TRUTH, generate(machine, list(machine.paths)), NOISE_UM)


LONGER = GAUGE + 100.0       # the second nest's distance below the gauge line, mm


def _at_nest(machine, poses, length):
    """``poses`` with the nest ``length`` mm below the gauge line: the same angles and ball,
    the axes where the longer lever puts the nest on the ball."""
    rotary = poses.q[:, [machine.index(a.name) for a in machine.rotary_axes]]
    nest = np.full(len(poses), length)
    return Poses(inverse(machine, rotary, poses.ball, nest=nest), poses.ball, poses.t, poses.path,
                 poses.side, nest)


def _sag(machine, q, k):
    """The head bent by its weight, written from the physics: the tool's weight across its
    axis is its weight times sin B, so the nest moves k·sin B across the tool (in the plane
    B turns it in), whatever the nest's length (a bend in front of the pivot)."""
    B = q[:, machine.index("B")]
    C = q[:, machine.index("C")] if machine.axis("C").side == "tool" else np.zeros(len(q))
    across = np.column_stack([np.cos(C) * np.cos(B), np.sin(C) * np.cos(B), -np.sin(B)])
    return k * np.sin(B)[:, None] * across


def test_the_chain_follows_a_longer_nest_as_described(case, rng):
    """Poses at two nest lengths in one set (half at the file's 120 mm, half 100 mm longer):
    compgen's deviation and its X, Y, Z for each equal the hand-written head with that
    nest to 1e-9 mm; the nominal machine still puts the nest on the ball."""
    machine, hand, poses = case
    half = len(poses) // 2
    longer = _at_nest(machine, poses, LONGER)
    mixed = Poses.concat([poses.take(slice(0, half)), longer.take(slice(half, None))])
    names = list(location_model(machine))
    values = rng.uniform(-3e-3, 3e-3, len(names))
    v = dict(zip(names, values, strict=True))
    zero = dict.fromkeys(TRUTH, 0.0)
    ours = Model(machine, names).deviation(mixed, values)
    for part, gauge in ((slice(0, half), GAUGE), (slice(half, None), LONGER)):
        q, ball = mixed.q[part], mixed.ball[part]
        np.testing.assert_allclose(ours[part], hand(q, ball, v, gauge) - hand(q, ball, zero, gauge),
                                   rtol=0, atol=1e-9)
        assert np.abs(hand(q, ball, zero, gauge)).max() < 1e-9
        np.testing.assert_allclose(commanded(machine, q, mixed.nest[part])[:, :3],
                                   _nominal_nest(q, hand, gauge), rtol=0, atol=1e-9)
    assert np.abs(longer.q - poses.q).max() > 50      # the head's axes follow the lever


def test_a_heads_sag_is_named_found_with_a_second_nest_length(case):
    """A head bent by its weight (5 µm across the tool at 90°, written from the physics
    above, not from compgen's catalogue) with every location error: at one nest length it
    is not told from an angle of B at the pivot (the test above); with K1, K2, K4 at the
    file's nest and K4 with the nest 100 mm longer, diagnose names the 2/rev radial motion
    of B found, in the sag's words; added, the fit reaches the noise with every location
    error within 4 σ of the truth. An angle at the pivot instead (the same 5 µm at the
    first nest) is named as B's angular error, not as the sag's translation."""
    machine, hand, poses = case
    zero = dict.fromkeys(TRUTH, 0.0)
    rng = np.random.default_rng(5)

    def session(p, gauge, k, angle):
        dev = (hand(p.q, p.ball, TRUTH, gauge) - hand(p.q, p.ball, zero, gauge) + _sag(machine, p.q, k)
               + _sag(machine, p.q, angle * (PIVOT + gauge)))     # a small angle: its lever times it
        return RTestData(p, dev + rng.normal(0, NOISE_UM * UM, dev.shape))

    k4 = poses.take(poses.path == "K4")
    for k, angle, named in ((5 * UM, 0.0, "EZB+EXB:h2"), (0.0, 5 * UM / (PIVOT + GAUGE), "EBB:h1")):
        data = [session(poses, GAUGE, k, angle), session(_at_nest(machine, k4, LONGER), LONGER, k, angle)]
        found = diagnose(machine, data, identify(machine, data), noise_um=NOISE_UM, advisor=Advisor)
        assert found.found == named, ([c.effect for c in found.significant[:3]], found.rivals)
        assert "sag" in found.significant[0].cause
        fit = identify(machine, data, compose(machine, location_model(machine), [named]))
        assert fit.residual["sigma_um"] == pytest.approx(NOISE_UM, rel=0.1)
        off = {n: abs(fit.parameters[n].value - v) / fit.parameters[n].std for n, v in TRUTH.items()}
        assert max(off.values()) < 4, (named, off)


def test_a_user_told_to_measure_with_a_longer_nest_can_and_the_sag_is_found(tmp_path):
    """The loop as a user runs it on LinuxCNC's maxkins: one nest length, diagnose says the
    sag and B's angle are not told apart and advises K4 with the nest 100 mm longer; the
    printed command, pasted into bash, writes a program whose guard asks the pivot-length
    pin for the longer nest (370 mm) and whose pose list carries probe_length; compgen's own
    check passes it, with the nest named; the R-test's readings of it (the hand-written
    machine at the pose list's poses) fitted with the first data: the sag is named found."""
    path = on_linuxcnc(tmp_path)
    machine = load_machine(path)
    zero, rng = dict.fromkeys(TRUTH, 0.0), np.random.default_rng(8)

    def readings(p, gauge):
        dev = (_swivel(p.q, p.ball, TRUTH, gauge) - _swivel(p.q, p.ball, zero, gauge)
               + _sag(machine, p.q, 5 * UM))
        return RTestData(p, dev + rng.normal(0, NOISE_UM * UM, dev.shape))

    (tmp_path / "s1.csv").write_text(format_rtest(machine, readings(generate(machine, list(machine.paths)),
                                                                     GAUGE)))
    assert run("fit", "--machine", path, tmp_path / "s1.csv", "-o", tmp_path / "fit.json")[0] == 0
    code, out, err = run("diagnose", "--from", tmp_path / "fit.json", "--noise-um", NOISE_UM)
    assert code == 0 and "Not told apart" in out, err
    command = next(ln.strip() for ln in out.splitlines() if "--probe-length 220 " in ln)
    assert "K4 with the nest 100 mm longer" in out and "measure-program" in command, out
    done = pasted(command, tmp_path, timeout=120)
    assert done.returncode == 0, (command, done.stderr)
    program = (tmp_path / "K4_NEST100.ngc").read_text()
    assert "pivot-length]> - 370.0000] GT" in program and "220.0000 mm below the gauge line" in program
    code, out, err = run("check-program", "--machine", path, "--mode", "tcpm", tmp_path / "K4_NEST100.ngc")
    assert code == 0 and "nest 220 mm below the gauge line (from the program's header)" in out, err
    listed = read_rtest_poses(tmp_path / "K4_NEST100.poses.csv", machine)
    assert (listed.nest == LONGER).all()
    (tmp_path / "K4_NEST100.csv").write_text(format_rtest(machine, readings(listed, LONGER)))
    code, _, err = run("fit", "--from", tmp_path / "fit.json", "--data", tmp_path / "K4_NEST100.csv",
                       "-o", tmp_path / "fit+1.json")
    assert code == 0, err
    code, out, err = run("diagnose", "--from", tmp_path / "fit+1.json", "--noise-um", NOISE_UM, "--json")
    assert code == 0, err
    said = json.loads(out)
    assert said["found"] == "EZB+EXB:h2", (said["found"], said.get("rivals"))


@pytest.mark.parametrize("source, module", [(None, "maxkins"), (FORK_MACHINE, "5axiskins")])
def test_linuxcnc_head_programs_are_written_and_checked_with_the_heads_body(tmp_path, source, module):
    """On LinuxCNC's maxkins (the swivel head) and 5axiskins (the fork) compgen writes K4
    (the tests with the real modules are in test_linuxcnc.py): the nest goes onto and off
    the ball along its tilted axis, the head's turns keep it where it is, and the program
    stops unless the module's pivot-length pin holds the pivot to the nest. check-program
    passes what was written; it refuses a G43 length (it would act along world Z), a guard
    for another pin value and a program without the guard. K1 taken to 90° (the machine
    file's stops at 75°) with the ball 80 mm above the table: the head's body would enter
    the table, and the program is refused, naming it; without the body's size no program is
    written."""
    path = on_linuxcnc(tmp_path, source)
    machine_head = load_machine(path).heads[0].name        # its body is about the first head's pivot
    code, out, err = run("measure-program", "--machine", path, "--path", "K4", "-o", tmp_path / "K4.ngc")
    assert code == 0, err
    program = (tmp_path / "K4.ngc").read_text()
    guard = f"o101 if [ABS[#<_hal[{module}.pivot-length]> - 270.0000] GT 0.1000]"
    assert f"; mode TCPM: {module} kinematics, " in program and "trt" not in program
    assert "\nG49 ;" in program and "\nM66 E0 L0 ;" in program and f"\n{guard}\n(abort," in program
    assert program.index("\nG49") < program.index("M66 E0 L0") < program.index(guard) < program.index("\nG0 ")
    code, out, err = run("check-program", "--machine", path, "--mode", "tcpm", tmp_path / "K4.ngc")
    assert code == 0 and "OK" in out, err
    for bad, says in [(program.replace("\nG49 ", "\nG43 H7 "),
                       f"under {module} a G43 length acts along world Z"),
                      (program.replace("- 270.0000]", "- 250.0000]"), "must stop unless"),
                      (program.replace("GT 0.1000]", "GT 5.0000]"), "must stop unless"),
                      (re.sub(r"o101 if.*\n.*\no101 endif\n", "", program), "no pin guard")]:
        (tmp_path / "bad.ngc").write_text(bad)
        code, _, err = run("check-program", "--machine", path, "--mode", "tcpm", tmp_path / "bad.ngc")
        assert code == 2 and says in err, err
    code, _, err = run("measure-program", "--machine", path, "--path", "K1", "-o", tmp_path / "K1.ngc")
    assert code == 0, err
    path.write_text(path.read_text().replace("from = -75.0, to = 75.0", "from = -90.0, to = 90.0"))
    code, _, err = run("measure-program", "--machine", path, "--path", "K1", "-o", tmp_path / "K1b.ngc")
    assert code == 2 and f"head {machine_head} enters the table" in err, err
    path.write_text(path.read_text().replace("head_radius = 120.0", ""))
    code, _, err = run("measure-program", "--machine", path, "--path", "K4", "-o", tmp_path / "K4b.ngc")
    assert code == 2 and "head_radius" in err and not (tmp_path / "K4b.ngc").exists(), err


@pytest.mark.parametrize("source, module", [(None, "maxkins"), (FORK_MACHINE, "5axiskins")])
def test_linuxcnc_edits_a_head_modules_pin_and_compare_predicts_what_it_leaves(tmp_path, source, module):
    """On LinuxCNC's head modules the edit sets the one pin, pivot-length, by the B line's
    offset along the tool (ZOB; the run with the real modules is in test_linuxcnc.py), and
    names every other location error as not expressible; compare predicts the K4 misfit the
    B line's X offset leaves, as the true machine driven by the edited control would read it
    (written out here from the truth, apart from compare's plan); the edit's sign check
    turns B to ±45° (at 90° the head's body would enter the table)."""
    path = on_linuxcnc(tmp_path, source)
    machine = load_machine(path)
    truth = {"XOW": 4 * UM, "YOW": -6 * UM, "ZOW": 9 * UM, "ZOB": 30 * UM, "XOB": 12 * UM}
    poses = generate(machine, ["K4", "K2"])
    data = tmp_path / "d.csv"
    session = simulate(machine, truth, poses, NOISE_UM, np.random.default_rng(5))
    data.write_text(format_rtest(machine, session))
    fit = tmp_path / "fit.json"
    code, _, err = run("fit", "--machine", path, data, "-o", fit)
    assert code == 0, err
    code, out, err = run("kinematics", "--from", fit, "-o", tmp_path / "KIN.hal")
    assert code == 0, err
    hal = (tmp_path / "KIN.hal").read_text()
    pin = float(re.search(rf"(?m)^setp {module}\.pivot-length (\S+)   # was 270\.000000$", hal)[1])
    assert pin - 270 == pytest.approx(truth["ZOB"], abs=0.5 * UM)
    rest = hal.split("NOT EXPRESSIBLE")[1]
    assert re.search(r"B offset \+1[12]\.\d\d um along X", rest) and "along Z" not in rest
    assert "S5_B-45:" in hal and "S6_B+45:" in hal
    # compare predicts the K4 misfit XOB leaves (B turns in K4; at K2's fixed B it is a
    # constant): as the truth's machine reads it, driven where the edited control drives it
    # (the pin's ZOB held, nothing else), and the fit's noise
    k4 = poses.take(np.flatnonzero(poses.path == "K4"))
    fitted = load_fit(fit)
    assert set(corrected_by(machine, fitted, controller("linuxcnc"))) == {"ZOB"}     # what history records
    got = compare(machine, [read_rtest(data, machine)], fitted, "linuxcnc")
    assert not any("no edit is written" in a for a in got.assumes), got.assumes
    q = controller_inverse(machine, linuxcnc.head_lines(machine, pin - 270), k4.q[:, [
        machine.index(a.name) for a in machine.rotary_axes]], k4.ball)
    true = Model(machine, list(truth))
    after = true.relative(Poses(q, k4.ball, k4.t, k4.path), np.array(list(truth.values())))
    expect = float(np.sqrt(np.mean(np.square(beyond_setup(machine, k4, after)["per_path"]["K4"]["rms_um"]))))
    predicted = float(np.sqrt(np.mean(np.square(got.predicted_post["per_path"]["K4"]["rms_um"]))))
    assert expect > 4 * NOISE_UM
    assert predicted == pytest.approx(np.hypot(expect, NOISE_UM), rel=0.1), (predicted, expect)


def _on_sinumerik(folder, source, vectors: str):
    """A reference head on SINUMERIK with its $TC_CARR record (fine offsets on)."""
    path = folder / f"sinumerik-{source.stem}.toml"
    path.write_text(source.read_text().replace('controller = "tnc640"', 'controller = "sinumerik840d"')
                    .replace("[limits]", "[sinumerik]\ntcarr = 1\nfine_correction = true\nmodulo = [\"C\"]\n"
                                         f"vectors = {vectors}\n\n[limits]"))
    return load_machine(path)


@pytest.mark.parametrize("case", ["fork", "swivel"])
def test_sinumerik_edits_of_a_head_against_hand_computed_records(tmp_path, case):
    """The fork is a kind T record (rotary axis 1 = C, carrying axis 2 = B), the swivel head
    over its C table a kind M (axis 1 the head's B, axis 2 the table's C). Their fine offsets
    are computed here by hand from the Commissioning Manual's definitions (03/2013 p.502):
    T: l3 tool adapter -> pivot 2, l2 pivot 2 -> pivot 1, l1 = -(l2 + l3); M: l2 tool adapter
    -> pivot 1, l1 = -l2, l3 machine reference point -> pivot 2, l4 = -l3. A location error
    moves its axis's pivot by its offsets and turns its vector by its tilt (the table's C
    vector held reversed). The edit writes exactly those, reads back as the fitted lines,
    and writes its sign check as a program under TRAORI, which check-program passes."""
    sec = 1 / 3600
    if case == "fork":
        machine = _on_sinumerik(tmp_path, FORK_MACHINE, "{ C = [0.0, 0.0, 1.0], B = [0.0, 1.0, 0.0] }")
        truth = {"XOC": 5 * UM, "YOC": -7 * UM, "AOC": 8 * ARCSEC, "XOB": 10 * UM, "ZOB": 20 * UM,
                 "COB": 6 * ARCSEC}
        held = ([0, 0, 1], [0, 1, 0])
        t1, t2 = np.array([5, -7, 0]) * UM, np.array([10, 0, 20]) * UM          # pivot 1 (C), 2 (B)
        fine = {"l3": t2, "l2": t1 - t2, "l1": -t1}
        v1 = [0, -np.sin(np.radians(8 * sec)), np.cos(np.radians(8 * sec))]       # C turned 8" about X
        v2 = [-np.sin(np.radians(6 * sec)), np.cos(np.radians(6 * sec)), 0]       # B turned 6" about Z
    else:
        machine = _on_sinumerik(tmp_path, HEAD_MACHINE,
                                "{ B = [0.0, 1.0, 0.0], C = [0.0, 0.0, -1.0] }")
        truth = {"XOB": 10 * UM, "ZOB": 20 * UM, "AOB": 5 * ARCSEC, "XOC": 5 * UM, "YOC": -7 * UM,
                 "BOC": 7 * ARCSEC}
        held = ([0, 1, 0], [0, 0, -1])
        t1, t2 = np.array([10, 0, 20]) * UM, np.array([5, -7, 0]) * UM          # pivot 1 (B), 2 (C)
        fine = {"l2": t1, "l1": -t1, "l3": t2, "l4": -t2}
        v1 = [0, np.cos(np.radians(5 * sec)), np.sin(np.radians(5 * sec))]        # B turned 5" about X
        v2 = [-np.sin(np.radians(7 * sec)), 0, -np.cos(np.radians(7 * sec))]      # C 7" about Y, reversed
    assert machine.sinumerik["kind"] == ("T" if case == "fork" else "M")
    data = [simulate(machine, truth, generate(machine, ["K4", "K2"]), 0.0, np.random.default_rng(0))]
    fit = identify(machine, data, location_model(machine))
    edit, sign = carr_edit_is(machine, fit, held, fine, v1, v2, tmp_path)
    assert f"kind {machine.sinumerik['kind']}" in edit and "TRAORI" in sign


SWIVEL_TAB = (ROOT / "examples" / "swivel-head-itnc530.TAB").read_text()   # the OEM's rows


@pytest.mark.parametrize("case", ["swivel-itnc530", "fork-tnc640"])
def test_heidenhain_edits_of_a_head_against_hand_computed_rows(tmp_path, case):
    """A head's location errors go into HEIDENHAIN's chain as a table's do (Technical Manual
    p.684): error rows before its MachAxis, their inverse after it, the DOC naming each by its
    ISO symbol (U18: the manual's example reads the tool side's Trans rows as the table
    side's). The rows are written out here by hand from the fitted truth: the swivel head's
    description table (iTNC 530) and the fork's change list (TNC 640). A table whose rows put
    the B head 1 mm from where the machine file does is refused. The sign check is a program
    under FUNCTION TCPM, which check-program passes."""
    sec = 1 / 3600
    if case == "swivel-itnc530":
        machine = load_machine(HEAD_MACHINE)
        ctl, current = "itnc530", SWIVEL_TAB
    else:
        machine = load_machine(FORK_MACHINE)
        ctl, current = "tnc640", None
    truth = {"XOB": 10 * UM, "ZOB": 20 * UM, "AOB": 5 * ARCSEC, "XOC": 5 * UM, "YOC": -7 * UM,
             "BOC": 7 * ARCSEC}
    by_hand = {"B": [("X0B", "X", 0.010), ("Z0B", "Z", 0.020), ("A0B", "A", 5 * sec), ("C0B", "C", 0.0)],
               "C": [("X0C", "X", 0.005), ("Y0C", "Y", -0.007), ("A0C", "A", 0.0), ("B0C", "B", 7 * sec)]}
    data = [simulate(machine, truth, generate(machine, ["K4", "K2"]), 0.0, np.random.default_rng(0))]
    fit = identify(machine, data, location_model(machine))
    out = kinematics_edit(machine, fit, ctl, current, "current.TAB", "KIN", "0", "d")
    assert "FUNCTION TCPM F" in out.files["_SIGN.H"] and not any("by hand" in n for n in out.notes)
    (tmp_path / "KIN_SIGN.H").write_text(out.files["_SIGN.H"])
    code, _, err = run("check-program", "--machine", machine.source, tmp_path / "KIN_SIGN.H")
    assert code == 0, err
    if current is not None:        # the table: each axis's pairs around it, the OEM's rows kept
        want = [("Trans", "Z", 150.0, "tool")]
        for key, axis in [("MachAxis", "B"), ("MachAxis", "Z"), ("MachAxis", "Y"), ("MachAxis", "X"),
                          ("MachBase", None), ("MachAxis", "C")]:
            pairs = by_hand.get(axis, [])
            want += [("Trans", a, v, doc) for doc, a, v in pairs] + [(key, axis, None, None)]
            want += [("Trans", a, -v, f"-{doc}") for doc, a, v in reversed(pairs)]
        rows = [ln.split() for ln in out.files[".TAB"].splitlines()[2:-1]]
        got = [(r[1], r[2] if r[1] != "MachBase" else None, float(r[3]) if r[1] == "Trans" else None,
                r[4] if r[1] == "Trans" else None) for r in rows]
        assert [g[:2] + g[3:] for g in got] == [w[:2] + w[3:] for w in want], got
        assert np.allclose([g[2] for g in got if g[2] is not None], [w[2] for w in want if w[2] is not None],
                           rtol=0, atol=1e-7)
        far = current.replace("+150  ", "+151  ")
        with pytest.raises(CompgenError, match="puts the head's B axis at .* tool reference point"):
            kinematics_edit(machine, fit, ctl, far, "far.TAB", "KIN", "0", "d")
    text = out.files[".txt"]       # the change list
    assert "UNCONFIRMED U18" in text
    for doc, a, v in (row for pairs in by_hand.values() for row in pairs):
        line = re.search(rf"(?m)^\s+{doc}\s+Trans\s+{a}\s+(\S+) (mm|deg)", text)
        assert line and float(line[1]) == pytest.approx(v, abs=1e-7), (doc, line and line[0])
    held = read_edits(machine, {"KIN.txt": text}, None)
    fitted = plan(machine, fit).lines
    for a in machine.rotary_axes:
        np.testing.assert_allclose(held.lines[a.name].offset, fitted[a.name].offset, atol=6e-6)
        np.testing.assert_allclose(held.lines[a.name].tilt, fitted[a.name].tilt, atol=1e-8)


# a non-zero state each control starts from (an OEM's or an earlier round's), and what the
# edit of each is read as; every case's truth holds only what that control can hold
ROUNDS = {
    "linuxcnc-maxkins": (None, {"XOW": 4 * UM, "YOW": -6 * UM, "ZOW": 9 * UM, "ZOB": 30 * UM}),
    "linuxcnc-5axiskins": (FORK_MACHINE, {"XOW": 4 * UM, "YOW": -6 * UM, "ZOW": 9 * UM, "ZOB": -25 * UM}),
    "sinumerik-T": (FORK_MACHINE, TRUTH),
    "sinumerik-M": (HEAD_MACHINE, TRUTH),
    "itnc530": (HEAD_MACHINE, TRUTH),
}
SWIVEL_TAB_HELD = """BEGIN KINEMATIC_BC.TAB MM
NR  KEY       AXIS  COORD        DOC
0   Trans     Z     +150         tool reference point to the B pivot
1   Trans     X     +0.00600     X0B
2   MachAxis  B
3   Trans     X     -0.00600     -X0B
4   MachAxis  Z
5   MachAxis  Y
6   MachAxis  X
7   MachBase
8   MachAxis  C
[END]
"""


@pytest.mark.parametrize("case", list(ROUNDS))
def test_two_rounds_on_a_head_from_a_non_zero_state_reach_the_noise(tmp_path, case):
    """Second rounds compose on a head as on a table: from a state that already holds a
    correction (LinuxCNC's pin 5 µm off, a SINUMERIK fine offset, an iTNC 530 row), round 1
    corrects the head's own axis only and round 2 everything, each edit over the state the
    last one left. The true machine, driven where the control then drives it, reads the set-up
    and the noise only."""
    source, truth = ROUNDS[case]
    controller = case.split("-")[0]
    if controller == "linuxcnc":
        machine = load_machine(on_linuxcnc(tmp_path, source))
        name = linuxcnc.head_module(machine)[0].module
        state = f"setp {name}.pivot-length 270.005\n"
    elif controller == "sinumerik":
        machine = _on_sinumerik(tmp_path, source, "{ C = [0.0, 0.0, 1.0], B = [0.0, 1.0, 0.0] }"
                                if case.endswith("T") else "{ B = [0.0, 1.0, 0.0], C = [0.0, 0.0, -1.0] }")
        held0 = ([0, 0, 1], [0, 1, 0]) if case.endswith("T") else ([0, 1, 0], [0, 0, -1])
        nominal = carr_record(*held0)
        # an earlier round's 4.7 µm on pivot 2 (the fork's B, the table's C), its chain closed
        closing = "$TC_CARR44[1]=-0.0047" if case.endswith("T") else "$TC_CARR58[1]=-0.0047"
        state = nominal.replace("$TC_CARR55[1]=0", "$TC_CARR55[1]=0.0047").replace(
            closing.split("=")[0] + "=0", closing)
        controller = "sinumerik840d"
    else:
        machine = load_machine(source)
        state, nominal = SWIVEL_TAB_HELD, None

    def held(text):                        # what the control holds in ``text``, as lines
        if controller == "linuxcnc":
            return read_edits(machine, {"KIN.hal": text}, None).lines
        if controller == "sinumerik840d":
            return read_edits(machine, {"KIN.MPF": text}, nominal).lines
        return read_edits(machine, {"KIN.TAB": text}, None).lines

    poses = generate(machine, ["K4", "K1", "K2"])
    rng = np.random.default_rng(3)

    def measure(text):
        return measured_under(machine, truth, held(text), poses, rng, NOISE_UM)

    setup = ["XOW", "YOW", "ZOW"]
    assert any(np.abs(line.offset).max() > 0 for line in held(state).values())
    before = identify(machine, [measure(state)], setup)
    head = machine.heads[-1].name
    partial = [*setup, *(n for n in location_model(machine) if n.endswith(head))]
    for model in (partial, location_model(machine)):
        fit = identify(machine, [measure(state)], model)
        out = kinematics_edit(machine, fit, controller, state, "current", "KIN", "0", "d")
        state = out.files[{"linuxcnc": ".hal", "sinumerik840d": ".MPF", "itnc530": ".TAB"}[controller]]
    after = identify(machine, [measure(state)], setup)
    was, now = before.residual["rms_um"], after.residual["rms_um"]
    print(f"{case}: misfit beyond set-up {was:.2f} -> {now:.2f} um")
    assert before.residual["rms_um"] > 6 * NOISE_UM, before.residual["rms_um"]
    assert after.residual["rms_um"] == pytest.approx(NOISE_UM, rel=0.15), (before.residual["rms_um"],
                                                                            after.residual["rms_um"])


def test_a_longer_nest_is_advised_with_the_ball_where_the_machine_file_has_it(tmp_path):
    """On a head (LinuxCNC's maxkins) the longer nest is the one thing changed: every path
    is offered with the nest 100 mm longer and the ball where the machine file stands it."""
    machine = load_machine(on_linuxcnc(tmp_path))
    longer = [m for m in Advisor(machine).candidates if m.label.endswith(" with the nest 100 mm longer")]
    assert sorted(m.path for m in longer) == sorted(machine.paths)
    for m in longer:
        assert m.ball == pytest.approx(machine.ball) and (m.poses.ball == m.ball).all(), m.label
        assert m.nest == machine.probe_length + 100 and (m.poses.nest == m.nest).all(), m.label


def test_a_heads_pivot_stands_where_the_head_carries_it_when_the_table_moves_too(tmp_path):
    """The motion check's head body is a sphere about the pivot, in the table frame. The
    pivot is rigid with the nest, so at every pose of every path (the nest at the ball) it
    stands the pivot-to-nest distance from the ball: on the swivel-head machine as shipped
    (the table only turns) and with X moved to the table (a travelling table: the table
    frame's origin then moves, 711 mm over the paths). Taken the wrong way round, the head
    stood 30–570 mm from the ball instead of 270."""
    from compgen.model.frames import head_pivots
    text = (HEAD_MACHINE).read_text()
    x = re.search(r'\[\[tool\]\]\naxis = "X".*?feed_max = 30000.0\n', text, re.S).group(0)
    table_x = x.replace("[[tool]]", "[[workpiece]]")
    moved = text.replace(x, "").replace('[[workpiece]]\naxis = "C"', table_x + '\n[[workpiece]]\naxis = "C"')
    (tmp_path / "x-table.toml").write_text(moved)
    shipped = load_machine(HEAD_MACHINE)
    travelling = load_machine(tmp_path / "x-table.toml")
    assert [a.name for a in travelling.workpiece] == ["X", "C"]
    for m in (shipped, travelling):
        poses = generate(m, list(m.paths))
        distance = np.linalg.norm(head_pivots(m, poses.q)[:, 0] - poses.ball, axis=1)
        assert distance == pytest.approx(np.full(len(poses), 150.0 + m.probe_length), abs=1e-9)
    assert np.ptp(generate(travelling, ["K4"]).q[:, travelling.index("X")]) > 100


def test_linuxcnc_refuses_what_a_head_module_cannot_take(tmp_path):
    """On maxkins: an INI that loads a joint compensation table (compgen does not compose
    one for a head module yet) is refused at its COMP_FILE line; conventional_directions =
    true is refused on 2.9 (no such pin before 2.10) and on 2.10 (compgen models the head
    modules as Debian's 2.9 runs them, without the pin); a head's program checked
    against a table machine's file says it was written for a head."""
    from compgen.controllers.registry import read_state
    path = on_linuxcnc(tmp_path, None)
    machine = load_machine(path)
    (tmp_path / "a.hal").write_text("setp maxkins.pivot-length 270\n")
    (tmp_path / "c.comp").write_text("-10 -0.001 0.001\n10 0.001 -0.001\n")
    (tmp_path / "m.ini").write_text("[HAL]\nHALFILE = a.hal\n[JOINT_4]\nCOMP_FILE = c.comp\n")
    state = read_state(str(tmp_path / "m.ini"))
    with pytest.raises(CompgenError, match=r"m.ini:4.*compgen does not compose them for a head module"):
        linuxcnc.loaded_joint_tables(machine, state)
    code, _, err = run("measure-program", "--machine", path, "--path", "K4", "-o", tmp_path / "K4.ngc")
    assert code == 0, err
    table = tmp_path / "table.toml"
    table.write_text(re.sub(r'controller = "\w+"', 'controller = "linuxcnc"', SEED_MACHINE.read_text())
                     .replace('tool = "RTEST"', 'tool = "7"'))
    code, _, err = run("check-program", "--machine", table, "--mode", "tcpm", tmp_path / "K4.ngc")
    assert code == 2 and "the program was written for a head on maxkins, which this machine file is not" \
        in err, err
    path.write_text(path.read_text().replace("directions = false", "directions = true"))
    code, _, err = run("measure-program", "--machine", path, "--path", "K4", "-o", tmp_path / "K4b.ngc")
    assert code == 2 and "LinuxCNC 2.9 has no conventional-directions pin" in err, err
    assert "its kinematics modules, trt or head, turn the axes" in err, err      # not "its trt kinematics"
    path.write_text(path.read_text().replace('version = "2.9"', 'version = "2.10"'))   # the trt pin's version
    code, _, err = run("measure-program", "--machine", path, "--path", "K4", "-o", tmp_path / "K4b.ngc")
    assert code == 2 and "maxkins was run without a conventional-directions pin" in err, err
    assert "[linuxcnc] conventional_directions" in err and not (tmp_path / "K4b.ngc").exists()


def test_a_longer_nest_is_a_nest_put_in_again_with_an_offset_of_its_own():
    """The advice sends a head to K4 with a longer nest: another nest, or the same on
    another holder, off the spindle's axis by what that clamping left. With one nest offset
    for both, 3, −2, 1 µm of it read as a 25″ tilt error motion of C, significant; with an
    offset for each nest (``sides.nest_mountings``) the fit is the one whose second nest sat
    as the first, to 0.001 µm and ″, the location errors within 3 σ of the truth, and
    diagnose, told the noise, finds nothing left."""
    machine = load_machine(FORK)
    truth = {"XOW": 5 * UM, "YOW": -8 * UM, "ZOW": 12 * UM, "XOC": 6 * UM, "YOC": -4 * UM,
             "AOC": 5 * ARCSEC, "BOC": -4 * ARCSEC, "XOB": 10 * UM, "ZOB": -7 * UM, "AOB": 6 * ARCSEC,
             "COB": -3 * ARCSEC}
    first = simulate(machine, truth, generate(machine, ["K4", "K1", "K2"]), NOISE_UM,
                     np.random.default_rng(1))
    k4 = generate(machine, ["K4"])
    longer = Poses(k4.q, k4.ball, k4.t, k4.path, k4.side, np.full(len(k4), machine.probe_length + 30))
    fits = {}
    for name, offset in {"kept": (0, 0, 0), "put in again": (3, -2, 1)}.items():
        nest = {f"nest_{d}": v * UM for d, v in zip("XYZ", offset, strict=True)}
        second = simulate(machine, {**truth, **nest}, longer, NOISE_UM, np.random.default_rng(2))
        fits[name] = (identify(machine, [first, second]), [first, second])
    kept, (again, data) = fits["kept"][0], fits["put in again"]
    assert again.residual["rms_um"] == pytest.approx(kept.residual["rms_um"], abs=1e-3)
    for n, p in kept.parameters.items():            # to 0.001 µm or ″
        near = 1e-3 * (UM if p.unit == "mm" else ARCSEC)
        assert again.parameters[n].value == pytest.approx(p.value, abs=near), n
        assert abs(again.parameters[n].value - truth[n]) < 3 * again.parameters[n].std, n
    assert not diagnose(machine, data, again, noise_um=NOISE_UM).significant


@pytest.mark.parametrize("machine_file", [HEAD_MACHINE, FORK_MACHINE], ids=["swivel", "fork"])
@pytest.mark.parametrize("seed", [1, 2])
def test_a_sensor_gain_on_a_head_is_blamed_in_the_frame_the_nest_turns_in(machine_file, seed):
    """The nest turns with the head: its X sensor reads along the tool's turned X. A 2 % gain
    of it is blamed on the device, within 3 σ, and no machine effect is found; the gains'
    columns along the machine's X, Y, Z read it as rivals of machine effects, or missed it
    ("explained"), on both heads. The readings are made here with the tool's axes from the
    chain itself, not through compgen's sensor_axes."""
    from compgen.data.rtest import RTestData
    from compgen.model.effects import resolve
    from compgen.model.kinematics import chain_transform
    from compgen.model.poses import Poses
    machine = load_machine(machine_file)
    poses = generate(machine, list(machine.paths))
    truth = {n: (1 + i % 3) * (-1) ** i * (8e-3 if resolve(machine, n).unit == "mm" else np.radians(8 / 3600))
             for i, n in enumerate(location_model(machine))}
    y = simulate(machine, truth, poses).deviation
    u = chain_transform(machine, machine.tool, Poses.at(poses.q, np.zeros(3)), {},
                        np.zeros((len(poses), 6)))[:, :3, 0]
    read = y + 0.02 * u * np.einsum("ni,ni->n", u, y)[:, None]
    noise = np.random.default_rng(seed).normal(0, 0.5e-3, y.shape)
    data = [RTestData(poses, read + noise, "gain.csv", "", tuple(range(2, len(poses) + 2)))]
    d = diagnose(machine, data, identify(machine, data), noise_um=0.5)
    assert d.device_blamed == "gain_X" and d.found is None, (d.verdict, d.devices)
    gain = d.blamed
    assert abs(gain.value - 2.0) < 3 * gain.std and gain.std < 0.4, gain


def test_a_heads_error_motion_no_table_holds_is_named_by_the_edit_and_never_sent_to_a_comp_csv(tmp_path):
    """The fork head on a TNC 640 with a 2/rev angular motion of C (ECC:h2) fitted: the
    edit writes no table for a head's own error motion; it names it as not compensable
    (it vanished without a word), and compare no longer tells the user to enter the values
    of a .comp.csv that was never written. A table machine's positioning table still goes
    to its .comp.csv, and compare still says so."""
    truth = tmp_path / "t.json"
    truth.write_text('{"parameters": {"ECC:h2c": {"value": 4e-5, "unit": "rad"}, '
                     '"YOC": {"value": -0.008, "unit": "mm"}}}')
    assert run("simulate", "--machine", FORK_MACHINE, "--truth", truth, "--noise-um", "0.5", "-o",
               tmp_path / "s.csv")[0] == 0
    assert run("fit", "--machine", FORK_MACHINE, tmp_path / "s.csv", "--add", "ECC:h2", "-o",
               tmp_path / "f.json")[0] == 0
    code, out, err = run("kinematics", "--from", tmp_path / "f.json", "-o", tmp_path / "KIN.txt")
    assert code == 0 and "not compensable on HEIDENHAIN TNC 640 by compgen: ECC:h2" in out, out + err
    assert "; Not compensable on this control by compgen: ECC:h2" in (tmp_path / "KIN.txt").read_text()
    assert not (tmp_path / "KIN.comp.csv").exists()
    code, out, err = run("compare", "--from", tmp_path / "f.json")
    assert code == 0 and ".comp.csv" not in out and "cannot hold it from compgen's files: ECC:h2" in out, out
    # a table machine: C's 1/rev positioning error goes to the .comp.csv, entered by hand
    table = tmp_path / "table.json"
    table.write_text('{"parameters": {"ECC:h1s": {"value": 4e-5, "unit": "rad"}}}')
    assert run("simulate", "--machine", SEED_MACHINE, "--truth", table, "--noise-um", "0.5", "-o",
               tmp_path / "t.csv")[0] == 0
    assert run("fit", "--machine", SEED_MACHINE, tmp_path / "t.csv", "--add", "ECC:h1", "-o",
               tmp_path / "g.json")[0] == 0
    code, out, err = run("kinematics", "--from", tmp_path / "g.json", "-o", tmp_path / "T.txt")
    assert code == 0 and (tmp_path / "T.comp.csv").exists() and "not compensable" not in out, out + err
    code, out, err = run("compare", "--from", tmp_path / "g.json")
    assert "the compensation values of the edit's .comp.csv (ECC:h1) are entered" in out, out


def test_a_nest_put_back_at_its_length_between_two_files_is_no_machine_effect(head_machine):
    """The nest taken out and put back between a.csv (K4) and b.csv (K2 + K4), 2 µm off in Y:
    one nest to the fit (the same length). Nothing is named found: the step between the
    files rivals the best candidate, the first line says so."""
    from dataclasses import replace

    from compgen.statistics.diagnose import diagnose
    truth = {"XOC": 0.01, "YOC": -0.008}
    rng = np.random.default_rng(3)
    first = generate(head_machine, ["K4"])
    then = generate(head_machine, ["K2", "K4"], start_s=float(np.nanmax(first.t)) + 120.0)
    data = [replace(simulate(head_machine, truth, first, NOISE_UM, rng), source="a.csv", sha256="1" * 64),
            replace(simulate(head_machine, {**truth, "nest_Y": 2 * UM}, then, NOISE_UM, rng), source="b.csv",
                    sha256="2" * 64)]
    d = diagnose(head_machine, data, identify(head_machine, data), noise_um=NOISE_UM)
    assert d.verdict == "set-up step" and d.found is None and d.setup_step.before == "b.csv", d.verdict
    assert abs(d.setup_step.nest_um[1] - 2.0) < 0.3, d.setup_step        # told as the nest's, in size
