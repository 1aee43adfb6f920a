"""A Hirth-coupled rotary axis (``hirth_deg``): its paths rest on the grid, every program of
every control holds only grid positions and takes the nest off the ball before the axis
indexes (the control releases and clamps it: U23), and passes check-program; a pose list
between the teeth is refused, as are a grid that is no whole number of teeth and a session
sampled on the fly while the axis turns."""

import re

import numpy as np
import pytest
from conftest import SEED_MACHINE, TABLE4, run

from compgen.configuration.machine_file import load_machine
from compgen.data.simulate import simulate
from compgen.model.paths import generate
from compgen.statistics.identify import identify

WORD = {"itnc530": r"\bC([+-]\d+\.\d+)", "sinumerik840d": r"\bC(?:=(?:DC|ACP|ACN)\()?(-?\d+\.\d+)",
        "linuxcnc": r"\bC(-?\d+\.\d+)"}
EXT = {"itnc530": ".H", "sinumerik840d": ".MPF", "linuxcnc": ".ngc"}


@pytest.fixture
def hirth(tmp_path):
    path = tmp_path / "hirth.toml"
    path.write_text(SEED_MACHINE.read_text().replace('axis = "C"\n', 'axis = "C"\nhirth_deg = 3.0\n', 1))
    return path


@pytest.mark.parametrize("ctl", sorted(WORD))
def test_a_hirth_axis_is_programmed_on_its_grid_only(hirth, tmp_path, ctl):
    out = tmp_path / f"K{EXT[ctl]}"
    code, _, err = run("measure-program", "--machine", hirth, "--path", "all", "--controller", ctl, "-o", out)
    assert code == 0, err
    text = out.read_text()
    body = [ln for ln in text.splitlines() if not ln.lstrip("0123456789 ").startswith((";", "("))]
    values = [float(v) for ln in body for v in re.findall(WORD[ctl], ln)]
    assert len(values) > 100 and all(abs(v / 3.0 - round(v / 3.0)) < 1e-9 for v in values), values[:20]
    assert "UNCONFIRMED U23" in text and "Hirth-coupled (3 deg grid)" in text
    # the nest leaves the ball before each index: as many such moves as C changes between poses
    rows = [ln.split(",") for ln in (tmp_path / "K.poses.csv").read_text().splitlines()]
    at, path = rows[0].index("C"), [r[0] for r in rows[1:]]
    c = [float(r[at]) for r in rows[1:]]
    within = sum(1 for i in range(1, len(c)) if c[i] != c[i - 1] and path[i] == path[i - 1])
    assert text.count("a Hirth axis indexes") == within > 100
    code, said, err = run("check-program", "--machine", hirth, "--controller", ctl, out)
    assert code == 0 and "OK" in said, err


def test_a_pose_between_the_teeth_is_refused(hirth, tmp_path):
    (tmp_path / "p.csv").write_text("path,A,C\nK2,0,0\nK2,0,1.5\nK2,0,3\n")
    code, _, err = run("measure-program", "--machine", hirth, "--poses", tmp_path / "p.csv", "-o",
                       tmp_path / "P.H")
    assert code == 2 and "between the teeth" in err and "pose 2" in err and not (tmp_path / "P.H").exists()


@pytest.mark.parametrize("text, says", [('axis = "X"\n', "rotary axis"), ('axis = "C"\n', "whole number")])
def test_a_grid_that_is_no_hirth_coupling_is_refused(tmp_path, text, says):
    grid = "3.0" if "X" in text else "7.0"
    path = tmp_path / "m.toml"
    path.write_text(SEED_MACHINE.read_text().replace(text, text + f"hirth_deg = {grid}\n", 1))
    code, _, err = run("effects", "--machine", path)
    assert code == 2 and "hirth_deg" in err and "whole number of teeth" in err, err


def test_a_hirth_axis_is_not_measured_on_the_fly(hirth, tmp_path):
    truth = tmp_path / "t.json"
    truth.write_text('{"parameters": {}}')
    code, _, err = run("simulate", "--machine", hirth, "--truth", truth, "--paths", "K2", "--rate-hz", "10",
                       "-o", tmp_path / "s.csv")
    assert code == 2 and "Hirth" in err and not (tmp_path / "s.csv").exists(), err


def test_a_session_on_the_grid_is_fitted_to_the_noise(hirth):
    machine = load_machine(hirth)
    poses = generate(machine, ["K4", "K1", "K2"])
    assert np.allclose(np.degrees(poses.q[:, machine.index("C")]) / 3.0,
                       np.round(np.degrees(poses.q[:, machine.index("C")]) / 3.0))
    fit = identify(machine, [simulate(machine, TABLE4, poses, 0.5, np.random.default_rng(2))])
    off = {n: abs(fit.parameters[n].value - v) / fit.parameters[n].std for n, v in TABLE4.items()}
    assert fit.residual["sigma_um"] == pytest.approx(0.5, rel=0.1) and max(off.values()) < 4, off
