"""Monte-Carlo efficiency of the fit and its wall time. A benchmark, not a test: it prints.

Efficiency per parameter = Cramér–Rao variance σ²·[(JᵀJ)⁻¹]ᵢᵢ (true σ, Jacobian at the
truth) / variance of the estimates over repeated noise draws. 1.0 is the best any unbiased
estimator can do; the figure's own sampling error is about ±√(2/runs).

    python benchmarks/fit_efficiency.py [--runs 300] [--noise-um 0.5]
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from compgen.configuration.machine_file import load_machine
from compgen.data.simulate import read_truth, simulate
from compgen.model.kinematics import Model
from compgen.model.paths import generate
from compgen.statistics.identify import identify
from compgen.units import shown

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=300)
    ap.add_argument("--noise-um", type=float, default=0.5)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    machine = load_machine(ROOT / "machines" / "ac-trunnion-itnc530.toml")
    truth = read_truth(ROOT / "examples" / "truth-table4.json", machine)
    rng = np.random.default_rng(args.seed)
    print(f"machine: {machine.name}; truth: seed Table 4; noise σ {args.noise_um} µm; "
          f"{args.runs} runs")
    for paths in (["K4"], ["K4", "K1", "K2"]):
        poses = generate(machine, paths)
        model = Model(machine, list(truth))
        J = model.jacobian(poses, np.array(list(truth.values()))).reshape(-1, len(truth))
        crb = (args.noise_um * 1e-3) ** 2 * np.linalg.inv(J.T @ J).diagonal()
        estimates, seconds = [], []
        for _ in range(args.runs):
            data = simulate(machine, truth, poses, args.noise_um, rng)
            t0 = time.perf_counter()
            fit = identify(machine, [data])
            seconds.append(time.perf_counter() - t0)
            estimates.append([fit.parameters[n].value for n in truth])
        est = np.array(estimates)
        var = est.var(axis=0, ddof=1)
        print(f"\n{'+'.join(paths)} ({len(poses)} poses); fit wall time median "
              f"{1e3 * np.median(seconds):.0f} ms, max {1e3 * max(seconds):.0f} ms")
        print(f"  {'param':<6}{'CRB sd':>10}{'MC sd':>10}{'bias':>10}   efficiency")
        for i, name in enumerate(truth):
            unit = model.effects[i].unit
            sd_crb, u = shown(math.sqrt(crb[i]), unit)
            sd_mc, _ = shown(math.sqrt(var[i]), unit)
            bias, _ = shown(est[:, i].mean() - truth[name], unit)
            print(f"  {name:<6}{sd_crb:>8.3f}{u:<2}{sd_mc:>8.3f}{u:<2}{bias:>8.3f}{u:<2}"
                  f"   {crb[i] / var[i]:.2f}")


if __name__ == "__main__":
    main()
