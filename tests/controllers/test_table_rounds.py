"""Compensation tables over correction rounds: the control keeps the tables it holds, so a
second round's table must be the loaded one plus this round's residual (issue 20: a CEC or
joint table that held the residual alone put the machine back to uncorrected).

Truth is simulated, not written by the code under test: location errors, C's 2/rev angle
error (ECC:h2c, ECC:h2s) and Y's scale error (EYY:p1) on the B/C table. Round 1 is fitted
on data measured in the OEM's state, loaded as the control loads it (``read_edits``: a
table loaded into a place replaces the one there), measured again, fitted, and round 2
written over the state read. A third measurement with round 2 loaded must be at the noise.
"""

import re

import numpy as np
import pytest
from conftest import ARCSEC, ROOT, UM

from compgen.controllers import sinumerik
from compgen.controllers.base import joined
from compgen.controllers.correction import CompTable, compose_tables
from compgen.controllers.kinematics import kinematics_edit
from compgen.controllers.registry import read_edits
from compgen.data.simulate import simulate
from compgen.errors import CompgenError
from compgen.model.effects import location_model
from compgen.model.paths import generate
from compgen.statistics.identify import identify

NOISE_UM = 0.5
OEM_CARR = (ROOT / "examples" / "bc-tcarr-current.txt").read_text()
TRUTH = {"XOW": 5 * UM, "YOW": -8 * UM, "ZOW": 12 * UM, "XOB": 15 * UM, "ZOB": -20 * UM,
         "AOB": 6 * ARCSEC, "COB": -9 * ARCSEC, "XOC": -7 * UM, "YOC": 11 * UM,
         "AOC": 4 * ARCSEC, "BOC": -5 * ARCSEC, "ECC:h2c": 8 * ARCSEC, "ECC:h2s": -4 * ARCSEC,
         "EYY:p1": 15 * UM}
TABLES = ["ECC:h2c", "ECC:h2s", "EYY:p1"]
SETUP_NAMES = ["XOW", "YOW", "ZOW"]
# between the rounds the machine moves on (a bearing settles, the scale warms): round 2 must
# add its residual to round 1's tables, not replace them
LATER = {**TRUTH, "ECC:h2c": 11 * ARCSEC, "EYY:p1": 21 * UM, "YOC": 15 * UM}


def _measure(machine, held, rng, state, truth=TRUTH):
    poses = generate(machine, ["K4", "K1", "K2"])
    drive = None
    if held:
        loaded = read_edits(machine, held, state)
        def drive(p):
            return loaded.drive(machine, p)
    return simulate(machine, truth, poses, NOISE_UM, rng, drive)


def _edit(machine, data, current, name, model):
    fit = identify(machine, [data], model)
    return fit, kinematics_edit(machine, fit, "sinumerik840d", current, "current", name, "0", "d")


def test_compose_adds_on_the_loaded_grid_and_keeps_its_place():
    grid_old = CompTable("CEC table 3", "as loaded", "C", "C", 0.0, 360.0, tuple(np.linspace(0, 1, 37)), True,
                         "deg")
    new = CompTable("ECC", "C angle", "C", "C", 0.0, 360.0, tuple(np.full(37, 0.5)), True, "deg")
    other = CompTable("EYY", "Y scale", "Y", "Y", -200.0, 200.0, tuple(np.linspace(-1, 1, 5)), False, "mm")
    out = compose_tables([grid_old], [new, other])
    assert [t.effect for t in out] == ["CEC table 3", "EYY"]
    np.testing.assert_allclose(out[0].values, np.linspace(0, 1, 37) + 0.5)
    # a coarser loaded table: composed on the finer step, both interpolated as the control does
    coarse = CompTable("CEC table 0", "", "Y", "Y", -100.0, 100.0, (1.0, 2.0, 3.0), False, "mm")
    (got,) = compose_tables([coarse], [other])
    assert got.step == pytest.approx(100.0) and (got.start, got.stop) == (-200.0, 200.0)
    x = np.array([-200.0, -150.0, 0.0, 150.0, 200.0])
    np.testing.assert_allclose(got.at(x), coarse.at(x) + other.at(x))


def test_sinumerik_cec_second_round_holds_the_first_plus_the_residual(bc_machine):
    rng = np.random.default_rng(7)
    model = [*location_model(bc_machine), *TABLES]
    before = _measure(bc_machine, {}, rng, OEM_CARR)
    fit_a, a = _edit(bc_machine, before, OEM_CARR, "A", model)
    loaded_a = {"A.MPF": a.files[".MPF"], "A_CEC.INI": a.files["_CEC.INI"]}
    during = _measure(bc_machine, loaded_a, rng, OEM_CARR, LATER)
    # the state the control holds after round 1, read from the files a user would give
    state = joined([("A.MPF", a.files[".MPF"]), ("A_CEC.INI", a.files["_CEC.INI"])])
    fit_b, b = _edit(bc_machine, during, state, "B", model)
    after = _measure(bc_machine, {"B.MPF": b.files[".MPF"], "B_CEC.INI": b.files["_CEC.INI"]}, rng,
                     OEM_CARR, LATER)
    # loaded over round 1 (as the control does: B's tables take A's places) the same
    stacked = _measure(bc_machine, {**loaded_a, "B.MPF": b.files[".MPF"], "B_CEC.INI": b.files["_CEC.INI"]},
                       np.random.default_rng(9), OEM_CARR, LATER)
    rms = {k: identify(bc_machine, [d], ["XOW", "YOW", "ZOW"]).residual["rms_um"]
           for k, d in (("before", before), ("during", during), ("after", after), ("stacked", stacked))}
    print("CEC rounds, rms µm:", {k: round(v, 3) for k, v in rms.items()})
    assert rms["before"] > 10 * NOISE_UM and rms["during"] > 3 * NOISE_UM, rms
    assert rms["after"] == pytest.approx(NOISE_UM, rel=0.1), rms
    assert rms["stacked"] == pytest.approx(NOISE_UM, rel=0.1), rms
    # the composed tables are round 1's plus round 2's, place by place, to the file's rounding
    ta, tb = (sinumerik.read_cec(f.files["_CEC.INI"], bc_machine) for f in (a, b))
    assert [t.effect for t in ta] == [t.effect for t in tb]
    residual = {t.input: t for t in sinumerik.read_cec(
        kinematics_edit(bc_machine, fit_b, "sinumerik840d", OEM_CARR, "c", "R", "0", "d").files["_CEC.INI"],
        bc_machine)}
    for old, new in zip(ta, tb, strict=True):
        np.testing.assert_allclose(new.values, np.add(old.values, residual[old.input].values), atol=2e-6)
    # the old behaviour, the residual alone in A's places, leaves the machine far from corrected
    undone = _measure(bc_machine, {"B.MPF": b.files[".MPF"], "R_CEC.INI": kinematics_edit(
        bc_machine, fit_b, "sinumerik840d", OEM_CARR, "c", "R", "0", "d").files["_CEC.INI"]}, rng, OEM_CARR,
        LATER)
    assert identify(bc_machine, [undone], ["XOW", "YOW", "ZOW"]).residual["rms_um"] > 3 * NOISE_UM


def test_sinumerik_cec_restore_puts_back_the_tables_read(bc_machine):
    model = [*location_model(bc_machine), *TABLES]
    rng = np.random.default_rng(3)
    _, a = _edit(bc_machine, _measure(bc_machine, {}, rng, OEM_CARR), OEM_CARR, "A", model)
    state = joined([("carr.txt", a.files[".MPF"]), ("cec.ini", a.files["_CEC.INI"])])
    _, b = _edit(bc_machine, _measure(bc_machine, {}, rng, OEM_CARR), state, "B", model)
    cec_lines = [ln for ln in a.files["_CEC.INI"].splitlines() if ln.startswith("$AN_CEC")]
    restore = [ln for ln in b.files["_CEC_RESTORE.INI"].splitlines() if ln.startswith("$AN_CEC")]
    assert restore == cec_lines
    # the record's restore writes each value as the state wrote it
    def carr(text):
        return [ln for ln in text.splitlines() if ln.startswith("$TC_CARR")]
    assert carr(b.files["_RESTORE.MPF"]) == carr(a.files[".MPF"]) != carr(b.files[".MPF"])


@pytest.mark.parametrize("damage, says", [
    ("$AN_CEC_STEP[0]=10.000000\n", "assigned twice"),
    ("", "lacks $AN_CEC_STEP"),
    ("MAX=359", "do not span its 37 values in whole steps"),        # MAX not MIN + 36 steps
    ("MIN=400", "do not span"),                                      # MIN above MAX
    ("STEP=0", "do not span"),
    ("STEP=-10", "do not span"),
    ("STEP=9.7", "do not span"),
    ("VALUE", "do not span"),                                        # a 38th value
    ("MODULO=2", "$AN_CEC_IS_MODULO is 2"),
    ("STEP=1e-9", "do not span"),                                    # 2.6·10^11 points: counted, not made
    ("$AN_CEC_MIN[-1]=0\n", "is no CEC entry compgen reads"),        # a negative table is not skipped
    ("$AN_CEC[0,x]=0\n", "is no CEC entry compgen reads"),
])
def test_a_damaged_cec_state_is_refused_with_its_line(bc_machine, damage, says):
    model = [*location_model(bc_machine), *TABLES]
    _, a = _edit(bc_machine, _measure(bc_machine, {}, np.random.default_rng(1), OEM_CARR), OEM_CARR, "A",
                 model)
    cec = a.files["_CEC.INI"]
    key = {"MAX=359": ("$AN_CEC_MAX[0]=", "359"), "MIN=400": ("$AN_CEC_MIN[0]=", "400"),
           "STEP=0": ("$AN_CEC_STEP[0]=", "0"), "STEP=-10": ("$AN_CEC_STEP[0]=", "-10"),
           "STEP=9.7": ("$AN_CEC_STEP[0]=", "9.7"),
           "STEP=1e-9": ("$AN_CEC_STEP[0]=", "1e-9"), "MODULO=2": ("$AN_CEC_IS_MODULO[0]=", "2")}
    if damage in key:
        start, value = key[damage]
        cec = "\n".join(start + value if ln.startswith(start) else ln for ln in cec.splitlines())
    elif damage == "VALUE":
        cec = cec.replace("$AN_CEC_INPUT_AXIS[0]", "$AN_CEC[0,37]=0.0\n$AN_CEC_INPUT_AXIS[0]")
    else:
        cec = cec + damage if damage else "\n".join(ln for ln in cec.splitlines()
                                                     if not ln.startswith("$AN_CEC_STEP[0]"))
    with pytest.raises(CompgenError, match=re.escape(says)) as e:
        sinumerik.read_cec(joined([("carr", OEM_CARR), ("cec.ini", cec)]), bc_machine, "x")
    assert re.fullmatch(r"cec\.ini:\d+", str(e.value.where)), e.value.where      # its own file's line


def test_the_second_round_on_the_command_line_takes_both_files_as_current(tmp_path, monkeypatch):
    """The user's loop through the CLI: fit, edit, load (simulate --edit), measure, fit, edit
    with the record and the CEC file as --current, load, measure: at the noise."""
    import json

    from conftest import run

    from compgen.configuration.machine_file import load_machine
    from compgen.model.effects import effect_of_param
    monkeypatch.chdir(tmp_path)
    machine = load_machine("bc-table-sinumerik840d")
    for name, truth in (("t1.json", TRUTH), ("t2.json", LATER)):
        (tmp_path / name).write_text(json.dumps({"parameters": {
            n: {"value": v, "unit": effect_of_param(machine, n).unit} for n, v in truth.items()}}))
    (tmp_path / "carr.txt").write_text(OEM_CARR)
    m = ["--machine", "bc-table-sinumerik840d"]
    add = ["--add", "ECC:h2", "--add", "EYY:p1"]
    # every draw seeded: unseeded, the gate refused f1 in about 1 run of 13 (a chance periodic line
    # of 0.15 µm in the residual, see the note on issue 22) and the test failed at random
    steps = [["simulate", *m, "--truth", "t1.json", "--noise-um", NOISE_UM, "--seed", "1", "-o", "s1.csv"],
             ["fit", *m, "s1.csv", *add, "-o", "f1.json"],
             ["kinematics", "--from", "f1.json", "--current", "carr.txt", "-o", "A.MPF"],
             ["simulate", *m, "--truth", "t2.json", "--noise-um", NOISE_UM, "--seed", "2", "--edit", "A.MPF",
              "--edit", "A_CEC.INI", "--current", "carr.txt", "-o", "s2.csv"],
             ["fit", *m, "s2.csv", *add, "-o", "f2.json"],
             ["kinematics", "--from", "f2.json", "--current", "A.MPF", "--current", "A_CEC.INI",
              "-o", "B.MPF"],
             ["simulate", *m, "--truth", "t2.json", "--noise-um", NOISE_UM, "--seed", "3", "--edit", "B.MPF",
              "--edit", "B_CEC.INI", "--current", "carr.txt", "-o", "s3.csv"],
             ["fit", *m, "s3.csv", "--model", "XOW,YOW,ZOW", "-o", "f3.json"]]
    for step in steps:
        code, out, err = run(*step)
        assert code == 0, (step, out, err)
    sigma = [json.loads((tmp_path / f"f{k}.json").read_text())["residual"]["sigma_um"] for k in (2, 3)]
    assert sigma[1] == pytest.approx(NOISE_UM, rel=0.1), sigma
    code, _, err = run("kinematics", "--from", "f2.json", "--controller", "itnc530", "--current", "A.MPF",
                       "--current", "A_CEC.INI", "-o", "X.TAB")
    assert code == 2 and "reads its state from one file" in err, err


LINUX_TRUTH = {"XOW": 4 * UM, "YOW": -6 * UM, "ZOW": 9 * UM, "YOA": 18 * UM, "ZOA": -14 * UM,
               "XOC": 11 * UM, "YOC": -13 * UM, "ECC:h2c": 6 * ARCSEC, "ECC:h2s": -3 * ARCSEC,
               "EYY:p1": 12 * UM}
LINUX_LATER = {**LINUX_TRUTH, "ECC:h2c": 9 * ARCSEC, "EYY:p1": 18 * UM, "XOC": 15 * UM}


def test_linuxcnc_joint_tables_compose_through_the_ini(seed_machine, tmp_path):
    """LinuxCNC's second round reads the joints' COMP_FILEs the INI loads and writes each
    joint's table as the loaded one plus this round's; started with round 2's INI the
    machine is at the noise, and round 2's restore is round 1's configuration."""
    from compgen.controllers import linuxcnc
    from compgen.controllers.registry import read_state
    machine = seed_machine
    module, tilt, c = linuxcnc.trt_module(machine)
    nominal = linuxcnc.nominal_pins(machine, tilt, c)
    (tmp_path / "machine.hal").write_text("".join(f"setp {module}.{n} {v:.6f}\n" for n, v in nominal.items()))
    (tmp_path / "machine.ini").write_text(f"[KINS]\nKINEMATICS = {module}\n[HAL]\nHALFILE = core_sim.hal\n"
                                          "HALFILE = machine.hal\n[JOINT_1]\nTYPE = LINEAR\n"
                                          "[JOINT_4]\nTYPE = ANGULAR\n")
    model = [*(n for n in location_model(machine) if n[1] == "O" and n[0] in "XYZ"), *TABLES]
    rng = np.random.default_rng(11)
    poses = generate(machine, ["K4", "K1", "K2"])

    def measure(ini, truth):
        drive = None
        if ini:
            loaded = read_edits(machine, {ini: read_state(str(tmp_path / ini))}, None)
            def drive(p):
                return loaded.drive(machine, p)
        return simulate(machine, truth, poses, NOISE_UM, rng, drive)

    def edit(data, ini, stem):
        fit = identify(machine, [data], model)
        out = kinematics_edit(machine, fit, "linuxcnc", read_state(str(tmp_path / ini)), str(tmp_path / ini),
                              stem, "0", "d", stem=stem, folder=str(tmp_path))
        for suffix, text in out.files.items():
            (tmp_path / f"{stem}{suffix}").write_text(text)
        return fit, out

    fit_a, a = edit(measure(None, LINUX_TRUTH), "machine.ini", "A")
    assert set(a.files) >= {".ini", "_RESTORE.ini", ".C.comp", ".Y.comp"}
    for joint, axis in ((1, "Y"), (4, "C")):
        section = rf"\[JOINT_{joint}\]\nCOMP_FILE = A.{axis}.comp\nCOMP_FILE_TYPE = 1\n"
        assert re.search(section, a.files[".ini"])
    during = measure("A.ini", LINUX_LATER)
    fit_b, b = edit(during, "A.ini", "B")
    assert "held one" in "\n".join(b.notes)
    after = measure("B.ini", LINUX_LATER)
    alone = kinematics_edit(machine, fit_b, "linuxcnc", None, "", "R", "0", "d", stem="R").files
    for suffix in (".C.comp", ".Y.comp"):
        (tmp_path / f"R{suffix}").write_text(alone[suffix])
    (tmp_path / "U.ini").write_text(b.files[".ini"].replace("= B.C.comp", "= R.C.comp").replace("= B.Y.comp",
                                                                                                "= R.Y.comp"))
    undone = measure("U.ini", LINUX_LATER)
    rms = {k: identify(machine, [d], SETUP_NAMES).residual["rms_um"]
           for k, d in (("during", during), ("after", after), ("undone", undone))}
    print("LinuxCNC rounds, rms µm:", {k: round(v, 3) for k, v in rms.items()})
    assert rms["during"] > 3 * NOISE_UM and rms["undone"] > 3 * NOISE_UM, rms
    assert rms["after"] == pytest.approx(NOISE_UM, rel=0.1), rms
    # each joint's table is A's plus the residual's, line for line (the grids are the same)
    for suffix in (".C.comp", ".Y.comp"):
        ta, tb, tr = (linuxcnc.read_comp(f[suffix], machine, suffix) for f in (a.files, b.files, alone))
        np.testing.assert_allclose(tb.values, np.add(ta.values, tr.values), atol=2e-6)
    # the restore: round 1's configuration, pins and tables
    a_held, restored = (read_edits(machine, {k: read_state(str(tmp_path / k))}, None)
                        for k in ("A.ini", "B_RESTORE.ini"))
    np.testing.assert_allclose(restored.drive(machine, poses), a_held.drive(machine, poses))


def test_linuxcnc_type0_table_is_read_as_nominal_minus_actual(seed_machine, tmp_path):
    from compgen.controllers import linuxcnc
    from compgen.controllers.registry import read_state
    (tmp_path / "m.ini").write_text("[HAL]\nHALFILE = core_sim.hal\n[JOINT_4]\nCOMP_FILE = c.comp\n")
    (tmp_path / "c.comp").write_text("0 0.001 -0.001\n180 180.002 179.998\n360 360.001 359.999\nend\n7 7 7\n")
    (fwd, rev), = linuxcnc.loaded_joint_tables(seed_machine, read_state(str(tmp_path / "m.ini"))).values()
    np.testing.assert_allclose(fwd.values, [-0.001, -0.002, -0.001])
    np.testing.assert_allclose(rev.values, [0.001, 0.002, 0.001])
    assert fwd.input == "C" and fwd.grid.tolist() == [0, 180, 360]
    (tmp_path / "c.comp").write_text("0 1 1\n-5 1 1\n")
    with pytest.raises(CompgenError, match="do not increase"):
        read_state(str(tmp_path / "m.ini")) and linuxcnc.loaded_joint_tables(
            seed_machine, read_state(str(tmp_path / "m.ini")))


def test_every_cec_table_compgen_writes_spans_its_values_in_whole_steps(bc_machine):
    """(MAX − MIN) / STEP is exactly the number of steps the values span, as written: the
    control places value n at MIN + n·STEP. Steps are round (1, 2, 2.5, 5 × 10^k)."""
    from decimal import Decimal
    model = [*location_model(bc_machine), *TABLES]
    data = _measure(bc_machine, {}, np.random.default_rng(1), OEM_CARR)
    _, a = _edit(bc_machine, data, OEM_CARR, "A", model)
    cec = a.files["_CEC.INI"]
    tables = set(re.findall(r"(?m)^\$AN_CEC_STEP\[(\d+)\]", cec))
    assert len(tables) == 2
    for k in tables:
        get = {w: Decimal(re.search(rf"(?m)^\$AN_CEC_{w}\[{k}\]=(\S+)$", cec)[1])
               for w in ("MIN", "MAX", "STEP")}
        count = len(re.findall(rf"(?m)^\$AN_CEC\[{k},\d+\]=", cec))
        assert (get["MAX"] - get["MIN"]) / get["STEP"] == count - 1, (k, get, count)
        assert get["STEP"].normalize().as_tuple().digits[0] in (1, 2, 5)


def test_a_turn_table_is_modulo_only_on_a_modulo_axis_and_a_new_table_names_its_data(bc_machine, tmp_path):
    """C's 2/rev table is a modulo table where the machine file says C is modulo; where it
    says C is not, the turn repeats over C's travel (IS_MODULO 0); where it does not say,
    the edit is refused. A table in a new slot names the data that enable it."""
    from dataclasses import replace

    model = [*location_model(bc_machine), *TABLES]
    data = _measure(bc_machine, {}, np.random.default_rng(1), OEM_CARR)
    _, a = _edit(bc_machine, data, OEM_CARR, "A", model)
    assert "$AN_CEC_IS_MODULO[0]=1" in a.files["_CEC.INI"]
    notes = "\n".join(a.notes)
    for k in (0, 1):
        assert f"CEC table {k} is new: MD18342 $MN_MM_CEC_MAX_POINTS[{k}] >=" in notes
        assert f"SD41300 $SN_CEC_TABLE_ENABLE[{k}] = 1" in notes
    assert "MD32710 $MA_CEC_ENABLE = 0 on C1, Y1" in notes
    plain = replace(bc_machine, sinumerik={**bc_machine.sinumerik, "modulo": ()})
    _, b = _edit(plain, data, OEM_CARR, "B", model)
    table = sinumerik.read_cec(b.files["_CEC.INI"], plain)
    c = next(t for t in table if t.input == "C")
    assert not c.modulo and (c.start, c.stop) == (max(plain.axis("C").travel[0], -1260.0),
                                                    min(plain.axis("C").travel[1], 1260.0))
    ran = np.linspace(c.start, c.stop, 997)
    modulo = next(t for t in sinumerik.read_cec(a.files["_CEC.INI"], bc_machine) if t.input == "C")
    np.testing.assert_allclose(c.at(ran), modulo.at(ran), atol=1e-6)
    unsaid = replace(bc_machine, sinumerik={**bc_machine.sinumerik, "modulo": None})
    with pytest.raises(CompgenError, match=r"does not say whether it is"):
        _edit(unsaid, data, OEM_CARR, "U", model)


@pytest.mark.parametrize("record, says", [
    ("$TC_CARR4[1]=500.0\n", r"c:\d+: \$TC_CARR4\[1\] \(l2.x\) = 500 mm: the machine file does not say which "
                             r"l2"),
    ("$TC_CARR4[1]=500.0\n", r"c:\d+: \$TC_CARR4\[1\] \(l2.x\) = 500 mm, \+500.0000 mm from the machine "
                             r"file's 0"),
    ("$TC_CARR5[1]=0.05\n", None),                                        # 50 µm: within [limits]
])
def test_the_records_coarse_offsets_are_checked_against_the_machine_file(bc_machine, record, says):
    from dataclasses import replace
    machine = bc_machine
    if "the machine file's 0" in (says or "") or says is None:
        machine = replace(bc_machine, sinumerik={**bc_machine.sinumerik, "offsets": {
            "l2": np.zeros(3), "l3": np.zeros(3), "l4": np.zeros(3)}})
    fit = identify(machine, [_measure(machine, {}, np.random.default_rng(2), OEM_CARR)])
    state = OEM_CARR + record
    if says is None:
        kinematics_edit(machine, fit, "sinumerik840d", state, "c", "K", "0", "d")
    else:
        with pytest.raises(CompgenError, match=says):
            kinematics_edit(machine, fit, "sinumerik840d", state, "c", "K", "0", "d")


# Siemens's numbering (shared/research/controllers.md: l1 = $TC_CARR1..3, l2 = 4..6,
# l3 = 15..17, l4 = 18..20), written here from the manual, not from compgen's table
COARSE_NUMBERS = [("l1", "x", 1), ("l1", "y", 2), ("l1", "z", 3), ("l2", "x", 4), ("l2", "y", 5),
                  ("l2", "z", 6), ("l3", "x", 15), ("l3", "y", 16), ("l3", "z", 17), ("l4", "x", 18),
                  ("l4", "y", 19), ("l4", "z", 20)]


@pytest.mark.parametrize("vec, xyz, n", COARSE_NUMBERS)
def test_every_coarse_offset_of_the_record_is_checked_under_its_own_name(bc_machine, vec, xyz, n):
    """Each of the twelve coarse offsets the OEM set is read from its own $TC_CARR number:
    0.5 mm off the machine file's value is refused under that offset's name. Read under
    another number, one would pass unchecked and another be blamed."""
    from dataclasses import replace
    machine = replace(bc_machine, sinumerik={**bc_machine.sinumerik, "offsets": {
        v: np.zeros(3) for v in ("l1", "l2", "l3", "l4")}})
    fit = identify(machine, [_measure(machine, {}, np.random.default_rng(2), OEM_CARR)])
    state = OEM_CARR + f"$TC_CARR{n}[1]=0.5\n"
    said = rf"\$TC_CARR{n}\[1\] \({vec}\.{xyz}\) = 0.5 mm, \+0.5000 mm from "
    with pytest.raises(CompgenError, match=said):
        kinematics_edit(machine, fit, "sinumerik840d", state, "c", "K", "0", "d")


def test_the_machine_file_declares_the_records_coarse_offsets(tmp_path):
    from conftest import BC_MACHINE

    from compgen.configuration.machine_file import load_machine
    offsets = "offsets = { l2 = [0.0, 0.0, -120.5], l4 = [1, 2, 3] }\n"
    text = BC_MACHINE.read_text().replace("tcarr = 1 ", offsets + "tcarr = 1 ")
    (tmp_path / "m.toml").write_text(text)
    got = load_machine(tmp_path / "m.toml").sinumerik["offsets"]
    assert set(got) == {"l2", "l4"} and got["l2"].tolist() == [0.0, 0.0, -120.5]
    (tmp_path / "m.toml").write_text(text.replace("l4 =", "l5 ="))
    with pytest.raises(CompgenError, match="unknown key l5"):
        load_machine(tmp_path / "m.toml")


@pytest.mark.parametrize("travel, step", [((0.0, 360.0), 10.0), ((-180.0, 180.0), 10.0), ((0.0, 370.0), 20.0),
                                          ((-200.0, 160.0), 10.0), ((0.0, 36.0), 1.0), ((0.0, 37.0), 2.0)])
def test_a_generated_table_has_at_most_37_points_on_the_finest_round_step(travel, step):
    """0..360 at 10 is 37 points; 0..370 at 10 would be 38: the next round step, 20, ends
    beyond the end (no round step divides 370 within 37 points but 20's multiples cover it)."""
    from types import SimpleNamespace

    from compgen.controllers.correction import TABLE_POINTS, _grid
    grid = _grid(SimpleNamespace(full_turn=False, travel=travel, name="X"))
    assert len(grid) <= TABLE_POINTS == 37
    assert grid[1] - grid[0] == pytest.approx(step)
    assert grid[0] <= travel[0] and grid[-1] >= travel[1]


def test_a_modulo_table_unrolled_over_the_travel_repeats_its_turn_on_the_same_step():
    """For a control that does not wrap a table's input: the turn's values at every position
    of the travel (clipped to ±span) on the table's own step, as the wrapped table gives them."""
    from compgen.controllers.correction import unrolled
    turn = CompTable("ECC", "", "C", "C", 30.0, 390.0, tuple(np.sin(np.radians(np.arange(30, 391, 10)) * 2)),
                     True, "deg")
    plain = unrolled(turn, (-400.0, 500.0), 2520.0)
    assert (plain.start, plain.stop, plain.modulo, plain.step) == (-400.0, 500.0, False, 10.0)
    grid = np.arange(-400.0, 501.0, 10.0)
    np.testing.assert_allclose(plain.values, turn.at(grid), atol=1e-12)
    np.testing.assert_allclose(plain.values, np.sin(np.radians(grid) * 2), atol=1e-12)
    clipped = unrolled(turn, (-4000.0, 4000.0), 720.0)
    assert (clipped.start, clipped.stop) == (-720.0, 720.0)


def test_a_linuxcnc_joint_table_of_a_long_travel_turn_spans_the_travel_within_1260_degrees(seed_machine):
    """LinuxCNC does not wrap a joint's table: C's 2/rev table repeats its turn over C's
    travel (±720° on the seed machine) and, for a longer travel, over ±1260° (what the
    README promises; 256 lines at most)."""
    from dataclasses import replace

    from compgen.controllers import linuxcnc
    model = [*(n for n in location_model(seed_machine) if n[1] == "O" and n[0] in "XYZ"), *TABLES]
    data = simulate(seed_machine, LINUX_TRUTH, generate(seed_machine, ["K4", "K1", "K2"]), NOISE_UM,
                    np.random.default_rng(3))
    fit = identify(seed_machine, [data], model)
    long = replace(seed_machine, workpiece=tuple(replace(a, travel=(-3000.0, 3000.0)) if a.name == "C" else a
                                                 for a in seed_machine.workpiece))
    for machine, span in ((seed_machine, 720.0), (long, 1260.0)):
        files = kinematics_edit(machine, fit, "linuxcnc", None, "", "R", "0", "d", stem="R").files
        c = linuxcnc.read_comp(files[".C.comp"], machine, ".C.comp")
        assert (c.grid[0], c.grid[-1]) == (-span, span) and len(c.grid) <= linuxcnc.COMP_ENTRIES
        np.testing.assert_allclose(c.at(c.grid), c.at(np.mod(c.grid, 360.0)), atol=2e-6)   # one turn repeated


@pytest.mark.parametrize("points, start, stop, values", [
    ((-1.0, 1.0, 10.0), 1.0, 10.0, 3),        # the first position is not the start (the second is)
    ((1.0, 5.0, 9.0), 1.0, 10.0, 3),          # the last is not the stop
    ((1.0, 5.0, 10.0, 12.0), 1.0, 10.0, 4),   # past the stop
    ((1.0, 5.0, 5.0), 1.0, 5.0, 3),           # not increasing
    ((1.0, 10.0), 1.0, 10.0, 3),              # two positions for three values
])
def test_uneven_positions_must_run_from_the_tables_start_to_its_stop(points, start, stop, values):
    with pytest.raises(ValueError, match="do not run from"):
        CompTable("EXX:t", "", "X", "X", start, stop, (0.001,) * values, False, "mm", points)
    CompTable("EXX:t", "", "X", "X", 1.0, 10.0, (0.001,) * 3, False, "mm", (1.0, 4.0, 10.0))   # as it must be


def test_a_periodic_error_goes_into_a_table_only_with_eight_points_a_pitch(seed_machine):
    """X's table on the seed machine (±400 mm) steps 25 mm: a 200 mm pitch has its 8 points
    a pitch, a 5 mm screw period (docs: `kinematics` lists it, no table) would alias."""
    from compgen.controllers.correction import _compensable_by_table, _grid
    from compgen.model.effects import resolve
    step = float(np.diff(_grid(seed_machine.axis("X")))[0])
    assert step == 25.0
    assert _compensable_by_table(seed_machine, resolve(seed_machine, "EXX:w200"))
    assert not _compensable_by_table(seed_machine, resolve(seed_machine, "EXX:w5"))
    assert not _compensable_by_table(seed_machine, resolve(seed_machine, "EXX:w199"))   # 7.96 a pitch


def test_composed_uneven_tables_keep_points_a_files_rounding_cannot_join():
    """Positions within 2e-6 are one point (a file's rounding); 3e-6 apart, both are kept,
    and the sum holds at each."""
    old = CompTable("EXX:a", "", "X", "X", 0.0, 10.0, (0.0, 0.002, 0.0), False, "mm", (0.0, 1.000003, 10.0))
    new = CompTable("EXX:b", "", "X", "X", 0.0, 10.0, (0.0, 0.001, 0.0), False, "mm", (0.0, 1.0, 10.0))
    (got,) = compose_tables([old], [new])
    assert got.grid.tolist() == [0.0, 1.0, 1.000003, 10.0]
    np.testing.assert_allclose(got.values, old.at(got.grid) + new.at(got.grid), atol=1e-12)
    near = CompTable("EXX:b", "", "X", "X", 0.0, 10.0, (0.0, 0.001, 0.0), False, "mm", (0.0, 1.0000015, 10.0))
    joined = compose_tables([old], [near])[0].grid.tolist()
    assert len(joined) == 3 and joined[1] in (1.0000015, 1.000003), joined


@pytest.mark.parametrize("stop, count, written", [
    (350.0, 4, "350.000001"),     # 350/3 at 6 decimals: 1e-6 off, within 1e-6 of 350
    (0.3, 8, "0.299999"),         # 1e-6 off: within 1e-6 (the tolerance is never below that)
    (1.0, 3, "1.000000"),         # a step of 0.5
    (1.0, 37, None),              # 1/36 at 6 decimals: 8e-6 off
    (1.0, 32, None),              # 1/31: 2e-6 off
])
def test_a_cec_table_is_written_where_its_six_decimals_reach_its_stop(stop, count, written):
    """The step at 6 decimals times the steps must reach the stop within 1e-6 of its size
    (at least 1e-6): the control places value n at MIN + n·STEP."""
    from compgen.controllers.sinumerik import _cec_text
    t = CompTable("EXX:t", "", "X", "X", 0.0, stop, (0.0,) * count, False, "mm")
    if written is None:
        with pytest.raises(CompgenError, match="does not divide"):
            _cec_text(t, 0, {"X": "X1"})
    else:
        assert _cec_text(t, 0, {"X": "X1"})["max"] == written


@pytest.mark.parametrize("held, says", [
    (-120.5, None),                     # the OEM's value, as the machine file declares it
    (-120.0, r"\$TC_CARR6\[1\] \(l2\.z\) = -120 mm, \+0\.5000 mm from the machine file's -120\.5"),
    (-120.35, r"\(l2\.z\) = -120\.35 mm, \+0\.1500 mm from the machine file's -120\.5: beyond its \[limits\] "
              r"offset_um 100 µm"),                                # 150 µm: beyond the 100 µm, not 200
    (120.5, r"\$TC_CARR6\[1\] \(l2\.z\) = 120\.5 mm, \+241\.0000 mm from the machine file's -120\.5"),
])
def test_a_coarse_offset_is_held_to_the_machine_files_own_value_not_to_zero(bc_machine, held, says):
    """The OEM's l2 at z = -120.5 mm, as declared: the record holding it is the measured
    machine's; 0.5 mm off, or the sign turned, is another record (every declared value in the
    tests before was 0, where value - want and value + want agree)."""
    from dataclasses import replace
    machine = replace(bc_machine, sinumerik={**bc_machine.sinumerik, "offsets": {
        "l2": np.array([0.0, 0.0, -120.5])}})
    fit = identify(machine, [_measure(machine, {}, np.random.default_rng(2), OEM_CARR)])
    state = OEM_CARR + f"$TC_CARR6[1]={held}\n"
    if says is None:
        kinematics_edit(machine, fit, "sinumerik840d", state, "c", "K", "0", "d")
    else:
        with pytest.raises(CompgenError, match=says):
            kinematics_edit(machine, fit, "sinumerik840d", state, "c", "K", "0", "d")


def test_a_loaded_cec_tables_direction_and_multiplier_are_kept_or_the_round_refused(bc_machine):
    """A loaded table's $AN_CEC_DIRECTION and $AN_CEC_MULT_BY_TABLE are written back as read
    (they were reset to 0 while this round was added); this round is not added to a table
    that acts one way only or through another table's factor, since its trims act both ways
    and alone."""
    model = [*location_model(bc_machine), *TABLES]
    rng = np.random.default_rng(4)
    _, a = _edit(bc_machine, _measure(bc_machine, {}, rng, OEM_CARR), OEM_CARR, "A", model)
    # an OEM table of X on Z, one way and multiplied by table 0, which this round does not touch
    oem = ("".join(f"$AN_CEC[7,{k}]=0.00{k}\n" for k in range(3))
           + "$AN_CEC_INPUT_AXIS[7]=(X1)\n$AN_CEC_OUTPUT_AXIS[7]=(Z1)\n$AN_CEC_STEP[7]=100\n"
             "$AN_CEC_MIN[7]=-100\n$AN_CEC_MAX[7]=100\n$AN_CEC_DIRECTION[7]=1\n$AN_CEC_MULT_BY_TABLE[7]=2\n"
             "$AN_CEC_IS_MODULO[7]=0\n")
    cec = a.files["_CEC.INI"].removesuffix("M17\n") + oem + "M17\n"
    state = joined([("carr.txt", a.files[".MPF"]), ("cec.ini", cec)])
    _, b = _edit(bc_machine, _measure(bc_machine, {}, rng, OEM_CARR), state, "B", model)
    lines = b.files["_CEC.INI"].splitlines()
    assert "$AN_CEC_DIRECTION[7]=1" in lines and "$AN_CEC_MULT_BY_TABLE[7]=2" in lines, lines
    # the same on a table this round adds to: refused
    first = next(ln for ln in a.files["_CEC.INI"].splitlines() if ln.startswith("$AN_CEC_DIRECTION["))
    one_way = a.files["_CEC.INI"].replace(first, first.replace("=0", "=-1"))
    with pytest.raises(CompgenError, match=r"acts with \$AN_CEC_DIRECTION.*=-1: compgen does not add"):
        _edit(bc_machine, _measure(bc_machine, {}, rng, OEM_CARR),
              joined([("carr.txt", a.files[".MPF"]), ("cec.ini", one_way)]), "C", model)
