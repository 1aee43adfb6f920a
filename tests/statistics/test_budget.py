"""A fit's uncertainty budget: the R-test's sensor gains as its calibration allows
([rtest] gain_u) join every σ, so a gain error within the calibration stays within the σ
reported; fit.json and the report carry it; the machine file refuses a gain_u that is no
calibration."""

import json
from dataclasses import replace

import jsonschema
import numpy as np
import pytest
from conftest import SEED_MACHINE, TABLE4, run

from compgen.configuration.machine_file import load_machine
from compgen.data.simulate import simulate
from compgen.errors import CompgenError
from compgen.model.paths import generate
from compgen.statistics.budget import gain_sensitivity, with_budget
from compgen.statistics.identify import identify
from compgen.statistics.results import FitResult

GAIN_X = 0.015          # the X sensor reads 1.5 % high


@pytest.fixture(scope="module")
def sessions(seed_machine):
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    out = []
    for seed in range(5):
        d = simulate(seed_machine, TABLE4, poses, 0.5, np.random.default_rng(seed))
        out.append(replace(d, deviation=d.deviation * np.array([1 + GAIN_X, 1, 1])))
    return out


def _worst(fit):
    return max(abs(fit.parameters[n].value - v) / fit.parameters[n].std for n, v in TABLE4.items())


def test_a_gain_error_within_the_calibration_stays_within_the_sigma(seed_machine, sessions):
    """1.5 % on X: by the data's σ alone the location errors end up to ~5σ off; with a 1 %
    calibration declared, every one is within 3σ in every session."""
    calibrated = replace(seed_machine, gain_u=0.01)
    alone = [_worst(identify(seed_machine, [d])) for d in sessions]
    held = [_worst(with_budget(calibrated, [d], identify(calibrated, [d]))) for d in sessions]
    assert max(alone) > 3 and max(held) < 3, (alone, held)


def test_the_gain_sensitivity_is_the_refit_of_scaled_readings(seed_machine, sessions):
    """First order: readings scaled by 1 + g in X move the fit by g times the sensitivity."""
    d = sessions[0]
    fit = identify(seed_machine, [d])
    s = gain_sensitivity(seed_machine, [d], fit)
    assert s.shape == (3, len(fit.free))       # one row per sensor, X Y Z
    g = 1e-3
    moved = identify(seed_machine, [replace(d, deviation=d.deviation * np.array([1 + g, 1, 1]))])
    got = np.array([moved.parameters[n].value - fit.parameters[n].value for n in fit.free])
    np.testing.assert_allclose(got, g * s[0], rtol=0.02, atol=1e-9)


def test_the_budget_is_in_fit_json_and_the_report(seed_machine, sessions):
    calibrated = replace(seed_machine, gain_u=0.002)
    fit = with_budget(calibrated, sessions[:1], identify(calibrated, sessions[:1]))
    assert fit.device_budget["gain_u"] == 0.002 and set(fit.device_budget["std"]) == set(fit.free)
    again = FitResult.from_dict(json.loads(fit.to_json()))
    assert again.device_budget == fit.device_budget and again.to_json() == fit.to_json()
    text = fit.report()
    assert "sensor gains as its calibration allows (± 0.2 %, [rtest] gain_u)" in text
    # their share: the six whose σ the gains make most of, largest share first
    share = {n: fit.device_budget["std"][n] / fit.parameters[n].std for n in fit.free}
    listed = text.split("their share:\n")[1].splitlines()[0].strip().split(", ")
    assert [item.split()[0] for item in listed] == sorted(share, key=share.get, reverse=True)[:6], listed
    for bad in ({"gain_u": -1, "std": {}}, {"gain_u": 0.01, "std": {"YOW": "x"}}, {"std": {}}):
        with pytest.raises(CompgenError, match="device budget"):
            FitResult.from_dict({**json.loads(fit.to_json()), "device_budget": bad})


@pytest.mark.parametrize("value, ok", [("0.002", True), ("0", True), ("0.2", False), ("-0.01", False),
                                       ('"1 %"', False)])
def test_the_machine_file_reads_gain_u_as_a_fraction(tmp_path, value, ok):
    path = tmp_path / "m.toml"
    path.write_text(SEED_MACHINE.read_text().replace("[rtest]\n", f"[rtest]\ngain_u = {value}\n", 1))
    if ok:
        assert load_machine(path).gain_u == float(value)
    else:
        with pytest.raises(CompgenError, match="gain_u"):
            load_machine(path)


def test_fit_prints_the_budget_of_a_calibrated_r_test(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(SEED_MACHINE.read_text().replace("[rtest]\n", "[rtest]\ngain_u = 0.005\n", 1))
    session = SEED_MACHINE.parents[1] / "examples" / "seed-session.csv"
    code, out, err = run("fit", "--machine", path, session, "-o", tmp_path / "fit.json")
    assert code == 0, err
    assert "(± 0.5 %, [rtest] gain_u)" in out
    doc = json.loads((tmp_path / "fit.json").read_text())
    assert doc["device_budget"]["gain_u"] == 0.005
    schema = json.loads((SEED_MACHINE.parents[1] / "docs" / "schemas" / "fit.schema.json").read_text())
    jsonschema.Draft202012Validator(schema).validate(doc)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.Draft202012Validator(schema).validate({**doc, "device_budget": {"gain_u": 0.2, "std": {}}})
