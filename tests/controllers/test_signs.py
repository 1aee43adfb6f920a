"""Signs, units and axis indices of the kinematics edits, pinned with expectations derived
here and read back by parsers written here (not compgen's readers):

* the HEIDENHAIN rows of a fit, squareness included, each on its MachAxis with its sign;
* a closed loop per controller, from a non-zero starting state, over two rounds, on
  machines with either sense of their rotary axes: the control holds what the files say
  (read here, with the controller's documented meaning), drives the true machine by TCP,
  and the R-test then reads set-up and noise only.
"""

import re

import numpy as np
import pytest
from conftest import ARCSEC, BC_MACHINE, OEM_TAB, ROOT, SEED_MACHINE, UM, measured_under

from compgen.configuration.machine_file import load_machine
from compgen.controllers.correction import plan
from compgen.controllers.kinematics import kinematics_edit
from compgen.data.simulate import simulate
from compgen.model.effects import location_model
from compgen.model.kinematics import Model
from compgen.model.lines import AxisLine
from compgen.model.paths import generate
from compgen.model.poses import Poses
from compgen.statistics.identify import identify

NOISE_UM = 0.5
DEG = np.pi / 180
SETUP = ["XOW", "YOW", "ZOW"]
ISO = re.compile(r"^\s*\d+\s+Trans\s+([XYZABC])\s+(\S+)\s+([XYZABC])0([A-Z])\s*$")


def test_heidenhain_rows_with_squareness_by_hand(seed_machine):
    truth = {"YOA": 20 * UM, "ZOA": -15 * UM, "BOA": 8 * ARCSEC, "COA": -6 * ARCSEC, "XOC": 12 * UM,
             "YOC": -9 * UM, "AOC": 5 * ARCSEC, "BOC": -7 * ARCSEC,
             "COX": 5 * ARCSEC, "BOZ": -4 * ARCSEC, "AOZ": 3 * ARCSEC}
    model = [*location_model(seed_machine), "COX", "BOZ", "AOZ"]
    fit = identify(seed_machine, [simulate(seed_machine, truth, generate(seed_machine, ["K4", "K1", "K2"]))],
                   model)
    text = kinematics_edit(seed_machine, fit, "itnc530", None, "", "KIN", "0", "d").files[".txt"]
    rows = re.findall(r"^\s+(-?[XYZABC]0[A-Z])\s+Trans\s+([XYZABC])\s+(\S+) (mm|deg)", text, re.MULTILINE)
    got = {doc: (axis, float(v)) for doc, axis, v, _ in rows}
    # the squareness rows: the tilt in degrees before its linear MachAxis, the inverse after
    for name, (rot, axis) in {"COX": ("C", "X"), "BOZ": ("B", "Z"), "AOZ": ("A", "Z")}.items():
        assert got[f"{rot}0{axis}"] == (rot, pytest.approx(truth[name] / DEG, abs=1e-7))
        assert got[f"-{rot}0{axis}"] == (rot, pytest.approx(-truth[name] / DEG, abs=1e-7))
    # each group sits around its own MachAxis: the block of rows after '---- around MachAxis K'
    blocks = dict(re.findall(r"---- around MachAxis (\w)\n(.*?)(?=\n; ----|\n;\n|\Z)", text, re.S))
    assert set(blocks) == {"A", "C", "X", "Z"}
    assert "C0X" in blocks["X"] and "B0Z" in blocks["Z"] and "A0Z" in blocks["Z"]
    assert "C0X" not in blocks["Z"] and "B0Z" not in blocks["X"]
    # the A rows: its offsets (mm) and tilts (deg), the inverse rows in reverse order
    for doc, value, axis in (("Y0A", truth["YOA"], "Y"), ("Z0A", truth["ZOA"], "Z"),
                             ("B0A", truth["BOA"] / DEG, "B"), ("C0A", truth["COA"] / DEG, "C")):
        assert got[doc] == (axis, pytest.approx(value, abs=1e-5 if axis in "XYZ" else 1e-7)), doc
    order = re.findall(r"(-?[XYZABC]0A)", blocks["A"])
    assert order == ["Y0A", "Z0A", "B0A", "C0A", "-C0A", "-B0A", "-Z0A", "-Y0A"]


# ---------------------------------------------------------------------- independent readers

def _rot(axis: str, angle: float) -> np.ndarray:
    c, s_ = np.cos(angle), np.sin(angle)
    i, j = {"A": (1, 2), "B": (2, 0), "C": (0, 1)}[axis]
    R = np.eye(3)
    R[i, i] = R[j, j] = c
    R[j, i], R[i, j] = s_, -s_
    return R


def lines_from_table(text: str, machine) -> tuple[dict[str, tuple], dict[str, float]]:
    """A HEIDENHAIN table (MM) read as its chain (Technical Manual p.684): after MachBase,
    each Trans row translates or turns the frame of everything after it; an axis turns
    about its frame's Z/X/Y line where its MachAxis row stands. Per rotary axis (offset at
    the nominal pivot's plane, mm; tilt, rad) against the nominal machine; and the
    squareness rows around a linear MachAxis, each checked against its inverse row."""
    rows = [ln.split() for ln in text.splitlines()[2:] if ln[:1].isdigit()]
    o, R, after_base, found = np.zeros(3), np.eye(3), False, {}
    square, pending = {}, {}
    for r in rows:
        key = r[1]
        if key == "MachBase":
            after_base = True
        elif key == "MachAxis" and after_base and r[2] in "ABC":
            found[r[2]] = (o.copy(), R.copy())
        elif key == "Trans":
            axis, value = r[2], float(r[3])
            doc = r[4] if len(r) > 4 else ""
            if re.fullmatch(r"-?[ABC]0[XYZ]", doc):        # squareness around a linear axis
                name = f"{doc.lstrip('-')[0]}O{doc[-1]}"
                if doc.startswith("-"):
                    assert abs(pending.pop(name) + value) < 1e-12, f"{doc} is not the inverse row"
                else:
                    pending[name] = value
                    square[name] = value * DEG
            elif after_base and axis in "XYZ":
                o = o + R @ (value * np.eye(3)["XYZ".index(axis)])
            elif after_base:
                R = R @ _rot(axis, value * DEG)
    assert not pending, f"squareness rows without their inverse: {pending}"
    out = {}
    for a in machine.rotary_axes:
        point, frame = found[a.name]
        e = np.eye(3)["xyz".index(a.direction)]
        d = frame @ e
        names = [x.name for x in machine.workpiece]
        pivot = sum(np.asarray(b.offset, float) for b in machine.workpiece[:names.index(a.name) + 1])
        at = point - ((point - pivot) @ e) / (d @ e) * d       # the line where it crosses the plane
        out[a.name] = (at - pivot, turn(e, d))
    return out, square


def carr(text: str) -> dict[int, float]:
    return {int(m[1]): float(m[2]) for m in re.finditer(r"\$TC_CARR(\d+)\[1\]=([-+.\d]+)\s", text)}


def turn(a, b):
    a, b = np.asarray(a) / np.linalg.norm(a), np.asarray(b) / np.linalg.norm(b)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis)
    return np.zeros(3) if s == 0 else axis / s * np.arctan2(s, a @ b)


def lines_from_carr(text: str, nominal: str, axes) -> dict[str, tuple]:
    """$TC_CARR fine offsets l2 (44-46), l3 (55-57) and vectors v1 (7-9), v2 (10-12),
    against the nominal record: t1 = Δl2, t2 = Δl2 + Δl3, tilts from the vectors' turn."""
    now, was = carr(text), carr(nominal)
    d = {n: now[n] - was[n] for n in now}
    t1 = np.array([d[44], d[45], d[46]])
    t2 = t1 + np.array([d[55], d[56], d[57]])
    tilts = [turn([was[n] for n in idx], [now[n] for n in idx]) for idx in ((7, 8, 9), (10, 11, 12))]
    return {axes[0]: (t1, tilts[0]), axes[1]: (t2, tilts[1])}


def pins(text: str) -> dict[str, float]:
    return {m[1]: float(m[2]) for m in re.finditer(r"(?m)^setp \S+?\.(\S+) (\S+)", text)}


def lines_from_pins(text: str, nominal: str, tilt_axis: str) -> dict[str, tuple]:
    """trtfuncs.c: C turns about the rot point, the tilting axis about rot point + offsets."""
    now, was = pins(text), pins(nominal)
    r = np.array([now[f"{a}-rot-point"] - was[f"{a}-rot-point"] for a in "xyz"])
    d = np.array([now.get(f"{a}-offset", 0.0) - was.get(f"{a}-offset", 0.0) for a in "xyz"])
    return {"C": (r, np.zeros(3)), tilt_axis: (r + d, np.zeros(3))}


# ---------------------------------------------------------------------- the loop

NOMINAL_CARR = (ROOT / "examples" / "bc-tcarr-current.txt").read_text()


def _machine(tmp_path, name):
    if name == "bc":
        return load_machine(BC_MACHINE)
    text = SEED_MACHINE.read_text()
    if name == "flipped":               # A and C turning the other way
        text = (text.replace('direction = "x"        # right-handed', 'sense = -1\ndirection = "x"  #')
                .replace('direction = "z"        # about the A-carried', 'sense = -1\ndirection = "z"  #'))
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    machine = load_machine(path)
    assert [a.sense for a in machine.rotary_axes] == ([-1, -1] if name == "flipped" else [1, 1])
    return machine


def _held_lines(machine, read):
    out = {}
    for a in machine.rotary_axes:
        offset, tilt = read.get(a.name, (np.zeros(3), np.zeros(3)))
        names = [x.name for x in machine.workpiece]
        pivot = sum(np.asarray(b.offset, float) for b in machine.workpiece[:names.index(a.name) + 1])
        out[a.name] = AxisLine(a.name, a.direction, pivot, offset, tilt)
    return out


def _measure(machine, truth, held, squareness, poses, rng):
    return measured_under(machine, truth, held, poses, rng, NOISE_UM, squareness)


def _truth(machine, controller):
    first, second = (a.name for a in machine.rotary_axes)
    across = "Y" if first == "A" else "X"          # offsets of the tilting axis's line
    truth = {"XOW": 4 * UM, "YOW": -6 * UM, "ZOW": 9 * UM, f"{across}O{first}": 18 * UM,
             f"ZO{first}": -14 * UM, f"XO{second}": 11 * UM, f"YO{second}": -13 * UM}
    if controller != "linuxcnc":         # angular location errors, where the control holds them
        tilt = "B" if first == "A" else "A"
        truth |= {f"{tilt}O{first}": 9 * ARCSEC, f"AO{second}": -7 * ARCSEC, f"BO{second}": 6 * ARCSEC}
    if controller == "itnc530":
        truth |= {"COX": 4 * ARCSEC}
    return truth


CASES = [("seed", "itnc530"), ("flipped", "itnc530"), ("bc", "sinumerik840d"),
         ("flipped", "sinumerik840d"), ("seed", "linuxcnc")]


@pytest.mark.parametrize("name, controller", CASES)
def test_two_rounds_from_a_non_zero_state_bring_the_machine_to_the_noise(tmp_path, name, controller):
    machine = _machine(tmp_path, name)
    rotary = [a.name for a in machine.rotary_axes]
    truth = _truth(machine, controller)
    rng = np.random.default_rng(3)
    poses = generate(machine, ["K4", "K1", "K2"])
    if controller == "itnc530":
        state = OEM_TAB

        def read(text):
            lines, square = lines_from_table(text, machine)
            return _held_lines(machine, lines), square
    elif controller == "sinumerik840d":
        nominal = NOMINAL_CARR
        if name == "flipped":            # the A/C record: v1 along -X
            nominal = nominal.replace("$TC_CARR7[1]=0.0", "$TC_CARR7[1]=-1.0").replace(
                "$TC_CARR8[1]=-1.0", "$TC_CARR8[1]=0.0")
        state = nominal.replace("$TC_CARR45[1]=0.0", "$TC_CARR45[1]=0.0047").replace(
            "$TC_CARR11[1]=0.0", "$TC_CARR11[1]=0.00004")

        def read(text):
            return _held_lines(machine, lines_from_carr(text, nominal, rotary)), {}
    else:
        nominal = kinematics_edit(machine, identify(machine, [simulate(machine, {}, poses)], SETUP),
                                  "linuxcnc", None, "", "N", "0", "d").files[".hal"]
        state = nominal.replace("y-rot-point 0.000000", "y-rot-point 0.005000")
        assert state != nominal

        def read(text):
            return _held_lines(machine, lines_from_pins(text, nominal, rotary[0])), {}

    held, square = read(state)
    assert any(np.abs(line.offset).max() > 0 or np.abs(line.tilt).max() > 0 for line in held.values())
    before = identify(machine, [_measure(machine, truth, held, square, poses, rng)], SETUP)
    model = [*location_model(machine), *(["COX"] if "COX" in truth else [])]
    partial = [*SETUP, *[n for n in location_model(machine) if n.endswith(rotary[0])]]
    for round_model in (partial, model):   # round 1 corrects the tilting axis only, round 2 all
        fit = identify(machine, [_measure(machine, truth, held, square, poses, rng)], round_model)
        files = kinematics_edit(machine, fit, controller, state, "current", "KIN", "0", "d").files
        state = files[{"itnc530": ".TAB", "sinumerik840d": ".MPF", "linuxcnc": ".hal"}[controller]]
        held, square = read(state)
    after = identify(machine, [_measure(machine, truth, held, square, poses, rng)], SETUP)
    assert before.residual["rms_um"] > 8 * NOISE_UM, before.residual["rms_um"]
    assert after.residual["rms_um"] == pytest.approx(NOISE_UM, rel=0.1), (before.residual["rms_um"],
                                                                           after.residual["rms_um"])
    # the control now holds the truth's lines (the exact fit of noiseless data), to the noise;
    # an offset along an axis's own direction does not move its line (an OEM's fine offset
    # along B, LinuxCNC's rot point along A): compared across the axis only
    truth_lines = plan(machine, identify(machine, [simulate(machine, truth, poses)], model)).lines
    for axis, line in held.items():
        across = [k for k in range(3) if k != "xyz".index(line.nominal)]
        np.testing.assert_allclose(line.offset[across], truth_lines[axis].offset[across], atol=0.3 * UM)
        np.testing.assert_allclose(line.tilt, truth_lines[axis].tilt, atol=0.3 * ARCSEC)


def test_sinumerik_squareness_goes_to_a_cec_table_that_cancels_it(bc_machine):
    """COX (X's line turned about Z): moving the tool-side X by x puts the nest COX·x off in
    +Y (a positive turn about Z takes +x towards +y). The CEC table must therefore add
    −COX·x to Y (machine axis Y1) as a function of X (X1), read here from the file."""
    cox = 5 * ARCSEC
    truth = {"XOC": 11 * UM, "COX": cox}
    model = [*location_model(bc_machine), "COX"]
    poses = generate(bc_machine, ["K4", "K1", "K2"])
    fit = identify(bc_machine, [simulate(bc_machine, truth, poses)], model)
    cec = kinematics_edit(bc_machine, fit, "sinumerik840d", NOMINAL_CARR, "c", "KIN", "0",
                          "d").files["_CEC.INI"]
    tables = {}
    for m in re.finditer(r"(?m)^\$AN_CEC(_[A-Z_]+)?\[(\d+)(?:,(\d+))?\]=\(?([^)\s]+)\)?$", cec):
        t = tables.setdefault(int(m[2]), {"values": {}})
        if m[1] is None:
            t["values"][int(m[3])] = float(m[4])
        else:
            t[m[1]] = m[4]
    square = [t for t in tables.values() if t["_INPUT_AXIS"] == "X1" and t["_OUTPUT_AXIS"] == "Y1"]
    assert len(square) == 1, tables
    t = square[0]
    x = float(t["_MIN"]) + float(t["_STEP"]) * np.arange(len(t["values"]))
    x_axis = bc_machine.axis("X")
    assert x[0] == pytest.approx(x_axis.travel[0]) and x[-1] == pytest.approx(x_axis.travel[1])
    values = np.array([t["values"][i] for i in range(len(x))])
    np.testing.assert_allclose(values, -np.tan(cox) * x, atol=2e-6)      # 6 decimals of mm
    # the model agrees with the hand rule (it is the truth the fit was made from)
    q = np.zeros((len(x), len(bc_machine.axes)))
    q[:, bc_machine.index("X")] = x
    dev = Model(bc_machine, ["COX"]).deviation(Poses.at(q, bc_machine.ball), np.array([cox]))
    np.testing.assert_allclose(dev[:, 1], np.tan(cox) * x, rtol=1e-6, atol=1e-12)


def test_linuxcnc_pins_of_a_c_axis_off_the_z_axis(tmp_path):
    """With C's pivot at x = 1.5, y = -2.0 mm (above A's, which is at the origin) the trt
    pins are, by trtfuncs.c's meaning: the rot point at C's pivot, the offsets from it to
    A's pivot, and XOC/YOC added to the rot point (and taken out of the offsets, so A's
    line stays where it is)."""
    text = SEED_MACHINE.read_text().replace("offset = [0.0, 0.0, 29.794]", "offset = [1.5, -2.0, 29.794]")
    path = tmp_path / "m.toml"
    path.write_text(text)
    machine = load_machine(path)
    truth = {"XOC": 3 * UM, "YOC": -4 * UM}
    poses = generate(machine, ["K4", "K1", "K2"])
    fit = identify(machine, [simulate(machine, truth, poses)])
    hal = kinematics_edit(machine, fit, "linuxcnc", None, "", "KIN", "0", "d").files[".hal"]
    got = {m[1]: (float(m[2]), float(m[3])) for m in
           re.finditer(r"(?m)^setp xyzac-trt-kins\.(\S+) (\S+)\s+# was (\S+)$", hal)}
    assert got["x-rot-point"] == (pytest.approx(1.5 + 0.003, abs=1e-6), 1.5)
    assert got["y-rot-point"] == (pytest.approx(-2.0 - 0.004, abs=1e-6), -2.0)
    assert got["z-rot-point"] == (pytest.approx(29.794, abs=1e-6), 29.794)
    assert got["y-offset"] == (pytest.approx(2.0 + 0.004, abs=1e-6), 2.0)
    assert got["z-offset"] == (pytest.approx(-29.794, abs=1e-6), -29.794)
