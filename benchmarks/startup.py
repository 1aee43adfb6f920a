"""CPU time of each command against ``python -c "import numpy"``, and diagnose's peak
memory against fit's on a session 30× denser than the example. A benchmark, not a test.

    python benchmarks/startup.py [--repeats 5] [--density 30]

Every command runs as its own process (``python -m compgen …``, as a user runs it); CPU is
user + system time of that process, the median over the repeats. Memory is the process's
peak resident set (what the machine must have) and, for the library call alone, the peak
of numpy's and Python's allocations seen by ``tracemalloc``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

from compgen.__main__ import BLAS_THREADS  # no numpy: this process keeps its own BLAS

ROOT = Path(__file__).resolve().parents[1]
MACHINE = ROOT / "machines" / "ac-trunnion-itnc530.toml"
SESSION = ROOT / "examples" / "seed-session.csv"
TRUTH = ROOT / "examples" / "truth-seed-session.json"
LIMITS = {"--help": 3.0, "fit": 4.0, "diagnose --json": 4.0}   # issues 13 and 25, × import numpy


def run(argv: list[str], cwd: Path, env: dict[str, str] | None = None) -> tuple[float, float]:
    """CPU seconds (user + sys) and peak RSS (MiB) of one child process (``env`` added to
    this one's environment)."""
    proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            env={**os.environ, **(env or {})})
    _, status, usage = os.wait4(proc.pid, 0)
    err = proc.stderr.read().decode()
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(argv)} failed:\n{err}")
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def dense_session(folder: Path, density: int) -> Path:
    """The example session's machine, truth and noise, with ``density`` × the poses."""
    import numpy as np

    from compgen.configuration.machine_file import load_machine
    from compgen.data.rtest import format_rtest
    from compgen.data.simulate import read_truth, simulate
    from compgen.model.paths import generate

    machine = load_machine(MACHINE)
    machine = replace(machine, paths={k: replace(p, n=p.n * density) for k, p in machine.paths.items()})
    poses = generate(machine, ["K4", "K1", "K2"])
    data = simulate(machine, read_truth(TRUTH, machine), poses, 0.5, np.random.default_rng(7))
    out = folder / f"dense{density}.csv"
    out.write_text(format_rtest(machine, data, ("benchmark: dense session",)), encoding="utf-8")
    return out


def library_peaks(csv: Path) -> tuple[float, float]:
    """tracemalloc peak (MiB) of the library's fit and of its diagnose on the same data."""
    code = (
        "import sys, tracemalloc, json\n"
        "from compgen.configuration.machine_file import load_machine\n"
        "from compgen.data.rtest import read_rtest\n"
        "from compgen.statistics.identify import identify\nfrom compgen.statistics.diagnose import diagnose\n"
        "from compgen.planning.advice import Advisor\n"
        f"m = load_machine({str(MACHINE)!r}); d = [read_rtest({str(csv)!r}, m)]\n"
        "tracemalloc.start(); fit = identify(m, d); a = tracemalloc.get_traced_memory()[1]\n"
        "tracemalloc.reset_peak(); diagnose(m, d, fit, advisor=Advisor)\n"
        "b = tracemalloc.get_traced_memory()[1]\n"
        "print(json.dumps([a / 2**20, b / 2**20]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return tuple(json.loads(out.stdout))


def blas_threads(csv: Path, repeats: int) -> dict[str, tuple[float, float]]:
    """The library's fit and diagnose with BLAS at one thread and at its default: median
    (wall s, CPU s) in one process, on the example session."""
    code = (
        "import json, statistics, time\nfrom threadpoolctl import threadpool_limits\n"
        "from compgen.configuration.machine_file import load_machine\n"
        "from compgen.data.rtest import read_rtest\n"
        "from compgen.statistics.identify import identify\nfrom compgen.statistics.diagnose import diagnose\n"
        "from compgen.planning.advice import Advisor\n"
        f"m = load_machine({str(MACHINE)!r}); d = [read_rtest({str(csv)!r}, m)]\n"
        "def once():\n    w, c = time.perf_counter(), time.process_time()\n"
        "    diagnose(m, d, identify(m, d), advisor=Advisor)\n"
        "    return time.perf_counter() - w, time.process_time() - c\n"
        "once(); out = {}\n"
        "for label, limit in (('default', None), ('one', 1)):\n"
        "    with threadpool_limits(limits=limit, user_api='blas'):\n"
        f"        runs = [once() for _ in range({repeats})]\n"
        "    out[label] = [statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)]\n"
        "print(json.dumps(out))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--density", type=int, default=30)
    args = ap.parse_args()
    py = [sys.executable]
    cg = [*py, "-m", "compgen"]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        subprocess.run([*cg, "fit", "--machine", str(MACHINE), str(SESSION), "-o", "fit.json"],
                       cwd=work, check=True, capture_output=True)
        commands = {
            "import numpy": [*py, "-c", "import numpy"],
            "--help": [*cg, "--help"],
            "fit": [*cg, "fit", "--machine", str(MACHINE), str(SESSION), "-o", "f2.json", "--force"],
            "fit --method linear": [*cg, "fit", "--from", "fit.json", "--method", "linear",
                                    "-o", "f3.json", "--force"],
            "diagnose --json": [*cg, "diagnose", "--from", "fit.json", "--json"],
            # the example misses EXC:h2: the gate (run as every user runs it) would refuse the edit
            "kinematics": [*cg, "kinematics", "--from", "fit.json", "-o", "KIN.txt", "--force",
                           "--despite-gate"],
            "measure-program": [*cg, "measure-program", "--machine", str(MACHINE), "--path", "all",
                                "-o", "RTEST.H", "--force"],
            "compare": [*cg, "compare", "--from", "fit.json"],
        }
        cpu = {name: statistics.median(run(argv, work)[0] for _ in range(args.repeats))
               for name, argv in commands.items()}
        # the commands hold BLAS to one thread before numpy loads (compgen/__main__.py), which
        # also spares numpy's own start-up the spinning of OpenBLAS's idle workers: the
        # baseline as the commands start, beside the limits' baseline (as a user runs it)
        one = statistics.median(run(commands["import numpy"], work, dict.fromkeys(BLAS_THREADS, "1"))[0]
                                for _ in range(args.repeats))
        base = cpu["import numpy"]
        print(f"CPU seconds (user + sys), median of {args.repeats}, and × `python -c \"import numpy\"`:")
        for name, seconds in cpu.items():
            limit = f"   (limit {LIMITS[name]:g}×)" if name in LIMITS else ""
            print(f"  {name:<22}{seconds:6.2f} s {seconds / base:6.1f}×{limit}")
        print(f"  (import numpy with one BLAS thread, as the commands load it: {one:.2f} s; "
              f"diagnose --json is {cpu['diagnose --json'] / one:.1f}× that)")

        threads = blas_threads(SESSION, args.repeats)
        print("\nfit + diagnose, library call, example session (wall s / CPU s):")
        for label, (wall, cpu_s) in threads.items():
            print(f"  BLAS threads {label:<8}{wall:6.3f} / {cpu_s:6.3f}")

        csv = dense_session(work, args.density)
        fit_cpu, fit_rss = run([*cg, "fit", "--machine", str(MACHINE), str(csv), "-o", "dense.json",
                                "--force"], work)
        diag_cpu, diag_rss = run([*cg, "diagnose", "--from", "dense.json", "--json"], work)
        fit_lib, diag_lib = library_peaks(csv)
        rows = sum(1 for line in csv.read_text().splitlines() if line[:1].isalpha()) - 1
        print(f"\n{args.density}× denser session ({rows} poses):")
        print(f"  peak RSS      fit {fit_rss:7.1f} MiB   diagnose {diag_rss:7.1f} MiB   "
              f"ratio {diag_rss / fit_rss:.2f} (limit 1.5)")
        print(f"  tracemalloc   fit {fit_lib:7.1f} MiB   diagnose {diag_lib:7.1f} MiB   "
              f"ratio {diag_lib / fit_lib:.2f}   (library call only)")
        print(f"  CPU           fit {fit_cpu:7.2f} s     diagnose {diag_cpu:7.2f} s")


if __name__ == "__main__":
    main()
