"""A machine's fits read back as a trend of machine values: steps and drifts flagged, the
last accepted calibration, the fleet's due dates."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta

import numpy as np

from .. import me
from ..errors import CompgenError, one_line
from ..model.effects import effect_of_param
from ..model.machine import Machine
from ..statistics.results import FitResult
from ..units import shown
from .ledger import DAYS_PER_MONTH, days, file_ref, machine_id, machine_key, taken_at, utc
from .store import Store


@dataclass(frozen=True)
class Entry:
    """One fit of a machine's history with the corrections written before it."""

    id: int
    taken: str
    marker: str
    kind: str
    device: str
    verdict: str
    sigma_um: float
    values: dict[str, float]          # as measured (mm, rad)
    std: dict[str, float]
    units: dict[str, str]
    corrected: dict[str, float]       # sum of the corrections written before it (mm, rad)
    recorded_by: str = ""             # the database role that wrote it (PostgreSQL)
    machine_sha256: str = ""          # the machine file it was measured with

    def machine_value(self, name: str) -> float:
        return self.values[name] + self.corrected.get(name, 0.0)


@dataclass(frozen=True)
class Flag:
    """A step (a machine value moved beyond its limit and k σ from one fit to the next) or a
    drift (its slope since the last step, per month) of one location error."""

    kind: str             # "step" or "drift"
    param: str
    taken: str            # the fit at which it shows
    change: float         # step: mm or rad; drift: per month
    std: float
    unit: str
    since: str = ""

    def text(self) -> str:
        v, u = shown(self.change, self.unit)
        s, _ = shown(self.std, self.unit)
        if self.kind == "step":
            return f"{self.taken[:10]}  {self.param} moved {v:+.2f} ± {s:.2f} {u} since the fit before"
        return (f"{self.taken[:10]}  {self.param} drifts {v:+.2f} ± {s:.2f} {u}/month "
                f"(since {self.since[:10]})")


@dataclass(frozen=True)
class Trend:
    """A machine's history: its fits in time order with the corrections written before each
    (``entries``), its edits, the steps and drifts flagged, and each check's path ranges."""

    machine: str
    serial: str
    params: tuple[str, ...]
    entries: list[Entry]
    edits: list[dict]
    flags: list[Flag] = field(default_factory=list)
    # each check's largest deviation range per path (µm), in time order: (taken, {path: range})
    ranges: list[tuple[str, dict]] = field(default_factory=list)


def edit_key(edit: dict, fit_taken: Mapping[int, str]) -> tuple:
    """Where an edit stands among fits keyed (taken, id, 0): after the fit it was written
    from, even at that fit's very instant (an edit recorded with its fit, to the second:
    counted before that fit, its correction would be in the calibration's machine values and
    the first check after it would fail by the whole correction), and before any other fit
    of its instant. ``fit_taken``: fit id → its instant."""
    own = fit_taken.get(edit["fit_id"])
    return (edit["taken"], edit["fit_id"] if own == edit["taken"] else 0, 1)


def timeline(entries: Sequence[Entry], edits: Sequence[dict]) -> list[Entry | dict]:
    """The fits and edits of a machine in the order they happened."""
    at = {e.id: e.taken for e in entries}
    return sorted([*entries, *edits], key=lambda x: (x.taken, x.id, 0) if isinstance(x, Entry)
                  else edit_key(x, at))


def _entries(store: Store, mid: int) -> tuple[list[Entry], list[dict]]:
    """The machine's fits in time order, each with the corrections written before it (one
    sweep through fits and edits together: linear in their number)."""
    fits = store.rows("SELECT f.id, f.marker, f.kind, f.parameters, f.sigma_um, f.verdict, "
                      "f.recorded_by, s.taken, s.device, s.machine_sha256 FROM fits f "
                      "JOIN sessions s ON s.id = f.session_id WHERE s.machine_id = ? "
                      "ORDER BY s.taken, f.id", (mid,))
    # an edit counts for a machine only where its fit is that machine's: one filed under another
    # machine (a writer can append it so) would add its corrections to this one's values
    edits = store.rows("SELECT e.id, e.taken, e.controller, e.corrects, e.written, e.loaded, e.fit_id, "
                       "e.recorded_by, "
                       "f.marker, f.verdict FROM edits e JOIN fits f ON f.id = e.fit_id "
                       "JOIN sessions s ON s.id = f.session_id "
                       "WHERE e.machine_id = ? AND s.machine_id = ? ORDER BY e.taken, e.id", (mid, mid))
    for e in edits:
        with _read(store, "edit", e):
            e["corrects"] = _numbers(json.loads(e["corrects"]), "its corrections")
            e["written"], e["loaded"] = json.loads(e["written"]), json.loads(e["loaded"])
            e["taken"] = utc(e["taken"])
    for f in fits:
        with _read(store, "fit", f):
            f["taken"] = utc(f["taken"])
            f["parameters"] = _parameters(f["parameters"])
            _numbers({"σ̂": f["sigma_um"]}, "its σ̂")
    fits.sort(key=lambda f: (f["taken"], f["id"]))       # as instants: rows an older compgen kept
    at = {f["id"]: f["taken"] for f in fits}
    edits.sort(key=lambda e: (edit_key(e, at), e["id"]))      # with their offsets order as time does
    out = []
    corrected: dict[str, float] = {}
    done = 0
    for f in fits:
        while done < len(edits) and edit_key(edits[done], at) < (f["taken"], f["id"], 0):
            for n, v in edits[done]["corrects"].items():
                corrected[n] = corrected.get(n, 0.0) + v
            done += 1
        p = f["parameters"]
        out.append(Entry(f["id"], f["taken"], f["marker"], f["kind"], f["device"], f["verdict"],
                         f["sigma_um"],
                         {n: q["value"] for n, q in p.items()}, {n: q["std"] for n, q in p.items()},
                         {n: q["unit"] for n, q in p.items()}, dict(corrected),
                         f["recorded_by"] or "", f["machine_sha256"]))
    return out, edits


@contextmanager
def _read(store: Store, what: str, row: dict):
    """A row read as compgen writes it, or named: another writer's row (an SQLite file's
    writers are not held by the database; PostgreSQL holds types and JSON, not what the JSON
    says) is refused in one line, never a crash and never left out in silence (a machine value
    or a correction would be wrong without it)."""
    try:
        yield
    except (CompgenError, ValueError, TypeError, KeyError, AttributeError) as exc:
        why = exc.message if isinstance(exc, CompgenError) else (
            str(exc) if isinstance(exc, ValueError) else "a column is not what compgen writes")
        who = f", recorded by {one_line(row['recorded_by'])}" if row.get("recorded_by") else ""
        hint = ("ask the store's owner to look at that row (compgen did not write it); the machine's "
                "history is not shown without it")
        raise CompgenError(f"{what} #{row['id']}{who} cannot be read: {one_line(why)[:120]}",
                           where=store.where, hint=hint) from None


def _numbers(d, what: str) -> dict:
    """``d`` when it is a dict of finite numbers."""
    if not isinstance(d, dict) or not all(isinstance(v, int | float) and not isinstance(v, bool)
                                          and math.isfinite(v) for v in d.values()):
        raise ValueError(f"{what} are not finite numbers")
    return d


def _parameters(text: str) -> dict:
    """A fit row's parameters: each a value and a σ (finite numbers) and a unit."""
    p = json.loads(text)
    if not isinstance(p, dict) or not all(isinstance(q, dict) and isinstance(q.get("unit"), str)
                                          for q in p.values()):
        raise ValueError("its parameters are not a fit's")
    for q in p.values():
        _numbers({k: q.get(k) for k in ("value", "std")}, "its parameters' values or σ")
    return p


def machine_params(machine: Machine, names: Sequence[str]) -> tuple[str, ...]:
    """The location errors of the machine among ``names``: the ball's and the nest's
    set-up terms change with every set-up and are no history of the machine."""
    return tuple(n for n in names if effect_of_param(machine, n).carrier not in ("ball", "nest")
                 and effect_of_param(machine, n).basis.kind == "const")


def drift_limits(machine: Machine, t: Trend) -> dict[str, float]:
    """Each parameter of the trend's ``[drift]`` limit (mm or rad, by its class)."""
    return {n: limit_of(machine, next(e.units[n] for e in t.entries if n in e.units), name=n)
            for n in t.params if any(n in e.units for e in t.entries)}


def limit_of(machine: Machine, unit: str, per_month: bool = False, name: str | None = None) -> float:
    """A location error's ``[drift]`` limit (mm or rad): its own (``each``), else its class's;
    per month: its class's steady drift."""
    d = machine.drift
    own = dict(d.each).get(name) if not per_month else None
    if own is not None:
        return own * 1e-3 if unit == "mm" else math.radians(own / 3600.0)
    if unit == "mm":
        return (d.per_month_um if per_month else d.offset_um) * 1e-3
    return math.radians((d.per_month_arcsec if per_month else d.tilt_arcsec) / 3600.0)


def trend(store: Store, machine: Machine, serial: str | None = None,
          params: Sequence[str] | None = None) -> Trend:
    """Every fit of the machine in time order, and the steps and drifts in its machine values."""
    name, serial = machine_key(machine, serial)
    entries, edits = _entries(store, machine_id(store, machine, serial))
    seen = list(dict.fromkeys(n for e in entries for n in e.values))
    names = tuple(params) if params else machine_params(machine, seen)
    missing = [n for n in names if n not in seen]
    if missing:
        raise CompgenError(f"no recorded fit holds {', '.join(missing)}",
                           hint="recorded: " + ", ".join(seen))
    return Trend(name, serial, names, entries, edits, flags(machine, entries, names),
                 _check_ranges(store, machine_id(store, machine, serial)))


def _check_ranges(store: Store, mid: int) -> list[tuple[str, dict]]:
    """Each check's path ranges (µm) as its summary keeps them, in time order; checks an
    older compgen recorded without them, and rows no reader can read, are left out."""
    out = []
    for r in store.rows("SELECT c.summary, s.taken FROM checks c JOIN fits f ON f.id = c.fit_id "
                        "JOIN sessions s ON s.id = f.session_id WHERE c.machine_id = ? "
                        "ORDER BY s.taken, c.id", (mid,)):
        try:
            ranges = json.loads(r["summary"]).get("path_ranges_um") or {}
        except (TypeError, ValueError, AttributeError):
            continue
        if isinstance(ranges, dict) and all(isinstance(v, int | float) for v in ranges.values()):
            out.append((utc(r["taken"]), ranges))
    return out


def flags(machine: Machine, entries: Sequence[Entry], names: Sequence[str]) -> list[Flag]:
    """Steps: a machine value moving from one fit to the next beyond ``[drift]``'s limit and
    beyond k σ of the change. Drifts: the slope of the machine values since the last step
    (three fits at least), beyond the monthly limit and k σ of the slope. One pass: the
    slope's sums grow with each fit (linear in the number of fits)."""
    k = machine.drift.k_sigma
    out = []
    for n in names:
        run = [e for e in entries if n in e.values and e.std.get(n, 0.0) > 0]
        if not run:
            continue
        line, drifting = _Line(run[0].taken), False
        line.add(run[0], n)
        for i in range(1, len(run)):
            a, b = run[i - 1], run[i]
            change = b.machine_value(n) - a.machine_value(n)
            std = math.hypot(a.std[n], b.std[n])
            if abs(change) > limit_of(machine, b.units[n], name=n) and abs(change) > k * std:
                out.append(Flag("step", n, b.taken, change, std, b.units[n]))
                line, drifting = _Line(b.taken), False
                line.add(b, n)
                continue
            line.add(b, n)
            if line.count < 3 or drifting:
                continue
            rate, rate_std = line.slope()
            if abs(rate) > limit_of(machine, b.units[n], per_month=True) and abs(rate) > k * rate_std:
                out.append(Flag("drift", n, b.taken, rate, rate_std, b.units[n], line.since))
                drifting = True          # flagged once per run: the trend table shows the rest
    return sorted(out, key=lambda f: (f.taken, f.param))


class _Line:
    """A weighted least-squares line through machine values over months since ``since``,
    kept as its sums: the slope per month and its σ (scaled by the scatter when that exceeds
    the fits' own σ: a slope is not surer than its points)."""

    def __init__(self, since: str):
        self.since, self.count = since, 0
        self.s = np.zeros(6)          # Σw, Σwt, Σwt², Σwy, Σwty, Σwy²
        self.y0 = None                # values relative to the first: no cancellation in Σwy²

    def add(self, e: Entry, n: str) -> None:
        t = days(self.since, e.taken) / DAYS_PER_MONTH
        if self.y0 is None:
            self.y0 = e.machine_value(n)
        y, w = e.machine_value(n) - self.y0, 1.0 / e.std[n] ** 2
        self.s += w * np.array([1.0, t, t * t, y, t * y, y * y])
        self.count += 1

    def slope(self) -> tuple[float, float]:
        sw, st, stt, sy, sty, syy = self.s
        det = sw * stt - st * st
        if det <= 0:
            return 0.0, math.inf
        b = (sw * sty - st * sy) / det
        a = (sy - b * st) / sw
        chi2 = max(syy - 2 * a * sy - 2 * b * sty + a * a * sw + 2 * a * b * st + b * b * stt, 0.0)
        return float(b), float(math.sqrt(sw / det * max(chi2 / max(self.count - 2, 1), 1.0)))


def last_calibration(store: Store, machine: Machine, serial: str | None = None,
                     before: str | None = None) -> tuple[Entry, list[Entry], list[dict]]:
    """The last accepted calibration measured before ``before`` (default: any), and every fit
    and edit of the machine up to then."""
    entries, edits = _entries(store, machine_id(store, machine, serial))
    if before:
        entries = [e for e in entries if e.taken <= before]
        edits = [e for e in edits if e["taken"] <= before]
    accepted = [e for e in entries if e.kind == "calibration" and e.verdict == "accepted"]
    if not accepted:
        raise CompgenError("no accepted calibration of this machine is recorded (each recorded fit "
                           "has a reason it should not reach the control)", where=store.where,
                           hint=f"{me()} history show --machine {file_ref(machine)} lists them")
    calibration_fit(store, accepted[-1])
    return accepted[-1], entries, edits


def calibration_fit(store: Store, entry: Entry) -> FitResult:
    """The fit a reference was recorded from, trusted only as its own fit wrote it: its
    values, model and marker recomputed from the fit.json kept with it. A row whose values
    were written by hand (a writer of the database can append one) is named and refused,
    never compared against."""
    row = store.rows("SELECT model, parameters, fit_json FROM fits WHERE id = ?", (entry.id,))[0]
    who = f", recorded by {one_line(entry.recorded_by)}" if entry.recorded_by else ""
    try:
        fit = FitResult.from_dict(json.loads(row["fit_json"]))
        same = (json.loads(row["model"]) == list(fit.model) and fit.holds_marker(entry.marker)
                and json.loads(row["parameters"]) == {n: {"value": e.value, "std": e.std, "unit": e.unit}
                                                      for n, e in fit.parameters.items()})
    except (CompgenError, AttributeError, KeyError, TypeError, ValueError):   # JSON of any shape
        same = False
    if not same:
        raise CompgenError(f"the last accepted calibration (fit #{entry.id}, {one_line(entry.marker)}, "
                           f"{entry.taken[:16]}{who}) does not hold the values its own fit gives: the row "
                           "was not written by compgen's fit", where=store.where,
                           hint="ask the store's owner to look at that row; compgen checks against no "
                                "calibration it cannot trust")
    return fit


def fleet(store: Store, every_days: float, today: str | None = None) -> list[dict]:
    """Every machine: its last calibration and check, the last edit, and when a check is due."""
    out = []
    today = taken_at(today)
    latest = (datetime.now(UTC) + timedelta(days=1)).isoformat(timespec="seconds")    # as taken_at allows
    for m in store.rows("SELECT id, name, serial FROM machines ORDER BY name, serial"):
        fits = store.rows("SELECT f.kind, f.verdict, s.taken FROM fits f "
                          "JOIN sessions s ON s.id = f.session_id "
                          "WHERE s.machine_id = ? ORDER BY s.taken, f.id", (m["id"],))
        checks = store.rows("SELECT c.passed, s.taken FROM checks c JOIN fits f ON f.id = c.fit_id "
                            "JOIN sessions s ON s.id = f.session_id WHERE c.machine_id = ? "
                            "ORDER BY s.taken, c.id",
                            (m["id"],))
        edits = store.rows("SELECT taken FROM edits WHERE machine_id = ? ORDER BY taken", (m["id"],))
        try:
            for row in (*fits, *checks, *edits):
                row["taken"] = utc(row["taken"])
                if row["taken"] > latest:       # no due date follows from it (9999: past the calendar)
                    raise CompgenError(f"a stored date {row['taken'][:19]!r} lies after today: not one "
                                       "compgen writes")
        except CompgenError as exc:     # one machine's unreadable row: it says so, the rest go on
            out.append({"machine": m["name"], "serial": m["serial"], "fits": len(fits),
                        "last_calibration": None, "last_check": None, "last_check_passed": None,
                        "last_edit": None, "due": None, "overdue": False, "unreadable": exc.message})
            continue
        fits.sort(key=lambda f: f["taken"])
        checks.sort(key=lambda c: c["taken"])
        edits.sort(key=lambda e: e["taken"])
        calib = [f for f in fits if f["kind"] == "calibration" and f["verdict"] == "accepted"]
        last = max([f["taken"] for f in fits] or [""])
        due = (datetime.fromisoformat(last).timestamp() + every_days * 86400) if last else None
        out.append({"machine": m["name"], "serial": m["serial"], "fits": len(fits),
                    "last_calibration": calib[-1]["taken"] if calib else None,
                    "last_check": checks[-1]["taken"] if checks else None,
                    "last_check_passed": bool(checks[-1]["passed"]) if checks else None,
                    "last_edit": edits[-1]["taken"] if edits else None,
                    "due": datetime.fromtimestamp(due, UTC).date().isoformat() if due else None,
                    "overdue": bool(due and due < datetime.fromisoformat(today).timestamp())})
    return out
