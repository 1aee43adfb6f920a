"""A rotary axis the PLC positions (issue 69): `positioning = "m-function"`, `m_function = N`.
The NC never writes its word: HEIDENHAIN hands its target to the OEM's M-function in Q120-Q122
(the iTNC 530's MP6602 and KinematicsOpt's convention, U26) and calls it; SINUMERIK stops for
the operator to call it and stops the program unless the axis stands there; LinuxCNC (whose
kinematics move every axis themselves) and heads (under TCP throughout) are refused in one
line. It turns only with the nest (or stylus) up at the safe height and TCP off, and the
motion check refuses an NC word of it, another M-function, and a PLC turn under TCP."""

import re

import pytest
from conftest import HEAD_MACHINE, SEED_MACHINE, run

from compgen.configuration.machine_file import load_machine
from compgen.controllers.checking import check_file
from compgen.controllers.registry import for_machine

A_LINE = 'direction = "x"        # right-handed about +X (contract §2)\noffset = [0.0, 0.0, 0.0]\n' \
         'travel = [-120.0, 120.0]\nfeed_max = 5400.0\n'


def _plc(tmp_path, more='positioning = "m-function"\nm_function = 130\n', source=SEED_MACHINE):
    """The seed machine with A positioned by the PLC, K4 and K1 at 25 poses (every pose that
    turns A is a run of its own: the shipped 241 and 361 are seconds of checking each)."""
    text = source.read_text()
    assert A_LINE in text and "n = 241\n" in text and "n = 361\n" in text
    path = tmp_path / "m.toml"
    path.write_text(text.replace(A_LINE, A_LINE + more).replace("n = 241\n", "n = 25\n")
                    .replace("n = 361\n", "n = 25\n"))
    return path


@pytest.mark.parametrize("ctl, ext", [("itnc530", "H"), ("tnc640", "H"), ("sinumerik840d", "MPF")])
@pytest.mark.parametrize("verb", ["measure-program", "probe-program"])
def test_the_nc_never_turns_an_axis_the_plc_positions(tmp_path, ctl, ext, verb):
    path = _plc(tmp_path)
    out = tmp_path / f"P.{ext}"
    code, _, err = run(verb, "--machine", path, "--path", "K4,K1", "--controller", ctl, "-o", out)
    assert code == 0, err
    code, said, err = run("check-program", "--machine", path, "--controller", ctl, out)
    assert code == 0 and "OK" in said, err
    machine = load_machine(path)
    text = out.read_text()
    blocks = for_machine(ctl, machine).blocks(text)
    moves = [b for b in blocks if b.kind == "move"]
    assert not any("A" in b.target for b in moves if not b.plc), "an NC word of A"
    turns = [b for b in moves if b.plc]
    # every A position of the program's poses is an M-function's (or the operator's) turn
    rows = out.with_suffix(".poses.csv").read_text().splitlines()
    col = rows[0].split(",").index("A")
    angles = {round(float(r.split(",")[col]), 4) for r in rows[1:]}
    assert {round(b.target["A"], 4) for b in turns} == angles
    if ext == "H":
        assert len(re.findall(r"^\d+ FN 0: Q120 = \S+ ; A's target", text, re.M)) == len(turns)
        assert all(b.name == "M130" for b in turns) and "UNCONFIRMED U26" in text
    else:
        assert len(re.findall(r'^MSG\("INDEX A TO ', text, re.M)) == len(turns)
        assert len(re.findall(r"^IF ABS\(\$AA_IM\[A\]-", text, re.M)) == len(turns)
    # the PLC turns A with TCP off: never between a TCP on and its off
    tcp = False
    for b in blocks:
        if b.kind == "tcp":
            tcp = b.on
        assert not (b.kind == "move" and b.plc and tcp), b.text


def test_the_check_refuses_an_nc_word_another_m_function_and_a_turn_under_tcp(tmp_path):
    path = _plc(tmp_path)
    out = tmp_path / "P.H"
    code, _, err = run("measure-program", "--machine", path, "--path", "K1", "--controller", "itnc530",
                       "-o", out)
    assert code == 0, err
    machine, ctl = load_machine(path), for_machine("itnc530", load_machine(path))
    text = out.read_text()
    first_c = re.search(r"^(\d+) L C([+-]\d+\.\d+) R0 FMAX", text, re.M)
    cases = {
        "an NC move of an axis the PLC positions":
            text.replace(first_c[0], f"{first_c[1]} L A+1.0000 C{first_c[2]} R0 FMAX", 1),
        "not the axis's M-function": re.sub(r"^(\d+) M130 ;", r"\1 M131 ;", text, count=1, flags=re.M),
        "the PLC turns an axis under TCP":
            re.sub(r"^(\d+) (FN 0: Q120 = )", r"\1 FUNCTION TCPM F CONT AXIS POS PATHCTRL AXIS\n\1 \2",
                   text, count=1, flags=re.M),
    }
    for rule, edited in cases.items():
        edited = "\n".join(f"{k} {ln.split(' ', 1)[1]}" if re.match(r"\d+ ", ln) else ln
                           for k, ln in enumerate(edited.splitlines()))         # renumbered
        result = check_file(machine, ctl, edited, "P.H").result
        assert any(f.rule == rule for f in result.findings), (rule, [f.rule for f in result.findings][:3])


@pytest.mark.parametrize("more, words", [
    ('positioning = "m-function"\n', "needs the M-function's number"),
    ("m_function = 130\n", 'positioning = "m-function"'),
    ('positioning = "plc"\nm_function = 130\n', 'positioning must be "nc" or "m-function"'),
    ('positioning = "m-function"\nm_function = 1.5\n', "whole number"),
])
def test_a_machine_file_says_an_m_function_axis_whole_or_is_refused_in_one_line(tmp_path, more, words):
    path = _plc(tmp_path, more)
    code, _, err = run("simulate", "--machine", path, "--truth", path, "-o", tmp_path / "s.csv")
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1, err


def test_where_the_plc_cannot_be_had_to_turn_it_nothing_is_written(tmp_path):
    """LinuxCNC's kinematics move every axis themselves; a head runs under TCP throughout."""
    path = _plc(tmp_path)
    for verb in ("measure-program", "probe-program"):
        code, _, err = run(verb, "--machine", path, "--path", "K1", "--controller", "linuxcnc",
                           *(["--mode", "axes"] if verb == "measure-program" else []),
                           "-o", tmp_path / "P.ngc")
        assert code == 2 and "positioned by the PLC" in err and len(err.strip().splitlines()) == 1, err
    head = tmp_path / "h.toml"
    b = 'offset = [0.0, 0.0, 150.0]    # the pivot, 150 mm above the spindle\'s gauge line (pivot length)\n'
    text = HEAD_MACHINE.read_text()
    assert b in text
    head.write_text(text.replace(b, b + 'positioning = "m-function"\nm_function = 131\n'))
    code, _, err = run("measure-program", "--machine", head, "--path", "K2", "-o", tmp_path / "H.H")
    assert code == 2 and "a head's program runs under TCP" in err and len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.toml", "m.toml"]


def test_a_path_turning_it_is_measured_at_rest_not_on_the_fly(tmp_path):
    path = _plc(tmp_path)
    (tmp_path / "t.json").write_text('{"parameters": {}}')
    code, _, err = run("simulate", "--machine", path, "--truth", tmp_path / "t.json", "--paths", "K1",
                       "--rate-hz", "10", "-o", tmp_path / "s.csv")
    assert code == 2 and "measured at rest, not on the fly" in err, err
