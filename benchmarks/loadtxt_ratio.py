"""The measure at streaming size: fit, diagnose and report of 723 000 readings with an
effect present, against the time ``numpy.loadtxt`` takes to read the same file, on the same
machine in the same run. A benchmark, not a test.

    python benchmarks/loadtxt_ratio.py [--size 723000] [--repeats 3]

The session is the seed machine with seed Table 4's errors, a hidden 2/rev radial error of
C (EXC:h2c, 3 µm) and 0.5 µm white noise, sampled at 100 Hz while K4, K1, K2 run
(``compgen simulate --rate-hz 100 --feed F``, F from ``streaming.pace``). loadtxt reads every
numeric column of it (all but the path label) in its own process, the median of the
repeats; each command runs as its own process, as a user runs it, as many times: the
median wall and CPU seconds and peak resident memory. The ratios are wall time over
loadtxt's. The report reads the diagnosis diagnose kept beside the fit; "report, none
kept" is the report made without it. ``kinematics`` and ``history add`` are shown beside
them: each runs the fit gate, a diagnose without the advice (a gate recomputes its
diagnosis: it never reads one from a file).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from streaming import MACHINE, PATHS, TRUTH, pace

LOADTXT = """
import sys, time
import numpy as np
path = sys.argv[1]
with open(path) as f:
    skip = next(i for i, line in enumerate(f) if not line.startswith("#")) + 1   # comments, header
    f.seek(0)
    columns = f.readlines()[skip - 1].count(",") + 1
t = time.perf_counter()
np.loadtxt(path, delimiter=",", skiprows=skip, usecols=range(1, columns))
print(time.perf_counter() - t)
"""
AIMS = {"fit": 10.0, "diagnose --json": 40.0, "report": 40.0}      # × loadtxt


def timed(argv: list[str], cwd: Path) -> tuple[float, float, float]:
    """Wall s, CPU s (user + sys) and peak RSS (MiB) of one child process."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    err = proc.stderr.read().decode()
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(argv)} failed:\n{err}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=723_000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    cg = [sys.executable, "-m", "compgen"]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        truth = json.loads(TRUTH.read_text())
        truth["parameters"]["EXC:h2c"] = {"value": 3.0, "unit": "um"}
        (work / "truth.json").write_text(json.dumps(truth))
        feed, rate = pace(args.size, 100.0)
        subprocess.run([*cg, "simulate", "--machine", str(MACHINE), "--truth", "truth.json", "--paths",
                        ",".join(PATHS), "--noise-um", "0.5", "--seed", "1", "--rate-hz", f"{rate:.6f}",
                        "--feed", f"{feed:.9f}", "-o", "s.csv"], cwd=work, check=True, capture_output=True)
        rows = sum(1 for line in (work / "s.csv").open() if line[:1].isalpha()) - 1
        read = statistics.median(
            float(subprocess.run([sys.executable, "-c", LOADTXT, "s.csv"], cwd=work, check=True,
                                 capture_output=True, text=True).stdout) for _ in range(args.repeats))
        steps = {"fit": [*cg, "fit", "--machine", str(MACHINE), "s.csv", "-o", "fit.json", "--force"],
                 "diagnose --json": [*cg, "diagnose", "--from", "fit.json", "--json"],
                 # the report reads the diagnosis diagnose kept beside the fit
                 "report": [*cg, "report", "--from", "fit.json", "-o", "report{i}.html"],
                 # and makes its own where none is kept
                 "report, none kept": [*cg, "report", "--from", "fit.json", "-o", "none{i}.html"],
                 # both run the fit gate: a diagnose without the advice (the example's hidden
                 # EXC:h2 makes the gate refuse, so the edit is written despite it)
                 "kinematics": [*cg, "kinematics", "--from", "fit.json", "-o", "K{i}.txt", "--despite-gate"],
                 "history add": [*cg, "history", "add", "fit.json", "--db", "h{i}.sqlite"]}
        print(f"{rows} readings, {(work / 's.csv').stat().st_size / 2**20:.1f} MiB; numpy.loadtxt of its "
              f"numeric columns {read:.2f} s (median of {args.repeats})")
        print(f"  {'command':<18}{'wall s':>8}{'CPU s':>8}{'peak MiB':>10}{'× loadtxt':>11}")
        peaks = {}
        for name, argv in steps.items():
            runs = []
            for _ in range(args.repeats):
                if name == "report, none kept":
                    (work / "fit.diagnosis.json").unlink(missing_ok=True)
                runs.append(timed([a.format(i=len(runs)) for a in argv], work))
            wall, cpu, rss = (statistics.median(r[k] for r in runs) for k in range(3))
            peaks[name] = rss
            met = "met" if wall / read <= AIMS.get(name, 0) else "NOT met"
            aim = f"   (aim ≤ {AIMS[name]:g}×: {met})" if name in AIMS else ""
            print(f"  {name:<18}{wall:8.1f}{cpu:8.1f}{rss:10.0f}{wall / read:10.1f}×{aim}")
        print(f"diagnose's peak memory / fit's at this size: {peaks['diagnose --json'] / peaks['fit']:.2f} "
              "(the aim of ≤ 1.5 is at 21 690 poses: benchmarks/startup.py)")


if __name__ == "__main__":
    main()
