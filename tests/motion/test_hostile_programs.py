"""check-program refuses what it does not model (issue 21): each case is a program compgen
wrote, changed the way a hand edit or a damaged file would change it. The rule: a construct
the check does not model exactly is refused with its line and the reason (exit 2), never
simulated as something else, never an internal error (exit 3)."""

import re

import pytest
from conftest import BC_MACHINE, ROOT, SEED_MACHINE, run

MACHINES = {".H": SEED_MACHINE, ".MPF": BC_MACHINE, ".ngc": SEED_MACHINE}


@pytest.fixture(scope="module")
def programs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("p")
    out = {}
    for ext, ctl in ((".H", "itnc530"), (".MPF", "sinumerik840d"), (".ngc", "linuxcnc")):
        path = folder / ext[1:] / f"K4{ext}"
        path.parent.mkdir()
        code, _, err = run("measure-program", "--machine", MACHINES[ext], "--controller", ctl, "--path", "K4",
                           "--mode", "tcpm", "-o", path)
        assert code == 0, err
        out[ext] = path.read_text()
    return out


def _drop(text, pred):
    return "\n".join(ln for ln in text.splitlines() if not pred(ln)) + "\n"


def _sub(a, b):
    def change(text):
        assert a in text, a
        return text.replace(a, b, 1)
    return change


CASES = [
    (".H", "inch", _sub("BEGIN PGM K4 MM", "BEGIN PGM K4 INCH"), "only programs in MM"),
    (".H", "no END PGM", lambda t: _drop(t, lambda ln: "END PGM" in ln), "no end block"),
    (".H", "empty", lambda t: "", "no move"),
    (".H", "comments only", lambda t: "0 ; nothing here\n", "no move"),
    (".H", "DWELL .", _sub("CYCL DEF 9.1 DWELL 1", "CYCL DEF 9.1 DWELL ."), "not a block this check knows"),
    (".H", "400 digits", _sub("L Z+378.0000 R0 FMAX", "L Z+" + "9" * 400 + " R0 FMAX"),
     "is not a word this check reads"),
    (".H", "F0", _sub("C+1.5000 R0 F500", "C+1.5000 R0 F0"), "F0: a feed must be above zero"),
    (".H", "F-500", _sub("C+1.5000 R0 F500", "C+1.5000 R0 F-500"), "a feed must be above zero"),
    (".H", "a block after END PGM", lambda t: t + "999 L Z+400 R0 FMAX\n", "after the program's end"),
    (".H", "no BEGIN PGM", lambda t: _drop(t, lambda ln: "BEGIN PGM" in ln),
     "'END PGM K4 MM' ends a program no BEGIN PGM began"),
    (".H", "END PGM of another", _sub("END PGM K4 MM", "END PGM K5 MM"), "ends a program other than K4"),
    (".H", "an axis the machine lacks", _sub("L Z+378.0000 R0 FMAX", "L V+378.0000 R0 FMAX"),
     "'V+378.0000' is not a word this check reads"),
    (".MPF", "no M30", lambda t: t[:t.rindex("\nM30")] + "\n", "no end block"),   # the last: the guards' stay
    (".MPF", "G57 for G54", _sub("\nG54 ;", "\nG57 ;"), "selects G57; the machine file's work offset is G54"),
    (".MPF", "G70 (inch)", _sub("G17 G90 G71 G94", "G17 G90 G70 G94"), "not a word"),
    (".MPF", "G4 F1..2", lambda t: re.sub(r"G4 F1\b", "G4 F1..2", t, count=1), "not a block this check"),
    (".ngc", "guard without its abort", lambda t: _drop(t, lambda ln: ln.startswith("(abort")),
     "is not compgen's guard"),
    (".ngc", "guard naming B", _sub("#5425", "#5424"), "the guard reads B, which this machine lacks"),
    (".ngc", "G4 P1..2", lambda t: re.sub(r"G4 P1\b", "G4 P1..2", t, count=1), "not a block this check"),
    (".ngc", "no M2", lambda t: _drop(t, lambda ln: ln.strip() in ("M2", "M30")), "no end block"),
    (".ngc", "header says AXES", _sub("; mode TCPM:", "; mode AXES:"), "written for mode AXES"),
    (".ngc", "G20 (inch)", _sub("G21 G90 G94 G17", "G20 G90 G94 G17"), "not a word"),
]


@pytest.mark.parametrize("ext, name, change, says", CASES, ids=[f"{c[0]}-{c[1]}" for c in CASES])
def test_a_construct_the_check_does_not_model_is_refused(programs, tmp_path, ext, name, change, says):
    path = tmp_path / f"X{ext}"
    path.write_text(change(programs[ext]))
    mode = ["--mode", "tcpm"] if ext == ".ngc" else []
    code, out, err = run("check-program", "--machine", MACHINES[ext], path, *mode)
    assert code == 2 and says in err and len(err.strip().splitlines()) == 1, (code, out, err)


def test_a_linuxcnc_program_is_checked_under_the_mode_the_user_names(programs, tmp_path):
    path = tmp_path / "X.ngc"
    path.write_text(programs[".ngc"])
    code, out, err = run("check-program", "--machine", SEED_MACHINE, path)    # the header's mode
    assert code == 0 and "OK" in out, err
    code, _, err = run("check-program", "--machine", SEED_MACHINE, path, "--mode", "axes")
    assert code == 2 and "written for mode TCPM" in err
    assert run("check-program", "--machine", SEED_MACHINE, path, "--mode", "tcpm")[0] == 0
    h = tmp_path / "X.H"
    h.write_text(programs[".H"])
    code, _, err = run("check-program", "--machine", SEED_MACHINE, h, "--mode", "tcpm")
    assert code == 2 and "switch it themselves" in err


def test_a_turn_alone_faster_than_the_rotary_axis_can_is_refused(programs, tmp_path):
    """C alone at F99999 deg/min, from a known place at the safe height: C's feed_max is
    10800 deg/min (the mutation that flipped the rotary speed's sign survived every test)."""
    text = programs[".H"]
    at = "L A+0.0000 C+0.0000 R0 FMAX ; turn at the safe height"
    number = re.search(rf"(?m)^(\d+) {re.escape(at)}", text)[1]
    bad = text.replace(f"{number} {at}", f"{number} {at}\n{number} L C+90.0000 R0 F99999", 1)
    path = tmp_path / "FAST.H"
    path.write_text(bad)
    code, out, err = run("check-program", "--machine", SEED_MACHINE, path)
    assert code == 1 and "feed above feed_max: C would move at 99999 deg/min" in out, out + err
    path.write_text(bad.replace("C+90.0000 R0 F99999", "C+90.0000 R0 F9999"))
    assert run("check-program", "--machine", SEED_MACHINE, path)[0] == 0


# ISO 230-1 / 230-7 names, from the standard's tables, not from compgen: a swapped
# description or cause (EXC called "axial") once survived every test (mutation sample)
ISO_WORDS = {"EXX:p1": "positioning error of X", "EYX:p2": "straightness of X in Y", "EAX:p1": "roll of X",
             "EBX:p1": "pitch of X", "ECX:p1": "yaw of X", "EZC:h1": "axial error motion of C",
             "EXC:h1": "radial error motion of C in X", "EYC:h1": "radial error motion of C in Y",
             "EAC:h1": "tilt error motion of C about X", "EBC:h1": "tilt error motion of C about Y",
             "ECC:h1": "angular positioning error of C"}
ISO_CAUSES = {"EZC:h1": "face runout", "EXC:h1": "bearing runout", "EAC:h1": "wobble",
              "ECC:h2": "worm or scale error", "EXX:p1": "scale error"}


def test_effects_carry_their_iso_names_and_causes():
    from compgen.configuration.machine_file import load_machine
    from compgen.model.effects import effect_of_param
    m = load_machine(SEED_MACHINE)
    for name, words in ISO_WORDS.items():
        e = effect_of_param(m, f"{name}c" if ":h" in name else name)
        assert e.words.startswith(words), (name, e.words)
    for name, cause in ISO_CAUSES.items():
        e = effect_of_param(m, f"{name}c" if ":h" in name else name)
        assert cause in e.cause, (name, e.cause)


def test_the_linuxcnc_guard_reads_linuxcncs_position_parameters():
    """#5420-#5425 are the current X Y Z A B C (LinuxCNC's numbered parameters)."""
    from compgen.controllers.linuxcnc import program_blocks
    text = ("G21 G90 G94 G17\no100 if [[ABS[#5420] GT 0.0001] OR [ABS[#5421] GT 0.0001] OR "
            "[ABS[#5422] GT 0.0001] OR [ABS[#5423] GT 0.0001] OR [ABS[#5424] GT 0.0001] OR "
            "[ABS[#5425] GT 0.0001]]\n(abort, no)\no100 endif\nM2\n")
    (guard,) = [b for b in program_blocks(text, True) if b.kind == "require"]
    assert list(guard.target) == ["X", "Y", "Z", "A", "B", "C"]


def _machine_with(tmp_path, before, after):
    text = SEED_MACHINE.read_text()
    assert before in text
    path = tmp_path / "m.toml"
    path.write_text(text.replace(before, after, 1))
    return path


def test_measure_program_refuses_a_tcpm_feed_a_rotary_axis_cannot_turn(tmp_path):
    """In TCPM a pose block only turns, at F deg/min: C with feed_max 400 cannot take F500.
    Said by measure-program in the user's terms, before the motion check would find it."""
    m = _machine_with(tmp_path, "feed_max = 10800.0", "feed_max = 400.0")
    code, _, err = run("measure-program", "--machine", m, "--path", "K4", "-o", tmp_path / "X.H")
    assert code == 2 and "[program] feed 500 (deg/min where a TCPM pose block only turns) exceeds C's " \
        "feed_max 400" in err, err


def test_measure_program_checks_the_clearance_above_the_poses_along_z(tmp_path):
    """Z's travel ends 10 mm above the highest pose: the poses fit, the 20 mm clearance
    above them does not."""
    from compgen.configuration.machine_file import load_machine
    from compgen.model.paths import generate
    machine = load_machine(SEED_MACHINE)
    top = generate(machine, ["K4"]).q[:, machine.index("Z")].max()
    m = _machine_with(tmp_path, "travel = [-300.0, 400.0]", f"travel = [-300.0, {top + 10:.3f}]")
    code, _, err = run("measure-program", "--machine", m, "--path", "K4", "-o", tmp_path / "X.H")
    assert code == 2 and "(clearance 20 mm off the ball)" in err and "puts Z at" in err, err


@pytest.mark.parametrize("ball", ["X-0,5 Y0 Z100 mm", "X1e2 Y0 Z100 mm", "X10 Y0 mm", "X10 Y0 Z100 inch"])
def test_a_header_ball_that_does_not_read_is_refused_not_replaced(tmp_path, ball):
    """A program's header names its ball; one that does not read as X Y Z mm is refused with
    its line, never silently replaced by the machine file's ball."""
    out = tmp_path / "K4.ngc"
    code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--controller", "linuxcnc",
                       "--path", "K4", "-o", out)
    assert code == 0, err
    text = out.read_text()
    line = 1 + next(k for k, ln in enumerate(text.splitlines()) if "ball centre in the table frame:" in ln)
    bad = tmp_path / "B.ngc"
    said = r"(ball centre in the table frame: )X\S+ Y\S+ Z\S+ mm"
    bad.write_text(re.sub(said, lambda m: m[1] + ball, text))
    code, _, err = run("check-program", "--machine", SEED_MACHINE, "--mode", "tcpm", bad)
    assert code == 2 and f"B.ngc:{line}: the header names the ball as" in err, err
    assert len(err.splitlines()) == 1
    given = run("check-program", "--machine", SEED_MACHINE, "--mode", "tcpm", "--ball", "0,0,100", bad)
    assert given[0] in (0, 1)


def test_a_file_name_with_a_line_break_stays_on_its_comment_line(tmp_path):
    """predict writes the pose list's name into its CSV comments: a line break in it is
    written as \\n, not obeyed (it would start a line the reader takes for data)."""
    poses = tmp_path / "a\nb.csv"
    code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--controller", "linuxcnc",
                       "--path", "K4", "-o", tmp_path / "K4.ngc")
    assert code == 0, err
    poses.write_text((tmp_path / "K4.poses.csv").read_text())
    fit = tmp_path / "fit.json"
    data = tmp_path / "s.csv"
    truth = ROOT / "examples" / "truth-table4.json"
    assert run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--paths", "K4", "-o", data)[0] == 0
    assert run("fit", "--machine", SEED_MACHINE, data, "-o", fit)[0] == 0
    code, _, err = run("predict", "--from", fit, "--poses", poses, "-o", tmp_path / "p.csv")
    assert code == 0, err
    text = (tmp_path / "p.csv").read_text()
    assert "a\\nb.csv" in text and not any(ln.startswith("b.csv") for ln in text.splitlines())


def test_tcp_switched_on_before_every_axis_is_positioned_is_a_finding(programs, tmp_path):
    """FUNCTION TCPM before the first positioning block: the control's TCP would start from
    positions nobody wrote. Found at its line (exit 1), not simulated from somewhere."""
    text = programs[".H"]
    first = re.search(r"(?m)^(\d+) L Z\+378\.0000 R0 FMAX", text)
    early = text.replace(first[0], f"{first[1]} FUNCTION TCPM F CONT AXIS POS PATHCTRL AXIS\n{first[0]}", 1)
    path = tmp_path / "EARLY.H"
    path.write_text(early)
    code, out, err = run("check-program", "--machine", SEED_MACHINE, path)
    assert code == 1 and "TCP before positioning: TCP is on before every axis has been positioned" in out, (
        out, err)
