"""Moving a history between stores: exported whole, imported only when every row is valid,
and the flat rows a spreadsheet takes."""

from __future__ import annotations

import csv
import io
import json
import math
import re
import shlex
from collections.abc import Collection

from .. import me
from ..controllers.registry import CONTROLLERS
from ..errors import CompgenError, one_line
from ..model.machine import identifier
from ..statistics.gate import SIGMA_PLAUSIBLE_UM
from ..statistics.results import SHORT_MARKER, FitResult
from .ledger import content_key, lookup_machine, taken_at
from .store import Store, now


def export_rows(store: Store, machine_name: str | None = None,
                fits: Collection[int] | None = None) -> list[dict]:
    """One row per fit and parameter: the flat table a spreadsheet or a plant's database takes
    (of the fits whose ids are ``fits``, where given: the readable ones)."""
    sql = ("SELECT f.id, m.name, m.serial, s.taken, s.device, s.operator, f.marker, f.kind, f.verdict, "
           "f.sigma_um, f.parameters FROM fits f JOIN sessions s ON s.id = f.session_id "
           "JOIN machines m ON m.id = s.machine_id"
           + (" WHERE m.name = ?" if machine_name else "") + " ORDER BY m.name, m.serial, s.taken, f.id")
    out = []
    for r in store.rows(sql, (machine_name,) if machine_name else ()):
        fid = r.pop("id")
        if fits is not None and fid not in fits:
            continue
        for n, p in json.loads(r.pop("parameters")).items():
            out.append({**r, "parameter": n, "value": p["value"], "std": p["std"], "unit": p["unit"]})
    return out


EXPORT_FIELDS = ["name", "serial", "taken", "device", "operator", "marker", "kind", "verdict", "sigma_um",
                 "parameter", "value", "std", "unit"]


def export_text(store: Store, machine_name: str | None, whole: bool) -> tuple[int, str, list[str]]:
    """The export's rows counted, its text, and the rows it left out (each said as why):
    JSON, the whole history (what ``import`` reads) with the flat rows, when ``whole``; else
    the flat rows as CSV."""
    doc = export_all(store, machine_name)
    if whole:
        return len(doc["rows"]), json.dumps(doc, indent=2, ensure_ascii=False) + "\n", doc["left_out"]
    out = io.StringIO()
    w = csv.DictWriter(out, EXPORT_FIELDS, lineterminator="\n")
    w.writeheader()
    w.writerows({k: r[k] for k in EXPORT_FIELDS} for r in doc["rows"])
    return len(doc["rows"]), out.getvalue(), doc["left_out"]


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
    takes, and the flat rows a spreadsheet takes. A row compgen cannot read (another writer's
    to an SQLite file, which the database does not hold) is left out with every row that
    names it, and said in ``left_out``: one such row broke the export for everyone, and an
    export holding it would not import."""
    mids = [r["id"] for r in store.rows("SELECT id, name FROM machines ORDER BY id")
            if machine_name is None or r["name"] == machine_name]
    keep = ",".join(str(int(m)) for m in mids) or "NULL"
    where = {"machines": f"id IN ({keep})", "sessions": f"machine_id IN ({keep})",
             "fits": f"session_id IN (SELECT id FROM sessions WHERE machine_id IN ({keep}))",
             "edits": f"machine_id IN ({keep})", "checks": f"machine_id IN ({keep})"}
    tables = {t: store.rows(f"SELECT {', '.join(c)} FROM {t} WHERE {where[t]} ORDER BY id")
              for t, c in _COLUMNS.items()}
    left_out = _readable(tables, store.where)
    return {"format": EXPORT_FORMAT, "store_id": store.store_id(), "exported": now(), "tables": tables,
            "rows": export_rows(store, machine_name, {f["id"] for f in tables["fits"]}), "left_out": left_out}


# the rows that name a row of each table: a row left out takes them with it
_NAMED_BY = {"machines": (("sessions", "machine_id"), ("edits", "machine_id"), ("checks", "machine_id")),
             "sessions": (("fits", "session_id"),),
             "fits": (("edits", "fit_id"), ("checks", "fit_id"), ("checks", "against_fit_id")),
             "edits": (), "checks": ()}


def _readable(tables: dict[str, list], where: str) -> list[str]:
    """``tables`` cut, in place, to the rows an import accepts (``_valid_rows``), checked on
    copies (the check normalises dates in place); each row left out said once, with how
    many rows that name it went with it."""
    left_out = []
    while True:
        try:
            _valid_rows({t: [dict(r) for r in rows] for t, rows in tables.items()}, where)
            return left_out
        except _BadRow as bad:
            gone = _drop(tables, bad.table, bad.rid)
            left_out.append(f"{bad.table} row {bad.rid}: {bad.what}"
                            + (f" (and {gone} row(s) that name it)" if gone else ""))


def _drop(tables: dict[str, list], table: str, rid: int) -> int:
    """Row ``rid`` of ``table`` taken out with the rows that name it, theirs too: how many
    of those went."""
    tables[table][:] = [r for r in tables[table] if r["id"] != rid]
    gone = 0
    for other, key in _NAMED_BY[table]:
        for r in [r for r in tables[other] if r.get(key) == rid]:
            gone += 1 + _drop(tables, other, r["id"])
    return gone


def check_export(doc, where: str) -> dict[str, list]:
    """An export's tables, every row checked (``_valid_rows``): what is not a history export
    compgen wrote is refused before any store is opened (or made) for it."""
    if (not isinstance(doc, dict) or doc.get("format") != EXPORT_FORMAT
            or not isinstance(doc.get("tables"), dict)):
        raise CompgenError("not a compgen history export", where=where,
                           hint=f"make one with {me()} history export -o H.json on the other store")
    # the store it came from: recorded with every row imported, the one key an import is told by
    if not isinstance(doc.get("store_id"), str) or not re.fullmatch(r"[0-9a-f]{32}", doc["store_id"]):
        raise CompgenError("the export names no store it came from (store_id); nothing was imported",
                           where=where, hint="import an export compgen wrote, unchanged")
    try:
        t = {name: list(doc["tables"][name]) for name in _COLUMNS}
    except (KeyError, TypeError) as exc:
        raise CompgenError(f"the export is incomplete or damaged ({exc!r}); nothing was imported",
                           where=where) from None
    _valid_rows(t, where)
    return t


def _valid_rows(t: dict[str, list], where: str) -> None:
    """Every row of an export as compgen writes its rows, checked before anything is written
    (a row the store would keep forever must not break every later read): dates (normalised to
    UTC), one-line names, JSON columns, finite numbers, kinds, controllers, ids that exist,
    and each fit's marker recomputed from its own fit_json."""
    rows = _Rows(t, where)
    rows.shape()
    rows.machines()
    rows.sessions()
    values, sigma = rows.fits()
    rows.edits(values)
    rows.checks(sigma)
    rows.once()


class _BadRow(CompgenError):
    """A row an import refuses: its table, its id and why."""

    def __init__(self, table: str, rid, what: str, where: str):
        super().__init__(f"{table} row {rid!r}: {what}; nothing was imported", where=where,
                         hint="import an export compgen wrote, unchanged")
        self.table, self.rid, self.what = table, rid, what


class _Rows:
    """An export's tables being checked: each check refuses the whole import, naming its row."""

    def __init__(self, t: dict[str, list], where: str):
        self.t, self.where = t, where

    def bad(self, table, row, what):
        raise _BadRow(table, row.get("id") if isinstance(row, dict) else None, what, self.where)

    def text(self, table, row, key, line=True):
        v = row.get(key)
        if not isinstance(v, str) or (line and one_line(v) != v):
            self.bad(table, row, f"{key} is not one line of text")
        return v

    def doc(self, table, row, key, kind):
        v = row.get(key)
        try:
            v = json.loads(v) if isinstance(v, str) else v
        except ValueError:
            self.bad(table, row, f"{key} is not JSON")
        if not isinstance(v, kind):
            self.bad(table, row, f"{key} is not a JSON {kind.__name__}")
        return v

    def finite(self, table, row, key):
        v = row.get(key)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            self.bad(table, row, f"{key} is not a finite number")

    def instant(self, table, row):
        """The row's ``taken``, normalised to UTC in place."""
        try:
            row["taken"] = taken_at(self.text(table, row, "taken"))
        except CompgenError as exc:
            self.bad(table, row, exc.message)

    def shape(self) -> None:
        """Whole-number ids, each once; a table's own columns; references that exist."""
        t, bad = self.t, self.bad
        for table, rows in t.items():
            seen = set()
            for row in rows:
                if not isinstance(row, dict) or type(row.get("id")) is not int:
                    bad(table, row if isinstance(row, dict) else {}, "no whole-number id")
                if row["id"] in seen:
                    bad(table, row, "its id is another row's")
                seen.add(row["id"])
                if set(row) != set(_COLUMNS[table]):
                    odd = sorted(set(row) ^ set(_COLUMNS[table]))
                    bad(table, row, f"its columns are not a {table[:-1]}'s ({', '.join(odd)})")
        ids = {table: {r["id"] for r in rows} for table, rows in t.items()}
        for table, refs in (("sessions", {"machine_id": "machines"}), ("fits", {"session_id": "sessions"}),
                            ("edits", {"machine_id": "machines", "fit_id": "fits"}),
                            ("checks", {"machine_id": "machines", "fit_id": "fits",
                                        "against_fit_id": "fits"})):
            for row in t[table]:
                for key, other in refs.items():
                    if row.get(key) not in ids[other]:
                        bad(table, row, f"{key} names no {other[:-1]} of the export")

    def machines(self) -> None:
        for m in self.t["machines"]:
            self.text("machines", m, "name")
            if self.text("machines", m, "serial"):
                try:
                    identifier("serial", m["serial"], "serial")
                except CompgenError as exc:
                    self.bad("machines", m, exc.message)

    def sessions(self) -> None:
        for s in self.t["sessions"]:
            self.instant("sessions", s)
            self.text("sessions", s, "device"), self.text("sessions", s, "operator")
            temps = self.doc("sessions", s, "temperatures", dict)
            if not all(isinstance(v, int | float) and math.isfinite(v) for v in temps.values()):
                self.bad("sessions", s, "a temperature is not a finite number")
            self.doc("sessions", s, "data", list)

    def fits(self) -> tuple[dict, dict]:
        """Each fit's parameters and σ̂ as parsed here (for its edits and its verdict), every
        fit recomputed from its own fit_json."""
        bad, values, sigma = self.bad, {}, {}
        for f in self.t["fits"]:
            if f.get("kind") not in ("calibration", "check"):
                bad("fits", f, "kind is neither calibration nor check")
            self.finite("fits", f, "sigma_um"), self.finite("fits", f, "rms_um")
            self.text("fits", f, "verdict")
            model, params = self.doc("fits", f, "model", list), self.doc("fits", f, "parameters", dict)
            for q in params.values():
                if not isinstance(q, dict) or not all(
                        isinstance(q.get(k), int | float) and math.isfinite(q[k]) for k in ("value", "std")):
                    bad("fits", f, "a parameter's value or σ is not a finite number")
            try:
                fit = FitResult.from_dict(self.doc("fits", f, "fit_json", dict))
            except (CompgenError, KeyError, TypeError, ValueError):
                bad("fits", f, "fit_json is not a fit compgen wrote")
            values[f["id"]], sigma[f["id"]] = params, fit.residual["sigma_um"]
            if model != list(fit.model) or params != {n: {"value": e.value, "std": e.std, "unit": e.unit}
                                                      for n, e in fit.parameters.items()}:
                bad("fits", f, "its model or parameters are not its fit_json's: the row was changed")
            if not fit.holds_marker(f.get("marker")):
                bad("fits", f, f"its marker {f.get('marker')!r} is not its fit's ({fit.record_marker}): the "
                               "row was changed")
        return values, sigma

    def edits(self, values: dict) -> None:
        t, bad = self.t, self.bad
        fitted = {f["id"]: f for f in t["fits"]}
        sessions = {x["id"]: x for x in t["sessions"]}
        for e in t["edits"]:
            if e.get("controller") not in CONTROLLERS:
                bad("edits", e, "controller is none compgen knows")
            corrects = self.doc("edits", e, "corrects", dict)
            self.doc("edits", e, "written", dict), self.doc("edits", e, "loaded", dict)
            # an edit corrects its fit's own values (kinematics.corrected_by): any other figure,
            # or an edit filed under another machine than its fit's, was changed after it was written
            held = values[e["fit_id"]]
            if any(n not in held or v != held[n]["value"] for n, v in corrects.items()):
                bad("edits", e, "it corrects values its fit does not hold: the row was changed")
            if sessions[fitted[e["fit_id"]]["session_id"]]["machine_id"] != e["machine_id"]:
                bad("edits", e, "it is filed under another machine than its fit's")
            self.instant("edits", e)

    def checks(self, sigma: dict) -> None:
        """Each check's verdict its fit's; each fit labelled as the checks say of it; no
        calibration accepted beyond the gate's σ̂."""
        t, bad = self.t, self.bad
        fitted = {f["id"]: f for f in t["fits"]}
        checked = {c.get("fit_id") for c in t["checks"]}
        for c in t["checks"]:
            if c.get("passed") not in (0, 1) or isinstance(c.get("passed"), bool):
                bad("checks", c, "passed is neither 0 nor 1")
            self.doc("checks", c, "summary", dict)
            if fitted[c["fit_id"]]["kind"] != "check" or fitted[c["against_fit_id"]]["kind"] != "calibration":
                bad("checks", c, "its fit is not a check, or what it was checked against not a calibration: "
                                 "a fit was relabelled")
            if fitted[c["fit_id"]]["verdict"] != ("check passed" if c["passed"] else "check failed"):
                bad("checks", c, "its verdict is not its fit's: the row was changed")
        for f in t["fits"]:
            # a check's fit is a check row's fit; a calibration's never: a relabelled one is refused
            if (f["kind"] == "check") != (f["id"] in checked):
                bad("fits", f, f"its kind ({f['kind']}) is not what the checks say of it: the row was "
                               "relabelled")
            # a calibration whose own fit says its residual is no R-test's cannot have been accepted
            if f["verdict"] == "accepted" and not (s_hat := sigma[f["id"]]) <= SIGMA_PLAUSIBLE_UM:
                bad("fits", f, f"accepted with σ̂ {s_hat:.2f} µm, beyond the fit gate's "
                               f"{SIGMA_PLAUSIBLE_UM:g} µm: the verdict was changed")

    def once(self) -> None:
        """What the store keeps once (its content keys): twice in one export is refused here,
        before any store is opened or made for it."""
        _, of_session = _machine_keys(self.t)
        fits, edited = set(), set()
        for f in self.t["fits"]:
            key = (of_session[f["session_id"]], f["marker"])
            if key in fits:
                self.bad("fits", f, f"fit {f['marker']} of {key[0][0]!r} is in the export twice")
            fits.add(key)
        for e in self.t["edits"]:
            if e["fit_id"] in edited:
                self.bad("edits", e, "a second edit from one fit (the store keeps one per fit)")
            edited.add(e["fit_id"])


def _machine_keys(t: dict[str, list]) -> tuple[dict[int, tuple], dict[int, tuple]]:
    """Each machine row's key in a store, (name, serial), and each session's machine's key
    (the rows' references checked already)."""
    machines = {m["id"]: (m["name"], m["serial"]) for m in t["machines"]}
    return machines, {s["id"]: machines[s["machine_id"]] for s in t["sessions"]}


def import_history(store: Store, doc: dict, sha256: str, where: str,
                   same: Collection[str] = ()) -> dict[str, int]:
    """Another store's export, appended in one transaction with its origin recorded. Refused:
    this store's own rows, an export already imported, or a fit this store already holds
    (for the same machine): nothing is merged silently, and nothing twice. A machine without
    a serial whose name this store holds is merged only when named in ``same``: a name alone
    does not tell one machine from another plant's (with the same bundled machine file)."""
    t = check_export(doc, where)
    if doc.get("store_id") == store.store_id():
        raise CompgenError("this export is this store's own history", where=where,
                           hint="nothing to import")
    if store.rows("SELECT id FROM imports WHERE file_sha256 = ?", (sha256,)):
        raise CompgenError("this export has been imported here already", where=where,
                           hint="nothing to import")
    _refuse_merges(store, t, where, same)
    _append(store, t, str(doc["store_id"]), sha256, where)
    return {name: len(t[name]) for name in _COLUMNS}


def _refuse_merges(store: Store, t: dict[str, list], where: str, same: Collection[str]) -> None:
    """What the import must not merge: another machine under a known name (another machine
    file, or no serial without ``same``), and a fit this store holds already."""
    machines, session_machine = _machine_keys(t)
    held = {(session_machine[f["session_id"]], f["marker"]) for f in t["fits"]}
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
                               "of the same name", where=where,
                               hint="give each machine its serial in its machine file, or import into "
                                    "another store; nothing was imported")
    # the same fit: the same record marker, or the same 6 digits where a row is an older
    # compgen's (its marker has no more)
    named = {(r["name"], r["serial"]) for r in store.rows("SELECT name, serial FROM machines")}
    unknown = [n for n in same if (n, "") not in machines.values()]
    if unknown:
        raise CompgenError(f"--same-machine {unknown[0]!r}: the export holds no machine of that name "
                           "without a serial", where=where,
                           hint="name a machine the export holds; nothing was imported")
    for name, serial in sorted(set(machines.values())):
        if not serial and (name, serial) in named and name not in same:
            raise CompgenError(f"machine {name!r} has no serial, and this store holds a machine of that "
                               "name: a name alone does not tell one machine from another plant's",
                               where=where, hint=f"if they are one machine, add --same-machine "
                                                 f"{shlex.quote(name)} to this import; else give each its "
                                                 "serial ([machine] serial) and record with --serial; "
                                                 "nothing was imported")
    mine: dict[tuple, set] = {}
    for r in store.rows("SELECT m.name, m.serial, f.marker FROM fits f JOIN sessions s "
                        "ON s.id = f.session_id JOIN machines m ON m.id = s.machine_id"):
        mine.setdefault(((r["name"], r["serial"]), r["marker"][:SHORT_MARKER]), set()).add(r["marker"])
    twice = sorted((key, marker) for key, marker in held
                   if any(marker == m or SHORT_MARKER in (len(marker), len(m))
                          for m in mine.get((key, marker[:SHORT_MARKER]), ())))
    if twice:
        raise CompgenError(f"{len(twice)} fit(s) of the export are already here (first: {twice[0][1]} of "
                           f"{twice[0][0][0]!r})", where=where,
                           hint="the two stores share history: import into a fresh store, or keep them apart")


def _append(store: Store, t: dict[str, list], origin: str, sha256: str, where: str) -> None:
    """The export's rows appended in one transaction, each with its new ids and its origin."""
    machines, session_machine = _machine_keys(t)
    ids: dict[str, dict] = {name: {} for name in _COLUMNS}
    with store.writing():
        imp = store.insert("imports", {"origin_store": origin, "file_sha256": sha256,
                                       "recorded": now()})
        for m in t["machines"]:
            ids["machines"][m["id"]] = lookup_machine(store, m["name"], m["serial"], create=True)
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
                "content_sha256": content_key("fit", name, serial, f["marker"])}, unique="content_sha256")
            if ids["fits"][f["id"]] is None:     # another writer recorded it since the check above
                raise CompgenError(f"fit {f['marker']} of {name!r} was recorded in this store while the "
                                   "import ran; nothing was imported", where=where,
                                   hint="import again: what this store holds by then is refused by name")
        for e in t["edits"]:
            name, serial = machines[e["machine_id"]]
            if store.insert("edits", {**{k: e[k] for k in _COLUMNS["edits"][3:]},
                                      "machine_id": ids["machines"][e["machine_id"]],
                                      "fit_id": ids["fits"][e["fit_id"]],
                                      "content_sha256": content_key("edit", name, serial,
                                                                    markers[e["fit_id"]])},
                            unique="content_sha256") is None:
                raise CompgenError(f"an edit from fit {markers[e['fit_id']]} of {name!r} was recorded in "
                                   "this store while the import ran; nothing was imported", where=where,
                                   hint="import again: what this store holds by then is refused by name")
        for c in t["checks"]:
            store.insert("checks", {**{k: c[k] for k in _COLUMNS["checks"][4:]},
                                    "machine_id": ids["machines"][c["machine_id"]],
                                    "fit_id": ids["fits"][c["fit_id"]],
                                    "against_fit_id": ids["fits"][c["against_fit_id"]]})
