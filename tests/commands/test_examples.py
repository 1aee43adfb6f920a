"""The examples run as documented, and the bundled data are what their scripts make."""

import os
import subprocess
import sys

from conftest import ROOT


def _run(script, *args):
    env = {**os.environ, "PY": sys.executable}
    return subprocess.run(["bash", str(ROOT / "examples" / script), *map(str, args)], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=300)


def test_bundled_session_is_what_its_script_makes(tmp_path):
    out = tmp_path / "session.csv"
    done = _run("make-seed-session.sh", out)
    assert done.returncode == 0, done.stderr
    assert out.read_bytes() == (ROOT / "examples" / "seed-session.csv").read_bytes()


def test_discovery_example_finds_the_hidden_effect_and_reaches_the_noise(tmp_path):
    done = _run("discover.sh", tmp_path / "work")
    assert done.returncode == 0, done.stderr
    assert "1. EXC:h2" in done.stdout                           # the hidden effect, named first
    assert "residual RMS 0.770 µm" in done.stdout               # before: 11 parameters
    assert "residual RMS 0.501 µm" in done.stdout               # after: at the 0.5 µm noise
    assert "explains these data to the R-test's noise (0.5 µm)" in done.stdout   # tested against it


def test_probe_example_runs_from_program_to_edit(tmp_path):
    done = _run("probe.sh", tmp_path / "work")
    assert done.returncode == 0, done.stderr
    assert "PROBE.H: OK (HEIDENHAIN iTNC 530)" in done.stdout                   # the program, checked
    assert "36 poses by touch probe (K4 12, K1 12, K2 12)" in done.stdout        # the log, fitted
    assert "1. EXC:h2" in done.stdout                                           # the hidden effect first
    assert (tmp_path / "work" / "KIN.TAB").exists()                             # the edit written
