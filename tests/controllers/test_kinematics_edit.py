"""Kinematics edits: golden files, round trip, the closed loop in simulation, refusals."""

import re

import numpy as np
import pytest
from conftest import ARCSEC, ROOT, SEED_MACHINE, TABLE4, UM, run

from compgen.controllers import heidenhain, sinumerik
from compgen.controllers.correction import nominal_lines, plan
from compgen.controllers.kinematics import kinematics_edit
from compgen.controllers.registry import read_edits
from compgen.data.rtest import RTestData
from compgen.data.simulate import simulate
from compgen.errors import CompgenError
from compgen.model.effects import location_model
from compgen.model.kinematics import Model
from compgen.model.paths import generate
from compgen.model.poses import Poses
from compgen.statistics.identify import identify

CURRENT_TAB = (ROOT / "examples" / "itnc530-current.TAB").read_text()
CURRENT_CARR = (ROOT / "examples" / "bc-tcarr-current.txt").read_text()
DATE = "2026-11-24"
NOISE_UM = 0.5
SETUP = ["XOW", "YOW", "ZOW"]
BC_TRUTH = {"XOW": 5 * UM, "YOW": -8 * UM, "ZOW": 12 * UM, "XOB": 15 * UM, "ZOB": -20 * UM,
            "AOB": 6 * ARCSEC, "COB": -9 * ARCSEC, "XOC": -7 * UM, "YOC": 11 * UM,
            "AOC": 4 * ARCSEC, "BOC": -5 * ARCSEC, "ECC:h2c": 3 * ARCSEC, "EYY:p1": 8 * UM}


def _fit(machine, truth, model=None, noise=0.0, seed=1):
    poses = generate(machine, ["K4", "K1", "K2"])
    data = simulate(machine, truth, poses, noise, np.random.default_rng(seed))
    return identify(machine, [data], model), poses


@pytest.fixture(scope="module")
def seed_fit(seed_machine):
    return _fit(seed_machine, TABLE4)[0]


@pytest.fixture(scope="module")
def bc_fit(bc_machine):
    model = [*location_model(bc_machine), "ECC:h2c", "ECC:h2s", "EYY:p1"]
    return _fit(bc_machine, BC_TRUTH, model)[0]


@pytest.mark.parametrize("controller", ["itnc530", "tnc640", "linuxcnc"])
def test_heidenhain_and_linuxcnc_outputs_match_golden_files(seed_machine, seed_fit, controller, golden):
    current = CURRENT_TAB if controller == "itnc530" else None
    emitted = kinematics_edit(seed_machine, seed_fit, controller, current, "current.TAB", "KIN",
                              "0.1.0", DATE)
    for suffix, text in emitted.files.items():
        golden(f"ac-trunnion-itnc530/{controller}/kinematics{suffix}", text)


def test_sinumerik_outputs_match_golden_files(bc_machine, bc_fit, golden):
    emitted = kinematics_edit(bc_machine, bc_fit, "sinumerik840d", CURRENT_CARR, "current", "KIN",
                              "0.1.0", DATE)
    assert set(emitted.files) == {".MPF", "_RESTORE.MPF", "_CEC.INI", "_CEC_RESTORE.INI", "_SIGN.MPF"}
    for suffix, text in emitted.files.items():
        golden(f"bc-table-sinumerik840d/sinumerik840d/kinematics{suffix}", text)


def test_heidenhain_round_trip(seed_machine, seed_fit):
    p = plan(seed_machine, seed_fit)
    emitted = kinematics_edit(seed_machine, seed_fit, "itnc530", CURRENT_TAB, "c", "KIN", "0.1.0", DATE)
    for text in (emitted.files[".TAB"], emitted.files[".txt"]):
        got = heidenhain.read_lines(text, seed_machine, nominal_lines(seed_machine))
        for axis, line in p.lines.items():
            np.testing.assert_allclose(got[axis].offset, line.offset, atol=0.5e-5)  # 5 decimals, mm
            np.testing.assert_allclose(got[axis].tilt, line.tilt, atol=np.radians(0.5e-7))


def test_sinumerik_round_trip(bc_machine, bc_fit):
    p = plan(bc_machine, bc_fit)
    emitted = kinematics_edit(bc_machine, bc_fit, "sinumerik840d", CURRENT_CARR, "c", "KIN", "0.1.0", DATE)
    got = sinumerik.read_lines(emitted.files[".MPF"], bc_machine, sinumerik.read_carr(CURRENT_CARR, "c", 1),
                               nominal_lines(bc_machine))
    for axis, line in p.lines.items():
        np.testing.assert_allclose(got[axis].offset, line.offset, atol=1e-5)    # l2 + l3, rounded
        np.testing.assert_allclose(got[axis].tilt, line.tilt, atol=1e-9)
    restore = sinumerik.read_carr(emitted.files["_RESTORE.MPF"], "r", 1)
    assert all(restore[n] == v for n, v in sinumerik.read_carr(CURRENT_CARR, "c", 1).items())


def _setup_only_rms(machine, poses, reading):
    """RMS left once the ball's set-up offset is fitted: what a kinematics edit can remove."""
    return identify(machine, [RTestData(poses, reading)], SETUP).residual["rms_um"]


def _closed_loop(machine, truth, model, controller, current, rng):
    poses = generate(machine, ["K4", "K1", "K2"])
    pre = simulate(machine, truth, poses, NOISE_UM, rng)
    fit = identify(machine, [pre], model)
    emitted = kinematics_edit(machine, fit, controller, current, "current", "KIN", "0.1.0", DATE)
    # apply the files, the way the control would
    loaded = {k: v for k, v in emitted.files.items() if k in (".MPF", "_CEC.INI", ".TAB")}
    q = read_edits(machine, loaded, current).drive(machine, poses)
    true = Model(machine, list(truth))
    post_poses = Poses(q, poses.ball, poses.t, poses.path)
    noise = rng.normal(0, NOISE_UM * 1e-3, q[:, :3].shape)
    post = true.relative(post_poses, np.array(list(truth.values()))) + noise
    return (_setup_only_rms(machine, poses, pre.deviation), _setup_only_rms(machine, post_poses, post))


def test_closed_loop_itnc530_brings_the_seed_machine_to_the_noise(seed_machine, rng):
    before, after = _closed_loop(seed_machine, TABLE4, None, "itnc530", CURRENT_TAB, rng)
    assert before > 10.0                                       # µm: Table 4 is far from noise
    assert after == pytest.approx(NOISE_UM, rel=0.05), (before, after)


def test_closed_loop_sinumerik_with_cec_brings_the_bc_machine_to_the_noise(bc_machine, bc_fit, rng):
    before, after = _closed_loop(bc_machine, BC_TRUTH, bc_fit.model, "sinumerik840d", CURRENT_CARR, rng)
    assert before > 5.0
    assert after == pytest.approx(NOISE_UM, rel=0.05), (before, after)


def test_corrections_beyond_the_plausibility_limits_are_refused(seed_machine):
    big = {k: 10 * v for k, v in TABLE4.items()}          # 325 µm, 123″
    fit = _fit(seed_machine, big)[0]
    with pytest.raises(CompgenError, match="beyond the plausibility limits"):
        kinematics_edit(seed_machine, fit, "itnc530", CURRENT_TAB, "c", "KIN", "0.1.0", DATE)
    forced = kinematics_edit(seed_machine, fit, "itnc530", CURRENT_TAB, "c", "KIN", "0.1.0", DATE,
                             force=True)
    assert ".TAB" in forced.files




@pytest.fixture
def fit_file(tmp_path):
    truth = tmp_path / "t.json"
    truth.write_text('{"parameters": {"XOC": {"value": 3, "unit": "um"}, '
                     '"BOA": {"value": 5, "unit": "arcsec"}}}')
    data = tmp_path / "d.csv"
    assert run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "-o", data)[0] == 0
    fit = tmp_path / "fit.json"
    assert run("fit", "--machine", SEED_MACHINE, data, "-o", fit)[0] == 0
    return fit


def test_cli_writes_table_change_list_and_sign_check(tmp_path, fit_file):
    current = tmp_path / "cur.TAB"
    current.write_text(CURRENT_TAB)
    out = tmp_path / "new.TAB"
    code, stdout, err = run("kinematics", "--from", fit_file, "--current", current, "-o", out)
    assert code == 0, err
    assert "X0C" in out.read_text() and "(new row)" in stdout
    assert (tmp_path / "new.txt").exists() and (tmp_path / "new_SIGN.H").exists()
    assert "sign check" in stdout


@pytest.mark.parametrize("args, expected", [
    (["--controller", "fanuc"], "unknown controller 'fanuc'"),
    (["--controller", "sinumerik840d"], "needs --current"),
    (["--controller", "tnc640", "--current", ROOT / "examples" / "itnc530-current.TAB"],
     "configuration editor"),
    (["--measured-with", ROOT / "examples" / "itnc530-current.TAB"], "Give --current as well"),
])
def test_cli_refusals(tmp_path, fit_file, args, expected):
    out = tmp_path / "k.txt"
    code, _, err = run("kinematics", "--from", fit_file, *args, "-o", out)
    assert code == 2 and expected in err, err
    assert not out.exists()


def test_cli_existing_output_and_bad_current_table(tmp_path, fit_file):
    out = tmp_path / "k.txt"
    out.write_text("mine")
    code, _, err = run("kinematics", "--from", fit_file, "-o", out)
    assert code == 2 and "--force" in err and out.read_text() == "mine"
    assert not (tmp_path / "k_SIGN.H").exists()
    header = "NR  KEY       AXIS  COORD        DOC\n"
    for row, expected in (("0   Trans     Z     abc          x", "not a number"),
                          ("0 Trans Z +1 x", "not a kinematics key")):
        bad = tmp_path / "bad.TAB"
        bad.write_text(f"BEGIN X.TAB MM\n{header}{row}\n[END]\n")
        code, _, err = run("kinematics", "--from", fit_file, "--current", bad, "-o", tmp_path / "n.TAB")
        assert code == 2 and "bad.TAB:3" in err and expected in err, err
    (tmp_path / "none.TAB").write_text(f"BEGIN X.TAB MM\n{header}0   MachAxis  Z\n[END]\n")
    code, _, err = run("kinematics", "--from", fit_file, "--current", tmp_path / "none.TAB", "-o",
                       tmp_path / "n2.TAB")
    assert code == 2 and "no 'MachAxis A' row" in err, err


def test_every_controller_file_is_ascii(seed_machine, seed_fit, bc_machine, bc_fit):
    for emitted in (kinematics_edit(seed_machine, seed_fit, "itnc530", CURRENT_TAB, "c", "K", "0", DATE),
                    kinematics_edit(bc_machine, bc_fit, "sinumerik840d", CURRENT_CARR, "c", "K", "0", DATE)):
        for text in emitted.files.values():
            text.encode("ascii")


@pytest.mark.parametrize("controller", ["itnc530", "linuxcnc"])
def test_sign_check_promises_what_the_loaded_edit_does(seed_machine, seed_fit, controller):
    """The expected reading changes printed with an edit, against the change the edit makes
    when its files are read back and loaded, pose by pose (µm, two decimals printed)."""
    from compgen.controllers.programs import read_program
    emitted = kinematics_edit(seed_machine, seed_fit, controller, CURRENT_TAB if controller == "itnc530"
                              else None, "c", "KIN", "0", DATE)
    main = emitted.files[".TAB" if controller == "itnc530" else ".hal"]
    held = read_edits(seed_machine, {"edit": main}, None)
    _, _, rot = read_program(emitted.files[f"_SIGN{'.H' if controller == 'itnc530' else '.ngc'}"],
                             seed_machine, controller)
    listed = [ln for ln in emitted.notes if re.match(r"S\d+_", ln)]
    assert len(listed) == len(rot)
    truth = Model(seed_machine, list(seed_fit.model))
    values = np.array([seed_fit.parameters[n].value for n in seed_fit.model])
    from compgen.model.kinematics import inverse
    rotary = np.radians(rot)
    ball = np.broadcast_to(seed_machine.ball, (len(rot), 3))
    blank = (np.zeros(len(rot)), np.full(len(rot), "", dtype=object))
    before = truth.relative(Poses(inverse(seed_machine, rotary, ball), ball, *blank), values)
    moved = held.drive(seed_machine, Poses(inverse(seed_machine, rotary, ball), ball, *blank))
    after = truth.relative(Poses(moved, ball, *blank), values)
    for line, change in zip(listed, (after - before) * 1e3, strict=True):
        printed = [float(v) for v in re.findall(r"d[XYZ] ([+-]\d+\.\d+)", line)]
        # printed to 0.01 µm (±0.005) from values the table rounds to 0.01 µm (±0.005)
        np.testing.assert_allclose(printed, change, atol=0.011, err_msg=line)


def test_a_linuxcnc_edit_sets_a_netted_pin_through_its_signal(seed_machine, seed_fit):
    """setp on a pin the configuration nets stops LinuxCNC; compgen must write sets."""
    from compgen.controllers.linuxcnc import read_hal
    hal = ("loadrt xyzac-trt-kins\nnet zrot => xyzac-trt-kins.z-rot-point\nsets zrot 29.8\n"
           "net tool-offset motion.tooloffset.z => xyzac-trt-kins.tool-offset\n"
           + "".join(f"setp xyzac-trt-kins.{p} {v}\n" for p, v in (
               ("x-rot-point", 0.001), ("y-rot-point", -0.002), ("y-offset", 0.0), ("z-offset", -29.8))))
    values, signal = read_hal(hal, "xyzac-trt-kins", "h")
    assert signal == {"z-rot-point": "zrot", "tool-offset": "tool-offset"}
    assert values == {"x-rot-point": 0.001, "y-rot-point": -0.002, "y-offset": 0.0, "z-offset": -29.8,
                      "z-rot-point": 29.8}
    out = kinematics_edit(seed_machine, seed_fit, "linuxcnc", hal, "h", "KIN", "0", "d").files[".hal"]
    z = plan(seed_machine, seed_fit).lines["C"].offset[2]
    assert re.search(rf"(?m)^sets zrot {29.8 + z:.6f}\s+# was 29.8$", out), out   # as the file wrote it
    assert re.search(r"(?m)^setp xyzac-trt-kins\.x-rot-point ", out)
    assert not re.search(r"(?m)^setp \S+z-rot-point", out)
    with pytest.raises(CompgenError, match="refuses to start"):
        read_hal(hal + "setp xyzac-trt-kins.z-rot-point 29.8\n", "xyzac-trt-kins", "h")


def test_the_marker_names_the_values_as_written_not_their_last_bits(seed_fit):
    """Another CPU's BLAS kernel changes a fit's last bits, never its marker; a change any
    output could print (1 nm, 1e-9 rad) changes it."""
    from dataclasses import replace

    def moved(by):
        params = {n: replace(e, value=by(e.value, e.unit)) for n, e in seed_fit.parameters.items()}
        return replace(seed_fit, parameters=params).marker

    assert moved(lambda v, u: np.nextafter(v, np.inf)) == seed_fit.marker
    assert moved(lambda v, u: v * (1 + 4e-16)) == seed_fit.marker
    assert moved(lambda v, u: v + (1e-6 if u == "mm" else 1e-9)) != seed_fit.marker


@pytest.mark.parametrize("controller", ["itnc530", "sinumerik840d", "linuxcnc"])
def test_every_sign_check_pose_expects_a_change_an_rtest_sees(seed_machine, seed_fit, bc_machine, bc_fit,
                                                              controller):
    """A pose whose reading the edit does not change (the zero pose, where TCPM holds the
    nest on the ball whatever the pivots) cannot show a sign: none is in the program."""
    machine, fit, current = {"itnc530": (seed_machine, seed_fit, CURRENT_TAB),
                             "sinumerik840d": (bc_machine, bc_fit, CURRENT_CARR),
                             "linuxcnc": (seed_machine, seed_fit, None)}[controller]
    notes = kinematics_edit(machine, fit, controller, current, "c", "KIN", "0", DATE).notes
    expected = [n for n in notes if re.match(r"S\d+_", n)]
    assert expected, notes
    for line in expected:
        values = [abs(float(v)) for v in re.findall(r"d[XYZ] ([+-][\d.]+)", line)]
        assert max(values) >= 1.0, line


def test_a_sinumerik_edit_needs_the_fine_offsets_switched_on_and_within_their_limit(tmp_path, bc_fit):
    """compgen writes fine offsets: they act only with SD42974 = 1, within MD20188. The
    machine file says so, or the edit is refused with the key to set; a limit given is kept."""
    from conftest import BC_MACHINE

    from compgen.configuration.machine_file import load_machine
    text = BC_MACHINE.read_text()
    cases = {"unsaid": re.sub(r"(?m)^fine_correction = .*$", "", text),
             "off": text.replace("fine_correction = true", "fine_correction = false"),
             "tight": text.replace("fine_correction = true", "fine_correction = true\nfine_limit_mm = 0.001")}
    expect = {"unsaid": "does not say whether it is", "off": "says it is 0", "tight": "beyond MD20188"}
    for name, body in cases.items():
        (tmp_path / f"{name}.toml").write_text(body)
        machine = load_machine(tmp_path / f"{name}.toml")
        with pytest.raises(CompgenError, match=expect[name]):
            kinematics_edit(machine, bc_fit, "sinumerik840d", CURRENT_CARR, "c", "KIN", "0", DATE)
    from compgen.reports.checklist import checklist
    steps = checklist(load_machine(BC_MACHINE), tmp_path)
    assert any("SD42974" in s.note for s in steps)


def test_an_implausible_current_state_is_refused_with_its_file_and_line(seed_machine, seed_fit, bc_machine,
                                                                        bc_fit):
    """Every control's current state as iTNC's is: finite, one assignment per key, pivots and
    fine offsets within the machine file's [limits] — refused with the file and line."""
    lines = CURRENT_CARR.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("$TC_CARR44["))
    metre = "\n".join(lines[:k] + ["$TC_CARR44[1]=1000"] + lines[k + 1:])
    with pytest.raises(CompgenError, match=rf"^c:{k + 1}: \$TC_CARR44\[1\] = 1000 mm: a fine offset beyond"):
        kinematics_edit(bc_machine, bc_fit, "sinumerik840d", metre, "c", "KIN", "0", DATE)
    twice = CURRENT_CARR + "\n" + lines[k] + "\n"
    with pytest.raises(CompgenError, match=r"\$TC_CARR44\[1\] is assigned twice"):
        kinematics_edit(bc_machine, bc_fit, "sinumerik840d", twice, "c", "KIN", "0", DATE)
    # the record's kind: a head's record (T) is another chain than the table's (P)
    assert '$TC_CARR23[1]="P"' in CURRENT_CARR
    assert kinematics_edit(bc_machine, bc_fit, "sinumerik840d", CURRENT_CARR.replace('="P"', '="p"'), "c",
                           "KIN", "0", DATE).files[".MPF"]
    k23 = next(i for i, ln in enumerate(lines) if ln.startswith("$TC_CARR23["))
    with pytest.raises(CompgenError, match=rf'^c:{k23 + 1}: \$TC_CARR23\[1\] = "T": a record of kind T; the '
                                           r"machine file's rotary axes make a kind P record \(table\)"):
        kinematics_edit(bc_machine, bc_fit, "sinumerik840d", CURRENT_CARR.replace('="P"', '="T"'), "c", "KIN",
                        "0", DATE)
    from compgen.controllers import linuxcnc
    module, tilt, c = linuxcnc.trt_module(seed_machine)
    nominal = linuxcnc.nominal_pins(seed_machine, tilt, c)
    hal = "\n".join(f"setp {module}.{n} {v:.6f}" for n, v in nominal.items()) + "\n"
    off = hal.replace(f"setp {module}.x-rot-point {nominal['x-rot-point']:.6f}",
                      f"setp {module}.x-rot-point {nominal['x-rot-point'] + 1:.6f}")
    with pytest.raises(CompgenError, match=r"^h:1: xyzac-trt-kins.x-rot-point = .* \+1\.0000 mm from the"):
        kinematics_edit(seed_machine, seed_fit, "linuxcnc", off, "h", "KIN", "0", DATE)
    with pytest.raises(CompgenError, match=r"x-rot-point is set twice in one file \(lines 1 and \d+\)"):
        kinematics_edit(seed_machine, seed_fit, "linuxcnc", hal + hal.splitlines()[0] + "\n", "h", "KIN", "0",
                        DATE)
    assert kinematics_edit(seed_machine, seed_fit, "linuxcnc", hal, "h", "KIN", "0", DATE).files[".hal"]


def test_an_edit_of_a_long_oem_table_says_the_reported_entry_limit(tmp_path, fit_file):
    """An OEM table of 54 entries passes an edit that adds its rows (with squareness more): the
    notes say the table holds more than the 50 entries a description is reported to take
    (unconfirmed, U19); a short table's edit says nothing of it."""
    rows = CURRENT_TAB.splitlines()
    at = next(i for i, ln in enumerate(rows) if "MachBase" in ln)
    padded = rows[:at] + [f"0   Trans     X     +0           OEM element {k}" for k in range(45)] + rows[at:]
    renumbered, n = [], 0
    for ln in padded:
        if re.match(r"^\d+\s", ln):
            ln = f"{n:<4}{ln.split(None, 1)[1]}"        # NR in its column, the rest as it stood
            n += 1
        renumbered.append(ln)
    (tmp_path / "long.TAB").write_text("\n".join(renumbered) + "\n")
    code, out, err = run("kinematics", "--from", fit_file, "--current", tmp_path / "long.TAB", "-o",
                         tmp_path / "K.TAB")
    assert code == 0, err
    assert "more than the 50 a kinematics description is reported to take (UNCONFIRMED U19)" in out, out
    code, out, err = run("kinematics", "--from", fit_file, "--current",
                         ROOT / "examples" / "itnc530-current.TAB", "-o", tmp_path / "S.TAB")
    assert code == 0 and "U19" not in out, out + err
