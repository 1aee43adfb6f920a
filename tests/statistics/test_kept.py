"""A diagnosis kept beside its fit: read back as it was made (every field, the advised
measurements with their poses), refused when it was made of anything else, never replacing a
file that is not one, and read by the report in place of a diagnose of its own."""

import json
from dataclasses import replace

import numpy as np
import pytest
from conftest import ROOT, TABLE4, UM, run

from compgen.configuration.session import reload
from compgen.data.simulate import simulate
from compgen.model.paths import generate
from compgen.planning.advice import Advisor, Proposal
from compgen.statistics import kept
from compgen.statistics.diagnose import diagnose
from compgen.statistics.diagnose_text import report
from compgen.statistics.identify import identify
from compgen.statistics.results import load_fit

SESSION = ROOT / "examples" / "seed-session.csv"


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    folder = tmp_path_factory.mktemp("kept")
    assert run("fit", "--machine", "ac-trunnion-itnc530", SESSION, "-o", folder / "fit.json")[0] == 0
    fit = load_fit(str(folder / "fit.json"))
    machine, sets = reload(fit)
    found = diagnose(machine, sets, fit, fit_file="fit.json", advisor=Advisor)
    return folder, fit, machine, found, kept.key(fit, machine, None, None, True)


def _same(a, b):
    assert json.dumps(a.to_dict(), sort_keys=True) == json.dumps(b.to_dict(), sort_keys=True)
    assert report(a) == report(b)


def test_a_kept_diagnosis_reads_back_as_made(made):
    _, _, _, found, made_of = made
    back = kept.loads(kept.dumps(found, made_of), made_of, Proposal)
    _same(back, found)
    proposals = [m for c in found.candidates for m in c.separated_by]
    assert proposals, "the example advises measurements: their poses are what is tested here"
    for m, n in zip(proposals, (m for c in back.candidates for m in c.separated_by), strict=True):
        assert type(n) is type(m) and n.label == m.label and n.ball == m.ball
        for f in ("q", "ball", "t", "side", "nest"):
            np.testing.assert_array_equal(getattr(n.poses, f), getattr(m.poses, f))
        assert list(n.poses.path) == list(m.poses.path)


def test_the_rarer_fields_read_back_too(seed_machine):
    """Repeats (no noise given, K4 measured twice), the device's gains, a set-up step tried
    between two files."""
    machine = replace(seed_machine, noise_um=None)
    poses = generate(machine, ["K4"])
    rng = np.random.default_rng(4)
    data = [replace(simulate(machine, {**TABLE4, "EXC:h2c": 3 * UM}, poses, 0.5, rng), source=name)
            for name in ("a.csv", "b.csv")]
    fit = identify(machine, data)
    found = diagnose(machine, data, fit)
    assert found.repeats is not None and found.devices and found.setup_step is not None
    made_of = kept.key(fit, machine, None, None, False)
    _same(kept.loads(kept.dumps(found, made_of), made_of, Proposal), found)


@pytest.mark.parametrize("change", [{"noise_um": 0.5}, {"candidates": ["EXC:h2"]}, {"advised": False},
                                    {"compgen": "0.0.0"}, {"fit": "fit:0000000000000000"},
                                    {"machine_sha256": "0" * 64}])
def test_a_diagnosis_made_of_anything_else_is_not_read(made, change):
    _, _, _, found, made_of = made
    assert kept.loads(kept.dumps(found, made_of), {**made_of, **change}, Proposal) is None


@pytest.mark.parametrize("text", ["", "{", "[]", '{"format": "compgen.kept-diagnosis/1"}', "NaN",
                                  "[" * 100000], ids=["empty", "open", "list", "format", "nan", "deep"])
def test_a_damaged_kept_file_is_made_again(made, text):
    assert kept.loads(text, made[4], Proposal) is None


def test_a_field_this_compgen_does_not_know_is_stale(made):
    _, _, _, found, made_of = made
    doc = json.loads(kept.dumps(found, made_of))
    doc["diagnosis"]["candidates"][0]["another"] = 1
    doc["sha256"] = kept._marker(doc["diagnosis"])
    assert kept.loads(json.dumps(doc), made_of, Proposal) is None


@pytest.mark.parametrize("field, value", [("rms_um", "1.0"), ("per_path", None), ("readings", 1.5),
                                          ("verdict", "found")])
def test_a_kept_file_changed_by_hand_is_made_again(made, field, value):
    """A value of another type (the report would format it), a field gone, one added: the
    content no longer holds its marker."""
    _, _, _, found, made_of = made
    doc = json.loads(kept.dumps(found, made_of))
    doc["diagnosis"][field] = value
    assert kept.loads(json.dumps(doc), made_of, Proposal) is None


def test_a_file_that_is_not_a_kept_diagnosis_is_never_replaced(made, tmp_path):
    _, _, _, found, made_of = made
    (tmp_path / "fit.diagnosis.json").write_text("my notes\n")
    said = kept.keep(tmp_path / "fit.json", found, made_of)
    assert "not kept" in said and (tmp_path / "fit.diagnosis.json").read_text() == "my notes\n"


def test_diagnose_keeps_it_and_the_report_reads_it(tmp_path):
    assert run("fit", "--machine", "ac-trunnion-itnc530", SESSION, "-o", tmp_path / "fit.json")[0] == 0
    code, _, err = run("report", "--from", tmp_path / "fit.json", "-o", tmp_path / "fit.json", "--force")
    assert code == 2 and not (tmp_path / "fit.diagnosis.json").exists(), err      # refused: nothing kept
    code, _, err = run("report", "--from", tmp_path / "fit.json", "-o", tmp_path / "made.html")
    assert code == 0 and "kept the diagnosis in" in err, err
    path = tmp_path / "fit.diagnosis.json"
    path.unlink()
    code, out, err = run("diagnose", "--from", tmp_path / "fit.json")
    assert code == 0 and "kept the diagnosis in" in err and path.exists(), err
    code, _, err = run("report", "--from", tmp_path / "fit.json", "-o", tmp_path / "read.html")
    assert code == 0 and "kept the diagnosis" not in err, err
    assert (tmp_path / "read.html").read_text() == (tmp_path / "made.html").read_text()
    # what is read is what is kept: a word changed in it (its marker made again) shows in the
    # report; changed without its marker, the file is made again
    doc = json.loads(path.read_text())
    doc["diagnosis"]["candidates"][0]["description"] = "a mark put in the kept file"
    path.write_text(json.dumps(doc))
    code, _, err = run("report", "--from", tmp_path / "fit.json", "-o", tmp_path / "damaged.html")
    assert code == 0 and "kept the diagnosis in" in err, err
    assert "a mark put in the kept file" not in (tmp_path / "damaged.html").read_text()
    doc["sha256"] = kept._marker(doc["diagnosis"])
    path.write_text(json.dumps(doc))
    assert run("report", "--from", tmp_path / "fit.json", "-o", tmp_path / "changed.html")[0] == 0
    assert "a mark put in the kept file" in (tmp_path / "changed.html").read_text()
    # a refit put in the fit's place is another fit: its diagnosis is made again
    refit = ("fit", "--from", tmp_path / "fit.json", "--add", "EXC:h2", "-o", tmp_path / "fit2.json")
    assert run(*refit)[0] == 0
    (tmp_path / "fit.json").write_text((tmp_path / "fit2.json").read_text())
    code, _, err = run("report", "--from", tmp_path / "fit.json", "-o", tmp_path / "refit.html")
    assert code == 0 and "kept the diagnosis in" in err, err
