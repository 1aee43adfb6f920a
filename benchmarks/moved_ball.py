"""A follow-up at another ball position is a new set-up: the ball sits where it was mounted,
off the centre the program was written for by what mounting left. Until 2026-12-06 compgen
fitted one ball offset (XOW YOW ZOW) to every file of a fit, and 3 µm of re-mounting named a
wrong effect found; each mounting now has an offset of its own. A benchmark, not a test: it
shows what a user meets.

    python benchmarks/moved_ball.py [--delta 15,-10,5]

On the bundled example (the seed machine, its Table 4 errors, a hidden 2/rev radial error
of C, 0.5 µm noise), it does what the README's loop does: fit, diagnose, and the measurement
diagnose advises first (``next_measurement``), simulated with fresh noise; then fit both
files together and diagnose again. Twice: the follow-up's ball exactly as offset as the
first (what ``compgen simulate`` assumes with the first's truth), and re-mounted ``--delta``
µm further off (table frame). Printed: the combined fit's RMS, the worst location error
against the truth in its own σ, and what diagnose names first: the same both times, where
the fit holds an offset per mounting.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MACHINE = ROOT / "machines" / "ac-trunnion-itnc530.toml"
SESSION = ROOT / "examples" / "seed-session.csv"
TRUTH = ROOT / "examples" / "truth-seed-session.json"
TO_INSIDE = {"um": 1e-3, "arcsec": math.radians(1 / 3600)}    # fit.json holds mm and rad


def compgen(work: Path, *args: str) -> str:
    out = subprocess.run([sys.executable, "-m", "compgen", *args], cwd=work, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"compgen {' '.join(args)} failed:\n{out.stderr}")
    return out.stdout


def worst_off(fit: dict, truth: dict) -> tuple[str, float]:
    """The machine's location error furthest from the truth, in its own σ (the ball's offset
    XOW YOW ZOW is the set-up's, not the machine's)."""
    offs = {n: (p["value"] - truth[n]["value"] * TO_INSIDE[truth[n]["unit"]]) / p["std"]
            for n, p in fit["parameters"].items()
            if n in truth and p.get("std") and n not in ("XOW", "YOW", "ZOW")}
    name = max(offs, key=lambda n: abs(offs[n]))
    return name, offs[name]


def _offset(text: str) -> list[float]:
    """X,Y,Z in µm, three finite numbers (argparse's one-line refusal otherwise)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{text!r} is not X,Y,Z in µm (e.g. 15,-10,5)")
    return values


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--delta", default="15,-10,5", type=_offset,
                    help="the re-mounted ball's further offset, µm, X,Y,Z")
    args = ap.parse_args()
    delta = args.delta
    truth = json.loads(TRUTH.read_text())["parameters"]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        compgen(work, "fit", "--machine", str(MACHINE), str(SESSION), "-o", "fit.json")
        advice = json.loads(compgen(work, "diagnose", "--from", "fit.json", "--json", "--noise-um", "0.5"))
        step = advice["next_measurement"]
        ball = ",".join(f"{v:g}" for v in step["ball"])
        print(f"diagnose advises first: {step['label']} (would show {', '.join(step['would_show'])})")
        print(f"  {'follow-up ball':<34}{'fit RMS µm':>11}  {'worst location error':<22}  "
              "diagnose names first")
        for label, extra in (("as offset as the first", (0.0, 0.0, 0.0)),
                             (f"re-mounted {','.join(f'{v:g}' for v in delta)} µm further", delta)):
            moved = {n: dict(p) for n, p in truth.items()}
            for name, v in zip(("XOW", "YOW", "ZOW"), extra, strict=True):
                moved[name]["value"] = truth[name]["value"] + v
            (work / "moved.json").write_text(json.dumps({"parameters": moved}))
            compgen(work, "simulate", "--machine", str(MACHINE), "--truth", "moved.json", "--paths",
                    step["path"], "--ball", ball, "--noise-um", "0.5", "--seed", "11", "-o", "next.csv",
                    "--force")
            compgen(work, "fit", "--from", "fit.json", "--data", "next.csv", "-o", "both.json", "--force")
            both = json.loads((work / "both.json").read_text())
            found = json.loads(compgen(work, "diagnose", "--from", "both.json", "--json",
                                       "--noise-um", "0.5"))
            first = found["candidates"][0]
            name, off = worst_off(both, truth)
            said = (f"{first['effect']} ({'significant' if first['significant'] else 'not significant'}"
                    f"{', found' if first['effect'] in found['found'] else ''})")
            print(f"  {label:<34}{both['residual']['rms_um']:11.3f}  {name} {off:+7.1f} σ{'':<8}  {said}")


if __name__ == "__main__":
    main()
