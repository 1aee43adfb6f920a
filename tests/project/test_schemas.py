"""The JSON compgen writes, against the schemas in docs/schemas (what a user's own tools may
rely on): fit.json, diagnose --json, check-program --json, check --json."""

import json

import jsonschema
import pytest
from conftest import ROOT, SEED_MACHINE, run

from compgen.errors import CompgenError
from compgen.statistics.results import FitResult

SCHEMAS = ROOT / "docs" / "schemas"
SESSION = ROOT / "examples" / "seed-session.csv"


def _validate(doc, name):
    schema = json.loads((SCHEMAS / f"{name}.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.Draft202012Validator(schema).validate(doc)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fit")
    assert run("fit", "--machine", SEED_MACHINE, SESSION, "-o", folder / "fit.json")[0] == 0
    return folder


def test_fit_json_meets_its_schema_and_a_damaged_one_does_not(fitted):
    doc = json.loads((fitted / "fit.json").read_text())
    _validate(doc, "fit")
    for damage in ({**doc, "sign": "nest-plus-ball"}, {k: v for k, v in doc.items() if k != "residual"},
                   {**doc, "parameters": {"XOC": {"value": 1.0, "unit": "um", "std": 0.1}}}):
        with pytest.raises(jsonschema.ValidationError):
            _validate(damage, "fit")


def test_a_fit_with_choices_meets_the_schema_and_a_bad_choice_does_not(fitted):
    """fit.json's choices (what a fit cannot tell apart, already in the σ): as written, and
    damaged."""
    doc = json.loads((fitted / "fit.json").read_text())
    choice = {"effect": "EYA+EZA:h-1", "equivalents": ["EZA:h1"], "half_range": {"ZOW": 0.0015}}
    _validate({**doc, "choices": [choice]}, "fit")
    for bad in ({**choice, "equivalents": []}, {**choice, "half_range": {"ZOW": "big"}},
                {k: v for k, v in choice.items() if k != "effect"}):
        with pytest.raises(jsonschema.ValidationError):
            _validate({**doc, "choices": [bad]}, "fit")
        with pytest.raises(CompgenError, match="a choice must hold"):
            FitResult.from_dict({**doc, "choices": [bad]})


def test_diagnose_json_meets_its_schema(fitted):
    code, out, err = run("diagnose", "--from", fitted / "fit.json", "--json")
    assert code == 0, err
    doc = json.loads(out)
    _validate(doc, "diagnose")
    assert doc["candidates"] and any(c["separated_by"] for c in doc["candidates"])


def test_check_program_json_meets_its_schema(tmp_path):
    program = tmp_path / "K4.H"
    assert run("measure-program", "--machine", SEED_MACHINE, "--path", "K4", "-o", program)[0] == 0
    code, out, _ = run("check-program", "--machine", SEED_MACHINE, program, "--json")
    assert code == 0
    doc = json.loads(out)
    _validate(doc, "check-program")
    assert doc["ok"] and doc["ball_from"] == "the program's header"
