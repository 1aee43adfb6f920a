"""compgen plan against the machine file's own paths, and its σ against Monte Carlo. A
benchmark, not a test.

    python benchmarks/plan.py [--draws 100] [--noise-um 0.5] [--device rtest|probe]

For each bundled machine: the default paths' minutes and worst σ (each location error's σ of
its [limits]); the plan at those minutes and at half of them, and its ratio to the default's;
then the plan at the default's minutes simulated ``--draws`` times (the truth: zero location
errors, white noise), each draw fitted: the spread of the fitted values and the mean σ the
fit reports, each against the plan's σ, worst over the location errors. With ``--device
probe`` the plans are a touch probe's (the machines with a [probe] section and no head),
``--noise-um`` per touch, and each draw's set-ups are probe logs written as a probing
program logs them and read back (``sphere_centres``: each centre with its covariance).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from compgen.configuration.machine_file import load_machine  # noqa: E402
from compgen.data.probe import format_probe_log, read_probe_log, simulate_touches, sphere_centres  # noqa: E402
from compgen.data.simulate import simulate  # noqa: E402
from compgen.errors import CompgenError  # noqa: E402
from compgen.planning.plan import plan  # noqa: E402
from compgen.statistics.identify import identify  # noqa: E402

REFUSED = []      # probe logs the reader refused (a touch taken for a chip): probed again


def measured(machine, poses, noise_um: float, rng, device: str, folder: Path):
    """One set-up's readings of the machine without errors: an R-test's, or a probe log's
    centres (each touch ``noise_um`` off the sphere, read back as compgen reads a log; one
    the reader refuses is probed again, as its message says, and counted)."""
    if device == "rtest":
        return simulate(machine, {}, poses, noise_um, rng)
    path, clean = folder / "p.log", simulate(machine, {}, poses).deviation
    while True:
        tips, directions = simulate_touches(machine, poses, clean, noise_um, rng)
        path.write_text(format_probe_log(machine, machine.probe, poses, tips, directions))
        try:
            return sphere_centres(read_probe_log(path, machine), machine).data
        except CompgenError as e:
            REFUSED.append(str(e))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=100)
    ap.add_argument("--noise-um", type=float, default=0.5)
    ap.add_argument("--device", choices=("rtest", "probe"), default="rtest")
    args = ap.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="compgen-plan-"))
    t0 = time.time()
    print(f"{'machine':<24}{'default':>16}{'plan, same min':>22}{'plan, half min':>22}"
          f"{'MC spread/σ':>14}{'fit σ/σ':>10}")
    for path in sorted((ROOT / "machines").glob("*.toml")):
        machine = load_machine(path)
        if args.device == "probe" and (machine.probe is None or machine.heads):
            continue
        whole = plan(machine, 1e6, args.noise_um, device=args.device)
        minutes, _, worst = whole.default
        same = plan(machine, minutes, args.noise_um, device=args.device)
        half = plan(machine, minutes / 2, args.noise_um, device=args.device)
        rng = np.random.default_rng(1)
        names = list(same.sigma)
        values, reported = [], []
        for _ in range(args.draws):
            data = [measured(machine, s.proposal.poses, args.noise_um, rng, args.device, folder)
                    for s in same.setups]
            fit = identify(machine, data)
            values.append([fit.parameters[n].value for n in names])
            reported.append([fit.parameters[n].std for n in names])
        sigma = np.array([same.sigma[n] for n in names])
        spread = np.std(values, axis=0, ddof=1) / sigma
        said = np.mean(reported, axis=0) / sigma
        print(f"{path.stem:<24}{minutes:7.1f} min {worst:.5f}"
              f"{same.minutes:8.1f} min {same.worst:.5f} {same.worst / worst:4.2f}"
              f"{half.minutes:8.1f} min {half.worst:.5f} {half.worst / worst:4.2f}"
              f"  {spread.min():4.2f}-{spread.max():4.2f}  {said.min():4.2f}-{said.max():4.2f}")
        print(f"{'':<24}plan: " + "; ".join(s.proposal.label for s in same.setups))
    if args.device == "probe":
        print(f"probe logs refused by the reader and probed again: {len(REFUSED)}")
    print(f"\n{time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
