"""LinuxCNC's configuration read as LinuxCNC starts it (inivar, the start script, halcmd),
each case one a reader that looked at the files rather than at LinuxCNC got wrong; and the
configuration to start with that an edit writes, evaluated the same way."""

import os
import re
import shutil
import subprocess

import numpy as np
import pytest
from conftest import ARCSEC, SEED_MACHINE, UM, run

from compgen.configuration.machine_file import load_machine
from compgen.controllers import linuxcnc
from compgen.controllers.kinematics import kinematics_edit
from compgen.controllers.linuxcnc.config import evaluate, hal_file, then
from compgen.controllers.registry import read_state
from compgen.data.rtest import format_rtest
from compgen.data.simulate import simulate
from compgen.errors import CompgenError
from compgen.model.effects import location_model
from compgen.model.paths import generate
from compgen.statistics.identify import identify

SEED_MACHINE_TEXT = SEED_MACHINE.read_text()
TRUTH = {"XOC": 12 * UM, "YOC": -9 * UM, "YOA": 20 * UM, "ZOA": -15 * UM, "AOC": 5 * ARCSEC}


@pytest.fixture
def trt(seed_machine):
    module, tilt, c = linuxcnc.trt_module(seed_machine)
    return module, linuxcnc.nominal_pins(seed_machine, tilt, c)


def _config(tmp_path, ini: str, **files: str):
    for name, text in files.items():
        (tmp_path / name.replace("__", ".")).write_text(text)
    (tmp_path / "m.ini").write_text(ini)
    return read_state(str(tmp_path / "m.ini"))


def _pins(state, module):
    return linuxcnc.held_pins(evaluate(state), module)[0]


def _edit_ini(machine, fit, state, folder):
    """The edit with ``m.ini``'s configuration as --current, its files to go to ``folder``."""
    return kinematics_edit(machine, fit, "linuxcnc", state, "m.ini", "N", "0", "d", stem="N",
                           folder=str(folder))


def _setp(module, nominal, skip=()):
    return "".join(f"setp {module}.{n} {v:.6f}\n" for n, v in nominal.items() if n not in skip)


def test_a_key_given_twice_takes_its_first_value_and_a_second_section_is_not_read(tmp_path, trt):
    module, nominal = trt
    state = _config(
        tmp_path,
        "[TRT]\nZ = 29.794\nZ = 99\n[HAL]\nHALFILE = a.hal\n[HAL]\nHALFILE = b.hal\n",
        a__hal=_setp(module, nominal, ["z-rot-point"]) + f"setp {module}.z-rot-point [TRT]Z\n",
        b__hal=f"setp {module}.x-rot-point 5\n",
    )
    assert _pins(state, module)["z-rot-point"] == 29.794  # inivar: the first occurrence
    assert _pins(state, module)["x-rot-point"] == 0.0  # the second [HAL] is never read
    assert "(HALFILE b.hal)" not in state


@pytest.mark.skipif(shutil.which("inivar") is None and not os.environ.get("COMPGEN_REQUIRE_LINUXCNC"),
                    reason="LinuxCNC's inivar (Debian's linuxcnc-uspace) is not installed")
def test_a_line_ending_in_a_backslash_is_joined_with_the_next_as_inivar_joins_it(tmp_path, trt):
    module, nominal = trt
    ini = "[TRT]\nZ = 29.\\\n794\n[HAL]\nHALFILE = a.hal\n"
    state = _config(tmp_path, ini,
                    a__hal=_setp(module, nominal, ["z-rot-point"]) + f"setp {module}.z-rot-point [TRT]Z\n")
    told = subprocess.run(["inivar", "-ini", str(tmp_path / "m.ini"), "-sec", "TRT", "-var", "Z"],
                          capture_output=True, text=True, check=True).stdout.strip()
    assert told == "29.794"                                   # LinuxCNC's own reading
    assert _pins(state, module)["z-rot-point"] == float(told)


def test_an_include_is_expanded_and_its_joint_table_kept(tmp_path, trt, seed_machine):
    module, nominal = trt
    table = "0 0.001 0.001\n360 0.001 0.001\n"
    state = _config(
        tmp_path,
        "[HAL]\nHALFILE = a.hal\n#INCLUDE joints.inc\n",
        a__hal=_setp(module, nominal),
        joints__inc="[JOINT_4]\nCOMP_FILE = c.comp\nCOMP_FILE_TYPE = 1\n",
        c__comp=table,
    )
    ((fwd, _),) = linuxcnc.loaded_joint_tables(seed_machine, state).values()
    assert fwd.input == "C" and fwd.values == (0.001, 0.001)
    fit = identify(
        seed_machine,
        [
            simulate(
                seed_machine, {**TRUTH, "ECC:h2c": 3 * ARCSEC}, generate(seed_machine, ["K4", "K1", "K2"])
            )
        ],
        [*location_model(seed_machine), "ECC:h2c", "ECC:h2s"],
    )
    out = _edit_ini(seed_machine, fit, state, tmp_path)
    # the table stands in the included file: written anew with the INI naming it
    assert "#INCLUDE N.joints.inc" in out.files[".ini"]
    assert (
        "COMP_FILE = N.C.comp" in out.files[".joints.inc"]
        and "COMP_FILE_TYPE = 1" in out.files[".joints.inc"]
    )


@pytest.mark.parametrize(
    "ini, files, says",
    [
        ("[HAL]\nHALFILE = gone.hal\n", {}, r"m.ini:2: HALFILE gone.hal: no such file"),
        (
            "[HAL]\nHALFILE = LIB:nothere.tcl\n",
            {},
            r"m.ini:2: HALFILE LIB:nothere.tcl: no such file in LinuxCNC's",
        ),
        ("[HAL]\nPOSTGUI_HALFILE = post.hal\n", {}, r"m.ini:2: POSTGUI_HALFILE post.hal: no such file"),
        (
            "[HAL]\nHALFILE = a.hal\n#INCLUDE x.inc\n",
            {"a__hal": ""},
            r"m.ini:3: #INCLUDE x.inc: no such file",
        ),
        ("[HAL]\nHALFILE = sub\n", {}, r"m.ini:2: HALFILE sub: not a regular file"),
        (
            "[HAL]\nHALFILE = a.hal\n[JOINT_4]\nCOMP_FILE = c.comp\n",
            {"a__hal": ""},
            r"m.ini:4: COMP_FILE c.comp: no such",
        ),
        ("[HAL]\nHALFILE = own.tcl\n", {"own__tcl": "puts hi\n"}, r"m.ini:2: .*Tcl HAL file"),
        (
            "[HAL]\nHALCMD = setp xyzac-trt-kins.x-rot-point 0 # zero\n",
            {},
            r"m.ini:2: HALCMD .* holds a comment",
        ),
        (
            "[HAL]\nHALFILE = a.hal\n",
            {"a__hal": "sets s 1\nnet s xyzac-trt-kins.x-rot-point\n"},
            r"a.hal:2: signal s is set at .*a.hal:1 before this line makes it",
        ),
        (
            "[HAL]\nHALFILE = a.hal\n",
            {"a__hal": "setp xyzac-trt-kins.x-rot-point [TRT]X\n"},
            r"a.hal:1: \[TRT\]X is not",
        ),
        (
            "[HAL]\nHALFILE = a.hal\n",
            {"a__hal": "setp xyzac-trt-kins.x-rot-point '0\n"},
            r"a.hal:1: an unterminated",
        ),
        ("[HAL]\n#INCLUDE $(HOME).inc\n", {}, r"m.ini:2: #INCLUDE \$\(HOME\).inc: the start script expands"),
        ("# compgen: file a.hal\n[HAL]\n", {}, r"the INI holds a line starting '# compgen: file'"),
        (
            "[HAL]\nHALFILE = a.hal\n",
            {"a__hal": "# compgen: file b.hal\n"},
            r"a.hal: HALFILE a.hal holds a line starting '# compgen: file'",
        ),
        ("[HAL]\nTWOPASS = on\nHALFILE = a.hal\n", {"a__hal": ""}, r"\[HAL\] TWOPASS: LinuxCNC runs the HAL"),
        (
            "[HAL]\nHALFILE = a.hal\n[JOINT_0]\nCOMP_FILE = c.comp\nCOMP_FILE_TYPE = 2\n",
            {"a__hal": "", "c__comp": "0 0 0\n"},
            r"m.ini:5: \[JOINT_0\] COMP_FILE_TYPE = 2: LinuxCNC takes 0 or 1",
        ),
        (
            "[HAL]\nHALFILE = a.hal\n",
            {"a__hal": "unlinkp xyzac-trt-kins.x-rot-point\n"},
            r"a.hal:1: unlinkp: compgen does not evaluate it",
        ),
        (
            "[HAL]\nHALFILE = a.hal\n",
            {"a__hal": "net a xyzac-trt-kins.x-rot-point\nnet b xyzac-trt-kins.x-rot-point\n"},
            r"a.hal:2: net b: xyzac-trt-kins.x-rot-point is already on a",
        ),
        (
            "[HAL]\nHALFILE = a.hal\n",
            {"a__hal": "source b.hal\n", "b__hal": "unlinkp xyzac-trt-kins.x-rot-point\n"},
            r"b.hal:1: unlinkp",       # a sourced file is read as the HAL file's own lines
        ),
        ("[HAL]\nHALFILE = a.hal " + "x" * 250 + "\n", {"a__hal": ""},
         r"m.ini:2: a line of 266 characters: LinuxCNC reads 255"),
        ("[HAL]\n#INCLUDE\n", {}, r"m.ini:2: #INCLUDE without a file name"),
        ("[HAL]\n#INCLUDE x.inc\n", {"x__inc": "#INCLUDE y.inc\n"}, r"an #INCLUDE inside an included file"),
        ("[HAL]\n#INCLUDE x.inc\n", {"x__inc": "HALFILE = " + "y" * 260 + "\n"},
         r"a line of 270 characters: LinuxCNC reads 255"),
    ],
)
def test_every_file_and_line_linuxcnc_would_stop_at_is_refused_with_its_line(tmp_path, ini, files, says):
    (tmp_path / "sub").mkdir()
    with pytest.raises(CompgenError, match=says):
        _config(tmp_path, ini, **files)


def test_library_files_are_linuxcncs_own_and_a_halfile_edit_is_overwritten_by_halcmd(tmp_path, trt):
    """The trt samples' way: LIB:basic_sim.tcl, then HALCMD lines set the pins. A further
    HALFILE (the old way to load an edit) runs before them: its setp is overwritten, its
    sets on a HALCMD-made signal stops LinuxCNC's start."""
    module, nominal = trt
    sample = (
        "[HAL]\nHALFILE = LIB:basic_sim.tcl -no_use_hal_manualtoolchange\n"
        f"HALCMD = net :y-offset {module}.y-offset\nHALCMD = sets :y-offset 0\n"
        + "".join(f"HALCMD = setp {module}.{n} {v:.6f}\n" for n, v in nominal.items() if n != "y-offset")
    )
    state = _config(tmp_path, sample)
    assert _pins(state, module) == pytest.approx(nominal)
    late = _config(
        tmp_path,
        sample.replace("[HAL]\n", "[HAL]\nHALFILE = edit.hal\n"),
        edit__hal=f"setp {module}.x-rot-point 0.5\n",
    )
    assert _pins(late, module)["x-rot-point"] == nominal["x-rot-point"]  # HALCMD runs after it
    with pytest.raises(CompgenError, match=r"m.ini:4: signal :y-offset is set at .*edit.hal:1 before"):
        _config(
            tmp_path, sample.replace("[HAL]\n", "[HAL]\nHALFILE = edit.hal\n"), edit__hal="sets :y-offset 1\n"
        )


def test_halcmd_forms_pin_equals_value_and_comments_anywhere(tmp_path, trt):
    module, nominal = trt
    hal = (
        f"net yo {module}.y-offset # {module}.x-rot-point is not on this signal\nsets yo 0.25\n"
        f"{module}.x-rot-point = 0.125\n"
        + _setp(module, nominal, ["y-offset", "x-rot-point"]).replace("\n", "   # pin\n", 1)
    )
    state = _config(
        tmp_path,
        "[HAL]\nHALFILE = a.hal\nPOSTGUI_HALFILE = post.hal\n",
        a__hal=hal,
        post__hal=f"setp {module}.z-offset -29.5\n",
    )
    pins = _pins(state, module)
    assert pins["x-rot-point"] == 0.125 and pins["y-offset"] == 0.25
    assert pins["z-offset"] == -29.5  # POSTGUI_HALFILE runs last
    assert evaluate(state).net == {f"{module}.y-offset": "yo"}


def test_linkps_and_linksp_net_a_pin_each_their_own_way_round(tmp_path, trt):
    """halcmd's linkps takes the pin first, linksp the signal first: the signal each makes
    reaches its pin."""
    module, nominal = trt
    hal = (f"linkps {module}.y-offset yo\nsets yo 0.25\nlinksp xr {module}.x-rot-point\nsets xr 0.125\n"
           + _setp(module, nominal, ["y-offset", "x-rot-point"]))
    state = _config(tmp_path, "[HAL]\nHALFILE = a.hal\n", a__hal=hal)
    pins = _pins(state, module)
    assert pins["y-offset"] == 0.25 and pins["x-rot-point"] == 0.125
    assert evaluate(state).net == {f"{module}.y-offset": "yo", f"{module}.x-rot-point": "xr"}


def test_a_new_signal_takes_the_value_its_first_pin_held(tmp_path, trt):
    module, nominal = trt
    state = _config(
        tmp_path, "[HAL]\nHALFILE = a.hal\n", a__hal=_setp(module, nominal) + f"net zz {module}.z-offset\n"
    )
    assert _pins(state, module)["z-offset"] == nominal["z-offset"]


def test_a_joint_table_beyond_the_limits_is_refused_with_its_line(tmp_path, trt, seed_machine):
    module, nominal = trt
    state = _config(
        tmp_path,
        "[HAL]\nHALFILE = a.hal\n[JOINT_1]\nCOMP_FILE = y.comp\nCOMP_FILE_TYPE = 1\n",
        a__hal=_setp(module, nominal),
        y__comp="-100 0.5 0.5\n100 0 0\n",
    )
    with pytest.raises(CompgenError, match=r"m.ini:4 \(y.comp\): joint 1's table trims Y by up to 0.5 mm"):
        linuxcnc.loaded_joint_tables(seed_machine, state)


def test_a_rotary_joints_table_is_held_to_the_tilt_limit_in_degrees(tmp_path, trt, seed_machine):
    """C's table in degrees against [limits] tilt_arcsec = 60″ (0.0167°): 0.01° is kept,
    0.02° refused at its line."""
    module, nominal = trt
    for trim, kept in ((0.01, True), (0.02, False)):
        state = _config(
            tmp_path,
            "[HAL]\nHALFILE = a.hal\n[JOINT_4]\nCOMP_FILE = c.comp\nCOMP_FILE_TYPE = 1\n",
            a__hal=_setp(module, nominal),
            c__comp=f"0 {trim} {trim}\n360 0 0\n",
        )
        if kept:
            ((fwd, _),) = linuxcnc.loaded_joint_tables(seed_machine, state).values()
            assert fwd.values == (trim, 0.0)
        else:
            says = r"m.ini:4 \(c.comp\): joint 4's table trims C by up to 0.02 deg: beyond the machine file's"
            with pytest.raises(CompgenError, match=says + r" \[limits\] \(tilt_arcsec\)"):
                linuxcnc.loaded_joint_tables(seed_machine, state)


def test_a_table_for_a_joint_the_trt_module_lacks_is_refused_with_its_line(tmp_path, trt, seed_machine):
    """The trt modules have joints 0-4 (X Y Z and the two rotary axes)."""
    module, nominal = trt
    state = _config(tmp_path, "[HAL]\nHALFILE = a.hal\n[JOINT_5]\nCOMP_FILE = w.comp\nCOMP_FILE_TYPE = 1\n",
                    a__hal=_setp(module, nominal), w__comp="-100 0 0\n100 0 0\n")
    with pytest.raises(CompgenError, match=r"joint 5 has a COMP_FILE, and the trt module has joints 0-4"):
        linuxcnc.loaded_joint_tables(seed_machine, state)


def test_the_configuration_to_start_with_holds_exactly_the_correction(tmp_path, trt, seed_machine):
    """Pins set in three places (a HALCMD line, a HAL file, an INI key a HAL line takes):
    the new INI, evaluated as LinuxCNC starts it, holds the pins of the edit written with no
    configuration; the user's files are untouched; writing it elsewhere is refused."""
    module, nominal = trt
    ini = (
        "[TRT]\nYO = {yo:.6f}\n[HAL]\nHALFILE = LIB:basic_sim.tcl\nHALFILE = trt.hal\n"
        f"HALCMD = setp {module}.x-rot-point {nominal['x-rot-point']:.6f}\n"
    ).format(yo=nominal["y-offset"])
    hal = f"setp {module}.y-offset [TRT]YO\n" + _setp(module, nominal, ["x-rot-point", "y-offset"])
    state = _config(tmp_path, ini, trt__hal=hal)
    fit = identify(seed_machine, [simulate(seed_machine, TRUTH, generate(seed_machine, ["K4", "K1", "K2"]))])
    out = _edit_ini(seed_machine, fit, state, tmp_path).files
    alone = kinematics_edit(seed_machine, fit, "linuxcnc", None, "", "H", "0", "d").files[".hal"]
    want = {m[1]: float(m[2]) for m in re.finditer(rf"(?m)^setp {module}\.(\S+) (\S+)", alone)}
    for suffix, text in out.items():
        (tmp_path / f"N{suffix}").write_text(text)
    got = _pins(read_state(str(tmp_path / "N.ini")), module)
    assert {n: got[n] for n in want} == pytest.approx(want, abs=1e-12) and len(want) == 5
    assert re.search(r"(?m)^YO = (\S+)$", out[".ini"])[1] == f"{want['y-offset']:.6f}"
    assert f"HALCMD = setp {module}.x-rot-point {want['x-rot-point']:.6f}" in out[".ini"]
    assert "HALFILE = N.trt.hal" in out[".ini"] and "[TRT]YO" in out[".trt.hal"]
    assert (tmp_path / "trt.hal").read_text() == hal and (tmp_path / "m.ini").read_text() == ini
    assert _pins(read_state(str(tmp_path / "N_RESTORE.ini")), module) == pytest.approx(nominal)
    elsewhere = tmp_path / "other"
    elsewhere.mkdir()
    with pytest.raises(CompgenError, match="write it there"):
        _edit_ini(seed_machine, fit, state, elsewhere)
    assert np.isfinite(list(want.values())).all()


@pytest.mark.parametrize("lines, says", [
    ("conventional_directions = false\nversion = \"2.10\"\n", "does not invert its own forward kinematics"),
    ("conventional_directions = false\n", "which LinuxCNC runs xyzbc-trt-kins"),
    ("conventional_directions = true\nversion = \"2.9\"\n", "has no conventional-directions pin"),
    ("conventional_directions = false\nversion = 2.10\n", "must be LinuxCNC's version as text"),
    ("conventional_directions = true\nversion = \"2.10\"\n", None),
    ("conventional_directions = false\nversion = \"2.9.4\"\n", None),
])
def test_xyzbc_trt_at_pin_0_is_refused_from_linuxcnc_2_10(tmp_path, lines, says):
    """Upstream's xyzbc inverse from 2.10 carries pin 1's signs in dpx/dpz: at pin 0 the
    nest would stand 2·sin B·dz off under TCP, so the machine file must say the version."""
    from conftest import BC_MACHINE

    from compgen.configuration.machine_file import load_machine
    text = re.sub(r"(?ms)^\[linuxcnc\].*?(?=^\[)", "[linuxcnc]\n" + lines + "\n", BC_MACHINE.read_text())
    (tmp_path / "m.toml").write_text(text)
    if says is None:
        assert load_machine(tmp_path / "m.toml").linuxcnc["version"] is not None
    else:
        with pytest.raises(CompgenError, match=says):
            load_machine(tmp_path / "m.toml")


def test_the_command_writes_the_configuration_beside_the_ini(tmp_path, trt, seed_machine):
    """`kinematics --current CONFIG.ini -o CONFIG/KIN.ini`: the INI, a changed HAL file and
    the restore beside it, the notes saying what to start; elsewhere, or over its own files
    without --force, one line and nothing written."""
    from conftest import run

    from compgen.data.rtest import format_rtest
    module, nominal = trt
    text = SEED_MACHINE_TEXT.replace('controller = "itnc530"', 'controller = "linuxcnc"')
    (tmp_path / "m.toml").write_text(text)
    machine = (tmp_path / "m.toml")
    config = tmp_path / "config"
    config.mkdir()
    (config / "trt.hal").write_text(_setp(module, nominal))
    (config / "machine.ini").write_text("[HAL]\nHALFILE = LIB:basic_sim.tcl\nHALFILE = trt.hal\n")
    data = simulate(seed_machine, TRUTH, generate(seed_machine, ["K4", "K1", "K2"]))
    (tmp_path / "s.csv").write_text(format_rtest(seed_machine, data))
    assert run("fit", "--machine", machine, tmp_path / "s.csv", "-o", tmp_path / "fit.json")[0] == 0
    args = ["kinematics", "--from", tmp_path / "fit.json", "--current", config / "machine.ini"]
    code, out, err = run(*args, "-o", tmp_path / "KIN.ini")
    assert code == 2 and "write it there" in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "KIN.ini").exists()
    code, out, err = run(*args, "-o", config / "KIN.ini")
    assert code == 0, err
    assert {p.name for p in config.iterdir()} >= {"KIN.ini", "KIN.trt.hal", "KIN_RESTORE.ini", "KIN_SIGN.ngc"}
    assert f"start LinuxCNC with {config / 'KIN.ini'}" in out
    code, _, err = run(*args, "-o", config / "KIN.ini")
    assert code == 2 and "exists" in err, err


def test_a_joint_table_read_back_stands_for_the_mean_of_its_two_directions(seed_machine):
    """compgen's predictions do not follow the direction of motion: a table whose trims differ
    by direction (a loaded one, kept) reads back as their mean, on its own grid (values by hand)."""
    text = ("-100 0.010 0.006\n0 0.002 0.002\n100 -0.004 0.000\n"
            "# compgen joint compensation for LinuxCNC: joint 1 = Y (mm)\n")
    table = linuxcnc.read_comp(text, seed_machine, "KIN.Y.comp")
    assert table.input == "Y" and tuple(table.grid) == (-100.0, 0.0, 100.0)
    assert table.values == pytest.approx((0.008, 0.002, -0.002), abs=1e-15)


def test_an_edit_run_after_a_configuration_is_refused_at_its_own_line():
    """A HAL edit read after what the configuration ran (as kinematics reads it back) names
    its own lines from 1, as halcmd does."""
    cfg = hal_file("setp trtkins.x-rot-point 1\n", "m.hal")
    with pytest.raises(CompgenError, match="takes a name and one value") as caught:
        then(cfg, "# the edit\nsetp trtkins.y-offset\n", "edit")
    assert caught.value.where == "edit:2"
    with pytest.raises(CompgenError, match=r"set twice in one file \(lines 1 and 3\)") as caught:
        then(cfg, "setp trtkins.z-offset 1\n\nsetp trtkins.z-offset 2\n", "edit")
    assert caught.value.where == "edit:3"


def test_a_linear_joints_trims_are_written_to_the_nanometre_and_an_angles_finer(seed_machine):
    """A joint table's trims, as LinuxCNC reads them from text: mm to 6 decimals (1 nm),
    degrees to 7 (0.00036″), and not the round-off of a coarser table."""
    fit = identify(seed_machine, [simulate(seed_machine, {**TRUTH, "EXX:p1": 20 * UM, "ECC:h2c": 3 * ARCSEC},
                                           generate(seed_machine, ["K4", "K1", "K2"]))],
                   [*location_model(seed_machine), "EXX:p1", "ECC:h2c", "ECC:h2s"])
    files = kinematics_edit(seed_machine, fit, "linuxcnc", None, "", "N", "0", "d", stem="N").files
    for suffix, decimals in ((".X.comp", 6), (".C.comp", 7)):
        rows = [ln.split() for ln in files[suffix].splitlines() if ln and not ln.startswith("#")]
        trims = [w for row in rows for w in row[1:]]
        assert max(len(w.partition(".")[2]) for w in trims) == decimals, (suffix, trims[:4])
        table = linuxcnc.read_comp(files[suffix], seed_machine, f"N{suffix}")
        assert np.abs(table.values).max() > 10 ** -decimals


@pytest.mark.parametrize("ini, says", [
    # one INI key that two pins take: the correction moves them apart
    ("[TRT]\nR = 0.0\n", "one place sets two values that now differ"),
    # the value's own line continued by a backslash (inivar joins it)
    ("[TRT]\nR = 0.\\\n0\n", "the value is on a line that a backslash joins to the next"),
])
def test_a_pin_compgen_cannot_change_alone_is_refused_at_its_line(tmp_path, trt, seed_machine, ini, says):
    """The edit changes a value where the configuration sets it, or says why it cannot:
    never one pin's change carried silently into another, never half of a joined line."""
    module, nominal = trt
    two = "two" in says
    hal = (f"setp {module}.x-rot-point [TRT]R\n" + (f"setp {module}.y-rot-point [TRT]R\n" if two else "")
           + _setp(module, nominal, ["x-rot-point", *(["y-rot-point"] if two else [])]))
    state = _config(tmp_path, ini + "[HAL]\nHALFILE = trt.hal\n", trt__hal=hal)
    fit = identify(seed_machine, [simulate(seed_machine, TRUTH, generate(seed_machine, ["K4", "K1", "K2"]))])
    with pytest.raises(CompgenError, match=says) as got:
        _edit_ini(seed_machine, fit, state, tmp_path)
    assert "m.ini:2" in str(got.value), got.value


@pytest.mark.parametrize("comp, says", [
    ("# a table to come\n", "the joint table holds no line of three numbers"),
    ("-100 0 0\n0 1e999 0\n100 0 0\n", "'0 1e999 0' is not three finite numbers"),
    ("".join(f"{k} 0 0\n" for k in range(-150, 151)), "the joint table has 301 lines; LinuxCNC takes 256"),
])
def test_a_joint_table_linuxcnc_would_refuse_or_misread_is_refused(tmp_path, trt, seed_machine, comp, says):
    """usrmotLoadComp reads triplets up to the first other line, at most 256: an empty table,
    an infinite trim, a table longer than LinuxCNC holds are refused with the INI line."""
    module, nominal = trt
    state = _config(tmp_path, "[HAL]\nHALFILE = a.hal\n[JOINT_1]\nCOMP_FILE = y.comp\nCOMP_FILE_TYPE = 1\n",
                    a__hal=_setp(module, nominal), y__comp=comp)
    with pytest.raises(CompgenError, match=re.escape(says)) as got:
        linuxcnc.loaded_joint_tables(seed_machine, state)
    assert "m.ini:4 (y.comp)" in str(got.value), got.value


def test_a_joint_table_read_back_must_say_whose_joint_it_is(seed_machine):
    """compgen's closing notes name the joint and its axis: a table without them, or naming
    a joint that is not the axis's in the trt module, is refused (it would replace another
    joint's table)."""
    with pytest.raises(CompgenError, match="without compgen's closing notes"):
        linuxcnc.read_comp("-100 0 0\n100 0 0\n", seed_machine, "y.comp")
    note = "# compgen joint compensation for LinuxCNC: joint 2 = Y (mm)\n"
    with pytest.raises(CompgenError, match="the table says joint 2 = Y; the trt module's joint of Y is 1"):
        linuxcnc.read_comp("-100 0 0\n100 0 0\n" + note, seed_machine, "y.comp")



@pytest.mark.parametrize("stop, runs_b", [("HALFILE =", False), ("HALFILE ", False), ("HALFILE= ", False),
                                          ("HALFILE", True)])
def test_halfiles_are_read_up_to_the_first_without_a_value_as_linuxcncs_loop_reads_them(tmp_path, trt, stop,
                                                                                       runs_b):
    """The start script asks inivar for HALFILE 1, 2, ... and stops at the first empty
    answer: a HALFILE without a value ends the list, and the files after it never run. A bare
    "HALFILE" (no blank, no =) is no HALFILE to inivar: the list goes on. Where LinuxCNC's
    inivar is installed, it is asked too."""
    module, nominal = trt
    state = _config(tmp_path, f"[HAL]\nHALFILE = a.hal\n{stop}\nHALFILE = b.hal\n",
                    a__hal=_setp(module, nominal), b__hal=f"setp {module}.x-rot-point 5\n")
    assert _pins(state, module)["x-rot-point"] == (5.0 if runs_b else nominal["x-rot-point"])
    if shutil.which("inivar"):
        told = []
        for num in (1, 2, 3):
            got = subprocess.run(["inivar", "-ini", str(tmp_path / "m.ini"), "-sec", "HAL", "-var", "HALFILE",
                                  "-num", str(num)], capture_output=True, text=True)
            if got.returncode or not got.stdout.strip():
                break                       # where linuxcnc's loop ends
            told.append(got.stdout.strip())
        assert told == (["a.hal", "b.hal"] if runs_b else ["a.hal"]), told


@pytest.mark.parametrize("off_mm, refused", [(0.08, False), (0.15, True), (-0.15, True)])
def test_a_held_pin_beyond_the_limits_is_another_machines_configuration(trt, seed_machine, off_mm, refused):
    """--current with x-rot-point 80 µm from the machine file's value passes; 150 µm (either
    way) is beyond [limits] offset_um = 100 µm: refused at its line, never built on."""
    module, nominal = trt
    held = nominal["x-rot-point"] + off_mm
    hal = _setp(module, nominal, ["x-rot-point"]) + f"setp {module}.x-rot-point {held:.6f}\n"
    fit = identify(seed_machine, [simulate(seed_machine, TRUTH, generate(seed_machine, ["K4", "K1", "K2"]))])
    if not refused:
        kinematics_edit(seed_machine, fit, "linuxcnc", hal, "k.hal", "N", "0", "d")
        return
    said = (f"{module}.x-rot-point = {off_mm:g} mm, {off_mm:+.4f} mm from the machine file's 0: beyond its "
            "[limits] offset_um 100 µm")
    with pytest.raises(CompgenError, match=re.escape(said)) as got:
        kinematics_edit(seed_machine, fit, "linuxcnc", hal, "k.hal", "N", "0", "d")
    assert str(got.value.where) == f"k.hal:{len(nominal)}", got.value.where


# --- the configuration as LinuxCNC's start script reads it, corners included ---------------

@pytest.mark.parametrize("ini, files, says", [
    # handle_includes copies the INI through bash's `while read a b`: a last line without a line
    # end is dropped, a backslash is taken as an escape
    ("[HAL]\nHALFILE = a.hal\n#INCLUDE x.inc\n[KINS]\nX = 1", {"a__hal": "", "x__inc": "[TRT]\n"},
     r"m.ini:5: the INI's last line has no line end: with #INCLUDE"),
    ("[HAL]\nHALFILE = a\\b.hal\n#INCLUDE x.inc\n", {"x__inc": "[TRT]\n"},
     r"m.ini:2: a backslash in the INI: with #INCLUDE"),
    # cat of the included file, then its end marker on the same line
    ("[HAL]\nHALFILE = a.hal\n#INCLUDE x.inc\n", {"a__hal": "", "x__inc": "[TRT]\nX = 1"},
     r"x.inc:2: the included file's last line has no line end"),
    # IFS='\ ' read CFGFILE ARGS: a tab is part of the file's name
    ("[HAL]\nHALFILE = a.hal\targ\n", {"a__hal": ""}, r"m.ini:2: HALFILE a.hal\targ: no such file"),
    # halcmd would source a file that is running without end
    ("[HAL]\nHALFILE = a.hal\n", {"a__hal": "source b.hal\n", "b__hal": "source a.hal\n"},
     r"b.hal:1: source a.hal runs a file that is still running"),
    ("[HAL]\nHALFILE = a.hal\n", {"a__hal": "source a.hal\n"}, r"a.hal:1: source a.hal runs a file"),
])
def test_the_start_scripts_corners_are_refused_with_their_line(tmp_path, ini, files, says):
    with pytest.raises(CompgenError, match=says):
        _config(tmp_path, ini, **files)


def test_without_include_the_ini_is_read_as_inivar_reads_it(tmp_path, trt):
    """handle_includes copies nothing where no line starts with #INCLUDE: inivar reads the
    last line without a line end, and a HALFILE's arguments after a space are arguments."""
    module, nominal = trt
    state = _config(tmp_path, "[HAL]\nHALFILE = a.hal arg1\n[KINS]\nX = 1", a__hal=_setp(module, nominal))
    assert _pins(state, module) == pytest.approx(nominal)


def test_two_changed_files_of_one_name_are_written_to_two_files(tmp_path, trt, seed_machine):
    """a/p.hal and b/p.hal each set pins the edit changes: both are written, under two names,
    each named by the line that named its source, and each holds its own correction."""
    module, nominal = trt
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first = {n: v for n, v in nominal.items() if n.endswith("rot-point")}
    second = {n: v for n, v in nominal.items() if n not in first}
    (tmp_path / "a" / "p.hal").write_text("".join(f"setp {module}.{n} {v:.6f}\n" for n, v in first.items()))
    (tmp_path / "b" / "p.hal").write_text("".join(f"setp {module}.{n} {v:.6f}\n" for n, v in second.items()))
    state = _config(tmp_path, "[HAL]\nHALFILE = a/p.hal\nHALFILE = b/p.hal\n")
    fit = identify(seed_machine, [simulate(seed_machine, TRUTH, generate(seed_machine, ["K4", "K1", "K2"]))],
                   location_model(seed_machine))
    out = _edit_ini(seed_machine, fit, state, tmp_path)
    assert {".ini", ".p.hal", ".2.p.hal"} <= set(out.files), sorted(out.files)
    for suffix, text in out.files.items():
        (tmp_path / f"N{suffix}").write_text(text)
    assert "HALFILE = N.p.hal\nHALFILE = N.2.p.hal" in out.files[".ini"]
    held = _pins(read_state(str(tmp_path / "N.ini")), module)
    alone = kinematics_edit(seed_machine, fit, "linuxcnc", None, "", "H", "0", "d").files[".hal"]
    want = {**nominal, **{m[1]: float(m[2])
                          for m in re.finditer(rf"(?m)^setp {re.escape(module)}\.(\S+) (\S+)", alone)}}
    assert held == pytest.approx(want, abs=1e-9) and held != pytest.approx(nominal, abs=1e-6)


@pytest.mark.parametrize("stem", ["K#1", "K 1", "K$1", "K[1]"])
def test_an_output_name_halcmd_cannot_carry_is_refused(tmp_path, trt, seed_machine, stem):
    module, nominal = trt
    state = _config(tmp_path, "[HAL]\nHALFILE = a.hal\n", a__hal=_setp(module, nominal))
    fit = identify(seed_machine, [simulate(seed_machine, TRUTH, generate(seed_machine, ["K4", "K1", "K2"]))],
                   location_model(seed_machine))
    with pytest.raises(CompgenError, match="start script and halcmd cannot carry this name"):
        kinematics_edit(seed_machine, fit, "linuxcnc", state, "m.ini", "N", "0", "d", stem=stem,
                        folder=str(tmp_path))


def test_the_file_the_notes_name_is_the_file_written(tmp_path, trt, seed_machine):
    """-o KIN.hal with an INI as --current would put the configuration to start into a .hal
    file while the notes say to start KIN.ini: refused, nothing written."""
    module, nominal = trt
    _config(tmp_path, "[HAL]\nHALFILE = a.hal\n", a__hal=_setp(module, nominal))
    machine = tmp_path / "m.toml"
    machine.write_text(SEED_MACHINE_TEXT.replace('controller = "itnc530"', 'controller = "linuxcnc"'))
    data = tmp_path / "d.csv"
    m = load_machine(machine)
    data.write_text(format_rtest(m, simulate(m, TRUTH, generate(m, ["K4", "K1", "K2"]))))
    assert run("fit", "--machine", machine, data, "-o", tmp_path / "f.json")[0] == 0
    before = sorted(p.name for p in tmp_path.iterdir())
    code, _, err = run("kinematics", "--from", tmp_path / "f.json", "--current", tmp_path / "m.ini",
                       "-o", tmp_path / "KIN.hal")
    assert code == 2 and "-o KIN.hal: this edit's main file is a .ini file" in err and "KIN.ini" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


@pytest.mark.parametrize("comp, rows", [
    ("-100 0 0\n0 0.001 0.001 a note\n100 0 0\n", 3),          # sscanf ignores what follows the third
    ("-100 0 0\n0 0.001-0.001 0\n100 0 0\n", 3),               # "%lf %lf": no space needed between
    ("-100 0 0\n0 0.001 0.001" + " " * 300 + "x\n100 0 0\n", 2),  # a piece past 254 characters stops it
    ("-100 0 0\n0 0.001\n100 0 0\n", 1),
])
def test_a_joint_table_is_read_where_linuxcnc_reads_it_and_no_further(tmp_path, trt, seed_machine, comp,
                                                                       rows):
    module, nominal = trt
    state = _config(tmp_path, "[HAL]\nHALFILE = a.hal\n[JOINT_1]\nCOMP_FILE = y.comp\nCOMP_FILE_TYPE = 1\n",
                    a__hal=_setp(module, nominal), y__comp=comp)
    ((fwd, _),) = linuxcnc.loaded_joint_tables(seed_machine, state).values()
    assert len(fwd.grid) == rows, fwd.grid


def test_a_joint_table_number_compgen_cannot_read_as_linuxcnc_does_is_refused(tmp_path, trt, seed_machine):
    module, nominal = trt
    state = _config(tmp_path, "[HAL]\nHALFILE = a.hal\n[JOINT_1]\nCOMP_FILE = y.comp\nCOMP_FILE_TYPE = 1\n",
                    a__hal=_setp(module, nominal), y__comp="-100 0 0\n0 0x1p-10 0\n100 0 0\n")
    with pytest.raises(CompgenError, match="hexadecimal"):
        linuxcnc.loaded_joint_tables(seed_machine, state)


def test_a_long_machine_name_makes_a_configuration_compgen_reads_back(tmp_path, trt, seed_machine):
    """The name goes into every file's header: a 300-character one made a KIN.ini whose line
    compgen's own reader (and inivar) refuse; the header lines are cut to the line read."""
    from dataclasses import replace
    module, nominal = trt
    machine = replace(seed_machine, name="Machine " + "x" * 292)
    state = _config(tmp_path, "[HAL]\nHALFILE = a.hal\n", a__hal=_setp(module, nominal))
    fit = identify(machine, [simulate(machine, TRUTH, generate(machine, ["K4", "K1", "K2"]))],
                   location_model(machine))
    out = _edit_ini(machine, fit, state, tmp_path)
    for suffix, text in out.files.items():
        (tmp_path / f"N{suffix}").write_text(text)
    assert max(len(ln) for ln in out.files[".ini"].splitlines()) <= 255
    assert _pins(read_state(str(tmp_path / "N.ini")), module) != pytest.approx(nominal, abs=1e-6)


def test_an_ini_whose_hal_section_comes_from_an_include_is_read_as_the_configuration(tmp_path, trt,
                                                                                   seed_machine):
    """An INI whose [HAL] stands in an included file was taken for a HAL file and refused."""
    module, nominal = trt
    state = _config(tmp_path, "[EMC]\nVERSION = 1.1\n#INCLUDE hal.inc\n", hal__inc="[HAL]\nHALFILE = a.hal\n",
                    a__hal=_setp(module, nominal))
    assert _pins(state, module) == pytest.approx(nominal)
