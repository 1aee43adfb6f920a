"""Shapes the user declares (``[effects.shapes.NAME]``): a spline through knots and a lookup
table, for any component error of any axis, used by fit, diagnose and the kinematics plan as
catalogue effects are. The hidden errors here move the nominal machine's X axis (never
through compgen's effect), so the sign and the scale are the physics', not the model's."""

import numpy as np
import pytest
from conftest import SEED_MACHINE, TABLE4, run

from compgen.configuration.machine_file import load_machine
from compgen.controllers.correction import plan
from compgen.data.simulate import simulate
from compgen.errors import CompgenError
from compgen.model.effects import compose, effect_of_param, resolve
from compgen.model.paths import generate
from compgen.statistics.diagnose import diagnose
from compgen.statistics.identify import identify

NOISE_UM = 0.5
KNOTS = [-220.0, -110.0, 0.0, 110.0, 220.0]          # mm along X; the paths reach ±217.5 mm
SCREW = [0.0, 2.0, -1.0, 1.5, 0.5]                   # µm: X stands off by this, linear between
TABLE_AT = [-300.0, -200.0, -100.0, 0.0, 100.0, 200.0, 300.0]
TABLE = [0.0, 1.0, 3.0, 2.0, -1.0, 0.5, 0.0]         # a laser run's shape, any unit
SHAPES = f"""
[effects.shapes.screw]
at = {KNOTS}

[effects.shapes.laser]
at = {TABLE_AT}
values = {TABLE}
"""


@pytest.fixture(scope="module")
def machine(tmp_path_factory):
    path = tmp_path_factory.mktemp("shapes") / "m.toml"
    path.write_text(SEED_MACHINE.read_text().replace("[rtest]\n", "[rtest]\nnoise_um = 0.5\n", 1) + SHAPES)
    return load_machine(path)


def _session(machine, at, values, scale, seed):
    """K4, K1, K2 with X standing off by ``scale`` µm × the curve through (at, values)."""
    x = machine.index("X")

    def drive(p):
        q = p.q.copy()
        q[:, x] += scale * 1e-3 * np.interp(q[:, x], at, values)
        return q
    return [simulate(machine, TABLE4, generate(machine, ["K4", "K1", "K2"]), NOISE_UM,
                     np.random.default_rng(seed), drive=drive)]


@pytest.mark.parametrize("seed", [5, 6])
def test_a_spline_through_declared_knots_takes_the_curve_it_can_draw(machine, seed):
    """X off by a curve through the spline's own knots: EXX:s.screw's values at knots 2–5
    are the curve's within 3σ (minus: X's sense is −1, the error displaces the carried
    frame), zero at the first knot by construction, and σ̂ falls to the noise."""
    data = _session(machine, KNOTS, SCREW, 1.0, seed)
    base = identify(machine, data)
    fit = identify(machine, data, compose(machine, base.model, ["EXX:s.screw"]))
    names = [f"EXX:s.screw.{i}" for i in range(2, 6)]
    assert [n for n in fit.model if n.startswith("EXX")] == names
    got = np.array([fit.parameters[n].value for n in names]) * 1e3
    std = np.array([fit.parameters[n].std for n in names]) * 1e3
    assert np.all(np.abs(got + np.array(SCREW[1:])) < 3 * std), (got, std)
    assert abs(fit.residual["sigma_um"] - NOISE_UM) < 0.05 < base.residual["sigma_um"] - NOISE_UM


def test_a_lookup_table_is_fitted_in_size(machine):
    """X off by 1.5 × the laser table (peak 3 → 4.5 µm): EXX:l.laser, the table's size at its
    largest value, is −4.5 µm within 3σ and σ̂ falls to the noise; diagnose, which tries
    declared effects only when the machine file lists them, is given it as a candidate and
    names it found."""
    data = _session(machine, TABLE_AT, TABLE, 1.5, 7)
    base = identify(machine, data)
    fit = identify(machine, data, compose(machine, base.model, ["EXX:l.laser"]))
    size = fit.parameters["EXX:l.laser"]
    assert abs(size.value * 1e3 + 4.5) < 3 * size.std * 1e3, (size.value, size.std)
    assert abs(fit.residual["sigma_um"] - NOISE_UM) < 0.05
    found = diagnose(machine, data, base, candidates=["EXX:l.laser", "EXX:p2", "EXX:p3"])
    assert found.found == "EXX:l.laser", [c.effect for c in found.significant]


def test_a_declared_shape_names_its_parameters_and_its_shape(machine):
    e = resolve(machine, "EXX:s.screw")
    assert e.params == ("EXX:s.screw.2", "EXX:s.screw.3", "EXX:s.screw.4", "EXX:s.screw.5")
    assert effect_of_param(machine, "EXX:s.screw.3") == e
    assert "a spline through 5 knots from -220 to 220 mm (screw; zero at the first" in e.words
    hats = e.basis.values(np.array(KNOTS + [-400.0, 55.0, 400.0]) / 1000.0)
    np.testing.assert_allclose(hats[:5], np.eye(5)[:, 1:], atol=1e-15)     # 1 at its own knot
    np.testing.assert_allclose(hats[5:], [[0, 0, 0, 0], [0, 0.5, 0.5, 0], [0, 0, 0, 1]], atol=1e-15)
    table = resolve(machine, "EZZ:l.laser")
    assert table.params == ("EZZ:l.laser",) and max(np.abs(table.basis.table)) == 1.0
    np.testing.assert_allclose(table.basis.values(np.array([-0.1, -0.15]))[:, 0], [1.0, 2.0 / 3.0])
    c = resolve(machine, "ECC:s.screw")          # a rotary axis's shape: its positions in deg
    np.testing.assert_allclose(c.basis.at, np.radians(KNOTS))


def test_a_correction_table_holds_a_shape_only_where_its_corners_are_two_steps_apart(machine, tmp_path):
    """X's travel of 800 mm in 37 points steps 22.2 mm: knots 110 mm apart go into a table, 30 mm
    apart (less than two steps) are not compensable there."""
    data = _session(machine, KNOTS, SCREW, 1.0, 5)
    fit = identify(machine, data, compose(machine, identify(machine, data).model, ["EXX:s.screw"]))
    assert plan(machine, fit).tables == ("EXX:s.screw",)
    path = tmp_path / "fine.toml"
    path.write_text(SEED_MACHINE.read_text() + "\n[effects.shapes.screw]\nat = [-220, -30, 0, 30, 220]\n")
    fine = load_machine(path)
    fit_fine = identify(fine, data, compose(fine, identify(fine, data).model, ["EXX:s.screw"]))
    assert "EXX:s.screw" in plan(fine, fit_fine).not_compensable


@pytest.mark.parametrize("shapes, says", [
    ("[effects.shapes.screw]\nat = [0, 100, 50]\n", r"effects: shapes: screw: at: positions must increase"),
    ("[effects.shapes.screw]\nat = [0, 100]\n", r"shapes: screw: at: must be a list of 3 or more finite"),
    ("[effects.shapes.t]\nat = [0, 1]\nvalues = [1, 2, 3]\n", r"shapes: t: values: must be a list of 2"),
    ("[effects.shapes.t]\nat = [0, 1]\nvalues = [0, 0]\n", r"shapes: t: values: a lookup table of zeros"),
    ("[effects.shapes.Screw]\nat = [0, 1, 2]\n", r"effects: shapes: Screw: a shape's name is lower-case"),
    ("[effects.shapes.screw]\nat = [0, 1, 2]\nknots = [1]\n", r"effects: shapes: screw: unknown key knots"),
    ('[effects]\ndeclared = ["EXX:s.nut"]\n',
     r"declared\[0\]: EXX:s.nut: the machine file declares no spline through knots \(at\) named .nut."),
    ('[effects]\ndeclared = ["EXX:l.screw"]\n[effects.shapes.screw]\nat = [0, 1, 2]\n',
     r"declared\[0\]: EXX:l.screw: the machine file declares no lookup table \(at, values\) named 'screw'"),
    ('[effects]\ndeclared = ["XOC:s.screw"]\n[effects.shapes.screw]\nat = [0, 1, 2]\n',
     r"declared\[0\]: XOC:s.screw: a declared shape is for a component error of an axis"),
])
def test_a_bad_shape_is_refused_with_its_file_and_key(tmp_path, shapes, says):
    path = tmp_path / "m.toml"
    path.write_text(SEED_MACHINE.read_text() + "\n" + shapes)
    with pytest.raises(CompgenError, match=says):
        load_machine(path)


def test_fit_add_and_diagnose_take_a_declared_shape_from_the_command_line(machine, tmp_path):
    """The shape lives in the machine file: fit.json names the file, diagnose reloads it."""
    from compgen.data.rtest import format_rtest
    path = tmp_path / "m.toml"
    path.write_text(SEED_MACHINE.read_text() + SHAPES)
    csv = tmp_path / "s.csv"
    csv.write_text(format_rtest(machine, _session(machine, TABLE_AT, TABLE, 1.5, 8)[0]))
    code, out, err = run("fit", "--machine", path, csv, "--add", "EXX:l.laser", "-o", tmp_path / "f.json")
    assert code == 0 and "EXX:l.laser" in out, err
    code, out, err = run("diagnose", "--from", tmp_path / "f.json", "--noise-um", "0.5")
    assert code == 0, err
    assert "No candidate is significant: the model explains these data to the R-test" in out, out
    code, _, err = run("fit", "--machine", SEED_MACHINE, csv, "--add", "EXX:l.laser", "-o", tmp_path / "g")
    assert code == 2 and "declares no lookup table (at, values) named 'laser'" in err, err


def test_kinematics_writes_a_declared_spline_into_the_compensation_table(machine, tmp_path):
    """The .comp.csv holds EXX:s.screw on X's 33 points (a round 25 mm step over ±400 mm,
    the finest that spans X's travel in at most 37): the command that undoes the curve X
    stood off by (within 0.5 µm of minus that curve, held beyond the knots) — the fitted
    spline in X's sense — and a value that rounds to zero is written 0.000000, not -0.000000."""
    from compgen.data.rtest import format_rtest
    path = tmp_path / "m.toml"
    path.write_text(SEED_MACHINE.read_text() + SHAPES)
    csv = tmp_path / "s.csv"
    csv.write_text(format_rtest(machine, _session(machine, KNOTS, SCREW, 1.0, 5)[0]))
    assert run("fit", "--machine", path, csv, "--add", "EXX:s.screw", "-o", tmp_path / "f.json")[0] == 0
    code, _, err = run("kinematics", "--from", tmp_path / "f.json", "-o", tmp_path / "KIN.txt")
    assert code == 0, err
    text = (tmp_path / "KIN.comp.csv").read_text()
    rows = [r.split(",") for r in text.splitlines() if r.startswith("EXX:s.screw,")]
    assert len(rows) == 33 and [float(r[2]) for r in rows[:2]] == [-400.0, -375.0] and "-0.000000" not in text
    from compgen.statistics.results import load_fit
    fit = load_fit(tmp_path / "f.json")
    spline = [0.0] + [fit.parameters[f"EXX:s.screw.{i}"].value for i in range(2, 6)]
    x, comp = np.array([[float(r[2]), float(r[4])] for r in rows]).T
    np.testing.assert_allclose(comp, -machine.axis("X").sense * np.interp(x, KNOTS, spline), atol=1e-6)
    assert np.abs(comp + 1e-3 * np.interp(x, KNOTS, SCREW)).max() < 0.5e-3
