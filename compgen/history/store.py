"""The calibration history's store: an SQLite file (the default: nothing to install) or a
PostgreSQL database (a plant), with one schema and one set of queries on both.

Append-only, and the database enforces it: every table has a trigger that refuses UPDATE,
DELETE (and, on PostgreSQL, TRUNCATE), and on PostgreSQL compgen's writers hold only SELECT
and INSERT (``grant``); a correction is a new row. Migrations are numbered; a store made by
a newer compgen, or one that is not compgen's, is refused. Only the store's owner migrates a
PostgreSQL store (``init``); an SQLite file is its user's and is migrated on first use.

A DSN's password is never shown: every message names the store by ``redact(url)``.
"""

from __future__ import annotations

import json
import os
import re
import sqlite3
import uuid
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

from .. import me
from ..errors import CompgenError
from ..files import reading

APP = "compgen.history"
DEFAULT_FILE = "compgen-history.sqlite"
ENV = "COMPGEN_DB"
PG_SCHEMA = "compgen"
TABLES = ("machines", "sessions", "fits", "edits", "checks", "imports")

AUTHORED = ("machines", "sessions", "checks", "imports")     # the tables given an author in schema 5
# Each migration: (version, DDL with {id} for the key column, {json} for JSON text). A new
# version appends; nothing earlier changes once released.
MIGRATIONS: tuple[tuple[int, tuple[str, ...]], ...] = (
    (1, (
        """CREATE TABLE machines (id {id}, name TEXT NOT NULL, serial TEXT NOT NULL,
               recorded TEXT NOT NULL, UNIQUE (name, serial))""",
        """CREATE TABLE sessions (id {id}, machine_id BIGINT NOT NULL REFERENCES machines(id),
               taken TEXT NOT NULL, device TEXT NOT NULL, operator TEXT NOT NULL,
               temperatures {json} NOT NULL, machine_sha256 TEXT NOT NULL, data {json} NOT NULL,
               recorded TEXT NOT NULL)""",
        """CREATE TABLE fits (id {id}, session_id BIGINT NOT NULL REFERENCES sessions(id),
               marker TEXT NOT NULL, kind TEXT NOT NULL CHECK (kind IN ('calibration', 'check')),
               model {json} NOT NULL, parameters {json} NOT NULL, sigma_um DOUBLE PRECISION NOT NULL,
               rms_um DOUBLE PRECISION NOT NULL, verdict TEXT NOT NULL, fit_json {json} NOT NULL,
               recorded TEXT NOT NULL)""",
        """CREATE TABLE edits (id {id}, machine_id BIGINT NOT NULL REFERENCES machines(id),
               fit_id BIGINT NOT NULL REFERENCES fits(id), controller TEXT NOT NULL,
               corrects {json} NOT NULL, written {json} NOT NULL, loaded {json} NOT NULL,
               taken TEXT NOT NULL, recorded TEXT NOT NULL)""",
        """CREATE TABLE checks (id {id}, machine_id BIGINT NOT NULL REFERENCES machines(id),
               fit_id BIGINT NOT NULL REFERENCES fits(id), against_fit_id BIGINT NOT NULL REFERENCES fits(id),
               passed INTEGER NOT NULL, summary {json} NOT NULL, recorded TEXT NOT NULL)""",
    )),
    # another store's history, imported explicitly: its rows carry where they came from
    (2, (
        """CREATE TABLE imports (id {id}, origin_store TEXT NOT NULL, file_sha256 TEXT NOT NULL,
               recorded TEXT NOT NULL)""",
        "ALTER TABLE sessions ADD COLUMN import_id BIGINT REFERENCES imports(id)",
    )),
    # the same fit or edit recorded twice (a retry, two writers at once) is one row, by the
    # database's word; rows recorded before stay without a key (append-only: never updated).
    # recorded_by: the database role that wrote a row (PostgreSQL sets it; nobody can choose it)
    (3, (
        "ALTER TABLE fits ADD COLUMN content_sha256 TEXT",
        "CREATE UNIQUE INDEX fits_content ON fits (content_sha256)",
        "ALTER TABLE edits ADD COLUMN content_sha256 TEXT",
        "CREATE UNIQUE INDEX edits_content ON edits (content_sha256)",
        "ALTER TABLE fits ADD COLUMN recorded_by TEXT",
        "ALTER TABLE edits ADD COLUMN recorded_by TEXT",
    )),
    # (PostgreSQL only, below) every row's id from the database's own sequence
    (4, ()),
    # every row's author, not only a fit's and an edit's (and, on PostgreSQL, below: every
    # row's time of recording is the database's clock, whatever a writer's INSERT says)
    (5, tuple(f"ALTER TABLE {t} ADD COLUMN recorded_by TEXT" for t in AUTHORED)),
    # (each database its own, below) the dates an older compgen kept with the offset it was
    # given, normalised once to UTC instants: every row's date then compares as text too
    (6, ()),
)
DATED = ("sessions", "edits")        # the tables whose ``taken`` is a measurement's instant
VERSION = MIGRATIONS[-1][0]
# an instant as compgen stores it (UTC; an older compgen kept the offset it was given)
INSTANT_PG = r"^[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9]{2}:[0-9]{2}:[0-9]{2}[+-][0-9]{2}:[0-9]{2}$"
# What SQLite adds to a migration: version 6 rewrites dates, so the append-only triggers step
# aside for it (inside the migration's transaction) and are made again as they were
def sqlite_refusal(table: str, op: str) -> str:
    """The SQLite trigger that refuses ``op`` (UPDATE, DELETE) on ``table``."""
    return (f"CREATE TRIGGER {table}_no_{op.lower()} BEFORE {op} ON {table} BEGIN "
            f"SELECT RAISE(ABORT, 'compgen history is append-only: {op} on {table} refused'); END")


SQLITE_MIGRATIONS: dict[int, tuple[str, ...]] = {
    6: tuple(s for t in DATED for s in (
        f"DROP TRIGGER IF EXISTS {t}_no_update",
        f"UPDATE {t} SET taken = strftime('%Y-%m-%dT%H:%M:%S+00:00', taken) WHERE taken NOT LIKE '%+00:00' "
        "AND strftime('%Y-%m-%dT%H:%M:%S+00:00', taken) IS NOT NULL",
        sqlite_refusal(t, "UPDATE"))),
}
# What PostgreSQL adds to a migration: the role that writes a row is the database's word
POSTGRES_MIGRATIONS: dict[int, tuple[str, ...]] = {
    3: (f"""CREATE OR REPLACE FUNCTION {PG_SCHEMA}.recorded_by() RETURNS trigger LANGUAGE plpgsql AS $$
            BEGIN NEW.recorded_by := session_user; RETURN NEW; END $$""",
        *(f"CREATE TRIGGER {t}_recorded_by BEFORE INSERT ON {t} FOR EACH ROW "
          f"EXECUTE FUNCTION {PG_SCHEMA}.recorded_by()" for t in ("fits", "edits")),
        # a writer granted INSERT on the schema's table by an earlier compgen loses it
        f"""DO $$ DECLARE r record; BEGIN
            FOR r IN SELECT DISTINCT grantee FROM information_schema.role_table_grants
                     WHERE table_schema = '{PG_SCHEMA}' AND table_name = 'compgen_schema'
                     AND privilege_type <> 'SELECT' AND grantee NOT IN (current_user, 'PUBLIC') LOOP
                EXECUTE format('REVOKE INSERT ON {PG_SCHEMA}.compgen_schema FROM %I', r.grantee);
            END LOOP; END $$"""),
    # a writer may INSERT ... OVERRIDING SYSTEM VALUE an id the sequence will give later: every
    # insert after it would then fail on the key, for every writer. The id is the sequence's,
    # whatever an INSERT says (SQLite takes the largest id + 1 and is not blocked so)
    # (the identity's own default has just taken currval; an id given in the INSERT is another)
    4: (f"""CREATE OR REPLACE FUNCTION {PG_SCHEMA}.sequence_id() RETURNS trigger LANGUAGE plpgsql AS $$
            DECLARE seq text := pg_get_serial_sequence(TG_TABLE_SCHEMA || '.' || TG_TABLE_NAME, 'id');
            BEGIN
              BEGIN
                IF NEW.id IS DISTINCT FROM currval(seq) THEN NEW.id := nextval(seq); END IF;
              EXCEPTION WHEN object_not_in_prerequisite_state THEN NEW.id := nextval(seq);
              END;
              RETURN NEW;
            END $$""",
        *(f"CREATE TRIGGER {t}_sequence_id BEFORE INSERT ON {t} FOR EACH ROW "
          f"EXECUTE FUNCTION {PG_SCHEMA}.sequence_id()" for t in TABLES),
        # a row every reader can read: one a writer appends with a date that is none, a JSON
        # column that is no JSON or a σ that is no number broke fleet and export for everyone.
        # NOT VALID: rows already there are read as they are (and named where unreadable)
        *(f"ALTER TABLE {t} ADD CONSTRAINT {t}_{c}_readable CHECK ({rule}) NOT VALID" for t, c, rule in (
            ("sessions", "taken", f"taken ~ '{INSTANT_PG}'"), ("edits", "taken", f"taken ~ '{INSTANT_PG}'"),
            ("sessions", "json", "temperatures::jsonb IS NOT NULL AND data::jsonb IS NOT NULL"),
            ("fits", "json", "model::jsonb IS NOT NULL AND parameters::jsonb IS NOT NULL "
                             "AND fit_json::jsonb IS NOT NULL"),
            ("fits", "numbers", "sigma_um >= 0 AND sigma_um < 'Infinity'::float8 AND rms_um >= 0 "
                                "AND rms_um < 'Infinity'::float8"),
            ("edits", "json", "corrects::jsonb IS NOT NULL AND written::jsonb IS NOT NULL "
                              "AND loaded::jsonb IS NOT NULL")))),
    # who and when, by the database: a writer's clock or a forged "recorded" says neither
    5: (*(f"CREATE TRIGGER {t}_recorded_by BEFORE INSERT ON {t} FOR EACH ROW "
          f"EXECUTE FUNCTION {PG_SCHEMA}.recorded_by()" for t in AUTHORED),
        f"""CREATE OR REPLACE FUNCTION {PG_SCHEMA}.recorded_at() RETURNS trigger LANGUAGE plpgsql AS $$
            BEGIN NEW.recorded := to_char(clock_timestamp() AT TIME ZONE 'UTC',
                                          'YYYY-MM-DD"T"HH24:MI:SS"+00:00"'); RETURN NEW; END $$""",
        *(f"CREATE TRIGGER {t}_recorded_at BEFORE INSERT ON {t} FOR EACH ROW "
          f"EXECUTE FUNCTION {PG_SCHEMA}.recorded_at()" for t in TABLES)),
    # older rows' dates to UTC, by the owner, the append-only trigger off for this one update
    6: tuple(s for t in DATED for s in (
        f"ALTER TABLE {t} DISABLE TRIGGER {t}_append_only",
        f"""UPDATE {t} SET taken = to_char(taken::timestamptz AT TIME ZONE 'UTC',
                                        'YYYY-MM-DD"T"HH24:MI:SS"+00:00"')
            WHERE taken ~ '{INSTANT_PG}' AND taken NOT LIKE '%+00:00'""",
        f"ALTER TABLE {t} ENABLE TRIGGER {t}_append_only")),
}


# a URL's scheme and the slashes after it, however many a user typed (postgresql:/, or a
# driver's postgresql+psycopg://): what follows may hold a user's password
SCHEME = re.compile(r"(?i)[a-z][a-z0-9+.-]*:/*")


def redact(url: str) -> str:
    """The store as it may be shown: a DSN's password replaced by ***. In a URL the user
    information runs to the last "@" before the path (a password may hold "@"); in a
    keyword DSN the password is a word or a quoted string with backslash escapes."""
    scheme = SCHEME.match(url)
    if scheme:
        rest = url[scheme.end():]
        host_end = rest.find("/") if "/" in rest else len(rest)
        at = rest.rfind("@", 0, host_end)
        if at >= 0 and ":" in rest[:at]:
            user = rest[:rest.index(":")]
            url = url[:scheme.end()] + f"{user}:***" + rest[at:]
    return re.sub(r"(password\s*=\s*)('(?:[^'\\]|\\.)*'|\S+)", r"\1***", url, flags=re.I)


def now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def store_url(given: str | None) -> str:
    """``--db``, else $COMPGEN_DB, else the SQLite file beside the job (the current folder).
    An empty --db is refused: it would be taken for "not given" and record into the default
    (an empty $COMPGEN_DB is the shell's unset)."""
    if given is not None and not str(given).strip():
        raise CompgenError("--db is empty", hint=f"name the store, or leave --db out for {DEFAULT_FILE} in "
                                                 "this folder")
    return str(given or os.environ.get(ENV) or DEFAULT_FILE)


def _sqlite_path(url: str, create: bool) -> Path:
    """The SQLite file a --db names, refused where no file store can be kept: SQLite's own
    in-memory and URI names (a history kept nowhere), a link to nowhere, a FIFO or device,
    a folder that is not there or not writable."""
    name = url.removeprefix("sqlite:///") if url.startswith("sqlite:///") else url
    if name == ":memory:" or name.startswith("file:"):
        raise CompgenError(f"--db {name!r} is SQLite's name for a store kept nowhere (in memory, or a URI)",
                           hint="give a file name: the history is to outlive the command")
    path = Path(name)
    if path.is_symlink() and not path.exists():
        raise CompgenError("the history store is a link to a file that is not there", where=str(path),
                           hint="give the file itself, or make the link point at one")
    if path.exists() and not path.is_dir() and not path.is_file():
        raise CompgenError("the history store is not a regular file (a FIFO or a device)", where=str(path),
                           hint="give a file")
    if not path.exists() and create:
        folder = path.absolute().parent
        if not folder.is_dir():
            raise CompgenError("the history store's folder does not exist", where=str(path),
                               hint=f"make {folder} first, or give another --db")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise CompgenError("the history store's folder is not writable: no store can be made there",
                               where=str(path), hint="give a folder you can write, or another --db")
    return path


def _is_postgres(url: str) -> bool:
    """A postgresql:// URL or a libpq keyword DSN (any ``keyword=value``, as libpq parses
    it); a file name otherwise, given plainly or as sqlite:///PATH. A name with "=" that
    libpq does not read is refused rather than taken for a file (it may hold a password)."""
    if url.lower().startswith(("postgresql://", "postgres://")):
        return True
    if url.startswith("sqlite:///"):
        return False
    scheme = SCHEME.match(url)
    if scheme and (scheme[0].endswith("/") or scheme[0][:-1].lower().startswith(("postgres", "sqlite"))):
        # a URL compgen does not read, never a file name: shown without what may be a password
        raise CompgenError(f"--db {redact(url)!r} is a URL compgen does not read",
                           hint="give postgresql://user@host/db (or postgres://), a libpq keyword DSN "
                                "(host=… dbname=…), a file, or sqlite:///PATH")
    if "=" not in url:
        return False
    try:
        from psycopg import conninfo
    except ImportError:        # no PostgreSQL client here: a keyword DSN is still one
        return bool(re.match(r"^\s*[A-Za-z_]+\s*=", url))
    try:
        conninfo.conninfo_to_dict(url)
    except Exception:          # psycopg.ProgrammingError: libpq's own words, which may echo a password
        raise CompgenError("--db is neither a connection string libpq reads nor a plain file name (it is not "
                           "shown: it may hold a password)",
                           hint="give postgresql://user@host/db, host=… dbname=…, or "
                                "sqlite:///PATH for a file whose name holds '='") from None
    return True


class Store:
    """One connection to a history store. Reads are plain; every write is one transaction
    (``with store.writing():``), so a writer killed half-way leaves nothing of its own."""

    def __init__(self, url: str, connection, postgres: bool):
        self.url, self.where, self.db, self.postgres = url, redact(url), connection, postgres

    # -- the dialects' one difference in queries: the placeholder
    def _sql(self, sql: str) -> str:
        return sql.replace("?", "%s") if self.postgres else sql

    def rows(self, sql: str, params: tuple = ()) -> list[dict]:
        with self._errors():
            cur = self.db.execute(self._sql(sql), params)
            names = [d[0] for d in cur.description]
            return [dict(zip(names, r, strict=True)) for r in cur.fetchall()]

    def insert(self, table: str, row: Mapping, unique: str | None = None) -> int | None:
        """One row, JSON columns given as Python values; returns its id. With ``unique`` (a
        column with a unique key), None when a row with that value is there already: the
        database decides, so two writers at once still make one row."""
        values = [json.dumps(v, sort_keys=True, allow_nan=False) if isinstance(v, dict | list) else v
                  for v in row.values()]
        sql = (f"INSERT INTO {table} ({', '.join(row)}) VALUES ({', '.join('?' * len(row))}) "
               + (f"ON CONFLICT ({unique}) DO NOTHING " if unique else "") + "RETURNING id")
        with self._errors():
            got = self.db.execute(self._sql(sql), values).fetchone()
        return None if got is None else int(got[0])

    @contextmanager
    def writing(self) -> Iterator[Store]:
        with self._errors():
            if self.postgres:
                with self.db.transaction():
                    yield self
            else:
                self.db.execute("BEGIN IMMEDIATE")     # one writer at a time; others wait (timeout)
                try:
                    yield self
                except BaseException:
                    self.db.execute("ROLLBACK")
                    raise
                self.db.execute("COMMIT")

    @contextmanager
    def _errors(self):
        """A database's refusal as one line naming the store (never its password)."""
        try:
            yield
        except sqlite3.Error as exc:
            raise CompgenError(f"the history store refused: {exc}", where=self.where) from None
        except Exception as exc:
            if self.postgres and _is_psycopg_error(exc):
                text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
                raise CompgenError(f"the history store refused: {_scrub(text, self.url)}",
                                   where=self.where) from None
            raise

    def close(self) -> None:
        self.db.close()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- schema
    def version(self) -> int | None:
        """The schema version, None for an empty database; refuses a foreign one."""
        if self.postgres:
            have = self.rows("SELECT table_name FROM information_schema.tables WHERE table_schema = ?",
                             (PG_SCHEMA,))
        else:
            have = self.rows("SELECT name AS table_name FROM sqlite_master WHERE type = 'table' "
                             "AND name NOT LIKE 'sqlite_%'")
        names = {r["table_name"] for r in have}
        if not names:
            return None
        if "compgen_schema" not in names:
            raise CompgenError("this database holds tables that are not a compgen history "
                               f"({', '.join(sorted(names)[:4])})", where=self.where,
                               hint="give another --db; compgen does not write into a foreign database")
        rows = self.rows("SELECT app, MAX(version) AS version FROM compgen_schema GROUP BY app")
        if [r["app"] for r in rows] != [APP]:
            raise CompgenError("this database's compgen_schema is not a compgen history's", where=self.where,
                               hint="give another --db")
        return int(rows[0]["version"])

    def store_id(self) -> str:
        return self.rows("SELECT store_id FROM compgen_schema ORDER BY version LIMIT 1")[0]["store_id"]

    def migrate(self) -> list[int]:
        """Bring the schema to ``VERSION``; the versions applied."""
        have = self.version()
        _refuse_newer(have, self.where)
        todo = [(v, ddl) for v, ddl in MIGRATIONS if have is None or v > have]
        if not todo:
            return []
        ident = ("BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY" if self.postgres
                 else "INTEGER PRIMARY KEY")
        kind = "TEXT"      # JSON as text on both: the same rows come back from either
        store_id = self.store_id() if have else uuid.uuid4().hex
        with self.writing():
            if have is None:
                if self.postgres:
                    self.db.execute(f"CREATE SCHEMA IF NOT EXISTS {PG_SCHEMA}")
                self.db.execute("CREATE TABLE compgen_schema (app TEXT NOT NULL, version INTEGER NOT NULL, "
                                "store_id TEXT NOT NULL, applied TEXT NOT NULL, PRIMARY KEY (app, version))")
                self._append_only(["compgen_schema"])
            for v, ddl in todo:
                for statement in ddl:
                    self.db.execute(statement.format(id=ident, json=kind))
                self._append_only([t for t in TABLES if f"CREATE TABLE {t} " in "".join(ddl)])
                for statement in (POSTGRES_MIGRATIONS if self.postgres else SQLITE_MIGRATIONS).get(v, ()):
                    self.db.execute(statement)
                self.db.execute(self._sql("INSERT INTO compgen_schema VALUES (?, ?, ?, ?)"),
                                (APP, v, store_id, now()))
        return [v for v, _ in todo]

    def _append_only(self, tables: list[str]) -> None:
        if self.postgres:
            self.db.execute(f"""CREATE OR REPLACE FUNCTION {PG_SCHEMA}.append_only() RETURNS trigger
                LANGUAGE plpgsql AS $$ BEGIN
                RAISE EXCEPTION 'compgen history is append-only: % on % refused', TG_OP, TG_TABLE_NAME;
                END $$""")
        for t in tables:
            if self.postgres:
                self.db.execute(f"CREATE TRIGGER {t}_append_only BEFORE UPDATE OR DELETE ON {t} "
                                f"FOR EACH ROW EXECUTE FUNCTION {PG_SCHEMA}.append_only()")
                self.db.execute(f"CREATE TRIGGER {t}_no_truncate BEFORE TRUNCATE ON {t} "
                                f"FOR EACH STATEMENT EXECUTE FUNCTION {PG_SCHEMA}.append_only()")
            else:
                for op in ("UPDATE", "DELETE"):
                    self.db.execute(sqlite_refusal(t, op))

    def grant(self, role: str) -> None:
        """PostgreSQL: let ``role`` read and append, nothing more (run by the owner)."""
        _grantable(role, self.postgres, self.where)
        with self.writing():
            self.db.execute(f"GRANT USAGE ON SCHEMA {PG_SCHEMA} TO {role}")
            self.db.execute(f"REVOKE ALL ON ALL TABLES IN SCHEMA {PG_SCHEMA} FROM {role}")
            self.db.execute(f"GRANT SELECT, INSERT ON ALL TABLES IN SCHEMA {PG_SCHEMA} TO {role}")
            # the schema's own table is the owner's: a row a writer added there would make
            # every later open refuse the store (or take it for another version)
            self.db.execute(f"REVOKE INSERT ON {PG_SCHEMA}.compgen_schema FROM {role}")
            self.db.execute(f"GRANT USAGE ON ALL SEQUENCES IN SCHEMA {PG_SCHEMA} TO {role}")


def _grantable(role: str, postgres: bool, where: str) -> None:
    if not postgres:
        raise CompgenError("roles are PostgreSQL's: an SQLite store is a file, guarded by its "
                           "permissions", where=where, hint="leave --grant out")
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,62}", role):
        raise CompgenError(f"{role!r} is not a plain role name", hint="letters, digits and _")


def _refuse_newer(version: int | None, where: str) -> None:
    if version is not None and version > VERSION:
        raise CompgenError(f"this history store has schema {version}, newer than this compgen's "
                           f"({VERSION})", where=where, hint="use the compgen that wrote it, or a newer one")


def _is_psycopg_error(exc: Exception) -> bool:
    return any(c.__module__.startswith("psycopg") and c.__name__ == "Error" for c in type(exc).__mro__)


def _scrub(text: str, url: str) -> str:
    """A driver's message with any password from ``url`` taken out: the one libpq reads,
    and, in a URL, the user information to its last "@" (a password holding "@" is read by
    libpq as part of the host, which its messages then name)."""
    secrets = set()
    try:
        from psycopg import conninfo
        secrets.add(conninfo.conninfo_to_dict(url).get("password") or "")
    except Exception:          # no psycopg, or a DSN libpq does not read: the patterns below
        pass
    scheme = SCHEME.match(url)
    if scheme:
        rest = url[scheme.end():]
        info = rest[:rest.rfind("@", 0, rest.find("/") if "/" in rest else len(rest))]
        if ":" in info:
            secrets |= {info.split(":", 1)[1], *info.split(":", 1)[1].split("@")}
    secrets |= {m[1] for m in re.finditer(r"password\s*=\s*'?([^'\s]+)", url, re.I)}
    for secret in sorted((x for x in secrets if len(x) >= 3), key=len, reverse=True):
        text = text.replace(secret, "***")
    return text


def open_store(given: str | None = None, create: bool = True) -> Store:
    """The store ``--db`` names (or $COMPGEN_DB, or the SQLite file here), at this compgen's
    schema. An SQLite file is created and migrated when ``create``; a PostgreSQL store must
    have been made by its owner (``history init``)."""
    url = store_url(given)
    if _is_postgres(url):
        store = _postgres(url)
        try:
            version = store.version()
            _refuse_newer(version, store.where)
            if version != VERSION:
                what = "no compgen history" if version is None else f"schema {version}, older than {VERSION}"
                raise CompgenError(f"this PostgreSQL database holds {what}", where=store.where,
                                   hint=f"its owner runs: {me()} history init --db URL")
        except BaseException:
            store.close()
            raise
        return store
    path = _sqlite_path(url, create)
    if path.is_dir():
        raise CompgenError("the history store is a folder", where=str(path),
                           hint=f"give a file, e.g. --db {path / DEFAULT_FILE}")
    if not path.exists() and not create:
        raise CompgenError("no history store here", where=str(path),
                           hint=f"record a fit first: {me()} history add FIT.json")
    if path.exists() and path.stat().st_size:
        with path.open("rb") as f:
            if f.read(16) != b"SQLite format 3\x00":
                raise CompgenError("this file is not an SQLite history store", where=str(path),
                                   hint="give another --db")
    reading(path)             # no command writes a file over the store it opened
    try:
        db = sqlite3.connect(path, timeout=60.0, isolation_level=None)
    except sqlite3.Error as exc:          # a folder or file the system refuses: one line
        raise CompgenError(f"cannot open the history store: {exc}", where=str(path)) from None
    try:
        db.execute("PRAGMA foreign_keys = ON")
    except sqlite3.Error as exc:
        db.close()
        raise CompgenError(f"cannot open the history store: {exc}", where=str(path)) from None
    store = Store(str(path), db, postgres=False)
    try:
        store.migrate()
    except BaseException:
        store.close()
        raise
    return store


def _postgres(url: str) -> Store:
    try:
        import psycopg
    except ImportError:
        raise CompgenError("a PostgreSQL store needs the psycopg package",
                           hint="pip install 'psycopg[binary]'") from None
    try:
        db = psycopg.connect(url, connect_timeout=20, autocommit=True)
    except psycopg.Error as exc:
        text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise CompgenError(f"cannot reach the history store: {_scrub(text, url)}", where=redact(url),
                           hint="check the host, port, user and database; the server must be "
                                "running") from None
    db.execute(f"SET search_path TO {PG_SCHEMA}")
    return Store(url, db, postgres=True)


def init(given: str | None, grant: tuple[str, ...] = ()) -> tuple[Store, list[int]]:
    """Create or migrate a store (PostgreSQL: as its owner), and grant writers."""
    url = store_url(given)
    postgres = _is_postgres(url)
    for role in grant:          # before a store is opened, or made
        _grantable(role, postgres, redact(url))
    store = _postgres(url) if postgres else open_store(url)
    try:
        applied = store.migrate() if store.postgres else []
        for role in grant:
            store.grant(role)
    except BaseException:
        store.close()
        raise
    return store, applied
