"""Mutation testing of the sign-critical modules and the wings: does the suite notice a
wrong sign, unit or axis index? A benchmark, run outside CI (it takes minutes).

    python benchmarks/mutation.py [--jobs 2] [--only compgen/units.py] [--lines 140-150] [--list]
    python benchmarks/mutation.py --draw 100 [--seed S]     # a fresh random sample of all of them

Each mutant is one small change (the issue's kinds): ``+`` ↔ ``-``, ``*`` ↔ ``/``, a unary
minus dropped or added, an integer index 0/1/2 shifted, a numeric constant changed (0 → 1,
1 → 0, x → 2x). A mutant is *killed* when the module's tests fail with it. The module's
tests are a fixed selection (``TESTS``), so a run stays in minutes. Survivors are printed
with their line; ``benchmarks/mutation-survivors.md`` says why each cannot change an output.

A mutant that passes its selection runs the rest of the suite (LinuxCNC's real runs aside;
``--selection-only`` skips that), and a run starts with the unmutated tree passing the same
steps in every copy at once: a test failing there would count every mutant as killed.
"""

from __future__ import annotations

import argparse
import ast
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EDITS = ["test_kinematics_edit.py", "test_compose.py", "test_signs.py"]
PROGRAMS = ["test_motion.py", "test_programs.py"]     # the controllers' program readers
HOSTILE = [*PROGRAMS, "test_hostile_programs.py"]            # what check-program must refuse
STATS = ["test_diagnose_stats.py", "test_startup.py", "test_shapes.py",
         "test_diagnose.py"]
TESTS = {
    "compgen/model/lines.py": ["test_lines.py", *EDITS],
    "compgen/statistics/identify.py": ["test_identify.py", "test_startup.py",
                                       "test_probe.py"],        # two devices' variance components
    "compgen/model/kinematics.py": ["test_kinematics.py", "test_effects.py",
                                    "test_identify.py"],
    "compgen/model/poses.py": ["test_kinematics.py", "test_noise.py", "test_identify.py"],
    # the reversal sides: the start sides' constants are fitted by identify and diagnose
    "compgen/model/sides.py": ["test_kinematics.py", "test_identify.py", "test_diagnose.py",
                               "test_programs.py"],
    "compgen/units.py": ["test_units.py", "test_edge.py"],
    "compgen/controllers/correction.py": [*EDITS, "test_edge.py"],
    "compgen/controllers/heidenhain.py": [*EDITS, "test_tab.py", "test_edge.py", *PROGRAMS,
                                          "test_probe_programs.py"],
    "compgen/controllers/tab.py": ["test_tab.py", "test_kinematics_edit.py"],
    # each control's probing programs, second rounds and configuration are its writer's too
    **{f"compgen/controllers/sinumerik/{m}.py": [*EDITS, "test_edge.py", *PROGRAMS,
                                                  "test_probe_programs.py",
                                                  "test_table_rounds.py"]
       for m in ("controller", "carr", "cec", "reader")},
    # a head module's senses are seen only by LinuxCNC itself running compgen's program
    **{f"compgen/controllers/linuxcnc/{m}.py": [*EDITS, "test_edge.py", *PROGRAMS,
                                                 "test_probe_programs.py", "test_table_rounds.py",
                                                 "test_linuxcnc_config.py",
                                                 "test_linuxcnc.py::test_a_head_modules_edit_runs_"
                                                 "compgens_program_where_compgen_puts_it"]
       for m in ("controller", "heads", "pins", "reader", "tables")},
    # probes, angle senses
    "compgen/motion/check.py": [*HOSTILE, "test_probe_programs.py", "test_trt.py"],
    "compgen/motion/blocks.py": [*HOSTILE, "test_probe_programs.py"],
    "compgen/controllers/programs.py": [*HOSTILE, "test_trt.py"],        # read back under trt's senses
    "compgen/model/effects.py": ["test_effects.py", "test_kinematics.py", "test_shapes.py"],
    # diagnose and its statistics: the closed-form tests first (quick to fail), the distributions
    # against scipy (test_startup), the declared shapes and the loop a user follows
    "compgen/statistics/diagnose.py": [*STATS, "test_edge.py", "test_loop.py"],
    "compgen/statistics/ranking.py": [*STATS, "test_loop.py"],
    "compgen/statistics/separation.py": [*STATS, "test_loop.py"],
    "compgen/statistics/choice.py": ["test_diagnose.py", "test_schemas.py"],
    "compgen/statistics/budget.py": ["test_budget.py"],
    # the wings: probe logs, the history and its store, diagnose's spectrum and significance
    "compgen/data/probe.py": ["test_probe.py", "test_probe_programs.py"],
    "compgen/controllers/probing.py": ["test_probe_programs.py", "test_probe.py"],
    "compgen/history/store.py": ["test_history.py"],
    "compgen/history/ledger.py": ["test_history.py"],
    "compgen/history/drift.py": ["test_history.py"],
    "compgen/history/checks.py": ["test_history.py"],
    "compgen/history/words.py": ["test_history.py"],
    "compgen/history/exchange.py": ["test_history.py"],
    "compgen/statistics/spectrum.py": [*STATS, "test_loop.py"],
    "compgen/statistics/significance.py": [*STATS, "test_loop.py"],
    "compgen/statistics/device.py": ["test_diagnose.py", "test_probe.py"],
    # the rest of the package (2026-12-04: the draws had sampled 31 of 59 modules): readers,
    # the command layer, the controller registry and files, the paths, the text and the gate
    "compgen/configuration/machine_file.py": ["test_edge.py", "test_hostile_inputs.py",
                                              "test_cli.py"],
    "compgen/configuration/session.py": ["test_csv_reader.py", "test_streaming.py",
                                         "test_edge.py"],
    "compgen/data/rtest.py": ["test_csv_reader.py", "test_hostile_inputs.py",
                              "test_edge.py"],
    "compgen/data/simulate.py": ["test_csv_reader.py", "test_identify.py"],
    "compgen/model/machine.py": ["test_kinematics.py", "test_heads.py", "test_edge.py",
                                 "test_motion.py"],        # the set-up's solids and their defaults
    "compgen/model/frames.py": ["test_motion.py", "test_probe_programs.py"],
    "compgen/model/paths.py": ["test_kinematics.py", "test_heads.py", "test_motion.py"],
    "compgen/transforms.py": ["test_kinematics.py", "test_compose.py", "test_motion.py"],
    "compgen/files.py": ["test_edge.py", "test_hostile_inputs.py", "test_cli.py"],
    "compgen/errors.py": ["test_edge.py", "test_cli.py"],
    "compgen/search.py": ["test_controllers.py", "test_edge.py", *PROGRAMS],
    "compgen/planning/advice.py": ["test_diagnose.py", "test_loop.py",
                                      "test_probe_programs.py"],
    "compgen/controllers/base.py": ["test_controllers.py", *EDITS],
    "compgen/controllers/kinematics.py": ["test_controllers.py", *EDITS, "test_heads.py"],
    "compgen/controllers/registry.py": ["test_controllers.py", "test_imports.py", *EDITS],
    "compgen/controllers/linuxcnc/config.py": ["test_linuxcnc_config.py", "test_trt.py",
                                               "test_table_rounds.py"],
    "compgen/controllers/linuxcnc/files.py": ["test_linuxcnc_config.py", "test_trt.py",
                                              "test_table_rounds.py"],
    "compgen/statistics/diagnose_text.py": ["test_diagnose.py", "test_loop.py"],
    "compgen/statistics/gate.py": ["test_history.py", "test_diagnose.py", "test_edge.py"],
    "compgen/statistics/results.py": ["test_schemas.py", "test_identify.py",
                                      "test_history.py"],
    "compgen/statistics/signature.py": ["test_diagnose_stats.py", "test_effects.py"],
    "compgen/commands/cli.py": ["test_cli.py", "test_edge.py", "test_hostile_inputs.py"],
    "compgen/commands/cli_common.py": ["test_cli.py", "test_edge.py",
                                       "test_hostile_inputs.py"],     # a closed pipe, a bug's exit
    "compgen/commands/cli_history.py": ["test_history.py"],
    "compgen/reports/checklist.py": ["test_cli.py", "test_controllers.py",
                                      "test_report.py"],
    "compgen/reports/compare.py": ["test_compare.py"],
    "compgen/reports/plots.py": ["test_plots.py", "test_report.py",
                                  "test_streaming.py::test_a_dense_sessions_plots_draw_thinned_series_"
                                  "and_count_every_reading",
                                  "test_diagnose.py::test_ambiguous_scale_is_reported_with_the_"
                                  "measurement_that_resolves_it"],
    "compgen/reports/report.py": ["test_report.py"],
    "compgen/statistics/noise.py": ["test_noise.py", "test_identify.py",
                                    "test_diagnose_stats.py",
                                    *(f"test_diagnose.py::test_{t}" for t in (
        "outliers_are_listed_where_the_user_finds_them_and_flag_nothing",
        "correlated_noise_flags_nothing_because_it_is_whitened",
        "under_correlated_noise_a_real_effect_is_still_found"))],
}


def _located(name: str) -> str:
    """A test file named by its base name (``test_x.py``, ``::node`` allowed) at its place
    in tests/ (one folder per package folder)."""
    file, _, node = name.partition("::")
    path = next(ROOT.glob(f"tests/**/{file}")).relative_to(ROOT).as_posix()
    return f"{path}::{node}" if node else path


TESTS = {module: [_located(t) for t in tests] for module, tests in TESTS.items()}
# functions to mutate only, by module (none now: diagnose's statistics moved to
# significance.py and spectrum.py, which are mutated whole)
ONLY_FUNCTIONS: dict[str, set[str]] = {}
# LinuxCNC's real runs (2½ minutes a mutant) stay out of the rest of the suite; a selection
# may name one (the LinuxCNC package's: the head modules' senses)
SKIP = ["--deselect", _located("test_linuxcnc.py")]


class Sites(ast.NodeVisitor):
    """Where a mutation can go: (line, col, kind, before, after) with a node id."""

    def __init__(self, functions: set[str] | None):
        self.sites, self.functions, self.inside = [], functions, [] if functions else None

    def visit_FunctionDef(self, node):
        if self.inside is not None:
            self.inside.append(node.name)
            self.generic_visit(node)
            self.inside.pop()
        else:
            self.generic_visit(node)

    def _ok(self):
        return self.functions is None or (self.inside and self.inside[-1] in self.functions)

    def visit_BinOp(self, node):
        swap = {ast.Add: ast.Sub, ast.Sub: ast.Add, ast.Mult: ast.Div, ast.Div: ast.Mult}
        if self._ok() and type(node.op) in swap:
            self.sites.append((node, "op", swap[type(node.op)]))
        self.generic_visit(node)

    def visit_UnaryOp(self, node):
        if self._ok() and isinstance(node.op, ast.USub):
            self.sites.append((node, "drop-minus", None))
        self.generic_visit(node)

    def visit_Subscript(self, node):
        s = node.slice
        if self._ok() and isinstance(s, ast.Constant) and type(s.value) is int and s.value in (0, 1, 2):
            self.sites.append((s, "index", (s.value + 1) % 3))
        self.generic_visit(node)

    def visit_Constant(self, node):
        if self._ok() and type(node.value) in (int, float) and not isinstance(node.value, bool):
            new = {0: 1, 1: 0}.get(node.value, node.value * 2)
            self.sites.append((node, "const", new))

    def visit_JoinedStr(self, node):     # f-string formats are presentation, not physics
        return


def mutants(path: Path, functions: set[str] | None):
    source = path.read_text()
    tree = ast.parse(source)
    original = ast.unparse(tree)
    finder = Sites(functions)
    finder.visit(tree)
    seen = set()
    for i, (node, kind, arg) in enumerate(finder.sites):
        tree = ast.parse(source)            # a fresh tree per mutant
        target = [n for n in ast.walk(tree) if (getattr(n, "lineno", None), getattr(n, "col_offset", None),
                                                type(n)) == (node.lineno, node.col_offset, type(node))]
        if not target:
            continue
        t = target[0]
        if kind == "op":
            t.op = arg()
        elif kind == "drop-minus":
            parent = next(p for p in ast.walk(tree) for f, v in ast.iter_fields(p)
                          if v is t or (isinstance(v, list) and any(x is t for x in v)))
            for f, v in ast.iter_fields(parent):
                if v is t:
                    setattr(parent, f, t.operand)
                elif isinstance(v, list):
                    v[:] = [t.operand if x is t else x for x in v]
        else:
            t.value = arg
        text = ast.unparse(tree)
        if text in seen or text == original:
            continue
        seen.add(text)
        pairs = zip(original.splitlines(), text.splitlines(), strict=False)
        changed = next((b for a, b in pairs if a != b), "")
        yield i, node.lineno, f"{kind} -> {changed.strip()[:90]}", text


def run_mutant(work: Path, module: str, text: str, tests: list[str], whole: bool) -> str | None:
    """What kills the mutant (None: it survives): the module's selection first (most mutants
    fail there in seconds), then, for one that passes it and with ``whole``, the rest of the
    suite — the question is whether the suite notices, not one file of it. A kill by the rest
    names the test that failed, for a reader to judge."""
    target = work / module
    original = target.read_text()
    target.write_text(text)
    env = {**os.environ, "PYTHONPATH": str(work), "PYTHONDONTWRITEBYTECODE": "1"}

    def fails(timeout: float, *args) -> str | None:
        # its own process group: a mutant that loops inside a command the tests start is
        # stopped with the tests, not left spinning after them
        with tempfile.TemporaryFile("w+") as out:
            skip = [] if any(a.startswith(f"{SKIP[1]}::") for a in args) else SKIP
            proc = subprocess.Popen([sys.executable, "-m", "pytest", "-x", "-q", "-rfE", "-p",
                                     "no:cacheprovider", *skip, *args], cwd=work, env=env, stdout=out,
                                    stderr=subprocess.STDOUT, start_new_session=True)
            try:
                code = proc.wait(timeout)
            except subprocess.TimeoutExpired:              # a mutant that loops is killed
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
                return "a timeout"
            if code in (0, 5):                             # 5: nothing collected (a selection's test gone)
                return None
            out.seek(0)
            failed = [ln.split(" - ")[0] for ln in out.read().splitlines()
                      if ln.startswith(("FAILED", "ERROR"))]
            return failed[0] if failed else f"exit {code}"
    try:
        if fails(300, *tests):       # every selection runs in well under a minute
            return "the selection"
        rest = [f"--deselect={t}" for t in tests if "::" not in t]
        return fails(900, "tests", *rest) if whole else None
    finally:
        target.write_text(original)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--only", action="append", default=None, help="a module path (repeatable)")
    ap.add_argument("--list", action="store_true", help="count the mutants, run nothing")
    ap.add_argument("--lines", default=None, metavar="A-B",
                    help="only the mutants on these lines (with one --only): to see a new test kill them")
    ap.add_argument("--tests", action="append", default=None,
                    help="run these tests instead of the module's selection (repeatable): a quick look, "
                         "not the measurement")
    ap.add_argument("--draw", type=int, default=None, metavar="N",
                    help="run N mutants drawn at random from all of them (a fresh sample: --seed)")
    ap.add_argument("--seed", type=int, default=None, help="the draw's seed (default: from the clock)")
    ap.add_argument("--no-control", action="store_true", help="skip the unmutated tree's run")
    ap.add_argument("--selection-only", action="store_true",
                    help="run the module's selection only, not the rest of the suite for its survivors "
                         "(the runs before 2026-12-03 were measured so)")
    args = ap.parse_args()
    modules = args.only or list(TESTS)
    lo, hi = map(int, args.lines.split("-")) if args.lines else (0, 10**9)
    plan = [(m, i, line, kind, text) for m in modules
            for i, line, kind, text in mutants(ROOT / m, ONLY_FUNCTIONS.get(m)) if lo <= line <= hi]
    if args.draw:
        import random
        seed = args.seed if args.seed is not None else time.time_ns() % 10**6
        total = len(plan)
        plan = random.Random(seed).sample(plan, min(args.draw, total))
        print(f"a draw of {len(plan)} of {total} mutants (seed {seed})", flush=True)
    print(f"{len(plan)} mutants in {len(modules)} modules")
    lines = {m: (ROOT / m).read_text().splitlines() for m in modules}    # as mutated, not as edited since
    if args.list:
        for m in modules:
            print(f"  {m}: {sum(1 for p in plan if p[0] == m)}")
        return
    works = []
    for j in range(args.jobs):
        work = Path(tempfile.mkdtemp(prefix=f"compgen-mut{j}-"))
        # the checkout's files as git knows them (docs, README and benchmarks are read by tests too);
        # the files being edited are taken as they are now
        tracked = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
        for name in tracked.decode().split("\0"):
            if name and (ROOT / name).is_file():
                (work / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(ROOT / name, work / name)
        (work.parent / "shared").exists() or os.symlink(ROOT.parent / "shared", work.parent / "shared") \
            if (ROOT.parent / "shared").exists() and not (work.parent / "shared").exists() else None
        works.append(work)
    t0 = time.perf_counter()
    whole = not (args.selection_only or args.tests)
    # the control: the unmutated tree through the same runs, all jobs at once as the mutants
    # run, its first module written as every mutant is (ast.unparse: no comments). Were a test
    # to fail here (a shared resource, a flaky test, a test reading a comment), every mutant
    # reaching it would count as killed: the run stops instead.
    if not args.no_control:
        with ThreadPoolExecutor(args.jobs) as pool:
            failed = [w for w, bad in zip(works, pool.map(
                lambda w: run_mutant(w, modules[0], ast.unparse(ast.parse((ROOT / modules[0]).read_text())),
                                     args.tests or TESTS[modules[0]], whole), works), strict=True) if bad]
        if failed:
            sys.exit(f"the unmutated tree fails its tests in {len(failed)} of {len(works)} copies: "
                     "no mutant can be judged (run the suite there to see why)")
        print(f"control: the unmutated tree passes in all {len(works)} copies "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
    free = list(range(args.jobs))
    lock = threading.Lock()

    def one(p):
        with lock:
            j = free.pop()
        try:
            return p, run_mutant(works[j], p[0], p[4], args.tests or TESTS[p[0]], whole)
        finally:
            with lock:
                free.append(j)

    results = []
    with ThreadPoolExecutor(args.jobs) as pool:     # each result printed as it comes: a run
        for future in as_completed([pool.submit(one, p) for p in plan]):   # cut short keeps them
            (m, _, line, kind, _text), by = future.result()
            killed = by is not None
            results.append(((m, _, line, kind, _text), killed))
            if by not in (None, "the selection"):
                print(f"killed by the rest of the suite {m}:{line} {kind}: {by}", flush=True)
            if not killed:
                src = lines[m][line - 1].strip()
                print(f"SURVIVED {m}:{line} {kind}: {src[:100]}", flush=True)
            if len(results) % 10 == 0:
                print(f"  ... {len(results)} of {len(plan)} run, {sum(k for _, k in results)} killed "
                      f"({time.perf_counter() - t0:.0f} s)", flush=True)
    for w in works:
        shutil.rmtree(w, ignore_errors=True)
    killed = sum(k for _, k in results)
    print(f"killed {killed} of {len(results)}: score {100 * killed / max(len(results), 1):.1f} % "
          f"({time.perf_counter() - t0:.0f} s)")
    for m in modules:
        mine = [(p, k) for p, k in results if p[0] == m]
        if mine:
            print(f"  {m}: {sum(k for _, k in mine)}/{len(mine)}")


if __name__ == "__main__":
    main()
