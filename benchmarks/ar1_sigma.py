"""Are fit's uncertainties honest under correlated noise? Monte-Carlo under AR(1) noise on
continuous sessions sampled at 100 Hz. A benchmark, not a test: it prints.

    python benchmarks/ar1_sigma.py [--runs 200] [--poses 7230] [--rho 0.5,0.9,0.98]

For each ρ, ``runs`` sessions of the seed machine (seed Table 4's errors, 0.5 µm AR(1)
noise, K4 + K1 + K2 sampled at 100 Hz with the feed that gives ``poses`` poses) are fitted
as a user fits them (``identify``, default model). Per parameter: the spread of the
estimates over the runs (the truth about the uncertainty), the median σ fit reports, and
the σ white-noise least squares would report (σ̂·√diag (JᵀJ)⁻¹). Issue 25's bar: the
reported σ within 20 % of the spread. The spread's own sampling error is ±√(1/(2·runs)).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from compgen.configuration.machine_file import load_machine
from compgen.data.simulate import read_truth, simulate
from compgen.model.kinematics import Model
from compgen.model.paths import arc, generate, path_def
from compgen.statistics.identify import identify
from compgen.units import shown

ROOT = Path(__file__).resolve().parents[1]
PATHS = ["K4", "K1", "K2"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--poses", type=int, default=7230)
    ap.add_argument("--rho", default="0.5,0.9,0.98")
    ap.add_argument("--rate-hz", type=float, default=100.0)
    ap.add_argument("--noise-um", type=float, default=0.5)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    machine = load_machine(ROOT / "machines" / "ac-trunnion-itnc530.toml")
    truth = read_truth(ROOT / "examples" / "truth-table4.json", machine)
    degrees = sum(arc(machine, path_def(machine, p)) for p in PATHS)
    feed = 60 * args.rate_hz * degrees / (args.poses - len(PATHS))
    poses = generate(machine, PATHS, rate_hz=args.rate_hz, feed=feed)
    names = list(truth)
    model = Model(machine, names)
    J = model.jacobian(poses, np.array(list(truth.values()))).reshape(-1, len(names))
    gain = np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    rng = np.random.default_rng(args.seed)
    print(f"{len(poses)} poses at {args.rate_hz:g} Hz ({feed:.1f} deg/min), {args.noise_um} µm AR(1) noise, "
          f"{args.runs} runs per ρ; sampling error of a spread ±{100 / math.sqrt(2 * args.runs):.0f} %")
    worst = 0.0
    for rho in (float(r) for r in args.rho.split(",")):
        est, said, white, kinds = [], [], [], set()
        for _ in range(args.runs):
            data = simulate(machine, truth, poses, args.noise_um, rng, rho=rho)
            fit = identify(machine, [data])
            est.append([fit.parameters[n].value for n in names])
            said.append([fit.parameters[n].std for n in names])
            white.append(fit.residual["sigma_um"] * 1e-3 * gain)
            kinds.add(fit.residual.get("noise", "white"))
        spread = np.std(est, axis=0, ddof=1)
        reported, plain = np.median(said, axis=0), np.median(white, axis=0)
        ratio = reported / spread
        worst = max(worst, float(np.abs(ratio - 1).max()))
        print(f"\nρ = {rho:g} (theory for slowly varying J: ×{math.sqrt((1 + rho) / (1 - rho)):.2f}); "
              f"noise model fit chose: {', '.join(sorted(kinds))}")
        print(f"  {'param':<6}{'MC spread':>12}{'reported':>12}{'ratio':>8}{'white LS':>12}{'ratio':>8}")
        for i, name in enumerate(names):
            unit = model.effects[i].unit
            sd, u = shown(spread[i], unit)
            print(f"  {name:<6}{sd:>10.4f} {u:<2}{shown(reported[i], unit)[0]:>10.4f}  {ratio[i]:>7.2f}"
                  f"{shown(plain[i], unit)[0]:>10.4f}  {plain[i] / spread[i]:>7.2f}")
    print(f"\nlargest |reported/spread − 1| over every ρ and parameter: {100 * worst:.0f} % "
          f"(bar 20 %: {'holds' if worst <= 0.2 else 'FAILS'})")


if __name__ == "__main__":
    main()
