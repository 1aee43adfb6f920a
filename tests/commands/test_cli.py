"""Bad input: one line on stderr naming what and where, exit code 2, no traceback, and no
output file written. Good input: the commands do what the README says."""

import json
import os
from pathlib import Path

import numpy as np
import pytest
from conftest import BC_MACHINE, ROOT, SEED_MACHINE, TABLE4, run

from compgen.configuration.machine_file import load_machine
from compgen.data.rtest import format_rtest
from compgen.data.simulate import simulate
from compgen.model.paths import generate

GOOD_HEADER = "path,t,X,Y,Z,A,C,dX,dY,dZ"
GOOD_ROW = "K4,0.000,-217.5040,-0.2790,241.3310,0.0000,0.0000,-7.8617,2.7427,-6.7288"




@pytest.fixture
def truth(tmp_path):
    path = tmp_path / "truth.json"
    path.write_text(json.dumps({"parameters": {
        n: {"value": v * (1e3 if n[0] in "XYZ" else 648000 / 3.141592653589793),
            "unit": "um" if n[0] in "XYZ" else "arcsec"} for n, v in TABLE4.items()}}))
    return path


@pytest.fixture
def good_csv(tmp_path, truth):
    path = tmp_path / "good.csv"
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--noise-um",
                       0.5, "--seed", 7, "-o", path)
    assert code == 0, err
    return path


def test_simulate_then_fit_recovers_truth(tmp_path, good_csv):
    out = tmp_path / "fit.json"
    code, stdout, err = run("fit", "--machine", SEED_MACHINE, good_csv, "-o", out)
    assert code == 0, err
    fit = json.loads(out.read_text())
    for name, value in TABLE4.items():
        p = fit["parameters"][name]
        assert abs(p["value"] - value) < 4 * p["std"], name
    assert "YOC" in stdout and "µm" in stdout and "″" in stdout and "K4" in stdout
    assert abs(fit["residual"]["rms_um"] - 0.5) < 0.05


def test_aliases_and_fixing_on_the_command_line(tmp_path, good_csv):
    out = tmp_path / "fit.json"
    code, stdout, err = run("fit", "--machine", SEED_MACHINE, good_csv, "--fix", "X0C=1.4um",
                            "--fix", "E_B0C=-4.6arcsec", "-o", out)
    assert code == 0, err
    params = json.loads(out.read_text())["parameters"]
    assert params["XOC"]["fixed"] and params["BOC"]["fixed"] and "X0C" not in params


def _bad_csv(tmp_path, text: str | bytes):
    path = tmp_path / "bad.csv"
    (path.write_bytes if isinstance(text, bytes) else path.write_text)(text)
    return path


BAD_DATA = {
    "empty": ("", "empty file"),
    "comments only": ("# nothing\n\n", "empty file"),
    "header only": (GOOD_HEADER + "\n", "header only"),
    "missing column": ("path,t,X,Y,Z,A,dX,dY,dZ\n" + "K4,0,1,2,3,4,5,6,7\n", "missing column C"),
    "text in a number": (GOOD_HEADER + "\n" + GOOD_ROW.replace("-7.8617", "abc") + "\n",
                         "bad.csv:2:8"),
    "NaN": (GOOD_HEADER + "\n" + GOOD_ROW.replace("2.7427", "nan") + "\n", "bad.csv:2:9"),
    "infinity": (GOOD_HEADER + "\n" + GOOD_ROW.replace("0.0000,0.0000", "inf,0.0000") + "\n",
                 "bad.csv:2:6"),
    "ragged": (GOOD_HEADER + "\n" + GOOD_ROW + "\n" + GOOD_ROW + ",1\n", "bad.csv:3"),
    "binary": (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "binary"),
    "not utf-8": (b"path,X\n\xff\xfe\xfa\n", "not UTF-8"),
    "duplicate column": ("path,X,X,Y,Z,A,C,dX,dY,dZ\n", "appears twice"),
    "wrong machine": (GOOD_HEADER + "\n" + GOOD_ROW.replace("-217.5040", "-117.5040") + "\n",
                      "from the nominal ball"),
    "too few poses": (GOOD_HEADER + "\n" + GOOD_ROW + "\n" * 2, "readings for 11 parameters"),
    "degenerate poses": (GOOD_HEADER + "\n" + (GOOD_ROW + "\n") * 50, "cannot separate"),
}


@pytest.mark.parametrize("case", BAD_DATA)
def test_bad_data_is_refused_cleanly(tmp_path, case):
    text, expected = BAD_DATA[case]
    out = tmp_path / "fit.json"
    code, stdout, err = run("fit", "--machine", SEED_MACHINE, _bad_csv(tmp_path, text), "-o", out)
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert expected in err, err
    assert not out.exists()


BAD_MACHINE = {
    "not toml": ("name = [unclosed\n", "not valid TOML"),
    "missing rtest": ('name = "m"\ncontroller = "itnc530"\n[[workpiece]]\naxis="C"\n', "missing key"),
    "unknown controller": ('name = "m"\ncontroller = "fanuc"\n', "unknown controller"),
}


@pytest.mark.parametrize("case", BAD_MACHINE)
def test_bad_machine_file_is_refused_cleanly(tmp_path, good_csv, case):
    text, expected = BAD_MACHINE[case]
    machine = tmp_path / "m.toml"
    machine.write_text(text)
    out = tmp_path / "fit.json"
    code, _, err = run("fit", "--machine", machine, good_csv, "-o", out)
    assert code == 2 and err.count("\n") == 1 and expected in err, err
    assert not out.exists()


def test_machine_file_errors_name_the_key(tmp_path, good_csv):
    text = SEED_MACHINE.read_text().replace("travel = [-120.0, 120.0]", "travel = [120.0, -120.0]")
    machine = tmp_path / "m.toml"
    machine.write_text(text)
    code, _, err = run("fit", "--machine", machine, good_csv, "-o", tmp_path / "f.json")
    assert code == 2 and "workpiece[1]: travel" in err, err


@pytest.mark.parametrize("args, expected", [
    (["--model", "XOW,NOPE"], "unknown effect 'NOPE'"),
    (["--fix", "BOA=12.3"], "has no unit"),
    (["--fix", "BOA=12.3um"], "is not an angle"),
    (["--fix", "BOA"], "NAME=VALUE"),
])
def test_bad_options_are_refused_cleanly(tmp_path, good_csv, args, expected):
    out = tmp_path / "fit.json"
    code, _, err = run("fit", "--machine", SEED_MACHINE, good_csv, *args, "-o", out)
    assert code == 2 and expected in err and err.count("\n") == 1, err
    assert not out.exists()


def test_missing_files_are_refused_cleanly(tmp_path, good_csv):
    for args in (["--machine", tmp_path / "nope.toml", good_csv],
                 ["--machine", SEED_MACHINE, tmp_path / "nope.csv"]):
        code, _, err = run("fit", *args, "-o", tmp_path / "f.json")
        assert code == 2 and "nope" in err and "Traceback" not in err, err


def test_existing_output_needs_force(tmp_path, good_csv, truth):
    out = tmp_path / "fit.json"
    out.write_text("mine")
    code, _, err = run("fit", "--machine", SEED_MACHINE, good_csv, "-o", out)
    assert code == 2 and "--force" in err and out.read_text() == "mine"
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "-o", out)
    assert code == 2 and out.read_text() == "mine"
    code, _, err = run("fit", "--machine", SEED_MACHINE, good_csv, "-o", out, "--force")
    assert code == 0 and json.loads(out.read_text())["format"] == "compgen.fit/1"


@pytest.mark.parametrize("args, expected", [
    (["--paths", "K9"], "defines no path 'K9'"),
    (["--noise-um", "-1"], "noise"),
    (["--noise-um", "0.5", "--noise-rho", "1"], "ρ must be in [0, 1)"),
    (["--noise-um", "0.5", "--noise-rho", "nan"], "'nan' is not a finite number"),
    (["--ball", "1,2"], "three numbers"),
    (["--ball", "0,0,900"], "outside its travel"),
])
def test_simulate_refuses_bad_requests(tmp_path, truth, args, expected):
    out = tmp_path / "s.csv"
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", truth, *args, "-o", out)
    assert code == 2 and expected in err and err.count("\n") == 1, err
    assert not out.exists()


def test_simulate_writes_what_fit_reads_on_the_bc_machine(tmp_path):
    truth = tmp_path / "t.json"
    truth.write_text('{"parameters": {"XOB": {"value": 12, "unit": "um"}}}')
    data = tmp_path / "bc.csv"
    assert run("simulate", "--machine", BC_MACHINE, "--truth", truth, "--paths", "BK4,K1,K2",
               "-o", data)[0] == 0
    code, stdout, err = run("fit", "--machine", BC_MACHINE, data, "-o", tmp_path / "f.json")
    assert code == 0, err
    fit = json.loads((tmp_path / "f.json").read_text())
    assert abs(fit["parameters"]["XOB"]["value"] - 0.012) < 1e-8


@pytest.fixture
def hidden_session(tmp_path):
    truth = tmp_path / "truth.json"
    truth.write_text(json.dumps({"parameters": {"XOC": {"value": 5, "unit": "um"},
                                                "ECC:h2c": {"value": 3, "unit": "arcsec"}}}))
    data = tmp_path / "data.csv"
    assert run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--noise-um", 0.5,
               "--seed", 11, "-o", data)[0] == 0
    fit = tmp_path / "fit.json"
    assert run("fit", "--machine", SEED_MACHINE, data, "-o", fit)[0] == 0
    return tmp_path, data, fit


def test_discovery_loop_on_the_command_line(hidden_session):
    folder, data, fit = hidden_session
    code, out, err = run("diagnose", "--from", fit)
    assert code == 0, err
    assert "1. ECC:h2" in out and "SIGNIFICANT" in out and f"--from {fit} --add ECC:h2" in out
    code, out, err = run("diagnose", "--from", fit, "--json")
    d = json.loads(out)
    assert d["candidates"][0]["effect"] == "ECC:h2" and d["candidates"][0]["significant"]
    fit2 = folder / "fit2.json"
    code, out, err = run("fit", "--from", fit, "--add", "ECC:h2", "-o", fit2)
    assert code == 0, err
    after = json.loads(fit2.read_text())
    assert after["effects"][-1] == "ECC:h2" and "ECC:h2c" in after["model"]
    assert after["residual"]["rms_um"] < 0.55 < json.loads(fit.read_text())["residual"]["rms_um"]
    code, out, err = run("diagnose", "--from", fit2, "--before", fit, "--plots", folder / "plots")
    assert code == 0, err
    assert "noise level" in out
    pngs = sorted(p.name for p in (folder / "plots").iterdir())
    assert pngs == ["measured-vs-model-K1.png", "measured-vs-model-K2.png", "measured-vs-model-K4.png",
                    "residual-vs-A.png", "residual-vs-C.png", "residual-vs-X.png", "residual-vs-Y.png",
                    "residual-vs-Z.png"]
    assert all((folder / "plots" / p).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)
    fit3 = folder / "fit3.json"
    assert run("fit", "--from", fit2, "--remove", "ECC:h2", "-o", fit3)[0] == 0
    assert json.loads(fit3.read_text())["model"] == json.loads(fit.read_text())["model"]


@pytest.mark.parametrize("args, expected", [
    (["--add", "ECC:h9x"], "takes hN"),
    (["--add", "XOC"], "already in the model"),
    (["--remove", "ECC:h2"], "not in the model"),
    (["--add", "nest_X"], "cannot separate"),
])
def test_bad_discovery_requests_are_refused_cleanly(hidden_session, args, expected):
    folder, _, fit = hidden_session
    out = folder / "new.json"
    code, _, err = run("fit", "--from", fit, *args, "-o", out)
    assert code == 2 and expected in err and err.count("\n") == 1, err
    assert not out.exists()


def test_diagnose_refuses_changed_or_foreign_files(hidden_session, tmp_path):
    folder, data, fit = hidden_session
    code, _, err = run("diagnose", "--from", data)
    assert code == 2 and "not a JSON fit file" in err
    data.write_text(data.read_text() + "# edited\n")
    code, _, err = run("diagnose", "--from", fit)
    assert code == 2 and "changed since the fit" in err, err


def test_predict_writes_what_a_session_at_another_ball_would_read(hidden_session):
    """The fitted model at a ball never measured, against the truth simulated there (the
    hidden ECC:h2 is not in the fit: its 3″ at 215 mm stays as the difference, ≤ 3.2 µm)."""
    folder, _, fit = hidden_session
    program = folder / "RT2.h"
    code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--path", "K4", "--ball",
                       "-150,120,180", "-o", program)
    assert code == 0, err
    poses = folder / "RT2.poses.csv"
    assert "K4,-150.000000,120.000000" in poses.read_text()
    pred = folder / "pred.csv"
    code, out, err = run("predict", "--from", fit, "--poses", poses, "-o", pred)
    assert code == 0 and "241 poses predicted by fit:" in out, err
    truth = folder / "truth2.csv"
    assert run("simulate", "--machine", SEED_MACHINE, "--truth", folder / "truth.json", "--paths", "K4",
               "--ball", "-150,120,180", "-o", truth)[0] == 0

    def readings(path):
        rows = [r.split(",") for r in path.read_text().splitlines() if r and not r.startswith("#")]
        head = rows[0]
        cols = [head.index(c) for c in ("dX", "dY", "dZ")]
        return np.array([[float(r[c]) for c in cols] for r in rows[1:]])

    diff = readings(pred) - readings(truth)
    assert np.abs(diff - diff.mean(axis=0)).max() < 3.2
    code, _, err = run("predict", "--from", fit, "--poses", poses, "-o", pred)
    assert code == 2 and "--force" in err and err.count("\n") == 1


def test_measure_program_ball_is_checked(tmp_path):
    out = tmp_path / "p.h"
    for ball, expected in (("1,2", "three numbers"), ("nan,0,0", "--ball X 'nan' is not a number"),
                           ("1_0,0,211", "--ball X '1_0' is not a number"),
                           ("\u0661,0,211", "is not a number (a finite one, in ASCII digits)"),
                           ("", "three numbers"), ("-217.5,0,2000", "outside its travel")):
        code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--path", "K4", "--ball", ball,
                           "-o", out)
        assert code == 2 and expected in err and err.count("\n") == 1, err
        assert not out.exists()


def test_measure_program_there_and_back_turns_every_axis_back(tmp_path):
    out = tmp_path / "p.h"
    code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--path", "K2", "--there-and-back",
                       "-o", out)
    assert code == 0, err
    text = next(tmp_path.glob("*.poses.csv")).read_text()
    rows = [r.split(",") for r in text.splitlines() if not r.startswith("#")]
    c = np.array([float(r[rows[0].index("C")]) for r in rows[1:]])
    assert len(c) == 242 and c[0] == c[-1] == 0.0 and c.max() == 360.0
    assert (np.diff(c[:121]) > 0).all() and (np.diff(c[121:]) < 0).all()


def test_dash_output_goes_to_stdout_and_multi_file_outputs_refuse_it(hidden_session, tmp_path):
    folder, data, fit = hidden_session
    code, out, err = run("fit", "--from", fit, "-o", "-")
    assert code == 0 and json.loads(out)["format"] == "compgen.fit/1" and "wrote -" in err
    assert not (tmp_path / "-").exists() and not (folder / "-").exists()
    code, out, err = run("kinematics", "--from", fit, "-o", "-", "--despite-gate")
    assert code == 2 and "-o - writes one file" in err, err


def test_fit_data_adds_to_the_fits_own_and_positional_data_are_refused_with_the_way(hidden_session, tmp_path):
    folder, data, fit = hidden_session
    more = tmp_path / "more.csv"
    assert run("simulate", "--machine", SEED_MACHINE, "--truth", ROOT / "examples" / "truth-table4.json",
               "--paths", "K2", "--ball", "-108.752,-0.1395,211.537", "--noise-um", "0.5", "--seed", "3",
               "-o", more)[0] == 0
    code, _, err = run("fit", "--from", fit, "--data", more, "-o", tmp_path / "f2.json")
    assert code == 0, err
    doc = json.loads((tmp_path / "f2.json").read_text())
    assert len(doc["data"]) == len(json.loads(Path(fit).read_text())["data"]) + 1
    code, _, err = run("fit", "--from", fit, more, "-o", tmp_path / "f3.json")
    assert code == 2 and "--data" in err and not (tmp_path / "f3.json").exists()
    code, _, err = run("fit", "--from", fit, "--data", data, "-o", tmp_path / "f4.json")
    assert code == 2 and "same readings" in err, err


def test_a_ball_mounted_again_elsewhere_has_an_offset_of_its_own(hidden_session, tmp_path):
    """A ball moved is a ball mounted again, off its nominal centre by what mounting left:
    a follow-up at another position, its ball re-mounted 15, −10, 5 µm off, fits with the
    first session exactly as one whose ball sat as the first's (where one offset for both
    left 3.6 µm of misfit and named an error motion found, benchmarks/moved_ball.py); fit
    says the ball offset it reports is the first mounting's, and says nothing of the kind
    where the ball stood at one position."""
    folder, data, fit = hidden_session
    code, _, err = run("fit", "--from", fit, "-o", tmp_path / "same.json")
    assert code == 0 and "mountings" not in err, err
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    got = {}
    for name, offset in {"kept": (0, 0, 0), "mounted again": (15, -10, 5)}.items():
        moved = tmp_path / f"{name}.json"
        ball = {n: {"value": v, "unit": "um"} for n, v in zip(("XOW", "YOW", "ZOW"), offset, strict=True)}
        moved.write_text(json.dumps({"parameters": {**truth, **ball}}))
        more = tmp_path / f"{name}.csv"
        assert run("simulate", "--machine", SEED_MACHINE, "--truth", moved, "--paths", "K2", "--ball",
                   "-108.752,-0.1395,211.537", "--noise-um", "0.5", "--seed", "3", "-o", more)[0] == 0
        code, _, err = run("fit", "--from", fit, "--data", more, "-o", tmp_path / f"{name}-fit.json")
        assert code == 0 and err.count("the ball at 2 mountings") == 1, err
        assert "XOW YOW ZOW are the first's (ball at -217.504, -0.279, 211.537 mm)" in err
        got[name] = json.loads((tmp_path / f"{name}-fit.json").read_text())
    kept, again = got["kept"], got["mounted again"]
    assert again["parameters"]["XOW"]["description"].endswith(", at the first of the ball's 2 mountings")
    assert again["residual"]["rms_um"] == pytest.approx(kept["residual"]["rms_um"], abs=1e-3)
    for n, p in kept["parameters"].items():        # the same to a thousandth of a µm or ″
        assert again["parameters"][n]["value"] == pytest.approx(p["value"], abs=5e-9), n
    code, out, err = run("diagnose", "--from", tmp_path / "mounted again-fit.json")
    assert code == 0 and err.count("the ball at 2 mountings") == 1, err
    assert "1. ECC:h2" in out


@pytest.mark.parametrize("command", ["effects", "checklist"])
def test_listing_commands_speak_json(command):
    code, out, _ = run(command, "--machine", SEED_MACHINE, "--json")
    assert code == 0 and json.loads(out)["format"] == f"compgen.{command}/1"


def test_measure_program_dash_output_is_stdout_as_without_o(tmp_path):
    code, out, err = run("measure-program", "--machine", SEED_MACHINE, "--path", "K2", "-o", "-")
    assert code == 0 and "BEGIN PGM RTEST_K2 MM" in out and "pose list RTEST_K2.poses.csv" in out, out[:300]
    assert "the pose list was not written" in err


def test_a_follow_up_simulated_on_the_sessions_clock_fits_a_drift_without_a_warning(tmp_path):
    """``simulate --start-s`` puts a follow-up's readings on the session's clock (as an
    R-test running on does): fitted with a drift, nothing is said; the same follow-up with
    its clock restarted at 0 is said. A start that is no time is refused in one line."""
    truth = ROOT / "examples" / "truth-table4.json"
    first, again, late = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "c.csv"
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--noise-um", "0.5",
                       "--seed", "1", "-o", first)
    assert code == 0, err
    end = max(float(line.split(",")[1]) for line in first.read_text().splitlines()
              if line.startswith("K"))
    for out, start in ((again, 0.0), (late, end + 20)):
        code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--paths", "K2",
                           "--noise-um", "0.5", "--seed", "2", "--start-s", start, "-o", out)
        assert code == 0, err
    rows = [line.split(",") for line in late.read_text().splitlines() if line.startswith("K2")]
    assert float(rows[0][1]) == pytest.approx(end + 20, abs=1e-3)
    assert run("fit", "--machine", SEED_MACHINE, first, "-o", tmp_path / "f.json")[0] == 0
    for data, said in ((again, True), (late, False)):
        code, _, err = run("fit", "--from", tmp_path / "f.json", "--data", data, "--add", "YOC:e15",
                           "-o", tmp_path / "g.json", "--force")
        assert code == 0, err
        assert ("drift with the session's clock" in err) == said, err
    for bad in ("-5", "nan", "inf"):
        code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--start-s", bad,
                           "-o", tmp_path / "x.csv")
        assert code == 2 and err.count("\n") == 1 and "--start-s" in err and not (tmp_path / "x.csv").exists()


def test_a_fit_whose_machine_file_or_data_moved_on_is_refused(hidden_session):
    """What a fit was made with must be what a later command reads: a machine file edited
    since, a data file gone, a bundled machine that differs from the fit's: one line each,
    with what to do."""
    folder, data, _ = hidden_session
    machine = folder / "m.toml"
    machine.write_text(SEED_MACHINE.read_text())
    fit = folder / "own.json"
    assert run("fit", "--machine", machine, data, "-o", fit)[0] == 0
    machine.write_text(SEED_MACHINE.read_text().replace("feed = 500.0", "feed = 400.0"))
    code, _, err = run("diagnose", "--from", fit)
    assert code == 2 and "machine file changed since the fit" in err and err.count("\n") == 1, err
    machine.write_text(SEED_MACHINE.read_text())
    assert run("diagnose", "--from", fit, "--json")[0] == 0
    data.rename(folder / "elsewhere.csv")
    code, _, err = run("diagnose", "--from", fit)
    assert code == 2 and "data file of the fit is gone" in err and "refit" in err, err
    (folder / "elsewhere.csv").rename(data)
    bundled = folder / "bundled.json"
    assert run("fit", "--machine", "ac-trunnion-itnc530", data, "-o", bundled)[0] == 0
    doc = json.loads(bundled.read_text())
    assert doc["machine"]["bundled"]
    doc["machine"]["sha256"] = "0" * 64          # as if made with another compgen's bundled file
    bundled.write_text(json.dumps(doc))
    code, _, err = run("diagnose", "--from", bundled)
    assert code == 2 and "the bundled machine 'ac-trunnion-itnc530' of this compgen differs" in err, err
    assert "--machine FILE" in err


def test_a_device_reporting_ball_minus_nest_fits_the_same_once_told(hidden_session):
    """The contract's sign switch: the same readings negated, read with --sign
    ball-minus-nest, give the same fit; the fit keeps the sign, so a later command reading the
    file again reads it the same way (never guessed)."""
    folder, data, fit = hidden_session
    lines = data.read_text().splitlines()
    head = next(i for i, x in enumerate(lines) if not x.startswith("#"))
    cols = [lines[head].split(",").index(c) for c in ("dX", "dY", "dZ")]
    for i in range(head + 1, len(lines)):
        cells = lines[i].split(",")
        for j in cols:
            cells[j] = f"{-float(cells[j]):.6f}"
        lines[i] = ",".join(cells)
    flipped = folder / "flipped.csv"
    flipped.write_text("\n".join(lines) + "\n")
    out = folder / "flipped.json"
    assert run("fit", "--machine", SEED_MACHINE, flipped, "--sign", "ball-minus-nest", "-o", out)[0] == 0
    a, b = json.loads(fit.read_text()), json.loads(out.read_text())
    for name, p in a["parameters"].items():
        assert b["parameters"][name]["value"] == pytest.approx(p["value"], abs=1e-9), name
    code, got, err = run("diagnose", "--from", out, "--json")
    assert code == 0 and json.loads(got)["candidates"][0]["effect"] == "ECC:h2", err
    unsigned = folder / "unsigned.json"        # the same file read as the contract's default
    assert run("fit", "--machine", SEED_MACHINE, flipped, "-o", unsigned)[0] == 0
    c = json.loads(unsigned.read_text())
    assert c["parameters"]["XOC"]["value"] == pytest.approx(-a["parameters"]["XOC"]["value"], rel=0.05)


def test_the_effects_catalogue_as_text_marks_the_default_model():
    code, out, err = run("effects", "--machine", SEED_MACHINE)
    assert code == 0, err
    lines = out.splitlines()
    xoc = next(ln for ln in lines if ln[2:].startswith("XOC "))
    ecc = next(ln for ln in lines if ln[2:].startswith("ECC:h2 "))
    assert xoc.startswith("* ") and ecc.startswith("  ") and "ECC:h2c, ECC:h2s" in ecc, (xoc, ecc)
    assert sum(ln.startswith("* ") for ln in lines[:-1]) == 11 and lines[-1] == "* in the default model"


@pytest.mark.parametrize("argv, says", [
    (["simulate", "--machine", SEED_MACHINE, "--truth", "truth.json", "--paths", " , ", "-o", "s.csv"],
     "--paths names no path"),
    (["simulate", "--machine", SEED_MACHINE, "--truth", "truth.json", "--device", "probe", "--there-and-back",
      "-o", "s.log"],
     "--there-and-back, --noise-rho, --rate-hz, --feed and --probe-length are for R-test sessions"),
    (["measure-program", "--machine", SEED_MACHINE, "--poses", "p.csv", "--ball", "0,0,200", "-o", "P.H"],
     "--ball, --there-and-back and --probe-length go with --path"),
    (["history", "add", "fit.json", "--temperature", "hall", "--db", "h.sqlite"],
     "--temperature takes NAME=°C, not 'hall'"),
    (["history", "add", "fit.json", "--temperature", "=21", "--db", "h.sqlite"],
     "--temperature takes NAME=°C, not '=21'"),
])
def test_options_that_do_not_go_together_are_refused_before_anything_is_written(hidden_session, monkeypatch,
                                                                                 argv, says):
    folder, data, fit = hidden_session
    monkeypatch.chdir(folder)
    (folder / "p.csv").write_text("A,C\n0,0\n")
    before = sorted(p.name for p in folder.iterdir())
    code, _, err = run(*argv)
    assert code == 2 and says in err and err.count("\n") == 1, err
    assert sorted(p.name for p in folder.iterdir()) == before


def test_the_report_lists_the_files_sent_to_the_control_with_their_checksums(hidden_session):
    import hashlib
    folder, _, fit = hidden_session
    kin = folder / "KIN.txt"
    code, _, err = run("kinematics", "--from", fit, "-o", kin, "--despite-gate")
    assert code == 0, err
    code, _, err = run("report", "--from", fit, "--emitted", kin, "-o", folder / "r.html")
    assert code == 0, err
    html = (folder / "r.html").read_text()
    assert "KIN.txt" in html and hashlib.sha256(kin.read_bytes()).hexdigest() in html


def test_a_fit_with_nothing_to_fit_or_too_few_readings_is_refused(hidden_session):
    """Every parameter held, or fewer readings than parameters: one line, no fit file."""
    folder, data, fit = hidden_session
    out = folder / "n.json"
    code, _, err = run("fit", "--from", fit, "--model", "XOC", "--fix", "XOC=0", "-o", out)
    assert code == 2 and "every parameter is fixed: nothing to fit" in err and not out.exists(), err
    lines = data.read_text().splitlines()
    head = next(i for i, x in enumerate(lines) if not x.startswith("#"))
    few = folder / "few.csv"
    few.write_text("\n".join(lines[:head + 4]) + "\n")           # three poses, nine readings
    code, _, err = run("fit", "--machine", SEED_MACHINE, few, "-o", out)
    assert code == 2 and "3 poses give 9 readings for 11 parameters" in err, err
    assert "Measure more poses" in err
    assert not out.exists()


def test_a_machine_with_nothing_to_correct_gets_no_edit(tmp_path):
    """Every location error within its noise (a machine already corrected, measured again):
    kinematics says so in one line and writes nothing, unless --anyway; compare and the report
    say it too. A machine with one error beyond its noise gets its edit."""
    machine = load_machine(SEED_MACHINE)
    clean = simulate(machine, {}, generate(machine, ["K4", "K1", "K2"]), 0.5, np.random.default_rng(61))
    (tmp_path / "clean.csv").write_text(format_rtest(machine, clean))
    assert run("fit", "--machine", SEED_MACHINE, tmp_path / "clean.csv", "-o", tmp_path / "f.json")[0] == 0
    code, out, err = run("kinematics", "--from", tmp_path / "f.json", "-o", tmp_path / "KIN.txt")
    assert code == 0 and out.startswith("nothing to correct: every correction an edit would write is within "
                                        "3 σ"), out
    assert "no edit written (--anyway writes it)" in out and len(out.strip().splitlines()) == 1, out
    assert not list(tmp_path.glob("KIN*"))
    code, out, err = run("compare", "--from", tmp_path / "f.json")
    assert code == 0 and "nothing to correct" in out.splitlines()[1], out
    code, out, err = run("compare", "--from", tmp_path / "f.json", "--json")
    assert json.loads(out)["nothing_to_correct"].startswith("nothing to correct"), out
    code, _, err = run("report", "--from", tmp_path / "f.json", "-o", tmp_path / "r.html")
    assert code == 0 and "Nothing to correct" in (tmp_path / "r.html").read_text(), err
    code, out, err = run("kinematics", "--from", tmp_path / "f.json", "-o", tmp_path / "KIN.txt", "--anyway")
    assert code == 0 and (tmp_path / "KIN.txt").exists(), err
    # one location error beyond its noise: the edit is written
    moved = simulate(machine, {"XOC": 3e-3}, generate(machine, ["K4", "K1", "K2"]), 0.5,
                     np.random.default_rng(62))
    (tmp_path / "moved.csv").write_text(format_rtest(machine, moved))
    assert run("fit", "--machine", SEED_MACHINE, tmp_path / "moved.csv", "-o", tmp_path / "g.json")[0] == 0
    code, out, err = run("kinematics", "--from", tmp_path / "g.json", "-o", tmp_path / "K2.txt")
    assert code == 0 and "nothing to correct" not in out and (tmp_path / "K2.txt").exists(), out + err


def test_every_commands_help_line_is_whole():
    """`compgen-cli --help` lists each command with its docstring's first sentence: one that
    held "e.g." was cut inside its parentheses ("Check a short measurement (e.g.")."""
    import click

    from compgen.commands.cli import main

    def commands(group, prefix=""):
        for name, cmd in group.commands.items():
            yield prefix + name, cmd
            if isinstance(cmd, click.Group):
                yield from commands(cmd, prefix + name + " ")

    for name, cmd in commands(main):
        line = cmd.get_short_help_str(limit=300)
        assert line.count("(") == line.count(")") and not line.endswith(("e.g.", "i.e.")), (name, line)


def test_a_hint_names_compgen_the_way_it_was_called(tmp_path, monkeypatch):
    """.venv/bin/compgen-cli called by its path with the venv not active: every hint said
    "compgen-cli …", which bash then does not find. A hint names the path where the alias on
    PATH is not this program, the alias where it is, and python -m compgen with its Python."""
    import subprocess
    import sys

    venv_bin = Path(sys.executable).parent
    alias = venv_bin / "compgen-cli"
    if not alias.exists():
        pytest.skip("compgen-cli is not installed beside this Python")
    path_without = ":".join(p for p in os.environ["PATH"].split(":")
                            if Path(p).resolve() != venv_bin.resolve())
    for path, hint in ((path_without, str(alias)), (f"{venv_bin}:{path_without}", "compgen-cli")):
        done = subprocess.run([str(alias), "probe-program", "--machine", "ac-trunnion-itnc530", "--path",
                               "K2", "-o", tmp_path / "P.H", "--force"], capture_output=True, text=True,
                              env={**os.environ, "PATH": path})
        said = done.stdout + done.stderr
        assert done.returncode == 0 and f"check it: {hint} check-program" in said, said


def test_a_fit_file_moved_alone_still_finds_its_machine_file_and_data(tmp_path):
    """fit.json keeps its files relative to itself (the job folder can move) and absolute (the
    fit file can move alone): moved to another folder, it found neither ("cannot read"); a
    file changed at that path is still refused by its checksum."""
    job, elsewhere = tmp_path / "job", tmp_path / "elsewhere"
    job.mkdir(), elsewhere.mkdir()
    (job / "m.toml").write_text(SEED_MACHINE.read_text())
    (job / "s.csv").write_text((ROOT / "examples" / "seed-session.csv").read_text())
    assert run("fit", "--machine", job / "m.toml", job / "s.csv", "-o", job / "fit.json")[0] == 0
    (job / "fit.json").rename(elsewhere / "fit.json")
    code, out, err = run("compare", "--from", elsewhere / "fit.json")
    assert code == 0, err
    (job / "m.toml").write_text(SEED_MACHINE.read_text() + "\n# changed\n")
    code, _, err = run("compare", "--from", elsewhere / "fit.json")
    assert code == 2 and "machine file changed since the fit" in err, err


def test_fit_model_takes_effects_as_add_does(tmp_path):
    """--model took parameter names (EXC:h2c,EXC:h2s) where --add takes effects (EXC:h2): an
    effect's name in --model now stands for its parameters, and gives the same fit."""
    session = ROOT / "examples" / "seed-session.csv"
    base = "XOW,YOW,ZOW,YOA,ZOA,BOA,COA,XOC,YOC,AOC,BOC"
    for model, out in ((f"{base},EXC:h2", "a.json"), (f"{base},EXC:h2c,EXC:h2s", "b.json")):
        code, _, err = run("fit", "--machine", SEED_MACHINE, session, "--model", model, "-o", tmp_path / out)
        assert code == 0, err
    a, b = (json.loads((tmp_path / n).read_text()) for n in ("a.json", "b.json"))
    assert a["model"] == b["model"] and a["parameters"] == b["parameters"]
    code, _, err = run("fit", "--machine", SEED_MACHINE, session, "--model", f"{base},EXC:h9x", "-o",
                       tmp_path / "c.json")
    assert code == 2 and "EXC" in err and len(err.strip().splitlines()) == 1, err
