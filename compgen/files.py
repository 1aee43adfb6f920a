"""Writing outputs: atomically, and never over a user's file without ``force``."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from .errors import CompgenError


def read_text(path: str | Path, what: str, ansi_ok: bool = False) -> tuple[str, bytes]:
    """A user's text file: its text and raw bytes (for checksums), or one clear line.

    ``ansi_ok`` accepts Latin-1 where UTF-8 fails: controller exports are often ANSI.
    """
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise CompgenError(f"cannot read {what}: {exc.strerror}", where=str(path)) from None
    if b"\x00" in raw:
        raise CompgenError(f"binary file, not a text {what}", where=str(path))
    try:
        return raw.decode("utf-8-sig"), raw
    except UnicodeDecodeError as exc:
        if ansi_ok:
            return raw.decode("latin-1"), raw
        raise CompgenError(f"{what} is not UTF-8 text (byte {exc.start})", where=str(path)) from None


def write_atomically(path: str | Path, text: str, force: bool = False, newline: str = "\n") -> None:
    """Write ``text`` to ``path`` via a temporary file and ``os.replace``: nothing half-written."""
    path = Path(path)
    if path.exists() and not force:
        raise CompgenError("output file exists", where=str(path), hint="use --force to overwrite it")
    if path.is_dir():
        raise CompgenError("output path is a directory", where=str(path))
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise CompgenError("output folder does not exist", where=str(folder))
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline=newline) as f:
            f.write(text)
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise CompgenError(f"cannot write: {exc.strerror}", where=str(path)) from None


def write_all(files: dict[str | Path, str], force: bool = False) -> None:
    """Write several files as one: every target is checked before any is written, and each
    goes through a temporary file, so a refusal leaves nothing behind."""
    for path in files:
        path = Path(path)
        if path.exists() and not force:
            raise CompgenError("output file exists", where=str(path), hint="use --force to overwrite it")
    for path, text in files.items():
        write_atomically(path, text, force=True)
