"""check-program refuses what it does not model (issue 21): each case is a program compgen
wrote, changed the way a hand edit or a damaged file would change it. The rule: a construct
the check does not model exactly is refused with its line and the reason (exit 2), never
simulated as something else, never an internal error (exit 3)."""

import re

import pytest
from conftest import BC_MACHINE, SEED_MACHINE, run

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
    (".MPF", "no M30", lambda t: _drop(t, lambda ln: ln.strip() == "M30"), "no end block"),
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
    code, _, err = run("check-program", "--machine", SEED_MACHINE, path)
    assert code == 2 and "--mode tcpm" in err
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
