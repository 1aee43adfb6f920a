"""Wall time of `diagnose` over the whole effect catalogue. A benchmark, not a test.

    python benchmarks/diagnose_time.py [--repeats 10]

Seed machine, K4+K1+K2 (723 poses), Table 4 truth with a hidden EXC:h2 and 0.5 µm noise;
times the library call (no start-up, no file reading).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from compgen.configuration.machine_file import load_machine
from compgen.data.simulate import read_truth, simulate
from compgen.model.effects import catalogue
from compgen.model.paths import generate
from compgen.planning.advice import Advisor
from compgen.statistics.diagnose import diagnose
from compgen.statistics.identify import identify

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=10)
    args = ap.parse_args()
    machine = load_machine(ROOT / "machines" / "ac-trunnion-itnc530.toml")
    truth = read_truth(ROOT / "examples" / "truth-seed-session.json", machine)
    poses = generate(machine, ["K4", "K1", "K2"])
    data = [simulate(machine, truth, poses, 0.5, np.random.default_rng(1))]
    fit = identify(machine, data)
    effects = catalogue(machine)
    seconds = []
    for _ in range(args.repeats + 1):
        t0 = time.perf_counter()
        result = diagnose(machine, data, fit, advisor=Advisor)     # as the command runs it
        seconds.append(time.perf_counter() - t0)
    seconds = seconds[1:]   # the first run pays for imports and caches
    print(f"catalogue: {len(effects)} effects, {sum(len(e.params) for e in effects)} parameters; "
          f"{len(poses)} poses; {result.tested} visible candidates tested")
    print(f"diagnose wall time: median {1e3 * np.median(seconds):.0f} ms, "
          f"max {1e3 * max(seconds):.0f} ms over {args.repeats} runs")
    print(f"best candidate: {result.candidates[0].effect}")


if __name__ == "__main__":
    main()
