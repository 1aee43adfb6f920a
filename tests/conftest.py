import os
import re
import subprocess
import sys
from pathlib import Path

from compgen.__main__ import BLAS_THREADS

# the in-process commands run as the real ones do: one BLAS thread, set before numpy loads
os.environ.update(dict.fromkeys(BLAS_THREADS, "1"))

import numpy as np  # noqa: E402
import pytest
from click.testing import CliRunner

from compgen.commands.cli import main
from compgen.configuration.machine_file import load_machine

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("COMPGEN_SHARED", ROOT.parent / "shared"))
VECTORS = SHARED / "vectors"
SEED_MACHINE = ROOT / "machines" / "ac-trunnion-itnc530.toml"
BC_MACHINE = ROOT / "machines" / "bc-table-sinumerik840d.toml"
HEAD_MACHINE = ROOT / "machines" / "bc-swivel-head-table.toml"
FORK_MACHINE = ROOT / "machines" / "bc-fork-head.toml"
NUTATING_MACHINE = ROOT / "machines" / "bc-nutating-head-table.toml"
UM, ARCSEC = 1e-3, np.pi / 648000

# Seed report, Table 4 (the truth in shared/vectors/seed-table4-noiseless.csv), inside units
TABLE4 = {"XOW": -3.2 * UM, "YOW": -21.6 * UM, "ZOW": -33.9 * UM, "YOA": 20.5 * UM,
          "ZOA": 32.5 * UM, "BOA": 12.3 * ARCSEC, "COA": -7.2 * ARCSEC, "XOC": 1.4 * UM,
          "YOC": -15.9 * UM, "AOC": -6.5 * ARCSEC, "BOC": -4.6 * ARCSEC}


# an OEM's table: nominal rows plus KinematicsOpt-style rows already named by ISO symbol
OEM_TAB = """BEGIN KINEMATIC_AC.TAB MM
NR  KEY       AXIS  COORD        DOC
0   Trans     Z     +0           spindle gauge line
1   MachAxis  Z
2   MachAxis  Y
3   MachBase
4   MachAxis  X
5   Trans     Z     +0           to the A/C intersection
6   Trans     Y     +0.00310     Y0A
7   Trans     B     +0.0012000   B0A
8   MachAxis  A
9   Trans     B     -0.0012000   -B0A
10  Trans     Y     -0.00310     -Y0A
11  Trans     Z     +29.794      Zc: C table origin
12  MachAxis  C
[END]
"""

GOLDEN = ROOT / "tests" / "golden"


def pytest_addoption(parser):
    parser.addoption("--update-golden", action="store_true",
                     help="rewrite tests/golden/ from the current output; review with git diff")


@pytest.fixture
def golden(request):
    """Compare text with tests/golden/<name> byte for byte (line endings count)."""
    def check(name: str, text: str) -> None:
        path = GOLDEN / name
        if request.config.getoption("--update-golden"):
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(text.encode("ascii"))
        assert path.exists(), f"no golden file {path}: run pytest --update-golden and review"
        assert text.encode("ascii") == path.read_bytes(), f"{name} differs from its golden file"
    return check


@pytest.fixture(scope="session")
def seed_machine():
    return load_machine(SEED_MACHINE)


@pytest.fixture(scope="session")
def bc_machine():
    return load_machine(BC_MACHINE)


@pytest.fixture(scope="session")
def head_machine():
    return load_machine(HEAD_MACHINE)


def on_linuxcnc(folder: Path, source: Path = None) -> Path:
    """A reference head (the swivel head by default: maxkins; the fork head: 5axiskins) on
    LinuxCNC, with a quick [program] (the file's path, written in ``folder``)."""
    source = source or HEAD_MACHINE
    path = folder / f"linuxcnc-{source.stem}.toml"
    text = re.sub(r"feed_max = [0-9.]+", "feed_max = 60000.0", source.read_text())  # the sim's axes
    text = re.sub(r"(?ms)^\[program\].*?\n\n", "", text)        # the bundled one: HEIDENHAIN's tool
    path.write_text(text.replace('controller = "tnc640"', 'controller = "linuxcnc"')
                    .replace("[limits]", '[program]\ntool = "7"\nfeed = 8000.0\ndwell = 0.1\n'
                             'clearance = 20.0\n\n[linuxcnc]\nconventional_directions = false\n'
                             'version = "2.9"\n\n[limits]')
                    .replace("max_step_deg = 10.0", "max_step_deg = 20.0"))
    return path


def measured_under(machine, truth: dict, lines: dict, poses, rng, noise_um: float, squareness=None):
    """An R-test session of the machine whose truth is ``truth`` (name -> inside units), its
    control holding the axis ``lines`` (and ``squareness``): the axes where that control drives
    them under TCPM, read by the true machine, with ``noise_um`` of white noise."""
    from compgen.data.rtest import RTestData
    from compgen.model.kinematics import Model
    from compgen.model.lines import controller_inverse
    from compgen.model.poses import Poses
    rot = poses.q[:, [machine.index(a.name) for a in machine.rotary_axes]]
    q = controller_inverse(machine, lines, rot, poses.ball, squareness)
    reading = Model(machine, list(truth)).relative(Poses(q, poses.ball, poses.t, poses.path),
                                                    np.array(list(truth.values())))
    return RTestData(poses, reading + rng.normal(0, noise_um * 1e-3, reading.shape))


@pytest.fixture
def rng():
    return np.random.default_rng(20261124)


def run(*args):
    """Invoke the CLI in-process: (exit code, stdout, stderr)."""
    result = CliRunner().invoke(main, [str(a) for a in args])
    return result.exit_code, result.stdout, result.stderr


def pasted(line: str, cwd, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """``line`` pasted into bash in ``cwd``, as a user pastes what compgen printed. By default
    this venv's bin first on PATH: a user who installed compgen has it there."""
    if env is None:
        env = {**os.environ, "PATH": os.path.dirname(sys.executable) + os.pathsep + os.environ["PATH"]}
    return subprocess.run(["bash", "-c", line], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)


def rs274(folder: Path, program: str, tool: str, coordinates: str = "XYZAC", params: dict | None = None):
    """LinuxCNC's stand-alone interpreter on ``folder/program`` with the one-line tool table
    ``tool``: its canonical calls (canon.txt) and the finished run. Its own HOME: rs274
    re-creates $HOME/.tool.mmap, the tool table a running LinuxCNC reads from, and emptied it
    under the LinuxCNC test running beside it ("Requested tool 7 not found in the tool table").
    ``params``: the parameter file's values (number -> value), as a shop left them (the
    persistent work offsets: G92 #5211-, G54 #5221-)."""
    import shutil
    import subprocess
    if shutil.which("rs274") is None:
        if os.environ.get("COMPGEN_REQUIRE_LINUXCNC"):
            pytest.fail("rs274 (LinuxCNC's interpreter) is required here")
        pytest.skip("rs274 is not installed (apt-get install linuxcnc-uspace)")
    (folder / "t.tbl").write_text(tool + "\n")
    (folder / "v.var").write_text("".join(f"{n}\t{v}\n" for n, v in sorted((params or {}).items())))
    (folder / "rs.ini").write_text("[RS274NGC]\nPARAMETER_FILE = v.var\n[TRAJ]\nLINEAR_UNITS = mm\n"
                                   f"ANGULAR_UNITS = degree\nCOORDINATES = {coordinates}\n")
    done = subprocess.run(["rs274", "-i", "rs.ini", "-t", "t.tbl", "-v", "v.var", "-g", program,
                           "canon.txt"], cwd=folder, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "HOME": str(folder)})
    canon = folder / "canon.txt"
    return (canon.read_text() if canon.exists() else ""), done


def vector(name: str) -> Path:
    """A shared test vector; CI sets COMPGEN_REQUIRE_SHARED so a missing one fails there."""
    path = VECTORS / name
    if not path.exists():
        if os.environ.get("COMPGEN_REQUIRE_SHARED"):
            pytest.fail(f"shared vector {path} is missing")
        pytest.skip(f"shared vectors not found at {VECTORS}")
    return path


@pytest.fixture(scope="session")
def postgres():
    """A real PostgreSQL server for the history tests: ``initdb`` in a temporary folder, a
    loopback port, trust authentication for the local owner role, stopped at the end. CI
    sets COMPGEN_REQUIRE_POSTGRES: there it must start (Debian's postgresql package)."""
    import glob
    import pwd
    import shutil
    import socket
    import subprocess
    import tempfile

    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"), key=lambda p: int(p.split("/")[4]))
    initdb = found[-1] if found else shutil.which("initdb")
    try:
        import psycopg  # noqa: F401
    except ImportError:
        initdb = None
    if not initdb:
        if os.environ.get("COMPGEN_REQUIRE_POSTGRES"):
            pytest.fail("PostgreSQL (initdb) or psycopg is missing: install Debian's postgresql")
        pytest.skip("PostgreSQL (initdb) or psycopg not installed here")
    bin_dir = Path(initdb).resolve().parent
    folder = Path(tempfile.mkdtemp(prefix="compgen-pg-"))
    as_user = []
    if os.geteuid() == 0:              # the server refuses to run as root
        user = pwd.getpwnam("postgres")
        os.chown(folder, user.pw_uid, user.pw_gid)
        as_user = ["runuser", "-u", "postgres", "--"]
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    data = folder / "data"
    ctl = [*as_user, str(bin_dir / "pg_ctl"), "-D", str(data)]
    try:
        subprocess.run([*as_user, str(bin_dir / "initdb"), "-D", str(data), "-U", "compgen_owner",
                        "-A", "trust",
                        "-E", "UTF8", "--no-sync"], check=True, capture_output=True, timeout=120)
        subprocess.run([*ctl, "-l", str(folder / "log"), "-w", "-t", "60", "-o",
                        f"-p {port} -c listen_addresses=127.0.0.1 -k {folder} -c fsync=off", "start"],
                       check=True, capture_output=True, timeout=90)
    except (subprocess.CalledProcessError, subprocess.TimeoutExpired) as exc:
        log = (folder / "log").read_text() if (folder / "log").exists() else ""
        message = f"PostgreSQL did not start: {exc} {getattr(exc, 'stderr', b'')!r} {log[-500:]}"
        if os.environ.get("COMPGEN_REQUIRE_POSTGRES"):
            pytest.fail(message)
        pytest.skip(message)
    try:
        yield f"postgresql://compgen_owner@127.0.0.1:{port}"
    finally:
        subprocess.run([*ctl, "-m", "immediate", "stop"], capture_output=True, timeout=60)
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def pg_db(postgres, request):
    """A fresh database on the test server for one test: its owner's URL."""
    import re

    import psycopg
    name = "t_" + re.sub(r"\W", "_", request.node.name.lower())[:50]
    with psycopg.connect(f"{postgres}/postgres", autocommit=True) as db:
        db.execute(f"DROP DATABASE IF EXISTS {name}")
        db.execute(f"CREATE DATABASE {name}")
    return f"{postgres}/{name}"


def hidden_2_per_rev_is_found(machine, truth: dict, poses, noise_um: float) -> None:
    """C's radial motion at 2/rev hidden beside ``truth`` (3 and −2 µm): diagnose names it
    found; added, the fit reaches the noise with every location error within 4 σ of the truth."""
    from compgen.data.simulate import simulate
    from compgen.model.effects import compose, location_model
    from compgen.planning.advice import Advisor
    from compgen.statistics.diagnose import diagnose
    from compgen.statistics.identify import identify

    hidden = {**truth, "EXC:h2c": 3 * UM, "EXC:h2s": -2 * UM}
    data = [simulate(machine, hidden, poses, noise_um, np.random.default_rng(2))]
    found = diagnose(machine, data, identify(machine, data), noise_um=noise_um, advisor=Advisor)
    assert found.found == "EXC:h2", ([c.effect for c in found.significant[:3]], found.rivals)
    fit = identify(machine, data, compose(machine, location_model(machine), ["EXC:h2"]))
    assert abs(fit.residual["sigma_um"] / noise_um - 1) < 0.1, fit.residual["sigma_um"]
    off = {n: abs(fit.parameters[n].value - v) / fit.parameters[n].std for n, v in truth.items()}
    assert max(off.values()) < 4, off


def carr_record(v1, v2) -> str:
    """A $TC_CARR record 1 as the control holds it: fine offsets 0, the axis vectors v1, v2."""
    fine = [41, 42, 43, 44, 45, 46, 55, 56, 57, 58, 59, 60]
    return "\n".join([*(f"$TC_CARR{n}[1]={x}" for n, x in zip(range(7, 13), [*v1, *v2], strict=True)),
                      *(f"$TC_CARR{n}[1]=0" for n in fine)]) + "\n"


def carr_edit_is(machine, fit, held, fine: dict, v1, v2, folder: Path) -> str:
    """The SINUMERIK edit of ``fit`` from the record ``held`` (v1, v2 as the control holds
    them) writes exactly the fine offsets ``fine`` (vector name → mm) and the vectors v1, v2
    (5 decimals of a mm, 10 of a vector), reads back as the fitted lines, and its sign check
    passes check-program. Returns the edit's main file."""
    import re

    from compgen.controllers.correction import plan
    from compgen.controllers.kinematics import kinematics_edit
    from compgen.controllers.registry import read_edits

    out = kinematics_edit(machine, fit, "sinumerik840d", carr_record(*held), "current", "KIN", "0", "d")
    got = {int(m[1]): float(m[2]) for m in re.finditer(r"(?m)^\$TC_CARR(\d+)\[1\]=(\S+)$", out.files[".MPF"])}
    index = {"l1": (41, 42, 43), "l2": (44, 45, 46), "l3": (55, 56, 57), "l4": (58, 59, 60)}
    want = {n: float(v[k]) for vec, v in fine.items() for k, n in enumerate(index[vec])}
    want |= {n: x for n, x in zip(range(7, 13), [*v1, *v2], strict=True)}
    assert set(got) == set(want), sorted(set(got) ^ set(want))
    for n in want:
        assert abs(got[n] - want[n]) <= (6e-6 if n > 12 else 1e-9), (n, got[n], want[n])
    (folder / "KIN_SIGN.MPF").write_text(out.files["_SIGN.MPF"])
    code, _, err = run("check-program", "--machine", machine.source, folder / "KIN_SIGN.MPF")
    assert code == 0, err
    now = read_edits(machine, {"KIN.MPF": out.files[".MPF"]}, carr_record(*held))
    fitted = plan(machine, fit).lines
    for a in machine.rotary_axes:
        np.testing.assert_allclose(now.lines[a.name].offset, fitted[a.name].offset, atol=6e-6)
        np.testing.assert_allclose(now.lines[a.name].tilt, fitted[a.name].tilt, atol=1e-9)
    return out.files[".MPF"], out.files["_SIGN.MPF"]


def fitted_at_the_bound(machine, truth: dict, poses, deviation, noise_um: float, seed: int) -> None:
    """Location errors only, white noise: each estimate within 5 σ of the truth, σ the bound
    that ``deviation`` (poses, values → (n, 3) mm, the geometry written out by hand) gives
    by central differences, and the fit's own σ that bound to 2 % (its σ̂ for the noise)."""
    from compgen.data.simulate import simulate
    from compgen.model.effects import location_model
    from compgen.statistics.identify import identify

    names = list(location_model(machine))
    fit = identify(machine, [simulate(machine, truth, poses, noise_um, np.random.default_rng(seed))], names)
    h = 1e-6
    J = np.column_stack([(deviation(poses, {**truth, n: truth[n] + h})
                          - deviation(poses, {**truth, n: truth[n] - h})).ravel() / (2 * h) for n in names])
    bound = noise_um * UM * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    sigma_hat = fit.residual["sigma_um"] / noise_um
    for n, b in zip(names, bound, strict=True):
        e = fit.parameters[n]
        assert abs(e.value - truth[n]) < 5 * b, (n, e.value, truth[n], b)
        assert abs(e.std / (b * sigma_hat) - 1) < 0.02, (n, e.std, b)
