"""A machine's calibrations over time: what the store holds, read as a trend, a step or a
drift, and a short check against the last accepted calibration.

Values compare across an edit: an edit written from a fit corrects that fit's location
errors, so after it the control should measure them less by as much. Each fit's *machine
value* is what it measured plus every correction written before it; a step or a drift is
judged on machine values, so an edit is never mistaken for a crash, and a crash after an
edit is still one.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import re
import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta

import numpy as np

from . import me
from .effects import effect_of_param
from .emit.registry import CONTROLLERS, controller
from .errors import CompgenError, one_line
from .machine import Machine, identifier
from .results import FitResult
from .rtest import device_of
from .store import Store, now
from .units import shown

DAYS_PER_MONTH = 30.0
DEVICES = ("rtest", "probe")


EARLIEST = datetime(1970, 1, 1, tzinfo=UTC)
DATE = re.compile(r"[0-9]{4}-[0-9]{2}-[0-9]{2}(?:[T ][0-9]{2}:[0-9]{2}(?::[0-9]{2}(?:\.[0-9]{1,6})?)?"
                  r"(?:Z|[+-][0-9]{2}:[0-9]{2})?)?")


def taken_at(text: str | None) -> str:
    """A session's date as given (ISO 8601, a date or a date and time; UTC if no zone), or
    now: stored as the UTC instant, so that dates given with different offsets compare in
    time order as the text they are kept as. None before 1970 or after tomorrow."""
    if not text:
        return now()
    # the forms people write, in ASCII digits: Python's own reader takes any character
    # between date and time ("2026-03-01\n2027" is 20:27), weeks and other scripts' digits
    if not isinstance(text, str) or not DATE.fullmatch(text):
        raise CompgenError(f"{text!r} is not a date",
                           hint="give it as 2026-07-15 or 2026-07-15T09:30+02:00") from None
    try:
        t = datetime.fromisoformat(text)
    except (ValueError, TypeError):
        raise CompgenError(f"{text!r} is not a date",
                           hint="give it as 2026-07-15 or 2026-07-15T09:30+02:00") from None
    t = (t if t.tzinfo else t.replace(tzinfo=UTC)).astimezone(UTC)
    if not EARLIEST <= t <= datetime.now(UTC) + timedelta(days=1):
        raise CompgenError(f"{text!r} is not a date a measurement was taken on (1970 to tomorrow)",
                           hint="check the year and the clock of the machine that wrote it")
    return t.isoformat(timespec="seconds")


def _utc(text: str) -> str:
    """A stored date as the UTC instant ``taken_at`` keeps (rows of an older compgen kept
    the offset they were given; this compgen's rows come back as they are)."""
    t = datetime.fromisoformat(text)
    return (t if t.tzinfo else t.replace(tzinfo=UTC)).astimezone(UTC).isoformat(timespec="seconds")


def _days(a: str, b: str) -> float:
    return (datetime.fromisoformat(b) - datetime.fromisoformat(a)).total_seconds() / 86400.0


def _ref(machine: Machine) -> str:
    """The machine as a command names it, pasted into a shell: a bundled name or its file."""
    return shlex.quote(machine.bundled or machine.source)


def machine_key(machine: Machine, serial: str | None = None) -> tuple[str, str]:
    """The machine's name and serial as the history keys it: a ``--serial`` by the machine
    file's rule for one (one line: it is printed in every history text)."""
    if serial is not None and serial != "":
        identifier("serial", serial, "--serial")
    return machine.name, serial if serial is not None else machine.serial


def _machine_id(store: Store, name: str, serial: str, create: bool) -> int | None:
    if create:     # two writers may meet here: the one that loses the race reads the winner's row
        store.rows("INSERT INTO machines (name, serial, recorded) VALUES (?, ?, ?) "
                   "ON CONFLICT (name, serial) DO NOTHING RETURNING id", (name, serial, now()))
    rows = store.rows("SELECT id FROM machines WHERE name = ? AND serial = ?", (name, serial))
    return int(rows[0]["id"]) if rows else None


def machine_id(store: Store, machine: Machine, serial: str | None = None) -> int:
    name, serial = machine_key(machine, serial)
    found = _machine_id(store, name, serial, create=False)
    if found is None:
        known = store.rows("SELECT name, serial FROM machines ORDER BY name, serial")
        raise CompgenError(f"no calibration of {name!r}{f' serial {serial}' if serial else ''} is recorded",
                           where=store.where,
                           hint=(f"record one: {me()} history add FIT.json" if not known else
                                 "recorded: " + "; ".join(f"{r['name']}" + (f" ({r['serial']})" if r["serial"]
                                                                            else "") for r in known[:5])))
    return found


def _key(*parts) -> str:
    """A row's content key: the same fit (or the edit from it) recorded twice is one row."""
    return hashlib.sha256(json.dumps(parts, ensure_ascii=False).encode()).hexdigest()


class Recorded(CompgenError):
    """The row is in the history already (found before writing, or by the database's key)."""


def record_fit(store: Store, fit: FitResult, machine: Machine, *, serial: str | None = None,
               taken: str | None = None, device: str | None = None, operator: str = "",
               temperatures: Mapping[str, float] | None = None, kind: str = "calibration",
               verdict: Sequence[str] = (), exist_ok: bool = False) -> int:
    """One session and its fit, in one transaction; returns the fit's id. ``verdict``: why
    the fit should not reach a control (``gate.fit_gate``), empty for an accepted fit. The
    same fit twice is refused, or with ``exist_ok`` its first record's id returned.
    ``device``: default, the one the fit's data came from."""
    device = device or device_of(fit.data)
    if device not in DEVICES:
        raise CompgenError(f"device must be one of {', '.join(DEVICES)}, not {device!r}")
    name, serial = machine_key(machine, serial)
    if fit.machine.get("sha256") and fit.machine["sha256"] != machine.sha256:
        raise CompgenError("the fit was made with another machine file than the one given",
                           hint="give the machine file the fit names, or refit")
    when = taken_at(taken)
    try:
        with store.writing():
            mid = _machine_id(store, name, serial, create=True)
            return _session_and_fit(store, mid, fit, machine, when, device, operator, temperatures or {},
                                    kind, "; ".join(verdict) or "accepted")
    except Recorded:
        if not exist_ok:
            raise
        return int(_fit_rows(store, fit.marker, name, serial)[0]["id"])


def _fit_rows(store: Store, marker: str, name: str, serial: str) -> list[dict]:
    return store.rows("SELECT f.id, s.taken FROM fits f JOIN sessions s ON s.id = f.session_id "
                      "JOIN machines m ON m.id = s.machine_id WHERE f.marker = ? AND m.name = ? "
                      "AND m.serial = ? ORDER BY f.id", (marker, name, serial))


def _session_and_fit(store: Store, mid: int, fit: FitResult, machine: Machine, taken: str, device: str,
                     operator: str, temperatures: Mapping[str, float], kind: str, verdict: str) -> int:
    """The two rows every measurement adds (inside the caller's transaction); the fit's id.
    A fit the machine's history holds already is refused (``Recorded``), the transaction
    undone: by compgen's look first, and by the database's unique key when two writers
    record it at once."""
    name, serial = store.rows("SELECT name, serial FROM machines WHERE id = ?", (mid,))[0].values()
    twice = Recorded(
        f"this fit ({fit.marker}) is already in the history", where=store.where,
        hint=f"{me()} history show --machine {_ref(machine)} lists it")
    if _fit_rows(store, fit.marker, name, serial):
        raise twice
    sid = store.insert("sessions", {
        "machine_id": mid, "taken": taken, "device": device, "operator": operator,
        "temperatures": dict(temperatures), "machine_sha256": machine.sha256,
        "data": [{"file": d.file, "sha256": d.sha256, "rows": d.rows} for d in fit.data],
        "recorded": now()})
    fid = store.insert("fits", {
        "session_id": sid, "marker": fit.marker, "kind": kind, "model": list(fit.model),
        "parameters": {n: {"value": e.value, "std": e.std, "unit": e.unit}
                       for n, e in fit.parameters.items()},
        "sigma_um": fit.residual["sigma_um"], "rms_um": fit.residual["rms_um"], "verdict": verdict,
        "fit_json": fit.to_dict(), "recorded": now(),
        "content_sha256": _key("fit", name, serial, fit.marker)}, unique="content_sha256")
    if fid is None:
        raise twice
    return fid


def edit_of(store: Store, fit: FitResult, machine: Machine, serial: str | None = None) -> dict | None:
    """The edit recorded from ``fit``, if any: its id, when, and the files' checksums."""
    name, serial = machine_key(machine, serial)
    rows = store.rows("SELECT e.id, e.taken, e.written FROM edits e JOIN fits f ON f.id = e.fit_id "
                      "JOIN machines m ON m.id = e.machine_id WHERE f.marker = ? AND m.name = ? "
                      "AND m.serial = ? ORDER BY e.id", (fit.marker, name, serial))
    return {**rows[0], "written": json.loads(rows[0]["written"])} if rows else None


def record_edit(store: Store, fit: FitResult, machine: Machine, controller: str,
                corrects: Mapping[str, float],
                written: Mapping[str, str], loaded: Mapping[str, str], *, serial: str | None = None,
                taken: str | None = None) -> int:
    """An edit written from ``fit`` (recorded before it): the location errors it corrects
    (name → value, mm or rad), the files written and those loaded on the control (name →
    SHA-256). One edit per fit: the same edit again is ``Recorded`` (its correction must
    not count twice), another edit from the same fit is refused."""
    name, serial = machine_key(machine, serial)
    with store.writing():
        rows = _fit_rows(store, fit.marker, name, serial)
        if not rows:
            raise CompgenError(f"the edit's fit ({fit.marker}) is not in the history", where=store.where,
                               hint=f"record it first: {me()} history add FIT.json")
        when = taken_at(taken)
        if when < rows[0]["taken"]:
            raise CompgenError("an edit cannot come before the fit it was written from",
                               hint=f"the fit was measured {rows[0]['taken']}")
        refuse_second_edit(store, fit, machine, written, serial)
        eid = store.insert("edits", {
            "machine_id": _machine_id(store, name, serial, create=False), "fit_id": rows[0]["id"],
            "controller": controller, "corrects": dict(corrects), "written": dict(written),
            "loaded": dict(loaded), "taken": when, "recorded": now(),
            "content_sha256": _key("edit", name, serial, fit.marker)}, unique="content_sha256")
        if eid is None:         # another writer recorded it a moment ago
            raise Recorded(f"the edit from {fit.marker} is already in the history", where=store.where)
        return eid


def refuse_second_edit(store: Store, fit: FitResult, machine: Machine, written: Mapping[str, str],
                        serial: str | None) -> None:
    """Before any file is written: the same edit again is ``Recorded``; another edit from a
    fit whose edit is recorded would count its correction twice in every later value."""
    had = edit_of(store, fit, machine, serial)
    if had is None:
        return
    if sorted(had["written"].values()) == sorted(written.values()):
        raise Recorded(f"this edit is recorded already (#{had['id']}, {had['taken'][:10]})",
                       where=store.where)
    raise CompgenError(f"an edit from {fit.marker} is recorded already (#{had['id']}, {had['taken'][:10]}), "
                       "with other files: a fit's correction is made once", where=store.where,
                       hint="leave out --record (the history keeps the edit that was loaded), or measure "
                            "again and write the edit from that fit")


# -- reading it back

@dataclass
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


@dataclass
class Flag:
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


@dataclass
class Trend:
    machine: str
    serial: str
    params: tuple[str, ...]
    entries: list[Entry]
    edits: list[dict]
    flags: list[Flag] = field(default_factory=list)


def _entries(store: Store, mid: int) -> tuple[list[Entry], list[dict]]:
    """The machine's fits in time order, each with the corrections written before it (one
    sweep through fits and edits together: linear in their number)."""
    fits = store.rows("SELECT f.id, f.marker, f.kind, f.parameters, f.sigma_um, f.verdict, "
                      "f.recorded_by, s.taken, s.device, s.machine_sha256 FROM fits f "
                      "JOIN sessions s ON s.id = f.session_id WHERE s.machine_id = ? "
                      "ORDER BY s.taken, f.id", (mid,))
    edits = store.rows("SELECT e.id, e.taken, e.controller, e.corrects, e.written, e.loaded, f.marker, "
                       "f.verdict FROM edits e JOIN fits f ON f.id = e.fit_id WHERE e.machine_id = ? "
                       "ORDER BY e.taken, e.id", (mid,))
    for e in edits:
        e["corrects"] = json.loads(e["corrects"])
        e["written"], e["loaded"] = json.loads(e["written"]), json.loads(e["loaded"])
        e["taken"] = _utc(e["taken"])
    for f in fits:
        f["taken"] = _utc(f["taken"])
    fits.sort(key=lambda f: (f["taken"], f["id"]))       # as instants: rows an older compgen kept
    edits.sort(key=lambda e: (e["taken"], e["id"]))      # with their offsets order as time does
    out = []
    corrected: dict[str, float] = {}
    done = 0
    for f in fits:
        while done < len(edits) and edits[done]["taken"] <= f["taken"]:
            for n, v in edits[done]["corrects"].items():
                corrected[n] = corrected.get(n, 0.0) + v
            done += 1
        p = json.loads(f["parameters"])
        out.append(Entry(f["id"], f["taken"], f["marker"], f["kind"], f["device"], f["verdict"],
                         f["sigma_um"],
                         {n: q["value"] for n, q in p.items()}, {n: q["std"] for n, q in p.items()},
                         {n: q["unit"] for n, q in p.items()}, dict(corrected),
                         f["recorded_by"] or "", f["machine_sha256"]))
    return out, edits


def machine_params(machine: Machine, names: Sequence[str]) -> tuple[str, ...]:
    """The location errors of the machine among ``names``: the ball's and the nest's
    set-up terms change with every set-up and are no history of the machine."""
    return tuple(n for n in names if effect_of_param(machine, n).carrier not in ("ball", "nest")
                 and effect_of_param(machine, n).basis.kind == "const")


def _limit(machine: Machine, unit: str, per_month: bool = False) -> float:
    d = machine.drift
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
    return Trend(name, serial, names, entries, edits, flags(machine, entries, names))


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
            if abs(change) > _limit(machine, b.units[n]) and abs(change) > k * std:
                out.append(Flag("step", n, b.taken, change, std, b.units[n]))
                line, drifting = _Line(b.taken), False
                line.add(b, n)
                continue
            line.add(b, n)
            if line.count < 3 or drifting:
                continue
            rate, rate_std = line.slope()
            if abs(rate) > _limit(machine, b.units[n], per_month=True) and abs(rate) > k * rate_std:
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
        t = _days(self.since, e.taken) / DAYS_PER_MONTH
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
                           hint=f"{me()} history show --machine {_ref(machine)} lists them")
    _as_fitted(store, accepted[-1])
    return accepted[-1], entries, edits


def _as_fitted(store: Store, entry: Entry) -> None:
    """A reference is trusted only as its own fit wrote it: its values, model and marker
    recomputed from the fit.json kept with it. A row whose values were written by hand (a
    writer of the database can append one) is named and refused, never compared against."""
    row = store.rows("SELECT model, parameters, fit_json FROM fits WHERE id = ?", (entry.id,))[0]
    who = f", recorded by {one_line(entry.recorded_by)}" if entry.recorded_by else ""
    try:
        fit = FitResult.from_dict(json.loads(row["fit_json"]))
        same = (json.loads(row["model"]) == list(fit.model) and fit.marker == entry.marker
                and json.loads(row["parameters"]) == {n: {"value": e.value, "std": e.std, "unit": e.unit}
                                                      for n, e in fit.parameters.items()})
    except (CompgenError, KeyError, TypeError, ValueError):
        same = False
    if not same:
        raise CompgenError(f"the last accepted calibration (fit #{entry.id}, {one_line(entry.marker)}, "
                           f"{entry.taken[:16]}{who}) does not hold the values its own fit gives: the row "
                           "was not written by compgen's fit", where=store.where,
                           hint="ask the store's owner to look at that row; compgen checks against no "
                                "calibration it cannot trust")


def fleet(store: Store, every_days: float, today: str | None = None) -> list[dict]:
    """Every machine: its last calibration and check, the last edit, and when a check is due."""
    out = []
    today = taken_at(today)
    for m in store.rows("SELECT id, name, serial FROM machines ORDER BY name, serial"):
        fits = store.rows("SELECT f.kind, f.verdict, s.taken FROM fits f "
                          "JOIN sessions s ON s.id = f.session_id "
                          "WHERE s.machine_id = ? ORDER BY s.taken, f.id", (m["id"],))
        checks = store.rows("SELECT c.passed, s.taken FROM checks c JOIN fits f ON f.id = c.fit_id "
                            "JOIN sessions s ON s.id = f.session_id WHERE c.machine_id = ? "
                            "ORDER BY s.taken, c.id",
                            (m["id"],))
        edits = store.rows("SELECT taken FROM edits WHERE machine_id = ? ORDER BY taken", (m["id"],))
        for row in (*fits, *checks, *edits):
            row["taken"] = _utc(row["taken"])
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


def export_rows(store: Store, machine_name: str | None = None) -> list[dict]:
    """One row per fit and parameter: the flat table a spreadsheet or a plant's database takes."""
    sql = ("SELECT m.name, m.serial, s.taken, s.device, s.operator, f.marker, f.kind, f.verdict, f.sigma_um, "
           "f.parameters FROM fits f JOIN sessions s ON s.id = f.session_id "
           "JOIN machines m ON m.id = s.machine_id"
           + (" WHERE m.name = ?" if machine_name else "") + " ORDER BY m.name, m.serial, s.taken, f.id")
    out = []
    for r in store.rows(sql, (machine_name,) if machine_name else ()):
        for n, p in json.loads(r.pop("parameters")).items():
            out.append({**r, "parameter": n, "value": p["value"], "std": p["std"], "unit": p["unit"]})
    return out


EXPORT_FIELDS = ["name", "serial", "taken", "device", "operator", "marker", "kind", "verdict", "sigma_um",
                 "parameter", "value", "std", "unit"]


def export_text(store: Store, machine_name: str | None, whole: bool) -> tuple[int, str]:
    """The export's rows counted and its text: JSON, the whole history (what ``import``
    reads) with the flat rows, when ``whole``; else the flat rows as CSV."""
    if whole:
        doc = export_all(store, machine_name)
        return len(doc["rows"]), json.dumps(doc, indent=2, ensure_ascii=False) + "\n"
    rows = export_rows(store, machine_name)
    out = io.StringIO()
    w = csv.DictWriter(out, EXPORT_FIELDS, lineterminator="\n")
    w.writeheader()
    w.writerows({k: r[k] for k in EXPORT_FIELDS} for r in rows)
    return len(rows), out.getvalue()


def machines_text(store: Store) -> str:
    """Every machine in the store, with its number of fits and its last one, a line each."""
    rows = store.rows("SELECT m.name, m.serial, COUNT(f.id) AS fits, MAX(s.taken) AS last FROM machines m "
                      "LEFT JOIN sessions s ON s.machine_id = m.id LEFT JOIN fits f ON f.session_id = s.id "
                      "GROUP BY m.id, m.name, m.serial ORDER BY m.name, m.serial")
    if not rows:
        return f"{store.where}: no machine recorded yet"
    lines = []
    for r in rows:
        serial = f" ({one_line(r['serial'])})" if r["serial"] else ""
        lines.append(f"{one_line(r['name'])}{serial}: {r['fits']} fit(s), last {str(r['last'])[:16]}")
    return "\n".join(lines)


# -- a check against the last calibration

@dataclass
class Change:
    param: str
    change: float          # machine value now minus at the calibration (mm, rad)
    std: float
    unit: str
    limit: float
    status: str            # "pass", "fail", or "unsure" (beyond the limit, but not beyond k σ)
    words: str

    def text(self) -> str:
        v, u = shown(self.change, self.unit)
        s, _ = shown(self.std, self.unit)
        lim, _ = shown(self.limit, self.unit)
        return (f"  {self.param:<6}{v:>+9.2f} ± {s:.2f} {u:<7}limit {lim:g} {u:<7}"
                f"{self.status.upper():<7}{self.words}")


@dataclass
class CheckResult:
    machine: str
    serial: str
    against: Entry
    marker: str
    taken: str
    changes: list[Change]
    sigma_um: float
    paths: dict[str, str]          # path → PASS/FAIL against [tolerances]
    flags: list[Flag]
    advice: list[str]
    machine_changed: bool = False    # checked with another machine file than the calibration's

    @property
    def passed(self) -> bool:
        """Every location error within its limit and every path within its tolerance; a
        change too uncertain to judge does not pass (a drift within limits does, with advice)."""
        return (all(c.status == "pass" for c in self.changes)
                and not any(v.startswith("FAIL") for v in self.paths.values()))

    def summary(self) -> dict:
        return {"format": "compgen.check/1", "machine": self.machine, "serial": self.serial,
                "passed": self.passed, "taken": self.taken, "fit": self.marker,
                "against": {"fit": self.against.marker, "taken": self.against.taken},
                "sigma_um": self.sigma_um, "paths": self.paths,
                "changes": [{"parameter": c.param, "change": c.change, "std": c.std, "unit": c.unit,
                             "limit": c.limit, "status": c.status} for c in self.changes],
                "flags": [f.text() for f in self.flags], "advice": self.advice,
                "machine_file_changed": self.machine_changed,
                **({"recorded_by": self.against.recorded_by} if self.against.recorded_by else {})}

    def text(self) -> str:
        who = f", recorded by {one_line(self.against.recorded_by)}" if self.against.recorded_by else ""
        serial = f" ({one_line(self.serial)})" if self.serial else ""
        lines = [f"compgen check: {one_line(self.machine)}{serial}, "
                 f"measured {self.taken[:16]}",
                 f"  against the calibration of {self.against.taken[:16]} ({self.against.marker}{who}), "
                 "corrections written since counted"]
        if self.machine_changed:
            lines.append("  with a machine file changed since that calibration (--machine-changed)")
        lines += ["", f"  {'param':<6}{'change':>9}   {'σ':<12}{'':<16}{'status':<7}"]
        lines += [c.text() for c in self.changes]
        lines.append(f"\n  residual σ̂ {self.sigma_um:.3f} µm (the calibration's "
                     f"{self.against.sigma_um:.3f} µm)")
        lines += [f"  {p}: {v} µm range beyond the set-up" for p, v in self.paths.items()]
        lines += [f"  flagged: {f.text()}" for f in self.flags]
        lines += ["", "PASS: the machine is where its last calibration left it" if self.passed else "FAIL"]
        lines += [f"  next: {a}" for a in self.advice]
        return "\n".join(lines) + "\n"


def check(machine: Machine, fit: FitResult, data, calibration: Entry, entries: Sequence[Entry],
          edits: Sequence[dict], taken: str, serial: str | None = None,
          machine_changed: bool = False) -> CheckResult:
    """A short measurement's fit against the last accepted calibration: each location
    error's change (machine values: the corrections written since are counted) with its σ,
    the paths against ``[tolerances]``, and a drift or step it completes. A machine file
    other than the calibration's is refused: its nominal geometry, limits or tolerances may
    differ, and the changes would be measured against another machine; ``machine_changed``
    checks anyway and says so."""
    from .identify import beyond_setup
    from .kinematics import Poses

    name, serial = machine_key(machine, serial)
    changed = bool(calibration.machine_sha256) and calibration.machine_sha256 != machine.sha256
    if changed and not machine_changed:
        raise CompgenError(f"the machine file changed since the calibration of {calibration.taken[:16]} "
                           f"(SHA-256 {calibration.machine_sha256[:12]}… then, {machine.sha256[:12]}… now)",
                           where=machine.source,
                           hint="check with the machine file of then; or, if the change is known (a "
                                "tolerance, a limit), add --machine-changed; after a change of geometry, "
                                "calibrate again")
    k = machine.drift.k_sigma
    corrected: dict[str, float] = {}
    for e in edits:
        if e["taken"] <= taken:
            for n, v in e["corrects"].items():
                corrected[n] = corrected.get(n, 0.0) + v
    now_entry = Entry(0, taken, fit.marker, "check", "rtest", "", fit.residual["sigma_um"],
                      {n: e.value for n, e in fit.parameters.items()},
                      {n: e.std for n, e in fit.parameters.items()},
                      {n: e.unit for n, e in fit.parameters.items()}, corrected)
    names = [n for n in machine_params(machine, fit.model) if n in calibration.values]
    changes = []
    for n in names:
        change = now_entry.machine_value(n) - calibration.machine_value(n)
        std = math.hypot(now_entry.std[n], calibration.std[n])
        limit = _limit(machine, now_entry.units[n])
        status = "pass" if abs(change) <= limit else ("fail" if abs(change) > k * std else "unsure")
        changes.append(Change(n, change, std, now_entry.units[n], limit, status,
                              effect_of_param(machine, n).words))
    got = beyond_setup(machine, Poses.concat([d.poses for d in data]),
                       np.concatenate([d.deviation for d in data]))
    paths = {}
    for p, stats in got["per_path"].items():
        if p in machine.tolerances:
            worst = max(stats["range_um"])
            tol = machine.tolerances[p]
            paths[p] = f"PASS {worst:.2f} <= {tol:g}" if worst <= tol else f"FAIL {worst:.2f} > {tol:g}"
    series = [e for e in entries if e.taken <= taken] + [now_entry]
    new_flags = [f for f in flags(machine, series, names) if f.taken == taken]
    advice = []
    failed = [c for c in changes if c.status == "fail"]
    if failed:
        worst = max(failed, key=lambda c: abs(c.change) / c.limit)
        advice.append(f"re-calibrate: {', '.join(c.param for c in failed)} moved beyond its limit "
                      f"({worst.param}, {worst.words}, most); measure all paths ({me()} measure-program "
                      f"--machine {_ref(machine)} --path all -o calibration"
                      f"{controller(machine.controller).program_ext}), fit, and write the edit with "
                      "kinematics")
        axes = {c.param[-1] for c in failed}      # ISO 230 symbols end with the axis they locate
        if len(axes) == 1:
            axis = axes.pop()
            advice.append(f"look at axis {axis} first: a location error of one axis moving alone points "
                          "to a collision, a loosened clamp or a bearing, not to temperature")
    if any(c.status == "unsure" for c in changes):
        advice.append("measure more (all paths, or the check path twice): "
                      + ", ".join(c.param for c in changes if c.status == "unsure")
                      + " may have moved beyond its limit, but its σ is too large to say")
    if fit.residual["sigma_um"] > 2.0 * calibration.sigma_um and fit.residual["sigma_um"] > 1.0:
        advice.append(f"check the set-up: the residual σ̂ is {fit.residual['sigma_um']:.2f} µm against the "
                      f"calibration's {calibration.sigma_um:.2f} µm (ball stem, nest, temperature, a loose "
                      "magnet base)")
    if any(v.startswith("FAIL") for v in paths.values()):
        advice.append("a path is beyond its tolerance: re-calibrate, then compare the predicted residual"
                      if failed else
                      "the location errors are where the last calibration found them, but a path is beyond "
                      f"its tolerance: that calibration ({calibration.marker}, {calibration.taken[:10]}) "
                      "is not corrected on the control; write the edit from its fit.json with kinematics, "
                      "and load it")
    for f in new_flags:
        if f.kind == "drift":
            advice.append(f"{f.param} drifts steadily ({f.text().split('  ', 1)[1]}): plan the next "
                          "calibration before it reaches its limit, and look for its cause (warm-up, season)")
    return CheckResult(name, serial, calibration, fit.marker, taken, changes, fit.residual["sigma_um"],
                       paths, new_flags, advice, changed)


def record_check(store: Store, result: CheckResult, fit: FitResult, machine: Machine, *,
                 serial: str | None = None, operator: str = "") -> int:
    """The check's session, its fit and its verdict, in one transaction."""
    name, serial = machine_key(machine, serial)
    with store.writing():
        mid = _machine_id(store, name, serial, create=False)
        fid = _session_and_fit(store, mid, fit, machine, result.taken, device_of(fit.data), operator, {},
                               "check",
                               "check passed" if result.passed else "check failed")
        return store.insert("checks", {"machine_id": mid, "fit_id": fid, "against_fit_id": result.against.id,
                                       "passed": int(result.passed), "summary": result.summary(),
                                       "recorded": now()})


# -- the trend as text and JSON

def trend_dict(t: Trend) -> dict:
    return {"format": "compgen.trend/1", "machine": t.machine, "serial": t.serial,
            "parameters": list(t.params),
            "fits": [{"taken": e.taken, "fit": e.marker, "kind": e.kind, "device": e.device,
                      "verdict": e.verdict, "sigma_um": e.sigma_um,
                      "values": {n: {"measured": e.values[n], "machine": e.machine_value(n), "std": e.std[n],
                                     "unit": e.units[n]} for n in t.params if n in e.values}}
                     for e in t.entries],
            "edits": [{"taken": e["taken"], "fit": e["marker"], "controller": e["controller"],
                       "corrects": e["corrects"], "written": e["written"], "loaded": e["loaded"]}
                      for e in t.edits],
            "flags": [{"kind": f.kind, "parameter": f.param, "taken": f.taken, "change": f.change,
                       "std": f.std, "unit": f.unit, "since": f.since, "text": f.text()} for f in t.flags]}


def trend_text(t: Trend) -> str:
    """One row per fit: each location error's machine value ± σ (µm, ″); edits between."""
    units = {n: shown(1.0, next(e.units[n] for e in t.entries if n in e.units))[1] for n in t.params}
    head = "".join(f"{n + ' ' + units[n]:>18}" for n in t.params)
    serial = f" ({one_line(t.serial)})" if t.serial else ""
    lines = [f"{one_line(t.machine)}{serial}: machine values (measured + corrections "
             "written before), ± σ", f"{'date':<12}{'fit':<11}{'kind':<12}{head}"]
    events = [(e.taken, 1, e) for e in t.entries] + [(d["taken"], 0, d) for d in t.edits]
    for _, is_fit, e in sorted(events, key=lambda x: (x[0], x[1])):
        if not is_fit:
            lines.append(f"{e['taken'][:10]:<12}{'edit':<11}{e['controller'][:11]:<12}corrects "
                         + ", ".join(map(one_line, e["corrects"])) + f" (from {one_line(e['marker'])}"
                         + (f", written despite the fit gate: {one_line(e['verdict'])})"
                            if e["verdict"] != "accepted"
                            else ")"))
            continue
        cells = []
        for n in t.params:
            if n not in e.values:
                cells.append(f"{'-':>18}")
                continue
            v, _ = shown(e.machine_value(n), e.units[n])
            s, _ = shown(e.std[n], e.units[n])
            mark = "*" if any(f.param == n and f.taken == e.taken for f in t.flags) else " "
            cells.append(f"{v:>10.2f} ± {s:<4.2f}{mark}")
        lines.append(f"{e.taken[:10]:<12}{one_line(e.marker):<11}{e.kind:<12}{''.join(cells)}")
    lines.append("")
    lines += [f"flagged: {f.text()}" for f in t.flags] or ["nothing flagged against [drift]"]
    return "\n".join(lines) + "\n"


# -- moving a history between stores: exported whole, imported only when asked

EXPORT_FORMAT = "compgen.history-export/1"
_COLUMNS = {
    "machines": ("id", "name", "serial", "recorded"),
    "sessions": ("id", "machine_id", "taken", "device", "operator", "temperatures", "machine_sha256", "data",
                 "recorded"),
    "fits": ("id", "session_id", "marker", "kind", "model", "parameters", "sigma_um", "rms_um", "verdict",
             "fit_json", "recorded"),
    "edits": ("id", "machine_id", "fit_id", "controller", "corrects", "written", "loaded", "taken",
              "recorded"),
    "checks": ("id", "machine_id", "fit_id", "against_fit_id", "passed", "summary", "recorded"),
}


def export_all(store: Store, machine_name: str | None = None) -> dict:
    """The store's rows (of one machine, or all), with the store's id: what ``import_history``
    takes, and the flat rows a spreadsheet takes."""
    mids = [r["id"] for r in store.rows("SELECT id, name FROM machines ORDER BY id")
            if machine_name is None or r["name"] == machine_name]
    keep = ",".join(str(int(m)) for m in mids) or "NULL"
    where = {"machines": f"id IN ({keep})", "sessions": f"machine_id IN ({keep})",
             "fits": f"session_id IN (SELECT id FROM sessions WHERE machine_id IN ({keep}))",
             "edits": f"machine_id IN ({keep})", "checks": f"machine_id IN ({keep})"}
    tables = {t: store.rows(f"SELECT {', '.join(c)} FROM {t} WHERE {where[t]} ORDER BY id")
              for t, c in _COLUMNS.items()}
    return {"format": EXPORT_FORMAT, "store_id": store.store_id(), "exported": now(), "tables": tables,
            "rows": export_rows(store, machine_name)}


def check_export(doc, where: str) -> dict[str, list]:
    """An export's tables, every row checked (``_valid_rows``): what is not a history export
    compgen wrote is refused before any store is opened (or made) for it."""
    if (not isinstance(doc, dict) or doc.get("format") != EXPORT_FORMAT
            or not isinstance(doc.get("tables"), dict)):
        raise CompgenError("not a compgen history export", where=where,
                           hint=f"make one with {me()} history export -o H.json on the other store")
    try:
        t = {name: list(doc["tables"][name]) for name in _COLUMNS}
    except (KeyError, TypeError) as exc:
        raise CompgenError(f"the export is incomplete or damaged ({exc!r})", where=where) from None
    _valid_rows(t, where)
    return t


def _valid_rows(t: dict[str, list], where: str) -> None:
    """Every row of an export as compgen writes its rows, checked before anything is written
    (a row the store would keep forever must not break every later read): dates (normalised to
    UTC), one-line names, JSON columns, finite numbers, kinds, controllers, ids that exist,
    and each fit's marker recomputed from its own fit_json."""
    def bad(table, row, what):
        rid = row.get("id") if isinstance(row, dict) else None
        raise CompgenError(f"{table} row {rid!r}: {what}; nothing was imported", where=where,
                           hint="import an export compgen wrote, unchanged")

    def text(table, row, key, line=True):
        v = row.get(key)
        if not isinstance(v, str) or (line and one_line(v) != v):
            bad(table, row, f"{key} is not one line of text")
        return v

    def doc(table, row, key, kind):
        v = row.get(key)
        try:
            v = json.loads(v) if isinstance(v, str) else v
        except ValueError:
            bad(table, row, f"{key} is not JSON")
        if not isinstance(v, kind):
            bad(table, row, f"{key} is not a JSON {kind.__name__}")
        return v

    def finite(table, row, key):
        v = row.get(key)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            bad(table, row, f"{key} is not a finite number")

    for table, rows in t.items():
        for row in rows:
            if not isinstance(row, dict) or type(row.get("id")) is not int:
                bad(table, row if isinstance(row, dict) else {}, "no whole-number id")
            if set(row) != set(_COLUMNS[table]):
                odd = sorted(set(row) ^ set(_COLUMNS[table]))
                bad(table, row, f"its columns are not a {table[:-1]}'s ({', '.join(odd)})")
    ids = {table: {r["id"] for r in rows} for table, rows in t.items()}
    for table, refs in (("sessions", {"machine_id": "machines"}), ("fits", {"session_id": "sessions"}),
                        ("edits", {"machine_id": "machines", "fit_id": "fits"}),
                        ("checks", {"machine_id": "machines", "fit_id": "fits", "against_fit_id": "fits"})):
        for row in t[table]:
            for key, other in refs.items():
                if row.get(key) not in ids[other]:
                    bad(table, row, f"{key} names no {other[:-1]} of the export")
    for m in t["machines"]:
        text("machines", m, "name")
        if text("machines", m, "serial"):
            try:
                identifier("serial", m["serial"], "serial")
            except CompgenError as exc:
                bad("machines", m, exc.message)
    for s in t["sessions"]:
        try:
            s["taken"] = taken_at(text("sessions", s, "taken"))
        except CompgenError as exc:
            bad("sessions", s, exc.message)
        text("sessions", s, "device"), text("sessions", s, "operator")
        temps = doc("sessions", s, "temperatures", dict)
        if not all(isinstance(v, int | float) and math.isfinite(v) for v in temps.values()):
            bad("sessions", s, "a temperature is not a finite number")
        doc("sessions", s, "data", list)
    for f in t["fits"]:
        if f.get("kind") not in ("calibration", "check"):
            bad("fits", f, "kind is neither calibration nor check")
        finite("fits", f, "sigma_um"), finite("fits", f, "rms_um")
        text("fits", f, "verdict")
        model, params = doc("fits", f, "model", list), doc("fits", f, "parameters", dict)
        for q in params.values():
            if not isinstance(q, dict) or not all(isinstance(q.get(k), int | float) and math.isfinite(q[k])
                                                  for k in ("value", "std")):
                bad("fits", f, "a parameter's value or σ is not a finite number")
        try:
            fit = FitResult.from_dict(doc("fits", f, "fit_json", dict))
        except (CompgenError, KeyError, TypeError, ValueError):
            bad("fits", f, "fit_json is not a fit compgen wrote")
        marker = fit.marker
        if model != list(fit.model) or params != {n: {"value": e.value, "std": e.std, "unit": e.unit}
                                                  for n, e in fit.parameters.items()}:
            bad("fits", f, "its model or parameters are not its fit_json's: the row was changed")
        if marker != f.get("marker"):
            bad("fits", f, f"its marker {f.get('marker')!r} is not its fit's ({marker}): the row was changed")
    for e in t["edits"]:
        if e.get("controller") not in CONTROLLERS:
            bad("edits", e, "controller is none compgen knows")
        for key in ("corrects", "written", "loaded"):
            doc("edits", e, key, dict)
        try:
            e["taken"] = taken_at(text("edits", e, "taken"))
        except CompgenError as exc:
            bad("edits", e, exc.message)
    for c in t["checks"]:
        if c.get("passed") not in (0, 1) or isinstance(c.get("passed"), bool):
            bad("checks", c, "passed is neither 0 nor 1")
        doc("checks", c, "summary", dict)


def import_history(store: Store, doc: dict, sha256: str, where: str) -> dict[str, int]:
    """Another store's export, appended in one transaction with its origin recorded. Refused:
    this store's own rows, an export already imported, or a fit this store already holds
    (for the same machine): nothing is merged silently, and nothing twice."""
    t = check_export(doc, where)
    if doc.get("store_id") == store.store_id():
        raise CompgenError("this export is this store's own history", where=where,
                           hint="nothing to import")
    if store.rows("SELECT id FROM imports WHERE file_sha256 = ?", (sha256,)):
        raise CompgenError("this export has been imported here already", where=where,
                           hint="nothing to import")
    try:
        machines = {m["id"]: (m["name"], m["serial"]) for m in t["machines"]}
        session_machine = {s["id"]: machines[s["machine_id"]] for s in t["sessions"]}
        held = {(session_machine[f["session_id"]], f["marker"]) for f in t["fits"]}
    except (KeyError, TypeError) as exc:
        raise CompgenError(f"the export is incomplete or damaged ({exc!r})", where=where) from None
    # a machine of the same name and serial here is the same machine only if it was measured
    # with a machine file this store has seen for it (two plants' "DMU-50" without serials are
    # two machines, never merged silently)
    files_here: dict[tuple, set] = {}
    for r in store.rows("SELECT m.name, m.serial, s.machine_sha256 FROM sessions s "
                        "JOIN machines m ON m.id = s.machine_id"):
        files_here.setdefault((r["name"], r["serial"]), set()).add(r["machine_sha256"])
    for s in t["sessions"]:
        key = machines[s["machine_id"]]
        if key in files_here and s["machine_sha256"] not in files_here[key]:
            raise CompgenError(f"machine {key[0]!r}{f' serial {key[1]}' if key[1] else ''} of the export was "
                               "measured with a machine file this store never saw for it: another machine "
                               "of the same name?", where=where,
                               hint="give each machine its serial in its machine file, or import into "
                                    "another store; nothing was imported")
    mine = {((r["name"], r["serial"]), r["marker"]) for r in store.rows(
        "SELECT m.name, m.serial, f.marker FROM fits f JOIN sessions s ON s.id = f.session_id "
        "JOIN machines m ON m.id = s.machine_id")}
    twice = sorted(held & mine)
    if twice:
        raise CompgenError(f"{len(twice)} fit(s) of the export are already here (first: {twice[0][1]} of "
                           f"{twice[0][0][0]!r})", where=where,
                           hint="the two stores share history: import into a fresh store, or keep them apart")
    ids: dict[str, dict] = {name: {} for name in _COLUMNS}
    with store.writing():
        imp = store.insert("imports", {"origin_store": str(doc["store_id"]), "file_sha256": sha256,
                                       "recorded": now()})
        for m in t["machines"]:
            ids["machines"][m["id"]] = _machine_id(store, m["name"], m["serial"], create=True)
        for s in t["sessions"]:
            ids["sessions"][s["id"]] = store.insert("sessions", {
                **{k: s[k] for k in _COLUMNS["sessions"][2:]}, "machine_id": ids["machines"][s["machine_id"]],
                "import_id": imp})
        markers = {}
        for f in t["fits"]:
            name, serial = session_machine[f["session_id"]]
            markers[f["id"]] = f["marker"]
            ids["fits"][f["id"]] = store.insert("fits", {
                **{k: f[k] for k in _COLUMNS["fits"][2:]}, "session_id": ids["sessions"][f["session_id"]],
                "content_sha256": _key("fit", name, serial, f["marker"])}, unique="content_sha256")
            if ids["fits"][f["id"]] is None:
                raise CompgenError(f"the export holds fit {f['marker']} of {name!r} twice; nothing was "
                                   "imported", where=where, hint="import an export compgen wrote, unchanged")
        for e in t["edits"]:
            name, serial = machines[e["machine_id"]]
            if store.insert("edits", {**{k: e[k] for k in _COLUMNS["edits"][3:]},
                                      "machine_id": ids["machines"][e["machine_id"]],
                                      "fit_id": ids["fits"][e["fit_id"]],
                                      "content_sha256": _key("edit", name, serial, markers[e["fit_id"]])},
                            unique="content_sha256") is None:
                raise CompgenError(f"the export holds two edits from fit {markers[e['fit_id']]} of {name!r}; "
                                   "nothing was imported", where=where,
                                   hint="a fit's correction is made once: import an export compgen wrote")
        for c in t["checks"]:
            store.insert("checks", {**{k: c[k] for k in _COLUMNS["checks"][4:]},
                                    "machine_id": ids["machines"][c["machine_id"]],
                                    "fit_id": ids["fits"][c["fit_id"]],
                                    "against_fit_id": ids["fits"][c["against_fit_id"]]})
    return {name: len(t[name]) for name in _COLUMNS}
