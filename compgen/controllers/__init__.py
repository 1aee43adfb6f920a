"""The controls compgen writes for, and their files: measurement and probing programs,
kinematics edits, compensation tables. What a fit asks of any control (``correction``), one
module per control behind ``registry``, the programs, the edit, and the advice (measurements
the machine can make, their programs written and checked).

Templates (``templates/<family>/``) hold layout only; this package prepares every number,
formats it once (``fmt_*``) and checks it before anything is written. Syntax no source has
confirmed lives in one place, ``templates/unconfirmed.j2``, and each emitted file lists the
unconfirmed items it uses.
"""

from __future__ import annotations

import functools
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import CONTROL, CompgenError

if TYPE_CHECKING:
    from jinja2 import Environment


@dataclass(frozen=True)
class Emitted:
    """What one command writes: file name suffix → text, and what the user must know."""

    files: dict[str, str]
    notes: tuple[str, ...] = field(default_factory=tuple)
    named: frozenset[str] = frozenset()    # suffixes of files a program names by its program name

    def paths(self, out: Path, name: str, main: str) -> dict[Path, str]:
        """Where each file goes, ``out`` holding the ``main`` one: a file a program names
        (``TNC:\\NAME_MSG.A``) beside it under the program's name, the others under
        ``out``'s stem."""
        def path(suffix: str) -> Path:
            stem = name if suffix in self.named else out.stem
            return out if suffix == main else out.with_name(stem + suffix)
        return {path(suffix): body for suffix, body in self.files.items()}


def ascii_text(text: str) -> str:
    """Free text (a machine's name, a file name) made safe for a comment of any control:
    plain ASCII (µm → um, ″ → arcsec, accents dropped), one line (control characters become
    spaces), and no comment terminator (LinuxCNC's parentheses become brackets)."""
    for sign, word in (("µ", "u"), ("″", " arcsec"), ("σ", "sigma"), ("°", " deg"), ("→", "->")):
        text = text.replace(sign, word)
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    return CONTROL.sub(" ", text).replace("(", "[").replace(")", "]")


def _one_line(value) -> None:
    """Every string a template is given, however deep: a line break or control character in
    it would start a block of its own on the control, so it is refused (free text goes
    through ``ascii_text``, identifiers are checked where they are read). Walked with a list,
    not by recursion: a program's steps are thousands of small dicts."""
    todo = [value]
    while todo:
        v = todo.pop()
        if isinstance(v, str):
            if CONTROL.search(v):
                raise CompgenError(f"refusing to write {v[:40]!r}: a line break or control "
                                   "character in a value would become a block of its own")
        elif isinstance(v, dict):
            todo += v.keys()
            todo += v.values()
        elif isinstance(v, list | tuple):
            todo += v


def fmt_signed(value: float, decimals: int = 4) -> str:
    """HEIDENHAIN style: an explicit sign, fixed decimals, no negative zero (+0.0000)."""
    text = f"{value:+.{decimals}f}"
    return "+" + text[1:] if float(text) == 0 else text


def fmt_plain(value: float, decimals: int = 4) -> str:
    """SINUMERIK style: a minus sign only, fixed decimals, no negative zero."""
    text = f"{value:.{decimals}f}"
    return text.lstrip("-") if float(text) == 0 else text


def template_dir() -> Path:
    """``compgen/templates`` in an installed wheel (pyproject's force-include), else the
    top-level ``templates/`` of a source checkout."""
    package = Path(__file__).resolve().parents[1]
    for folder in (package / "templates", package.parent / "templates"):
        if (folder / "unconfirmed.j2").is_file():
            return folder
    raise CompgenError("compgen's templates are missing", hint="reinstall compgen (pip install .)")


@functools.cache     # compiled templates are kept: diagnose checks every advised program
def environment() -> Environment:
    from jinja2 import Environment, FileSystemLoader, StrictUndefined  # only commands that emit

    env = Environment(loader=FileSystemLoader(template_dir()), undefined=StrictUndefined,
                      trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True,
                      autoescape=False)
    env.filters.update(signed=fmt_signed, plain=fmt_plain, ascii=ascii_text)
    return env


def render(template: str, **context) -> str:
    _one_line(context)
    text = environment().get_template(template).render(**context)
    try:
        text.encode("ascii")
    except UnicodeEncodeError as exc:   # a template or a name let a non-ASCII character in
        raise CompgenError(f"internal: {template} produced non-ASCII text at {exc.start}") from None
    return text
