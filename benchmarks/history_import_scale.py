"""A large history moved between stores: `history export` of N fits, then `history import`.

    python benchmarks/history_import_scale.py [--fits 10000]

One real fit (the bundled example session) is recorded, then --fits calibrations made from
it with values drifting, each a whole fit (its fit.json, its record marker recomputed) as
compgen writes it: what a plant's store holds after years. The export is imported into a
fresh store in a fresh process; wall seconds and the importer's peak memory (maximum
resident set, MB) are printed. Outside CI: a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from datetime import UTC, datetime, timedelta
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MACHINE = "ac-trunnion-itnc530"


# compgen run in a process of its own that prints its peak memory (maximum resident set, kB)
PEAK = ("import resource, runpy, sys\nsys.argv = ['compgen', *sys.argv[1:]]\ntry:\n"
        "    runpy.run_module('compgen', run_name='__main__')\nfinally:\n"
        "    print('PEAK', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)\n")


def run(args: list[str], cwd: Path) -> tuple[float, float]:
    """Wall seconds and peak memory (MB) of one compgen command."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", PEAK, *args], capture_output=True, text=True, cwd=cwd)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(args)}: exit {done.returncode}: {done.stderr.strip()}")
    peak = int(done.stderr.rsplit("PEAK ", 1)[1].split()[0]) / 1024
    return time.perf_counter() - t0, peak


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fits", type=int, default=10000)
    n = ap.parse_args().fits
    sys.path.insert(0, str(ROOT))
    from compgen.history.ledger import content_key
    from compgen.history.store import DEFAULT_FILE, open_store
    from compgen.statistics.results import FitResult

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        data = ROOT / "examples" / "seed-session.csv"
        run(["fit", "--machine", MACHINE, str(data), "-o", "fit.json", "--record", "--date",
             "2020-01-01"], folder)
        with open_store(str(folder / DEFAULT_FILE)) as store, store.writing():
            session = store.rows("SELECT * FROM sessions")[0]
            row = store.rows("SELECT * FROM fits")[0]
            machine = store.rows("SELECT name, serial FROM machines")[0]
            fit = FitResult.from_dict(json.loads(row["fit_json"]))
            start = datetime(2020, 1, 2, 9, tzinfo=UTC)
            for i in range(n):
                taken = (start + timedelta(hours=6 * i)).isoformat(timespec="seconds")
                sid = store.insert("sessions", {k: v for k, v in session.items() if k != "id"}
                                   | {"taken": taken})
                f = replace(fit, parameters={k: replace(e, value=e.value * (1 + 1e-4 * (i + 1)))
                                             for k, e in fit.parameters.items()})
                store.insert("fits", {k: v for k, v in row.items() if k not in ("id", "content_sha256")}
                             | {"session_id": sid, "marker": f.record_marker, "fit_json": f.to_dict(),
                                "parameters": {k: {"value": e.value, "std": e.std, "unit": e.unit}
                                               for k, e in f.parameters.items()},
                                "content_sha256": content_key("fit", machine["name"], machine["serial"],
                                                              f.record_marker)})
        export, export_peak = run(["history", "export", "-o", "h.json"], folder)
        size = (folder / "h.json").stat().st_size / 2**20
        seconds, peak = run(["history", "import", "h.json", "--db", "other.sqlite"], folder)
    print(f"{n + 1} fits, {size:.0f} MB: export {export:.1f} s, peak {export_peak:.0f} MB; "
          f"import {seconds:.1f} s, peak {peak:.0f} MB")


if __name__ == "__main__":
    main()
