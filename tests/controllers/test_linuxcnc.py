"""A real controller in the loop: a headless LinuxCNC (Debian's linuxcnc-uspace) with the
xyzac-trt kinematics runs compgen's programs; its joints are checked against compgen, and
compgen's kinematics edit, loaded into LinuxCNC, is shown to remove the errors it can hold.

Both trt kinematics run: xyzac-trt-kins (the seed machine) and xyzbc-trt-kins (the B/C
table), each with a configuration that sets one pin through a signal, so the edit must
respect the configuration's nets. maxkins (a B head over a C table) runs the reference
swivel head's K4 poses: its joints are held to compgen's chain for heads. CI installs
LinuxCNC and sets COMPGEN_REQUIRE_LINUXCNC; elsewhere the test is skipped when LinuxCNC is
not installed.
"""

import contextlib
import fcntl
import json
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from conftest import BC_MACHINE, FORK_MACHINE, ROOT, SEED_MACHINE, UM, on_linuxcnc

from compgen.configuration.machine_file import load_machine
from compgen.controllers import linuxcnc
from compgen.controllers.correction import nominal_lines
from compgen.controllers.kinematics import kinematics_edit
from compgen.controllers.programs import measure_program
from compgen.controllers.registry import read_edits, read_state
from compgen.data.rtest import RTestData
from compgen.data.simulate import simulate
from compgen.model.effects import location_model
from compgen.model.kinematics import Model, inverse
from compgen.model.lines import controller_inverse
from compgen.model.machine import at_nest
from compgen.model.paths import generate
from compgen.model.poses import Poses
from compgen.statistics.identify import identify

HERE = ROOT / "tests" / "linuxcnc"
JOINT_MM = 1e-6     # LinuxCNC's trt inverse vs compgen's, both in double precision
NOISE_UM = 0.5
ARCSEC = np.pi / 648000
# what LinuxCNC can hold: axis-line positions in the trt pins (and the ball's set-up), and
# each axis's error along itself in its joint's compensation table
TRUTH = {
    "xyzac": {"XOW": 4 * UM, "YOW": -6 * UM, "ZOW": 9 * UM, "YOA": 20 * UM, "ZOA": -15 * UM,
              "XOC": 12 * UM, "YOC": -8 * UM, "ECC:h2c": 4 * ARCSEC, "EAA:p1": 5 * ARCSEC},
    "xyzbc": {"XOW": -3 * UM, "YOW": 5 * UM, "ZOW": 7 * UM, "XOB": 18 * UM, "ZOB": -12 * UM,
              "XOC": -9 * UM, "YOC": 14 * UM, "ECC:h2s": -3 * ARCSEC, "EYY:p1": 10 * UM},
}
TABLES = {"xyzac": ["ECC:h2c", "ECC:h2s", "EAA:p1"], "xyzbc": ["ECC:h2c", "ECC:h2s", "EYY:p1"]}
INI_LINE = re.compile(r"^#\s+\[JOINT_(\d)\] COMP_FILE = (\S+), COMP_FILE_TYPE = (\d)$", re.MULTILINE)

pytestmark = [pytest.mark.slow,      # every test here starts LinuxCNC
              pytest.mark.skipif(
                  shutil.which("linuxcnc") is None and not os.environ.get("COMPGEN_REQUIRE_LINUXCNC"),
                  reason="LinuxCNC is not installed (apt-get install linuxcnc-uspace)")]


@pytest.fixture(scope="module", params=["xyzac", "xyzbc"])
def machine(request, tmp_path_factory):
    """The seed machine (xyzac-trt) and the B/C table (xyzbc-trt) on LinuxCNC, with a quick
    [program]: short dwell, brisk feed, a numbered tool."""
    source = SEED_MACHINE if request.param == "xyzac" else BC_MACHINE
    return load_machine(_as_linuxcnc(tmp_path_factory.mktemp("m"), source, request.param))


def _as_linuxcnc(folder, source, name="xyzac"):
    path = folder / f"{name}.toml"
    # the sim's axes (sim.ini: 1000 mm/s, 3600 deg/s), so that a run takes seconds
    text = re.sub(r"feed_max = [0-9.]+", "feed_max = 60000.0", source.read_text())
    path.write_text(re.sub(r'controller = "\w+"', 'controller = "linuxcnc"', text)
                    .replace("dwell = 1.0", "dwell = 0.1").replace("feed = 500.0", "feed = 8000.0")
                    .replace('tool = "RTEST"', 'tool = "7"')
                    .replace("max_step_deg = 10.0", "max_step_deg = 20.0"))
    return path


def current_hal(machine) -> str:
    """The configuration's HAL file, pins nominal: what ``--current`` is given."""
    module, tilt, _ = linuxcnc.trt_module(machine)
    nominal = linuxcnc.nominal_pins(machine, tilt, machine.rotary_axes[1])
    pins = [f"setp {module}.{n} {nominal[n]:.6f}" for n in linuxcnc.pin_names(tilt) if n != "z-rot-point"]
    return (HERE / "sim.hal.in").read_text().replace("@KINS@", module).replace(
        "@PINS@", "\n".join([*pins, f"sets zrot {nominal['z-rot-point']:.6f}"]))


# A run takes 10–40 s on an idle two-core machine; a loaded one may take several times that
RUN_BUDGET_S = 400


def _ours(marker: str) -> list[int]:
    """Every process of one LinuxCNC run: each carries the run's own COMPGEN_JOINTS in its
    environment, including linuxcncsvr and rtapi_app, which leave the launcher's session."""
    pids = []
    for proc in Path("/proc").iterdir():
        try:
            if proc.name.isdigit() and f"COMPGEN_JOINTS={marker}".encode() in (
                    proc / "environ").read_bytes().split(b"\0"):
                pids.append(int(proc.name))
        except OSError:      # gone, or not ours to read
            continue
    return pids


def _milltasks() -> list[int]:
    """Live LinuxCNC task processes on the machine (a zombie left for init to reap, as a
    container's init may leave it a while, is no running LinuxCNC)."""
    pids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            name, state = re.match(r"\d+ \((.*)\) (\S)", stat.read_text()).groups()
        except (OSError, AttributeError):
            continue
        if name == "milltask" and state != "Z":
            pids.append(int(stat.parent.name))
    return pids


def end_linuxcnc(marker: str, grace_s: float = 10.0) -> None:
    """End every process of the run named by ``marker``, whatever state it is in: the
    launcher's own shutdown first (SIGTERM), then SIGKILL for what is left."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in _ours(marker):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, sig)
        end = time.monotonic() + grace_s
        while _ours(marker) and time.monotonic() < end:
            time.sleep(0.1)
        if not _ours(marker):
            break
    assert not _ours(marker), f"LinuxCNC processes {_ours(marker)} survived SIGKILL"
    lock = Path("/tmp/linuxcnc.lock")
    if not _milltasks():
        lock.unlink(missing_ok=True)
        _remove_left_buffers(wait_s=grace_s)


# the NML file of every configuration here: none sets [EMC] NML_FILE, as none of LinuxCNC's
# samples does
NML_FILE = Path("/usr/share/linuxcnc/linuxcnc.nml")


def _nml_buffers() -> list[list[str]]:
    """The kernel's rows (key shmid perms size cpid lpid nattch …) of the System V shared
    memory at the SHMEM keys of LinuxCNC's NML file: its NML buffers."""
    keys = {int(w[9]) for w in (ln.split() for ln in NML_FILE.read_text().splitlines())
            if len(w) > 9 and w[0] == "B" and w[2] == "SHMEM"}
    rows = (ln.split() for ln in Path("/proc/sysvipc/shm").read_text().splitlines()[1:])
    return [r for r in rows if int(r[0]) in keys]


def _buffers_held() -> bool:
    """Whether a process holds one of LinuxCNC's NML buffers (nattch, the rows' 7th column)."""
    return any(r[6] != "0" for r in _nml_buffers())


def _remove_left_buffers(wait_s: float = 0.0) -> None:
    """Remove the NML buffers a run left, as LinuxCNC's launcher does at its end (``ipcrm -M``
    for each SHMEM buffer of the NML file). A run killed outright, or whose launcher was killed
    during that clean-up (the grace above runs out under load), never gets there, and the next
    run's linuxcncsvr takes the buffers over as they were: the IO command buffer's serial
    numbers then run ahead of milltask's count, every IO command 'times out' and the program
    never starts (a CI run waited out its whole budget so). Only buffers no process holds,
    after up to ``wait_s`` for killed processes to let go: one held is a live LinuxCNC's."""
    end = time.monotonic() + wait_s
    while _buffers_held() and time.monotonic() < end:
        time.sleep(0.1)
    for row in _nml_buffers():
        if row[6] == "0":
            subprocess.run(["ipcrm", "-m", row[1]], check=True, capture_output=True)


class Rest(NamedTuple):
    """The joints at rest once, as the test driver wrote it: the program line (1-based) of
    the move that brought them there (0: none yet), the servo periods they held, the joints
    read."""
    line: int
    periods: int
    joints: np.ndarray


def _rests(text: str, width: int) -> list[Rest]:
    """The driver's rests, in the order they came, of ``width`` joint values each."""
    return [Rest(int(w[0]), int(w[1]), np.array([float(v) for v in w[2:2 + width]]))
            for w in (ln.split() for ln in text.splitlines()) if w[0].isdigit()]


def run_linuxcnc(folder, machine, program: str, edit: str, budget_s: float = RUN_BUDGET_S,
                 tables: dict[str, str] | None = None) -> list[Rest]:
    """Run ``program`` on a headless LinuxCNC with the configuration's pins and ``edit`` (a
    further HAL file, as a user loads compgen's edit) and the joint compensation ``tables``
    (file name → text) put in the INI as the edit's header says; every rest of the joints, in
    time order: the five joint positions then the five motor commands (with the tables'
    trims), the nest's tool length taken off Z (G43 adds it to the joint)."""
    assert shutil.which("linuxcnc"), "LinuxCNC is required here (COMPGEN_REQUIRE_LINUXCNC)"
    module, tilt, _ = linuxcnc.trt_module(machine)
    folder.mkdir(exist_ok=True)
    ini = (HERE / "sim.ini.in").read_text().replace("@DRIVER@", str(HERE / "driver.py")).replace(
        "@KINS@", module).replace("@TILT@", tilt.name)
    for joint, file, kind in INI_LINE.findall(edit):
        (folder / file).write_text((tables or {})[file])
        ini = ini.replace(f"[JOINT_{joint}]\n",
                          f"[JOINT_{joint}]\nCOMP_FILE = {file}\nCOMP_FILE_TYPE = {kind}\n")
    (folder / "sim.ini").write_text(ini)
    (folder / "sim.hal").write_text(current_hal(machine))
    (folder / "edit.hal").write_text(edit or "# no edit\n")
    tool = machine.program.tool
    (folder / "sim.tbl").write_text(f"T{tool} P1 Z{machine.probe_length:.6f} ;R-test nest\n")
    (folder / "sim.var").write_text("")
    (folder / "prog.ngc").write_text(program)
    launcher = launch(folder, folder / "sim.ini", {"COMPGEN_NGC": str(folder / "prog.ngc")}, budget_s)
    result = folder / "joints.txt"
    assert result.exists(), (f"LinuxCNC wrote no joints (exit {launcher.returncode})",
                             launcher.stdout[-1500:])
    text = result.read_text()
    assert text.rstrip().endswith("done"), text[-500:]
    stops = re.search(r"(?m)^stops (\d+)$", text)
    assert stops and int(stops[1]) == program.count("\nM0"), ("the program's stops", text[-300:])
    return [r._replace(joints=r.joints - [0, 0, machine.probe_length, 0, 0] * 2) for r in _rests(text, 10)]


def launch(folder: Path, ini: Path, more_env: dict[str, str], budget_s: float = RUN_BUDGET_S,
           screen: bool = False) -> subprocess.CompletedProcess:
    """Start LinuxCNC on ``ini`` as a user does (``linuxcnc INI``) and wait for its display
    (a test driver) to end it; ``screen``: under a virtual X screen, for GUIs a
    configuration loads itself (the trt samples' vismach models)."""
    sockets = Path(tempfile.mkdtemp(prefix="compgen-rtapi-"))
    sockets.chmod(0o777)                  # rtapi_app, no longer root, must create its socket
    env = {**os.environ, **more_env, "COMPGEN_JOINTS": str(folder / "joints.txt"),
           "RTAPI_FIFO_PATH": str(sockets / "rtapi.sock")}
    if os.geteuid() == 0:
        env["RTAPI_UID"] = "65534"        # rtapi_app drops root to this uid
    env.pop("PYTHONPATH", None)
    command = ["linuxcnc", str(ini)]
    if screen:
        assert shutil.which("xvfb-run"), "xvfb-run is required here (Debian's xvfb)"
        command = ["xvfb-run", "-a", *command]
    # one LinuxCNC at a time on a machine (its launcher keeps /tmp/linuxcnc.lock): tests
    # run at once (two pytest processes, xdist) wait here for each other
    with open(Path(tempfile.gettempdir()) / "compgen-linuxcnc-test.lock", "w") as guard:
        fcntl.flock(guard, fcntl.LOCK_EX)
        lock = Path("/tmp/linuxcnc.lock")     # LinuxCNC's own, one path for every run on the machine
        running = _milltasks()
        if running:                         # another LinuxCNC: its launcher would offer to end it
            pytest.fail(f"another LinuxCNC runs on this machine (milltask {running}); the test neither "
                        "waits for it nor ends it: run the test when it has stopped")
        if lock.exists():                   # left by a run that died: the launcher would ask
            lock.unlink()
        _remove_left_buffers()              # likewise, and they would stop the run (above)
        # a terminal as its input: the start script then prints to the pipe what it otherwise
        # writes to temporary files it deletes (``if ! tty -s``)
        terminal, keys = os.openpty()
        launcher = subprocess.Popen(command, cwd=folder, env=env, stdin=keys, stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT, text=True, start_new_session=True)
        os.close(keys)
        late = False
        try:
            stdout, _ = launcher.communicate(timeout=budget_s)
        except subprocess.TimeoutExpired:
            late = True
        finally:
            end_linuxcnc(env["COMPGEN_JOINTS"])
            os.close(terminal)
        if late:                             # what LinuxCNC said until then, to read in the failure
            stdout, _ = launcher.communicate(timeout=30)
            pytest.fail(f"LinuxCNC did not finish within {budget_s} s; it said: {(stdout or '')[-2000:]}")
        launcher.wait(timeout=30)            # reaped: the launcher was one of the run's processes
    shutil.rmtree(sockets, ignore_errors=True)   # a folder a start: 186 were left in /tmp
    return subprocess.CompletedProcess(command, launcher.returncode, stdout or "")


def _at_poses(rests: list[Rest], program: str) -> np.ndarray:
    """Joints at each pose block, read where the machine rested at that pose: for each pose
    in the program's order, of the rests after the last pose's, the one the latest move up to
    the pose's own line brought about (HAL's line of that move, sampled in the servo thread),
    at the angles the pose's line writes (in the module's own turn); the longest if there are
    several. The latest move, not the pose's line alone: the first pose repeats the approach
    onto the ball, which does not move, so its dwell is the approach's rest. The program's
    words, the order and HAL's lines say which rest is the pose's, never compgen's model."""
    out, after, before = [], 0, 0
    numbered = enumerate(program.splitlines(), start=1)
    for line, raw in ((i, ln) for i, ln in numbered if re.search(r"; pose \d+", ln)):
        words = dict(re.findall(r"\b([A-C])(-?[0-9.]+)", raw.split(";")[0]))
        angles = [float(words[a]) for a in sorted(words, key=lambda a: a == "C")]        # tilt, C
        here = [k for k in range(after, len(rests)) if before < rests[k].line <= line
                and np.allclose(rests[k].joints[3:5], angles, rtol=0, atol=1e-6)]
        assert here, (f"LinuxCNC did not rest at line {line}'s angles {angles} after its rest {after}",
                      [(r.line, r.periods, r.joints[3:5]) for r in rests[after:after + 8]])
        after = max(here, key=lambda k: (rests[k].line, rests[k].periods))
        before = line
        out.append(rests[after].joints)
    return np.array(out)


def _every(machine, step=12):
    """K4 at every ``step``-th pose (18° apart: each pose costs a LinuxCNC run a third of a
    second, most of it settling for its dwell)."""
    return generate(machine, ["K4"]).take(np.arange(0, 241, step))


def test_compgens_edit_loaded_into_linuxcnc_removes_what_it_can_hold(machine, tmp_path):
    kins = linuxcnc.trt_module(machine)[0][:5]
    truth = TRUTH[kins]
    full = generate(machine, ["K4", "K1", "K2"])
    rng = np.random.default_rng(11)
    pre = simulate(machine, truth, full, NOISE_UM, rng)
    fit = identify(machine, [pre], [*location_model(machine), *TABLES[kins]])
    current = current_hal(machine)
    files = kinematics_edit(machine, fit, "linuxcnc", current, "sim.hal", "KIN", "0", "d").files
    hal = files[".hal"]
    assert re.search(r"(?m)^sets zrot ", hal) and not re.search(r"(?m)^setp \S+z-rot-point", hal)
    tables = {f"KIN{k}": v for k, v in files.items() if k.endswith(".comp")}
    assert len(INI_LINE.findall(hal)) == len(tables) == 2           # C's table and A's or Y's
    subset = np.arange(0, 241, 12)                     # K4 comes first in ``full``
    poses = full.take(subset)
    emitted = measure_program(machine, poses, "K4", "linuxcnc", "tcpm", "K4", "0", "d")
    program, listed = emitted.files[".ngc"], emitted.files[".poses.csv"]
    joints = run_linuxcnc(tmp_path / "edit", machine, program, hal, tables=tables)
    at = _at_poses(joints, program)
    # the rotary joints at every pose are the pose list's angles (the program's, as written);
    # the linear ones are where the edited pins put the nest on the ball (below)
    np.testing.assert_allclose(at[:, 3:5], np.loadtxt(listed.splitlines()[1:], delimiter=",", usecols=(4, 5)),
                               rtol=0, atol=1e-9)
    q, motor = at[:, :5], at[:, 5:]
    q[:, 3:], motor[:, 3:] = np.radians(q[:, 3:]), np.radians(motor[:, 3:])
    # LinuxCNC drives exactly as compgen's model of that controller says it will: the pins
    # move the joints, the tables' trims (as compgen reads its own files) move the motors
    # (at the angles as the program rounds them)
    held = read_edits(machine, {"KIN.hal": hal, **tables}, current)
    lines = linuxcnc.read_lines(hal, machine, current, nominal_lines(machine))
    np.testing.assert_allclose(q[:, :3], controller_inverse(machine, lines, q[:, 3:], poses.ball)[:, :3],
                               rtol=0, atol=JOINT_MM)
    as_run = Poses(q, poses.ball, poses.t, poses.path)
    np.testing.assert_allclose(motor, held.drive(machine, as_run), rtol=0, atol=JOINT_MM)
    assert np.abs(motor - q).max() > 10 * JOINT_MM          # the trims did move the motors (mm, rad)
    # the true machine, driven to LinuxCNC's motor positions, reads set-up and noise only; the
    # session records the nominal poses, as a real one would
    true = Model(machine, list(truth))
    reading = true.relative(Poses(motor, poses.ball, poses.t, poses.path), np.array(list(truth.values())))
    reading = reading + rng.normal(0, NOISE_UM * 1e-3, reading.shape)
    setup = ["XOW", "YOW", "ZOW"]
    before = identify(machine, [RTestData(poses, pre.deviation[subset])], setup)
    after = identify(machine, [RTestData(poses, reading)], setup)
    print(f"LinuxCNC edit: K4 misfit beyond set-up {before.residual['rms_um']:.3f} -> "
          f"{after.residual['rms_um']:.3f} um")
    assert before.residual["rms_um"] > 10 * NOISE_UM
    assert after.residual["rms_um"] == pytest.approx(NOISE_UM, rel=0.25)


def test_a_run_past_its_budget_is_ended_whole(tmp_path):
    """A program that does not finish in time fails its test with what LinuxCNC said, and
    leaves no LinuxCNC process behind (linuxcncsvr and rtapi_app run in sessions of their own)."""
    machine = load_machine(_as_linuxcnc(tmp_path, SEED_MACHINE))
    with pytest.raises(pytest.fail.Exception, match=r"did not finish within 4 s; it said: (?s:.*)LINUXCNC"):
        run_linuxcnc(tmp_path / "run", machine, "G4 P600\nM2\n", "", budget_s=4)
    assert not _ours(str(tmp_path / "run" / "joints.txt"))


def test_a_run_killed_outright_leaves_no_buffers_to_stop_the_next(tmp_path):
    """A run whose processes all die by SIGKILL (a crash, or a launcher killed during its own
    clean-up) leaves LinuxCNC's NML buffers behind; they are removed, and the next run goes
    through (with them, its IO commands time out and it waits out its budget)."""
    machine = load_machine(_as_linuxcnc(tmp_path, SEED_MACHINE))
    left, end_as_tests_do = [], end_linuxcnc

    def killed_outright(marker, grace_s=10.0):
        end = time.monotonic() + 60                 # linuxcncsvr has made its buffers
        while not _buffers_held() and time.monotonic() < end:
            time.sleep(0.1)
        for pid in _ours(marker):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        while _buffers_held() and time.monotonic() < end:
            time.sleep(0.1)                         # the killed let go of them
        left.extend(r[0] for r in _nml_buffers())
        end_as_tests_do(marker, grace_s)

    with pytest.MonkeyPatch.context() as patched:
        patched.setitem(globals(), "end_linuxcnc", killed_outright)
        with pytest.raises(pytest.fail.Exception, match="did not finish within 4 s"):
            run_linuxcnc(tmp_path / "killed", machine, "G4 P600\nM2\n", "", budget_s=4)
    assert sorted(left) == ["1001", "1002", "1003", "1004", "1005"] and not _nml_buffers()
    rests = run_linuxcnc(tmp_path / "next", machine, "G0 X1 Y2\nG4 P0.2\nM2\n", "", budget_s=120)
    assert any(np.allclose(r.joints[:2], [1, 2]) for r in rests)


# LinuxCNC's own trt sample configurations, as linuxcnc-uspace ships them: their pins are set
# by [HAL] HALCMD lines, which LinuxCNC runs after every HALFILE
SAMPLES = Path("/usr/share/doc/linuxcnc/examples/sample-configs/sim/axis/vismach/5axis/table-rotary-tilting")
# joint positions to read the tables' trims at: a joint's trim applies once it has moved
# (control.c), so the home position comes last; short moves, at the sample's 20 mm/s, 30 deg/s
# (~9 s of motion a start, 19 s with Y at ±60 and C at 200°: the suite has five minutes);
# each table's trims there above the 1e-4 the test asks of them
READ_AT = [[10, -30, 8, -20, 30], [-12, 30, -10, 25, 60], [15, 10, 12, -10, 80], [0, 0, 0, 0, 0]]


def sample_copy(folder: Path, machine, halfile: bool = False) -> Path:
    """LinuxCNC's sample configuration for the machine's trt module, copied to ``folder``
    with the machine file's pins where the sample sets them (as an integrator would) and
    the read-back test display in place of AXIS. The POSTGUI_HALFILE connects AXIS's panel
    only, and goes with it. ``halfile``: the same configuration with its HALCMD lines moved
    into a HAL file loaded as the second HALFILE."""
    module, tilt, c = linuxcnc.trt_module(machine)
    nominal = linuxcnc.nominal_pins(machine, tilt, c)
    kins = module[:5]
    shutil.copytree(SAMPLES, folder)
    for f in folder.rglob("*"):
        f.chmod(0o755 if f.is_dir() else 0o644)          # Debian ships them read-only
    ini = (folder / f"{kins}-trt.ini").read_text()
    ini = re.sub(r"(?m)^(\s*DISPLAY = )axis$", rf"\g<1>{HERE / 'read_back.py'}", ini)
    ini = re.sub(r"(?m)^POSTGUI_HALFILE = .*\n", "", ini)
    for pins in (r"sets\s+:([xyz]-offset)", r"setp \S+\.([xyz]-rot-point)"):
        ini = re.sub(rf"(?m)^(HALCMD = {pins}\s+)\S+$", lambda m: m[1] + f"{nominal[m[2]]:.6f}", ini)
    if halfile:
        commands = re.findall(r"(?m)^HALCMD = (.*)$", ini)
        (folder / "trt.hal").write_text("\n".join(commands) + "\n")
        ini = re.sub(r"(?m)^HALCMD = .*\n", "", ini).replace("HALFILE = LIB:basic_sim.tcl",
                                                             "HALFILE = LIB:basic_sim.tcl\nHALFILE = trt.hal")
    path = folder / f"{kins}-trt.ini"
    path.write_text(ini)
    return path


def read_back(ini: Path, machine) -> dict:
    """What LinuxCNC itself holds once it started ``ini``: the trt pins (halcmd getp) and
    the joints' commands and motor commands at ``READ_AT``."""
    module, tilt, _ = linuxcnc.trt_module(machine)
    pins = ",".join(f"{module}.{n}" for n in linuxcnc.pin_names(tilt))
    done = launch(ini.parent, ini, {"COMPGEN_PINS": pins, "COMPGEN_POSITIONS": json.dumps(READ_AT)},
                  screen=True)
    result = ini.parent / "joints.txt"
    assert result.exists(), f"LinuxCNC wrote nothing (exit {done.returncode}): {done.stdout[-1500:]}"
    got = json.loads(result.read_text())
    assert got.get("done"), (got, done.stdout[-1500:])
    return got


def test_linuxcnc_starts_its_own_sample_with_compgens_configuration_and_holds_it(machine, tmp_path):
    """The edit of LinuxCNC's own shipped trt sample (pins set by HALCMD lines) is the
    configuration to start with; LinuxCNC started with it reports (halcmd getp) the pins
    compgen computes, and the joints' tables trim the motors as compgen's tables say. On
    xyzbc the sample's HALCMD lines are first moved into a HAL file (a second HALFILE), as
    integrators write them: compgen's edit goes there, and LinuxCNC ends in the same pins
    (each start takes some 13 s at the sample's speeds: one start a module)."""
    kins = linuxcnc.trt_module(machine)[0][:5]
    module = linuxcnc.trt_module(machine)[0]
    truth = TRUTH[kins]
    fit = identify(machine, [simulate(machine, truth, generate(machine, ["K4", "K1", "K2"]), NOISE_UM,
                                      np.random.default_rng(5))], [*location_model(machine), *TABLES[kins]])
    alone = kinematics_edit(machine, fit, "linuxcnc", None, "", "H", "0", "d").files   # no configuration
    want = {m[2]: float(m[3]) for m in re.finditer(rf"(?m)^setp ({re.escape(module)})\.(\S+) (\S+)",
                                                    alone[".hal"])}
    for variant, halfile in [("halcmd", False) if kins == "xyzac" else ("halfile", True)]:
        ini = sample_copy(tmp_path / variant, machine, halfile)
        out = kinematics_edit(machine, fit, "linuxcnc", read_state(str(ini)), str(ini), "KIN", "0", "d",
                              stem="KIN", folder=str(ini.parent))
        for suffix, text in out.files.items():
            (ini.parent / f"KIN{suffix}").write_text(text)
        assert ("KIN.trt.hal" in out.files[".ini"]) == halfile
        got = read_back(ini.parent / "KIN.ini", machine)
        pins = {name.split(".", 1)[1]: v for name, v in got["values"].items()}
        assert pins == pytest.approx(want, abs=1e-9), (pins, want)
        shown = {name.split(".", 1)[1]: float(v) for name, v in got["pins"].items()}    # getp: 7 digits
        assert shown == pytest.approx(want, rel=1e-6, abs=1e-9), (shown, want)
        q, motor = (np.array([j[k] for j in got["joints"]]) for k in (0, 1))
        np.testing.assert_allclose(q, READ_AT, atol=1e-9)      # identity kinematics at start (identityfirst)
        for suffix in (k for k in out.files if k.endswith(".comp")):
            table = linuxcnc.read_comp(out.files[suffix], machine, suffix)
            j = linuxcnc.joint_number(machine, table.input)
            expect = np.interp(q[:, j], table.grid, table.values)
            np.testing.assert_allclose(motor[:, j] - q[:, j], expect, atol=1e-7)
            assert np.abs(expect).max() > 1e-4                  # the tables do trim the motors
        print(f"LinuxCNC {kins} sample ({variant}): pins {pins}")


def test_linuxcnc_starts_compgens_configuration_of_a_sample_with_the_start_scripts_corners(tmp_path):
    """The trt sample as a shop keeps it: its HAL lines in two files of one name (b/trt.hal:
    the nets and the offsets' signals; a/trt.hal: the rot points), and an #INCLUDE, so the
    start script copies the INI through bash's read. compgen's configuration to start with
    writes the two files as KIN.trt.hal and KIN.2.trt.hal (one was lost before: both were
    KIN.trt.hal), and LinuxCNC started with KIN.ini holds every pin compgen computes."""
    machine = load_machine(_as_linuxcnc(tmp_path, SEED_MACHINE, "xyzac"))
    module, tilt, c = linuxcnc.trt_module(machine)
    nominal = linuxcnc.nominal_pins(machine, tilt, c)
    ini = sample_copy(tmp_path / "shop", machine, halfile=True)
    lines = (ini.parent / "trt.hal").read_text().splitlines()
    for sub, keep in (("a", lambda ln: "rot-point" in ln), ("b", lambda ln: "rot-point" not in ln)):
        (ini.parent / sub).mkdir()
        (ini.parent / sub / "trt.hal").write_text("".join(ln + "\n" for ln in lines if keep(ln)))
    (ini.parent / "trt.hal").unlink()
    (ini.parent / "extra.inc").write_text("[COMPGEN]\nNOTE = corners\n")
    ini.write_text(ini.read_text().replace("HALFILE = trt.hal", "HALFILE = b/trt.hal\nHALFILE = a/trt.hal")
                   + "#INCLUDE extra.inc\n")
    session = simulate(machine, TRUTH["xyzac"], generate(machine, ["K4", "K1", "K2"]), NOISE_UM,
                       np.random.default_rng(9))
    fit = identify(machine, [session], location_model(machine))
    alone = kinematics_edit(machine, fit, "linuxcnc", None, "", "H", "0", "d").files[".hal"]
    out = kinematics_edit(machine, fit, "linuxcnc", read_state(str(ini)), str(ini), "KIN", "0", "d",
                          stem="KIN", folder=str(ini.parent))
    assert {".ini", ".trt.hal", ".2.trt.hal"} <= set(out.files), sorted(out.files)
    for suffix, text in out.files.items():
        (ini.parent / f"KIN{suffix}").write_text(text)
    setp = rf"(?m)^setp {re.escape(module)}\.(\S+) (\S+)"
    want = {**nominal, **{m[1]: float(m[2]) for m in re.finditer(setp, alone)}}
    got = read_back(ini.parent / "KIN.ini", machine)
    pins = {name.split(".", 1)[1]: v for name, v in got["values"].items()}
    assert set(pins) == set(linuxcnc.pin_names(tilt)) and len(pins) == 5, pins
    assert pins == pytest.approx({n: want[n] for n in pins}, abs=1e-9), (pins, want)
    assert pins != pytest.approx({n: nominal[n] for n in pins}, abs=1e-6)


HEAD_HAL = "\n".join([
    "loadrt [KINS]KINEMATICS",
    "loadrt [EMCMOT]EMCMOT servo_period_nsec=[EMCMOT]SERVO_PERIOD num_joints=[KINS]JOINTS",
    "addf motion-command-handler servo-thread",
    "addf motion-controller servo-thread",
    "{loops}",
    "net estop-loop iocontrol.0.user-enable-out => iocontrol.0.emc-enable-in",
    "net tool-prep-loop iocontrol.0.tool-prepare => iocontrol.0.tool-prepared",
    "net tool-change-loop iocontrol.0.tool-change => iocontrol.0.tool-changed",
    "setp {module}.pivot-length {pivot}", ""])
# each module's joints, as Debian's 2.9 maps them: maxkins X Y Z A B C U V W to joints 0-8
# (joint 3, A, looped back unused); 5axiskins its required X Y Z B C W to 0-5 (W unused by
# compgen): the coordinates the INI names, the joints read
HEAD_JOINTS = {"maxkins": ("XYZBC", "0 1 2 4 5"), "5axiskins": ("XYZBCW", "0 1 2 3 4")}


def _head_configuration(folder: Path, machine, pin: str) -> Path:
    """A configuration of ``machine``'s head module (its INI's path): loop-back joints, the
    pivot-length pin set to ``pin`` in its HAL file, HAL_PIN_VARS as compgen's programs need."""
    name = linuxcnc.head_module(machine)[0].module
    coordinates = HEAD_JOINTS[name][0]
    folder.mkdir()
    ini = (HERE / "sim.ini.in").read_text().replace("@DRIVER@", str(HERE / "driver.py")).replace(
        "@KINS@", name).replace("COORDINATES = XYZ@TILT@C", f"COORDINATES = {coordinates}").replace(
        "@TILT@", "B").replace("JOINTS = 5", "JOINTS = 6")
    ini = ini.replace("[HAL]\nHALFILE = sim.hal\nHALFILE = edit.hal", "[HAL]\nHALFILE = sim.hal").replace(
        "[RS274NGC]\n", "[RS274NGC]\nHAL_PIN_VARS = 1\n")
    ini += "\n" + ini[ini.index("[JOINT_4]"):].replace("[JOINT_4]", "[JOINT_5]")
    if name == "5axiskins":                          # W (joint 5) is linear, with an axis of its own
        ini = ini.replace("[JOINT_5]\nTYPE = ANGULAR", "[JOINT_5]\nTYPE = LINEAR")
        ini += "\n" + ini[ini.index("[AXIS_X]"):ini.index("[AXIS_Y]")].replace("[AXIS_X]", "[AXIS_W]")
    (folder / "sim.ini").write_text(ini)
    loops = "\n".join(f"net j{j} joint.{j}.motor-pos-cmd => joint.{j}.motor-pos-fb" for j in range(6))
    (folder / "sim.hal").write_text(HEAD_HAL.format(loops=loops, module=name, pivot=pin))
    (folder / "sim.tbl").write_text(f"T7 P1 Z0 ;R-test nest, its length in {name}.pivot-length\n")
    (folder / "sim.var").write_text("")
    return folder / "sim.ini"


def _run_head(ini: Path, machine, program: str) -> tuple[list[Rest], list[str]]:
    """Start LinuxCNC with ``ini`` and run ``program``: every rest of the joints (X Y Z, tilt,
    C), in time order, and the operator's messages."""
    folder = ini.parent
    (folder / "prog.ngc").write_text(program)
    read = HEAD_JOINTS[linuxcnc.head_module(machine)[0].module][1]
    launcher = launch(folder, ini, {"COMPGEN_NGC": str(folder / "prog.ngc"), "COMPGEN_READ_JOINTS": read})
    text = (folder / "joints.txt").read_text() if (folder / "joints.txt").exists() else ""
    assert text.rstrip().endswith("done"), (text[-500:], launcher.stdout[-1500:])
    return _rests(text, 5), re.findall(r"(?m)^message (.*)$", text)


# what a head module's pin holds (the B line 30 µm farther from the nest along the tool) and
# the ball's set-up
HEAD_TRUTH = {"XOW": 4 * UM, "YOW": -6 * UM, "ZOW": 9 * UM, "ZOB": 30 * UM}


@pytest.mark.parametrize("source", [None, FORK_MACHINE], ids=["maxkins", "5axiskins"])
def test_a_head_modules_edit_runs_compgens_program_where_compgen_puts_it(tmp_path, source):
    """LinuxCNC's own head modules (Debian's maxkins: a B head over a C table; 5axiskins: a
    C head carrying a B fork; one geometry pin each, pivot-length). A session of the
    reference swivel head or fork with its B line 30 µm off along the tool is fitted, and
    compgen's edit of the configuration (pivot-length at the machine file's 270 mm, the pivot
    to the nest) is started: LinuxCNC holds the pin compgen wrote, and runs compgen's K4
    program, which checks the pin (HAL_PIN_VARS), with its joints where compgen's model of
    the edited control puts the axes — B (and maxkins's C) turned the other way from the
    machine file, as the module turns them. The true machine driven there reads set-up and
    noise only. With the pin 20 mm off (maxkins: one run is enough, the guard is the same
    words), the program stops at its guard before anything moves and says why."""
    machine = load_machine(on_linuxcnc(tmp_path, source))
    module = linuxcnc.head_module(machine)[0]
    name, sense = module.module, dict(module.sense)
    half = np.arange(0, 121, 12)        # K4's first half, 18° apart: B to 60° and C to 180°
    poses = generate(machine, ["K4"]).take(half)
    emitted = measure_program(machine, poses, "K4", "linuxcnc", "tcpm", "HEAD", "0", "d")
    program, listed = emitted.files[".ngc"], emitted.files[".poses.csv"]
    guard = linuxcnc.PIN_GUARD.search(program)
    assert guard[1] == name and float(guard[2]) == pytest.approx(270.0)      # 150 pivot + 120 nest
    if name == "maxkins":
        joints, said = _run_head(_head_configuration(tmp_path / "short", machine, "250.0"), machine, program)
        assert said and "pivot-length is more than 0.1000 mm from 270.0000 mm" in said[-1], said
        assert joints and all(r.line == 0 for r in joints), joints      # no move of the program ran
        assert all(np.allclose(r.joints, 0, atol=1e-9) for r in joints), joints
    rng = np.random.default_rng(7)
    pre = simulate(machine, HEAD_TRUTH, generate(machine, ["K4", "K2"]), NOISE_UM, rng)
    fit = identify(machine, [pre], location_model(machine))
    ini = _head_configuration(tmp_path / "run", machine, guard[2])
    out = kinematics_edit(machine, fit, "linuxcnc", read_state(str(ini)), str(ini), "KIN", "0", "d",
                          stem="KIN", folder=str(ini.parent))
    for suffix, text in out.files.items():
        (ini.parent / f"KIN{suffix}").write_text(text)
    assert sorted(out.files) == [".ini", ".sim.hal", "_RESTORE.ini", "_SIGN.ngc"]   # the pin set where it was
    pin = float(re.search(rf"(?m)^setp {name}\.pivot-length (\S+)", out.files[".sim.hal"])[1])
    assert pin - 270 == pytest.approx(fit.parameters["ZOB"].value, abs=1e-6)
    assert abs(pin - 270 - HEAD_TRUTH["ZOB"]) < 3 * fit.parameters["ZOB"].std
    joints, said = _run_head(ini.parent / "KIN.ini", machine, program)
    assert [m[:13] for m in said] == ["PRESET CHECK:"], said           # the preset stop, nothing else
    got = _at_poses(joints, program)
    # the pose list's angles are the program's (as written, 1e-4 deg); the linear joints are
    # where compgen's model of the edited control puts the axes there
    header = listed.splitlines()[0].split(",")
    rotary = np.loadtxt(listed.splitlines()[1:], delimiter=",", usecols=(4, 5))
    held = linuxcnc.head_lines(machine, pin - 270)
    want = controller_inverse(machine, held, np.radians(rotary), poses.ball)
    np.testing.assert_allclose(got[:, :3], want[:, :3], rtol=0, atol=JOINT_MM)
    columns = [header.index(a) - 4 for a in "BC"]                           # the joints read: B, C
    np.testing.assert_allclose(got[:, 3:], rotary[:, columns] * [sense["B"], sense["C"]], rtol=0, atol=1e-9)
    assert np.abs(got[:, :3] - got[0, :3]).max() > 100       # the head's turn moved the axes by > 100 mm
    # the true machine at LinuxCNC's joints reads set-up and noise only
    q = np.concatenate([got[:, :3], np.radians(rotary)], axis=1)
    q = q[:, [["X", "Y", "Z", *header[4:6]].index(a) for a in machine.axis_names]]
    true = Model(machine, list(HEAD_TRUTH))
    reading = true.relative(Poses(q, poses.ball, poses.t, poses.path), np.array(list(HEAD_TRUTH.values())))
    reading = reading + rng.normal(0, NOISE_UM * 1e-3, reading.shape)
    setup = ["XOW", "YOW", "ZOW"]
    before = identify(machine, [RTestData(poses, pre.deviation[:241][half])], setup)
    after = identify(machine, [RTestData(poses, reading)], setup)
    print(f"{name}: pivot-length 270 -> {pin:.6f} mm; K4 misfit beyond set-up "
          f"{before.residual['rms_um']:.2f} -> {after.residual['rms_um']:.2f} um; joints within "
          f"{np.abs(got[:, :3] - want[:, :3]).max() * 1e3:.2g} um of compgen's model")
    assert before.residual["rms_um"] > 10 * NOISE_UM
    assert after.residual["rms_um"] == pytest.approx(NOISE_UM, rel=0.3)


def test_a_longer_nest_program_runs_under_maxkins_with_the_pin_it_asks_for(tmp_path):
    """The program diagnose advises to tell a head's sag from its angle (K4 with the nest
    100 mm longer, here its first half) asks maxkins's pivot-length for the pivot to the
    longer nest (370 mm): under the real module with that pin it runs through, and LinuxCNC
    puts the joints where compgen's model of the machine with that nest puts the axes; the
    nominal machine there with the longer nest reads zero. With the pin left at the first
    session's 270 mm the program stops at its guard, saying so, before anything moves."""
    machine = load_machine(on_linuxcnc(tmp_path))
    poses = generate(machine, ["K4"], nest=220.0).take(np.arange(0, 121, 12))
    emitted = measure_program(machine, poses, "K4", "linuxcnc", "tcpm", "NEST", "0", "d")
    program = emitted.files[".ngc"]
    guard = linuxcnc.PIN_GUARD.search(program)
    assert guard[1] == "maxkins" and float(guard[2]) == pytest.approx(370.0)      # 150 pivot + 220 nest
    joints, said = _run_head(_head_configuration(tmp_path / "first", machine, "270.0"), machine, program)
    assert said and "pivot-length is more than 0.1000 mm from 370.0000 mm" in said[-1], said
    assert joints and all(r.line == 0 for r in joints), joints          # no move of the program ran
    assert all(np.allclose(r.joints, 0, atol=1e-9) for r in joints), joints
    joints, said = _run_head(_head_configuration(tmp_path / "longer", machine, guard[2]), machine, program)
    assert [m[:13] for m in said] == ["PRESET CHECK:"], said
    got = _at_poses(joints, program)
    listed = emitted.files[".poses.csv"].splitlines()
    assert listed[0].split(",")[9] == "probe_length"
    assert {r.split(",")[9] for r in listed[1:]} == {"220.000000"}
    rotary = np.loadtxt(listed[1:], delimiter=",", usecols=(4, 5))          # C, B as written
    want = inverse(at_nest(machine, 220.0), np.radians(rotary), poses.ball)
    np.testing.assert_allclose(got[:, :3], want[:, :3], rtol=0, atol=JOINT_MM)
    q = np.concatenate([got[:, :3], np.radians(rotary)], axis=1)
    at = Poses(q, poses.ball, poses.t, poses.path, nest=poses.nest)
    assert np.abs(Model(machine, []).relative(at, np.zeros(0))).max() < 1e-5


def test_a_5axiskins_program_stops_on_w_or_a_work_offset_left_set(tmp_path):
    """What a shop leaves on the real LinuxCNC (5axiskins: a fork head on a bridge mill with
    W, which the module adds to its pivot): W jogged to -5 (here by the line before the
    program) and, in the parameter file, G54 touched off on the table centre. The program
    stops at its guard before any move of its own, and the operator's message says what is
    set (rs274 alone cannot show W: it has no W axis)."""
    machine = load_machine(on_linuxcnc(tmp_path, FORK_MACHINE))
    poses = generate(machine, ["K4"]).take(np.arange(0, 121, 12))
    program = measure_program(machine, poses, "K4", "linuxcnc", "tcpm", "HEAD", "0", "d").files[".ngc"]
    ini = _head_configuration(tmp_path / "w", machine, "270.0")
    joints, said = _run_head(ini, machine, "G0 W-5\n" + program)
    assert said and "W stands at W-5.000000 mm" in said[-1], said
    assert joints and all(r.line <= 1 for r in joints), joints                # no move of the program ran
    (ini.parent / "sim.var").write_text("5221\t100.0\n5222\t50.0\n")
    joints, said = _run_head(ini, machine, program)
    assert said and "G54 holds X100.000000 Y50.000000" in said[-1], said
    assert joints and all(r.line == 0 for r in joints), joints
