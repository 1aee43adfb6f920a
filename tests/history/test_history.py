"""The calibration history on both stores: a scripted year of one machine (a slow drift of
YOC, a crash that moves BOA in month 7, an edit after it), checks against the last
calibration, a plant's concurrent writers, a killed writer, and a database that refuses
what compgen's role may not do. The PostgreSQL server is real, started by the tests."""

import contextlib
import hashlib
import json
import math
import os
import re
import sqlite3
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np
import pytest
from conftest import ROOT, SEED_MACHINE, UM, pasted, run

from compgen import history as H
from compgen.configuration.machine_file import load_machine
from compgen.controllers.kinematics import corrected_by
from compgen.controllers.registry import controller
from compgen.data.rtest import format_rtest
from compgen.data.simulate import read_truth, simulate
from compgen.errors import CompgenError
from compgen.history.store import PG_SCHEMA, TABLES, init, open_store
from compgen.model.effects import compose, location_model
from compgen.model.paths import generate
from compgen.statistics.gate import fit_gate
from compgen.statistics.identify import identify
from compgen.statistics.results import load_fit

ARCSEC = math.pi / 648000
YOC_PER_MONTH = 1.5 * UM          # the slow drift (the [drift] limit is 1 µm/month)
CRASH = ("2026-06-15", 30 * ARCSEC)   # BOA moves 30″ (limit 10″)
EDIT_DATE = "2026-07-02T09:00:00+00:00"


def _truth(machine, base, when: str, corrected: dict) -> dict:
    """The machine on ``when``: the seed's errors, YOC drifting since 1 January, BOA after
    the crash; minus what the control corrects (an edit loaded)."""
    months = H.days("2026-01-01T00:00:00+00:00", H.taken_at(when)) / H.DAYS_PER_MONTH
    t = dict(base)
    t["YOC"] += YOC_PER_MONTH * months
    if when >= CRASH[0]:
        t["BOA"] += CRASH[1]
    return {n: v - corrected.get(n, 0.0) for n, v in t.items()}


def _session(machine, truth, paths, seed, name, noise_um=0.5):
    d = simulate(machine, truth, generate(machine, paths), noise_um, np.random.default_rng(seed))
    return replace(d, source=name, sha256=f"{seed:064x}")


@pytest.fixture(scope="module")
def year():
    """Twelve monthly calibrations (K4, K1, K2; 0.5 µm noise), each fitted and judged by the
    gate; the edit written from month 7's fit corrects what an iTNC 530 holds."""
    machine = load_machine("ac-trunnion-itnc530")
    base = read_truth(ROOT / "examples" / "truth-table4.json", machine)
    fits, corrected, edit = [], {}, None
    for month in range(1, 13):
        when = f"2026-{month:02d}-01T09:00:00+00:00"
        truth = _truth(machine, base, when, corrected)
        d = _session(machine, truth, ["K4", "K1", "K2"], month, f"m{month}.csv")
        fit = identify(machine, [d], location_model(machine))
        fits.append((when, fit, fit_gate(machine, [d], fit)))
        if month == 7:
            edit = (fit, corrected_by(machine, fit, controller("itnc530")))
            corrected = dict(edit[1])
    return machine, base, fits, edit


def _record(url, year, months=12):
    """The year's first ``months`` calibrations (and the edit, once its month is among them)."""
    machine, _, fits, (efit, corrects) = year
    store = init(url)[0]             # a PostgreSQL store is made by its owner; a file on first use
    for when, fit, verdict in fits[:months]:
        H.record_fit(store, fit, machine, taken=when, verdict=verdict)
        if fit is efit:
            H.record_edit(store, fit, machine, "itnc530", corrects, {"EDIT.TAB": "0" * 64}, {},
                          taken=EDIT_DATE)
    return store


STORES = ["sqlite", "postgresql"]


def _store(kind, request, tmp_path, name="h"):
    """A fresh, empty store of ``kind`` for one test: an SQLite file, or a PostgreSQL
    database made by its owner (``name`` gives a test a second one)."""
    if kind == "sqlite":
        url = str(tmp_path / f"{name}.sqlite")
    else:
        import psycopg
        url = request.getfixturevalue("pg_db")
        if name != "h":
            server, base = url.rsplit("/", 1)
            with psycopg.connect(f"{server}/postgres", autocommit=True) as db:
                db.execute(f"DROP DATABASE IF EXISTS {base}_{name}")
                db.execute(f"CREATE DATABASE {base}_{name}")
            url = f"{url}_{name}"
    init(url)[0].close()
    return url


@contextlib.contextmanager
def _raw(url):
    """Another writer's connection, outside compgen (an SQLite file's writers are not held by
    the database; on PostgreSQL, its owner's): ``execute(sql, args)`` with ``?`` marks."""
    if str(url).startswith("postgresql"):
        import psycopg
        with psycopg.connect(url, autocommit=True) as db:
            db.execute(f"SET search_path TO {PG_SCHEMA}")
            yield lambda sql, args=(): db.execute(sql.replace("?", "%s"), args)
    else:
        with contextlib.closing(sqlite3.connect(url)) as db, db:     # closed, not only committed
            yield db.execute


def _contents(url):
    """Every row of every table in id order: the store as it is."""
    with open_store(url) as store:
        return {t: store.rows(f"SELECT * FROM {t} ORDER BY id") for t in TABLES}


def _check(store, year, when, seed, moved=None, noise_um=0.5):
    """A K4-only check measured on ``when`` against the last calibration before it; ``moved``:
    location errors moved beyond the year's story (name → mm or rad)."""
    return _checked(store, year, when, seed, moved, noise_um)[0]


def _checked(store, year, when, seed, moved=None, noise_um=0.5):
    """``_check``'s result and the check's own fit."""
    machine, base, _, (_, corrects) = year
    corrected = corrects if when >= EDIT_DATE else {}
    truth = _truth(machine, base, when, corrected)
    truth = {n: v + (moved or {}).get(n, 0.0) for n, v in truth.items()}
    d = _session(machine, truth, ["K4"], seed, f"check{seed}.csv", noise_um)
    fit = identify(machine, [d], location_model(machine))
    calibration, entries, edits = H.last_calibration(store, machine, before=H.taken_at(when))
    return H.check(machine, fit, [d], calibration, entries, edits, H.taken_at(when)), fit


def _trend_rows(text, month="2026-"):
    """The trend's rows of ``month`` as (date, whether the row is an edit), in their order."""
    return [(ln[:10], ln[12:23].strip() == "edit") for ln in text.splitlines() if ln.startswith(month)]


def _year_checks(store, year):
    t = H.trend(store, year[0])
    flags = [(f.kind, f.param, f.taken[:10]) for f in t.flags]
    # the crash month and the drift, and nothing else: an edit is not a step
    assert flags == [("drift", "YOC", "2026-03-01"), ("step", "BOA", "2026-07-01")], flags
    step = next(f for f in t.flags if f.kind == "step")
    assert step.change / ARCSEC == pytest.approx(30.0, abs=0.3)
    drift = next(f for f in t.flags if f.kind == "drift")
    assert drift.change / UM == pytest.approx(1.5 * 30 / 30.4, abs=0.15)   # 1.5 µm per 30.4 days
    # after the edit the control measures BOA near its old value less 42″; the machine value goes on
    after = [e for e in t.entries if e.taken > EDIT_DATE]
    assert all(abs(e.values["BOA"]) < 0.3 * ARCSEC for e in after)
    assert all(e.machine_value("BOA") / ARCSEC == pytest.approx(42.3, abs=0.3) for e in after)
    for when, seed in (("2026-07-20T10:00", 101), ("2026-08-10T10:00", 103)):   # corrected and healthy
        healthy = _check(store, year, when, seed)
        assert healthy.passed, healthy.text()
    crashed = _check(store, year, "2026-06-20T10:00", 102)
    assert not crashed.passed
    assert [c.param for c in crashed.changes if c.status == "fail"] == ["BOA"], crashed.text()
    assert any("axis A" in a for a in crashed.advice) and any("re-calibrate" in a for a in crashed.advice)
    # before the crash nothing moved, but the calibration was never corrected: K4 is out of tolerance
    uncorrected = _check(store, year, "2026-05-10T10:00", 104)
    assert all(c.status == "pass" for c in uncorrected.changes) and not uncorrected.passed
    assert uncorrected.paths["K4"].startswith("FAIL") and "not corrected" in uncorrected.advice[0]
    text = H.trend_text(t)
    # the rows in time: the edit of 2 July between the fits of July and August
    rows = _trend_rows(text)
    assert rows == ([(f"2026-{m:02d}-01", False) for m in range(1, 8)] + [("2026-07-02", True)]
                    + [(f"2026-{m:02d}-01", False) for m in range(8, 13)]), text
    return text



def _meets_schema(doc, name):
    import jsonschema
    schema = json.loads((ROOT / "docs" / "schemas" / f"{name}.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.Draft202012Validator(schema).validate(doc)

def test_a_year_in_sqlite_and_in_postgresql_gives_one_trend(year, tmp_path, pg_db):
    with _record(tmp_path / "h.sqlite", year) as store:
        sqlite_text = _year_checks(store, year)
    with _record(pg_db, year) as store:
        pg_text = _year_checks(store, year)
    assert sqlite_text == pg_text
    assert "BOA moved +29.9" in sqlite_text or "BOA moved +30.0" in sqlite_text


def test_the_check_command_passes_a_healthy_machine_and_fails_the_crashed_one(year, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _record(tmp_path / "compgen-history.sqlite", year).close()      # the default store, here
    machine, base = year[0], year[1]
    for when, seed, code in (("2026-08-05T10:00", 201, 0), ("2026-06-20T10:00", 202, 1)):
        corrected = year[3][1] if when >= EDIT_DATE else {}
        d = _session(machine, _truth(machine, base, when, corrected), ["K4"], seed, "x")
        (tmp_path / f"{seed}.csv").write_text(format_rtest(machine, d))
        as_json = ["--json"] if code else []       # the failing one as a user's tool reads it
        rc, out, err = run("check", "--machine", "ac-trunnion-itnc530", f"{seed}.csv", "--date", when,
                           *as_json)
        assert rc == code, out + err
        assert ("PASS" if code == 0 else "FAIL") in out
        if code:
            assert "BOA" in out and "re-calibrate" in out
            doc = json.loads(out)
            _meets_schema(doc, "check")
            assert doc["format"] == "compgen.check/1" and not doc["passed"]
            assert next(c for c in doc["changes"] if c["parameter"] == "BOA")["status"] == "fail"
    rc, out, err = run("history", "fleet")
    # the last check measured (not the last recorded) is the healthy one; the next is due 90 days
    # after the last measurement, the calibration of 1 December
    assert rc == 0 and "2026-08-05  pass   2027-03-01" in out, out
    with open_store(tmp_path / "compgen-history.sqlite") as store:
        checks = store.rows("SELECT passed FROM checks ORDER BY id")
    assert [r["passed"] for r in checks] == [1, 0]


def test_a_fit_the_gate_refuses_is_recorded_as_not_accepted_with_its_reasons(tmp_path, monkeypatch):
    """`history add` of a fit whose data hold what its model misses (a 2/rev angle error of
    C, 4″): recorded, and said on the terminal as not a reference, with the gate's reason."""
    monkeypatch.chdir(tmp_path)
    machine = load_machine("ac-trunnion-itnc530")
    truth = {**read_truth(ROOT / "examples" / "truth-table4.json", machine),
             "ECC:h2c": np.radians(4 / 3600), "ECC:h2s": np.radians(-2 / 3600)}
    d = simulate(machine, truth, generate(machine, ["K4", "K1", "K2"]), 0.5, np.random.default_rng(5))
    (tmp_path / "a.csv").write_text(format_rtest(machine, d))
    assert run("fit", "--machine", "ac-trunnion-itnc530", "a.csv", "-o", "fit.json")[0] == 0
    rc, out, err = run("history", "add", "fit.json", "--date", "2026-03-01")
    assert rc == 0, out + err
    said = "as calibration #1 in compgen-history.sqlite: NOT accepted as a reference: " \
           "diagnose finds effects the model misses: ECC:h2"
    assert said in out and len(out.strip().splitlines()) == 1, out


def test_history_commands_on_a_real_fit(tmp_path, monkeypatch):
    """add, list, show, trend (with its plot), export: each as a user types it."""
    monkeypatch.chdir(tmp_path)
    machine = load_machine("ac-trunnion-itnc530")
    truth = read_truth(ROOT / "examples" / "truth-table4.json", machine)
    d = simulate(machine, truth, generate(machine, ["K4"]), 0.5, np.random.default_rng(5))
    (tmp_path / "a.csv").write_text(format_rtest(machine, d))
    assert run("fit", "--machine", "ac-trunnion-itnc530", "a.csv", "-o", "fit.json")[0] == 0
    rc, out, err = run("history", "add", "fit.json", "--date", "2026-03-01", "--operator", "J. Doe",
                       "--temperature", "hall=21.5")
    assert rc == 0 and "accepted" in out, out + err
    rc, out, err = run("history", "add", "fit.json")
    assert rc == 2 and "already in the history" in err
    rc, out, _ = run("history", "list")
    assert "1 fit(s)" in out
    rc, out, _ = run("history", "show", "--machine", "ac-trunnion-itnc530")
    assert "2026-03-01" in out and "calibration" in out
    rc, out, err = run("history", "trend", "--machine", "ac-trunnion-itnc530", "--param", "YOC,BOA",
                       "--plot", "trend.png")
    assert rc == 0 and "YOC µm" in out and "nothing flagged" in out, out + err
    assert (tmp_path / "trend.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rc, out, err = run("history", "trend", "--machine", "ac-trunnion-itnc530", "--param", "XYZ")
    assert rc == 2 and "no recorded fit holds XYZ" in err
    # the edit written from it, recorded: what it corrects, the files written and the state loaded
    # (saved by a Windows editor, with a byte-order mark: its SHA-256 is of the file's bytes)
    current = tmp_path / "current.TAB"
    current.write_bytes(b"\xef\xbb\xbf" + (ROOT / "examples" / "itnc530-current.TAB").read_bytes())
    rc, out, err = run("kinematics", "--from", "fit.json", "--current", current,
                       "-o", "EDIT.TAB", "--record", "--date", "2026-03-02")
    assert rc == 0 and "recorded the edit" in out, out + err
    with open_store(tmp_path / "compgen-history.sqlite") as store:
        edit = store.rows("SELECT corrects, written, loaded FROM edits")[0]
    corrects = json.loads(edit["corrects"])
    assert sorted(corrects) == sorted(["YOA", "ZOA", "BOA", "COA", "XOC", "YOC", "AOC", "BOC"])
    fit = load_fit(tmp_path / "fit.json")
    assert all(corrects[n] == fit.parameters[n].value for n in corrects)
    assert set(json.loads(edit["written"])) == {"EDIT.TAB", "EDIT.txt", "EDIT_SIGN.H", "EDIT_SIGN_MSG.A"}
    assert list(json.loads(edit["loaded"]).values())[0] == hashlib.sha256(current.read_bytes()).hexdigest()
    rc, out, _ = run("history", "show", "--machine", "ac-trunnion-itnc530")
    assert "edit        from " + fit.marker in out
    rc, out, err = run("report", "--from", "fit.json", "--history", "-o", "report.html")
    html = (tmp_path / "report.html").read_text()
    assert rc == 0 and "History of this machine" in html and 'alt="history trend"' in html, out + err
    assert "2026-03-02" in html and fit.marker in html     # the edit, listed
    assert run("history", "export", "-o", "h.csv")[0] == 0
    rows = (tmp_path / "h.csv").read_text().splitlines()
    assert rows[0].startswith("name,serial,taken") and len(rows) == 1 + 11
    assert run("history", "export", "-o", "h.csv")[0] == 2            # never overwritten without --force
    rc, out, _ = run("history", "export", "-o", "h.json")
    assert json.loads((tmp_path / "h.json").read_text())["rows"][0]["operator"] == "J. Doe"
    # a calibration 30 s after the edit, in the same minute: shown after it (by instant, not text)
    d = simulate(machine, truth, generate(machine, ["K4"]), 0.5, np.random.default_rng(6))
    (tmp_path / "b.csv").write_text(format_rtest(machine, d))
    assert run("fit", "--machine", "ac-trunnion-itnc530", "b.csv", "-o", "b.json")[0] == 0
    rc, out, _ = run("history", "show", "--machine", "ac-trunnion-itnc530")
    minute = [ln for ln in out.splitlines() if "edit        from" in ln][0].split()[0]   # 2026-03-02T00:00
    rc, out, err = run("history", "add", "b.json", "--date", f"{minute}:30+00:00")
    assert rc == 0, out + err
    rc, out, _ = run("history", "show", "--machine", "ac-trunnion-itnc530")
    kinds = [ln.split()[1] for ln in out.splitlines() if ln.startswith("  20")]
    assert kinds == ["calibration", "edit", "calibration"], out


def test_the_database_refuses_updates_and_compgen_refuses_foreign_and_newer_stores(tmp_path, year):
    with _record(tmp_path / "h.sqlite", year) as store:
        for sql in ("UPDATE fits SET verdict = 'x'", "DELETE FROM edits", "UPDATE machines SET serial = 'y'"):
            with pytest.raises(sqlite3.IntegrityError, match="append-only"):
                store.db.execute(sql)
    foreign = tmp_path / "other.sqlite"
    with contextlib.closing(sqlite3.connect(foreign)) as db:     # closed: Python 3.13 warns of one left open
        db.execute("CREATE TABLE orders (id INTEGER)")
        db.commit()
    rc, _, err = run("history", "list", "--db", foreign)
    assert rc == 2 and "not a compgen history" in err
    newer = tmp_path / "newer.sqlite"
    with open_store(newer) as store:
        store.db.execute("INSERT INTO compgen_schema VALUES ('compgen.history', 99, 'x', 'now')")
    rc, _, err = run("history", "list", "--db", newer)
    assert rc == 2 and "schema 99, newer than" in err
    (tmp_path / "text.sqlite").write_text("name,value\n")
    rc, _, err = run("history", "list", "--db", tmp_path / "text.sqlite")
    assert rc == 2 and "not an SQLite history store" in err


WRITER = """
import sys
import time
from dataclasses import replace
from compgen import history as H
from compgen.configuration.machine_file import load_machine
from compgen.statistics.results import load_fit
from compgen.history.store import PG_SCHEMA, TABLES, init, open_store
url, fit_file, worker = sys.argv[1], sys.argv[2], int(sys.argv[3])
machine = load_machine("ac-trunnion-itnc530")
base = load_fit(fit_file)
store = open_store(url)
for m in range(20):           # every worker writes every machine: they meet on each machine's row
    k = worker * 100 + m
    values = {n: replace(e, value=e.value + k * 1e-6) for n, e in base.parameters.items()}
    fit = replace(base, parameters=values)
    H.record_fit(store, fit, replace(machine, serial=f"M{m:02d}"), taken=f"2026-01-{1 + worker:02d}")
"""

KILLED = """
import os, signal, sys
from compgen import history as H
from compgen.configuration.machine_file import load_machine
from compgen.statistics.results import load_fit
from compgen.history.store import Store, open_store
url, fit_file = sys.argv[1], sys.argv[2]
insert = Store.insert
def dying(self, table, row, **how):
    if table == "fits":                          # the session row is in, the fit not yet
        os.kill(os.getpid(), signal.SIGKILL)
    return insert(self, table, row, **how)
Store.insert = dying
H.record_fit(open_store(url), load_fit(fit_file), load_machine("ac-trunnion-itnc530"), taken="2026-02-01")
"""


def _python(code, *args):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], env=env, capture_output=True,
                          text=True, timeout=120)


@pytest.fixture(scope="module")
def fit_file(year, tmp_path_factory):
    path = tmp_path_factory.mktemp("fit") / "fit.json"
    path.write_text(year[2][0][1].to_json())
    return path


def _counts(store):
    return {t: store.rows(f"SELECT COUNT(*) AS n FROM {t}")[0]["n"] for t in ("machines", "sessions", "fits")}


def test_four_writers_twenty_machines_in_postgresql_lose_nothing(pg_db, fit_file):
    assert run("history", "init", "--db", pg_db)[0] == 0
    procs = [subprocess.Popen([sys.executable, "-c", WRITER, pg_db, str(fit_file), str(w)],
                              env={**os.environ, "PYTHONPATH": str(ROOT)}, stderr=subprocess.PIPE, text=True)
             for w in range(4)]
    errors = [p.communicate(timeout=240)[1] for p in procs]
    assert [p.returncode for p in procs] == [0] * 4, errors
    with open_store(pg_db) as store:
        assert _counts(store) == {"machines": 20, "sessions": 80, "fits": 80}


@pytest.mark.parametrize("kind", ["sqlite", "postgresql"])
def test_a_writer_killed_mid_transaction_leaves_the_store_consistent(kind, tmp_path, request, fit_file):
    url = tmp_path / "h.sqlite" if kind == "sqlite" else request.getfixturevalue("pg_db")
    if kind == "postgresql":
        run("history", "init", "--db", url)
    done = _python(KILLED, url, fit_file)
    assert done.returncode == -9, done.stderr
    with open_store(url) as store:
        assert _counts(store) == {"machines": 0, "sessions": 0, "fits": 0}
        machine = load_machine("ac-trunnion-itnc530")
        H.record_fit(store, load_fit(fit_file), machine, taken="2026-02-01")
        assert _counts(store) == {"machines": 1, "sessions": 1, "fits": 1}


def test_postgresql_refuses_an_update_through_compgens_role_and_never_shows_the_password(pg_db, fit_file):
    import psycopg
    with psycopg.connect(pg_db, autocommit=True) as owner:
        owner.execute("CREATE ROLE compgen_writer LOGIN")
    rc, out, err = run("history", "init", "--db", pg_db, "--grant", "compgen_writer")
    assert rc == 0 and "compgen_writer may read and append" in out, out + err
    writer = pg_db.replace("compgen_owner@", "compgen_writer:s3cret-pw@")
    with open_store(writer) as store:          # the role appends
        H.record_fit(store, load_fit(fit_file), load_machine("ac-trunnion-itnc530"), taken="2026-02-01")
    rc, out, err = run("history", "init", "--db", writer)     # up to date: nothing to migrate
    assert rc == 0 and "up to date" in out, out + err
    assert "s3cret" not in out + err and "compgen_writer:***@" in out
    with psycopg.connect(writer, autocommit=True) as db:
        for sql in ("UPDATE compgen.fits SET verdict = 'x'", "DELETE FROM compgen.sessions",
                    "TRUNCATE compgen.checks", "DROP TABLE compgen.edits"):
            with pytest.raises(psycopg.errors.InsufficientPrivilege):
                db.execute(sql)
        assert db.execute("SELECT COUNT(*) FROM compgen.fits").fetchone()[0] == 1
    with psycopg.connect(pg_db, autocommit=True) as owner, \
            pytest.raises(psycopg.errors.RaiseException, match="append-only"):   # nor may the owner
        owner.execute("UPDATE compgen.fits SET verdict = 'x'")
    # a refused connection names the store without its password
    rc, _, err = run("history", "list", "--db", writer.replace(writer.split("@")[1].split("/")[0],
                                                                "127.0.0.1:1"))
    assert rc == 2 and "s3cret" not in err and "***" in err
    # a writer cannot migrate: an empty database is the owner's to make
    with psycopg.connect(pg_db.rsplit("/", 1)[0] + "/postgres", autocommit=True) as db:
        db.execute("DROP DATABASE IF EXISTS t_empty")
        db.execute("CREATE DATABASE t_empty")
    rc, _, err = run("history", "list", "--db", writer.rsplit("/", 1)[0] + "/t_empty")
    assert rc == 2 and "history init" in err and "s3cret" not in err


def test_the_machine_files_serial_and_drift_limits_are_checked(tmp_path):
    text = (ROOT / "machines" / "ac-trunnion-itnc530.toml").read_text()
    good = tmp_path / "m.toml"
    good.write_text('serial = "DMU-50/1234"\n' + text + "\n[drift]\noffset_um = 2.0\nk_sigma = 4.0\n")
    m = load_machine(good)
    assert m.serial == "DMU-50/1234" and m.drift.offset_um == 2.0 and m.drift.k_sigma == 4.0
    assert m.drift.tilt_arcsec == 10.0                       # the default where not given
    for extra, words in (('serial = "two words"\n', "not a valid serial"),
                         ("serial = 7\n", "not a valid serial")):
        bad = tmp_path / "bad.toml"
        bad.write_text(extra + text)
        rc, _, err = run("effects", "--machine", bad)
        assert rc == 2 and words in err, err
    bad.write_text(text + "\n[drift]\nofset_um = 2.0\n")
    rc, _, err = run("effects", "--machine", bad)
    assert rc == 2 and "ofset_um" in err, err
    bad.write_text(text + "\n[drift]\noffset_um = -2.0\n")
    rc, _, err = run("effects", "--machine", bad)
    assert rc == 2 and "offset_um" in err, err


def test_another_stores_history_is_imported_only_when_asked_and_only_once(year, tmp_path, pg_db, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with _record(tmp_path / "a.sqlite", year) as a:
        want = H.trend_text(H.trend(a, year[0]))
    assert run("history", "export", "--db", "a.sqlite", "-o", "a.json")[0] == 0
    assert run("history", "init", "--db", pg_db)[0] == 0
    rc, out, err = run("history", "import", "a.json", "--db", pg_db)
    assert rc == 0 and "12 fits" in out and "1 edits" in out, out + err
    with open_store(pg_db) as plant:
        assert H.trend_text(H.trend(plant, year[0])) == want          # the same history, the same flags
        origin = plant.rows("SELECT COUNT(*) AS n FROM sessions WHERE import_id IS NOT NULL")[0]["n"]
    assert origin == 12
    rc, _, err = run("history", "import", "a.json", "--db", pg_db)
    assert rc == 2 and "imported here already" in err
    rc, _, err = run("history", "import", "a.json", "--db", "a.sqlite")
    assert rc == 2 and "this store's own" in err
    rc, _, err = run("history", "import", ROOT / "examples" / "truth-table4.json", "--db", "new.sqlite")
    assert rc == 2 and "not a compgen history export" in err and not (tmp_path / "new.sqlite").exists()
    _record(tmp_path / "b.sqlite", year).close()                      # the same fits, recorded again
    rc, _, err = run("history", "import", "a.json", "--db", "b.sqlite")
    # a machine without a serial is not merged by its name alone (another plant's, with the
    # same bundled machine file, would be): the user says it is the same one
    assert rc == 2 and "has no serial, and this store holds a machine of that name" in err, err
    assert f"--same-machine '{year[0].name}'" in err
    rc, _, err = run("history", "import", "a.json", "--db", "b.sqlite", "--same-machine", year[0].name)
    assert rc == 2 and "12 fit(s) of the export are already here" in err
    # another plant's machine of the same name (no serial), measured with its own machine file
    (tmp_path / "other.toml").write_text((ROOT / "machines" / "ac-trunnion-itnc530.toml").read_text()
                                         + "\n# the other plant's\n")
    with open_store(tmp_path / "c.sqlite") as c:
        fit = year[2][0][1]
        other = load_machine(str(tmp_path / "other.toml"))
        H.record_fit(c, replace(fit, machine={**fit.machine, "sha256": ""}), other, taken="2025-06-01")
    before = (tmp_path / "c.sqlite").read_bytes()
    rc, _, err = run("history", "import", "a.json", "--db", "c.sqlite", "--same-machine", year[0].name)
    assert rc == 2 and "another machine of the same name" in err, err
    assert (tmp_path / "c.sqlite").read_bytes() == before
    # another plant's machine of the same name with the same bundled machine file: a name and a
    # file do not make one machine; the user's word does
    with open_store(tmp_path / "d.sqlite") as d:
        e = fit.parameters["YOC"]
        H.record_fit(d, replace(fit, parameters={**fit.parameters, "YOC": replace(e, value=e.value + 1e-3)}),
                     year[0], taken="2025-06-01")
    rc, _, err = run("history", "import", "a.json", "--db", "d.sqlite")
    assert rc == 2 and "has no serial" in err, err
    rc, _, err = run("history", "import", "a.json", "--db", "d.sqlite", "--same-machine", "no such")
    assert rc == 2 and "holds no machine of that name without a serial" in err, err
    rc, out, err = run("history", "import", "a.json", "--db", "d.sqlite", "--same-machine", year[0].name)
    assert rc == 0 and "12 fits" in out, err
    assert (tmp_path / "c.sqlite").read_bytes() == before


@pytest.mark.parametrize("kind", STORES)
def test_checks_failed_and_passed_travel_with_an_export(year, tmp_path, monkeypatch, request, kind):
    """A store's checks, the failed one too, come across an export and import as they were
    (and none is left out of the export as unreadable)."""
    monkeypatch.chdir(tmp_path)
    a_db = _store(kind, request, tmp_path, "a")
    with _record(a_db, year) as a:
        for when, seed in (("2026-06-20T10:00", 102), ("2026-07-20T10:00", 101)):   # crashed, healthy
            result, fit = _checked(a, year, when, seed)
            H.record_check(a, result, fit, year[0])
        want = [(c["passed"], c["summary"]) for c in a.rows("SELECT passed, summary FROM checks ORDER BY id")]
    assert [p for p, _ in want] == [0, 1]
    with open_store(a_db) as a:     # each check's path ranges, for the trend's panels
        ranges = H.trend(a, year[0]).ranges
    assert len(ranges) == 2 and all(set(r) == {"K4"} and r["K4"] > 0 for _, r in ranges), ranges
    rc, out, err = run("history", "export", "--db", a_db, "-o", "a.json")
    assert rc == 0 and not err and "left out" not in out, out + err
    b_db = _store(kind, request, tmp_path, "b")
    rc, out, err = run("history", "import", "a.json", "--db", b_db)
    assert rc == 0, out + err
    with open_store(b_db) as b:
        got = [(c["passed"], c["summary"]) for c in b.rows("SELECT passed, summary FROM checks ORDER BY id")]
    assert got == want
    # a check's verdict is 0 or 1 and its summary a JSON dict, or the import is refused
    doc = json.loads((tmp_path / "a.json").read_text())
    for key, value, says in (("passed", 2, "passed is neither 0 nor 1"),
                             ("passed", True, "passed is neither"), ("passed", "1", "passed is neither"),
                             ("summary", "[1]", "summary is not a JSON dict")):
        bad = json.loads(json.dumps(doc))
        bad["tables"]["checks"][0][key] = value
        (tmp_path / "bad.json").write_text(json.dumps(bad))
        rc, _, err = run("history", "import", "bad.json", "--db", "c.sqlite")
        assert rc == 2 and f"checks row {bad['tables']['checks'][0]['id']}" in err and says in err, err
        assert not (tmp_path / "c.sqlite").exists()


def test_a_store_of_the_first_schema_is_migrated_and_keeps_its_rows(tmp_path, fit_file, monkeypatch):
    import compgen.history.store as S
    with open_store(tmp_path / "now.sqlite") as now:        # the rows as the first schema held them
        H.record_fit(now, load_fit(fit_file), load_machine("ac-trunnion-itnc530"), taken="2026-01-05")
        tables = H.export_all(now)["tables"]
    with monkeypatch.context() as m:
        m.setattr(S, "MIGRATIONS", S.MIGRATIONS[:1])
        m.setattr(S, "VERSION", 1)
        with open_store(tmp_path / "old.sqlite") as old, old.writing():
            for table in ("machines", "sessions", "fits"):
                for row in tables[table]:
                    old.insert(table, row)
            assert old.version() == 1
    with open_store(tmp_path / "old.sqlite") as new:
        assert new.version() == S.VERSION == 6
        assert new.rows("SELECT import_id FROM sessions") == [{"import_id": None}]
        assert new.rows("SELECT content_sha256 FROM fits") == [{"content_sha256": None}]
        assert _counts(new) == {"machines": 1, "sessions": 1, "fits": 1}
        # a fit recorded before the key is still found: the same fit is not recorded again
        with pytest.raises(H.Recorded):
            H.record_fit(new, load_fit(fit_file), load_machine("ac-trunnion-itnc530"), taken="2026-01-05")


def test_the_measurement_a_failed_check_advises_runs_as_printed(year, tmp_path):
    """The re-calibration command in a failed check's advice, pasted into bash, writes a
    program that passes compgen's own motion check."""
    import re
    with _record(tmp_path / "h.sqlite", year) as store:
        crashed = _check(store, year, "2026-06-20T10:00", 102)
    advice = next(a for a in crashed.advice if a.startswith("re-calibrate"))
    command = re.search(r"\((\S+(?: -m compgen)? measure-program [^)]*)\)", advice)[1]
    # the advice names compgen as this process was called (in-process, whatever an earlier
    # test left: compgen-cli by default): a user who typed that has the venv on PATH
    done = pasted(command, tmp_path, timeout=120)
    assert done.returncode == 0 and (tmp_path / "calibration.H").exists(), (command, done.stderr)
    rc, out, err = run("check-program", "--machine", "ac-trunnion-itnc530", tmp_path / "calibration.H")
    assert rc == 0, out + err


def test_an_edit_written_despite_the_gate_says_so_in_the_history(tmp_path, monkeypatch):
    """The example session's fit misses EXC:h2: kinematics refuses it without --despite-gate
    (--force only overwrites); with it, the history's trend names the edit as written despite
    the gate, with the gate's reasons."""
    monkeypatch.chdir(tmp_path)
    assert run("fit", "--machine", "ac-trunnion-itnc530", ROOT / "examples" / "seed-session.csv",
               "-o", "fit.json")[0] == 0
    args = ["kinematics", "--from", "fit.json", "-o", "EDIT.txt", "--record", "--date", "2026-03-02"]
    rc, _, err = run(*args, "--force")
    assert rc == 2 and "--despite-gate" in err and not (tmp_path / "EDIT.txt").exists()
    rc, out, err = run(*args, "--despite-gate")
    assert rc == 0 and "recorded the edit" in out, out + err
    rc, out, err = run("history", "trend", "--machine", "ac-trunnion-itnc530")
    assert rc == 0, err
    edit = next(ln for ln in out.splitlines() if " edit " in f" {ln} ")
    assert "written despite the fit gate: diagnose finds effects the model misses" in edit, out


@pytest.mark.parametrize("text, stored", [
    ("2026-03-01T10:00+02:00", "2026-03-01T08:00:00+00:00"),
    ("2026-03-01T09:00-01:00", "2026-03-01T10:00:00+00:00"),
    ("2026-03-01", "2026-03-01T00:00:00+00:00"),
])
def test_dates_are_kept_as_utc_instants(text, stored):
    """10:00 at +02:00 comes before 09:00 at −01:00: kept as UTC, the text orders as time does."""
    assert H.taken_at(text) == stored


@pytest.mark.parametrize("text", ["9999-01-01", "1969-12-31T23:59+00:00", "2026-13-01", "yesterday",
                                  "3000-01-01T00:00Z", "2026-03-01\n2027", "2026-03-01x10:00", "2026-W09",
                                  "\u0662\u0660\u0662\u0666-03-01"])
def test_a_date_no_measurement_was_taken_on_is_refused(text):
    with pytest.raises(CompgenError, match="is not a date"):
        H.taken_at(text)


@pytest.mark.parametrize("kind", STORES)
def test_an_edit_is_ordered_against_its_fit_in_time_not_as_text(tmp_path, year, request, kind):
    """A fit taken 10:00 at +02:00 (08:00 UTC) and an edit at 09:00 at +00:00: the edit comes
    after the fit and is recorded; at 07:30 UTC given as 09:30+02:00 it comes before, refused
    (as text, "09:30+02:00" > "08:00" and "09:00+00:00" < "10:00+02:00" said the opposite)."""
    machine, _, fits, (efit, corrects) = year
    store = open_store(_store(kind, request, tmp_path))
    try:
        H.record_fit(store, efit, machine, taken="2026-03-01T10:00+02:00")
        with pytest.raises(CompgenError, match="cannot come before the fit"):
            H.record_edit(store, efit, machine, "itnc530", corrects, {}, {}, taken="2026-03-01T09:30+02:00")
        H.record_edit(store, efit, machine, "itnc530", corrects, {}, {}, taken="2026-03-01T09:00+00:00")
    finally:
        store.close()


def _first(tables, name):
    return tables[name][0]


@pytest.mark.parametrize("damage, says", [
    (lambda t: _first(t, "sessions").update(taken="9999-01-01"), "sessions row .*is not a date a "
                                                                 "measurement"),
    (lambda t: _first(t, "sessions").update(taken="2026-02-30"), "sessions row .*is not a date"),
    (lambda t: _first(t, "fits").update(sigma_um="0.5"), "fits row .*sigma_um is not a finite number"),
    (lambda t: _first(t, "fits").update(rms_um=True), "rms_um is not a finite number"),
    (lambda t: _first(t, "fits").update(parameters="{broken"), "parameters is not JSON"),
    (lambda t: _first(t, "fits").update(kind="calibrated"), "kind is neither"),
    (lambda t: _first(t, "fits").update(marker="fit:000000"), "is not its fit's"),
    (lambda t: _first(t, "fits").update(parameters=json.dumps({"XOC": {"value": 1, "std": 0.1,
                                                                         "unit": "mm"}})),
     "model or parameters are not its fit_json's"),
    (lambda t: _first(t, "fits").update(session_id=10 ** 9), "session_id names no session"),
    (lambda t: _first(t, "machines").update(name="a\nb"), "name is not one line"),
    (lambda t: _first(t, "machines").update(serial="A/B C"), "machines row .*not a valid serial"),
    (lambda t: _first(t, "edits").update(controller="fanuc"), "controller is none compgen knows"),
    (lambda t: _first(t, "edits").update(taken="tomorrow"), "edits row .*is not a date"),
    (lambda t: _first(t, "sessions").pop("machine_sha256"), "sessions row .*columns are not a session's "
                                                            r"\(machine_sha256\)"),
    (lambda t: _first(t, "fits").update(recorded_by="owner"), "columns are not a fit's"),
    (lambda t: _first(t, "sessions").update(temperatures='{"hall": "21"}'), "a temperature is not a finite"),
    (lambda t: _first(t, "sessions").update(temperatures="[21.5]"), "temperatures is not a JSON dict"),
    (lambda t: _first(t, "fits").update(parameters=json.dumps({"XOC": {"value": float("nan"), "std": 0.1,
                                                                         "unit": "mm"}})),
     "a parameter's value or σ is not a finite number"),
    (lambda t: _first(t, "fits").update(fit_json="{}"), "fit_json is not a fit compgen wrote"),
    (lambda t: _first(t, "machines").update(id="1"), "machines row '1': no whole-number id"),
    (lambda t: _first(t, "edits").update(corrects="[]"), "corrects is not a JSON dict"),
    (lambda t: t.pop("edits"), r"incomplete or damaged \(KeyError\('edits'\)\)"),
    # rows each well formed, but changed against what they hold (issue 65's held-out round)
    (lambda t: _first(t, "edits").update(corrects=json.dumps(
        {n: v * 2 for n, v in json.loads(_first(t, "edits")["corrects"]).items()})),
     "it corrects values its fit does not hold: the row was changed"),
    (lambda t: _first(t, "fits").update(kind="check"), r"its kind \(check\) is not what the checks say"),
    (lambda t: _first(t, "fits").update(fit_json=json.dumps(
        {**json.loads(_first(t, "fits")["fit_json"]), "residual": {
            **json.loads(_first(t, "fits")["fit_json"])["residual"], "sigma_um": 4.0}}), verdict="accepted"),
     "accepted with σ̂ 4.00 µm, beyond the fit gate's 3 µm: the verdict was changed"),
    # rows each valid, twice: what the store keeps once, refused before a store is opened
    (lambda t: t["fits"].append({**_first(t, "fits"), "id": 10 ** 6}),
     "fit fit:[0-9a-f]+ of .* is in the export twice"),
    (lambda t: t["edits"].append({**_first(t, "edits"), "id": 10 ** 6}), "a second edit from one fit"),
    (lambda t: t["sessions"].append({**_first(t, "sessions")}), "sessions row 1: its id is another row's"),
])
@pytest.mark.parametrize("kind", STORES)
def test_an_import_with_a_damaged_row_is_refused_and_leaves_the_store_as_it_was(tmp_path, year, monkeypatch,
                                                                               request, kind, damage, says):
    """Each row is checked before the import's transaction: a bad date, text in a number,
    broken JSON, a kind, an id, a changed fit: one line, and the store as it was (an SQLite
    file byte for byte; every row of a PostgreSQL store)."""
    monkeypatch.chdir(tmp_path)
    _record(tmp_path / "a.sqlite", year).close()
    assert run("history", "export", "--db", "a.sqlite", "-o", "a.json")[0] == 0
    doc = json.loads((tmp_path / "a.json").read_text())
    damage(doc["tables"])
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    b = _store(kind, request, tmp_path, "b")
    before, rows = (tmp_path / "b.sqlite").read_bytes() if kind == "sqlite" else None, _contents(b)
    rc, _, err = run("history", "import", "bad.json", "--db", b)
    assert rc == 2 and re.search(says, err) and "nothing was imported" in err, err
    assert len(err.splitlines()) == 1
    assert _contents(b) == rows
    if kind == "sqlite":
        assert (tmp_path / "b.sqlite").read_bytes() == before
        rc, _, err = run("history", "import", "bad.json", "--db", "new.sqlite")   # nor is a store made for it
        assert rc == 2 and not (tmp_path / "new.sqlite").exists(), err
    rc, out, err = run("history", "import", "a.json", "--db", b)     # the export as written imports
    assert rc == 0, err
    assert len(_contents(b)["fits"]) == len(rows["fits"]) + 12


@pytest.mark.parametrize("dsn, shown", [
    ("postgresql://u:p@ss@host/db", "postgresql://u:***@host/db"),
    ("POSTGRESQL://u:secret@h/db", "POSTGRESQL://u:***@h/db"),
    ("postgresql+psycopg://u:secret@h/db", "postgresql+psycopg://u:***@h/db"),
    ("postgresql:/u:secret@h/db", "postgresql:/u:***@h/db"),
    ("port=5432 dbname=x password=a@b", "port=5432 dbname=x password=***"),
    ("host=h password='a b\\' c' dbname=d", "host=h password=*** dbname=d"),
])
def test_a_password_is_never_shown_in_part(dsn, shown):
    from compgen.history.store import redact
    assert redact(dsn) == shown and "ss@" not in redact(dsn) and "secret" not in redact(dsn)


@pytest.mark.parametrize("dsn, postgres", [
    ("port=5432 dbname=plant", True),          # a keyword DSN not starting with host/dbname/user
    ("options='-c x=y' dbname=plant", True),
    ("sqlite:///odd=name.sqlite", False),
    ("plain.sqlite", False),
])
def test_a_keyword_dsn_is_read_by_libpq_never_taken_for_a_file(tmp_path, monkeypatch, dsn, postgres):
    from compgen.history.store import _is_postgres
    monkeypatch.chdir(tmp_path)
    assert _is_postgres(dsn) == postgres
    rc, _, err = run("history", "list", "--db", "password=hunter2 nonsense=1")
    assert rc == 2 and "hunter2" not in err and "libpq" in err, err
    assert list(tmp_path.iterdir()) == []            # no file named after the DSN


def test_the_drift_line_kept_as_sums_is_the_weighted_least_squares_line():
    """trend/check read a machine's fits once: the drift's slope and σ kept as running sums
    equal the weighted least-squares line fitted anew (σ scaled up by the scatter)."""
    rng = np.random.default_rng(7)
    for n in (3, 5, 40):
        days = np.sort(rng.uniform(0, 400, n))
        std = rng.uniform(0.2, 2.0, n) * UM
        y = 0.01 + 1.3 * UM * days / H.DAYS_PER_MONTH + rng.normal(0, 1, n) * std * rng.uniform(0.5, 3)
        entries = [H.Entry(i, H.taken_at("2026-01-01T00:00Z") if i == 0 else
                           (np.datetime64("2026-01-01T00:00") + np.timedelta64(int(d * 86400), "s"))
                           .astype(str) + "+00:00", "fit:0", "calibration", "rtest", "accepted", 1.0,
                           {"YOC": float(v)}, {"YOC": float(s)}, {"YOC": "mm"}, {})
                   for i, (d, v, s) in enumerate(zip(np.r_[0, days[1:]], y, std, strict=True))]
        from compgen.history.drift import _Line
        line = _Line(entries[0].taken)
        for e in entries:
            line.add(e, "YOC")
        t = np.array([H.days(entries[0].taken, e.taken) / H.DAYS_PER_MONTH for e in entries])
        w = 1 / std ** 2
        A = np.column_stack([np.ones(n), t]) * np.sqrt(w)[:, None]
        coef = np.linalg.lstsq(A, y * np.sqrt(w), rcond=None)[0]
        chi2 = np.sum(w * (y - A @ coef / np.sqrt(w)) ** 2) / max(n - 2, 1)
        sigma = np.sqrt(np.linalg.inv(A.T @ A)[1, 1] * max(chi2, 1.0))
        assert line.slope() == pytest.approx((coef[1], sigma), rel=1e-6)
    # fits all taken at one instant (one day's sessions dated alike) hold no slope: an unknown
    # rate (σ infinite), never flagged as a drift, however their values differ
    line = _Line(entries[0].taken)
    for k in range(3):
        line.add(replace(entries[0], values={"YOC": 0.01 + k * 0.1}), "YOC")
    assert line.slope() == (0.0, math.inf)


def test_a_serial_is_one_line_by_the_machine_files_rule(tmp_path, fit_file):
    rc, _, err = run("history", "add", fit_file, "--serial", "A\nB", "--db", tmp_path / "h.sqlite")
    assert rc == 2 and "not a valid serial" in err and len(err.splitlines()) == 1, err
    rc, _, err = run("history", "add", fit_file, "--date", "9999-01-01", "--db", tmp_path / "h.sqlite")
    assert rc == 2 and "not a date" in err and not (tmp_path / "h.sqlite").exists(), err   # no store made


def test_check_refuses_a_machine_file_changed_since_the_calibration(year, tmp_path):
    machine = year[0]
    changed = tmp_path / "m.toml"
    changed.write_text((ROOT / "machines" / "ac-trunnion-itnc530.toml").read_text() + "\n# changed\n")
    other = load_machine(str(changed))
    assert other.name == machine.name and other.sha256 != machine.sha256
    with _record(tmp_path / "h.sqlite", year) as store:
        d = _session(machine, _truth(machine, year[1], "2026-08-10T10:00", year[3][1]), ["K4"], 103, "c.csv")
        fit = identify(other, [d], location_model(other))
        when = H.taken_at("2026-08-10T10:00")
        calibration, entries, edits = H.last_calibration(store, other, before=when)
        with pytest.raises(CompgenError, match="machine file changed since the calibration") as got:
            H.check(other, fit, [d], calibration, entries, edits, when)
        assert "--machine-changed" in str(got.value)
        result = H.check(other, fit, [d], calibration, entries, edits, when, machine_changed=True)
        assert result.passed and result.summary()["machine_file_changed"] is True
        assert "machine file changed since that calibration" in result.text()
        assert H.check(machine, fit, [d], calibration, entries, edits, when).summary()[
            "machine_file_changed"] is False


def test_the_same_edit_twice_is_one_row_and_a_second_edit_from_a_fit_is_refused_before_writing(
        tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert run("fit", "--machine", "ac-trunnion-itnc530", ROOT / "examples" / "seed-session.csv",
               "-o", "fit.json")[0] == 0
    args = ["kinematics", "--from", "fit.json", "--record", "--date", "2026-03-02", "--despite-gate"]
    rc, out, err = run(*args, "-o", "EDIT.txt")
    assert rc == 0 and "recorded the edit as #1" in out, out + err
    rc, out, err = run(*args, "-o", "EDIT.txt", "--force")         # the same edit again: one row
    assert rc == 0 and "this edit is recorded already (#1" in out, out + err
    rc, out, err = run(*args, "-o", "OTHER.txt")                   # other files: refused, nothing written
    assert rc == 2 and "a fit's correction is made once" in err and not (tmp_path / "OTHER.txt").exists()
    with open_store("compgen-history.sqlite") as store:
        assert store.rows("SELECT COUNT(*) AS n FROM edits") == [{"n": 1}]
        fit = load_fit("fit.json")
        machine = load_machine("ac-trunnion-itnc530")
        with pytest.raises(H.Recorded):
            H.record_edit(store, fit, machine, "itnc530", {}, H.edit_of(store, fit, machine)["written"], {},
                          taken="2026-03-03")


ADD_SAME = """
import sys, time
from compgen import history as H
from compgen.configuration.machine_file import load_machine
from compgen.statistics.results import load_fit
from compgen.history.store import open_store
from compgen.history import ledger
look = ledger._fit_rows
def slow(*args):                 # every writer looks, finds nothing, and only then inserts
    found = look(*args)
    time.sleep(1.5)
    return found
ledger._fit_rows = slow
store, fit, machine = open_store(sys.argv[2]), load_fit(sys.argv[1]), load_machine("ac-trunnion-itnc530")
time.sleep(max(float(sys.argv[3]) - time.time(), 0))      # and all at once
try:
    H.record_fit(store, fit, machine, taken="2026-02-01")
except H.Recorded as exc:
    sys.exit(str(exc))
"""


def test_eight_writers_adding_the_same_fit_at_once_make_one_row(pg_db, fit_file):
    """Every writer looks first and finds nothing; the database's unique key lets one in."""
    assert run("history", "init", "--db", pg_db)[0] == 0
    with open_store(pg_db) as store, store.writing():     # the machine is known: its row holds no one up
        H.lookup_machine(store, *H.machine_key(load_machine("ac-trunnion-itnc530")), create=True)
    start = time.time() + 4
    procs = [subprocess.Popen([sys.executable, "-c", ADD_SAME, str(fit_file), pg_db, str(start)],
                              env={**os.environ, "PYTHONPATH": str(ROOT)}, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(8)]
    done = [(p.communicate(timeout=240), p.returncode) for p in procs]
    assert sorted(rc for _, rc in done) == [0] + [1] * 7, done
    assert all("is already in the history" in err for (_, err), rc in done if rc == 1), done
    with open_store(pg_db) as store:
        assert _counts(store) == {"machines": 1, "sessions": 1, "fits": 1}


def test_a_writer_can_neither_break_the_schema_nor_pass_a_forged_calibration_to_check(pg_db, fit_file, year):
    import psycopg
    with psycopg.connect(pg_db, autocommit=True) as owner:
        owner.execute("CREATE ROLE forger LOGIN")
    assert run("history", "init", "--db", pg_db, "--grant", "forger")[0] == 0
    writer = pg_db.replace("compgen_owner@", "forger@")
    machine = year[0]
    with open_store(writer) as store:
        H.record_fit(store, load_fit(fit_file), machine, taken="2026-01-01T09:00Z")
    with psycopg.connect(writer, autocommit=True) as db:
        with pytest.raises(psycopg.errors.InsufficientPrivilege):
            db.execute("INSERT INTO compgen.compgen_schema VALUES ('compgen.history', 99, 'x', 'now')")
        # a forged calibration: the real fit's row with BOA's value changed, claiming the owner wrote it
        row = db.execute("SELECT session_id, marker, kind, model, parameters, sigma_um, rms_um, verdict, "
                         "fit_json, recorded FROM compgen.fits").fetchone()
        params = json.loads(row[4])
        params["BOA"]["value"] += 100 * ARCSEC
        session = db.execute(
            "INSERT INTO compgen.sessions (machine_id, taken, device, operator, temperatures, "
            "machine_sha256, data, recorded) SELECT machine_id, '2026-01-02T09:00:00+00:00', device, "
            "operator, temperatures, "
            "machine_sha256, data, recorded FROM compgen.sessions RETURNING id").fetchone()[0]
        db.execute("INSERT INTO compgen.fits (session_id, marker, kind, model, parameters, sigma_um, rms_um, "
                   "verdict, fit_json, recorded, recorded_by) VALUES (%s, %s, %s, %s, %s, %s, %s, %s, %s, "
                   "%s, 'compgen_owner')", (session, *row[1:4], json.dumps(params), *row[5:]))
        # ids claimed ahead of the sequence: the database gives its own, so no writer is blocked
        last = db.execute("SELECT MAX(id) FROM compgen.machines").fetchone()[0]
        for ahead in range(1, 4):
            db.execute("INSERT INTO compgen.machines (id, name, serial, recorded) OVERRIDING SYSTEM VALUE "
                       "VALUES (%s, %s, '', 'now')", (last + ahead, f"squatter {ahead}"))
        # a row no reader can read: refused by PostgreSQL itself
        for bad in ("INSERT INTO compgen.sessions (machine_id, taken, device, operator, temperatures, "
                    "machine_sha256, data, recorded) SELECT machine_id, 'not a date', device, operator, "
                    "temperatures, machine_sha256, data, recorded FROM compgen.sessions LIMIT 1",
                    "INSERT INTO compgen.sessions (machine_id, taken, device, operator, temperatures, "
                    "machine_sha256, data, recorded) SELECT machine_id, taken, device, operator, '{', "
                    "machine_sha256, data, recorded FROM compgen.sessions LIMIT 1",
                    "INSERT INTO compgen.fits (session_id, marker, kind, model, parameters, sigma_um, "
                    "rms_um, verdict, fit_json, recorded) SELECT session_id, marker, kind, model, "
                    "parameters, 'NaN', rms_um, verdict, fit_json, recorded FROM compgen.fits LIMIT 1"):
            with pytest.raises((psycopg.errors.CheckViolation, psycopg.errors.InvalidTextRepresentation)):
                db.execute(bad)
    with open_store(writer) as store:
        other = replace(machine, name="another machine")
        H.record_fit(store, load_fit(fit_file), other, taken="2026-01-03T09:00Z")
        ids = [r["id"] for r in store.rows("SELECT id FROM machines ORDER BY id")]
        assert len(ids) == 5 and ids == list(range(ids[0], ids[0] + 5)), ids
    with open_store(pg_db) as store:
        assert store.version() == 6           # the store still opens for everyone
        assert {r["recorded_by"] for r in store.rows("SELECT recorded_by FROM fits")} == {"forger"}
        # who and when are the database's: a writer's "now" is its clock's instant, by its role
        squat = store.rows("SELECT recorded, recorded_by FROM machines WHERE name LIKE ?", ("squatter%",))
        assert len(squat) == 3 and {r["recorded_by"] for r in squat} == {"forger"}, squat
        instant = r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\+00:00"
        assert all(re.fullmatch(instant, r["recorded"]) for r in squat), squat
        with pytest.raises(CompgenError, match=r"recorded by forger\).*does not hold the values its own fit"):
            H.last_calibration(store, machine)


def test_a_machine_name_with_mathtext_and_a_writers_line_break_print_as_written(tmp_path, monkeypatch):
    """A name is text: "$\\undefinedcmd_{$" once stopped the trend plot (matplotlib read it as
    mathtext); a name with a line break, as a database writer can append it, stays on its line."""
    monkeypatch.chdir(tmp_path)
    text = (ROOT / "machines" / "ac-trunnion-itnc530.toml").read_text()
    name = r'name = "Cell $\\\\undefinedcmd_{$ 3"'
    (tmp_path / "m.toml").write_text(re.sub(r"(?m)^name = .*$", name, text))
    assert run("simulate", "--machine", "m.toml", "--truth", ROOT / "examples" / "truth-table4.json",
               "--paths", "K4", "--noise-um", "0.5", "--seed", "1", "-o", "a.csv")[0] == 0
    rc, out, err = run("fit", "--machine", "m.toml", "a.csv", "-o", "fit.json", "--record", "--date",
                       "2026-03-01")
    assert rc == 0, err
    rc, out, err = run("history", "trend", "--machine", "m.toml", "--plot", "t.png")
    assert rc == 0 and (tmp_path / "t.png").read_bytes()[:4] == b"\x89PNG", out + err
    with open_store("compgen-history.sqlite") as store, store.writing():
        store.insert("machines", {"name": "forged\nPASS: all machines", "serial": "", "recorded": "x"})
        store.insert("machines", {"name": "L" * 60, "serial": "SN-1", "recorded": "x"})
        store.insert("machines", {"name": "M", "serial": "S" * 20, "recorded": "x"})
    rc, out, err = run("history", "list")
    assert rc == 0 and "PASS: all machines" in out and not any(
        ln.startswith("PASS") for ln in out.splitlines()), out
    rc, out, err = run("history", "fleet")
    assert rc == 0 and not any(ln.startswith("PASS") for ln in out.splitlines()), out
    long = next(ln for ln in out.splitlines() if ln.startswith("L"))      # cut to its column, aligned
    assert long[:40] == "L" * 39 + " " and long[40:44] == "SN-1", out
    serial = next(ln for ln in out.splitlines() if ln.startswith("M "))
    assert serial[40:54] == "S" * 13 + " " and serial[54:55] == "-", out
    # a check may be due within a day; never at once
    assert run("history", "fleet", "--every-days", "0.5")[0] == 0
    rc, _, err = run("history", "fleet", "--every-days", "0")
    assert rc == 2 and "--every-days" in err, err


@pytest.mark.parametrize("dsn, secret", [("postgres://u:p@s3cr3t-Pw@127.0.0.1:1/db", "s3cr3t"),
                                         ("postgresql+psycopg://u:s3cr3t-Pw@127.0.0.1:1/db", "s3cr3t"),
                                         ("postgresql:/u:s3cr3t-Pw@127.0.0.1:1/db", "s3cr3t"),
                                         ("postgresql:u:s3cr3t-Pw@127.0.0.1:1/db", "s3cr3t"),
                                         ("mysql://u:s3cr3t-Pw@127.0.0.1:1/db", "s3cr3t"),
                                         ("postgres://u:p@Pw4@127.0.0.1:1/db", "Pw4"),   # short
                                         ("s3cr3t-Pw=x", "s3cr3t"),
                                         ("host=127.0.0.1 port=1 password = s3cr3t-Pw", "s3cr3t"),
                                         ("password='s3cr3t-Pw x' port=1", "s3cr3t")])
def test_no_message_shows_a_password_however_libpq_reads_the_dsn(tmp_path, dsn, secret):
    """libpq reads "u:p@s3cr3t-Pw@host" as the password p and the host "s3cr3t-Pw@host",
    and its message names that host; a DSN it cannot read is not echoed at all. Nor is a
    bad --date leaving a store behind."""
    for args in (["history", "list"], ["history", "init"]):
        rc, out, err = run(*args, "--db", dsn)
        assert rc == 2 and secret not in out + err and len(err.splitlines()) == 1, err
    rc, _, err = run("history", "list", "--db", tmp_path / "h.sqlite")
    assert rc == 2 and not (tmp_path / "h.sqlite").exists()


def test_rows_an_older_compgen_kept_with_their_offsets_are_read_in_time_order(tmp_path, year):
    """Before dates were kept as UTC instants, "2026-03-01T10:00:00+02:00" (08:00 UTC) was
    stored as given: as text it sorts after "2026-03-01T09:00:00+00:00", in time before."""
    machine, _, fits, _ = year
    with open_store(tmp_path / "h.sqlite") as store:
        H.record_fit(store, fits[0][1], machine, taken="2026-03-01T09:00:00+00:00")
        session = store.rows("SELECT * FROM sessions")[0]
        fit = store.rows("SELECT * FROM fits")[0]
        with store.writing():
            sid = store.insert("sessions", {k: v for k, v in session.items() if k != "id"}
                               | {"taken": "2026-03-01T10:00:00+02:00"})
            store.insert("fits", {k: v for k, v in fit.items() if k not in ("id", "content_sha256")}
                         | {"session_id": sid, "marker": "fit:older"})
        t = H.trend(store, machine)
        assert [(e.marker, e.taken) for e in t.entries] == [
            ("fit:older", "2026-03-01T08:00:00+00:00"), (fit["marker"], "2026-03-01T09:00:00+00:00")]
        assert H.fleet(store, 90.0)[0]["last_calibration"] == "2026-03-01T09:00:00+00:00"


@pytest.mark.parametrize("noise_um, said", [(1.3, True), (0.9, False)])
def test_a_check_far_noisier_than_its_calibration_asks_to_check_the_set_up(year, tmp_path, noise_um, said):
    """The calibrations leave σ̂ ≈ 0.5 µm: a check at 1.3 µm (over twice that, and over
    1 µm) asks for the set-up to be checked; one at 0.9 µm does not."""
    machine, base, _, (_, corrects) = year
    with _record(tmp_path / "h.sqlite", year) as store:
        when = H.taken_at("2026-08-10T10:00")
        truth = _truth(machine, base, "2026-08-10T10:00", corrects)
        d = simulate(machine, truth, generate(machine, ["K4"]), noise_um, np.random.default_rng(5))
        fit = identify(machine, [d], location_model(machine))
        calibration, entries, edits = H.last_calibration(store, machine, before=when)
        assert calibration.sigma_um < 0.6
        result = H.check(machine, fit, [d], calibration, entries, edits, when)
        assert any("check the set-up" in a for a in result.advice) == said, result.advice


@pytest.mark.parametrize("noise_um, said", [(1.3, True), (0.9, False)])
def test_a_check_under_a_micrometre_never_blames_the_set_up(year, tmp_path, noise_um, said):
    """Against a calibration of σ̂ 0.3 µm (a quiet day), a check at 0.9 µm is three times
    noisier yet within what the R-test gives on any day (1 µm): the set-up is not blamed; at
    1.3 µm it is."""
    from dataclasses import replace
    machine, base, _, (_, corrects) = year
    with _record(tmp_path / "h.sqlite", year) as store:
        when = H.taken_at("2026-08-10T10:00")
        truth = _truth(machine, base, "2026-08-10T10:00", corrects)
        d = simulate(machine, truth, generate(machine, ["K4"]), noise_um, np.random.default_rng(5))
        fit = identify(machine, [d], location_model(machine))
        calibration, entries, edits = H.last_calibration(store, machine, before=when)
        quiet = replace(calibration, sigma_um=0.3)
        result = H.check(machine, fit, [d], quiet, entries, edits, when)
        assert any("check the set-up" in a for a in result.advice) == said, result.advice


def test_an_unknown_machine_is_refused_naming_the_first_five_recorded(tmp_path):
    """A machine not in the store is refused, and the hint names what is recorded, in order,
    five at most (a plant's store holds dozens: the line stays one line)."""
    machine = load_machine("ac-trunnion-itnc530")
    with open_store(tmp_path / "h.sqlite") as store:
        store.migrate()
        for k in range(7):
            H.lookup_machine(store, f"mill {7 - k}", "S1" if k % 2 else "", create=True)
        said = re.escape(f"no calibration of '{machine.name}' is recorded")
        with pytest.raises(CompgenError, match=said) as e:
            H.machine_id(store, machine)
    assert str(e.value).endswith(". Recorded: mill 1; mill 2 (S1); mill 3; mill 4 (S1); mill 5"), str(e.value)


def test_a_failed_check_names_the_change_furthest_beyond_its_own_limit(year, tmp_path):
    """YOC 2 times its limit away (10 µm of 5) and BOA 3 times (30″ of 10″): both fail, and
    the advice names BOA as moved most, each change against the limit of its own unit."""
    with _record(tmp_path / "h.sqlite", year) as store:
        checked = _check(store, year, "2026-05-10T10:00", 105, {"YOC": 10 * UM, "BOA": 30 * ARCSEC})
    failed = {c.param: abs(c.change) / c.limit for c in checked.changes if c.status == "fail"}
    assert set(failed) == {"YOC", "BOA"} and 1.8 < failed["YOC"] < 2.5 < failed["BOA"] < 3.3, failed
    assert any(a.startswith("re-calibrate: ") and "(BOA, " in a and ", most)" in a for a in checked.advice), \
        checked.advice


def test_a_change_beyond_its_limit_but_within_its_noise_asks_to_measure_more(year, tmp_path):
    """YOC 7 µm away (limit 5 µm) measured with a noisy check (12 µm): beyond its limit but
    within 3 σ: unsure, and the advice asks to measure more, naming it."""
    with _record(tmp_path / "h.sqlite", year) as store:
        checked = _check(store, year, "2026-05-10T10:00", 106, {"YOC": 7 * UM}, noise_um=12.0)
    unsure = [c for c in checked.changes if c.status == "unsure"]
    assert [c.param for c in unsure] == ["YOC"] and not checked.passed
    assert ("measure more (all paths, or the check path twice): YOC may have moved beyond its limit, "
            "but its σ is too large to say") in checked.advice, checked.advice


def test_a_fit_measured_at_the_edit_s_instant_follows_it_in_the_trend(year, tmp_path):
    """A fit taken at the very instant the edit was recorded counts that edit's corrections
    (written before it, to the second), and the trend shows the edit's row first."""
    machine, base, _, (_, corrects) = year
    with _record(tmp_path / "h.sqlite", year) as store:
        d = _session(machine, _truth(machine, base, EDIT_DATE, corrects), ["K4", "K1", "K2"], 107, "same.csv")
        H.record_fit(store, identify(machine, [d], location_model(machine)), machine, taken=EDIT_DATE)
        t = H.trend(store, machine)
    same = next(e for e in t.entries if e.taken == EDIT_DATE)
    assert same.corrected == pytest.approx(dict(corrects))
    rows = _trend_rows(H.trend_text(t), "2026-07")
    assert rows == [("2026-07-01", False), ("2026-07-02", True), ("2026-07-02", False)], rows


def test_the_drift_defaults_are_those_the_machine_file_doc_gives():
    """docs/machine-file.md's `[drift]` row names each limit with its default in brackets:
    a machine file without `[drift]` takes exactly those (the next check due after 90 days)."""
    from dataclasses import fields

    from compgen.model.machine import Drift
    row = next(line for line in (ROOT / "docs" / "machine-file.md").read_text().splitlines()
               if line.startswith("| `[drift]`"))
    documented = {name: float(value) for name, value in re.findall(r"`(\w+)` \(([\d.]+)\)", row)}
    assert documented == {f.name: f.default for f in fields(Drift) if f.name != "each"}, documented
    assert "`each`" in row and Drift().each == ()          # a limit of its own: none by default
    assert load_machine(SEED_MACHINE).drift == Drift()


def test_the_ledger_refuses_what_it_cannot_key_before_writing(tmp_path, year):
    """The library's own entry points (no CLI in front): a device compgen does not know, a
    fit made with another machine file, an edit whose fit was never recorded, each one line,
    and the store left without a row."""
    machine, _, fits, (efit, corrects) = year
    store = init(tmp_path / "h.sqlite")[0]
    when, fit, verdict = fits[0]
    with pytest.raises(CompgenError, match="device must be one of rtest, probe, not 'laser'"):
        H.record_fit(store, fit, machine, taken=when, device="laser")
    other = replace(machine, sha256="0" * 64)
    with pytest.raises(CompgenError, match="another machine file than the one given"):
        H.record_fit(store, fit, other, taken=when)
    with pytest.raises(CompgenError, match=rf"the edit's fit \({efit.marker}\) is not in the history"):
        H.record_edit(store, efit, machine, "itnc530", corrects, {"EDIT.TAB": "0" * 64}, {}, taken=EDIT_DATE)
    assert store.rows("SELECT id FROM fits") == [] and store.rows("SELECT id FROM edits") == []
    store.close()


def _foreign_schema(path):
    with contextlib.closing(sqlite3.connect(path)) as db:
        db.execute("CREATE TABLE compgen_schema (app TEXT, version INTEGER, store_id TEXT)")
        db.execute("INSERT INTO compgen_schema VALUES ('another-tool', 1, 'x')")
        db.commit()


@pytest.mark.parametrize("argv, make, says", [
    (["history", "init", "--db", "h.sqlite", "--grant", "reader"], None, "roles are PostgreSQL's"),
    (["history", "init", "--db", "postgresql://u@127.0.0.1:1/plant", "--grant", "r; DROP SCHEMA x"], None,
     "'r; DROP SCHEMA x' is not a plain role name"),
    (["history", "list", "--db", "store"], lambda p: (p / "store").mkdir(), "the history store is a folder"),
    (["history", "list", "--db", "h.sqlite"], lambda p: _foreign_schema(p / "h.sqlite"),
     "compgen_schema is not a compgen history's"),
])
def test_a_store_compgen_cannot_use_is_refused_before_anything_is_made(tmp_path, monkeypatch, argv, make,
                                                                        says):
    """A grant on an SQLite file, a role name that is not one, a folder, another tool's
    schema table: one line, and nothing made or changed (a grant is judged before the store
    is opened: neither a file nor a connection for it)."""
    monkeypatch.chdir(tmp_path)
    if make:
        make(tmp_path)
    before = {p.name: p.read_bytes() if p.is_file() else None for p in tmp_path.iterdir()}
    rc, _, err = run(*argv)
    assert rc == 2 and says in err and len(err.splitlines()) == 1, err
    assert {p.name: p.read_bytes() if p.is_file() else None for p in tmp_path.iterdir()} == before


def test_a_store_without_an_accepted_calibration_says_so(year, tmp_path, monkeypatch):
    """list on a store with no machine, and check where every recorded fit has a reason it
    should not reach the control: one line each, what to do named (nothing to check against
    is not a pass)."""
    monkeypatch.chdir(tmp_path)
    assert run("history", "init", "--db", "h.sqlite")[0] == 0
    rc, out, err = run("history", "list", "--db", "h.sqlite")
    assert rc == 0 and out.strip().endswith("h.sqlite: no machine recorded yet"), out + err
    machine, base, fits, _ = year
    with open_store(tmp_path / "h.sqlite") as store:
        when, fit, _ = fits[0]
        H.record_fit(store, fit, machine, taken=when, verdict=["the fit leaves σ̂ = 4.00 µm"])
    d = _session(machine, _truth(machine, base, "2026-02-01T09:00:00+00:00", {}), ["K4"], 301, "x")
    (tmp_path / "c.csv").write_text(format_rtest(machine, d))
    rc, out, err = run("check", "--machine", "ac-trunnion-itnc530", "c.csv", "--date", "2026-02-01T10:00",
                       "--db", "h.sqlite")
    assert rc == 2 and "no accepted calibration of this machine is recorded" in err, out + err
    assert len(err.splitlines()) == 1


def test_a_check_that_shows_a_new_drift_advises_planning_the_next_calibration(year, tmp_path):
    """Two monthly calibrations, then a check a month later: YOC's 1.5 µm/month (limit 1) is
    a drift from the third point, flagged at the check and advised on in its words."""
    with _record(tmp_path / "h.sqlite", year, months=2) as store:
        result = _check(store, year, "2026-03-01T09:00", 103)
    drift = [f for f in result.flags if f.kind == "drift"]
    assert [f.param for f in drift] == ["YOC"], result.flags
    said = [a for a in result.advice if a.startswith("YOC drifts steadily (")]
    assert len(said) == 1 and "plan the next calibration before it reaches its limit" in said[0], said
    assert drift[0].text().split("  ", 1)[1] in said[0]


def test_a_trend_shows_a_dash_where_a_fit_does_not_hold_the_parameter(year, tmp_path):
    """A fit with an effect added (EXC:h2 here) beside fits of the location errors alone:
    the trend of the effect's parameter has a dash for each fit without it, and its value
    (µm) for the one that holds it."""
    machine, base, _, _ = year
    d = _session(machine, {**base, "EXC:h2c": 2 * UM}, ["K4", "K1", "K2"], 31, "m3.csv")
    added = identify(machine, [d], compose(machine, location_model(machine), ["EXC:h2"]))
    with _record(tmp_path / "h.sqlite", year, months=2) as store:
        H.record_fit(store, added, machine, taken="2026-03-01T09:00", verdict="accepted")
        text = H.trend_text(H.trend(store, machine, params=("EXC:h2c", "YOC")))
    rows = {ln[:10]: ln for ln in text.splitlines() if ln.startswith("2026-")}
    assert list(rows) == ["2026-01-01", "2026-02-01", "2026-03-01"], text
    for day in ("2026-01-01", "2026-02-01"):
        assert re.search(r" {17}- ", rows[day]), rows[day]
    value = added.parameters["EXC:h2c"]
    assert f"{value.value * 1e3:.2f} ± {value.std * 1e3:.2f}" in rows["2026-03-01"], text
    assert " - " not in rows["2026-03-01"]


@pytest.mark.parametrize("kind", ["sqlite", "postgresql"])
@pytest.mark.parametrize("dated", [True, False], ids=["date given", "no date"])
def test_the_first_check_after_an_edit_recorded_with_its_fit_passes(tmp_path, monkeypatch, request, kind,
                                                                     dated):
    """kinematics --record records the fit and its edit at one instant (the --date given, or
    now for both). The edit comes after its fit all the same: the calibration's machine
    values do not hold its own correction, so the same machine measured after the edit was
    loaded checks unchanged (before, every corrected location error failed by its whole
    correction: ZOA -32.6 µm)."""
    monkeypatch.chdir(tmp_path)
    db = request.getfixturevalue("pg_db") if kind == "postgresql" else str(tmp_path / "h.sqlite")
    if kind == "postgresql":
        assert run("history", "init", "--db", db)[0] == 0
    machine = load_machine("ac-trunnion-itnc530")
    from conftest import TABLE4
    pre = _session(machine, TABLE4, ["K4", "K1", "K2"], 31, "pre.csv")
    (tmp_path / "pre.csv").write_text(format_rtest(machine, pre))
    assert run("fit", "--machine", "ac-trunnion-itnc530", "pre.csv", "-o", "fit.json")[0] == 0
    date = ["--date", "2026-11-02T08:00"] if dated else []
    rc, out, err = run("kinematics", "--from", "fit.json", "-o", "EDIT.txt", "--record", *date, "--db", db)
    assert rc == 0 and "recorded the edit" in out, out + err
    corrects = corrected_by(machine, load_fit("fit.json"), controller("itnc530"))
    assert abs(corrects["ZOA"]) > 20 * UM                  # a correction the check would see
    post = _session(machine, {n: v - corrects.get(n, 0.0) for n, v in TABLE4.items()}, ["K4"], 32, "post.csv")
    (tmp_path / "post.csv").write_text(format_rtest(machine, post))
    when = ["--date", "2026-11-03T08:00"] if dated else []
    rc, out, err = run("check", "--machine", "ac-trunnion-itnc530", "post.csv", *when, "--db", db, "--json")
    doc = json.loads(out)
    worst = max(doc["changes"], key=lambda c: abs(c["change"]) / c["std"])
    assert rc == 0 and doc["passed"], (worst, err)
    assert all(abs(c["change"]) < 4 * c["std"] for c in doc["changes"]), worst


@pytest.mark.parametrize("kind", STORES)
def test_every_command_that_records_takes_the_serial(tmp_path, monkeypatch, request, kind):
    """fit --record and kinematics --record take --serial as history add does: the edit goes
    to the machine its fit was recorded under, and no other machine is made."""
    monkeypatch.chdir(tmp_path)
    db = _store(kind, request, tmp_path)
    machine = load_machine("ac-trunnion-itnc530")
    from conftest import TABLE4
    (tmp_path / "pre.csv").write_text(format_rtest(machine, _session(machine, TABLE4, ["K4", "K1", "K2"], 41,
                                                                     "pre.csv")))
    rc, out, err = run("fit", "--machine", "ac-trunnion-itnc530", "pre.csv", "-o", "fit.json", "--record",
                       "--serial", "SN-7", "--date", "2026-11-02", "--db", db)
    assert rc == 0 and "recorded as calibration" in out, out + err
    rc, out, err = run("kinematics", "--from", "fit.json", "-o", "EDIT.txt", "--record", "--serial", "SN-7",
                       "--date", "2026-11-02T10:00", "--db", db)
    assert rc == 0 and "recorded the edit" in out, out + err
    with open_store(db) as store:
        rows = store.rows("SELECT m.serial, COUNT(e.id) AS n FROM machines m LEFT JOIN edits e "
                          "ON e.machine_id = m.id GROUP BY m.serial")
    assert [(r["serial"], r["n"]) for r in rows] == [("SN-7", 1)], rows
    rc, out, err = run("history", "show", "--machine", "ac-trunnion-itnc530", "--serial", "SN-7", "--db", db)
    assert rc == 0 and " edit " in out, out + err
    rc, out, err = run("kinematics", "--from", "fit.json", "-o", "E2.txt", "--record", "--serial", "a b",
                       "--db", db)
    assert rc == 2 and "serial" in err and not (tmp_path / "E2.txt").exists(), err


@pytest.mark.parametrize("scale", [1.0, 8.0 / 1.7], ids=["the example's EXC:h2", "EXC:h2 of 8 um"])
def test_an_unchanged_machine_calibrated_with_an_effect_checks_unchanged(tmp_path, monkeypatch, scale):
    """A calibration that added an error motion (the example's EXC:h2, 1.5/0.8 µm, and one
    of 8 µm) is checked three times, K4 alone, on three days, the machine unchanged. The
    check fits the calibration's model (its added effect refitted where K4 allows, else held)
    and says so: every location error within 3σ of the calibration, no drift flagged, the
    residual at the calibration's noise, PASS. Before, the check fitted the location errors
    alone: ZOA, YOC, COA 6σ off on every check, drifts flagged after three, and with 8 µm
    "check the set-up"."""
    monkeypatch.chdir(tmp_path)
    machine = load_machine("ac-trunnion-itnc530")
    truth = read_truth(ROOT / "examples" / "truth-seed-session.json", machine)
    truth = {n: v * (scale if n.startswith("EXC") else 1.0) for n, v in truth.items()}
    cal = _session(machine, truth, ["K4", "K1", "K2"], 51, "cal.csv")
    (tmp_path / "cal.csv").write_text(format_rtest(machine, cal))
    rc, out, err = run("fit", "--machine", "ac-trunnion-itnc530", "cal.csv", "--add", "EXC:h2", "-o",
                       "cal.json", "--record", "--date", "2026-11-01T08:00")
    assert rc == 0 and "recorded as calibration" in out and "NOT accepted" not in out, out + err
    rc, out, err = run("kinematics", "--from", "cal.json", "-o", "KIN.txt", "--record", "--date",
                       "2026-11-01T09:00")
    assert rc == 0 and "recorded the edit" in out, out + err
    corrects = corrected_by(machine, load_fit("cal.json"), controller("itnc530"))
    after = {n: v - corrects.get(n, 0.0) for n, v in truth.items()}      # the control holds the edit
    for day, seed in ((2, 52), (3, 53), (4, 54)):
        k4 = _session(machine, after, ["K4"], seed, "k")
        (tmp_path / f"k{day}.csv").write_text(format_rtest(machine, k4))
        rc, out, err = run("check", "--machine", "ac-trunnion-itnc530", f"k{day}.csv", "--date",
                           f"2026-11-0{day}T08:00", "--json")
        doc = json.loads(out)
        _meets_schema(doc, "check")
        worst = max(doc["changes"], key=lambda c: abs(c["change"]) / c["std"])
        assert all(c["status"] == "pass" for c in doc["changes"]), (day, worst, doc["advice"])
        assert rc == (0 if scale == 1 else 1) and doc["passed"] == (scale == 1), (day, doc["paths"])
        assert abs(worst["change"]) < 3 * worst["std"], (day, worst)
        assert doc["flags"] == [] and doc["sigma_um"] < 0.7, (day, doc["flags"], doc["sigma_um"])
        assert doc["model"]["effects"] == ["EXC:h2c", "EXC:h2s"], doc["model"]
        assert doc["nothing_to_correct"].startswith("nothing to correct"), doc["nothing_to_correct"]
    (tmp_path / "k5.csv").write_text(format_rtest(machine, _session(machine, after, ["K4"], 55, "k")))
    rc, out, err = run("check", "--machine", "ac-trunnion-itnc530", "k5.csv", "--date", "2026-11-05T08:00")
    assert "set-up and EXC:h2c, EXC:h2s, refitted from these data" in out, out + err


def test_an_edit_dated_before_its_recorded_fit_is_refused_before_its_files_are_written(tmp_path, monkeypatch):
    """The fit recorded on 1 December, its edit with --record dated 1 November: refused in
    one line with nothing written (the four files of the edit were left behind)."""
    monkeypatch.chdir(tmp_path)
    assert run("fit", "--machine", "ac-trunnion-itnc530", ROOT / "examples" / "seed-session.csv", "--add",
               "EXC:h2", "-o", "fit.json")[0] == 0
    assert run("history", "add", "fit.json", "--date", "2026-12-01")[0] == 0
    rc, out, err = run("kinematics", "--from", "fit.json", "-o", "KIN.txt", "--record", "--date",
                       "2026-11-01")
    assert rc == 2 and "an edit cannot come before the fit it was written from" in err, out + err
    assert not list(tmp_path.glob("KIN*"))


NO_NUMBER = "a parameter's value or σ is not a finite number"


@pytest.mark.parametrize("kind, taken, parameters, says", [
    ("sqlite", "not a date", "{}", ("a stored date 'not a date' is not one compgen writes",
                                    "'not a date' is not a date")),
    ("sqlite", "9999-12-31T23:59:59+00:00", "{}", ("a stored date '9999-12-31T23:59:59' lies after today",
                                                   "'9999-12-31T23:59:59+00:00' is not a date a measurement "
                                                   "was taken on")),
    ("sqlite", "2026-03-01T00:00:00+00:00", '{"XOC": 5}', NO_NUMBER),
    ("postgresql", "9999-12-31T23:59:59+00:00", "{}", ("a stored date '9999-12-31T23:59:59' lies after today",
                                                       "'9999-12-31T23:59:59+00:00' is not a date a "
                                                       "measurement was taken on")),
    ("postgresql", "2026-03-01T00:00:00+00:00", '{"XOC": 5}', NO_NUMBER),
    ("postgresql", "2026-03-01T00:00:00+00:00", "[]", "parameters is not a JSON dict"),
], ids=["sqlite, no date", "sqlite, the year 9999", "sqlite, a parameter no number",
        "postgresql, the year 9999", "postgresql, a parameter no number", "postgresql, parameters a list"])
def test_one_unreadable_row_breaks_the_fleet_and_the_export_for_no_one(tmp_path, year, request, kind, taken,
                                                                       parameters, says):
    """A row another writer appended that compgen cannot read: a date that is none (an SQLite
    file's writers are not held by the database), the year 9999 (a date, past the calendar's
    end once a due date is added), parameters that are JSON but no fit's (PostgreSQL holds
    the types and the JSON, not what it says). The fleet lists the others; the export leaves
    the row out with the rows that name it, says so, and imports. Each was an internal error
    for everyone."""
    db = _store(kind, request, tmp_path)
    _record(db, year, months=2).close()
    with _raw(db) as execute:
        execute("INSERT INTO machines (name, serial, recorded) VALUES ('other', '', 'x')")
        mid = execute("SELECT id FROM machines WHERE name = 'other'").fetchone()[0]
        sid = execute("INSERT INTO sessions (machine_id, taken, device, operator, temperatures, "
                      "machine_sha256, data, recorded) VALUES (?, ?, 'rtest', '', '{}', 'x', '[]', 'x') "
                      "RETURNING id", (mid, taken)).fetchone()[0]
        fid = execute("INSERT INTO fits (session_id, marker, kind, model, parameters, sigma_um, rms_um, "
                      "verdict, fit_json, recorded) VALUES (?, 'fit:000000', 'calibration', '[]', ?, 1, 1, "
                      "'accepted', '{}', 'x') RETURNING id", (sid, parameters)).fetchone()[0]
    code, out, err = run("history", "fleet", "--db", db)
    assert code == 0 and "A/C trunnion" in out, out + err
    if isinstance(says, tuple):              # a date: the fleet names it
        assert f"UNREADABLE: {says[0]}" in out, out
    for output in ("e.json", "e.csv"):
        code, out, err = run("history", "export", "--db", db, "-o", tmp_path / output)
        row = (f"sessions row {sid}: {says[1]}" if isinstance(says, tuple) else f"fits row {fid}: {says}")
        assert code == 0 and f"warning: left out {row}" in err, out + err
        assert "1 unreadable row(s) left out" in out and "wrote 22 rows" in out, out
    other = _store(kind, request, tmp_path, "b")
    code, out, err = run("history", "import", tmp_path / "e.json", "--db", other)
    assert code == 0 and "2 fits" in out, out + err


@pytest.mark.parametrize("kind", STORES)
@pytest.mark.parametrize("table, column, value, says", [
    ("fits", "parameters", '{"XOC": 5}', "its parameters are not a fit's"),
    ("fits", "parameters", '{"XOC": {"value": "a", "std": 1, "unit": "mm"}}', "values or σ are not finite"),
    ("fits", "parameters", "[]", "its parameters are not a fit's"),
    ("edits", "corrects", '{"BOA": "-30"}', "its corrections are not finite numbers"),
    ("edits", "corrects", '[]', "its corrections are not finite numbers"),
])
def test_a_machines_row_compgen_cannot_read_is_named_by_show_trend_and_check(tmp_path, year, request,
                                                                             monkeypatch, kind, table, column,
                                                                             value, says):
    """A fit or an edit another writer appended for this machine, JSON of the wrong shape
    (PostgreSQL holds the JSON, not what it says): show, trend and check name the row and
    who recorded it, in one line; each was an internal error. Left out in silence, a machine
    value or a correction would be wrong."""
    monkeypatch.chdir(tmp_path)
    db = _store(kind, request, tmp_path)
    _record(db, year, months=8).close()
    with _raw(db) as execute:
        mid = execute("SELECT id FROM machines").fetchone()[0]
        sid = execute("INSERT INTO sessions (machine_id, taken, device, operator, temperatures, "
                      "machine_sha256, data, recorded) VALUES (?, '2026-09-01T00:00:00+00:00', 'rtest', '', "
                      "'{}', 'x', '[]', 'x') RETURNING id", (mid,)).fetchone()[0]
        params = value if column == "parameters" else "{}"
        fid = execute("INSERT INTO fits (session_id, marker, kind, model, parameters, sigma_um, rms_um, "
                      "verdict, fit_json, recorded) VALUES (?, 'fit:000000', 'calibration', '[]', ?, 1, 1, "
                      "'accepted', '{}', 'x') RETURNING id", (sid, params)).fetchone()[0]
        rid = fid
        if table == "edits":
            rid = execute("INSERT INTO edits (machine_id, fit_id, controller, corrects, written, loaded, "
                          "taken, recorded) VALUES (?, ?, 'itnc530', ?, '{}', '{}', "
                          "'2026-09-02T00:00:00+00:00', 'x') RETURNING id", (mid, fid, value)).fetchone()[0]
    truth = ROOT / "examples" / "truth-table4.json"
    assert run("simulate", "--machine", "ac-trunnion-itnc530", "--truth", truth, "--paths", "K4", "-o",
               "k4.csv")[0] == 0
    who = ", recorded by compgen_owner" if kind == "postgresql" else ""
    for argv in (["history", "show"], ["history", "trend"], ["check", "k4.csv", "--date", "2026-10-01"]):
        code, out, err = run(*argv, "--machine", "ac-trunnion-itnc530", "--db", db)
        assert code == 2 and f"{table[:-1]} #{rid}{who} cannot be read: " in err and says in err, (argv, err)
        assert len(err.strip().splitlines()) == 1 and "internal error" not in err, err


@pytest.mark.parametrize("fit_json", ["NaN", "[]", "5", '"text"'])
def test_a_calibration_whose_fit_json_is_json_of_another_shape_is_refused_in_one_line(tmp_path, year,
                                                                                     monkeypatch, fit_json):
    """Found by the fuzzer's foreign rows: a last accepted calibration whose fit_json is JSON
    but no object (json reads "NaN" as a number) was an internal error in check."""
    monkeypatch.chdir(tmp_path)
    db = _store("sqlite", None, tmp_path)
    _record(db, year, months=2).close()
    with _raw(db) as execute:
        sid = execute("INSERT INTO sessions (machine_id, taken, device, operator, temperatures, "
                      "machine_sha256, data, recorded) VALUES (1, '2026-04-01T00:00:00+00:00', 'rtest', '', "
                      "'{}', 'x', '[]', 'x') RETURNING id").fetchone()[0]
        execute("INSERT INTO fits (session_id, marker, kind, model, parameters, sigma_um, rms_um, "
                "verdict, fit_json, recorded) VALUES (?, 'fit:000000', 'calibration', '[]', '{}', 1, 1, "
                "'accepted', ?, 'x')", (sid, fit_json))
    truth = ROOT / "examples" / "truth-table4.json"
    assert run("simulate", "--machine", "ac-trunnion-itnc530", "--truth", truth, "--paths", "K4", "-o",
               "k4.csv")[0] == 0
    code, _, err = run("check", "--machine", "ac-trunnion-itnc530", "k4.csv", "--date", "2026-06-01",
                       "--db", db)
    assert code == 2 and "does not hold the values its own fit gives" in err, err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("kind", STORES)
def test_a_calibration_whose_values_a_writer_changed_is_never_checked_against(tmp_path, year, request, kind):
    """A writer appends the real calibration's row again, later, with BOA moved 100″ and its
    fit_json as it was (or the marker recomputed by hand): check refuses that calibration,
    naming it, on both stores; it never passes a crashed machine against it."""
    machine = year[0]
    db = _store(kind, request, tmp_path)
    _record(db, year, months=6).close()
    with _raw(db) as execute:
        cols = ("marker", "kind", "model", "parameters", "sigma_um", "rms_um", "verdict", "fit_json",
                "recorded")
        row = execute(f"SELECT {', '.join(cols)} FROM fits ORDER BY id DESC LIMIT 1").fetchone()
        params = json.loads(row[3])
        params["BOA"]["value"] += 100 * ARCSEC
        sid = execute("INSERT INTO sessions (machine_id, taken, device, operator, temperatures, "
                      "machine_sha256, data, recorded) SELECT machine_id, '2026-06-10T09:00:00+00:00', "
                      "device, operator, temperatures, machine_sha256, data, recorded FROM sessions ORDER BY "
                      "id DESC LIMIT 1 RETURNING id").fetchone()[0]
        execute(f"INSERT INTO fits (session_id, {', '.join(cols)}) VALUES (?, {', '.join('?' * len(cols))})",
                (sid, row[0], *row[1:3], json.dumps(params), *row[4:]))
    with open_store(db) as store, pytest.raises(CompgenError, match=r"does not hold the values its own fit"):
        H.last_calibration(store, machine, before=H.taken_at("2026-06-20T10:00"))


@pytest.mark.parametrize("kind", STORES)
def test_another_plants_machine_of_the_same_name_is_merged_only_when_the_user_says_so(tmp_path, year, request,
                                                                                      monkeypatch, kind):
    """Two plants' serial-less machines of one name, measured with the same bundled machine
    file: the import refuses to merge them without --same-machine and leaves the store as
    it was, on both stores; with it, the fits join that machine."""
    monkeypatch.chdir(tmp_path)
    _record(tmp_path / "a.sqlite", year, months=3).close()
    assert run("history", "export", "--db", "a.sqlite", "-o", "a.json")[0] == 0
    d = _store(kind, request, tmp_path, "d")
    with open_store(d) as store:
        fit = year[2][0][1]
        e = fit.parameters["YOC"]
        moved = {**fit.parameters, "YOC": replace(e, value=e.value + 1e-3)}
        H.record_fit(store, replace(fit, parameters=moved), year[0], taken="2025-06-01")
    rows = _contents(d)
    rc, _, err = run("history", "import", "a.json", "--db", d)
    assert rc == 2 and "has no serial, and this store holds a machine of that name" in err, err
    assert _contents(d) == rows
    rc, out, err = run("history", "import", "a.json", "--db", d, "--same-machine", year[0].name)
    assert rc == 0 and "3 fits" in out, err
    with open_store(d) as store:
        assert len(store.rows("SELECT id FROM machines")) == 1 and len(store.rows("SELECT id FROM fits")) == 4


@pytest.mark.parametrize("kind", STORES)
def test_an_edit_filed_under_another_machine_counts_for_no_machine(tmp_path, year, request, kind):
    """A writer appends an edit whose fit is another machine's under this machine's id, with
    a correction that would make a crashed machine pass: it counts for neither (the trend's
    values and the check go by edits whose fit is the machine's own)."""
    machine = year[0]
    db = _store(kind, request, tmp_path)
    with _record(db, year, months=8) as store:
        other = replace(machine, name="another machine")
        fid = H.record_fit(store, year[2][0][1], other, taken="2026-01-05T09:00Z")
        before = {e.taken: e.machine_value("BOA") for e in H.trend(store, machine).entries}
    with _raw(db) as execute:
        mid = execute("SELECT id FROM machines WHERE name = ?", (machine.name,)).fetchone()[0]
        execute("INSERT INTO edits (machine_id, fit_id, controller, corrects, written, loaded, taken, "
                "recorded) VALUES (?, ?, 'itnc530', ?, '{}', '{}', '2026-02-01T00:00:00+00:00', 'x')",
                (mid, fid, json.dumps({"BOA": -30 * ARCSEC})))
    with open_store(db) as store:
        assert len(store.rows("SELECT id FROM edits")) == 2          # the writer's row is there
        after = {e.taken: e.machine_value("BOA") for e in H.trend(store, machine).entries}
    assert after == before


def _colliding(fit):
    """Two fits that differ only in YOC's value and whose 6-digit markers are the same (the
    birthday bound: a few thousand tries)."""
    seen = {}
    for k in range(1, 200_000):
        e = fit.parameters["YOC"]
        other = replace(fit, parameters={**fit.parameters, "YOC": replace(e, value=e.value + k * 1e-6)})
        if (had := seen.get(other.marker)) is not None and had.record_marker != other.record_marker:
            return had, other
        seen[other.marker] = other
    raise AssertionError("no collision found")


@pytest.mark.parametrize("kind", STORES)
def test_two_fits_whose_short_markers_collide_are_two_rows_and_each_keeps_its_edit(tmp_path, year, request,
                                                                                    kind):
    """The store keeps a fit by its 16-digit record marker: two fits with the same 6 digits
    (one in 4 000 distinct fits met it) are both recorded, each edit goes to its own fit,
    and an export of both imports whole. Six digits refused the second as "already in the
    history" and gave its edit to the first."""
    machine = year[0]
    first, second = _colliding(year[2][0][1])
    assert first.marker == second.marker and first.record_marker != second.record_marker
    db = _store(kind, request, tmp_path)
    with open_store(db) as store:
        a = H.record_fit(store, first, machine, taken="2026-01-05T09:00Z")
        b = H.record_fit(store, second, machine, taken="2026-01-06T09:00Z")
        assert a != b
        H.record_edit(store, second, machine, "itnc530", {"YOC": second.parameters["YOC"].value}, {}, {},
                      taken="2026-01-06T10:00Z")
        edited = store.rows("SELECT fit_id FROM edits")
        assert [r["fit_id"] for r in edited] == [b]
        assert H.edit_of(store, first, machine) is None
    out = tmp_path / "x.json"
    assert run("history", "export", "--db", db, "-o", out)[0] == 0
    other = _store(kind, request, tmp_path, "other")
    code, _, err = run("history", "import", out, "--db", other)
    assert code == 0, err
    with open_store(other) as store:
        assert len(store.rows("SELECT id FROM fits")) == 2


@pytest.mark.parametrize("kind", STORES)
def test_a_fit_an_older_compgen_recorded_by_six_digits_is_still_that_fit(tmp_path, year, request, kind):
    """Rows written before the 16-digit record marker keep their 6 digits: the same fit is
    found there (recorded again: refused; its edit: attached to it), and an export holding
    it imports into a store that holds the same fit by 16 digits as "already here"."""
    machine, fit = year[0], year[2][0][1]
    db = _store(kind, request, tmp_path, "old")
    with open_store(db) as store, store.writing():
        mid = H.lookup_machine(store, machine.name, "", create=True)
        fid = H.session_and_fit(store, mid, fit, machine, "2026-01-05T09:00:00+00:00", "rtest", "", {},
                                "calibration", "accepted")
    with _raw(db) as execute:      # the row as an older compgen wrote it: the append-only rule off once
        execute("DROP TRIGGER IF EXISTS fits_no_update" if kind == "sqlite"
                else "ALTER TABLE fits DISABLE TRIGGER fits_append_only")
        execute("UPDATE fits SET marker = ? WHERE id = ?", (fit.marker, fid))
        if kind == "postgresql":
            execute("ALTER TABLE fits ENABLE TRIGGER fits_append_only")
    with open_store(db) as store:
        assert store.rows("SELECT marker FROM fits")[0]["marker"] == fit.marker      # as 6 digits
        with pytest.raises(CompgenError, match="already in the history"):
            H.record_fit(store, fit, machine)
        H.record_edit(store, fit, machine, "itnc530", {}, {}, {}, taken="2026-01-06T10:00Z")
        assert H.edit_of(store, fit, machine)["id"]
    assert run("history", "export", "--db", db, "-o", tmp_path / "old.json")[0] == 0
    new = _store(kind, request, tmp_path, "new")
    with open_store(new) as store:
        H.record_fit(store, fit, machine, taken="2026-01-05T09:00Z")
    code, _, err = run("history", "import", tmp_path / "old.json", "--db", new,
                       "--same-machine", machine.name)
    assert code == 2 and "already here" in err, err


@pytest.mark.parametrize("kind", STORES)
def test_an_export_beyond_the_64_mb_of_a_control_file_imports(tmp_path, year, monkeypatch, request, kind):
    """A plant's years are 140 MB of export (10 000 fits: benchmarks/history_import_scale.py);
    the import reads up to the data files' 256 MB (it refused anything past 64 MB, an
    export compgen itself had written). Here a small export padded past 64 MB with the white
    space JSON allows."""
    monkeypatch.chdir(tmp_path)
    _record(tmp_path / "a.sqlite", year, months=2).close()
    assert run("history", "export", "--db", "a.sqlite", "-o", "a.json")[0] == 0
    with open(tmp_path / "a.json", "a") as f:
        f.write(" " * (65 * 2**20))
    rc, out, err = run("history", "import", "a.json", "--db", _store(kind, request, tmp_path, "b"))
    assert rc == 0 and "2 fits" in out, err


@pytest.mark.parametrize("kind", STORES)
def test_a_calibration_marked_accepted_is_judged_again_on_its_own_data(tmp_path, monkeypatch, request, kind):
    """A writer (or a library caller) can record "accepted" for a fit compgen's gate refuses:
    the bundled session fitted without its hidden EXC:h2 (σ̂ 0.77 µm, plausible by its own
    numbers, so no check of the row alone can tell). check runs the gate again on the
    calibration's own data files (by their checksums) and refuses it; where those files are
    gone, it says the verdict stands as recorded."""
    monkeypatch.chdir(tmp_path)
    data = tmp_path / "session.csv"
    data.write_bytes((ROOT / "examples" / "seed-session.csv").read_bytes())
    assert run("fit", "--machine", SEED_MACHINE, data, "-o", "fit.json")[0] == 0
    machine = load_machine(SEED_MACHINE)
    db = _store(kind, request, tmp_path)
    with open_store(db) as store:
        # recorded "accepted": no gate's reason given
        H.record_fit(store, load_fit(tmp_path / "fit.json"), machine, taken="2026-01-05T09:00Z")
    truth = ROOT / "examples" / "truth-seed-session.json"
    assert run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--paths", "K4", "--seed", "3",
               "--noise-um", "0.5", "-o", "k4.csv")[0] == 0
    code, _, err = run("check", "--machine", SEED_MACHINE, "k4.csv", "--date", "2026-02-01", "--db", db)
    assert code == 2 and "fails compgen's fit gate on its own data" in err and "EXC:h2" in err, err
    data.rename(tmp_path / "elsewhere.csv")
    code, out, err = run("check", "--machine", SEED_MACHINE, "k4.csv", "--date", "2026-02-01", "--json",
                         "--db", db)
    assert code in (0, 1), err
    assert json.loads(out)["calibration_accepted"].startswith("accepted as recorded (its data are not here")


@pytest.mark.parametrize("store_id", [None, 7, "", "not a store"])
def test_an_export_that_names_no_store_is_refused_in_one_line(tmp_path, year, monkeypatch, store_id):
    """Found by the generated fuzz: an export whose store_id line was deleted was an internal
    error (KeyError) once every row had been checked."""
    monkeypatch.chdir(tmp_path)
    _record(tmp_path / "a.sqlite", year, months=1).close()
    assert run("history", "export", "--db", "a.sqlite", "-o", "a.json")[0] == 0
    doc = json.loads((tmp_path / "a.json").read_text())
    if store_id is None:
        del doc["store_id"]
    else:
        doc["store_id"] = store_id
    (tmp_path / "a.json").write_text(json.dumps(doc))
    code, _, err = run("history", "import", "a.json", "--db", "b.sqlite")
    assert code == 2 and "names no store it came from" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "b.sqlite").exists()


@pytest.mark.parametrize("kind", ["sqlite", "postgresql"])
def test_a_store_of_schema_5_has_its_older_dates_normalised_to_utc_once(tmp_path, year, monkeypatch, request,
                                                                        kind):
    """Rows an older compgen kept with the offset it was given ("2026-03-01T10:00:00+02:00")
    are rewritten once, by the migration the store records (version 6), as the UTC instant
    (08:00); the append-only rule holds again after it, and rows already in UTC are untouched."""
    import compgen.history.store as S
    url = str(tmp_path / "h.sqlite") if kind == "sqlite" else request.getfixturevalue("pg_db")
    machine, fit = year[0], year[2][0][1]
    with monkeypatch.context() as m:
        m.setattr(S, "MIGRATIONS", S.MIGRATIONS[:5])
        m.setattr(S, "VERSION", 5)
        with init(url)[0] as store:
            H.record_fit(store, fit, machine, taken="2026-03-01T09:00:00+00:00")
            session = store.rows("SELECT * FROM sessions")[0]
            with store.writing():
                store.insert("sessions", {k: v for k, v in session.items()
                                          if k not in ("id", "recorded_by", "import_id")}
                             | {"taken": "2026-03-01T10:00:00+02:00"})
            assert store.version() == 5
    with init(url)[0] as store:
        assert store.version() == 6
        assert sorted(r["taken"] for r in store.rows("SELECT taken FROM sessions")) == [
            "2026-03-01T08:00:00+00:00", "2026-03-01T09:00:00+00:00"]
        with pytest.raises(CompgenError, match="append-only"), store.writing():
            store.db.execute("UPDATE sessions SET taken = 'x'")
