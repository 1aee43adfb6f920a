"""Streaming-size sessions: fit, diagnose, predict and report of a continuous R-test session
(100 Hz, sampled while the paths run) from 723 to 723 000 poses. A benchmark, not a test.

    python benchmarks/streaming.py [--sizes 723,7230,72300,723000] [--rate-hz 100]

Each session is written by ``compgen simulate --rate-hz R --feed F`` (the feed chosen so
the three paths K4, K1, K2 give the size asked for at 100 Hz — 723 000 poses are two hours
at 7.5 deg/min — or, where that feed is beyond 3000 deg/min, 3000 deg/min at a lower rate)
on the seed machine with seed Table 4's errors and 0.5 µm white noise.
Every command runs as its own process, as a user runs it; CPU is its user + system time,
memory its peak resident set. The floor is start-up, reading the CSV and one evaluation
of the model: what no fit can avoid. Printed: the table, fit's ratio to the floor, and
each of issue 25's limits with whether it holds.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from startup import run as child  # this folder's: one way to measure a child process

ROOT = Path(__file__).resolve().parents[1]
MACHINE = ROOT / "machines" / "ac-trunnion-itnc530.toml"
TRUTH = ROOT / "examples" / "truth-table4.json"
PATHS = ["K4", "K1", "K2"]
FLOOR = """
import sys
import numpy as np
from compgen.model.effects import location_model
from compgen.model.kinematics import Model
from compgen.configuration.machine_file import load_machine
from compgen.configuration.session import read_data
machine = load_machine(sys.argv[1])
data = read_data(sys.argv[2], machine)
Model(machine, location_model(machine)).relative(data.poses, np.full(11, 1e-5))
"""
LIMITS = {"fit": 20.0, "diagnose": 60.0, "report": 60.0}   # s at 723 000 poses (issue 25)
PEAK_MIB = 2048.0
FEED_MAX = 3000.0      # deg/min: A's feed_max on the seed machine is 5400
FLOOR_RATIO = 3.0


def run(args: list[str], cwd: Path) -> tuple[float, float]:
    """CPU seconds and peak RSS (MiB) of ``python ARGS`` in its own process."""
    return child([sys.executable, *args], cwd)


def pace(size: int, rate_hz: float) -> tuple[float, float]:
    """(feed deg/min, rate Hz) at which K4, K1, K2 give about ``size`` poses: ``rate_hz``,
    unless the feed that needs is more than FEED_MAX (small sizes: the axes could not turn
    that fast), then FEED_MAX at the rate that gives the size."""
    from compgen.configuration.machine_file import load_machine
    from compgen.model.paths import arc, path_def

    machine = load_machine(MACHINE)
    degrees = sum(arc(machine, path_def(machine, p)) for p in PATHS)
    feed = min(FEED_MAX, 60 * rate_hz * degrees / (size - len(PATHS)))
    return feed, feed * (size - len(PATHS)) / (60 * degrees)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="723,7230,72300,723000")
    ap.add_argument("--rate-hz", type=float, default=100.0)
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    work = Path(tempfile.mkdtemp(prefix="compgen-streaming-"))
    stages = ["floor", "fit", "diagnose", "predict", "report"]
    table: dict[str, list[tuple[float, float]]] = {s: [] for s in stages}
    counts = []
    rates = []
    for size in sizes:
        csv = work / f"s{size}.csv"
        fit = work / f"fit{size}.json"
        feed, rate = pace(size, args.rate_hz)
        rates.append(f"{rate:.3g} Hz at {feed:.0f} deg/min")
        subprocess.run([sys.executable, "-m", "compgen", "simulate", "--machine", str(MACHINE),
                        "--truth", str(TRUTH), "--paths", ",".join(PATHS), "--rate-hz", f"{rate:.6f}",
                        "--feed", f"{feed:.6f}", "--noise-um", "0.5",
                        "--seed", "1", "-o", str(csv), "--force"], check=True, capture_output=True)
        counts.append(sum(1 for line in csv.open() if line[:1] == "K"))
        table["floor"].append(run(["-c", FLOOR, str(MACHINE), str(csv)], work))
        table["fit"].append(run(["-m", "compgen", "fit", "--machine", str(MACHINE), str(csv),
                                 "-o", str(fit), "--force"], work))
        table["diagnose"].append(run(["-m", "compgen", "diagnose", "--from", str(fit), "--json"], work))
        table["predict"].append(run(["-m", "compgen", "predict", "--from", str(fit), "--poses", str(csv),
                                     "-o", str(work / f"pred{size}.csv"), "--force"], work))
        table["report"].append(run(["-m", "compgen", "report", "--from", str(fit),
                                    "-o", str(work / f"report{size}.html"), "--force"], work))
    print("CPU seconds (peak MiB) by stage and poses; seed Table 4, 0.5 µm white noise; sampled at "
          + "; ".join(rates))
    print(f"| stage | {' | '.join(f'{n:,}'.replace(',', ' ') for n in counts)} |")
    print(f"|---|{'---|' * len(counts)}")
    for stage in stages:
        print(f"| {stage} | " + " | ".join(f"{s:.2f} ({m:.0f})" for s, m in table[stage]) + " |")
    ratios = [f[0] / fl[0] for f, fl in zip(table["fit"], table["floor"], strict=True)]
    print("fit / floor: " + ", ".join(f"{r:.2f}" for r in ratios)
          + f"  (limit {FLOOR_RATIO:g}: {'holds' if max(ratios) <= FLOOR_RATIO else 'FAILS'})")
    last = {stage: table[stage][-1] for stage in stages}
    for stage, limit in LIMITS.items():
        s, m = last[stage]
        print(f"{stage} at {counts[-1]} poses: {s:.1f} s (limit {limit:g} s), peak {m:.0f} MiB "
              f"(limit {PEAK_MIB:.0f}): {'holds' if s < limit and m < PEAK_MIB else 'FAILS'}")


if __name__ == "__main__":
    main()
