"""What a LinuxCNC configuration is made of, as LinuxCNC reads it: the INI as ``inivar``
reads it (``Ini``), its ``#INCLUDE`` lines expanded one level as the start script does, the
names of LinuxCNC's own HAL library, and the place (file and line) each setting comes from.
``config`` evaluates a configuration from these."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ...errors import CompgenError

# Debian's HALLIB_DIR; the start script searches ".:$HALLIB_DIR" for a plain HALFILE name
HALLIB = Path("/usr/share/linuxcnc/hallib")
# LinuxCNC 2.9's HAL library (linuxcnc-uspace's hallib): known by name where LinuxCNC is not
# installed beside compgen. None of them sets a kinematics module's pins.
LIBRARY = frozenset(
    [
        "axis_manualtoolchange.hal",
        "basic_sim.tcl",
        "check_config.tcl",
        "check_xyz_constraints.hal",
        "core_servo.hal",
        "core_sim.hal",
        "core_sim9.hal",
        "core_stepper.hal",
        "gantrysim.hal",
        "hal_procs_lib.tcl",
        "halcheck.tcl",
        "hookup_moveoff.tcl",
        "lathe.hal",
        "locking_indexer.hal",
        "moveoff_external.hal",
        "plasmac.tcl",
        "qtplasmac_comp.hal",
        "servo_sim.hal",
        "sim_ldelta.hal",
        "sim_lib.tcl",
        "sim_rdelta.hal",
        "sim_spindle_encoder.hal",
        "simulated-gantry-home.hal",
        "simulated_home.hal",
        "simulated_limits.hal",
        "tripodsim.hal",
        "util_lib.tcl",
        "var_show.tcl",
        "wheeljogpins.tcl",
    ]
)
INI_LINE_MAX = 255  # iniparse reads a line in pieces of 255 characters
MARK = "# compgen: file "
BUNDLE_MARK = re.compile(
    r"^# compgen: file (.+) \((INI|#INCLUDE|HALFILE|POSTGUI_HALFILE|source|COMP_FILE"
    r"|library) ?(.*)\)$"
)
NAME_WORDS = re.compile(r"[0-9A-Za-z.\-_]+")  # halcmd's characters of a variable's name


@dataclass(frozen=True)
class Place:
    """A line of one of the configuration's files."""

    file: str
    line: int  # from 1

    def __str__(self) -> str:
        return f"{self.file}:{self.line}"


@dataclass(frozen=True)
class Setting:
    """A value as LinuxCNC reads it and the one place it is written: a HAL command's value
    word (``kind`` "hal"), or an INI key's value a HAL line takes (``kind`` "ini")."""

    text: str
    place: Place
    kind: str


@dataclass(frozen=True)
class IniEntry:
    """A key's value in the expanded INI and the place (file, line) it was read from."""

    value: str
    place: Place


class Ini:
    """The expanded INI as inivar reads it: ``lines`` are (place, text) in expanded order."""

    def __init__(self, lines: list[tuple[Place, str]]):
        self.lines = lines
        # a backslash at the end of a line joins the next (iniparse); placed at the first line
        joined: list[tuple[Place, str]] = []
        carry: tuple[Place, str] | None = None
        for place, text in lines:
            if carry is not None:
                place, text = carry[0], carry[1] + text
            if text.endswith("\\"):
                carry = (place, text[:-1])
                continue
            carry = None
            joined.append((place, text))
        self.joined = joined + ([carry] if carry else [])

    def section(self, name: str) -> list[tuple[Place, str]]:
        """The lines of the first section ``[name]``: inivar never looks at a second one."""
        head = f"[{name}]"
        out, inside = [], False
        for place, text in self.joined:
            word = text.lstrip(" \t\r")
            if not word or word[0] in "#;":
                continue
            if inside and word.startswith("["):
                break
            if inside:
                out.append((place, word))
            elif word.startswith(head):
                inside = True
        return out

    def header(self, name: str) -> Place | None:
        head = f"[{name}]"
        return next((p for p, t in self.joined if t.lstrip(" \t\r").startswith(head)), None)

    def all(self, section: str, key: str) -> list[IniEntry]:
        """Every value of ``key`` in order, as ``inivar -num 1, 2, ...`` reads them: the list
        ends at the first occurrence without a value, where LinuxCNC's loops end."""
        out = []
        for place, text in self.section(section):
            if not text.startswith(key) or text[len(key) : len(key) + 1] not in (" ", "\t", "\r", "="):
                continue
            if "=" not in text[len(key) :]:
                break
            value = text[len(key) :].split("=", 1)[1].strip(" \t\r\n")
            if not value:
                break
            out.append(IniEntry(value, place))
        return out

    def get(self, section: str, key: str) -> IniEntry | None:
        found = self.all(section, key)
        return found[0] if found else None


# --- reading the files --------------------------------------------------------------------


def _as_read_by_the_start_script(path: str, text: str, lines: list[str]) -> None:
    """An INI with ``#INCLUDE`` is copied line by line by the start script's
    ``while read a b`` (handle_includes) before inivar reads it: bash's read drops a last
    line without a line end and takes backslashes as escapes ("a\\b" is "ab"). compgen refuses
    both rather than read what LinuxCNC does not (a dropped line compgen edited would start
    to count, with the edit on top)."""
    if text and not text.endswith("\n") and lines[-1].strip():
        raise CompgenError(
            "the INI's last line has no line end: with #INCLUDE, LinuxCNC's start script "
            "(handle_includes, bash's read) drops it, so LinuxCNC runs without it",
            where=f"{path}:{len(lines)}",
            hint="end it with a line break if LinuxCNC is to read it (the machine then runs with it), "
                 "or delete it",
        )
    for k, line in enumerate(lines, start=1):
        if "\\" in (line[:-1] if line.endswith("\\") and not line.endswith("\\\\") else line):
            raise CompgenError(
                "a backslash in the INI: with #INCLUDE, LinuxCNC's start script copies the INI "
                "through bash's read, which takes it as an escape and drops it",
                where=f"{path}:{k}",
                hint="write the line without a backslash",
            )


def start_script_name(value: str) -> str:
    """The file a HALFILE value names, as the start script splits it (``IFS='\\ ' read
    CFGFILE CFGFILE_ARGS``): backslash escapes taken, then the first word up to a space; a
    tab is part of the name (the file is then not found, and LinuxCNC stops)."""
    name, escaped = [], False
    for ch in value.lstrip(" "):
        if escaped:                       # an escaped character is the character, never a space
            name.append(ch)
            escaped = False
        elif ch == "\\":
            escaped = True
        elif ch == " ":                   # the rest is the file's arguments
            break
        else:
            name.append(ch)
    return "".join(name)


Loader = Callable[[str, str, Place | None], tuple[str, str | None]]


def expand_includes(
    path: str, text: str, load: Loader
) -> tuple[list[tuple[Place, str]], list[tuple[str, str, Place, str]]]:
    """The INI's lines with each ``#INCLUDE`` replaced by its file's (handle_includes: only
    where some line starts with ``#INCLUDE``; one level: an included file's own
    ``#INCLUDE`` stays a comment), and each included file (path, text, place, name)."""
    lines = text.splitlines()
    out: list[tuple[Place, str]] = []
    included = []
    expands = any(line.startswith("#INCLUDE") for line in lines)
    if expands:
        _as_read_by_the_start_script(path, text, lines)
    for k, line in enumerate(lines, start=1):
        at = Place(path, k)
        if len(line) > INI_LINE_MAX:
            raise CompgenError(
                f"a line of {len(line)} characters: LinuxCNC reads {INI_LINE_MAX} of a line and "
                "the rest as a line of its own",
                where=str(at),
            )
        words = line.split(None, 1)
        if not (expands and words and words[0] == "#INCLUDE"):
            out.append((at, line))
            continue
        if len(words) < 2:
            raise CompgenError(
                "#INCLUDE without a file name (LinuxCNC says so and goes on without it)", where=str(at)
            )
        name = words[1].strip()
        inc_path, inc_text = load("#INCLUDE", name, at)
        inc_text = inc_text or ""
        if inc_text and not inc_text.endswith("\n"):
            # cat "$breal", then echo "#*** End   #INCLUDE file: ..." onto the same line
            raise CompgenError(
                "the included file's last line has no line end: the start script appends its "
                "'#*** End   #INCLUDE file' line to it, and LinuxCNC reads that line otherwise",
                where=f"{inc_path}:{len(inc_text.splitlines())}",
                hint="end the file with a line break",
            )
        included.append((inc_path, inc_text, at, name))
        for j, inc in enumerate(inc_text.splitlines(), start=1):
            if inc.split(None, 1)[:1] == ["#INCLUDE"]:
                raise CompgenError(
                    "an #INCLUDE inside an included file: LinuxCNC expands one level and "
                    "takes this line as a comment",
                    where=f"{inc_path}:{j}",
                    hint="include that file from the INI itself",
                )
            if len(inc) > INI_LINE_MAX:
                raise CompgenError(
                    f"a line of {len(inc)} characters: LinuxCNC reads {INI_LINE_MAX} of a line",
                    where=f"{inc_path}:{j}",
                )
            out.append((Place(inc_path, j), inc))
    return out, included
