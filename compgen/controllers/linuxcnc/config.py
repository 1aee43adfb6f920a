"""A LinuxCNC configuration as LinuxCNC starts it, not as it looks.

The start script (``/usr/bin/linuxcnc``, from ``scripts/linuxcnc.in``) expands the INI's
``#INCLUDE`` lines one level deep (``handle_includes``), then runs every ``[HAL] HALFILE``
in order (a ``LIB:`` name from LinuxCNC's HAL library, a plain name from the INI's folder
first, then the library; ``.tcl`` files through haltcl), then every ``[HAL] HALCMD`` line
as the words of one halcmd call; the GUI runs ``POSTGUI_HALFILE`` once it is up
(``axis``). Keys are read as ``inivar`` reads them (``src/libnml/inifile``): the first
``[SECTION]`` of a name only, the first occurrence of a key, the value after the first
``=`` with no comment taken off, a trailing backslash joining the next line. halcmd takes
``#`` outside quotes as the start of a comment, puts ``[SECTION]KEY`` and ``$ENV`` into a
line, and runs ``setp``, ``PIN = VALUE``, ``sets``, ``net``, ``linkps``/``linksp`` and
``source`` in order; a new signal takes the value of the first pin netted to it (hal_link).

``bundle`` reads every file the configuration names, refusing each one that is missing,
unreadable or not a regular file with the line that names it; the bundle is one text (the
control's state, as every controller's) and ``evaluate`` gives what LinuxCNC holds from it:
each pin's value and the one place that sets it, which an edit rewrites.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from ...errors import CompgenError
from ...files import read_text
from .files import (
    BUNDLE_MARK,
    HALLIB,
    INI_LINE_MAX,
    LIBRARY,
    MARK,
    NAME_WORDS,
    Ini,
    IniEntry,
    Loader,
    Place,
    Setting,
    expand_includes,
    start_script_name,
)


def _file_loader(ini_path: Path, files: dict[str, tuple[str, str, str]]) -> Loader:
    """Reads each named file as the start script finds it, into ``files`` (path → (kind,
    name as written, text)); a missing, unreadable or odd file is refused with the line
    that names it."""
    folder = ini_path.parent

    def load(kind: str, name: str, at: Place | None) -> tuple[str, str | None]:
        where = str(at) if at else str(ini_path)
        if kind == "#INCLUDE":
            if re.search(r"[`$;|&<>(){}\\]", name):
                raise CompgenError(
                    f"#INCLUDE {name}: the start script expands this name with the shell, which "
                    "compgen does not do",
                    where=where,
                    hint="name the file plainly",
                )
            target = Path(os.path.expanduser(name))
        elif kind == "HALFILE":
            if name.startswith("LIB:"):
                base = name[4:]
                if (
                    not base
                    or (HALLIB.is_dir() and not (HALLIB / base).is_file())
                    or (not HALLIB.is_dir() and base not in LIBRARY)
                ):
                    raise CompgenError(f"HALFILE {name}: no such file in LinuxCNC's HAL library", where=where)
                files[name] = ("library", name, "")
                return name, None
            target = Path(os.path.expanduser(name))
            if (
                not target.is_absolute()
                and not (folder / target).exists()
                and ((HALLIB / target).is_file() or (not HALLIB.is_dir() and name in LIBRARY))
            ):
                files[name] = ("library", name, "")  # found in HALLIB_PATH's second folder
                return name, None
        else:
            target = Path(name)
        full = target if target.is_absolute() else folder / target
        what = {"#INCLUDE": "included INI file", "COMP_FILE": "joint compensation file"}.get(kind, "HAL file")
        if not full.exists():
            raise CompgenError(
                f"{kind} {name}: no such file ({full}); LinuxCNC would stop, or go on without it",
                where=where,
                hint="correct the INI, or put the file there",
            )
        try:
            text = read_text(full, what, ansi_ok=True)[0]
        except CompgenError as exc:
            raise CompgenError(f"{kind} {name}: {exc.message}", where=where) from None
        if any(line.startswith(MARK) for line in text.splitlines()):
            raise CompgenError(
                f"{kind} {name} holds a line starting {MARK.strip()!r}, which compgen uses to join "
                "a configuration's files",
                where=str(full),
                hint="change that comment",
            )
        files[str(full)] = (kind, name, text)
        return str(full), text

    return load


def bundle(path: str, text: str) -> str:
    """Every file of the configuration whose INI is ``path`` (its ``text``), each after a
    line naming it and how the INI reaches it: the control's state, as one text."""
    ini_path = Path(path).absolute()
    files: dict[str, tuple[str, str, str]] = {}
    load = _file_loader(ini_path, files)
    if any(line.startswith(MARK) for line in text.splitlines()):
        raise CompgenError(
            f"the INI holds a line starting {MARK.strip()!r}, which compgen uses to join a "
            "configuration's files",
            where=path,
            hint="change that comment",
        )
    _evaluate(str(ini_path), text, load)
    body = [f"{MARK}{ini_path} (INI)", text.rstrip("\n")]
    for full, (kind, name, content) in files.items():
        body += [f"{MARK}{full} ({kind} {name})", *([content.rstrip("\n")] if content else [])]
    return "\n".join(body) + "\n"


def is_bundle(text: str | None) -> bool:
    return text is not None and BUNDLE_MARK.match(text.split("\n", 1)[0]) is not None


def unbundle(text: str) -> tuple[str, str, dict[tuple[str, str], tuple[str, str]]]:
    """The INI's path and text and the other files by (kind, name) → (path, text)."""
    parts: list[list] = []
    for line in text.split("\n"):
        m = BUNDLE_MARK.match(line)
        if m is not None:
            parts.append([m[1], m[2], m[3], []])
        elif parts:
            parts[-1][3].append(line)
    if not parts or parts[0][1] != "INI":
        raise CompgenError("not a LinuxCNC configuration compgen read")
    files = {(kind, name): (p, "\n".join(body).rstrip("\n") + "\n") for p, kind, name, body in parts[1:]}
    return parts[0][0], "\n".join(parts[0][3]).rstrip("\n") + "\n", files


def evaluate(state: str) -> Configuration:
    """What LinuxCNC holds when it starts the configuration ``state`` (``bundle``'s text)."""
    ini_path, ini_text, files = unbundle(state)

    def load(kind: str, name: str, at: Place | None) -> tuple[str, str | None]:
        if (kind, name) in files:
            p, t = files[(kind, name)]
            return p, t
        if ("library", name) in files:
            return name, None
        raise CompgenError(
            f"{kind} {name} is not among the configuration's files as read", where=str(at) if at else ini_path
        )

    return _evaluate(ini_path, ini_text, load)


def _no_files(kind: str, name: str, at: Place | None) -> tuple[str, str | None]:
    raise CompgenError(
        f"{kind} {name}: compgen reads the files a configuration names from its INI",
        where=str(at) if at else None,
        hint="give the configuration's INI as --current",
    )


def hal_file(text: str, where: str) -> Configuration:
    """One HAL file run alone, as ``halcmd -f`` runs it (no INI to take references from)."""
    cfg = Configuration(where, Ini([]), {where: text}, {})
    run = _Hal(cfg, _no_files)
    for k, raw in enumerate(text.splitlines(), start=1):
        run.line(raw, Place(where, k))
    return cfg


def then(cfg: Configuration, text: str, where: str) -> Configuration:
    """``cfg`` with the HAL file ``text`` run after everything it ran (a further HALFILE)."""
    more = Configuration(
        cfg.ini_path,
        cfg.ini,
        {**cfg.texts, where: text},
        dict(cfg.named_at),
        dict(cfg.pins),
        dict(cfg.net),
        dict(cfg.signals),
        list(cfg.library),
    )
    run = _Hal(more, _no_files)
    for k, raw in enumerate(text.splitlines(), start=1):
        run.line(raw, Place(where, k))
    return more


# --- HAL as halcmd runs it ----------------------------------------------------------------


@dataclass
class Configuration:
    """The INI (expanded), every file by path, the HAL the files leave, and where each
    file was named (place, the name as written)."""

    ini_path: str
    ini: Ini
    texts: dict[str, str]
    named_at: dict[str, list[tuple[Place, str]]]
    pins: dict[str, Setting] = field(default_factory=dict)  # a pin's own value (setp)
    net: dict[str, str] = field(default_factory=dict)  # pin → signal
    signals: dict[str, Setting | None] = field(default_factory=dict)
    library: list[str] = field(default_factory=list)  # HAL library files, not read
    # per joint: its COMP_FILE entry, the type ("0" by default, inijoint.cc) and the file's text
    joints: dict[int, tuple[IniEntry, str, str]] = field(default_factory=dict)

    def value(self, pin: str) -> Setting | None:
        """The pin's value as HAL holds it once everything ran, and its place."""
        if pin in self.net:
            return self.signals.get(self.net[pin])
        return self.pins.get(pin)

    @property
    def folder(self) -> Path:
        return Path(self.ini_path).parent


def _evaluate(ini_path: str, ini_text: str, load: Loader) -> Configuration:
    lines, included = expand_includes(ini_path, ini_text, load)
    cfg = Configuration(ini_path, Ini(lines), {ini_path: ini_text}, {})
    ini = cfg.ini
    for inc_path, inc_text, at, name in included:
        cfg.texts[inc_path] = inc_text
        cfg.named_at.setdefault(inc_path, []).append((at, name))
    if ini.get("HAL", "TWOPASS") is not None:
        raise CompgenError(
            "[HAL] TWOPASS: LinuxCNC runs the HAL files in two passes (twopass.tcl), which "
            "compgen does not evaluate",
            where=str(ini.get("HAL", "TWOPASS").place),
        )
    run = _Hal(cfg, load)
    for entry in ini.all("HAL", "HALFILE"):
        run.file("HALFILE", start_script_name(entry.value), entry.place)
    for entry in ini.all("HAL", "HALCMD"):
        run.halcmd(entry)
    for entry in ini.all("HAL", "POSTGUI_HALFILE"):
        run.file("POSTGUI_HALFILE", entry.value, entry.place)
    for joint in sorted({int(m[1]) for _, t in ini.joined if (m := re.match(r"\s*\[JOINT_(\d+)\]", t))}):
        if (comp := ini.get(f"JOINT_{joint}", "COMP_FILE")) is None:
            continue
        kind = ini.get(f"JOINT_{joint}", "COMP_FILE_TYPE")
        if kind is not None and kind.value not in ("0", "1"):
            raise CompgenError(f"[JOINT_{joint}] COMP_FILE_TYPE = {kind.value}: LinuxCNC takes 0 or 1",
                               where=str(kind.place))
        full, text = load("COMP_FILE", comp.value, comp.place)
        cfg.texts[full] = text or ""
        cfg.named_at.setdefault(full, []).append((comp.place, comp.value))
        cfg.joints[joint] = (comp, kind.value if kind else "0", text or "")
    return cfg


class _Hal:
    """Runs HAL commands in LinuxCNC's order over a ``Configuration``'s pins and signals."""

    def __init__(self, cfg: Configuration, load: Loader):
        self.cfg, self.load = cfg, load
        self.pending: dict[str, Place] = {}  # signals set before any net names them
        self.set_in: dict[tuple[str, str, str], Place] = {}  # (file, kind, name) set once a file
        self.running: list[str] = []  # the files being run, outermost first (source nests)

    def file(self, kind: str, name: str, at: Place) -> None:
        full, text = self.load(kind, name, at)
        if text is None:
            self.cfg.library.append(name)
            return
        if full in self.running:
            raise CompgenError(
                f"{kind} {name} runs a file that is still running ({' -> '.join(self.running + [full])}): "
                "halcmd would source it again without end",
                where=str(at),
                hint="source each file once",
            )
        self.cfg.texts[full] = text
        self.cfg.named_at.setdefault(full, []).append((at, name))
        if full.endswith(".tcl"):
            raise CompgenError(
                f"{kind} {name} is a Tcl HAL file, which compgen does not evaluate",
                where=str(at),
                hint="set the kinematics pins in a .hal file or in HALCMD lines",
            )
        self.running.append(full)
        for k, raw in enumerate(text.splitlines(), start=1):
            self.line(raw, Place(full, k))
        self.running.pop()

    def halcmd(self, entry: IniEntry) -> None:
        # the start script runs `halcmd $HALCOMMAND`: the words as halcmd's arguments, with no
        # comment taken off and nothing from the INI put in
        for bad, why in (("#", "a comment"), ("[", "an INI reference"), ("$", "a variable")):
            if bad in entry.value:
                raise CompgenError(
                    f"HALCMD {entry.value!r} holds {why}: halcmd takes a HALCMD line's words as "
                    "they are, so this line would stop LinuxCNC's start",
                    where=str(entry.place),
                )
        self.command(entry.value.split(), [None] * len(entry.value.split()), entry.place, "HALCMD")

    def line(self, raw: str, at: Place) -> None:
        body, quote = [], None
        for ch in raw:  # strip_comments: '#' outside quotes ends the line
            if quote is None and ch == "#":
                break
            if ch in "'\"":
                quote = None if quote == ch else (ch if quote is None else quote)
            body.append(ch)
        if quote is not None:
            raise CompgenError(
                "an unterminated quoted string: halcmd stops LinuxCNC's start here", where=str(at)
            )
        words = "".join(body).split()
        if not words:
            return
        values, origins = [], []
        for w in words:
            value, origin = self.substitute(w, at)
            values.append(value)
            origins.append(origin)
        self.command(values, origins, at, "file")

    def substitute(self, word: str, at: Place) -> tuple[str, IniEntry | None]:
        """halcmd's replace_vars on one word; a word that is one INI reference keeps its entry."""
        # LinuxCNC's environment, or a HAL file read without its INI: the word stays as it is, and
        # a pin's value that holds it is refused as no number
        if "$" in word or not self.cfg.ini.lines:
            return word, None
        m = re.fullmatch(r"\[([^\]]*)\]\(?(" + NAME_WORDS.pattern + r")\)?", word)
        out, origin = word, None
        for ref in re.finditer(r"\[([^\]]*)\]\(?(" + NAME_WORDS.pattern + r")\)?", word):
            entry = (
                self.cfg.ini.get(ref[1], ref[2])
                if ref[1]
                else next((e for s in self._sections() if (e := self.cfg.ini.get(s, ref[2]))), None)
            )
            if entry is None:
                raise CompgenError(
                    f"{ref[0]} is not in the INI: halcmd stops LinuxCNC's start here", where=str(at)
                )
            out = out.replace(ref[0], entry.value, 1)
            origin = entry if m is not None else None
        return out, origin

    def _sections(self) -> list[str]:
        return [m[1] for _, t in self.cfg.ini.joined if (m := re.match(r"\s*\[([^\]]+)\]", t))]

    def command(self, words: list[str], origins: list, at: Place, how: str) -> None:
        cmd = words[0]
        if len(words) == 3 and words[1] == "=":
            self.setp(words[0], words[2], origins[2], at, how)
        elif cmd == "setp" and len(words) == 3:
            self.setp(words[1], words[2], origins[2], at, how)
        elif cmd == "sets" and len(words) == 3:
            self.sets(words[1], words[2], origins[2], at, how)
        elif cmd in ("setp", "sets"):
            raise CompgenError(
                f"{cmd} takes a name and one value; halcmd stops LinuxCNC's start here", where=str(at)
            )
        elif cmd == "net" and len(words) >= 2:
            for pin in words[2:]:
                if pin not in ("=>", "<=", "<=>"):
                    self.link(pin, words[1], at)
        elif cmd == "linkps" and len(words) == 3:
            self.link(words[1], words[2], at)
        elif cmd == "linksp" and len(words) == 3:
            self.link(words[2], words[1], at)
        elif cmd == "source" and len(words) == 2:
            self.file("source", words[1], at)
        elif cmd in ("unlinkp", "delsig", "linkpp"):
            raise CompgenError(
                f"{cmd}: compgen does not evaluate it",
                where=str(at),
                hint="connect the kinematics pins with net, setp and sets",
            )

    def _once(self, kind: str, name: str, at: Place) -> None:
        key = (at.file, kind, name)
        if key in self.set_in:
            raise CompgenError(
                f"{name} is set twice in one file (lines {self.set_in[key].line} and {at.line})",
                where=str(at),
                hint="keep the one the configuration means",
            )
        self.set_in[key] = at

    def setp(self, pin: str, value: str, origin: IniEntry | None, at: Place, how: str) -> None:
        if pin in self.cfg.net:
            raise CompgenError(
                f"setp {pin}: the pin is netted to {self.cfg.net[pin]}; LinuxCNC refuses to start "
                "such a configuration",
                where=str(at),
            )
        if how == "file":
            self._once("setp", pin, at)
        self.cfg.pins[pin] = self._setting(value, origin, at)

    def sets(self, signal: str, value: str, origin: IniEntry | None, at: Place, how: str) -> None:
        if how == "file":
            self._once("sets", signal, at)
        if signal not in self.cfg.signals and not self.cfg.library:
            self.pending[signal] = at  # (a library file, not read, may have made it)
        self.cfg.signals[signal] = self._setting(value, origin, at)

    def link(self, pin: str, signal: str, at: Place) -> None:
        if pin in self.cfg.net and self.cfg.net[pin] != signal:
            raise CompgenError(
                f"net {signal}: {pin} is already on {self.cfg.net[pin]}; LinuxCNC refuses to "
                "start such a configuration",
                where=str(at),
            )
        if signal in self.pending:
            raise CompgenError(
                f"signal {signal} is set at {self.pending[signal]} before this line makes it: "
                "LinuxCNC stops its start there",
                where=str(at),
                hint="set the signal after the net that makes it",
            )
        if signal not in self.cfg.signals:  # a new signal takes its first pin's value
            self.cfg.signals[signal] = self.cfg.pins.get(pin)
        self.cfg.net[pin] = signal

    def _setting(self, value: str, origin: IniEntry | None, at: Place) -> Setting:
        if origin is not None:
            return Setting(value, origin.place, "ini")
        return Setting(value, at, "hal")



# --- the configuration to start with --------------------------------------------------------


def _replace_word(line: str, old: str, new: str, last: bool, at: Place) -> str:
    """``line`` with the word ``old`` (between white space, ``=`` or the line's ends, before
    any halcmd comment) replaced by ``new``: the last such word (a value) or the first (a
    file name after its key)."""
    end = (
        len(line) if line.lstrip().startswith(("#INCLUDE", "#", ";")) else (line.find("#") % (len(line) + 1))
    )
    found = list(re.finditer(r"(?<![^\s=])" + re.escape(old) + r"(?![^\s#])", line[:end]))
    if not found:
        raise CompgenError(f"{old!r} is not a word of this line as compgen read it", where=str(at))
    m = found[-1] if last else found[0]
    return line[: m.start()] + new + line[m.end() :]


def configuration_files(
    cfg: Configuration, values: dict[str, str], joints: dict[int, str], stem: str, header: list[str]
) -> dict[str, str]:
    """The configuration to start with, as files to write beside the INI (suffix after
    ``stem`` → text): each pin of ``values`` (pin → new value) changed where the
    configuration sets it, each joint of ``joints`` (joint → table file) given that
    COMP_FILE with type 1; a changed file other than the INI is written anew as
    ``stem.NAME`` and the line that names it follows it there."""
    lines: dict[str, list[str]] = {p: t.splitlines() for p, t in cfg.texts.items()}
    after: dict[Place, list[str]] = {}
    changed: dict[Place, tuple[str, str, bool]] = {}

    def change(place: Place, old: str, new: str, last: bool = True) -> None:
        if place in changed and changed[place][1] != new:
            raise CompgenError(
                f"one place sets two values that now differ ({changed[place][1]} and {new}): "
                "compgen cannot change one without the other",
                where=str(place),
                hint="set each kinematics pin on a line of its own",
            )
        changed[place] = (old, new, last)

    for pin, new in values.items():
        s = cfg.value(pin)
        assert s is not None
        if lines[s.place.file][s.place.line - 1].endswith("\\"):
            raise CompgenError(
                "the value is on a line that a backslash joins to the next: compgen does not "
                "rewrite such lines",
                where=str(s.place),
            )
        change(s.place, s.text, new)
    for joint, name in joints.items():
        section = f"JOINT_{joint}"
        head = cfg.ini.header(section)
        if head is None:
            raise CompgenError(
                f"the INI has no [{section}] section for the joint's table", where=cfg.ini_path
            )
        comp, kind = cfg.ini.get(section, "COMP_FILE"), cfg.ini.get(section, "COMP_FILE_TYPE")
        if comp is None:
            after.setdefault(head, []).extend([f"COMP_FILE = {name}", "COMP_FILE_TYPE = 1"])
            if kind is not None:
                change(kind.place, kind.value, "1")
            continue
        change(comp.place, comp.value, name)
        if kind is None:
            after.setdefault(comp.place, []).append("COMP_FILE_TYPE = 1")
        else:
            change(kind.place, kind.value, "1")

    renamed: dict[str, str] = {}
    order = list(cfg.texts)         # the order the start script reads the files: names follow it
    todo = {p.file for p in changed} | {p.file for p in after}
    while todo:
        file = min(todo, key=order.index)
        todo.discard(file)
        if file == cfg.ini_path or file in renamed:
            continue
        # distinct sources, distinct files: a/p.hal and b/p.hal are KIN.p.hal and KIN.2.p.hal
        base, n = Path(file).name, 1
        while (name := f"{stem}.{base}" if n == 1 else f"{stem}.{n}.{base}") in renamed.values():
            n += 1
        renamed[file] = name
        for place, written in cfg.named_at.get(file, []):
            change(place, written, renamed[file], last=False)
            todo.add(place.file)
    out = {}
    for file in {p.file for p in changed} | {p.file for p in after} | {cfg.ini_path}:
        text = list(lines[file])
        for place, (old, new, last) in changed.items():
            if place.file == file:
                text[place.line - 1] = _replace_word(text[place.line - 1], old, new, last, place)
        for place in sorted((p for p in after if p.file == file), key=lambda p: -p.line):
            text[place.line : place.line] = after[place]
        # '#' opens a comment in an INI and in HAL; a line past INI_LINE_MAX is read as two
        body = [f"# {h}"[:INI_LINE_MAX] for h in header] + text
        suffix = ".ini" if file == cfg.ini_path else renamed[file][len(stem):]
        out[suffix] = "\n".join(body) + "\n"
    return out
