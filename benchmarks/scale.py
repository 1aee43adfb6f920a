"""Large inputs: predict at 1 000 000 poses, check-program of a 34 000-block program.

    python benchmarks/scale.py [--poses 1000000] [--program-poses 11000]

Each runs the real command in a fresh process (wall seconds, peak RSS of the child); the
program is compgen's own measure-program output for a pose list of the given length, so
its blocks are the ones check-program reads. Outside CI: a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SEED = ROOT / "machines" / "ac-trunnion-itnc530.toml"


def timed(args: list[str], cwd: Path) -> tuple[float, float, str]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "compgen", *args], capture_output=True, text=True, cwd=cwd)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(args)}: exit {done.returncode}: {done.stderr.strip()}")
    peak = max(before, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024
    return seconds, peak, (done.stdout or done.stderr).strip().splitlines()[-1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=1_000_000)
    ap.add_argument("--program-poses", type=int, default=11_000)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="compgen-scale-"))
    rng = np.random.default_rng(1)
    subprocess.run([sys.executable, "-m", "compgen", "fit", "--machine", str(SEED),
                    str(ROOT / "examples" / "seed-session.csv"), "-o", str(work / "fit.json")],
                   check=True, capture_output=True)
    a = rng.uniform(-90, 0, args.poses)
    c = rng.uniform(0, 360, args.poses)
    rows = (f"{x:.4f},{y:.4f}" for x, y in zip(a, c, strict=True))
    (work / "poses.csv").write_text("A,C\n" + "\n".join(rows) + "\n")
    s, peak, said = timed(["predict", "--from", "fit.json", "--poses", "poses.csv", "-o", "pred.csv"], work)
    print(f"predict {args.poses} poses: {s:.1f} s, peak {peak:.0f} MiB  ({said})")
    # a slow spiral over C's whole travel: every step well within max_step_deg
    n = args.program_poses
    t = np.linspace(0, 1, n)
    (work / "long.csv").write_text("path,A,C\n" + "\n".join(
        f"L,{-90 * x:.4f},{-720 + 1440 * x:.4f}" for x in t) + "\n")
    s, _, said = timed(["measure-program", "--machine", str(SEED), "--poses", "long.csv", "-o", "LONG.H"],
                       work)
    blocks = sum(1 for _ in (work / "LONG.H").open())
    print(f"measure-program {n} poses ({blocks} lines): {s:.1f} s")
    s, peak, said = timed(["check-program", "--machine", str(SEED), "LONG.H"], work)
    print(f"check-program {blocks} lines: {s:.1f} s ({s / blocks * 1e3:.3f} ms a line), peak {peak:.0f} MiB")


if __name__ == "__main__":
    main()
