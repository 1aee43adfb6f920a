"""LinuxCNC's trt kinematics under both values of its conventional-directions pin, checked
against LinuxCNC's current source (no LinuxCNC needed): the forward kinematics below are
transcribed from ``src/emc/kinematics/trtfuncs.c`` (LinuxCNC master, 2.10.0~pre1, commit
5c41560ebb; the pin came with bfb687eaa6, 2.10.0~pre0), ``con`` = +1 with the pin true, −1
with it false. Debian's 2.9.0~pre1, which predates the pin, runs compgen's default-direction
programs in ``tests/controllers/test_linuxcnc.py``; here the transcription is first held to those, then
used for the mirrored convention."""

import re

import numpy as np
import pytest
from conftest import BC_MACHINE, SEED_MACHINE

from compgen.configuration.machine_file import load_machine
from compgen.controllers import linuxcnc
from compgen.controllers.programs import measure_program, read_program
from compgen.errors import CompgenError
from compgen.model.paths import generate


def xyzac_forward(j, pins, con):
    """xyzacKinematicsForward: joints X Y Z A C (mm, deg) → the tool point (tool-offset 0)."""
    x, y, z, a, c = j[:, 0], j[:, 1], j[:, 2], np.radians(j[:, 3]), np.radians(j[:, 4])
    xr, yr, zr, dy, dz = (pins[k] for k in ("x-rot-point", "y-rot-point", "z-rot-point", "y-offset",
                                             "z-offset"))
    return np.column_stack([
        np.cos(c) * (x - xr) - con * np.sin(c) * np.cos(a) * (y - dy - yr)
        + np.sin(c) * np.sin(a) * (z - dz - zr) - con * np.sin(c) * dy + xr,
        con * np.sin(c) * (x - xr) + np.cos(c) * np.cos(a) * (y - dy - yr)
        - con * np.cos(c) * np.sin(a) * (z - dz - zr) + np.cos(c) * dy + yr,
        con * np.sin(a) * (y - dy - yr) + np.cos(a) * (z - dz - zr) + dz + zr])


def xyzbc_forward(j, pins, con):
    """xyzbcKinematicsForward: joints X Y Z B C (mm, deg) → the tool point (tool-offset 0)."""
    x, y, z, b, c = j[:, 0], j[:, 1], j[:, 2], np.radians(j[:, 3]), np.radians(j[:, 4])
    xr, yr, zr, dx, dz = (pins[k] for k in ("x-rot-point", "y-rot-point", "z-rot-point", "x-offset",
                                             "z-offset"))
    return np.column_stack([
        np.cos(c) * np.cos(b) * (x - dx - xr) - con * np.sin(c) * (y - yr)
        + con * np.cos(c) * np.sin(b) * (z - dz - zr) + np.cos(c) * dx + xr,
        con * np.sin(c) * np.cos(b) * (x - dx - xr) + np.cos(c) * (y - yr)
        + np.sin(c) * np.sin(b) * (z - dz - zr) + con * np.sin(c) * dx + yr,
        -con * np.sin(b) * (x - dx - xr) + np.cos(b) * (z - dz - zr) + dz + zr])


def _machine(tmp_path, source, conventional):
    text = re.sub(r'controller = "\w+"', 'controller = "linuxcnc"', source.read_text())
    text = text.replace('tool = "RTEST"', 'tool = "7"').replace(
        "conventional_directions = false", f"conventional_directions = {str(conventional).lower()}")
    if conventional:            # the pin exists from LinuxCNC 2.10
        text = text.replace('version = "2.9"', 'version = "2.10"')
    path = tmp_path / f"m{int(conventional)}.toml"
    path.write_text(text)
    return load_machine(path)


@pytest.mark.parametrize("source", [SEED_MACHINE, BC_MACHINE], ids=["xyzac", "xyzbc"])
@pytest.mark.parametrize("conventional", [False, True])
def test_programs_put_the_nest_on_the_ball_under_either_convention(tmp_path, source, conventional):
    """The machine axes compgen plans (its pose list) and the angles its TCP program writes,
    through LinuxCNC's forward kinematics with the pin as the machine file says, land on the
    program's own X Y Z to the 0.1 µm it writes; the angles are the pose list's, mirrored
    when the pin is true."""
    m = _machine(tmp_path, source, conventional)
    module, tilt, c = linuxcnc.trt_module(m)
    pins = linuxcnc.nominal_pins(m, tilt, c)
    pins.setdefault("x-offset", 0.0)
    pins.setdefault("y-offset", 0.0)
    files = measure_program(m, generate(m, ["K4", "K1"]), "K4", "linuxcnc", "tcpm", "K4", "0", "d").files
    _, xyz, rot = read_program(files[".ngc"], m, "linuxcnc")          # compgen's angles
    listed = np.loadtxt(files[".poses.csv"].splitlines()[1:], delimiter=",", usecols=(1, 2, 3, 4, 5))
    np.testing.assert_allclose(rot, listed[:, 3:], atol=1e-9)
    written = [float(v) for v in re.findall(rf"(?m)^G1 .*{tilt.name}(\S+) C\S+ F\S+ ; pose", files[".ngc"])]
    sign = -1 if conventional else 1
    np.testing.assert_allclose(written, sign * rot[:, 0], atol=1e-9)
    joints = np.column_stack([listed[:, :3], sign * listed[:, 3:]])
    forward = xyzac_forward if module.startswith("xyzac") else xyzbc_forward
    np.testing.assert_allclose(forward(joints, pins, 1.0 if conventional else -1.0), xyz, atol=1e-4)
    # the same program under the other convention lands elsewhere: the pin matters
    wrong = forward(joints, pins, -1.0 if conventional else 1.0)
    assert np.abs(wrong - xyz).max() > 10.0


def test_a_linuxcnc_machine_must_say_which_way_its_trt_kinematics_turn(tmp_path):
    text = re.sub(r'controller = "\w+"', 'controller = "linuxcnc"', SEED_MACHINE.read_text())
    text = re.sub(r"(?ms)^\[linuxcnc\].*?(?=^\[)", "", text).replace('tool = "RTEST"', 'tool = "7"')
    (tmp_path / "m.toml").write_text(text)
    m = load_machine(tmp_path / "m.toml")
    with pytest.raises(CompgenError, match=r"\[linuxcnc\] conventional_directions"):
        measure_program(m, generate(m, ["K4"]), "K4", "linuxcnc", "tcpm", "K4", "0", "d")
