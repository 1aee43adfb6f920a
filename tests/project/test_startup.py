"""Start-up and effort: what the CLI imports before it does anything, how many model
evaluations a fit costs, and the BLAS threads a command runs with. The figures (CPU against
`import numpy`, memory) are in benchmarks/startup.py; these are the mechanisms behind them."""

import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, SEED_MACHINE, run

import compgen.model.kinematics as kinematics
from compgen.data.rtest import read_rtest
from compgen.statistics.identify import identify

SESSION = ROOT / "examples" / "seed-session.csv"
HEAVY = ("scipy", "jinja2", "matplotlib",       # each only in the commands that use it
         "psycopg", "compgen.history.store", "compgen.history")


def _imported_by(statement: str) -> list[str]:
    code = f"import sys; {statement}; print(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.split()


def test_the_cli_and_the_fit_import_nothing_heavy():
    assert _imported_by("import compgen.commands.cli") == []
    assert _imported_by("import compgen.statistics.diagnose, compgen.reports.compare, "
                        "compgen.reports.report") == []


def test_diagnose_needs_no_scipy(tmp_path):
    """The F and χ² tails are compgen's own: a whole diagnose imports no scipy (its import
    alone cost diagnose more start-up than numpy's)."""
    fit = tmp_path / "fit.json"
    assert run("fit", "--machine", SEED_MACHINE, SESSION, "-o", fit)[0] == 0
    code = ("import sys; from compgen.commands.cli import main\n"
            "try:\n    main(['diagnose', '--from', sys.argv[1], '--json'])\nexcept SystemExit:\n    pass\n"
            "sys.stderr.write('\\nscipy: ' + ' '.join(m for m in sys.modules if m.split('.')[0] == 'scipy'))")
    out = subprocess.run([sys.executable, "-c", code, str(fit)], capture_output=True, text=True)
    assert '"found"' in out.stdout and out.stderr.splitlines()[-1] == "scipy: ", out.stderr[-500:]


def _walks(monkeypatch, machine, method):
    calls, data = [], read_rtest(SESSION, machine)
    original = kinematics._walk
    monkeypatch.setattr(kinematics, "_walk", lambda *a, **k: calls.append(1) or original(*a, **k))
    result = identify(machine, [data], method=method)
    return len(calls), result.iterations


def test_a_fit_walks_the_chains_once_a_step(monkeypatch, seed_machine):
    """The exact residual and the analytic Jacobian come from one walk of the chains (723
    poses: one block): the start, the first-order point, one walk per Gauss–Newton step —
    no finite differences (2p walks a Jacobian), no separate residual evaluations, and the
    nominal readings are those reading the session computed to check it."""
    n, iterations = _walks(monkeypatch, seed_machine, "exact")
    assert iterations >= 1 and n == 2 + iterations, (n, iterations)
    n, iterations = _walks(monkeypatch, seed_machine, "linear")
    assert iterations == 0 and n == 2, n


BLAS_SEEN = """
import sys
import threadpoolctl
assert "numpy" not in sys.modules
sys.argv = ["compgen", "fit", "--machine", sys.argv[1], sys.argv[2], "-o", sys.argv[3]]
from compgen.__main__ import main
try:
    main()
except SystemExit as exc:
    assert not exc.code, exc.code
print(sorted({i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"}))
"""


@pytest.mark.parametrize("asked", [None, "2"])
def test_commands_run_with_one_blas_thread(tmp_path, asked):
    """The commands' entry (``python -m compgen``, the console scripts) holds BLAS to one
    thread before numpy loads, whatever the environment asks for: numpy's own BLAS, seen
    from inside a real fit's process."""
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    if asked:
        env["OPENBLAS_NUM_THREADS"] = env["OMP_NUM_THREADS"] = asked
    out = subprocess.run([sys.executable, "-c", BLAS_SEEN, str(SEED_MACHINE), str(SESSION),
                          str(tmp_path / "fit.json")], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines()[-1] == "[1]", out.stderr
    assert (tmp_path / "fit.json").exists()


def test_the_p_value_is_the_f_distributions_tail():
    from scipy import stats

    from compgen.statistics.significance import p_value as _p_value
    for drop, k, rss, dof in [(3.0, 1, 700.0, 2158), (40.0, 2, 500.0, 2158), (1e-3, 2, 5.0, 100)]:
        F = (drop / k) / ((rss - drop) / (dof - k))
        want = min(1.0, stats.f.sf(F, k, dof - k) * 86)
        np.testing.assert_allclose(_p_value(drop, k, rss, dof, 86), want, rtol=1e-12)


def test_the_distributions_diagnose_uses_are_scipys():
    """compgen's F and χ² tails (standard library arithmetic, no scipy at run time) against
    scipy's, from p near 1 to the smallest doubles, for the sizes diagnose meets."""
    from scipy import special, stats

    from compgen.statistics.significance import chi2_isf, chi2_sf, f_sf
    for k in (1, 2, 3, 4, 6, 9):
        for m in (3, 10, 50, 300, 2158, 20000, 200000):
            for F in (0.0, 1e-20, 1e-3, 0.3, 1.0, 2.0, 5.0, 20.0, 100.0, 1e3, 1e5):   # 1e-20: x rounds to 1
                want = float(special.fdtrc(k, m, F))
                if want > 1e-290:
                    assert f_sf(F, k, m) == pytest.approx(want, rel=1e-8, abs=0), (k, m, F)
                else:
                    assert f_sf(F, k, m) < 1e-280
        for x in (-1.0, 0.0, 0.01, 0.5, 1.0, 3.0, 10.0, 40.0, 200.0, 1000.0):   # ≤ 0: a residual of 0
            assert chi2_sf(x, k) == pytest.approx(stats.chi2.sf(x, k), rel=1e-12, abs=1e-300)
        for alpha in (0.5, 0.01, 1e-6):
            assert chi2_isf(alpha, k) == pytest.approx(stats.chi2.isf(alpha, k), rel=1e-10)
    for k in (100, 1001, 5000, 20000):              # the lack-of-fit test's sizes
        for x in (0.8 * k, k, 1.2 * k, 3 * k):
            assert chi2_sf(x, k) == pytest.approx(stats.chi2.sf(x, k), rel=1e-9, abs=1e-300)
