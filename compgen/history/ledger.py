"""What the store holds of a machine's calibrations: dates as UTC instants, the machine's key,
and each fit and edit recorded once (its content hash the database's unique key)."""

from __future__ import annotations

import hashlib
import json
import re
import shlex
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime, timedelta

from .. import me
from ..data.rtest import device_of
from ..errors import CompgenError
from ..model.machine import Machine, identifier
from ..statistics.results import FitResult
from .store import Store, now

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


def utc(text: str) -> str:
    """A stored date as the UTC instant ``taken_at`` keeps (rows of an older compgen kept
    the offset they were given; this compgen's rows come back as they are)."""
    try:
        t = datetime.fromisoformat(text)
    except (TypeError, ValueError):      # a row compgen did not write: named, never a crash
        raise CompgenError(f"a stored date {str(text)[:40]!r} is not one compgen writes",
                           hint="ask the store's owner to look at that row") from None
    return (t if t.tzinfo else t.replace(tzinfo=UTC)).astimezone(UTC).isoformat(timespec="seconds")


def days(a: str, b: str) -> float:
    return (datetime.fromisoformat(b) - datetime.fromisoformat(a)).total_seconds() / 86400.0


def file_ref(machine: Machine) -> str:
    """The machine as a command names it, pasted into a shell: a bundled name or its file."""
    return shlex.quote(machine.bundled or machine.source)


def machine_key(machine: Machine, serial: str | None = None) -> tuple[str, str]:
    """The machine's name and serial as the history keys it: a ``--serial`` by the machine
    file's rule for one (one line: it is printed in every history text)."""
    if serial is not None and serial != "":
        identifier("serial", serial, "--serial")
    return machine.name, serial if serial is not None else machine.serial


def lookup_machine(store: Store, name: str, serial: str, create: bool) -> int | None:
    if create:     # two writers may meet here: the one that loses the race reads the winner's row
        store.rows("INSERT INTO machines (name, serial, recorded) VALUES (?, ?, ?) "
                   "ON CONFLICT (name, serial) DO NOTHING RETURNING id", (name, serial, now()))
    rows = store.rows("SELECT id FROM machines WHERE name = ? AND serial = ?", (name, serial))
    return int(rows[0]["id"]) if rows else None


def machine_id(store: Store, machine: Machine, serial: str | None = None) -> int:
    name, serial = machine_key(machine, serial)
    found = lookup_machine(store, name, serial, create=False)
    if found is None:
        known = store.rows("SELECT name, serial FROM machines ORDER BY name, serial")
        raise CompgenError(f"no calibration of {name!r}{f' serial {serial}' if serial else ''} is recorded",
                           where=store.where,
                           hint=(f"record one: {me()} history add FIT.json" if not known else
                                 "recorded: " + "; ".join(f"{r['name']}" + (f" ({r['serial']})" if r["serial"]
                                                                            else "") for r in known[:5])))
    return found


def content_key(*parts) -> str:
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
            mid = lookup_machine(store, name, serial, create=True)
            return session_and_fit(store, mid, fit, machine, when, device, operator, temperatures or {},
                                    kind, "; ".join(verdict) or "accepted")
    except Recorded:
        if not exist_ok:
            raise
        return int(_fit_rows(store, fit, name, serial)[0]["id"])


def _fit_rows(store: Store, fit: FitResult, name: str, serial: str) -> list[dict]:
    """The machine's rows of ``fit``: by its record marker (or an older row's short one)."""
    return store.rows("SELECT f.id, s.taken FROM fits f JOIN sessions s ON s.id = f.session_id "
                      "JOIN machines m ON m.id = s.machine_id WHERE f.marker IN (?, ?) AND m.name = ? "
                      "AND m.serial = ? ORDER BY f.id", (fit.record_marker, fit.marker, name, serial))


def session_and_fit(store: Store, mid: int, fit: FitResult, machine: Machine, taken: str, device: str,
                     operator: str, temperatures: Mapping[str, float], kind: str, verdict: str) -> int:
    """The two rows every measurement adds (inside the caller's transaction); the fit's id.
    A fit the machine's history holds already is refused (``Recorded``), the transaction
    undone: by compgen's look first, and by the database's unique key when two writers
    record it at once."""
    name, serial = store.rows("SELECT name, serial FROM machines WHERE id = ?", (mid,))[0].values()
    twice = Recorded(
        f"this fit ({fit.marker}) is already in the history", where=store.where,
        hint=f"{me()} history show --machine {file_ref(machine)} lists it")
    if _fit_rows(store, fit, name, serial):
        raise twice
    sid = store.insert("sessions", {
        "machine_id": mid, "taken": taken, "device": device, "operator": operator,
        "temperatures": dict(temperatures), "machine_sha256": machine.sha256,
        "data": [{"file": d.file, "sha256": d.sha256, "rows": d.rows} for d in fit.data],
        "recorded": now()})
    fid = store.insert("fits", {
        "session_id": sid, "marker": fit.record_marker, "kind": kind, "model": list(fit.model),
        "parameters": {n: {"value": e.value, "std": e.std, "unit": e.unit}
                       for n, e in fit.parameters.items()},
        "sigma_um": fit.residual["sigma_um"], "rms_um": fit.residual["rms_um"], "verdict": verdict,
        "fit_json": fit.to_dict(), "recorded": now(),
        "content_sha256": content_key("fit", name, serial, fit.record_marker)}, unique="content_sha256")
    if fid is None:
        raise twice
    return fid


def edit_of(store: Store, fit: FitResult, machine: Machine, serial: str | None = None) -> dict | None:
    """The edit recorded from ``fit``, if any: its id, when, and the files' checksums."""
    name, serial = machine_key(machine, serial)
    rows = store.rows("SELECT e.id, e.taken, e.written FROM edits e JOIN fits f ON f.id = e.fit_id "
                      "JOIN machines m ON m.id = e.machine_id WHERE f.marker IN (?, ?) AND m.name = ? "
                      "AND m.serial = ? ORDER BY e.id", (fit.record_marker, fit.marker, name, serial))
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
        rows = _fit_rows(store, fit, name, serial)
        if not rows:
            raise CompgenError(f"the edit's fit ({fit.marker}) is not in the history", where=store.where,
                               hint=f"record it first: {me()} history add FIT.json")
        when = taken_at(taken)
        if when < utc(rows[0]["taken"]):       # instants, not text (an older row kept its offset)
            raise CompgenError("an edit cannot come before the fit it was written from",
                               hint=f"the fit was measured {rows[0]['taken']}")
        refuse_second_edit(store, fit, machine, written, serial)
        eid = store.insert("edits", {
            "machine_id": lookup_machine(store, name, serial, create=False), "fit_id": rows[0]["id"],
            "controller": controller, "corrects": dict(corrects), "written": dict(written),
            "loaded": dict(loaded), "taken": when, "recorded": now(),
            "content_sha256": content_key("edit", name, serial, fit.record_marker)}, unique="content_sha256")
        if eid is None:         # another writer recorded it a moment ago
            raise Recorded(f"the edit from {fit.marker} is already in the history", where=store.where)
        return eid


def refuse_second_edit(store: Store, fit: FitResult, machine: Machine, written: Mapping[str, str],
                        serial: str | None, taken: str | None = None) -> None:
    """Before any file is written: the same edit again is ``Recorded``; another edit from a
    fit whose edit is recorded would count its correction twice in every later value; an
    edit dated before its fit as recorded is refused here too, not after its files are
    written."""
    if taken is not None:
        name, key = machine_key(machine, serial)
        rows = _fit_rows(store, fit, name, key)
        if rows and taken < utc(rows[0]["taken"]):
            raise CompgenError("an edit cannot come before the fit it was written from",
                               where=store.where, hint=f"the fit was measured {rows[0]['taken']}: give a "
                                                       "--date after it")
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
