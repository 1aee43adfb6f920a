"""What a shop leaves set never moves a LinuxCNC program: LinuxCNC applies G92 (and G52)
and the active G5x offset to a program's positions before its kinematics, so an offset
touched off on the table centre moves every tilted pose. Every LinuxCNC program compgen
writes (measuring under TCP and on axes, probing, the sign check, the heads') selects G54
and stops at its guard, naming what is set, before its tool change and any move; run by
LinuxCNC's own interpreter (rs274) with the offsets a shop leaves. check-program refuses a
program without the guard. W, which the head modules add to their pivot, is read by the
real LinuxCNC in test_linuxcnc.py (rs274 alone has no W axis)."""

import re

import pytest
from conftest import FORK_MACHINE, HEAD_MACHINE, SEED_MACHINE, on_linuxcnc, rs274, run

from compgen.configuration.machine_file import load_machine
from compgen.controllers import linuxcnc
from compgen.controllers.kinematics import kinematics_edit
from compgen.data.simulate import simulate
from compgen.model.paths import generate
from compgen.statistics.identify import identify

MOTION = re.compile(r"STRAIGHT_(?:TRAVERSE|FEED|PROBE)\(([^)]*)\)|ARC_FEED|CHANGE_TOOL")

# the states a shop leaves (parameter file: number -> value) and what the abort must name
LEFT_SET = {
    "G54 on the table centre": ({5221: 100.0, 5222: 50.0}, "G54 holds X100.000000 Y50.000000"),
    "G54 C turned": ({5226: 10.0}, "C10.000000"),
    "G54 rotated": ({5230: 2.0}, "R2.000000"),
    "G54 W": ({5229: -5.0}, "W-5.000000"),
    "G92 Z": ({5210: 1.0, 5213: 5.0}, "G92 offsets are set: X0.000000 Y0.000000 Z5.000000"),
    "G92 A": ({5210: 1.0, 5214: -3.0}, "A-3.000000"),
}


@pytest.fixture(scope="module")
def linuxcnc_seed(tmp_path_factory):
    path = tmp_path_factory.mktemp("m") / "seed-linuxcnc.toml"
    path.write_text(SEED_MACHINE.read_text().replace('controller = "itnc530"', 'controller = "linuxcnc"'))
    return path


def _programs(folder, machine_file) -> dict[str, tuple[str, str]]:
    """Each LinuxCNC program compgen writes for the seed machine: name -> (file, tool line)."""
    out = {}
    for mode in ("tcpm", "axes"):
        code, _, err = run("measure-program", "--machine", machine_file, "--path", "K2", "--mode", mode,
                           "-o", folder / f"RT_{mode}.ngc")
        assert code == 0, err
        out[f"measure {mode}"] = (f"RT_{mode}.ngc", "T99 P1 Z184.67 ;nest")
    code, _, err = run("probe-program", "--machine", machine_file, "--path", "K1,K2", "-o", folder / "PR.ngc")
    assert code == 0, err
    out["probe"] = ("PR.ngc", "T98 P1 Z120 ;probe")
    machine = load_machine(machine_file)
    fit = identify(machine, [simulate(machine, {"XOC": 5e-3}, generate(machine, ["K4", "K1", "K2"]))])
    sign = kinematics_edit(machine, fit, "linuxcnc", None, "", "KIN", "0", "d").files["_SIGN.ngc"]
    (folder / "KIN_SIGN.ngc").write_text(sign)
    out["sign check"] = ("KIN_SIGN.ngc", "T99 P1 Z184.67 ;nest")
    return out


def _motion(canon: str) -> list[str]:
    return [m[0] for m in MOTION.finditer(canon)]


def test_every_linuxcnc_program_stops_at_its_guard_on_what_a_shop_left_set(linuxcnc_seed, tmp_path):
    programs = _programs(tmp_path, linuxcnc_seed)
    for kind, (name, tool) in programs.items():
        clean, done = rs274(tmp_path, name, tool)
        moves = _motion(clean)
        assert done.returncode == 0 and len(moves) > 20, (kind, done.stdout[-400:], done.stderr[-400:])
        for state, (params, says) in LEFT_SET.items():
            canon, done = rs274(tmp_path, name, tool, params=params)
            assert _motion(canon) == [], (kind, state)       # neither the tool change nor a move ran
            said = done.stdout + done.stderr
            assert done.returncode != 0 and says in said, (kind, state, said[-400:])
        # G55 left active (its own offsets set): the program selects G54 and runs as on a clean control
        canon, done = rs274(tmp_path, name, tool, params={5220: 2.0, 5241: 100.0, 5242: -40.0})
        assert done.returncode == 0 and _motion(canon) == moves, kind


@pytest.mark.parametrize("source", [HEAD_MACHINE, FORK_MACHINE], ids=["maxkins", "5axiskins"])
def test_a_head_modules_program_stops_on_a_work_offset_before_its_tool_change(tmp_path, source):
    path = on_linuxcnc(tmp_path, source)
    code, _, err = run("measure-program", "--machine", path, "--path", "K4", "-o", tmp_path / "K4.ngc")
    assert code == 0, err
    for params, says in LEFT_SET.values():
        canon, done = rs274(tmp_path, "K4.ngc", "T7 P1 Z0 ;nest", "XYZBC", params=params)
        assert _motion(canon) == [] and says in done.stdout + done.stderr, done.stderr[-400:]
    text = (tmp_path / "K4.ngc").read_text()
    module = linuxcnc.head_module(load_machine(path))[0].module
    w_guard = linuxcnc.head_guard(module)
    assert "\n".join(w_guard) in text
    assert text.index("M66 E0 L0") < text.index(w_guard[0]) < text.index("\nG0 ")
    if module == "maxkins":          # how to leave an abort: its forward kinematics do not invert
        assert "Stay in MDI:" in text and "G0 B0 C0;\n; only then switch to Manual." in text


def _without(text: str, first: str) -> str:
    """``text`` without the guard that starts with the line ``first`` (its abort and endif)."""
    lines = text.splitlines()
    at = next(i for i, ln in enumerate(lines) if ln.startswith(first))
    return "\n".join([*lines[:at], *lines[at + 3:]]) + "\n"


@pytest.mark.parametrize("edit, says", [
    (lambda t: t.replace("\nG54 ;", "\n;"), "is not compgen's guard"),
    (lambda t: _without(t, "o102 if"), "is not compgen's guard"),
    (lambda t: re.sub(r"G54 ;.*\n(?:.*\n){5}o103 endif\n", "", t),
     "must stop unless G54's and G92's offsets are zero"),
    (lambda t: t.replace("[ABS[#5222] GT 0.0001] OR ", ""), "is not compgen's guard"),
    (lambda t: t.replace("G92.1 clears them)\no102 endif", "G92.1 clears them)\nG0 X0\no102 endif"),
     "is not compgen's guard"),
])
def test_check_program_refuses_a_linuxcnc_program_without_the_offsets_guard(linuxcnc_seed, tmp_path, edit,
                                                                            says):
    code, _, err = run("measure-program", "--machine", linuxcnc_seed, "--path", "K2", "--mode", "tcpm",
                       "-o", tmp_path / "RT.ngc")
    assert code == 0, err
    (tmp_path / "BAD.ngc").write_text(edit((tmp_path / "RT.ngc").read_text()))
    code, out, err = run("check-program", "--machine", linuxcnc_seed, "--mode", "tcpm", tmp_path / "BAD.ngc")
    assert code == 2 and says in err and len(err.strip().splitlines()) == 1, err


def test_the_guard_moves_after_the_tool_change_is_refused(linuxcnc_seed, tmp_path):
    """The guard must come before the tool change (a tool change can move: a changer)."""
    code, _, err = run("measure-program", "--machine", linuxcnc_seed, "--path", "K2", "--mode", "tcpm",
                       "-o", tmp_path / "RT.ngc")
    assert code == 0, err
    lines = (tmp_path / "RT.ngc").read_text().splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("G54 ;"))
    guard = lines[start:start + 7]
    rest = [*lines[:start], *lines[start + 7:]]
    tool = next(i for i, ln in enumerate(rest) if re.match(r"T\d+ M6", ln))
    (tmp_path / "LATE.ngc").write_text("\n".join([*rest[:tool + 1], *guard, *rest[tool + 1:]]) + "\n")
    code, out, err = run("check-program", "--machine", linuxcnc_seed, "--mode", "tcpm", tmp_path / "LATE.ngc")
    assert code == 2 and "before its tool change and any move" in err, err


def test_every_line_of_the_guards_fits_linuxcncs_line_length():
    heads = [g for m in linuxcnc.HEAD_MODULES for g in linuxcnc.head_guard(m.module)]
    for line in [*linuxcnc.offsets_guard(), *heads]:
        assert len(line) <= linuxcnc.LINE_MAX, line


def test_a_machine_name_of_300_characters_makes_programs_and_a_configuration_linuxcnc_reads(tmp_path):
    """A 300-character machine name once made header lines rs274 refuses ("Command too long")
    and a KIN.ini compgen itself refused: comments are cut to the line LinuxCNC reads, the
    probe log leaves a name it cannot carry out, and check-program refuses a longer line."""
    name = "Machine " + "x" * 292
    path = tmp_path / "long.toml"
    path.write_text(re.sub(r'(?m)^name = ".*"$', f'name = "{name}"', SEED_MACHINE.read_text())
                    .replace('controller = "itnc530"', 'controller = "linuxcnc"'))
    assert load_machine(path).name == name
    for args, out, tool in ((["measure-program", "--mode", "tcpm"], "RT.ngc", "T99 P1 Z184.67 ;nest"),
                            (["probe-program"], "PR.ngc", "T98 P1 Z120 ;probe")):
        code, _, err = run(*args, "--machine", path, "--path", "K2", "-o", tmp_path / out)
        assert code == 0, err
        text = (tmp_path / out).read_text()
        assert max(len(ln) for ln in text.splitlines()) <= linuxcnc.LINE_MAX
        canon, done = rs274(tmp_path, out, tool)
        said = done.stdout + done.stderr
        assert done.returncode == 0 and "Command too long" not in said, said[-300:]
    text = (tmp_path / "RT.ngc").read_text()
    (tmp_path / "BAD.ngc").write_text(text.replace("; mode TCPM", "; " + "y" * 300 + "\n; mode TCPM", 1))
    code, _, err = run("check-program", "--machine", path, "--mode", "tcpm", tmp_path / "BAD.ngc")
    assert code == 2 and "Command too long" in err, err


def test_check_program_takes_the_mode_from_compgens_header(linuxcnc_seed, tmp_path):
    """check-program on a LinuxCNC program refused without --mode although the header says
    "mode TCPM": the header's mode is checked; --mode must agree with it; a program whose
    header says none still needs --mode."""
    code, _, err = run("measure-program", "--machine", linuxcnc_seed, "--path", "K2", "--mode", "axes",
                       "-o", tmp_path / "RT.ngc")
    assert code == 0, err
    code, out, err = run("check-program", "--machine", linuxcnc_seed, tmp_path / "RT.ngc")
    assert code == 0 and "OK" in out, err
    code, out, err = run("check-program", "--machine", linuxcnc_seed, "--mode", "tcpm", tmp_path / "RT.ngc")
    assert code == 2 and "written for mode AXES (its header)" in err, err
    text = re.sub(r"(?m)^; mode AXES.*\n", "", (tmp_path / "RT.ngc").read_text())
    (tmp_path / "NOMODE.ngc").write_text(text)
    code, out, err = run("check-program", "--machine", linuxcnc_seed, tmp_path / "NOMODE.ngc")
    assert code == 2 and "header does not say which it was written for" in err, err
