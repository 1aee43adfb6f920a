"""The benchmark scripts stay runnable as the project moves (a test folder moved under them
once broke the fuzzer's import of the tests' LinuxCNC sample): each prints its help, and
every test module a script imports is found where the script looks for it."""

import re
import subprocess
import sys

import pytest
from conftest import ROOT

SCRIPTS = sorted((ROOT / "benchmarks").glob("*.py"))


@pytest.mark.parametrize("script", SCRIPTS, ids=[s.stem for s in SCRIPTS])
def test_a_benchmark_prints_its_help(script):
    done = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)
    assert done.returncode == 0 and "usage" in done.stdout.lower(), done.stderr[-500:]


def test_every_test_module_a_benchmark_imports_exists():
    for script in SCRIPTS:
        for name in re.findall(r"(?m)^\s*(?:from|import) (test_\w+)", script.read_text()):
            assert list(ROOT.glob(f"tests/*/{name}.py")), (script.name, name)
