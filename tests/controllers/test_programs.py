"""Measurement programs: golden files, round trip, independent checks, refusals."""

import re
from io import StringIO

import numpy as np
import pytest
from conftest import ROOT, SEED_MACHINE, run, vector

from compgen.controllers.programs import measure_program, read_program
from compgen.controllers.registry import CONTROLLERS
from compgen.data.rtest import read_rtest
from compgen.errors import CompgenError
from compgen.model.kinematics import Model
from compgen.model.paths import generate
from compgen.model.poses import Poses

FORMAT_MM = 5.01e-5      # four decimals in the program
FORMAT_DEG = 5.01e-5
DATE = "2026-11-24"


def _short(machine):
    """Five poses of K4 and three of K1: small enough to review a golden file by eye."""
    poses = generate(machine, ["K4", "K1"])
    return poses.take(np.r_[0:5, 241:244])


@pytest.mark.parametrize("controller", CONTROLLERS)
@pytest.mark.parametrize("mode", ["tcpm", "axes"])
def test_programs_match_golden_files(seed_machine, controller, mode, golden):
    emitted = measure_program(seed_machine, _short(seed_machine), "K4+K1", controller, mode,
                              "RTEST_GOLDEN", "0.1.0", DATE)
    for suffix, text in emitted.files.items():
        golden(f"ac-trunnion-itnc530/{controller}/rtest-{mode}{suffix}", text)


@pytest.mark.parametrize("controller", CONTROLLERS)
@pytest.mark.parametrize("mode", ["tcpm", "axes"])
def test_round_trip_gives_the_same_poses(seed_machine, controller, mode):
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    emitted = measure_program(seed_machine, poses, "all", controller, mode, "RT", "0.1.0", DATE)
    text = emitted.files[CONTROLLERS[controller].program_ext]
    text.encode("ascii")
    got_mode, xyz, rot = read_program(text, seed_machine, controller)
    assert got_mode == mode and len(xyz) == len(poses)
    np.testing.assert_allclose(rot, np.degrees(poses.q[:, 3:]), atol=FORMAT_DEG)
    listed = np.loadtxt(StringIO(emitted.files[".poses.csv"]), delimiter=",", skiprows=1,
                        usecols=(1, 2, 3, 4, 5))
    np.testing.assert_allclose(rot, listed[:, 3:], atol=1e-9)     # the list holds what is commanded
    if mode == "axes":
        np.testing.assert_allclose(xyz, listed[:, :3], atol=FORMAT_MM)


def test_tcpm_k4_holds_the_ball_centre_fixed_in_workpiece_coordinates(seed_machine):
    """Contract §2: the ball sits at Rx(A)·((0, 0, Zc) + Rz(C)·b); at A = C = 0 that is
    b + (0, 0, Zc), whatever the pose. Every TCPM block must program exactly that point."""
    poses = generate(seed_machine, ["K4"])
    text = emitted_program(seed_machine, poses)
    _, xyz, rot = read_program(text, seed_machine, "itnc530")
    b, zc = np.array(seed_machine.ball), seed_machine.axis("C").offset[2]
    np.testing.assert_allclose(xyz, np.broadcast_to(b + [0, 0, zc], xyz.shape), atol=FORMAT_MM)
    # the pose list holds the machine axes the control must reach at the programmed angles:
    # there the contract's formula puts the ball where the nest is
    listed = np.loadtxt(StringIO(emitted_list(seed_machine, poses)), delimiter=",", skiprows=1,
                        usecols=(1, 2, 3, 4, 5))
    np.testing.assert_allclose(listed[:, 3:], rot, atol=1e-9)
    A, C = np.radians(rot[:, 0]), np.radians(rot[:, 1])
    s = b[0] * np.sin(C) + b[1] * np.cos(C)
    ball = np.column_stack([b[0] * np.cos(C) - b[1] * np.sin(C),
                            np.cos(A) * s - np.sin(A) * (zc + b[2]),
                            np.sin(A) * s + np.cos(A) * (zc + b[2])])
    np.testing.assert_allclose(ball, listed[:, :3], atol=1e-6)   # 6 decimals in the pose list


def emitted_program(machine, poses):
    return measure_program(machine, poses, "K4", "itnc530", "tcpm", "K4", "0.1.0", DATE).files[".H"]


def emitted_list(machine, poses):
    emitted = measure_program(machine, poses, "K4", "itnc530", "tcpm", "K4", "0.1.0", DATE)
    return emitted.files[".poses.csv"]


def test_axes_program_equals_the_shared_vectors_poses(seed_machine):
    """The K4 axes-mode program against X Y Z from the independent simulator (4 decimals)."""
    data = read_rtest(vector("seed-table4-noiseless.csv"), seed_machine)
    k4 = data.poses.path == "K4"
    poses = generate(seed_machine, ["K4"])
    emitted = measure_program(seed_machine, poses, "K4", "sinumerik840d", "axes", "K4", "0.1.0", DATE)
    text = emitted.files[".MPF"]
    _, xyz, rot = read_program(text, seed_machine, "sinumerik840d")
    # the vectors hold X Y Z of the exact angles, the program of the angles as written:
    # they differ by up to lever × angle rounding, plus both roundings of X Y Z
    lever_mm = np.linalg.norm(np.array(seed_machine.ball) + [0, 0, 29.794])
    atol = lever_mm * np.radians(FORMAT_DEG) + 2 * FORMAT_MM
    np.testing.assert_allclose(xyz, data.poses.q[k4, :3], atol=atol)
    np.testing.assert_allclose(rot, np.degrees(data.poses.q[k4, 3:]), atol=2 * FORMAT_DEG)
    # and, at the angles as written, they put the nest on the ball to the X Y Z rounding
    back = Poses(np.column_stack([xyz, np.radians(rot)]), poses.ball, poses.t, poses.path)
    assert np.abs(Model(seed_machine, ()).relative(back)).max() < FORMAT_MM




def test_cli_writes_program_and_pose_list(tmp_path):
    out = tmp_path / "K4.H"
    code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--path", "BK4", "-o", out)
    assert code == 0, err
    assert out.read_text().startswith("0 BEGIN PGM K4 MM")
    poses = (tmp_path / "K4.poses.csv").read_text().splitlines()
    assert poses[0] == "path,X,Y,Z,A,C,bx,by,bz,A_side,C_side" and len(poses) == 242


def _poses_file(tmp_path, rows):
    path = tmp_path / "p.csv"
    path.write_text("path,A,C\n" + "".join(f"P,{a},{c}\n" for a, c in rows))
    return path


@pytest.mark.parametrize("rows, expected", [
    ([(0, 0), (-130, 0)], "p.csv:3: this pose puts A at -130.000 deg, outside its travel"),
    ([(0, 0), (0, 45)], "C jumps 45.00 deg between poses 1 and 2"),
])
def test_unsafe_pose_lists_are_refused(tmp_path, rows, expected):
    out = tmp_path / "x.H"
    code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--poses",
                       _poses_file(tmp_path, rows), "-o", out)
    assert code == 2 and expected in err and err.count("\n") == 1, err
    assert not out.exists() and not (tmp_path / "X.poses.csv").exists()


def test_refusals(tmp_path):
    out = tmp_path / "K4.H"
    assert run("measure-program", "--machine", SEED_MACHINE, "--path", "K4", "--controller",
               "fanuc", "-o", out)[0] == 2
    code, _, err = run("measure-program", "--machine", SEED_MACHINE, "-o", out)
    assert code == 2 and "either --path or --poses" in err
    (tmp_path / "K4.poses.csv").write_text("mine")
    code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--path", "K4", "-o", out)
    assert code == 2 and "--force" in err and not out.exists()     # nothing half-written
    assert (tmp_path / "K4.poses.csv").read_text() == "mine"
    bare = tmp_path / "m.toml"
    bare.write_text(SEED_MACHINE.read_text().split("[program]")[0])
    code, _, err = run("measure-program", "--machine", bare, "--path", "K4", "-o", out)
    assert code == 2 and "no [program] section" in err


@pytest.mark.parametrize("controller, stop", [("itnc530", r"^\d+ STOP\b"), ("sinumerik840d", r"^M0$"),
                                              ("linuxcnc", r"^M0$")])
def test_every_program_stops_once_for_the_preset_check_before_the_nest_goes_down(seed_machine, controller,
                                                                                 stop):
    """The programs trust the active preset: once, with the nest at its clearance above the
    ball, the program stops with a message, before the first move onto the ball."""
    poses = generate(seed_machine, ["K4", "K2"])
    ext = {"itnc530": ".H", "sinumerik840d": ".MPF", "linuxcnc": ".ngc"}[controller]
    text = measure_program(seed_machine, poses, "K4", controller, "tcpm", "K4", "0", DATE).files[ext]
    lines = text.splitlines()
    # a state guard's stop ends the program (M30 follows it): it is not the preset check
    stops = [i for i, ln in enumerate(lines) if re.search(stop, ln) and lines[i + 1:i + 2] != ["M30"]]
    onto = [i for i, ln in enumerate(lines) if "nest onto the ball" in ln]
    assert len(stops) == 1 and stops[0] < onto[0], (stops, onto[:2])
    assert "PRESET CHECK: the nest is 20 mm above the ball centre" in "\n".join(lines[stops[0] - 2:stops[0]])


def _sides_as_run(machine, controller, text, mode):
    """Each rotary axis's direction of its last turn at every pose (a dwell follows each),
    from the program as the control reads it: its blocks, its modulo rule and its sense."""
    from compgen.motion import check as motion

    ctl = CONTROLLERS[controller]
    modulo, sense = ctl.modulo_axes(machine), ctl.angle_sense(machine)
    names = [a.name for a in machine.rotary_axes]
    now, last, out = dict.fromkeys(names, np.nan), dict.fromkeys(names, 0.0), []
    for b in ctl.blocks(text, mode):
        if b.kind == "dwell":
            out.append([last[n] for n in names])
        if b.kind != "move":
            continue
        for n in names:
            if n in b.target:
                end = motion._turned(modulo, b, n, b.target[n] * sense.get(n, 1), now[n])
                if not np.isnan(now[n]) and abs(end - now[n]) > 1e-9:
                    last[n] = float(np.sign(end - now[n]))
                now[n] = end
    return np.array(out)


@pytest.mark.parametrize("controller", CONTROLLERS)
@pytest.mark.parametrize("mode", ["tcpm", "axes"])
@pytest.mark.parametrize("which", ["seed", "bc"])
def test_the_pose_list_says_from_which_side_the_program_reaches_every_pose(controller, mode, which):
    """Backlash as the program runs it: each path's first pose approached from a declared
    side, each later one by the move that reached it. The pose list's A_side/C_side (B_side)
    are what the program's blocks do, read as the control executes them — paths that turn
    an axis one way, hold it, or run there and back."""
    from conftest import BC_MACHINE

    from compgen.configuration.machine_file import load_machine

    machine = load_machine(SEED_MACHINE if which == "seed" else BC_MACHINE)
    if which == "bc" and controller == "linuxcnc":
        pytest.skip("the B/C machine's nest is a tool by name, which LinuxCNC does not call")
    names = list(machine.paths)
    poses = Poses.concat([generate(machine, names[:1], back=True), generate(machine, names)])
    emitted = measure_program(machine, poses, "all", controller, mode, "RT", "0.1.0", DATE)
    text = emitted.files[CONTROLLERS[controller].program_ext]
    ran = _sides_as_run(machine, controller, text, mode)
    listed = np.loadtxt(StringIO(emitted.files[".poses.csv"]), delimiter=",", skiprows=1,
                        usecols=range(1 + len(machine.axes) + 3, 1 + len(machine.axes) + 3 + len(ran[0])))
    assert ran.shape == listed.shape == (len(poses), len(machine.rotary_axes))
    np.testing.assert_array_equal(ran, listed)
    assert {-1.0, 1.0} <= set(np.unique(listed[:, 0]))       # the there-and-back run shows both sides


def _two_poses(machine, dx_mm, dc_deg):
    """Two poses in machine axes: X moved by dx_mm and C turned by dc_deg between them."""
    q = np.zeros((2, len(machine.axes)))
    q[:, machine.index("Z")] = 200.0
    q[1, machine.index("X")] = dx_mm
    q[1, machine.index("C")] = np.radians(dc_deg)
    return Poses(q, np.tile(machine.ball, (2, 1)), np.full(2, np.nan), np.array(["P", "P"]))


def test_the_rotary_speed_at_the_programs_feed_is_checked_in_axes_mode(seed_machine):
    """Axes mode: F (mm/min) runs along X Y Z and a turn rides on it. 10 mm at 500 mm/min
    take 1.2 s, so 0.5° of C in them is 25 deg/min; with C's feed_max at 20 deg/min that is
    refused, named, with the number; under TCPM a pose block only turns, at F deg/min."""
    from dataclasses import replace

    from compgen.controllers.programs import _check_feed
    from compgen.errors import CompgenError
    slow = replace(seed_machine, workpiece=tuple(replace(a, feed_max=20.0) if a.name == "C" else a
                                                 for a in seed_machine.workpiece))
    with pytest.raises(CompgenError, match=r"^P: at feed 500 mm/min, C would turn at 25 deg/min between "
                                           r"poses 1 and 2, above its feed_max 20"):
        _check_feed(slow, _two_poses(slow, 10.0, 0.5), 500.0, "P", "axes")
    _check_feed(slow, _two_poses(slow, 10.0, 0.3), 500.0, "P", "axes")          # 15 deg/min: fine
    _check_feed(slow, _two_poses(slow, 10.0, 0.0), 500.0, "P", "axes")          # no turn
    _check_feed(slow, _two_poses(slow, 0.0, 0.0), 500.0, "P", "axes")           # no move at all
    with pytest.raises(CompgenError, match=r"deg/min where a TCPM pose block only turns\) exceeds C's"):
        _check_feed(slow, _two_poses(slow, 10.0, 0.5), 500.0, "P", "tcpm")
    _check_feed(slow, _two_poses(slow, 10.0, 0.5), 15.0, "P", "tcpm")


def test_a_pose_block_that_only_turns_runs_at_f_deg_per_min_in_both_checks(seed_machine):
    """Axes mode, C turning with X Y Z still: F is deg/min (the motion check's rule, one
    function for both); it was taken as an infinite speed by the program's feed check while
    the motion check passed the same block at F deg/min."""
    from dataclasses import replace

    from compgen.controllers.programs import _check_feed
    from compgen.errors import CompgenError
    from compgen.motion import check as motion
    slow = replace(seed_machine, workpiece=tuple(replace(a, feed_max=20.0) if a.name == "C" else a
                                                 for a in seed_machine.workpiece))
    _check_feed(slow, _two_poses(slow, 0.0, 0.5), 15.0, "P", "axes")            # 15 deg/min: fine
    with pytest.raises(CompgenError, match=r"^P: at feed 25 mm/min, C would turn at 25 deg/min"):
        _check_feed(slow, _two_poses(slow, 0.0, 0.5), 25.0, "P", "axes")
    _check_feed(slow, _two_poses(slow, 0.0, 0.5), 20.0, "P", "axes")            # at feed_max: not over it
    crawl = replace(slow, workpiece=tuple(replace(a, feed_max=0.5) if a.rotary else a
                                          for a in slow.workpiece))
    _check_feed(crawl, _two_poses(crawl, 10.0, 0.0), 500.0, "P", "axes")      # no turn: no speed at all
    only = motion.ONLY_TURNS_MM
    np.testing.assert_allclose(motion.feed_minutes(np.array([0.0, only, 2 * only, 10.0]), 3.0, 15.0),
                               [0.2, 0.2, 2 * only / 15.0, 10.0 / 15.0])


@pytest.mark.parametrize("text, room, expected", [
    ("a" * 24, 0, "A" * 24), ("7x-y", 0, "P7X_Y"), ("", 0, "RTEST"), ("a" * 19, 5, "A" * 19),
    ("a" * 25, 0, None), ("a" * 20, 5, None)])
def test_program_names_are_kept_whole_within_what_the_controls_keep(text, room, expected):
    from compgen.controllers.programs import program_name
    from compgen.errors import CompgenError
    args = (text,) if room == 0 else (text, room)       # room 0: as the default gives it
    if expected is None:
        with pytest.raises(CompgenError, match=f"the control keeps {24 - room}"):
            program_name(*args)
    else:
        assert program_name(*args) == expected


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_a_path_of_one_pose_is_a_program(seed_machine, controller):
    """A pose list whose paths hold one pose each (as the sign check's do)."""
    poses = generate(seed_machine, ["K4"]).take(np.array([10]))
    one = Poses(poses.q, poses.ball, poses.t, np.array(["ONE"]))
    emitted = measure_program(seed_machine, one, "ONE", controller, "tcpm", "RT1", "0.1.0", DATE)
    text = next(t for s, t in emitted.files.items() if s != ".poses.csv")
    assert "---- ONE: poses 1 to 1" in text
    assert emitted.files[".poses.csv"].count("\n") == 2


def test_a_safe_height_above_z_travel_is_refused_before_anything_is_written(seed_machine):
    """The set-up needs the nest 378 mm above the rotary axes to turn them; a Z travel that
    ends at 350 mm cannot give it (the poses, 20 mm above them too, are within it)."""
    from dataclasses import replace

    from compgen.errors import CompgenError
    short = replace(seed_machine, tool=tuple(replace(a, travel=(-300.0, 350.0)) if a.name == "Z" else a
                                             for a in seed_machine.tool))
    with pytest.raises(CompgenError, match=r"the safe height Z 378 above the rotary axes"):
        measure_program(short, generate(short, ["K4"]), "K4", "itnc530", "tcpm", "RT", "0.1.0", DATE)


def test_a_path_starting_at_the_end_of_travel_is_approached_from_inside(seed_machine):
    """A path that starts at A's lower travel limit and turns A up: the approach cannot come
    from 1° below, so it comes from 1° above, and the first pose's side is −1 (the second's
    +1, reached going up). The program's approach block and the pose list say the same."""
    from dataclasses import replace
    m = replace(seed_machine, workpiece=tuple(replace(a, travel=(-90.0, 120.0)) if a.name == "A" else a
                                              for a in seed_machine.workpiece))
    a = np.radians(np.arange(-90.0, -79.0, 1.0))
    q = np.zeros((len(a), len(m.axes)))
    q[:, m.index("A")] = a
    from compgen.model.kinematics import inverse
    q = inverse(m, q[:, [m.index(x.name) for x in m.rotary_axes]], np.asarray(m.ball))
    poses = Poses(q, np.tile(m.ball, (len(a), 1)), np.full(len(a), np.nan), np.array(["UP"] * len(a)))
    emitted = measure_program(m, poses, "UP", "itnc530", "tcpm", "RT", "0.1.0", DATE)
    rows = emitted.files[".poses.csv"].splitlines()
    column = rows[0].split(",").index("A_side")
    assert [r.split(",")[column] for r in rows[1:4]] == ["-1", "+1", "+1"]
    assert re.search(r"L A-89\.0000 C-1\.0000 R0 FMAX ; approach from 1 deg before", emitted.files[".H"])


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_a_path_run_again_later_is_run_where_the_pose_list_has_it(seed_machine, controller):
    """K4, K1 and K4 again: the program takes the poses in the pose list's order (the
    R-test's readings come in it), three segments, each with its own approach; before, the
    two runs of K4 were joined into one segment ahead of K1."""
    poses = generate(seed_machine, ["K4", "K1", "K4"])
    emitted = measure_program(seed_machine, poses, "K4+K1+K4", controller, "tcpm", "RT", "0.1.0", DATE)
    text = emitted.files[CONTROLLERS[controller].program_ext]
    assert len(re.findall(r"---- K4: poses", text)) == 2 and "---- K1: poses 242 to 602" in text
    _, _, rot = read_program(text, seed_machine, controller)
    np.testing.assert_allclose(rot, np.degrees(poses.q[:, [3, 4]]), atol=FORMAT_DEG)
    ran = _sides_as_run(seed_machine, controller, text, "tcpm")
    listed = np.loadtxt(StringIO(emitted.files[".poses.csv"]), delimiter=",", skiprows=1, usecols=(9, 10))
    np.testing.assert_array_equal(ran, listed)


def test_one_ball_per_program_to_the_pose_lists_resolution(seed_machine):
    """A program measures one ball: poses whose balls differ by 1.5e-7 mm (below the pose
    list's 6 decimals) are one ball; 1.5e-5 mm apart, two — refused, one program per ball."""
    from compgen.errors import CompgenError
    p = generate(seed_machine, ["K4"])

    def shifted(by):
        ball = np.array(p.ball, float)
        ball[1::2, 0] += by
        return Poses(p.q, ball, p.t, p.path, p.side)
    emitted = measure_program(seed_machine, shifted(1.5e-7), "K4", "itnc530", "tcpm", "K4", "0", DATE)
    assert "END PGM" in emitted.files[".H"]
    with pytest.raises(CompgenError, match="a program measures one ball position; these poses hold 2"):
        measure_program(seed_machine, shifted(1.5e-5), "K4", "itnc530", "tcpm", "K4", "0", DATE)


def test_heidenhain_calls_a_tool_by_name_in_quotes_and_refuses_a_bare_name(tmp_path):
    """TOOL CALL RTEST Z is rejected by the control: a name goes in double quotes; a number
    as it is. check-program refuses the bare name at its line."""
    text = SEED_MACHINE.read_text().replace('tool = "99"', 'tool = "RTEST"', 1)
    assert 'tool = "RTEST"' in text
    (tmp_path / "m.toml").write_text(text)
    out = tmp_path / "K4.H"
    code, _, err = run("measure-program", "--machine", tmp_path / "m.toml", "--path", "K4", "-o", out)
    assert code == 0, err
    program = out.read_text()
    assert re.search(r'(?m)^\d+ TOOL CALL "RTEST" Z S0 ', program)
    assert run("check-program", "--machine", tmp_path / "m.toml", out)[0] == 0
    bare = tmp_path / "BARE.H"
    bare.write_text(program.replace('TOOL CALL "RTEST"', "TOOL CALL RTEST"))
    code, _, err = run("check-program", "--machine", tmp_path / "m.toml", bare)
    line = 1 + next(k for k, ln in enumerate(program.splitlines()) if "TOOL CALL" in ln)
    assert code == 2 and f"BARE.H:{line}: " in err and "needs double quotes" in err, err
    assert re.search(r"(?m)^\d+ TOOL CALL 99 Z S0 ", (ROOT / "tests" / "golden" / "ac-trunnion-itnc530" /
                                                      "itnc530" / "rtest-tcpm.H").read_text())


def test_the_heidenhain_preset_check_is_a_message_the_control_shows(tmp_path):
    out = tmp_path / "k4.H"          # a lower-case stem: the program and its message file are K4
    code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--path", "K4", "-o", out)
    assert code == 0, err
    lines = out.read_text().splitlines()
    at = next(k for k, ln in enumerate(lines) if re.search(r"^\d+ STOP\b", ln))
    assert re.fullmatch(r"\d+ FN 16: F-PRINT TNC:\\K4_MSG\.A / SCREEN:", lines[at - 1])
    assert (tmp_path / "K4_MSG.A").read_text().startswith('"PRESET CHECK: the nest is 20 mm above the ball')


def test_a_program_read_back_must_be_one_compgen_wrote_whole(seed_machine):
    """The reader of emitted programs (the round trips' oracle) refuses a text with no pose
    block, a pose renumbered, and a mode compgen does not write."""
    text = emitted_program(seed_machine, generate(seed_machine, ["K2"]))
    with pytest.raises(CompgenError, match="no pose blocks found"):
        read_program("; nothing\n", seed_machine, "itnc530")
    edited = re.sub(r"(?m)^(\d+ L .*;.*?\bpose )2\b", r"\g<1>7", text, count=1)
    assert edited != text
    with pytest.raises(CompgenError, match=r"pose numbers are not 1, 2, 3, …: the program was edited"):
        read_program(edited, seed_machine, "itnc530")
    with pytest.raises(CompgenError, match="mode must be one of tcpm, axes, not 'tcp'"):
        measure_program(seed_machine, generate(seed_machine, ["K2"]), "K2", "itnc530", "tcp", "RT", "0", DATE)


def test_a_program_whose_header_names_two_nests_is_not_checked_with_either(tmp_path):
    """Two programs pasted into one file, written for nests of 150 and 160 mm: check-program
    cannot tell which length the motion is for, and says to give it."""
    for n, length in (("A", 150), ("B", 160)):
        code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--path", "K2", "--probe-length",
                           length, "-o", tmp_path / f"{n}.H")
        assert code == 0, err
    both = tmp_path / "AB.H"
    both.write_text((tmp_path / "A.H").read_text() + (tmp_path / "B.H").read_text())
    code, _, err = run("check-program", "--machine", SEED_MACHINE, both)
    assert code == 2 and "the program's header names 2 nest lengths" in err and "--probe-length" in err, err
    code, _, err = run("check-program", "--machine", SEED_MACHINE, tmp_path / "B.H")
    assert code == 0, err


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_a_program_for_another_nest_is_checked_with_the_nest_its_header_names(tmp_path, controller):
    """A session with a 150 mm nest (the machine file's is 184.67): check-program moves that
    nest, 34.67 mm shorter, nearer the ball. HEIDENHAIN writes the length signed (+150.0000)
    and it was not read: the program was checked with the machine file's nest."""
    ext = CONTROLLERS[controller].program_ext
    code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--path", "K2", "--probe-length", 150,
                       "--controller", controller, "-o", tmp_path / f"P{ext}")
    assert code == 0, err
    args = ["--mode", "tcpm"] if controller == "linuxcnc" else []
    code, out, err = run("check-program", "--machine", SEED_MACHINE, "--controller", controller, *args,
                         tmp_path / f"P{ext}")
    assert code == 0 and "nest 150 mm below the gauge line (from the program's header)" in out, (out, err)


def test_a_path_named_twice_is_refused_in_one_line(tmp_path):
    """--path K2,K2 was one run whose C turned 360° between the two, refused for its step
    (or, simulated, read back as one run): a file holds one run of a path."""
    for command in (["measure-program", "--path", "K2,K2", "-o", tmp_path / "KK.H"],
                    ["simulate", "--truth", ROOT / "examples" / "truth-table4.json", "--paths", "K4,K2,K4",
                     "-o", tmp_path / "KK.csv"]):
        code, _, err = run(*command[:1], "--machine", SEED_MACHINE, *command[1:])
        assert code == 2 and "is named twice" in err and "save each run's readings" in err, err
        assert len(err.strip().splitlines()) == 1 and not list(tmp_path.iterdir())


@pytest.mark.parametrize("command, output, says", [
    ("measure-program", "K.x", "a HEIDENHAIN iTNC 530 program is a .H file. Give -o K.H"),
    ("probe-program", "P.ngc", "a HEIDENHAIN iTNC 530 program is a .H file. Give -o P.H"),
])
def test_a_program_is_written_under_its_controls_suffix(tmp_path, command, output, says):
    """A HEIDENHAIN program written as K.x was a file the control does not list as a program,
    and check-program would have taken its control from the suffix: refused in one line,
    nothing written."""
    code, _, err = run(command, "--machine", SEED_MACHINE, "--path", "K2", "-o", tmp_path / output)
    assert code == 2 and says in err and len(err.strip().splitlines()) == 1, err
    assert not list(tmp_path.iterdir())
