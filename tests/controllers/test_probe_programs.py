"""Probing programs: written for every control, checked with the probe in the set-up,
LinuxCNC's run through its own interpreter (rs274), and the log it writes read back."""

import re
import shlex

import numpy as np
import pytest
from conftest import BC_MACHINE, ROOT, SEED_MACHINE, TABLE4, UM, rs274, run

from compgen.configuration.machine_file import load_machine
from compgen.data.probe import read_probe_log, sphere_centres
from compgen.statistics.identify import identify

EXT = {"itnc530": ".H", "sinumerik840d": ".MPF", "linuxcnc": ".ngc"}
MACHINES = {"seed": SEED_MACHINE, "bc": BC_MACHINE}


def _program(tmp_path, machine, ctl, path="all"):
    out = tmp_path / "my programs" / f"PROBE{EXT[ctl]}"      # a space: the printed command quotes it
    out.parent.mkdir(exist_ok=True)
    code, _, err = run("probe-program", "--machine", machine, "--path", path, "--controller", ctl, "-o", out)
    assert code == 0, err
    return out, err


@pytest.mark.parametrize("ctl", list(EXT))
def test_a_probing_program_keeps_a_name_of_twenty_and_its_log_twenty_four(tmp_path, ctl):
    """The log is the program's name and ``_LOG``: a name of 20 characters is kept whole, its
    log named in 24 (what HEIDENHAIN and SINUMERIK keep); one of 21 is refused there, nothing
    written. LinuxCNC runs a program by its path: 21 are kept (issue 71)."""
    out = tmp_path / f"ABCDEFGHIJKLMNOPQRST{EXT[ctl]}"
    code, _, err = run("probe-program", "--machine", SEED_MACHINE, "--path", "K4", "--controller", ctl,
                       "-o", out)
    assert code == 0, err
    assert "the log: ABCDEFGHIJKLMNOPQRST_LOG" in out.read_text()
    longer = tmp_path / f"ABCDEFGHIJKLMNOPQRSTU{EXT[ctl]}"
    code, _, err = run("probe-program", "--machine", SEED_MACHINE, "--path", "K4", "--controller", ctl,
                       "-o", longer)
    if ctl == "linuxcnc":
        assert code == 0 and "the log: ABCDEFGHIJKLMNOPQRSTU_LOG" in longer.read_text(), err
        return
    assert code != 0 and "the control keeps 20" in err and "Traceback" not in err, err
    assert not longer.exists()


@pytest.mark.parametrize("ctl", list(EXT))
@pytest.mark.parametrize("machine", list(MACHINES))
def test_every_probing_program_passes_the_check_with_the_probe_in_the_set_up(tmp_path, ctl, machine):
    if ctl == "linuxcnc" and machine == "bc":     # its probe is called by name: refused, one line
        code, _, err = run("probe-program", "--machine", BC_MACHINE, "--path", "all", "--controller", ctl,
                           "-o", tmp_path / "P.ngc")
        assert code == 2 and "LinuxCNC calls tools by number; [probe] tool is 'PROBE'" in err, err
        assert not (tmp_path / "P.ngc").exists()
        return
    out, said = _program(tmp_path, MACHINES[machine], ctl)
    printed = shlex.split(re.search(r"check it: (.*)$", said.strip()).group(1))   # as bash reads it
    code, stdout, err = run(*printed[printed.index("check-program"):])
    assert code == 0 and "OK" in stdout, stdout + err
    closest = float(re.search(r"closest approach ([\d.]+) mm", stdout).group(1))
    assert closest >= load_machine(MACHINES[machine]).probe.margin
    text = out.read_text()
    word = {"itnc530": " TCH PROBE 4.3 ", "sinumerik840d": "\nMEAS=1 G1 ", "linuxcnc": "\nG38.2 "}[ctl]
    assert text.count(word) == 36 * 5


def test_a_heidenhain_probing_direction_of_length_one_and_a_half_is_refused_at_its_line(tmp_path):
    out, _ = _program(tmp_path, SEED_MACHINE, "itnc530", "K4")
    text = out.read_text()
    find = "IX-0.866025 IY+0.000000 IZ-0.500000"
    at = next(i for i, ln in enumerate(text.splitlines(), 1) if find in ln)
    bad = tmp_path / "BAD.H"
    bad.write_text(text.replace(find, "IX-1.299038 IY+0.000000 IZ-0.750000", 1))
    code, _, err = run("check-program", "--machine", SEED_MACHINE, bad)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert f"BAD.H:{at}: the probing direction is not a unit vector" in err, err


@pytest.mark.parametrize("ctl, find, replace, rule", [
    ("linuxcnc", "G38.2 ", "G1 ", "stylus tip enters the ball"),                 # a probe made a feed
    ("itnc530", "IX-0.866025 IY+0.000000 IZ-0.500000", "IX+0.866025 IY+0.000000 IZ-0.500000",
     "probing move does not touch the sphere"),                                 # probing away from it
    ("sinumerik840d", "MEAS=1 G1 X-206.9385 Y-0.2790 Z247.4310", "MEAS=1 G1 X-206.9385 Y-0.2790 Z252.4310",
     "does not touch the sphere"),                                               # stops 1 mm short
])
def test_a_damaged_probing_program_is_refused_at_its_line(tmp_path, ctl, find, replace, rule):
    out, _ = _program(tmp_path, SEED_MACHINE, ctl, "K4")
    text = out.read_text()
    assert find in text
    at = next(i for i, ln in enumerate(text.splitlines(), 1) if find in ln)
    bad = tmp_path / f"BAD{EXT[ctl]}"
    bad.write_text(text.replace(find, replace, 1))
    code, stdout, err = run("check-program", "--machine", SEED_MACHINE, bad,
                            *(["--mode", "axes"] if ctl == "linuxcnc" else []))
    assert code == 1 and rule in stdout, stdout + err
    assert re.search(rf"BAD{re.escape(EXT[ctl])}:({at}|{at + 1}|{at + 2}|{at + 3}): ", stdout), stdout


@pytest.mark.parametrize("ball, spindle", [(None, None), ("-217.504,-0.279,111.537", None), (None, "60")])
def test_linuxcnc_runs_the_probing_program_and_its_log_is_a_probe_log(tmp_path, ball, spindle):
    """rs274 (LinuxCNC's interpreter) reads the program to the simulator's probing moves;
    the LOG lines it writes, each probe result set where the stylus meets the sphere, are a
    probe log v1 that compgen fits back to the nominal machine: with the sphere where the
    machine file has it, and 100 mm lower (as diagnose advises a probe user): the log says
    where it stood (bx, by, bz); with the probe turned in the spindle (M19 R60 before the
    first touch), the log says that too."""
    out = tmp_path / "PROBE.ngc"
    code, _, err = run("probe-program", "--machine", SEED_MACHINE, "--path", "all", "--controller",
                       "linuxcnc", "-o", out, *([f"--ball={ball}"] if ball else []),
                       *(["--spindle-deg", spindle] if spindle else []))
    assert code == 0, err
    canon, done = rs274(out.parent, out.name, "T98 P1 Z120 ;probe")
    if spindle:
        assert 0 <= canon.find("ORIENT_SPINDLE(0, 60.0000, 0)") < canon.find("STRAIGHT_PROBE"), canon[:2000]
    probes = np.array([[float(v) for v in m[1].split(",")][:3]
                       for m in re.finditer(r"STRAIGHT_PROBE\(([^)]*)\)", canon)])
    assert len(probes) == 36 * 5, done.stdout + done.stderr
    logged = re.findall(r'LOG\("([^"]*)"\)', canon)
    head = ["# compgen probe log v1", "# sphere_diameter = 25.4000", "# stylus_diameter = 3.0000",
            *(["# spindle_deg = 60.0000"] if spindle else []), "path,pose,A,C,X,Y,Z,nx,ny,nz,bx,by,bz"]
    assert logged[:len(head)] == head
    rows = [r.split(",") for r in logged[len(head):]]
    assert len(rows) == len(probes)
    machine = load_machine(SEED_MACHINE)
    stood = [float(v) for v in ball.split(",")] if ball else list(machine.ball)
    # the interpreter's probe "touches" at the target: the stylus meets the sphere overtravel
    # (2 mm) before it, back along the probing direction
    for r, target in zip(rows, probes, strict=True):
        n = np.array([float(v) for v in r[7:10]])
        logged_xyz = np.array([float(v) for v in r[4:7]])
        np.testing.assert_allclose(logged_xyz, target, atol=1e-6)     # #5061-#5063 as rs274 set them
        np.testing.assert_allclose([float(v) for v in r[10:13]], stood, atol=1e-4)
        r[4:7] = [f"{v:.6f}" for v in target - 2.0 * n]
    log = tmp_path / "PROBE_LOG.log"
    log.write_text("\n".join(logged[:len(head)] + [",".join(r) for r in rows]) + "\n")
    fit = identify(machine, [sphere_centres(read_probe_log(log, machine), machine).data])
    # nominal, to the 0.1 µm the program writes its positions in: below 0.1 µm and 0.2″
    assert all(abs(e.value) < (1e-4 if e.unit == "mm" else 1e-6)
               for e in fit.parameters.values()), fit.parameters
    code, _, err = run("fit", "--machine", SEED_MACHINE, log, "-o", tmp_path / "fit.json")
    assert code == 0, err


def test_simulate_a_probe_log_then_fit_it(tmp_path):
    log = tmp_path / "sim.log"
    truth = tmp_path / "truth.json"
    truth.write_text('{"parameters": {' + ", ".join(
        f'"{n}": {{"value": {v}, "unit": "{"mm" if n[1] == "O" and n[0] in "XYZ" else "rad"}"}}'
        for n, v in TABLE4.items()) + "}}")
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--device", "probe",
                       "--noise-um", "1", "--seed", "3", "-o", log)
    assert code == 0, err
    code, _, err = run("fit", "--machine", SEED_MACHINE, log, "-o", tmp_path / "fit.json")
    assert code == 0, err
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--device", "probe",
                       "--noise-um", "1", "--seed", "3", "--stylus-error-um", "0", "-o", tmp_path / "0.log")
    assert code == 0 and (tmp_path / "0.log").read_bytes() == log.read_bytes(), err   # the default: none
    machine = load_machine(SEED_MACHINE)
    fit = identify(machine, [sphere_centres(read_probe_log(log, machine), machine).data])
    assert all(abs(fit.parameters[n].value - v) < 5 * fit.parameters[n].std for n, v in TABLE4.items())
    # without trigger noise the centres are the truth's, to the log's 0.1 µm: none is added to them
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--device", "probe",
                       "--noise-um", "0", "-o", tmp_path / "exact.log")
    assert code == 0, err
    exact = identify(machine, [sphere_centres(read_probe_log(tmp_path / "exact.log", machine), machine).data])
    assert exact.residual["rms_um"] < 0.1, exact.residual["rms_um"]
    assert all(abs(exact.parameters[n].value - v) < 0.1 * UM for n, v in TABLE4.items() if n[1] == "O"
               and n[0] in "XYZ")
    code, _, err = run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--device", "probe",
                       "--stylus-error-um", "20", "--seed", "3", "-o", tmp_path / "worn.log")
    assert code == 0, err
    code, _, err = run("fit", "--machine", SEED_MACHINE, tmp_path / "worn.log", "-o", tmp_path / "w.json")
    assert code == 2 and "+10.0" in err and "stylus diameter" in err, err


@pytest.mark.parametrize("args, expected", [
    (["--path", ""], "no path is named"),
    (["--path", "K9"], "defines no path 'K9'"),
    (["--path", "K4", "--ball", "1,2"], "--ball takes three numbers"),
    (["--path", "K4", "--ball", "0,0,-50"], "does not stand above the table top"),
])
def test_bad_probe_program_options_get_one_line(tmp_path, args, expected):
    code, _, err = run("probe-program", "--machine", SEED_MACHINE, *args, "-o", tmp_path / "P.H")
    assert code == 2 and expected in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "P.H").exists()


@pytest.mark.parametrize("start, end, said", [
    # along -x toward the sphere's side: touches where the tip's centre is rho from the ball's
    ((5.0, 0.0, 0.0), (-2.0, 0.0, 0.0), None),
    ((0.01, 0.0, 0.0), (-0.5, 0.0, 0.0), None),             # starting 0.01 mm off the sphere
    ((0.004, 0.0, 0.0), (-0.004, 0.0, 0.0), None),          # a move of 8 µm that touches
    ((5.0, 0.0, 0.0), (0.5, 0.0, 0.0), "ends 0.50 mm short of it"),
    ((5.0, 0.0, 0.0), (0.01, 0.0, 0.0), "ends 0.01 mm short of it"),
    # 2 mm beside the line through the centre: its end is √((ρ + 1)² + 2²) − ρ from the sphere
    ((5.0, 2.0, 0.0), (1.0, 2.0, 0.0), "ends 1.13 mm short of it"),
    ((5.0, 0.0, 0.0), (9.0, 0.0, 0.0), "misses it"),        # moving away
    ((-0.5, 0.0, 0.0), (-2.0, 0.0, 0.0), "starts inside the sphere"),
    ((0.01, 0.0, 0.0), (2.0, 0.0, 0.0), "misses it"),       # 0.01 mm off, away
    ((5.0, 3.0, 0.0), (5.0, 3.0, -30.0), "misses it"),      # beside the sphere, down past it
])
def test_a_probing_move_stops_where_the_tip_meets_the_sphere(start, end, said):
    """``motion._touch`` on the seed machine, rotary axes at zero: ``start`` and ``end`` are
    mm beyond contact along x (the tip's centre at rho = (sphere + tip) / 2 from the ball's
    centre at 0), y, z. A touch stops on the contact sphere; a move that does not touch is a
    finding that says why."""
    from compgen.model.frames import table_point
    from compgen.model.kinematics import inverse
    from compgen.motion.blocks import Block
    from compgen.motion.check import _touch
    m = load_machine(SEED_MACHINE)
    ball, rho = np.asarray(m.ball), (m.setup.ball_diameter + m.probe.stylus_diameter) / 2
    at = [ball + [rho + p[0], p[1], p[2]] for p in (start, end)]
    q0, q1 = inverse(m, np.zeros((2, len(m.rotary_axes))), np.array(at))
    findings = []
    got = _touch(m, m.probe, Block(7, "PROBE", "move", probe=True), q0, q1, findings)
    if said is None:
        assert findings == [] and got is not None
        tip = table_point(m, got[None])[0]
        assert np.linalg.norm(tip - ball) == pytest.approx(rho, abs=1e-9)
        assert tip[0] > ball[0] and abs(tip[1] - ball[1]) < 1e-9       # on the near side, on the line
    else:
        assert got is None and len(findings) == 1
        assert findings[0].text("P.H") == ("P.H:7: probing move does not touch the sphere: the stylus tip "
                                           f"{said}; the control stops the program with an error (at PROBE)")


def test_a_grazing_probing_move_touches():
    """A move passing 0.3 µm inside the contact sphere touches it (near-tangent: the
    discriminant is tiny but positive)."""
    from compgen.model.frames import table_point
    from compgen.model.kinematics import inverse
    from compgen.motion.blocks import Block
    from compgen.motion.check import _touch
    m = load_machine(SEED_MACHINE)
    ball, rho = np.asarray(m.ball), (m.setup.ball_diameter + m.probe.stylus_diameter) / 2
    h = rho - 3e-4
    at = np.array([ball + [h, 0.0, 3.5], ball + [h, 0.0, -3.5]])
    q0, q1 = inverse(m, np.zeros((2, len(m.rotary_axes))), at)
    findings = []
    got = _touch(m, m.probe, Block(3, "PROBE", "move", probe=True), q0, q1, findings)
    assert findings == [] and got is not None
    assert np.linalg.norm(table_point(m, got[None])[0] - ball) == pytest.approx(rho, abs=1e-9)


@pytest.mark.parametrize("ctl", list(EXT))
def test_every_probing_program_stops_for_the_preset_check_before_its_first_touch(tmp_path, ctl):
    """As every measuring program does: once, the stylus over the sphere, a message the
    control shows (LinuxCNC MSG, SINUMERIK MSG, HEIDENHAIN FN 16 to SCREEN with its format
    file beside the program), then a stop, before the first probing move."""
    out, _ = _program(tmp_path, SEED_MACHINE, ctl, "K4")
    lines = out.read_text().splitlines()
    stop = {"itnc530": r"^\d+ STOP\b", "sinumerik840d": r"^M0$", "linuxcnc": r"^M0$"}[ctl]
    probe = {"itnc530": r" TCH PROBE 4\.3 ", "sinumerik840d": r"^MEAS=1 ", "linuxcnc": r"^G38\.2 "}[ctl]
    stops = [i for i, ln in enumerate(lines) if re.search(stop, ln)]
    first = next(i for i, ln in enumerate(lines) if re.search(probe, ln))
    message = {"itnc530": r"FN 16: F-PRINT TNC:\\PROBE_MSG\.A / SCREEN:",
               "sinumerik840d": r'^MSG\("PRESET CHECK', "linuxcnc": r"^\(MSG, PRESET CHECK"}[ctl]
    preset = [i for i in stops if re.search(message, lines[i - 1])]
    assert len(preset) == 1 and preset[0] < first, (stops, first)
    if ctl == "itnc530":
        shown = (out.parent / "PROBE_MSG.A").read_text()
        assert re.fullmatch(r'"PRESET CHECK: the stylus tip is 5 mm above the sphere[^";%]*";\n', shown), \
            shown
        assert all(len(m) <= 124 for m in re.findall(r'"([^"]*)"', shown))


def test_sinumerik_probing_checks_every_switch_and_every_write(tmp_path):
    """After each MEAS block: STOPRE and a stop with a message unless $AC_MEA[1] says the
    probe switched; after each WRITE a stop unless it wrote (a full log drops lines, MD11420).
    check-program refuses the program with either guard taken out."""
    out, _ = _program(tmp_path, SEED_MACHINE, "sinumerik840d", "K4")
    text = out.read_text()
    lines = [ln.split(";")[0].strip() for ln in text.splitlines()]
    meas = [i for i, ln in enumerate(lines) if ln.startswith("MEAS=1 ")]
    writes = [i for i, ln in enumerate(lines) if ln.startswith("WRITE(")]
    assert len(meas) == 12 * 5 and len(writes) == len(meas) + 4
    for i in meas:
        assert lines[i + 1:i + 7] == ["STOPRE", "IF $AC_MEA[1]==0", lines[i + 3], "M0", "M30", "ENDIF"]
        assert lines[i + 3].startswith('MSG("PROBE DID NOT SWITCH')
    for i in writes:
        assert lines[i + 1] == "IF ERR<>0" and lines[i + 2].startswith('MSG("LOG NOT WRITTEN') and \
            lines[i + 3:i + 6] == ["M0", "M30", "ENDIF"]
    for cut in ("IF $AC_MEA[1]==0", "IF ERR<>0"):
        raw = text.splitlines()
        at = next(k for k, ln in enumerate(raw) if ln.startswith(cut))
        (out.parent / "cut.MPF").write_text("\n".join(raw[:at] + raw[at + 5:]) + "\n")
        code, _, err = run("check-program", "--machine", SEED_MACHINE, out.parent / "cut.MPF")
        assert code == 2 and f"cut.MPF:{at + 1}: " in err and "must follow" in err, err


def test_heidenhain_probing_cycle_retracts_and_a_deflected_one_is_refused(tmp_path):
    out, _ = _program(tmp_path, SEED_MACHINE, "itnc530", "K4")
    text = out.read_text()
    assert re.findall(r"TCH PROBE 4\.3 ABST\S+ F\S+ (MB\S+) ", text) == ["MB+5.0000"] * 60
    (out.parent / "mb0.H").write_text(text.replace("MB+5.0000", "MB0", 1))
    code, _, err = run("check-program", "--machine", SEED_MACHINE, out.parent / "mb0.H")
    assert code == 2 and "MB0: cycle 4 leaves the stylus deflected" in err, err


def test_names_that_a_control_would_expand_in_its_log_stay_out_of_it(tmp_path):
    """A '#' in the machine's name is a parameter to LinuxCNC's LOG, '%' a format to FN 16:
    the name is left out of the log (compgen would refuse the log it came back in); a path
    label the log cannot carry is refused with one line."""
    from compgen.controllers.probing import probe_program
    from compgen.data.probe import probe_poses

    text = SEED_MACHINE.read_text()
    name = re.search(r'(?m)^name = "([^"]*)"', text)[1]
    for odd in ("#3", "100%", "a;b", "x\"y"):
        m = tmp_path / "m.toml"
        m.write_text(text.replace(f'name = "{name}"', f"name = {odd!r}".replace("'", '"') if '"' not in odd
                                  else 'name = "x\\"y"', 1))
        machine = load_machine(m)
        for ctl in EXT:
            files = probe_program(machine, probe_poses(machine, ["K4"]), "K4", ctl, "P", "0", "d").files
            assert "# machine =" not in "\n".join(files.values()), (odd, ctl)
    machine = load_machine(SEED_MACHINE)
    from compgen.model.poses import Poses
    poses = probe_poses(machine, ["K4"])
    poses = Poses(poses.q, poses.ball, poses.t, np.full(len(poses), "K#4", dtype=object))
    with pytest.raises(Exception, match="path label 'K#4' cannot stand in the control's log"):
        probe_program(machine, poses, "K4", "linuxcnc", "P", "0", "d")


@pytest.mark.parametrize("ctl", ["itnc530", "sinumerik840d", "linuxcnc"])
@pytest.mark.parametrize("writer", ["measure-program", "probe-program"])
def test_every_pose_list_compgen_writes_is_read_back_by_predict(tmp_path, ctl, writer):
    """Everything compgen writes, compgen reads: a probing program's pose list had +nan in
    every row's A_side and C_side (a probe's poses have no side), which predict and
    measure-program --poses refused. A side is +1 or -1, or its column is left out."""
    fit = tmp_path / "f.json"
    assert run("fit", "--machine", SEED_MACHINE, ROOT / "examples" / "seed-session.csv", "-o", fit)[0] == 0
    ext = {"itnc530": ".H", "sinumerik840d": ".MPF", "linuxcnc": ".ngc"}[ctl]
    code, _, err = run(writer, "--machine", SEED_MACHINE, "--path", "K2", "--controller", ctl,
                       "-o", tmp_path / f"P{ext}")
    assert code == 0, err
    listed = (tmp_path / "P.poses.csv").read_text()
    assert "nan" not in listed.lower()
    code, _, err = run("predict", "--from", fit, "--poses", tmp_path / "P.poses.csv", "-o",
                       tmp_path / "pred.csv")
    assert code == 0, err


def test_a_linuxcnc_program_name_is_a_file_name_not_a_controls_24_characters(tmp_path):
    """LinuxCNC runs a program by its path: a name past 24 characters (the HEIDENHAIN and
    SINUMERIK limit) was refused for it; it still is for those controls."""
    long = "K2_WITH_THE_BALL_AT_HALF_ITS_RADIUS"          # 35 characters
    for writer in ("measure-program", "probe-program"):
        code, _, err = run(writer, "--machine", SEED_MACHINE, "--path", "K2", "--controller", "linuxcnc",
                           "-o", tmp_path / f"{long}.ngc", "--force")
        assert code == 0, err
        code, _, err = run(writer, "--machine", SEED_MACHINE, "--path", "K2", "-o", tmp_path / f"{long}.H")
        assert code == 2 and "the control keeps" in err, err
    assert f"(LOGOPEN,{long}_LOG.log)" in (tmp_path / f"{long}.ngc").read_text()
