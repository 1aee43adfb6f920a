"""Hostile input, second round (issue 21): each case a user's or an accident's input that
was once an internal error, a silent accept or a wrong refusal. Refusals are one line on
stderr with exit 2; nothing is written."""

import json
import os
import shlex
import subprocess
import sys

import pytest
from conftest import BC_MACHINE, ROOT, SEED_MACHINE, pasted, run

SESSION = ROOT / "examples" / "seed-session.csv"
TAB = ROOT / "examples" / "itnc530-current.TAB"
CARR = ROOT / "examples" / "bc-tcarr-current.txt"


@pytest.fixture(scope="module")
def fit(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fit")
    for step in (["fit", "--machine", SEED_MACHINE, SESSION, "-o", folder / "f0.json"],
                 ["fit", "--from", folder / "f0.json", "--add", "EXC:h2", "-o", folder / "fit.json"]):
        code, _, err = run(*step)
        assert code == 0, err
    return folder / "fit.json"


def _refused(args, says, tmp_path, output=None):
    code, out, err = run(*args)
    assert code == 2 and says in err and len(err.strip().splitlines()) == 1, (code, out, err)
    if output is not None:
        assert not (tmp_path / output).exists()


@pytest.mark.parametrize("rows, says", [
    ("A,C\n500,0\n", "A at 500.000 deg, outside its travel"),
    ("A,C\n0,99999\n", "C at 99999.000 deg, outside its travel"),
    ("A,C,bx,by,bz\n0,0,5000,0,100\n", "does not stand on the table"),
    ("A,C,bx,by,bz\n0,0,0,0,-100\n", "does not stand above the table top"),
])
def test_predict_refuses_a_pose_the_machine_cannot_take(fit, tmp_path, rows, says):
    (tmp_path / "p.csv").write_text(rows)
    _refused(["predict", "--from", fit, "--poses", tmp_path / "p.csv", "-o", tmp_path / "o.csv"],
             f"p.csv:2: {'this pose puts ' if 'travel' in says else 'the ball'}", tmp_path, "o.csv")
    _refused(["predict", "--from", fit, "--poses", tmp_path / "p.csv", "-o", tmp_path / "o.csv"], says,
             tmp_path, "o.csv")


def test_predict_refuses_a_ball_moved_off_the_table_at_the_row_it_moves(fit, tmp_path):
    """Each place the ball stands is checked at its first row, however late it moves."""
    (tmp_path / "p.csv").write_text("A,C,bx,by,bz\n" + "0,0,0,0,100\n" * 5 + "0,0,5000,0,100\n0,0,0,0,100\n")
    _refused(["predict", "--from", fit, "--poses", tmp_path / "p.csv", "-o", tmp_path / "o.csv"],
             "p.csv:7: the ball's stem", tmp_path, "o.csv")


@pytest.mark.parametrize("model, says", [
    ([], "model must be a non-empty list"), ("XOC", "model must be a non-empty list"),
    (["XOC", "QQQ"], "do not agree (QQQ)"), (None, "model must be a non-empty list"),
])
def test_a_fit_file_with_a_damaged_model_is_refused(fit, tmp_path, model, says):
    d = json.loads(fit.read_text())
    d["model"] = model
    (tmp_path / "bad.json").write_text(json.dumps(d))
    _refused(["kinematics", "--from", tmp_path / "bad.json", "-o", tmp_path / "K.txt"], says, tmp_path,
             "K.txt")


@pytest.mark.parametrize("measured, says", [
    (ROOT / "tests" / "golden" / "ac-trunnion-itnc530" / "linuxcnc" / "kinematics.hal",
     "the first line is not 'BEGIN <name>.TAB MM'"),
    (CARR, "the first line is not 'BEGIN <name>.TAB MM'"),
    ("off", "the table puts the C axis at (0.0000, 0.0000, 30.7940) mm"),
])
def test_measured_with_passes_every_current_check(fit, tmp_path, measured, says):
    """A state the data were measured in that is another control's file, or not this
    machine's table, was once ignored: the edit then applied a loaded correction twice."""
    if measured == "off":
        measured = tmp_path / "off.TAB"
        measured.write_text(TAB.read_text().replace("+29.794", "+30.794"))
    _refused(["kinematics", "--from", fit, "--current", TAB, "--measured-with", measured,
              "-o", tmp_path / "K.TAB"], says, tmp_path, "K.TAB")


def test_a_path_list_naming_no_path_is_refused(tmp_path):
    _refused(["measure-program", "--machine", SEED_MACHINE, "--path", ",,", "-o", tmp_path / "x.H"],
             "no path is named", tmp_path, "x.H")


def test_a_ball_on_cs_axis_is_measured_in_tcpm_mode(tmp_path):
    """The ball on C's axis: in TCPM a pose block only turns (F in deg/min), so nothing turns
    too fast; once refused with "C would turn at 42997 deg/min"."""
    out = tmp_path / "X.H"
    code, _, err = run("measure-program", "--machine", SEED_MACHINE, "--path", "K4", "--ball", "-0,-0,100",
                       "-o", out)
    assert code == 0, err
    assert run("check-program", "--machine", SEED_MACHINE, out)[0] == 0


@pytest.mark.parametrize("line, says", [
    ("setp xyzac-trt-kins.x-rot-point 0.0 junk", "setp takes a name and one value"),
    ("setp xyzac-trt-kins.x-rot-point 1_0", "'1_0' is not a number"),
])
def test_a_hal_value_is_the_whole_rest_of_its_line(fit, tmp_path, line, says):
    hal = (ROOT / "tests" / "golden" / "ac-trunnion-itnc530" / "linuxcnc" / "kinematics.hal").read_text()
    bad = "\n".join(line if ln.startswith("setp xyzac-trt-kins.x-rot-point") else ln
                    for ln in hal.splitlines())
    (tmp_path / "c.hal").write_text(bad + "\n")
    _refused(["kinematics", "--from", fit, "--controller", "linuxcnc", "--current", tmp_path / "c.hal",
              "-o", tmp_path / "K.hal", "--force"], says, tmp_path, "K.hal")


def test_a_carr_value_in_another_script_or_with_underscores_is_refused(tmp_path):
    bc = tmp_path / "bc"
    bc.mkdir()
    (bc / "t.json").write_text(json.dumps({"parameters": {"XOC": {"value": 5, "unit": "um"},
                                                          "XOB": {"value": -4, "unit": "um"}}}))
    code, _, err = run("simulate", "--machine", BC_MACHINE, "--truth", bc / "t.json", "--noise-um", "0.5",
                       "--seed", "5", "-o", bc / "s.csv")
    assert code == 0, err
    code, _, err = run("fit", "--machine", BC_MACHINE, bc / "s.csv", "-o", bc / "f.json")
    assert code == 0, err
    for value in ("1_5", "\u0661"):
        (bc / "c.txt").write_text(CARR.read_text().replace("$TC_CARR44[1]=0.0", f"$TC_CARR44[1]={value}"))
        _refused(["kinematics", "--from", bc / "f.json", "--current", bc / "c.txt", "-o", bc / "K.MPF",
                  "--force"], "is not a number", bc, "K.MPF")


def _bash(line, cwd):
    return pasted(line, cwd, dict(os.environ), timeout=60)


def test_a_closed_pipe_is_ordinary_and_a_full_disk_one_line(tmp_path):
    cg = f"{shlex.quote(sys.executable)} -m compgen"
    done = _bash(f"set -o pipefail; {cg} effects --machine {SEED_MACHINE} | head -1", tmp_path)
    assert done.returncode in (0, 141) and done.stderr == "", done.stderr     # 141: head closed it
    assert done.stdout.count("\n") == 1
    done = _bash(f"{cg} effects --machine {SEED_MACHINE} > /dev/full", tmp_path)
    assert done.returncode == 2 and done.stderr.strip() == \
        "compgen: error: standard output: No space left on device", done.stderr


def test_a_machine_file_number_no_float_holds_is_refused_in_one_line(tmp_path):
    """Found by the generated fuzz: a 400-digit integer in a machine file was an internal error."""
    text = SEED_MACHINE.read_text().replace("table_top = 0.0", "table_top = " + "1" * 400)
    (tmp_path / "m.toml").write_text(text)
    rc, _, err = run("effects", "--machine", tmp_path / "m.toml")
    assert rc == 2 and "table_top: must be a finite number" in err and len(err.splitlines()) == 1, err


@pytest.mark.parametrize("odd", ["\u2028", "\x0c", "\x0b", "\x85", "\r", "\x07"])
def test_a_control_character_inside_a_state_value_is_refused_with_its_line(tmp_path, odd):
    """Found by the generated fuzz: splitlines() ended a HAL line inside its value, so
    `setp …x-rot-point 0.00<U+2028>3175` was read as 0.00 and the edit written over it."""
    from compgen.files import read_text
    hal = (ROOT / "tests" / "golden" / "ac-trunnion-itnc530" / "linuxcnc" / "kinematics.hal").read_text()
    bad = tmp_path / "k.hal"
    bad.write_text(hal.replace("x-rot-point 0.003175", f"x-rot-point 0.00{odd}3175"), newline="")
    line = 1 + next(k for k, ln in enumerate(hal.splitlines()) if "x-rot-point 0.003175" in ln)
    with pytest.raises(Exception, match=rf"k.hal:{line}: .*control character"):
        read_text(bad, "state", ansi_ok=True)
    bad.write_bytes(b"\n" + bad.read_bytes())     # a blank first line counts too
    with pytest.raises(Exception, match=rf"k.hal:{line + 1}: .*control character"):
        read_text(bad, "state", ansi_ok=True)
    good = tmp_path / "cr.TAB"                 # a CR alone is a line end where no line ends in LF
    good.write_text((ROOT / "examples" / "itnc530-current.TAB").read_text().replace("\n", "\r"), newline="")
    assert read_text(good, "state", ansi_ok=True)[0].count("\r") == 12
    lines = good.read_bytes().decode().split("\r")      # lines ending in CR: counted by CR, first byte on
    lines[4] += "\x07"
    good.write_text("\r" + "\r".join(lines), newline="")
    with pytest.raises(Exception, match=r"cr.TAB:6: .*control character '\\x07'"):
        read_text(good, "state", ansi_ok=True)


def test_no_output_replaces_an_input_of_its_command_even_with_force(tmp_path, monkeypatch):
    """The history store, the machine file and the data a command read are its inputs:
    --force overwrites an earlier output, never one of them (each refused in one line, the
    file byte for byte as it was)."""
    monkeypatch.chdir(tmp_path)
    machine = tmp_path / "m.toml"
    machine.write_text(SEED_MACHINE.read_text())
    data, fit, store = tmp_path / "s.csv", tmp_path / "f.json", tmp_path / "h.sqlite"
    truth = ROOT / "examples" / "truth-table4.json"
    assert run("simulate", "--machine", machine, "--truth", truth, "--paths", "K4,K1,K2", "-o", data)[0] == 0
    code, _, err = run("fit", "--machine", machine, data, "-o", fit, "--record", "--db", store)
    assert code == 0, err
    cases = [
        ("history", "export", "--db", store, "-o", store, "--force"),
        ("history", "trend", "--machine", machine, "--db", store, "--plot", store, "--force"),
        ("history", "trend", "--machine", machine, "--db", store, "--plot", machine, "--force"),
        ("report", "--from", fit, "-o", machine, "--force"),
        ("report", "--from", fit, "-o", data, "--force"),
        ("predict", "--from", fit, "--poses", data, "-o", machine, "--force"),
    ]
    for args in cases:
        before = {p: p.read_bytes() for p in (machine, data, fit, store)}
        code, _, err = run(*args)
        assert code == 2 and "overwrite an input" in err and len(err.splitlines()) == 1, (args, err)
        assert {p: p.read_bytes() for p in before} == before, args


def test_a_reader_gone_before_the_first_line_is_ordinary_use(tmp_path):
    """The reader's end of the pipe is closed before compgen writes a byte (the race
    `| head -1` only sometimes loses, made certain): exit 0 and not a word on stderr."""
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, "-m", "compgen", "effects", "--machine", str(SEED_MACHINE)],
                              stdout=write, stderr=subprocess.PIPE, text=True, cwd=tmp_path, timeout=60)
    finally:
        os.close(write)
    assert done.returncode == 0 and done.stderr == "", (done.returncode, done.stderr)


@pytest.mark.parametrize("raised, code, said", [
    # docs/safety.md: an unexpected exception is compgen's bug, COMPGEN_DEBUG=1 shows its traceback
    (ZeroDivisionError("float division by zero"), 3,
     "compgen: error: internal error (ZeroDivisionError: float division by zero); this is a bug in "
     "compgen. Run again with COMPGEN_DEBUG=1 for the traceback and report it"),
    # Ctrl-C is the user's, not a bug; 130 as the shell's own, not check's 1 for a failed check
    (KeyboardInterrupt(), 130, "compgen: interrupted"),
    # another Python than compgen's (a hint pasted outside its venv): a package missing, not a bug
    (ModuleNotFoundError("No module named 'matplotlib'", name="matplotlib"), 2,
     f"compgen: error: this Python ({sys.executable}) lacks the package 'matplotlib' compgen needs: run "
     "compgen from the environment it was installed in, or install it there: "
     f"{sys.executable} -m pip install matplotlib"),
])
def test_a_bug_and_an_interrupt_are_one_line_with_their_exit_codes(monkeypatch, raised, code, said):
    from compgen.commands import cli

    def failing(*a, **k):
        raise raised
    monkeypatch.delenv("COMPGEN_DEBUG", raising=False)
    monkeypatch.setattr(cli, "catalogue", failing)
    got, out, err = run("effects", "--machine", SEED_MACHINE)
    assert (got, out, err.strip()) == (code, "", said), (got, err)


def _bump(d, key, value):
    d[key] = value
    return d


@pytest.mark.parametrize("damage, says", [
    (lambda d: _bump(d, "format", "compgen.fit/0"), "not a compgen fit file (format 'compgen.fit/0')"),
    (lambda d: d.pop("residual") and d, "fit file is incomplete or damaged (KeyError('residual'))"),
    (lambda d: d["parameters"]["XOC"].update(std=-0.001) or d, "negative uncertainty -0.001"),
    (lambda d: [d], "a fit file is a JSON object, not list"),
])
def test_a_fit_file_not_as_compgen_wrote_it_is_refused(fit, tmp_path, damage, says):
    (tmp_path / "bad.json").write_text(json.dumps(damage(json.loads(fit.read_text()))))
    _refused(["diagnose", "--from", tmp_path / "bad.json"], says, tmp_path)


@pytest.mark.parametrize("truth, says", [
    ({"parameters": ["XOC"]}, 'needs an object "parameters"'),
    ({"parameters": {"XOC": {"value": True, "unit": "um"}}}, 'must be {"value": number, "unit": text}'),
    ({"parameters": {"XOC": {"value": 5, "unit": 3}}}, 'must be {"value": number, "unit": text}'),
    ({"parameters": {"XOC": {"value": 5, "unit": "furlong"}}}, "furlong"),
])
def test_a_truth_file_not_as_the_contract_writes_it_is_refused(tmp_path, truth, says):
    (tmp_path / "t.json").write_text(json.dumps(truth))
    _refused(["simulate", "--machine", SEED_MACHINE, "--truth", tmp_path / "t.json",
              "-o", tmp_path / "s.csv"], says, tmp_path, "s.csv")


def test_what_no_controller_reads_and_a_folder_not_there_are_refused(fit, tmp_path):
    (tmp_path / "P.txt").write_text("G0 X0\n")
    _refused(["check-program", "--machine", SEED_MACHINE, tmp_path / "P.txt"],
             "no controller writes programs ending in '.txt'", tmp_path)
    (tmp_path / "E.txt").write_text("an edit, it says\n")
    _refused(["simulate", "--machine", SEED_MACHINE, "--truth", ROOT / "examples" / "truth-table4.json",
              "--edit", tmp_path / "E.txt", "-o", tmp_path / "s.csv"],
             "not a kinematics edit compgen wrote for any controller it knows", tmp_path, "s.csv")
    _refused(["kinematics", "--from", fit, "-o", tmp_path / "gone" / "K.txt"], "output folder does not exist",
             tmp_path)
    _refused(["fit", "--from", fit, "--fix", "XOC=12furlong", "-o", tmp_path / "f.json"],
             "--fix XOC=12furlong: unknown unit 'furlong'. Use one of mm, um", tmp_path, "f.json")
    _refused(["fit", "--from", fit, "--fix", "XOC=twelve", "-o", tmp_path / "f.json"],
             "cannot read 'twelve' as a number with a unit", tmp_path, "f.json")


@pytest.mark.parametrize("store, says", [
    (":memory:", "SQLite's name for a store kept nowhere"),
    ("file:h.sqlite", "SQLite's name for a store kept nowhere"),
    ("", "--db is empty"),
    ("dangling.sqlite", "a link to a file that is not there"),
    ("fifo", "not a regular file"),
    ("gone/h.sqlite", "the history store's folder does not exist"),
    ("postgresql+psycopg://u:s3cret@127.0.0.1:1/db", "a URL compgen does not read"),
])
def test_a_store_path_no_history_can_be_kept_at_is_refused_in_one_line(fit, tmp_path, monkeypatch, store,
                                                                       says):
    """Every kind of --db the held-out round found taken as a store, or crashing: each
    refused in one line, exit 2, nothing recorded anywhere (not the default store either)."""
    import os
    monkeypatch.chdir(tmp_path)
    (tmp_path / "dangling.sqlite").symlink_to(tmp_path / "nowhere" / "x.sqlite")
    os.mkfifo(tmp_path / "fifo")
    _refused(["history", "add", fit, "--db", store], says, tmp_path)
    assert not (tmp_path / "compgen-history.sqlite").exists() and "s3cret" not in says
    code, out, err = run("history", "add", fit, "--db", store)
    assert "s3cret" not in out + err


@pytest.mark.parametrize("args, says", [
    (["diagnose", "--noise-um", "1e308"], "is not in the range"),
    (["diagnose", "--noise-um", "nan"], "not a finite number"),
    (["history", "fleet", "--every-days", "inf"], "is not in the range"),
    (["history", "fleet", "--every-days", "nan"], "not a finite number"),
    (["simulate", "--noise-rho", "nan"], "not a finite number"),
    (["simulate", "--stylus-error-um", "inf"], "not a finite number"),
])
def test_a_number_option_out_of_its_range_or_not_finite_is_refused(fit, tmp_path, args, says):
    """click's ranges let NaN through and a plain float takes inf: every number option is a
    finite number within its range (a noise of 1e308 µm overflowed, a due date at inf too)."""
    cmd, *rest = args
    more = {"diagnose": ["--from", fit], "history": ["--db", tmp_path / "h.sqlite"],
            "simulate": ["--machine", "ac-trunnion-itnc530", "--truth",
                         ROOT / "examples" / "truth-table4.json", "-o", tmp_path / "s.csv"]}[cmd]
    _refused([cmd, *rest, *more], says, tmp_path, "s.csv")


def test_a_record_number_that_is_no_whole_number_and_an_implausible_temperature_are_refused(fit, tmp_path):
    """[sinumerik] tcarr = 1.5 was read as record 1 (int()), and a temperature of 10⁶ °C was
    recorded: each refused in one line at its key."""
    from conftest import BC_MACHINE
    bad = tmp_path / "bc.toml"
    text = BC_MACHINE.read_text()
    assert "tcarr = 1 " in text
    bad.write_text(text.replace("tcarr = 1 ", "tcarr = 1.5 ", 1))
    _refused(["measure-program", "--machine", bad, "--path", "K4", "-o", tmp_path / "x.MPF"],
             "tcarr: must be the record's number, a whole number from 1, not 1.5", tmp_path, "x.MPF")
    for value in ("1e6", "-500", "nan"):
        _refused(["history", "add", fit, "--db", tmp_path / "h.sqlite", "--temperature", f"spindle={value}"],
                 "--temperature spindle", tmp_path, "h.sqlite")


@pytest.mark.parametrize("edit, says", [
    (("touches = 5", "touches = 100000"), "at most 25 touches a pose"),
    (("poses = 12", "poses = 5000"), "a path needs 4 to 120 poses"),
    (("[probe]", "[effects.shapes.many]\nat = [" + ", ".join(str(k) for k in range(-200, 201, 2))
      + "]\n\n[probe]"), "a spline of 201 knots: at most 64"),
])
def test_a_machine_file_asking_for_hours_of_work_is_refused_at_its_key(tmp_path, edit, says):
    """Held-out inputs that ran for minutes (a spline of hundreds of knots, a probe of 10⁵
    touches a pose): refused in one line at the key, before anything runs."""
    text = SEED_MACHINE.read_text()
    assert edit[0] in text
    path = tmp_path / "m.toml"
    path.write_text(text.replace(edit[0], edit[1], 1))
    _refused(["effects", "--machine", path], says, tmp_path)
