"""The file edge: reading a user's files (regular files only, JSON without NaN or runaway
nesting) and writing outputs atomically, as one transaction, never over an input or a
user's file without ``force``."""

from __future__ import annotations

import json
import os
import re
import stat
import sys
import tempfile
from pathlib import Path

from .errors import CONTROL, CompgenError

MAX_BYTES = 64 * 2**20      # a state, a program, a machine file: more is not one of compgen's files
# R-test data sampled on the fly: two hours at 100 Hz is ~70 MB; this admits ~7 hours
MAX_DATA_BYTES = 256 * 2**20


# Every file the running command has read, and the history store it opened: an output never
# replaces one, --force or not (the CLI starts each command with none).
_READ: set[Path] = set()


def reading(path: str | Path) -> None:
    """Note ``path`` as an input of the running command."""
    _READ.add(Path(path).resolve())


def new_command() -> None:
    """A command starts: it has read nothing yet."""
    _READ.clear()


def _regular(path: Path, what: str, limit: int = MAX_BYTES) -> None:
    try:
        st = path.stat()
    except OSError as exc:
        raise CompgenError(f"cannot read {what}: {exc.strerror}", where=str(path)) from None
    if not stat.S_ISREG(st.st_mode):     # a FIFO would hang, a device would never end
        raise CompgenError(f"not a regular file, cannot be a {what}", where=str(path))
    if st.st_size > limit:
        raise CompgenError(f"{st.st_size / 2**20:.0f} MB is too large for a {what}", where=str(path))


def read_bytes(path: str | Path, what: str, limit: int = MAX_BYTES) -> bytes:
    """A user's text file's bytes, not yet decoded (a large data file is parsed from them),
    or one clear line."""
    path = Path(path)
    _regular(path, what, limit)
    reading(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise CompgenError(f"cannot read {what}: {exc.strerror}", where=str(path)) from None
    if b"\x00" in raw:
        raise CompgenError(f"binary file, not a text {what}", where=str(path))
    return raw


def decoded(raw: bytes, what: str, path: str | Path, ansi_ok: bool = False) -> str:
    """A text file's bytes as text, or one clear line. ``ansi_ok`` accepts Latin-1 where
    UTF-8 fails: controller exports are often ANSI."""
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        if not ansi_ok:
            raise CompgenError(f"{what} is not UTF-8 text (byte {exc.start})", where=str(path)) from None
        return raw.decode("latin-1")


def read_text(path: str | Path, what: str, ansi_ok: bool = False,
              limit: int = MAX_BYTES) -> tuple[str, bytes]:
    """A user's text file: its text and raw bytes (for checksums), or one clear line.

    ``ansi_ok`` accepts Latin-1 where UTF-8 fails: controller exports are often ANSI.
    """
    raw = read_bytes(path, what, limit)
    text = decoded(raw, what, path, ansi_ok)
    if ansi_ok:
        _no_odd_characters(text, what, path)
    return text, raw


# In a control's file (a state, a program, an edit: the files read with ``ansi_ok``) these
# are damage: Python's splitlines() would end a line at \v \f \x1c-\x1e \x85 \u2028 \u2029,
# where the control reads one line with a stray character in it; so are the other control
# characters, and a CR alone in a file whose lines end in LF. Tabs are kept.
ODD = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f\x85\u2028\u2029]")


def _no_odd_characters(text: str, what: str, path: Path) -> None:
    m = ODD.search(text) or (re.search(r"\r(?!\n)", text) if "\n" in text else None)
    if m:
        line = text.count("\n", 0, m.start()) + 1 if "\n" in text else text.count("\r", 0, m.start()) + 1
        raise CompgenError(f"{what} holds the control character {m[0]!r}: a control reads it as part of "
                           "the line, compgen would not", where=f"{path}:{line}",
                           hint="remove it, or export the file from the control again")


def _no_constant(name: str):
    raise ValueError(f"{name} is not a number compgen accepts")


def read_json(path: str | Path, what: str, limit: int = MAX_BYTES) -> dict:
    """A JSON object from a user's file: NaN and Infinity refused, nesting bounded."""
    return json_object(read_text(path, what, limit=limit)[0], what, path)


def json_object(text: str, what: str, path: str | Path) -> dict:
    """A JSON object from a file's text (``read_json``'s rules)."""
    try:
        doc = json.loads(text, parse_constant=_no_constant)
    except (json.JSONDecodeError, ValueError) as exc:
        raise CompgenError(f"not a JSON {what} ({exc})", where=str(path)) from None
    except RecursionError:
        raise CompgenError(f"JSON nested too deeply for a {what}", where=str(path)) from None
    if not isinstance(doc, dict):
        raise CompgenError(f"a {what} is a JSON object, not {type(doc).__name__}", where=str(path))
    return doc


STDOUT = "-"    # an output named so goes to standard output


def _target(path: Path, force: bool, inputs: tuple[Path, ...]) -> None:
    """Refuse an output path before anything is written."""
    if CONTROL.search(str(path)):
        raise CompgenError(f"output name {str(path)!r} holds a control character", hint="choose a plain name")
    for source in (*inputs, *_READ):
        if path.resolve() == source.resolve() or (path.exists() and source.exists()
                                                  and path.samefile(source)):
            raise CompgenError("output would overwrite an input of this command", where=str(path),
                               hint="write to a new file; keep the input as it is (it may be the only copy)")
    if path.is_symlink() or path.exists():
        if not path.is_file() or path.is_symlink():
            raise CompgenError("output path exists and is not a regular file", where=str(path))
        if not force:
            raise CompgenError("output file exists", where=str(path), hint="use --force to overwrite it")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise CompgenError("output folder does not exist", where=str(folder))
    if not os.access(folder, os.W_OK | os.X_OK):
        raise CompgenError("output folder is not writable", where=str(folder))


def write_atomically(path: str | Path, text: str | bytes, force: bool = False, newline: str = "\n",
                     inputs: tuple = ()) -> None:
    """Write ``text`` to ``path`` via a temporary file and ``os.replace``: nothing half-written."""
    write_all({path: text}, force, inputs, newline)


def write_all(files: dict[str | Path, str | bytes], force: bool = False, inputs: tuple = (),
              newline: str = "\n") -> None:
    """Write several files as one transaction: every target is checked, then every file is
    written to a temporary beside it, then all are renamed; a failure on the way removes the
    temporaries, so nothing of the set is left behind. Files get the umask's permissions."""
    if STDOUT in map(str, files):     # -o -: the one file goes to standard output
        if len(files) > 1:
            raise CompgenError(f"-o - writes one file to standard output; this command writes {len(files)}",
                               hint="give a file name")
        body = next(iter(files.values()))
        sys.stdout.buffer.write(body) if isinstance(body, bytes) else sys.stdout.write(body)
        sys.stdout.flush()
        return
    paths = {Path(p): text for p, text in files.items()}
    sources = tuple(Path(p) for p in inputs if p)
    for path in paths:
        _target(path, force, sources)
    umask = os.umask(0)
    os.umask(umask)
    temps: dict[Path, str] = {}
    saved: dict[Path, str] = {}      # a target that existed, moved aside until all are in place
    placed: list[Path] = []
    try:
        for path, text in paths.items():
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent if str(path.parent) else ".")
            temps[path] = tmp
            os.fchmod(fd, 0o666 & ~umask)
            with (os.fdopen(fd, "wb") if isinstance(text, bytes) else
                  os.fdopen(fd, "w", encoding="utf-8", newline=newline)) as f:
                f.write(text)
        for path, tmp in temps.items():
            if path.exists():
                saved[path] = f"{tmp}.old"
                os.replace(path, saved[path])
            os.replace(tmp, path)
            placed.append(path)
    except BaseException as exc:     # a full disk, or Ctrl-C between two renames: as before
        for path in placed:
            path.unlink(missing_ok=True)
        for path, old in saved.items():
            if Path(old).exists():
                os.rename(old, path)
        for tmp in temps.values():
            Path(tmp).unlink(missing_ok=True)
        if not isinstance(exc, OSError):
            raise
        raise CompgenError(f"cannot write: {exc.strerror}", where=str(exc.filename or path)) from None
    for old in saved.values():
        Path(old).unlink(missing_ok=True)
