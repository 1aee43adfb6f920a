"""A machine with many fits: `history trend`, `history show` and `check` against it.

    python benchmarks/history_scale.py [--fits 2000]

One real fit (the bundled example session) is recorded, then --fits rows copied from it
with dates a day apart and values drifting, each with its own marker: what a store holds
after years of daily checks. Each command runs in a fresh process (wall seconds). Outside
CI: a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MACHINE = "ac-trunnion-itnc530"


def run(args: list[str], cwd: Path) -> float:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "compgen", *args], capture_output=True, text=True, cwd=cwd)
    seconds = time.perf_counter() - t0
    if done.returncode not in (0, 1) or not done.stdout.strip():
        raise SystemExit(f"{' '.join(args)}: exit {done.returncode}: {done.stderr.strip()}")
    if "-v" in sys.argv:
        print(done.stdout[-600:], done.stderr[-300:])
    return seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fits", type=int, default=2000)
    ap.add_argument("-v", action="store_true", help="print the end of each command's output")
    n = ap.parse_args().fits
    sys.path.insert(0, str(ROOT))
    from compgen.history.store import DEFAULT_FILE, open_store

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        data = ROOT / "examples" / "seed-session.csv"
        run(["fit", "--machine", MACHINE, str(data), "-o", "fit.json", "--record", "--date",
             "2020-01-01"], folder)
        with open_store(str(folder / DEFAULT_FILE)) as store, store.writing():
            session = store.rows("SELECT * FROM sessions")[0]
            fit = store.rows("SELECT * FROM fits")[0]
            params = json.loads(fit["parameters"])
            start = datetime(2020, 1, 2, 9, tzinfo=UTC)
            for i in range(n):
                sid = store.insert("sessions", {k: v for k, v in session.items() if k != "id"}
                                   | {"taken": (start + timedelta(days=i)).isoformat(timespec="seconds")})
                p = {k: {**v, "value": v["value"] * (1 + 1e-4 * i)} for k, v in params.items()}
                store.insert("fits", {k: v for k, v in fit.items() if k not in ("id", "content_sha256")}
                             | {"session_id": sid, "marker": f"fit:{i:06x}", "parameters": p,
                                "kind": "check", "verdict": "check passed"})
            fit["verdict"] = "accepted"       # the reference: the real fit, as its fit.json gives it
            sid = store.insert("sessions", {k: v for k, v in session.items() if k != "id"}
                               | {"taken": (start + timedelta(days=n)).isoformat(timespec="seconds")})
            store.insert("fits", {k: v for k, v in fit.items() if k not in ("id", "content_sha256")}
                         | {"session_id": sid})
        run(["simulate", "--machine", MACHINE, "--truth", str(ROOT / "examples" / "truth-seed-session.json"),
             "--paths", "K4", "--noise-um", "0.5", "-o", "k4.csv"], folder)
        times = {
            "history trend": run(["history", "trend", "--machine", MACHINE], folder),
            "history show": run(["history", "show", "--machine", MACHINE], folder),
            "check": run(["check", "--machine", MACHINE, "k4.csv", "--date", "2026-01-01"], folder),
        }
    for what, seconds in times.items():
        print(f"{what:<16}{n + 1:>6} fits  {seconds:6.2f} s")


if __name__ == "__main__":
    main()
