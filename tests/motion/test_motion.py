"""Programs simulated block by block against the R-test set-up (`compgen check-program`):
every program compgen writes passes; crafted defects are refused; LinuxCNC's own
interpreter (rs274) reads compgen's programs to the same positions as the simulator."""

import json
import re

import numpy as np
import pytest
from conftest import BC_MACHINE, ROOT, SEED_MACHINE, rs274, run

from compgen.configuration.machine_file import load_machine
from compgen.controllers.registry import controller
from compgen.controllers.state_guards import heidenhain_guard
from compgen.errors import CompgenError
from compgen.model.frames import frames, safe_height
from compgen.model.kinematics import inverse
from compgen.motion import check as motion
from compgen.motion.check import clearances

PROGRAMS = [(m, c, mode, path) for m in ("seed", "bc") for c in ("itnc530", "sinumerik840d", "linuxcnc")
            for mode in ("tcpm", "axes") for path in ("K4", "K1,K2", "all")]


@pytest.fixture(scope="module")
def machines(tmp_path_factory):
    """The bundled machines; the B/C one with a numbered tool, as LinuxCNC calls tools."""
    folder = tmp_path_factory.mktemp("m")
    bc = folder / "bc.toml"
    bc.write_text(BC_MACHINE.read_text().replace('tool = "RTEST"', 'tool = "7"'))
    return {"seed": SEED_MACHINE, "bc": bc}


def _write(tmp_path, machine_file, ctl, mode, path, name="RT"):
    out = tmp_path / f"{name}{controller(ctl).program_ext}"
    code, _, err = run("measure-program", "--machine", machine_file, "--path", path, "--controller", ctl,
                       "--mode", mode, "-o", out, "--force")
    assert code == 0, err
    return out


@pytest.mark.parametrize("m, ctl, mode, path", PROGRAMS)
def test_every_program_compgen_writes_passes_the_check(machines, tmp_path, m, ctl, mode, path):
    program = _write(tmp_path, machines[m], ctl, mode, path)
    told = [] if controller(ctl).tcp_switchable else ["--mode", mode]     # LinuxCNC: the configuration's
    code, out, err = run("check-program", "--machine", machines[m], program, *told)
    assert code == 0, out + err
    closest = float(re.search(r"closest approach (-?[\d.]+) mm", out)[1])
    assert closest > 0, out


def _check(machine_file, path, text):
    path.write_text(text)
    mode = ["--mode", "tcpm" if "; mode TCPM" in text else "axes"] if path.suffix == ".ngc" else []
    return run("check-program", "--machine", machine_file, path, *mode)


def test_a_plunge_through_the_ball_is_refused(machines, tmp_path):
    program = _write(tmp_path, machines["seed"], "itnc530", "tcpm", "K4").read_text()
    bad = re.sub(r"Z\+241\.3310 (A\S+ C\S+) R0 F500 ; nest onto the ball", r"Z+200.0000 \1 R0 F500 ; plunge",
                 program)
    assert bad != program
    code, out, _ = _check(machines["seed"], tmp_path / "PLUNGE.H", bad)
    assert code == 1 and "housing enters the ball" in out and "housing enters the stem" in out, out
    depth = float(re.search(r"housing enters the ball by ([\d.]+) mm", out)[1])
    assert depth > 10


def test_a_retract_through_the_table_is_refused(machines, tmp_path):
    program = _write(tmp_path, machines["bc"], "sinumerik840d", "tcpm", "K2").read_text()
    bad = re.sub(r"(G1 X\S+ Y\S+ )Z\S+( B\S+ C\S+ F500) ; nest off the ball, along its axis",
                 r"\1Z-150.0000\2 ; down", program, count=1)
    assert bad != program
    code, out, _ = _check(machines["bc"], tmp_path / "DOWN.MPF", bad)
    line = 1 + next(i for i, ln in enumerate(bad.splitlines()) if "Z-150.0000" in ln)
    assert code == 1 and re.search(rf"DOWN\.MPF:{line}: .*enters the table", out), out


def test_a_feed_above_the_limit_is_refused(machines, tmp_path):
    program = _write(tmp_path, machines["seed"], "linuxcnc", "tcpm", "K4").read_text()
    bad = program.replace("F500 ; pose 10 ", "F900000 ; pose 10 ")
    assert bad != program
    code, out, _ = _check(machines["seed"], tmp_path / "fast.ngc", bad)
    line = 1 + next(i for i, ln in enumerate(bad.splitlines()) if "F900000" in ln)
    assert code == 1 and f"fast.ngc:{line}: feed above feed_max" in out, out


def test_a_pose_past_travel_is_refused(machines, tmp_path):
    program = _write(tmp_path, machines["seed"], "itnc530", "axes", "K1,K2").read_text()
    bad = re.sub(r"A-90\.0000 C\+0\.0000 R0 F500 ; pose 1 ", "A-130.0000 C+0.0000 R0 F500 ; pose 1 ", program)
    assert bad != program
    code, out, _ = _check(machines["seed"], tmp_path / "FAR.H", bad)
    assert code == 1 and "outside travel" in out and "A reaches -130.000" in out, out
    # --json: the same finding and exit code, for a script that reads the document
    code, doc, _ = run("check-program", "--machine", machines["seed"], tmp_path / "FAR.H", "--json")
    doc = json.loads(doc)
    assert code == 1 and doc["ok"] is False
    assert [f["text"] for f in doc["findings"]] == [ln for ln in out.splitlines() if "FAR.H:" in ln]


def test_turning_with_the_nest_down_is_refused(machines, tmp_path):
    program = _write(tmp_path, machines["seed"], "itnc530", "axes", "K2").read_text()
    lines = program.splitlines()
    at = next(i for i, ln in enumerate(lines) if "nest onto the ball" in ln)
    bad = "\n".join([*lines[:at + 1], "999 L C+90.0000 R0 FMAX", *lines[at + 1:]]) + "\n"
    code, out, _ = _check(machines["seed"], tmp_path / "TURN.H", bad)
    assert code == 1 and f"TURN.H:{at + 2}: " in out and "enters the" in out, out


def test_no_tool_call_and_machine_coordinates_are_refused(machines, tmp_path):
    program = _write(tmp_path, machines["bc"], "sinumerik840d", "axes", "K4").read_text()
    no_tool = re.sub(r'(?m)^T="[^"]*".*\n', "", program)
    assert no_tool != program
    code, out, _ = _check(machines["bc"], tmp_path / "NOTOOL.MPF", no_tool)
    assert code == 1 and "no tool call or length compensation" in out, out
    supa = program.replace("G0 Z", "G0 SUPA Z", 1)
    code, out, _ = _check(machines["bc"], tmp_path / "SUPA.MPF", supa)
    assert code == 1 and "machine coordinates" in out, out


@pytest.mark.parametrize("text, expected", [
    ("0 BEGIN PGM X MM\n1 L X+1 Q7 R0 FMAX\n", "'Q7' is not a word"),
    ("0 BEGIN PGM X MM\n1 CALL LBL 5\n", "is not a block this check knows"),
])
def test_blocks_it_cannot_read_are_an_error_not_a_pass(machines, tmp_path, text, expected):
    code, _, err = _check(machines["seed"], tmp_path / "ODD.H", text)
    assert code == 2 and expected in err and len(err.strip().splitlines()) == 1, err


def test_the_safe_height_clears_the_set_up_at_every_orientation(machines):
    seed, bc = (load_machine(machines[k]) for k in ("seed", "bc"))
    # the seed ball is 325 mm from the A/C intersection: 337.6 with its radius, + 5 + 30 + 5
    assert safe_height(seed) == 378.0
    assert safe_height(bc) < bc.axis("Z").travel[1]


@pytest.mark.parametrize("dx, dy", [(0.0, 0.0), (40.0, -25.0), (-60.0, 10.0)])
def test_the_safe_height_is_the_farthest_point_of_the_set_up(machines, dx, dy):
    """Against a brute force over the table's rims (3600 points each) and the ball, on the
    seed machine with its table carried off the A/C intersection (a C axis offset in X, Y):
    the farthest rim point then lies at one angle only."""
    from dataclasses import replace

    from compgen.transforms import apply
    seed = load_machine(machines["seed"])
    m = replace(seed, workpiece=tuple(replace(a, offset=(a.offset[0] + dx, a.offset[1] + dy, a.offset[2]))
                                      if a.name == "C" else a for a in seed.workpiece))
    s = m.setup
    table = frames(m, np.zeros((1, len(m.axes))))[0][0]
    t = np.linspace(0, 2 * np.pi, 3600, endpoint=False)
    rims = [np.column_stack([s.table_radius * np.cos(t), s.table_radius * np.sin(t), np.full_like(t, z)])
            for z in (s.table_top, s.table_top - s.table_thickness)]
    reach = max(np.linalg.norm(apply(table, np.concatenate(rims)), axis=1).max(),
                np.linalg.norm(apply(table, np.asarray(m.ball))) + s.ball_diameter / 2)
    assert safe_height(m) == np.ceil(reach + s.nest_below + s.nest_radius + s.margin)


def test_the_stem_points_down_the_table_at_every_pose(machines):
    """table_axis_down (where a probe's stem stands from its sphere) against the walk of the
    chains: a table point 1 mm lower on the stem moves the reading by minus that vector."""
    from compgen.model.frames import table_axis_down
    from compgen.model.kinematics import Model
    from compgen.model.poses import Poses
    for key in ("seed", "bc"):
        m = load_machine(machines[key])
        rng = np.random.default_rng(2)
        q = np.column_stack([rng.uniform(-50, 50, (20, 3)),
                             np.radians(rng.uniform(-90, 90, (20, len(m.rotary_axes))))])
        ball = np.asarray(m.ball)
        nominal = Model(m, ())
        walked = nominal.relative(Poses.at(q, ball)) - nominal.relative(Poses.at(q, ball - [0, 0, 1]))
        down = table_axis_down(m, q)
        assert down.shape == (20, 3) and abs(down[:, 2]).min() < 0.5     # the table turned
        np.testing.assert_allclose(down, walked, atol=1e-9)


@pytest.mark.parametrize("mode", ["tcpm", "axes"])
def test_linuxcnc_reads_compgens_program_to_the_simulators_positions(machines, tmp_path, mode):
    program = _write(tmp_path, machines["seed"], "linuxcnc", mode, "K4,K1")
    canon, done = rs274(tmp_path, program.name, "T99 P1 Z184.67 ;nest")
    assert "STRAIGHT" in canon, done.stdout + done.stderr
    theirs = np.array([[float(v) for v in m[1].split(",")] for m in
                       re.finditer(r"STRAIGHT_(?:TRAVERSE|FEED)\(([^)]*)\)", canon)])[:, [0, 1, 2, 3, 5]]
    # the simulator's reading of the same blocks: each move's end, modal words carried
    blocks = [b for b in controller("linuxcnc").blocks(program.read_text(), mode) if b.kind == "move"]
    pos, ours = dict.fromkeys("XYZAC", 0.0), []
    for b in blocks:
        pos.update(b.target)
        ours.append([pos[c] for c in "XYZAC"])
    assert len(ours) == len(theirs)
    np.testing.assert_allclose(np.array(ours), theirs, rtol=0, atol=1e-4)   # both print 4 decimals


@pytest.mark.parametrize("edit, expected", [
    (("probe_length = 184.670", "probe_length = 184.670\nball_diametre = 25.4"),
     "unknown key ball_diametre"),
    (("ball_diameter = 25.4", "ball_diameter = -25.4"), "ball_diameter"),
    (("table_top = 0.0", "table_top = 300.0"), "does not stand above the table top"),
    (("clearance = 20.0", "clearance = 20.0\nsafe_z = -5.0"), "safe_z (a height in machine coordinates)"),
])
def test_a_bad_set_up_is_refused_with_its_key(tmp_path, edit, expected):
    text = SEED_MACHINE.read_text()
    assert edit[0] in text
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(edit[0], edit[1], 1))
    code, _, err = run("check-program", "--machine", bad, tmp_path / "x.H")
    assert code == 2 and expected in err and len(err.strip().splitlines()) == 1, err


def test_a_heidenhain_datum_shift_is_refused_at_its_line(machines, tmp_path):
    program = _write(tmp_path, machines["seed"], "itnc530", "tcpm", "K2").read_text()
    lines = program.splitlines()
    at = next(i for i, ln in enumerate(lines) if "CYCL DEF 7.1 X+0" in ln)
    lines[at] = lines[at].replace("X+0", "X+5")
    code, out, err = _check(machines["seed"], tmp_path / "SHIFT.H", "\n".join(lines) + "\n")
    assert code == 2 and f"SHIFT.H:{at + 1}: a datum shift" in err, err


@pytest.mark.parametrize("ctl, junk", [("itnc530", "25 FOO BAR"), ("sinumerik840d", "FOO BAR"),
                                       ("linuxcnc", "M999 FOO")])
def test_a_block_the_check_cannot_read_is_named_by_its_line(machines, tmp_path, ctl, junk):
    program = _write(tmp_path, machines["seed"], ctl, "tcpm", "K2").read_text().splitlines()
    at = len(program) // 2
    text = "\n".join([*program[:at], junk, *program[at:]]) + "\n"
    code, out, err = _check(machines["seed"], tmp_path / f"JUNK{controller(ctl).program_ext}", text)
    assert code == 2 and f"JUNK{controller(ctl).program_ext}:{at + 1}: " in err, err   # the file and line


@pytest.mark.parametrize("ctl", ["itnc530", "sinumerik840d", "linuxcnc"])
@pytest.mark.parametrize("ball", ["-108.752,-0.1395,211.537", "-217.504,-0.279,111.537"])
def test_a_program_for_a_ball_elsewhere_carries_it_and_passes_the_check(machines, tmp_path, ctl, ball):
    """measure-program --ball writes the ball into the header; check-program checks the
    program against that set-up (the machine file's ball would put the nest into it)."""
    out = tmp_path / f"ELSEWHERE{controller(ctl).program_ext}"
    code, _, err = run("measure-program", "--machine", machines["seed"], "--path", "K2", "--ball", ball,
                       "--controller", ctl, "-o", out)
    assert code == 0, err
    mode = ["--mode", "tcpm"] if ctl == "linuxcnc" else []
    code, text, err = run("check-program", "--machine", machines["seed"], out, *mode)
    assert code == 0 and "from the program's header" in text, text + err
    code, text, err = run("check-program", "--machine", machines["seed"], out, *mode,
                          "--ball", "-217.504,-0.279,211.537")
    assert code == 1 and "from --ball" in err, text + err


def test_a_program_naming_two_balls_is_refused(machines, tmp_path):
    program = _write(tmp_path, machines["seed"], "itnc530", "tcpm", "K4").read_text()
    line = next(ln for ln in program.splitlines() if "ball centre in the table frame" in ln)
    bad = program.replace(line, line + "\n" + line.replace("X-217.5040", "X-100.0000"))
    code, out, err = _check(machines["seed"], tmp_path / "TWO.H", bad)
    assert code == 2 and "2 ball positions" in err, out + err


def test_check_program_refuses_an_empty_or_impossible_ball_in_one_line(machines, tmp_path):
    program = _write(tmp_path, machines["seed"], "itnc530", "tcpm", "K2")
    for ball, words in (("", "--ball takes three numbers"), ("0,0,-50", "does not stand above the table top"),
                        ("900,0,200", "does not stand on the table")):
        code, _, err = run("check-program", "--machine", machines["seed"], program, "--ball", ball)
        assert code == 2 and words in err and err.count("\n") == 1 and "the ball: the ball" not in err, err


def _around_the_set_up(m, rng, n):
    """``n`` random machine poses around the set-up: each rotary axis within ±100°, X and Y
    within ±150 mm, Z in the lowest 300 mm of its travel (each axis drawn per pose)."""
    q = np.zeros((n, len(m.axes)))
    for i, a in enumerate(m.axes):
        lo, hi = a.travel
        q[:, i] = np.radians(rng.uniform(max(lo, -100), min(hi, 100), n)) if a.rotary else rng.uniform(
            max(lo, -150), min(hi, 150), n)
    q[:, m.index("Z")] = rng.uniform(m.axis("Z").travel[0], m.axis("Z").travel[0] + 300, n)
    return q


@pytest.mark.parametrize("held, face", [("nest", 0.0), ("probe", 0.0), ("nest", -35.0)])
def test_the_searched_clearance_is_the_least_along_housing_and_spindle(held, face):
    """The closed forms (ball, stem) and the golden-section search (table) against a brute
    force: every part sampled every 0.02 mm, at random poses around the set-up (near the
    ball, the stem and the table's face), some with the tool axis parallel to the stem.
    The parts are the machine file's, read here: the R-test's housing and spindle, or the
    probe's stylus tip (a sphere), stylus, body and spindle. Poses whose tool axis stands
    in the table near its rim read how deep the part is; ``face``: the table's face moved
    below the C frame's origin."""
    from dataclasses import replace
    m = load_machine(SEED_MACHINE)
    m = replace(m, setup=replace(m.setup, table_top=face))
    s = m.setup
    rng = np.random.default_rng(5)
    n = 400
    q = _around_the_set_up(m, rng, n)
    q[:40, [m.index(a.name) for a in m.rotary_axes]] = 0.0     # the tool axis parallel to the stem
    # the tool axis upright in the table, 1-20 mm inside its rim, between its faces
    angle, radial = rng.uniform(0, 2 * np.pi, 20), s.table_radius - rng.uniform(1, 20, 20)
    z = rng.uniform(s.table_top - s.table_thickness + 5, s.table_top - 5, 20)
    rotary = np.zeros((20, len(m.rotary_axes)))
    q[40:60] = inverse(m, rotary, np.column_stack([radial * np.cos(angle), radial * np.sin(angle), z]))
    probe = m.probe if held == "probe" else None
    got, _ = clearances(m, q, probe)
    _, nest, axis = frames(m, q)
    ball, rb = np.asarray(m.ball), s.ball_diameter / 2
    parts = {"housing": (-s.nest_below, m.probe_length, s.nest_radius),
             "spindle": (m.probe_length, m.probe_length + s.spindle_length, s.spindle_radius)}
    if probe is not None:
        parts = {"stylus tip": (0.0, 0.0, probe.stylus_diameter / 2),
                 "stylus": (probe.stylus_diameter / 2, probe.stylus_length, probe.shaft_diameter / 2),
                 "probe body": (probe.stylus_length, probe.length, probe.body_diameter / 2),
                 "spindle": (probe.length, probe.length + s.spindle_length, s.spindle_radius)}
    assert set(got) == {f"{part} / {solid}" for part in parts for solid in ("ball", "stem", "table")}
    for part, (lo, hi, radius) in parts.items():
        t = np.linspace(lo, hi, int((hi - lo) / 0.02) + 1)
        pts = nest[:, None, :] + t[None, :, None] * axis[:, None, :]
        brute = (np.linalg.norm(pts - ball, axis=2) - rb).min(axis=1) - radius
        np.testing.assert_allclose(got[f"{part} / ball"], brute, atol=0.02)
        z = np.clip(pts[..., 2], s.table_top, ball[2] - rb)
        stem = np.hypot(np.hypot(pts[..., 0] - ball[0], pts[..., 1] - ball[1]), pts[..., 2] - z)
        np.testing.assert_allclose(got[f"{part} / stem"], (stem - s.stem_diameter / 2).min(axis=1) - radius,
                                   atol=0.02)
        radial, z = np.hypot(pts[..., 0], pts[..., 1]), pts[..., 2]
        top, bottom = s.table_top, s.table_top - s.table_thickness
        outside = np.hypot(np.maximum(np.maximum(z - top, bottom - z), 0),
                           np.maximum(radial - s.table_radius, 0))
        inside = -np.minimum(np.minimum(top - z, z - bottom), s.table_radius - radial)
        table = np.where(outside > 0, outside, inside).min(axis=1) - radius
        np.testing.assert_allclose(got[f"{part} / table"], table, atol=0.02)
        assert (got[f"{part} / table"] < 0).any() or part in ("spindle", "stylus tip")   # some reach in


def test_the_motion_check_applies_the_set_ups_margin_to_every_collision_rule():
    """compgen's K4 program comes within C mm of the set-up at its closest: a margin 1 mm
    above C is a finding naming the margin, 1 mm below is none. (Before, only entering a
    solid was refused: the spindle tangent to the table face passed.)"""
    from dataclasses import replace

    from compgen.controllers.programs import measure_program
    from compgen.model.paths import generate
    m = load_machine(SEED_MACHINE)
    ctl = controller(m.controller)
    text = measure_program(m, generate(m, ["K4"]), "K4", m.controller, "tcpm", "K4", "0", "d").files[".H"]
    closest = motion.run(m, ctl.blocks(text)).closest_mm
    for margin, near in ((closest + 1, True), (closest - 1, False)):
        found = motion.run(replace(m, setup=replace(m.setup, margin=margin)), ctl.blocks(text)).findings
        hits = [f for f in found if f"(margin {margin:g} mm)" in f.rule]
        assert bool(hits) == near, (margin, [f.rule for f in found][:3])
    found = motion.run(replace(m, setup=replace(m.setup, margin=closest + 1)), ctl.blocks(text)).findings
    assert any(f"within {closest:.1f} mm of the ball (margin" in f.rule for f in found)


def test_a_ball_the_path_cannot_reach_is_the_users_set_up_not_an_internal_error(tmp_path):
    code, out, err = run("measure-program", "--machine", BC_MACHINE, "--path", "K1", "--ball", "0,0,20",
                         "-o", tmp_path / "K1.MPF")
    assert code == 2 and "internal" not in err and err.count("\n") == 1, (code, err)
    assert "the machine cannot run K1 with the ball at 0, 0, 20 mm" in err and "Put the ball higher" in err
    assert not (tmp_path / "K1.MPF").exists()


@pytest.mark.parametrize("path, back", [("K2", False), ("K4", False), ("K2", True)])
def test_no_sinumerik_program_turns_a_modulo_axis_the_long_way(path, back):
    """The B/C table's C is a 360° modulo axis (MD30310): K2 ends at C360, which a plain C360
    after C357 would reach by turning −357° (MD30455 default). compgen writes each pose's way
    (ACP/ACN) and turns at the safe height the short way (DC): no block turns C more than
    half a turn, and the pose blocks turn it as the path goes."""
    from compgen.controllers.programs import measure_program
    from compgen.model.paths import generate
    m = load_machine(BC_MACHINE)
    ctl = controller("sinumerik840d")
    assert ctl.modulo_axes(m) == ("C",)
    poses = generate(m, [path], back=back)
    text = measure_program(m, poses, path, "sinumerik840d", "tcpm", path, "0", "d").files[".MPF"]
    assert not re.search(r"(?m)\bC3\d\d\.\d+ .*; pose", text) and "C=ACP(" in text
    c, turns = np.nan, []
    for b in ctl.blocks(text):
        if b.kind == "move" and "C" in b.target:
            end = motion._turned(("C",), b, "C", b.target["C"], c)
            turns.append((end - c, "; pose" in b.text))
            c = end
    assert max(abs(t) for t, _ in turns if np.isfinite(t)) <= 180
    at_poses = [t for t, pose in turns if pose and t]
    planned = np.diff(np.degrees(poses.q[:, m.index("C")]))
    np.testing.assert_allclose(at_poses, planned[planned != 0], atol=1e-3)
    assert motion.run(m, ctl.blocks(text), ctl.modulo_axes(m)).findings == ()


def test_a_plain_position_on_a_modulo_axis_is_refused_not_guessed():
    m = load_machine(BC_MACHINE)
    ctl = controller("sinumerik840d")
    text = ("G17 G90 G71 G94\nT=\"RTEST\"\nM6\nD1\nG54\nG0 Z286\nG0 B0 C=DC(357)\nG0 X100 Y40 Z286 B0 C357\n"
            "G0 X100 Y40 Z286 B0 C360\nM30\n")
    with pytest.raises(CompgenError, match=r"line 9: .*C is a 360° modulo axis.*ACP, ACN or DC"):
        motion.run(m, ctl.blocks(text), ctl.modulo_axes(m))
    seed = load_machine(SEED_MACHINE)           # C with limits: plain positions, as ever
    assert controller("sinumerik840d").modulo_axes(seed) == ()


def test_a_sinumerik_machine_must_say_whether_its_turning_axes_are_modulo(tmp_path):
    text = BC_MACHINE.read_text()
    (tmp_path / "m.toml").write_text(re.sub(r"(?m)^modulo = .*$", "", text))
    code, _, err = run("measure-program", "--machine", tmp_path / "m.toml", "--path", "K2", "-o",
                       tmp_path / "K2.MPF")
    assert code == 2 and "[sinumerik] modulo" in err and 'modulo = ["C"]' in err


@pytest.mark.parametrize("form", ["FUNCTION TCPM F TCP AXIS POS PATHCTRL AXIS",
                                  "FUNCTION TCPM F CONT AXIS SPAT PATHCTRL AXIS"])
def test_heidenhain_tcpm_forms_the_check_does_not_model_are_refused(tmp_path, form):
    """compgen writes F CONT AXIS POS: a pose block only turns the table, where F TCP's feed
    (the tool point's speed relative to the workpiece) is zero; AXIS SPAT reads rotary words
    as spatial angles. Either, edited in, is refused with its line, never simulated."""
    program = tmp_path / "K4.H"
    assert run("measure-program", "--machine", SEED_MACHINE, "--path", "K4", "-o", program)[0] == 0
    text = program.read_text()
    assert "FUNCTION TCPM F CONT AXIS POS PATHCTRL AXIS" in text
    program.write_text(text.replace("FUNCTION TCPM F CONT AXIS POS PATHCTRL AXIS", form))
    code, out, err = run("check-program", "--machine", SEED_MACHINE, program)
    assert code == 2 and f"{form!r}: only" in err and "not modelled" not in out, (code, out, err)


# the control's state guard (heidenhain_guard) after the program's first two lines: the
# blocks below it are GUARDED file lines further down
GUARD = "".join(f"1 {b}\n" for b in heidenhain_guard())
GUARDED = len(heidenhain_guard())
PROGRAM_TIMED = """0 BEGIN PGM T MM
1 FUNCTION RESET TCPM
""" + GUARD + """2 TOOL CALL 99 Z S0
3 L Z+378.0000 R0 FMAX
4 L X+0.0000 Y+0.0000 A+0.0000 C+0.0000 R0 FMAX
5 L C+30.0000 R0 F1000
6 L X+60.0000 R0 F600
7 CYCL DEF 9.0 DWELL TIME
8 CYCL DEF 9.1 DWELL 2
9 L X+60.0000 R0 FMAX
10 L X-0.5000 R0 FMAX
11 END PGM T MM
"""


def test_the_check_adds_the_programs_time_and_names_its_closest_approach():
    """A hand-written program on the seed machine: from unknown places (no time), a turn of
    30° at 1000 °/min (1.8 s), 60 mm at 600 mm/min (6 s), a 2 s dwell, a rapid that does not
    move (0 s), then a rapid back to X−0.5 at X's feed_max. The closest approach is named by
    its pair and line, and a finding's position is every axis's, mm and deg."""
    m = load_machine(SEED_MACHINE)
    ctl = controller("itnc530")
    text = PROGRAM_TIMED
    check = ctl.check(m, ctl.blocks(text, None))
    assert check.findings == () and check.blocks == 6
    back = 60.5 / m.axis("X").feed_max * 60.0
    assert check.seconds == pytest.approx(1.8 + 6.0 + 2.0 + back, abs=1e-9)
    assert re.fullmatch(r"(housing|spindle) / (ball|stem|table), line (\d+)", check.closest_at) and \
        int(check.closest_at.rsplit(" ", 1)[1]) - GUARDED in (6, 7, 10, 11), \
        check.closest_at                                    # the lines of the file, counted from 1
    # outside travel: the finding names the position of every axis, mm and deg
    far = ctl.check(m, ctl.blocks(text.replace("X+60.0000 R0 F600", "X+999.0000 R0 F600"), None))
    out = next(f for f in far.findings if f.rule == "outside travel")
    assert out.line == 7 + GUARDED and out.depth_mm == 0.0
    assert re.fullmatch(r"X\+\d+\.\d{3} Y\+0\.000 Z\+378\.000 A\+0\.000 C\+30\.000", out.axes), out.axes
    assert float(out.axes.split()[0][1:]) > m.axis("X").travel[1]
    # no depth: not a collision
    assert out.text("T.H").startswith(f"T.H:{7 + GUARDED}: outside travel: X reaches ")
    # a feed move at exactly X's feed_max is within it; 1 % above it is not, and the finding
    # stands at the move's end
    top = m.axis("X").feed_max
    for feed, refused in ((top, False), (top * 1.01, True)):
        fast = ctl.check(m, ctl.blocks(text.replace("X+60.0000 R0 F600", f"X+60.0000 R0 F{feed:g}"), None))
        over = [f for f in fast.findings if f.rule == "feed above feed_max"]
        assert len(over) == refused, feed
        assert not over or over[0].axes == "X+60.000 Y+0.000 Z+378.000 A+0.000 C+30.000"
    # A to the end of its travel, exactly, is within it
    to_end = f"5 L A{m.axis('A').travel[0]:+.4f} C+30.0000 R0 F1000"
    end = ctl.check(m, ctl.blocks(text.replace("5 L C+30.0000 R0 F1000", to_end), None))
    assert not any(f.rule == "outside travel" for f in end.findings), end.findings
    # a feed block that goes nowhere takes no time
    still = ctl.check(m, ctl.blocks(text.replace("9 L X+60.0000 R0 FMAX", "9 L X+60.0000 R0 F600"), None))
    assert still.seconds == pytest.approx(check.seconds, abs=1e-9)
    # X 1.5 times its feed_max and C twice its own in one move: the finding names C, the
    # axis furthest over its limit
    fast_both = text.replace("X+60.0000 R0 F600", "X+100.0000 C+102.0000 R0 F30000")
    both = ctl.check(m, ctl.blocks(fast_both, None))
    over = [f for f in both.findings if f.rule == "feed above feed_max"]
    assert len(over) == 1 and over[0].detail.startswith("C would move at 21600 deg/min"), over


def test_address_words_are_read_once_each_and_a_feed_above_zero_is_a_feed():
    from compgen.errors import CompgenError
    from compgen.motion.blocks import words
    assert words(["X+1.5", "A-90", "F0.5"], 3) == {"X": 1.5, "A": -90.0, "F": 0.5}
    for bad in (["X+1", "X+2"], ["F0"], ["F-500"], ["Q7"]):
        with pytest.raises(CompgenError, match="line 3: "):
            words(bad, 3)
    long = "X+1" + "0" * 100
    with pytest.raises(CompgenError) as e:
        words([long], 3)
    assert f"{long[:60]}...'" in str(e.value) and long[:61] not in str(e.value)


@pytest.mark.parametrize("how, now, value, end", [
    ("+", 90.0, 90.0 - 1e-9, 90.0),        # where it is, to rounding: no turn either way
    ("-", 90.0, 90.0 + 1e-9, 90.0),
    ("short", 90.0, 450.0, 90.0),
    ("+", 350.0, 10.0, 370.0),             # + turns up through 360
    ("-", 10.0, 350.0, -10.0),             # - turns down through 0
    ("-", 10.0, 20.0, -340.0),
    ("short", 350.0, 10.0, 370.0),         # the shorter way: 20° up, not 340° down
    ("short", 10.0, 200.0, -160.0),        # 190° ahead: 170° back
    ("short", 10.0, 190.0, 190.0),         # exactly 180° ahead: ahead
    ("+", np.nan, 400.0, 40.0),            # from an unknown place: to the value, modulo 360
])
def test_a_modulo_axis_turns_the_way_its_block_says(how, now, value, end):
    from compgen.motion.blocks import Block
    from compgen.motion.check import _turned
    b = Block(4, "C", "move", turn={"C": how})
    assert _turned(("C",), b, "C", value, now) == pytest.approx(end, abs=1e-6)
    assert _turned((), Block(4, "C", "move"), "C", value, now) == value       # not modulo: as written


def test_every_move_is_sampled_at_least_every_mm_and_half_degree_end_to_end():
    """``_paths`` on moves in machine axes and under TCP: n + 1 samples, n the
    larger of the millimetres and the half-degrees moved (rounded up), from start to end;
    TCP moves in TCP coordinates, each converted to its own machine poses."""
    from compgen.model.frames import from_world
    from compgen.motion.check import _paths, _Segment
    m = load_machine(SEED_MACHINE)
    linear = [m.index(c) for c in "XYZ"]
    rotary = [m.index(a.name) for a in m.rotary_axes]
    b = motion.Block(1, "L", "move")
    q0 = np.array([10.0, 20.0, 300.0, 0.0, 0.0])
    q1 = q0 + [10.3, 0.0, 0.0, 0.0, np.radians(3.2)]            # 10.3 mm, 6.4 half-degrees: 11 steps
    q2 = q1 + [0.0, 0.0, 0.0, np.radians(-7.3), 0.0]              # 14.6 half-degrees: 15 steps
    w0 = np.array([5.0, -5.0, 250.0, 0.0, 0.0])
    w1 = w0 + [2.0, 0.0, -1.0, np.radians(-4.2), np.radians(1.0)]   # 8.4 half-degrees: 9 steps
    w2 = w1 + [0.0, 3.7, 0.0, 0.0, 0.0]                           # 3.7 mm: 4 steps
    segs = [_Segment(b, False, q0, q1, False), _Segment(b, True, w0, w1, False),
            _Segment(b, False, q1, q2, False), _Segment(b, True, w1, w2, False),
            _Segment(b, False, q2, q2, False)]                       # no move: still one step
    _paths(m, segs, linear, rotary)
    for seg, n in zip(segs, (11, 9, 15, 4, 1), strict=True):
        assert len(seg.path) == n + 1
    np.testing.assert_allclose(segs[0].path, q0 + np.linspace(0, 1, 12)[:, None] * (q1 - q0), atol=1e-12)
    np.testing.assert_allclose(segs[2].path[[0, -1]], [q1, q2], atol=1e-12)
    for seg, (a, e) in ((segs[1], (w0, w1)), (segs[3], (w1, w2))):
        tcp = a + np.linspace(0, 1, len(seg.path))[:, None] * (e - a)
        np.testing.assert_allclose(seg.path, from_world(m, tcp[:, :3], tcp[:, 3:]), atol=1e-9)


def test_a_finding_says_how_deep_a_part_enters_and_only_then():
    from compgen.motion.check import Finding
    assert Finding(5, "housing enters the table", "L X+1", "X+1.000", 0.4).text("P.H") == \
        "P.H:5: housing enters the table by 0.4 mm: L X+1 (at X+1.000)"
    assert Finding(5, "outside travel", "X reaches 999", "X+999.000").text("P.H") == \
        "P.H:5: outside travel: X reaches 999 (at X+999.000)"


@pytest.mark.parametrize("length", [0.0, 0.3, 0.9, 12.0])
def test_segment_distance_in_closed_form_for_parts_of_any_length(length):
    """``_to_segment`` against a brute force for a part (a segment along random axes) of the
    given length, to a point and to a segment, including parallel ones."""
    from compgen.motion.check import _to_segment
    rng = np.random.default_rng(int(length * 10))
    n = 100
    p0 = rng.uniform(-20, 20, (n, 3))
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    axis[:10] = [0.0, 0.0, 1.0]                              # parallel to the segment below
    p1 = p0 + length * axis
    t = np.linspace(0, 1, 201)
    on_p = p0[:, None, :] + t[None, :, None] * (p1 - p0)[:, None, :]
    for q0, q1 in ((np.array([1.0, 2.0, 3.0]),) * 2, (np.array([0.0, 0.0, -5.0]), np.array([0.0, 0.0, 9.0]))):
        on_q = q0 + t[:, None] * (q1 - q0)
        brute = np.linalg.norm(on_p[:, :, None, :] - on_q[None, None, :, :], axis=3).min(axis=(1, 2))
        got = _to_segment(p0, p1, q0, q1)
        assert np.isfinite(got).all()
        # the brute force samples each segment every 1/200 of it: within that of the least
        np.testing.assert_allclose(got, brute, atol=(length + 14) / 200)
        assert (got <= brute + 1e-12).all()


def test_a_check_tells_its_first_finding_and_how_many_more():
    from compgen.motion.check import Check, Finding
    one = Finding(3, "outside travel", "X reaches 999", "X+999.000")
    assert Check(1, 0.0, 1.0, "", (one,)).first("P.H") == one.text("P.H")
    assert Check(1, 0.0, 1.0, "", (one, one, one)).first("P.H") == one.text("P.H") + " (and 2 more)"


def test_a_part_near_a_solid_is_within_the_margin_not_inside_it():
    """The nest lowered over the table's centre until its housing is 0.5 mm above the face:
    a finding "within 0.5 mm of the table (margin …)", no depth; 0.5 mm lower it enters.
    (The moves after it stay down there: their findings are not this test's.)"""
    from compgen.motion.check import clearances
    m = load_machine(SEED_MACHINE)
    ctl = controller("itnc530")
    q = np.zeros((1, len(m.axes)))
    q[0, m.index("Z")] = 100.0
    gap = clearances(m, q)[0]["housing / table"][0]
    for above, expected in ((0.5, "housing within 0.5 mm of the table (margin 5 mm)"),
                            (-0.5, "housing enters the table")):
        z = 100.0 - gap + above
        text = PROGRAM_TIMED.replace("6 L X+60.0000 R0 F600", f"6 L Z{z:+.4f} R0 F600")
        found = [f for f in ctl.check(m, ctl.blocks(text, None)).findings
                 if "table" in f.rule and f.line == 7 + GUARDED]         # the block that goes down
        assert [f.rule for f in found] == [expected]
        assert found[0].depth_mm == pytest.approx(max(-above, 0.0), abs=0.02)
        assert (" by " in found[0].text("T.H")) == (above < 0)


def test_where_rounding_ends_and_a_limit_begins():
    """The tolerances that tell rounding from a real excess, each pinned at 1.5 times itself
    (a doubled tolerance would pass it) and at half of itself: a modulo target 1.5e-6° from
    where C stands is a turn (0.5e-6°: where it is); 1.5e-9 mm past either end of travel is
    outside (the end itself is in); 1.5e-9 mm of X Y Z travel is a move (1e-9: only turns,
    F in deg/min); a speed 1.5e-9 of itself over feed_max is over it."""
    from compgen.motion.blocks import Block
    from compgen.motion.check import _per_segment, _Segment, _turned, feed_minutes
    b = Block(4, "C", "move", turn={"C": "+"})
    assert _turned(("C",), b, "C", 90.0 + 1.5e-6, 90.0) == pytest.approx(90.0 + 1.5e-6, abs=1e-12)
    assert _turned(("C",), b, "C", 90.0 + 0.5e-6, 90.0) == 90.0
    m = load_machine(SEED_MACHINE)
    x = m.index("X")
    lo, hi = m.axis("X").travel
    seg = _Segment(Block(1, "L", "move"), False, np.zeros(5), np.zeros(5), False)
    seg.path = np.zeros((5, 5))
    seg.path[:, m.index("Z")] = 300.0
    seg.path[:, x] = [lo, hi, lo - 1.5e-9, hi + 1.5e-9, hi + 0.5e-9]
    out = _per_segment(m, [seg])[2][0][:, x]
    assert out.tolist() == [False, False, True, True, False]
    assert feed_minutes(1.5e-9, 3.0, 15.0) == pytest.approx(1e-10)       # a move: 1.5e-9 mm at F15
    assert feed_minutes(1.0e-9, 3.0, 15.0) == pytest.approx(0.2)         # only turns: 3° at F15
    findings = []
    limits = np.array([a.feed_max for a in m.axes])
    move = _Segment(Block(2, "L", "move", feed=1.0), False, np.zeros(5), np.zeros(5), False)
    move.path = np.zeros((2, 5))
    move.path[1, x] = 1.0                      # 1 mm at F1: a minute, one step
    linear, rotary = [m.index(c) for c in "XYZ"], [m.index(a.name) for a in m.rotary_axes]
    took = motion._seconds(m, [move], np.zeros((1, 5)), limits[None] * (1 + 1.5e-9), linear, rotary,
                           findings)
    assert took == [60.0]
    assert [f.rule for f in findings] == ["feed above feed_max"]
    motion._seconds(m, [move], np.zeros((1, 5)), limits[None] * (1 + 0.5e-9), linear, rotary, findings)
    assert len(findings) == 1


@pytest.mark.parametrize("depth_um, enters", [(1.5, True), (0.5, False)])
def test_a_probing_tip_may_touch_the_sphere_to_a_micrometre_not_enter_it(depth_um, enters):
    """While probing, the stylus tip touches the sphere: 0.5 µm inside is the touch (its
    rounding), 1.5 µm inside enters it (TOUCH_MM, 1 µm; pinned at half and 1.5 times)."""
    from compgen.data.probe import probe_poses
    from compgen.motion.blocks import Block
    from compgen.motion.check import _check_collisions, _Segment
    m = load_machine(SEED_MACHINE)
    q = np.array(probe_poses(m, ["K4"]).q[0])                # the stylus tip at the sphere's centre
    reach = (m.probe.sphere_diameter + m.probe.stylus_diameter) / 2
    q[m.index("Z")] += reach - depth_um * 1e-3
    tip = motion.clearances(m, q[None], m.probe)[0]["stylus tip / ball"][0]
    assert tip == pytest.approx(-depth_um * 1e-3)
    seg = _Segment(Block(7, "TCH PROBE", "move"), False, q, q, False, probing=True)
    seg.path = np.array([q, q])
    findings = []
    _check_collisions(m, [seg], findings, m.probe)
    assert ["stylus tip enters the ball" in f.rule for f in findings].count(True) == int(enters), findings


def test_the_searched_table_clearance_is_the_least_to_a_micrometre_and_a_half():
    """The golden-section search along housing and spindle (step ``SEARCH_MM``) against a
    brute force in two stages (every 0.05 mm, then every 0.2 µm within 0.1 mm of the least:
    the signed distance from the convex table is convex along the axis): within 1.5 µm at 60
    random poses, many reaching into the table, where the distance has corners (the search
    leaves 1.33 µm at these poses, 1.6–2.1 µm with a step twice as long)."""
    m = load_machine(SEED_MACHINE)
    s = m.setup
    n = 60
    q = _around_the_set_up(m, np.random.default_rng(6), n)
    got, _ = clearances(m, q)
    _, nest, axis = frames(m, q)
    top, bottom = s.table_top, s.table_top - s.table_thickness

    def table(t):                                  # (n, k) signed distance of nest + t·axis
        pts = nest[:, None, :] + t[..., None] * axis[:, None, :]
        radial, z = np.hypot(pts[..., 0], pts[..., 1]), pts[..., 2]
        rim = s.table_radius - radial
        outside = np.hypot(np.maximum(np.maximum(z - top, bottom - z), 0), np.maximum(-rim, 0))
        return np.where(outside > 0, outside, -np.minimum(np.minimum(top - z, z - bottom), rim))
    for part, (lo, hi, radius) in {"housing": (-s.nest_below, m.probe_length, s.nest_radius),
                                   "spindle": (m.probe_length, m.probe_length + s.spindle_length,
                                               s.spindle_radius)}.items():
        steps = int((hi - lo) / 0.05) + 1
        coarse = np.broadcast_to(np.linspace(lo, hi, steps), (n, steps))
        near = coarse[np.arange(n), np.argmin(table(coarse), axis=1)]
        fine = np.clip(near[:, None] + np.linspace(-0.1, 0.1, 1001)[None, :], lo, hi)
        least = table(fine).min(axis=1) - radius
        assert (least < 0).sum() > 20                      # many reach into the table
        np.testing.assert_allclose(got[f"{part} / table"], least, atol=1.5e-3)


def test_the_set_ups_documented_defaults_are_the_ones_a_machine_file_without_them_gets(tmp_path):
    """docs/controllers.md gives each [rtest] size's default in brackets; a machine file
    that names only the ball and the probe length is read with exactly those (the table's
    radius: the ball's distance from the axis + 50 mm)."""
    doc = (ROOT / "docs" / "controllers.md").read_text(encoding="utf-8")
    said = doc[doc.index("**The set-up**"):]
    said = said[:said.index("\n\n")]
    documented = {k: float(v) for k, v in re.findall(r"`(\w+)`(?:\s+\([^)]*\))?\s+\[(-?[\d.]+)\]", said)}
    assert set(documented) == {"ball_diameter", "stem_diameter", "table_top", "table_thickness",
                               "nest_radius", "nest_below", "spindle_radius", "spindle_length",
                               "nest_range", "margin"}
    text = SEED_MACHINE.read_text()
    start = text.index("[rtest]")
    end = text.index("\n[", start + 1)
    bare = tmp_path / "bare.toml"
    bare.write_text(text[:start] + "[rtest]\nball = [-217.504, -0.279, 211.537]\nprobe_length = 184.670\n"
                    + text[end:])
    s = load_machine(bare).setup
    assert {k: getattr(s, k) for k in documented} == documented
    assert s.table_radius == pytest.approx(np.hypot(217.504, 0.279) + 50, abs=1e-9)


def test_every_move_is_sampled_as_its_own_straight_line():
    """``_paths`` samples all moves at once: each move's samples are np.linspace's fractions
    of it (≤ 1 mm and ≤ 0.5° apart, its ends exact), an axis not yet positioned goes straight
    to its target, and a TCP move is sampled in TCP coordinates, then converted."""
    from compgen.model.frames import from_world, world
    from compgen.motion.blocks import Block
    from compgen.motion.check import _paths, _Segment
    m = load_machine(SEED_MACHINE)
    linear = [m.index(c) for c in "XYZ"]
    rotary = [m.index(a.name) for a in m.rotary_axes]
    k = len(m.axes)
    q0 = np.zeros(k)
    q0[linear[2]] = 300.0
    q1 = q0.copy()
    q1[linear[0]] = 48.3                     # 48.3 mm: 49 steps (49 × (1/49) is not 1: the end is)
    q2 = q1.copy()
    q2[rotary[0]] = np.radians(1.2)          # 1.2°: three steps
    blind = np.full(k, np.nan)
    blind[linear[2]] = 300.0                 # only Z known: the others go straight to q1's
    w0 = np.concatenate([world(m, q2[None])[0], q2[rotary]])
    w1 = w0 + np.r_[0.0, 0.0, -0.4, np.zeros(len(rotary))]     # 0.4 mm down under TCP: one step
    segs = [_Segment(Block(1, "a", "move"), False, q0, q1, False),
            _Segment(Block(2, "b", "move"), True, w0, w1, False),
            _Segment(Block(3, "c", "move"), False, q1, q2, False),
            _Segment(Block(4, "d", "move"), False, blind, q1, True)]
    _paths(m, segs, linear, rotary)
    f = np.linspace(0, 1, 50)[:, None]
    assert np.array_equal(segs[0].path, q0 + f * (q1 - q0)) and segs[0].path[-1, linear[0]] == 48.3
    f = np.linspace(0, 1, 4)[:, None]
    assert np.array_equal(segs[2].path, q1 + f * (q2 - q1))
    tcp = w0 + np.linspace(0, 1, 2)[:, None] * (w1 - w0)
    assert np.array_equal(segs[1].path, from_world(m, tcp[:, :3], tcp[:, 3:]))
    assert np.array_equal(segs[3].path, np.tile(q1, (2, 1)))     # Z stays; the rest: q1 at once
