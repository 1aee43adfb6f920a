"""Edits compose with what the control holds: edit A, then edit B written over the result,
equals one edit of A + B from the original state, to first order; for every controller,
from a non-zero starting state (an OEM's tilts and offsets, compgen's own earlier rows).

How the expected numbers are derived: A, B and A + B are noiseless fits of location errors
(exact to 1e-9 µm), so the three edits are computed from exactly those. The lines of A + B
differ from the sum of the lines of A and of B only by second-order terms, tilt × offset
× lever: with 10″ (5e-5 rad) and 30 µm at 300 mm levers, below 1e-3 µm; the files round
to 1e-5 mm and 1e-7 deg (HEIDENHAIN), 1e-5 mm and 1e-10 (SINUMERIK), 1e-6 mm (LinuxCNC).
"""

import re
from dataclasses import replace

import numpy as np
import pytest
from conftest import ARCSEC, OEM_TAB, ROOT, UM

from compgen.controllers import heidenhain, sinumerik
from compgen.controllers.correction import nominal_lines, plan
from compgen.controllers.kinematics import kinematics_edit
from compgen.controllers.linuxcnc import SETP
from compgen.data.simulate import simulate
from compgen.errors import CompgenError
from compgen.model.paths import generate
from compgen.statistics.identify import identify
from compgen.transforms import rot_exact

SEED_A = {"YOA": 20 * UM, "ZOA": -15 * UM, "BOA": 8 * ARCSEC, "COA": -6 * ARCSEC,
          "XOC": 12 * UM, "YOC": -9 * UM, "AOC": 5 * ARCSEC, "BOC": -7 * ARCSEC}
SEED_B = {"YOA": -6 * UM, "ZOA": 9 * UM, "BOA": -3 * ARCSEC, "COA": 4 * ARCSEC,
          "XOC": 4 * UM, "YOC": 7 * UM, "AOC": -2 * ARCSEC, "BOC": 3 * ARCSEC}
BC_A = {"XOB": 15 * UM, "ZOB": -20 * UM, "AOB": 6 * ARCSEC, "COB": -9 * ARCSEC,
        "XOC": -7 * UM, "YOC": 11 * UM, "AOC": 4 * ARCSEC, "BOC": -5 * ARCSEC}
BC_B = {"XOB": -5 * UM, "ZOB": 6 * UM, "AOB": -2 * ARCSEC, "COB": 3 * ARCSEC,
        "XOC": 3 * UM, "YOC": -4 * UM, "AOC": 2 * ARCSEC, "BOC": 2 * ARCSEC}
SECOND_ORDER_MM = 1e-6
TILT_RAD = 1e-9          # SINUMERIK vectors: 1e-10 rounding and second-order products

# an OEM's record: fine offsets already set, the C vector tilted by about 20″
OEM_CARR = (ROOT / "examples" / "bc-tcarr-current.txt").read_text().replace(
    "$TC_CARR44[1]=0.0", "$TC_CARR44[1]=0.0123").replace(
    "$TC_CARR57[1]=0.0", "$TC_CARR57[1]=-0.0045").replace(
    "$TC_CARR11[1]=0.0", "$TC_CARR11[1]=0.0000969627")


def _fit(machine, truth):
    poses = generate(machine, ["K4", "K1", "K2"])
    return identify(machine, [simulate(machine, truth, poses)])


def _sum(a, b):
    return {k: a.get(k, 0.0) + b.get(k, 0.0) for k in {**a, **b}}


def _edit(machine, truth, controller, current):
    return kinematics_edit(machine, _fit(machine, truth), controller, current, "current", "KIN", "0", "d")


def test_heidenhain_second_round_adds_to_compgens_own_rows(seed_machine):
    first = _edit(seed_machine, SEED_A, "itnc530", OEM_TAB).files[".TAB"]
    second = _edit(seed_machine, SEED_B, "itnc530", first).files[".TAB"]
    once = _edit(seed_machine, _sum(SEED_A, SEED_B), "itnc530", OEM_TAB).files[".TAB"]
    nominal = nominal_lines(seed_machine)
    two, one = (heidenhain.read_lines(t, seed_machine, nominal) for t in (second, once))
    for axis in two:
        np.testing.assert_allclose(two[axis].offset, one[axis].offset, atol=3e-5)   # three roundings
        np.testing.assert_allclose(two[axis].tilt, one[axis].tilt, atol=np.radians(3e-7))
    # and the OEM's Y0A/B0A rows hold their value plus both corrections, not one of them
    oem = heidenhain.read_lines(OEM_TAB, seed_machine, nominal)["A"]
    a, b = (heidenhain.read_lines(_edit(seed_machine, t, "itnc530", OEM_TAB).files[".TAB"],
                                  seed_machine, nominal)["A"] for t in (SEED_A, SEED_B))
    np.testing.assert_allclose(two["A"].offset, a.offset + b.offset - oem.offset, atol=3e-5)
    assert abs(two["A"].offset[1] - oem.offset[1]) > 10 * UM    # the rows really moved


def test_sinumerik_second_round_composes_vectors_and_offsets(bc_machine):
    rec = bc_machine.sinumerik["tcarr"]
    first = _edit(bc_machine, BC_A, "sinumerik840d", OEM_CARR).files[".MPF"]
    second = _edit(bc_machine, BC_B, "sinumerik840d", first).files[".MPF"]
    once = _edit(bc_machine, _sum(BC_A, BC_B), "sinumerik840d", OEM_CARR).files[".MPF"]
    two, one, oem = (sinumerik.read_carr(t, "t", rec) for t in (second, once, OEM_CARR))
    for n in (*sinumerik.FINE["l2"], *sinumerik.FINE["l3"], *sinumerik.FINE["l4"]):
        assert two[n] == pytest.approx(one[n], abs=2e-5 + SECOND_ORDER_MM), n
    for idx in sinumerik.VECTOR.values():
        v2, v1, v0 = (np.array([d[n] for n in idx]) for d in (two, one, oem))
        np.testing.assert_allclose(v2, v1, atol=TILT_RAD)
        # the OEM's tilt is kept: the edited vector is the OEM's turned by the fit's tilt
        assert np.linalg.norm(v1 - v0) < 1e-3 and np.linalg.norm(v1 - v0) > 1e-6
    # exactly: the OEM's vectors turned by the tilt of A + B's lines
    lines = plan(bc_machine, _fit(bc_machine, _sum(BC_A, BC_B))).lines
    for axis, idx in zip(("B", "C"), sinumerik.VECTOR.values(), strict=True):
        v0 = np.array([oem[n] for n in idx])
        want = rot_exact(lines[axis].tilt)[:3, :3] @ (v0 / np.linalg.norm(v0))
        np.testing.assert_allclose([one[n] for n in idx], want, atol=1e-10)


def test_linuxcnc_second_round_adds_to_the_pins(seed_machine):
    def pins(text):
        return {m[2]: float(m[3]) for m in SETP.finditer(text)}

    first = _edit(seed_machine, SEED_A, "linuxcnc", None).files[".hal"]
    second = _edit(seed_machine, SEED_B, "linuxcnc", first).files[".hal"]
    once = _edit(seed_machine, _sum(SEED_A, SEED_B), "linuxcnc", None).files[".hal"]
    two, one = pins(second), pins(once)
    assert set(two) == set(one) and len(two) == 5
    for name in two:
        assert two[name] == pytest.approx(one[name], abs=2e-6 + SECOND_ORDER_MM), name
    # trtfuncs.c: the rot point lies on the C line, rot point + offsets on the A line (the
    # offset along A itself is not a pin); the lines at their pivots are the plan's
    lines = plan(seed_machine, _fit(seed_machine, _sum(SEED_A, SEED_B))).lines
    on_c = nominal_lines(seed_machine)["C"].pivot + lines["C"].offset
    on_a = nominal_lines(seed_machine)["A"].pivot + lines["A"].offset
    for k, axis in enumerate("xyz"):
        assert one[f"{axis}-rot-point"] == pytest.approx(on_c[k], abs=1e-6)
        if axis != "x":
            assert one[f"{axis}-rot-point"] + one[f"{axis}-offset"] == pytest.approx(on_a[k], abs=2e-6)


def test_linuxcnc_second_round_reads_the_configuration_through_its_ini(seed_machine, tmp_path):
    """The configuration's own HAL file sets the pins (one through a signal, its value an
    INI reference). Edit A, given the INI, is the configuration to start with: A.ini, with
    the HAL file written anew as A.machine.hal and the INI key changed where it stands.
    Edit B, given A.ini, lands where one edit of A + B lands; over the configuration
    without A it would undo A."""
    from compgen.controllers import linuxcnc
    from compgen.controllers.linuxcnc.config import evaluate
    from compgen.controllers.registry import read_state
    module, tilt, c = linuxcnc.trt_module(seed_machine)
    nominal = linuxcnc.nominal_pins(seed_machine, tilt, c)
    (tmp_path / "machine.hal").write_text("\n".join(
        [f"net yrot => {module}.y-rot-point", "sets yrot [KINS]YROT",
         *(f"setp {module}.{n} {v:.6f}" for n, v in nominal.items() if n != "y-rot-point")]) + "\n")
    (tmp_path / "before.ini").write_text(f"[KINS]\nKINEMATICS = {module}\n"
                                         f"YROT = {nominal['y-rot-point']:.6f}\n"
                                         "[HAL]\nHALFILE = core_sim.hal\nHALFILE = machine.hal\n")

    def edit(truth, ini, stem):
        out = kinematics_edit(seed_machine, _fit(seed_machine, truth), "linuxcnc",
                              read_state(str(tmp_path / ini)), str(tmp_path / ini), stem, "0", "d", stem=stem,
                              folder=str(tmp_path))
        for suffix, text in out.files.items():
            (tmp_path / f"{stem}{suffix}").write_text(text)
        return out

    def pins(ini):
        return linuxcnc.held_pins(evaluate(read_state(str(tmp_path / ini))), module)[0]

    a = edit(SEED_A, "before.ini", "A")
    assert set(a.files) >= {".ini", ".machine.hal", "_RESTORE.ini"}
    assert "HALFILE = A.machine.hal" in a.files[".ini"] and "HALFILE = machine.hal" in a.files["_RESTORE.ini"]
    # the INI key, where the value stands, holds what the edit without a configuration sets
    alone = kinematics_edit(seed_machine, _fit(seed_machine, SEED_A), "linuxcnc", None, "", "H", "0", "d")
    assert re.search(r"(?m)^YROT = (\S+)$", a.files[".ini"])[1] == re.search(
        rf"(?m)^setp {module}.y-rot-point (\S+)", alone.files[".hal"])[1]
    assert "sets yrot [KINS]YROT" in a.files[".machine.hal"]
    assert (tmp_path / "machine.hal").read_text().count("setp") == 5        # the user's files are untouched
    edit(SEED_B, "A.ini", "B")
    edit(_sum(SEED_A, SEED_B), "before.ini", "AB")
    edit(SEED_B, "before.ini", "U")
    two, one, undone = pins("B.ini"), pins("AB.ini"), pins("U.ini")
    for name in _pin_names_of(tilt):
        assert two[name] == pytest.approx(one[name], abs=2e-6 + SECOND_ORDER_MM), name
    assert max(abs(undone[n] - one[n]) for n in one) > 5 * UM
    assert pins("B_RESTORE.ini") == pins("A.ini") and pins("A_RESTORE.ini") == pins("before.ini")


def _pin_names_of(tilt):
    from compgen.controllers import linuxcnc
    return linuxcnc.pin_names(tilt)


@pytest.mark.parametrize("controller", ["itnc530", "sinumerik840d", "linuxcnc"])
def test_an_edit_against_a_state_that_holds_part_of_it_writes_the_rest(seed_machine, bc_machine, controller):
    """Measured in state S0; meanwhile part of the correction (say, the A line) was loaded:
    S1. The edit of the fit, against S1 with S0 named as the measured state, lands where
    the edit against S0 lands; without naming S0 it would add the part twice."""
    main = {"itnc530": ".TAB", "sinumerik840d": ".MPF", "linuxcnc": ".hal"}[controller]
    machine, truth = (bc_machine, BC_A) if controller == "sinumerik840d" else (seed_machine, SEED_A)
    s0 = {"itnc530": OEM_TAB, "sinumerik840d": OEM_CARR,     # LinuxCNC: its nominal pins
          "linuxcnc": _edit(seed_machine, {"XOC": 0.0}, "linuxcnc", None).files[".hal"]}[controller]
    first = machine.rotary_axes[0].name
    part = {k: v for k, v in truth.items() if k.endswith(first)}
    s1 = _edit(machine, part, controller, s0).files[main]
    fit = _fit(machine, truth)
    direct = kinematics_edit(machine, fit, controller, s0, "s0", "KIN", "0", "d").files[main]
    rest = kinematics_edit(machine, fit, controller, s1, "s1", "KIN", "0", "d", measured=s0).files[main]
    twice = kinematics_edit(machine, fit, controller, s1, "s1", "KIN", "0", "d").files[main]
    nominal = nominal_lines(machine)
    if controller == "itnc530":
        a, b, c = (heidenhain.read_lines(t, machine, nominal) for t in (direct, rest, twice))
        for axis in a:
            np.testing.assert_allclose(b[axis].offset, a[axis].offset, atol=3e-5)
        assert np.abs(c[first].offset - a[first].offset).max() > 10 * UM
    elif controller == "sinumerik840d":
        a, b, c = (sinumerik.read_carr(t, "t", 1) for t in (direct, rest, twice))
        for n in a:
            assert b[n] == pytest.approx(a[n], abs=3e-5), n
        assert max(abs(c[n] - a[n]) for n in sinumerik.FINE["l2"]) > 10 * UM
    else:
        a, b, c = ({m[2]: float(m[3]) for m in SETP.finditer(t)} for t in (direct, rest, twice))
        for n in a:
            assert b[n] == pytest.approx(a[n], abs=3e-6), n
        assert max(abs(c[n] - a[n]) for n in a) > 10 * UM


def test_the_rest_of_a_plan_subtracts_what_the_control_holds(seed_machine):
    """rest(): offsets, tilts and squareness the control already holds come off the plan,
    each by its own key; one the plan lacks goes back with the opposite sign."""
    from compgen.controllers.correction import Held, rest
    from compgen.model.effects import location_model
    truth = {"XOC": 9 * UM, "BOA": 4 * ARCSEC, "COX": 5 * ARCSEC}
    model = [*location_model(seed_machine), "COX"]
    fit = identify(seed_machine, [simulate(seed_machine, truth, generate(seed_machine, ["K4", "K1", "K2"]))],
                   model)
    p = plan(seed_machine, fit)
    held_lines = {n: type(line)(n, line.nominal, line.pivot, line.offset * 0.25, line.tilt * 0.5)
                  for n, line in p.lines.items()}
    r = rest(seed_machine, p, Held(held_lines, {"COX": 2 * ARCSEC, "BOZ": 1 * ARCSEC}))
    assert r.squareness["COX"] == pytest.approx(p.squareness["COX"] - 2 * ARCSEC, abs=1e-15)
    assert r.squareness["BOZ"] == pytest.approx(-1 * ARCSEC, abs=1e-15)
    only_held = rest(seed_machine, p, Held(held_lines, {"BOZ": 1 * ARCSEC}))   # COX: none held
    assert only_held.squareness["COX"] == pytest.approx(p.squareness["COX"], abs=1e-15)
    for n, line in r.lines.items():
        np.testing.assert_allclose(line.offset, 0.75 * p.lines[n].offset, atol=1e-15)
        np.testing.assert_allclose(line.tilt, 0.5 * p.lines[n].tilt, atol=1e-15)
    assert r.tables == p.tables and r.fit_params == p.fit_params


def _record(**values):
    text = OEM_CARR
    for n, v in values.items():
        text = re.sub(rf"\$TC_CARR{n[1:]}\[1\]=\S+", f"$TC_CARR{n[1:]}[1]={v}", text)
    return text


def test_sinumerik_vectors_of_any_length_and_a_wrong_record(bc_machine):
    """A record may hold its vectors unnormalised: the edit writes unit vectors, turned by the
    fit's tilt; a vector more than 1° from the machine file's is another record's, refused."""
    fit = _fit(bc_machine, BC_A)
    lines = plan(bc_machine, fit).lines
    twice = _record(c10=0.0, c11=0.000193925, c12=-2.0)       # C's vector, length 2, ~20″ off
    new = sinumerik.read_carr(kinematics_edit(bc_machine, fit, "sinumerik840d", twice, "c", "K", "0",
                                              "d").files[".MPF"], "t", 1)
    v = np.array([new[n] for n in (10, 11, 12)])
    want = rot_exact(lines["C"].tilt)[:3, :3] @ (np.array([0.0, 0.000193925, -2.0]) / 2.0000000094)
    np.testing.assert_allclose(v, want, atol=1e-9)
    assert np.linalg.norm(v) == pytest.approx(1.0, abs=1e-9)
    off = np.radians([0.5, 2.0])
    near, far = (_record(c11=2 * np.sin(a), c12=-2 * np.cos(a)) for a in off)
    kinematics_edit(bc_machine, fit, "sinumerik840d", near, "c", "K", "0", "d")
    with pytest.raises(CompgenError, match=r"c:5: the record's vector for C .* is not the one the machine "
                                           r"file"):
        kinematics_edit(bc_machine, fit, "sinumerik840d", far, "c", "K", "0", "d")


def test_sinumerik_edit_reads_back_as_its_plan_from_any_record(bc_machine):
    """read_lines (what `simulate --edit` and --measured-with use) on an edit made from a
    record with non-zero l2, l3 and l4: the plan's offsets and tilts."""
    fit = _fit(bc_machine, BC_A)
    p = plan(bc_machine, fit)
    record = _record(c58=-0.0123, c59=0.0, c60=0.0045)      # l4 closes the OEM's l2 + l3
    mpf = kinematics_edit(bc_machine, fit, "sinumerik840d", record, "c", "K", "0", "d").files[".MPF"]
    got = sinumerik.read_lines(mpf, bc_machine, sinumerik.read_carr(record, "r", 1),
                               nominal_lines(bc_machine))
    for axis, line in p.lines.items():
        across = [k for k in range(3) if k != "xyz".index(line.nominal)]
        np.testing.assert_allclose(got[axis].offset[across], line.offset[across], atol=1e-6)
        # a vector's turn about itself is not held; the OEM's 20″ tilt adds second-order terms
        np.testing.assert_allclose(got[axis].tilt[across], line.tilt[across], atol=1e-8)


def test_a_cec_file_reads_back_as_the_tables_it_was_written_from(bc_machine):
    from compgen.controllers.correction import comp_tables
    from compgen.model.effects import location_model
    truth = {"XOC": 3 * UM, "ECC:h2c": 6 * ARCSEC, "EYY:p1": 4 * UM}
    model = [*location_model(bc_machine), "ECC:h2c", "ECC:h2s", "EYY:p1"]
    fit = identify(bc_machine, [simulate(bc_machine, truth, generate(bc_machine, ["K4", "K1", "K2"]))], model)
    cec = kinematics_edit(bc_machine, fit, "sinumerik840d", OEM_CARR, "c", "K", "0", "d").files["_CEC.INI"]
    read = sinumerik.read_cec(cec, bc_machine)
    wrote = comp_tables(bc_machine, plan(bc_machine, fit))
    assert [(t.input, t.output, t.modulo) for t in read] == [(t.input, t.output, t.modulo) for t in wrote]
    for r, w in zip(read, wrote, strict=True):
        assert (r.start, r.stop) == (pytest.approx(w.start), pytest.approx(w.stop, abs=1e-4))
        np.testing.assert_allclose(r.values, w.values, atol=0.6e-6)


def test_a_modulo_table_wraps_and_a_ball_on_the_axis_has_no_positioning_error(seed_machine, tmp_path):
    from compgen.controllers.correction import CompTable, _positioning_error, apply_tables
    grid = np.linspace(0, 360, 37)
    t = CompTable("ECC:h1", "", "C", "C", 0.0, 360.0, tuple(np.sin(np.radians(grid)) * 1e-3), True, "deg")
    q = np.zeros((4, len(seed_machine.axes)))
    c = seed_machine.index("C")
    q[:, c] = np.radians([-90.0, 270.0, 450.0, 90.0])
    out = np.degrees(apply_tables(seed_machine, [t], q)[:, c]) - np.degrees(q[:, c])
    np.testing.assert_allclose(out, [-1e-3, -1e-3, 1e-3, 1e-3], atol=1e-9)
    shifted = tuple(np.sin(np.radians(grid - 180)) * 1e-3)
    half = CompTable("ECC:h1", "", "C", "C", -180.0, 180.0, shifted, True, "deg")   # the same over ±180
    out = np.degrees(apply_tables(seed_machine, [half], q)[:, c]) - np.degrees(q[:, c])
    np.testing.assert_allclose(out, [-1e-3, -1e-3, 1e-3, 1e-3], atol=1e-9)
    quarter = CompTable("ECC:h1", "", "C", "C", -90.0, 270.0,            # a start that is not
                        tuple(np.sin(np.radians(grid - 90)) * 1e-3), True, "deg")   # half a turn
    out = np.degrees(apply_tables(seed_machine, [quarter], q)[:, c]) - np.degrees(q[:, c])
    np.testing.assert_allclose(out, [-1e-3, -1e-3, 1e-3, 1e-3], atol=1e-9)
    # a ball on C's axis does not move when C turns: no positioning error can be seen there
    on_axis = replace(seed_machine, ball=(0.0, 0.0, seed_machine.ball[2]))
    c_axis = on_axis.axis("C")
    err = _positioning_error(on_axis, c_axis, ["ECC:h1c"], {"ECC:h1c": 5 * ARCSEC}, np.array([0.0, 90.0]))
    assert err.tolist() == [0.0, 0.0]
    # half a millimetre off the axis it is seen again, whole: 5″·cos C
    near = replace(seed_machine, ball=(0.5, 0.0, seed_machine.ball[2]))
    err = _positioning_error(near, near.axis("C"), ["ECC:h1c"], {"ECC:h1c": 5 * ARCSEC},
                             np.array([0.0, 60.0]))
    np.testing.assert_allclose(err, [5 * ARCSEC, 2.5 * ARCSEC], rtol=1e-4)


def test_linuxcnc_says_when_the_tool_offset_pin_is_not_netted(seed_machine):
    fit = _fit(seed_machine, {"XOC": 3 * UM})
    nominal = _fit(seed_machine, {})
    base = kinematics_edit(seed_machine, nominal, "linuxcnc", None, "", "N", "0", "d").files[".hal"]
    netted = base + "net tooloffset motion.tooloffset.z => xyzac-trt-kins.tool-offset\n"
    for current, warned in ((base, True), (netted, False)):
        notes = kinematics_edit(seed_machine, fit, "linuxcnc", current, "c", "K", "0", "d").notes
        assert any("tool-offset is not netted" in n for n in notes) == warned, notes


@pytest.mark.parametrize("l4_off_mm, ok", [(0.0, True), (1e-5, True), (2e-5, False), (1e-3, False)])
def test_sinumerik_l4_must_close_the_chain_to_its_rounding(bc_machine, l4_off_mm, ok):
    """l4 = −(l2 + l3): three values each rounded to 1e-5 mm may miss by 1.5e-5, not more."""
    current = sinumerik.read_carr(OEM_CARR, "c", 1)
    new = dict(current)
    new[44] += 0.010
    new[55] += 0.004
    new[58] += -0.014 + l4_off_mm
    text = "".join(f"$TC_CARR{n}[1]={v if n <= 12 else round(v, 5)!r}\n" for n, v in new.items())
    read = lambda: sinumerik.read_lines(text, bc_machine, current, nominal_lines(bc_machine))  # noqa: E731
    if ok:
        assert read()["C"].offset[0] == pytest.approx(0.014, abs=1e-9)
        assert read()["C"].tilt.tolist() == [0.0, 0.0, 0.0]      # the vectors did not turn
    else:
        with pytest.raises(CompgenError, match="do not close the chain"):
            read()


def _bc_file(tmp_path, before, after):
    from compgen.configuration.machine_file import load_machine
    text = (ROOT / "machines" / "bc-table-sinumerik840d.toml").read_text()
    assert before in text
    (tmp_path / "m.toml").write_text(text.replace(before, after, 1))
    return load_machine(tmp_path / "m.toml")


def test_a_sinumerik_state_or_machine_file_the_edit_cannot_build_on_is_refused(tmp_path, bc_machine):
    """--current without a vector the edit rewrites; a fine offset held beyond MD20188 (the
    control would refuse what it holds); a CEC table for a machine whose file names no
    machine axes: one line each."""
    fit = _fit(bc_machine, BC_A)
    lacking = re.sub(r"(?m)^\$TC_CARR10\[1\]=.*\n", "", OEM_CARR)
    with pytest.raises(CompgenError, match=r"--current lacks \$TC_CARR10\[1\] \(and 0 more\)"):
        kinematics_edit(bc_machine, fit, "sinumerik840d", lacking, "c", "K", "0", "d")
    tight = _bc_file(tmp_path, "fine_correction = true", "fine_correction = true\nfine_limit_mm = 0.01")
    k = next(i for i, ln in enumerate(OEM_CARR.splitlines(), 1) if ln.startswith("$TC_CARR44["))
    with pytest.raises(CompgenError, match=rf"^c:{k}: \$TC_CARR44\[1\] = 0\.0123 mm exceeds MD20188 = "
                                           r"0\.01 mm"):
        kinematics_edit(tight, fit, "sinumerik840d", OEM_CARR, "c", "K", "0", "d")
    unnamed = _bc_file(tmp_path, 'machine_axes = { X = "X1", Y = "Y1", Z = "Z1", B = "B1", C = "C1" }', "")
    model = [*fit.model, "ECC:h2c", "ECC:h2s"]
    cec = identify(unnamed, [simulate(unnamed, {**BC_A, "ECC:h2c": 6 * ARCSEC},
                                      generate(unnamed, ["K4", "K1", "K2"]))], model)
    with pytest.raises(CompgenError, match="CEC tables address machine axes .* the machine file does "
                                           "not name"):
        kinematics_edit(unnamed, cec, "sinumerik840d", OEM_CARR, "c", "K", "0", "d")


def test_a_heidenhain_table_without_doc_column_is_refused_before_any_row_is_written(seed_machine):
    """compgen's rows are named by their DOC (the ISO name, then the fit's marker): a table
    without that column could not tell later which rows are compgen's."""
    bare = "\n".join(line[:33].rstrip() for line in OEM_TAB.splitlines()) + "\n"
    assert "DOC" not in bare and "Trans     Z     +29.794" in bare
    with pytest.raises(CompgenError, match="the current table has no DOC column to name the correction rows"):
        _edit(seed_machine, SEED_A, "itnc530", bare)
