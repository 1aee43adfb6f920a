"""Start-up and effort: what the CLI imports before it does anything, how many model
evaluations a fit costs, and the BLAS threads a command runs with. The figures (CPU against
`import numpy`, memory) are in benchmarks/startup.py; these are the mechanisms behind them."""

import subprocess
import sys

import numpy as np
import threadpoolctl
from conftest import ROOT, SEED_MACHINE, run

import compgen.cli
import compgen.kinematics as kinematics
from compgen.identify import identify
from compgen.rtest import read_rtest

SESSION = ROOT / "examples" / "seed-session.csv"
HEAVY = ("scipy", "jinja2", "matplotlib")   # each only in the commands that use it


def _imported_by(statement: str) -> list[str]:
    code = f"import sys; {statement}; print(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.split()


def test_the_cli_and_the_fit_import_nothing_heavy():
    assert _imported_by("import compgen.cli") == []
    assert _imported_by("import compgen.diagnose, compgen.compare, compgen.report") == []


def _evaluations(monkeypatch, machine, method):
    calls = []
    original = kinematics.Model.relative
    monkeypatch.setattr(kinematics.Model, "relative",
                        lambda self, *a, **k: calls.append(1) or original(self, *a, **k))
    result = identify(machine, [read_rtest(SESSION, machine)], method=method)
    return len(calls), len(result.free)


def test_an_exact_fit_computes_two_jacobians(monkeypatch, seed_machine):
    """One at the start (first order, identifiability), one at the solution (covariance);
    between them one evaluation an iteration. Three or more Jacobians fail this."""
    n, p = _evaluations(monkeypatch, seed_machine, "exact")
    assert 2 * (2 * p) < n <= 2 * (2 * p) + 12, n
    n, p = _evaluations(monkeypatch, seed_machine, "linear")
    assert 2 * p < n <= 2 * p + 4, n   # one Jacobian, at the first-order point


def test_commands_run_with_one_blas_thread(monkeypatch, tmp_path):
    seen = []

    def spy(*args, **kwargs):
        seen.extend(i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas")
        return identify(*args, **kwargs)

    monkeypatch.setattr(compgen.cli, "identify", spy)
    code, _, err = run("fit", "--machine", SEED_MACHINE, SESSION, "-o", tmp_path / "fit.json")
    assert code == 0, err
    assert seen and set(seen) == {1}, seen


def test_the_p_value_is_the_f_distributions_tail():
    from scipy import stats

    from compgen.significance import p_value as _p_value
    for drop, k, rss, dof in [(3.0, 1, 700.0, 2158), (40.0, 2, 500.0, 2158), (1e-3, 2, 5.0, 100)]:
        F = (drop / k) / ((rss - drop) / (dof - k))
        want = min(1.0, stats.f.sf(F, k, dof - k) * 86)
        np.testing.assert_allclose(_p_value(drop, k, rss, dof, 86), want, rtol=1e-12)
