"""Nothing wrong reaches the controller: every input is checked at the edge, every string
that enters an emitted file is checked or cleaned, every edit is guarded. Each case here
failed before its fix (issue 9)."""

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import BC_MACHINE, ROOT, SEED_MACHINE, run

from compgen.configuration.session import reload
from compgen.controllers.correction import plan
from compgen.controllers.registry import CONTROLLERS
from compgen.errors import CompgenError
from compgen.statistics.results import load_fit

# (replace this, with that) in the seed machine file → the one line that must come back
BAD_MACHINE_EDITS = {
    "typo sense": ("sense = -1 ", "sence = -1 ", "unknown key sence"),
    "typo offset": ("offset = [0.0, 0.0, 29.794]", "ofset = [0.0, 0.0, 29.794]", "unknown key ofset"),
    "top-level typo": ('controller = "itnc530"', 'controller = "itnc530"\nlimit = 3', "unknown key limit"),
    "NaN ramp": ("C = { from = 0.0, to = 360.0 }", "C = { from = nan, to = 360.0 }", "finite number"),
    "inf amplitude": ("amplitude = -90.0", "amplitude = -inf", "finite number"),
    "injected axis": ('axis = "C"', 'axis = "C0 Z-500 C"', "not a valid axis name"),
    "axis with newline": ('axis = "C"', 'axis = "C\\nG0 Z-500"', "not a valid axis name"),
    "injected work offset": ("clearance = 20.0", 'clearance = 20.0\nwork_offset = "G0 Z-500"',
                             "not a valid work offset name"),
    "injected tool": ('tool = "99"', 'tool = "99\\nG0 Z-500"', "not a valid tool name"),
    "path label with a comma": ("[paths.K2]", '[paths."K2,x"]', "not a valid path name"),
    "tolerance of no path": ("K2 = 8.0", "K2 = 8.0\nK7 = 3.0", "unknown key K7"),
    "program typo": ("dwell = 1.0 ", "dwel = 1.0 ", "unknown key dwel"),
    "vector of no axis": ("C = [0.0, 0.0, -1.0] }", "C = [0.0, 0.0, -1.0], B = [0.0, 1.0, 0.0] }",
                          "unknown key B"),
    "an axis named twice": ('axis = "A"', 'axis = "C"', "an axis name appears twice"),
    "two linear axes along x": ('direction = "y"', 'direction = "x"',
                                "one linear axis along each of x, y, z"),
    "a direction no axis has": ('direction = "y"', 'direction = "w"',
                                "direction must be one of x, y, z or a vector [x, y, z], not 'w'"),
    "an inclined linear axis": ('direction = "y"', "direction = [0.0, 1.0, 1.0]",
                                "only a rotary axis A, B or C may be inclined"),
    "an inclined axis across its letter": ('direction = "x"        #', "direction = [0.0, 1.0, 0.0] #",
                                           "[0.0, 1.0, 0.0] of A is not within 90° of its letter's +x"),
    "an inclined axis of no length": ('direction = "x"        #', "direction = [0.0, 0.0, 0.0] #",
                                      "is not within 90° of its letter's +x"),
    "an inclined axis of NaN": ('direction = "x"        #', "direction = [nan, 0.0, 1.0] #",
                                "finite number"),
    "an axis type misspelt": ('type = "linear"', 'type = "linar"', "type must be 'linear' or 'rotary'"),
    "an empty axis type": ('type = "linear"', 'type = ""', "must be a non-empty string"),
    "sense 2": ("sense = -1 ", "sense = 2 ", "sense must be +1 or -1"),
    "feed_max 0": ("feed_max = 20000.0", "feed_max = 0.0", "feed_max must be positive"),
    "a path of one pose": ("n = 361", "n = 1", "a path needs n ≥ 2 poses"),
    "an angle no path shape has": ("C = 0.0", "C = { spin = 1.0 }", "cannot read {'spin': 1.0}"),
    "a declared effect that is no list": ("[program]", '[effects]\ndeclared = "EXC:h2"\n\n[program]',
                                          "must be a list of names"),
    "effects not a table": ('controller = "itnc530"', 'controller = "itnc530"\neffects = 3',
                            "must be a table"),
    "probe without its sphere": ("sphere_diameter = 25.4 ", "", "[probe] needs sphere_diameter (mm)"),
    "half a touch": ("touches = 5 ", "touches = 5.5 ", "must be a whole number"),
    "four touches": ("touches = 5 ", "touches = 4 ", "a pose needs 5 touches or more"),
    "three probed poses": ("poses = 12 ", "poses = 3 ", "a path needs 4 to 120 poses"),
    "touches from too high": ("touches = 5 ", "elevation = 70.0\ntouches = 5 ",
                              "elevation must be 10° to 60° above the horizontal"),
}


# the same in the bundled SINUMERIK machine's [sinumerik]: the key named as file: section: key
BAD_SINUMERIK_EDITS = {
    "a vector not a unit one": ("B = [0.0, -1.0, 0.0]", "B = [0.0, -0.5, 0.0]",
                                "m.toml: sinumerik: vectors: B: must be the unit vector ±y the control "
                                "holds for B, got [0.0, -0.5, 0.0]"),
    "a vector along another axis": ("B = [0.0, -1.0, 0.0]", "B = [1.0, 0.0, 0.0]",
                                    "m.toml: sinumerik: vectors: B: must be the unit vector ±y the control "
                                    "holds for B"),
    "a machine-axis name in lower case": ('X = "X1"', 'X = "x1"', "m.toml: sinumerik: machine_axes: X: "
                                          "machine-axis name 'x1' is not a SINUMERIK"),
    "a modulo axis that does not turn round": ('modulo = ["C"]', 'modulo = ["B"]',
                                               "m.toml: sinumerik: modulo: B is not a rotary axis that turns "
                                               "a whole revolution"),
    "a modulo axis the machine lacks": ('modulo = ["C"]', 'modulo = ["A"]', "m.toml: sinumerik: modulo: "
                                        "A is not a rotary axis that turns a whole revolution"),
    "fine correction as a number": ("fine_correction = true", "fine_correction = 1",
                                    "m.toml: sinumerik: fine_correction: must be true or false (SD42974 "
                                    "$SC_TOCARR_FINE_CORRECTION = 1 or 0)"),
}


@pytest.mark.parametrize("source, case", [*((SEED_MACHINE, c) for c in BAD_MACHINE_EDITS),
                                          *((BC_MACHINE, c) for c in BAD_SINUMERIK_EDITS)])
def test_machine_file_mistakes_are_refused_with_their_key(tmp_path, source, case):
    before, after, expected = (BAD_MACHINE_EDITS if source == SEED_MACHINE else BAD_SINUMERIK_EDITS)[case]
    text = source.read_text()
    assert before in text
    machine = tmp_path / "m.toml"
    machine.write_text(text.replace(before, after, 1))
    out = tmp_path / "P.H"
    code, _, err = run("measure-program", "--machine", machine, "--path", "K2", "-o", out)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert expected in err, err
    assert not out.exists()


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_free_text_cannot_add_a_block(tmp_path, controller):
    """A machine name with line breaks and comment terminators stays inside one comment."""
    text = SEED_MACHINE.read_text().replace(
        'name = "A/C trunnion, iTNC 530 (seed report)"', 'name = "evil\\nG0 Z-500\\r\\n) G0 Z-500 ("')
    machine = tmp_path / "m.toml"
    machine.write_text(text)
    ext = CONTROLLERS[controller].program_ext
    out = tmp_path / f"P{ext}"
    code, _, err = run("measure-program", "--machine", machine, "--path", "K2", "--controller",
                       controller, "-o", out)
    assert code == 0, err
    lines = out.read_text().splitlines()
    evil = [ln for ln in lines if "Z-500" in ln]
    assert len(evil) == 1, evil
    assert evil[0].startswith(";") or evil[0].split(" ", 1)[1].startswith(";"), evil[0]
    injected = evil[0][evil[0].index("evil"):evil[0].index("; controller")]
    assert "(" not in injected and ")" not in injected, injected


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A fit of the example session (Table 4 and a hidden 2/rev radial motion of C), and
    the same with that effect added: the fit a user would take to the control."""
    folder = tmp_path_factory.mktemp("job")
    code, _, err = run("fit", "--machine", SEED_MACHINE, ROOT / "examples" / "seed-session.csv",
                       "-o", folder / "fit.json")
    assert code == 0, err
    code, _, err = run("fit", "--from", folder / "fit.json", "--add", "EXC:h2", "-o", folder / "fit2.json")
    assert code == 0, err
    return folder


def _edited_fit(folder, tmp_path, change):
    doc = json.loads((folder / "fit2.json").read_text())
    change(doc)
    path = folder / f"variant-{tmp_path.name}.json"    # beside the fit: its relative paths hold
    path.write_text(json.dumps(doc))
    return path


BAD_FITS = {
    "NaN value": (lambda d: d["parameters"]["XOC"].update(value=float("nan")), "not a number"),
    "Infinity std": (lambda d: d["parameters"]["BOA"].update(std=float("inf")), "not a number"),
    "unknown unit": (lambda d: d["parameters"]["XOC"].update(unit="furlong"), "unknown unit"),
    "angle unit for a length": (lambda d: d["parameters"]["XOC"].update(unit="arcsec"), "unit of angle"),
    "value as text": (lambda d: d["parameters"]["XOC"].update(value="0.001"), "must be"),
    "unknown parameter": (lambda d: d["parameters"].update(XOQ={"value": 0, "std": 0, "unit": "mm"}),
                          "XOQ"),
}


@pytest.mark.parametrize("case", BAD_FITS)
def test_a_damaged_fit_never_reaches_the_control(fitted, tmp_path, case):
    change, expected = BAD_FITS[case]
    fit = _edited_fit(fitted, tmp_path, change)
    out = tmp_path / "K.TAB"
    code, _, err = run("kinematics", "--from", fit, "--controller", "itnc530", "-o", out)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert expected in err, err
    assert not list(tmp_path.iterdir())


def test_the_unit_of_a_fit_is_honoured(fitted, tmp_path):
    """XOC written in µm instead of mm gives the same edit, not one 1000 times larger."""
    def in_um(d):
        p = d["parameters"]["XOC"]
        p.update(value=p["value"] * 1e3, std=p["std"] * 1e3, unit="um")
    outs = []
    for fit in (fitted / "fit2.json", _edited_fit(fitted, tmp_path, in_um)):
        out = tmp_path / f"K{len(outs)}.txt"
        code, stdout, err = run("kinematics", "--from", fit, "--controller", "itnc530", "-o", out)
        assert code == 0, err
        outs.append(stdout)
    assert outs[0] == outs[1].replace("K1", "K0")


def test_a_job_folder_can_move(fitted, tmp_path):
    """fit.json names its data relative to itself, and a bundled machine by its name and
    checksum (a rebuilt venv moves the installed file, never the name)."""
    doc = json.loads((fitted / "fit.json").read_text())
    assert doc["machine"]["file"] == "ac-trunnion-itnc530" and doc["machine"]["bundled"] is True
    assert not Path(doc["data"][0]["file"]).is_absolute()
    moved = tmp_path / "a" / "b"
    moved.mkdir(parents=True)
    fit = moved / "fit.json"
    # the data at the same relative place from the moved fit
    for ref in (doc["data"][0]["file"],):
        target = (moved / ref).resolve()
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy((fitted / ref).resolve(), target)
    fit.write_text((fitted / "fit.json").read_text())
    code, _, err = run("diagnose", "--from", fit, "--json")
    assert code == 0, err


def test_a_fit_with_a_machine_file_of_its_own_names_it_relative_to_itself(tmp_path):
    job = tmp_path / "job"
    job.mkdir()
    machine = job / "m.toml"
    machine.write_text(SEED_MACHINE.read_text())
    data = job / "s.csv"
    assert run("simulate", "--machine", machine, "--truth", ROOT / "examples" / "truth-table4.json",
               "--noise-um", "0.5", "--seed", "1", "-o", data)[0] == 0
    assert run("fit", "--machine", machine, data, "-o", job / "fit.json")[0] == 0
    doc = json.loads((job / "fit.json").read_text())
    assert doc["machine"]["file"] == "m.toml" and "bundled" not in doc["machine"]
    moved = tmp_path / "elsewhere"
    shutil.copytree(job, moved)
    code, _, err = run("diagnose", "--from", moved / "fit.json", "--json")
    assert code == 0, err


def test_json_that_would_crash_the_parser_is_refused(tmp_path, fitted):
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100000 + "]" * 100000)
    for args in (("diagnose", "--from", deep),
                 ("simulate", "--machine", SEED_MACHINE, "--truth", deep, "-o", tmp_path / "x.csv")):
        code, _, err = run(*args)
        assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    stray = fitted / "stray.json"      # a checklist of the folder skips a file that is not compgen's
    stray.write_text("[" * 100000 + "]" * 100000)
    try:
        code, _, err = run("checklist", "--machine", SEED_MACHINE, "--dir", fitted)
        assert code == 0, err
    finally:
        stray.unlink()


def test_a_fifo_is_refused_not_waited_on(tmp_path):
    fifo = tmp_path / "data.csv"
    os.mkfifo(fifo)
    code, _, err = run("fit", "--machine", SEED_MACHINE, fifo, "-o", tmp_path / "f.json")
    assert code == 2 and "not a regular file" in err, err


def test_outputs_never_replace_an_input_or_a_device(fitted, tmp_path):
    current = tmp_path / "KINEMATIC.TAB"
    current.write_text((ROOT / "examples" / "itnc530-current.TAB").read_text())
    before = current.read_bytes()
    code, _, err = run("kinematics", "--from", fitted / "fit2.json", "--current", current, "-o", current,
                       "--force")
    assert code == 2 and "overwrite an input" in err, err
    assert current.read_bytes() == before
    truth = ROOT / "examples" / "truth-table4.json"
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", truth,
                       "-o", "/dev/null", "--force")
    assert code == 2 and "not a regular file" in err, err


def test_outputs_are_written_whole_with_normal_permissions(fitted, tmp_path):
    old = os.umask(0o022)
    try:
        code, _, err = run("kinematics", "--from", fitted / "fit2.json", "-o", tmp_path / "K.txt")
    finally:
        os.umask(old)
    assert code == 0, err
    for f in tmp_path.glob("K*"):
        assert f.stat().st_mode & 0o777 == 0o644, f
    code, _, err = run("kinematics", "--from", fitted / "fit2.json", "-o", "/proc/K.txt")
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        if not os.access(locked, os.W_OK):      # (root may write anywhere)
            code, _, err = run("kinematics", "--from", fitted / "fit2.json", "-o", locked / "K.txt")
            assert code == 2 and err.count("\n") == 1 and "not writable" in err, err
    finally:
        locked.chmod(0o755)


@pytest.mark.parametrize("stop, code, said", [
    (OSError(28, "No space left on device"), 2, "No space left"),
    (KeyboardInterrupt(), 130, "compgen: interrupted"),      # Ctrl-C between two renames
])
def test_an_edit_is_one_transaction(fitted, tmp_path, monkeypatch, stop, code, said):
    """When its last file cannot be written, or the user stops compgen on the way, none of
    the edit's files is left, and a file it was to replace (with --force) is as it was."""
    (tmp_path / "K.txt").write_text("the user's")
    real = os.replace
    calls = []

    def failing(src, dst):
        calls.append(dst)
        if len(calls) == 3:
            raise stop
        return real(src, dst)
    monkeypatch.setattr(os, "replace", failing)
    got, _, err = run("kinematics", "--from", fitted / "fit2.json", "-o", tmp_path / "K.txt", "--force")
    assert got == code and said in err and "\n" not in err.strip(), err   # (after ^C, click ends its line)
    assert [p.name for p in tmp_path.iterdir()] == ["K.txt"]
    assert (tmp_path / "K.txt").read_text() == "the user's"


def _big_table(d):
    d["model"].append("ECC:h2c")
    d["parameters"]["ECC:h2c"] = {"value": 0.05, "std": 0.001, "unit": "rad"}


def test_compensation_tables_are_held_to_the_limits(fitted, tmp_path):
    fit = load_fit(_edited_fit(fitted, tmp_path, _big_table))
    machine, _ = reload(fit)
    with pytest.raises(CompgenError, match=r"ECC:h2 table \d+\.\d arcsec > 60 arcsec"):
        plan(machine, fit)
    assert plan(machine, fit, force=True).tables == ("ECC:h2",)


NAN_STATES = {
    "itnc530": ("examples/itnc530-current.TAB", "+29.794", "nan"),
    "sinumerik840d": (None, "$TC_CARR1[1]=0.0", "$TC_CARR1[1]=nan"),
    "linuxcnc": (None, "setp xyzac-trt-kins.z-offset 0.0", "setp xyzac-trt-kins.z-offset inf"),
}


@pytest.mark.parametrize("controller", NAN_STATES)
def test_a_non_finite_current_state_is_refused(fitted, tmp_path, controller):
    source, good, bad = NAN_STATES[controller]
    text = (ROOT / source).read_text() if source else good + "\n"
    assert good in text
    current = tmp_path / "current.txt"
    current.write_text(text.replace(good, bad))
    code, _, err = run("kinematics", "--from", fitted / "fit2.json", "--controller", controller,
                       "--current", current, "-o", tmp_path / "K.out")
    assert code == 2 and "not a number" in err and "Traceback" not in err, err
    if controller != "linuxcnc":        # the line of the bad value (a HAL value names its pin)
        line = 1 + next(i for i, ln in enumerate(text.replace(good, bad).splitlines()) if bad in ln)
        assert f"current.txt:{line}" in err, err


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_the_same_fit_is_not_applied_twice(fitted, tmp_path, controller):
    """The edited state, given back as --current, carries the fit's marker: refused."""
    ctl = CONTROLLERS[controller]
    carr = tmp_path / "carr.txt"     # the seed machine's A/C record as the control holds it
    held = dict(zip(range(7, 13), (-1.0, 0.0, 0.0, 0.0, 0.0, -1.0), strict=True))
    carr.write_text("".join(f"$TC_CARR{k}[1]={held.get(k, 0.0)}\n"
                            for k in (*held, 44, 45, 46, *range(55, 61))))
    first = {"itnc530": ["--current", ROOT / "examples" / "itnc530-current.TAB"],
             "sinumerik840d": ["--current", carr]}.get(controller, [])
    out = tmp_path / f"K1{ctl.main_suffix('held' if first else None)}"
    code, _, err = run("kinematics", "--from", fitted / "fit2.json", "--controller", controller, *first,
                       "-o", out)
    assert code == 0, err
    again = tmp_path / "K2.out"
    code, _, err = run("kinematics", "--from", fitted / "fit2.json", "--controller", controller,
                       "--current", out, "-o", again)
    assert code == 2 and "already carries this fit's correction" in err, (ctl.name, err)
    assert not again.exists()


def _table(text):
    """An R-test CSV's lines, its header's index and the header's column names."""
    lines = text.splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("path,"))
    return lines, head, lines[head].split(",")


def _swap_dx_dy(text):
    lines, head, cols = _table(text)
    ix, iy = cols.index("dX"), cols.index("dY")
    out = lines[:head + 1]
    for ln in lines[head + 1:]:
        c = ln.split(",")
        c[ix], c[iy] = c[iy], c[ix]
        out.append(",".join(c))
    return "\n".join(out) + "\n"


def _in_mm(text):
    lines, head, cols = _table(text)
    idx = [cols.index(c) for c in ("dX", "dY", "dZ")]
    out = lines[:head + 1]
    for ln in lines[head + 1:]:
        c = ln.split(",")
        for i in idx:
            c[i] = f"{float(c[i]) / 1000:.7f}"
        out.append(",".join(c))
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("data, expected", [
    (None, "diagnose finds effects the model misses: EXC:h2"),
    (_swap_dx_dy, "above the 3 µm an R-test's noise allows"),
    (_in_mm, "likely in mm, not µm"),
])
def test_a_fit_that_does_not_explain_its_data_writes_no_edit(fitted, tmp_path, data, expected):
    fit = fitted / "fit.json"          # the example session's fit: EXC:h2 hidden, not modelled
    if data:
        csv = tmp_path / "session.csv"
        csv.write_text(data((ROOT / "examples" / "seed-session.csv").read_text()))
        fit = tmp_path / "fit.json"
        code, _, err = run("fit", "--machine", SEED_MACHINE, csv, "-o", fit)
        assert code == 0, err
        assert ("likely in mm" in err) == (data is _in_mm), err
        if data is _in_mm:         # the spread said is the file's: its largest column range, as µm
            lines, head, cols = _table(csv.read_text())
            rows = [ln.split(",") for ln in lines[head + 1:]]
            spread = max(np.ptp([float(r[cols.index(c)]) for r in rows]) for c in ("dX", "dY", "dZ"))
            assert f"the readings spread over {spread:.3g} µm at most" in err, (spread, err)
    out = tmp_path / "K.txt"
    code, _, err = run("kinematics", "--from", fit, "--controller", "itnc530", "-o", out)
    assert code == 2 and err.count("\n") == 1 and expected in err, err
    assert "diagnose --from" in err and "see compgen diagnose" not in err
    assert not out.exists()
    # --force overwrites, nothing more: the gate has its own option, said everywhere
    code, _, err = run("kinematics", "--from", fit, "--controller", "itnc530", "-o", out, "--force")
    assert code == 2 and expected in err and "--despite-gate" in err and not out.exists(), err
    code, _, err = run("kinematics", "--from", fit, "--controller", "itnc530", "-o", out, "--despite-gate",
                       "--beyond-limits")
    assert code == 0, err
    assert "warning: writing an edit despite the fit gate: " in err and expected in err
    said = [ln for ln in out.read_text().splitlines() if "WRITTEN DESPITE THE FIT GATE: " in ln]
    assert any(expected.replace("µ", "u") in ln for ln in said), said


def test_a_fit_that_explains_its_data_passes_the_gate(fitted, tmp_path):
    code, _, err = run("kinematics", "--from", fitted / "fit2.json", "--controller", "itnc530",
                       "-o", tmp_path / "K.txt")
    assert code == 0, err


def _session_with(tmp_path, change):
    """The example session with one data row's cells changed."""
    lines = (ROOT / "examples" / "seed-session.csv").read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("path,"))
    cols = lines[head].split(",")
    row = lines[head + 5].split(",")
    for column, value in change.items():
        row[cols.index(column)] = value
    lines[head + 5] = ",".join(row)
    path = tmp_path / "session.csv"
    path.write_text("\n".join(lines) + "\n")
    return path, head + 6


@pytest.mark.parametrize("change, expected", [
    ({"dX": "1e300"}, "not a finite number of a sensible size"),
    ({"dZ": "١٢"}, "is not a number"),
    ({"dY": "6000"}, "beyond any R-test's measuring range"),
    ({"dZ": "1" + "0" * 140000}, "not a CSV row"),
    ({"path": "K4 G0 Z-500"}, "not a valid path name"),
    ({"path": '"K4\nG0 Z-500"'}, "fields where the header has"),
])
def test_hostile_data_rows_are_refused_with_their_line(tmp_path, change, expected):
    csv, line = _session_with(tmp_path, change)
    code, _, err = run("fit", "--machine", SEED_MACHINE, csv, "-o", tmp_path / "f.json")
    assert code == 2 and err.count("\n") == 1 and expected in err, err
    assert f"session.csv:{line}" in err, err


@pytest.mark.parametrize("change, expected", [
    (lambda d: d.update(residual={}), "residual statistics are incomplete"),
    (lambda d: d["parameters"]["XOC"].update(value=1e300), "not the size of a machine error"),
])
def test_a_fit_with_damaged_numbers_is_refused_by_every_command(fitted, tmp_path, change, expected):
    fit = _edited_fit(fitted, tmp_path, change)
    for args in (("diagnose", "--from", fit), ("compare", "--from", fit),
                 ("kinematics", "--from", fit, "-o", tmp_path / "K.txt", "--despite-gate"),
                 ("report", "--from", fit, "-o", tmp_path / "r.html")):
        code, _, err = run(*args)
        assert code == 2 and err.count("\n") == 1 and expected in err, (args[0], err)


def test_a_bundled_machine_is_named_from_anywhere(tmp_path):
    done = subprocess.run([sys.executable, "-m", "compgen", "effects", "--machine", "bc-table-sinumerik840d"],
                          cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0 and "EXC" in done.stdout, done.stderr
    code, _, err = run("effects", "--machine", "no-such-machine")
    assert code == 2 and ("ac-trunnion-itnc530, bc-fork-head, bc-nutating-head-table, bc-swivel-head-table,"
                          " bc-table-sinumerik840d"
                          in err), err


def test_report_and_compare_show_the_same_figures(fitted, tmp_path):
    code, text, err = run("compare", "--from", fitted / "fit2.json")
    assert code == 0, err
    out = tmp_path / "r.html"
    code, _, err = run("report", "--from", fitted / "fit2.json", "-o", out)
    assert code == 0, err
    html = out.read_text()
    for path in ("K4", "K1", "K2"):
        row = next(ln.split() for ln in text.splitlines() if ln.strip().startswith(path + " "))
        before, predicted = row[1], row[2]
        assert f'<td class="l">{path}</td><td>{before}</td><td>{predicted}</td>' in html, (path, row)


def test_every_error_is_one_line(tmp_path, fitted):
    """Usage errors too, and a message quoting a line break shows it rather than breaking."""
    for args in (("fit", "--bogus"), ("kinematics", "--from", fitted / "fit2.json", "-o", tmp_path),
                 ("measure-program", "--machine", SEED_MACHINE, "--path", "K2", "--mode", "nope")):
        done = subprocess.run([sys.executable, "-m", "compgen", *map(str, args)], capture_output=True,
                              text=True)
        assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
        assert done.stderr.startswith("compgen: error:") and "--help" in done.stderr, done.stderr
    text = SEED_MACHINE.read_text().replace("[paths.K2]", '[paths."K2\\nG0 Z-500"]')
    machine = tmp_path / "m.toml"
    machine.write_text(text)
    code, _, err = run("effects", "--machine", machine)
    assert code == 2 and err.count("\n") == 1 and "K2\\nG0 Z-500" in err, err
    code, _, err = run("kinematics", "--from", fitted / "fit2.json", "-o", tmp_path / "K\nG0.txt")
    assert code == 2 and "control character" in err and not list(tmp_path.glob("K*")), err


@pytest.mark.parametrize("rows, expected", [
    ("6   Trans     Y     +0.01000     Y0A\n7   MachAxis  A\n", "has no partner row -Y0A"),
    ("6   Trans     Y     +0.01000     Y0A\n7   MachAxis  A\n8   Trans     Y     -0.01100     -Y0A\n",
     "do not cancel"),
])
def test_a_broken_pair_of_rows_is_not_edited(fitted, tmp_path, rows, expected):
    """A correction added to one half of an error/inverse pair would leave them inconsistent."""
    table = (ROOT / "examples" / "itnc530-current.TAB").read_text().replace("6   MachAxis  A\n", rows)
    current = tmp_path / "current.TAB"
    current.write_text(table)
    code, _, err = run("kinematics", "--from", fitted / "fit2.json", "--current", current,
                       "-o", tmp_path / "K.TAB")
    assert code == 2 and expected in err, err


def _only(name, value, extra=()):
    """fit2 with every parameter zero but ``name`` (and ``extra`` added to the model)."""
    def change(d):
        for n in extra:
            d["model"].append(n)
            d["parameters"][n] = {"value": 0.0, "std": 0.0, "unit": "rad" if n[:3] != "EYY" else "mm"}
        for n, p in d["parameters"].items():
            p["value"] = value if n == name else 0.0
    return change


@pytest.mark.parametrize("name, value, extra, expected", [
    ("XOC", 0.15, (), "C line offset 150.0 um > 100 um"),        # at the pivot: XOC itself
    ("ZOA", -0.12, (), "A line offset 120.0 um > 100 um"),
    ("BOC", 100 * np.pi / 648000, (), "C line tilt 100.0 arcsec > 60 arcsec"),
    ("COX", -70 * np.pi / 648000, ("COX",), "COX 70.0 arcsec > 60 arcsec"),
    ("ECC:h2c", 70 * np.pi / 648000, ("ECC:h2c", "ECC:h2s"), "ECC:h2 table 70.0 arcsec > 60 arcsec"),
    ("ECC:h2c", 50 * np.pi / 648000, ("ECC:h2c", "ECC:h2s"), None),
    ("EYY:p1", 0.3, ("EYY:p1",), "EYY:p1 table 105.0 um > 100 um"),     # 0.3 mm/m over ±350 mm
    ("EYY:p1", 0.25, ("EYY:p1",), None),                               # 87.5 µm
    ("XOC", 0.099, (), None),
    ("COX", 59 * np.pi / 648000, ("COX",), None),
])
def test_each_correction_is_held_to_its_limit(fitted, tmp_path, name, value, extra, expected):
    """[limits] of the seed machine: 100 µm, 60″; the sizes in the refusal derived here."""
    fit = load_fit(_edited_fit(fitted, tmp_path, _only(name, value, extra)))
    machine, _ = reload(fit)
    if expected is None:
        plan(machine, fit)
        return
    with pytest.raises(CompgenError) as exc:
        plan(machine, fit)
    assert expected in str(exc.value), str(exc.value)
    assert str(exc.value).count(">") == 1, str(exc.value)       # nothing else is over
    plan(machine, fit, force=True)


@pytest.mark.parametrize("inverse, ok", [("-0.01001", True), ("-0.01002", False)])
def test_a_pair_may_differ_by_one_unit_of_its_last_decimal(fitted, tmp_path, inverse, ok):
    """Both halves are rounded to the table's 5 decimals: 1e-5 mm apart is rounding, 2e-5 is not."""
    rows = f"6   Trans     Y     +0.01000     Y0A\n7   MachAxis  A\n8   Trans     Y     {inverse}     -Y0A\n"
    table = (ROOT / "examples" / "itnc530-current.TAB").read_text().replace("6   MachAxis  A\n", rows)
    current = tmp_path / "current.TAB"
    current.write_text(table)
    code, _, err = run("kinematics", "--from", fitted / "fit2.json", "--current", current,
                       "-o", tmp_path / "K.TAB")
    assert (code == 0) == ok and (ok or "do not cancel" in err), err


def test_compare_says_when_the_prediction_is_against_the_edit(tmp_path):
    """dX and dY swapped: σ̂ far above the noise, every path predicted beyond its tolerance."""
    csv = tmp_path / "session.csv"
    csv.write_text(_swap_dx_dy((ROOT / "examples" / "seed-session.csv").read_text()))
    assert run("fit", "--machine", SEED_MACHINE, csv, "-o", tmp_path / "fit.json")[0] == 0
    code, out, err = run("compare", "--from", tmp_path / "fit.json")
    assert code == 0, err
    assert "WARNING: the fit leaves σ̂ = 13.68 µm" in out, out
    for path, tol in (("K4", 10), ("K1", 8), ("K2", 8)):
        assert re.search(rf"WARNING: {path} is predicted at [\d.]+ µm range, beyond its tolerance {tol} µm",
                         out), path
