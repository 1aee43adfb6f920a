"""A large probe log: `fit` of a 20 MB log (some 240 000 touches, 48 000 poses).

    python benchmarks/probe_log_scale.py [--mb 20]

The log is the seed machine with the Table 4 errors (the shared vectors' noiseless poses,
every pose repeated under new numbers with 1 µm trigger noise), written as a probing
program's log; `fit` runs in a fresh process (wall seconds). Outside CI: a benchmark, not
a test.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mb", type=float, default=20.0)
    mb = ap.parse_args().mb
    here = [str(t.parent) for t in ROOT.glob("tests/*/test_probe.py")]
    sys.path[:0] = [str(ROOT / "tests"), *here, str(ROOT)]
    import test_probe as T  # the tests' log writer: the vectors' poses and touches

    rng = np.random.default_rng(0)
    rho = (25.4 + 3.0) / 2
    rows = list(T._rows(1))
    lines = ["# compgen probe log v1", "# sphere_diameter = 25.4", "# stylus_diameter = 3.0",
             "path,pose,A,C,X,Y,Z,nx,ny,nz"]
    size, k = 0, 0
    while size < mb * 1e6:
        for label, a, c, centre in rows:
            k += 1
            for u in T.DIRS:
                tip = centre + (rho + rng.normal(0, 1e-3)) * u
                lines.append(",".join([label, str(k), a, c, *(f"{v:.5f}" for v in tip),
                                       *(f"{-v:.6f}" for v in u)]))
                size += len(lines[-1]) + 1
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "big.log"
        log.write_text("\n".join(lines) + "\n")
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "compgen", "fit", "--machine", "ac-trunnion-itnc530",
                               str(log), "-o", str(Path(tmp) / "fit.json")], capture_output=True, text=True)
        seconds = time.perf_counter() - t0
        if done.returncode != 0:
            raise SystemExit(done.stderr.strip())
        print(f"fit of a {log.stat().st_size / 1e6:.1f} MB probe log ({len(lines) - 4} touches, {k} poses): "
              f"{seconds:.1f} s")


if __name__ == "__main__":
    main()
