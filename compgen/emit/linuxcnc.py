"""LinuxCNC with the trt kinematics (``xyzac-trt-kins``, ``xyzbc-trt-kins``): G-code
programs and HAL edits of the kinematics pins, and their reader.

The pins (``src/emc/kinematics/trtfuncs.c``): C turns about the line through the rot
point, the tilting axis about the line through the rot point plus the offsets. They hold
axis-line positions only: angular location errors cannot be expressed.

An axis's error along itself (a linear positioning error, a rotary axis's angle error) goes
to the joint's compensation table, ``[JOINT_n] COMP_FILE`` with ``COMP_FILE_TYPE = 1``:
lines "nominal trim-up trim-down" in machine units, ascending, at most 256
(``EMCMOT_COMP_SIZE``, ``src/emc/motion/motion.h``); the trim, interpolated, is added to the
joint's command (``src/emc/motion/control.c``); beyond the last line the end trim holds. The
loader reads triplets up to the first line that is not one (``usrmotintf.cc``), so compgen's
notes close the file. The tables use the trt modules' joint numbers for their default
coordinates (X Y Z, the tilting axis, C: joints 0–4), as LinuxCNC prints them at start.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..correction import ARCSEC, CompTable, Held, Plan, comp_tables, compose_tables, nominal_lines, pivot_of
from ..errors import CompgenError
from ..files import read_text
from ..lines import AxisLine
from ..machine import Machine
from ..motion import Block, dwell, gcode_move
from ..units import NUMBER, number
from . import fmt_plain, render
from .base import FILE_MARK, Controller, EditContext, EditFiles

# the value is the rest of the line (a comment aside): halcmd takes one word, so "1.0 junk"
# is refused as a value rather than read as 1.0
SETP = re.compile(r"^[ \t]*setp[ \t]+(\S+?)\.(\S+)[ \t]+([^#\n]*?)[ \t]*(?:#.*)?$", re.MULTILINE)
SETS = re.compile(r"^[ \t]*sets[ \t]+(\S+)[ \t]+([^#\n]*?)[ \t]*(?:#.*)?$", re.MULTILINE)
NET = re.compile(r"^\s*net\s+(\S+)\s+(.*)$", re.MULTILINE)
COMP_ENTRIES = 256           # EMCMOT_COMP_SIZE: the lines a joint's table may hold
TURNS_DEG = 1260.0           # a full-turn axis's table repeats its turn over ±this (≤ 256 lines)
COMP_NOTE = re.compile(r"^# compgen joint compensation for LinuxCNC: joint (\d+) = ([A-Z]) \((mm|deg)\)",
                       re.MULTILINE)


def _trt(machine: Machine) -> tuple[str, object, object]:
    """The trt module for a two-axis table (A or B tilting, C on it), or a clear refusal."""
    axes = machine.rotary_axes
    if (len(axes) != 2 or any(a.side != "workpiece" for a in axes) or axes[1].direction != "z"
            or axes[0].direction not in "xy"):
        raise CompgenError("LinuxCNC's trt kinematics is for a tilting table (A or B) carrying C",
                           hint="this machine's chain is not one xyzac-/xyzbc-trt-kins can drive")
    return f"xyz{axes[0].name.lower()}c-trt-kins", axes[0], axes[1]


def _pin_names(tilt) -> list[str]:
    along = "xyz".index(tilt.direction)
    return ["x-rot-point", "y-rot-point", "z-rot-point"] + [
        f"{'xyz'[k]}-offset" for k in range(3) if k != along]


def _nominal(machine: Machine, tilt, c) -> dict[str, float]:
    pivot_c, pivot_t = pivot_of(machine, c.name), pivot_of(machine, tilt.name)
    return {"x-rot-point": pivot_c[0], "y-rot-point": pivot_c[1], "z-rot-point": pivot_c[2],
            **{f"{'xyz'[k]}-offset": (pivot_t - pivot_c)[k] for k in range(3)}}




# A configuration as LinuxCNC loads it, resolved from its INI: each HAL file after a line
# "# compgen: HAL file NAME", in the order [HAL] HALFILE lists them, then the [HAL] HALCMD
# commands (scripts/linuxcnc.in §4.3.7-4.3.8), then POSTGUI_HALFILE, which the GUI runs once
# it is up (axis.py); a later file's setp overrides an earlier one's, as halcmd executes them.
INI_MARK = "# compgen: HAL file"
INI_SECTION = re.compile(r"^\s*\[([A-Za-z0-9_]+)\]\s*$")


def _ini(text: str) -> dict[str, list[tuple[str, str]]]:
    """An INI's sections: (key, value) pairs in order (a key may repeat, as HALFILE does)."""
    out: dict[str, list[tuple[str, str]]] = {}
    section = None
    for line in text.splitlines():
        if (m := INI_SECTION.match(line)) is not None:
            section = out.setdefault(m[1], [])
        elif section is not None and "=" in line and not line.lstrip().startswith(("#", ";")):
            key, value = line.split("=", 1)
            section.append((key.strip(), value.split("#", 1)[0].strip()))
    return out


def resolve_ini(path: str, text: str) -> str:
    """The HAL the INI at ``path`` loads, each file marked, ``[SECTION]KEY`` references put in
    from the INI as LinuxCNC does; a HAL file not beside the INI (LinuxCNC's own library)
    is named and left out: it sets no trt pin."""
    ini = _ini(text)
    hal = [v for k, v in ini.get("HAL", []) if k == "HALFILE"]
    commands = [v for k, v in ini.get("HAL", []) if k == "HALCMD"]
    post = [v for k, v in ini.get("HAL", []) if k == "POSTGUI_HALFILE"]
    if not hal:
        raise CompgenError("the INI's [HAL] section names no HALFILE", where=path)
    values = {(s, k): v for s, pairs in ini.items() for k, v in pairs}
    folder, out = Path(path).parent, []
    for name in [*hal, None, *post]:
        if name is None:           # the HALCMD lines run between the two
            out += [f"{INI_MARK} {path} [HAL] HALCMD", *commands] if commands else []
            continue
        if name.endswith(".tcl"):
            raise CompgenError(f"HALFILE {name} is a Tcl HAL file, which compgen does not evaluate",
                               where=path, hint="give the HAL file that sets the trt pins as --current")
        file = folder / name
        if not file.is_file():
            out.append(f"{INI_MARK} {name} (not beside the INI: LinuxCNC's own, not read)")
            continue
        body = read_text(file, "HAL file", ansi_ok=True)[0]
        body = re.sub(r"\[([A-Za-z0-9_]+)\]([A-Za-z0-9_]+)",
                      lambda m: values.get((m[1], m[2]), m[0]), body)
        out += [f"{INI_MARK} {file}", body]
    for section, pairs in ini.items():       # the joints' tables (inijoint.cc: type 0 by default)
        joint = re.fullmatch(r"JOINT_(\d+)", section)
        keys = dict(pairs)
        if joint is None or "COMP_FILE" not in keys:
            continue
        kind = keys.get("COMP_FILE_TYPE", "0")
        if kind not in ("0", "1"):
            raise CompgenError(f"[{section}] COMP_FILE_TYPE = {kind}: LinuxCNC takes 0 or 1", where=path)
        file = folder / keys["COMP_FILE"]
        if not file.is_file():
            raise CompgenError(f"[{section}] COMP_FILE {keys['COMP_FILE']} is not beside the INI",
                               where=path, hint="LinuxCNC would not load it either: correct the INI or put "
                                                "the file there")
        body = read_text(file, "joint compensation file", ansi_ok=True)[0]
        out += [f"# compgen: file {file} (COMP_FILE of joint {joint[1]}, type {kind}: {keys['COMP_FILE']})",
                body]
    return "\n".join(out) + "\n"


COMP_MARK = re.compile(r"^# compgen: file (.+) \(COMP_FILE of joint (\d+), type ([01]): (.+)\)$")
TRIPLET = re.compile(r"^\s*(\S+)\s+(\S+)\s+(\S+)")


def _triplets(lines, where: str) -> np.ndarray:
    """A joint table's lines as ``usrmotLoadComp`` (usrmotintf.cc) reads them: three numbers
    at the start of each line, up to the first line that has not."""
    rows = []
    for line in lines:
        m = TRIPLET.match(line)
        if m is None or not all(NUMBER.fullmatch(m[i]) for i in (1, 2, 3)):
            break
        row = [float(m[i]) for i in (1, 2, 3)]
        if not np.all(np.isfinite(row)):
            raise CompgenError(f"{line.strip()!r} is not three finite numbers", where=where)
        rows.append(row)
    if not rows:
        raise CompgenError("the joint table holds no line of three numbers", where=where)
    out = np.array(rows)
    if np.any(np.diff(out[:, 0]) <= 0):
        raise CompgenError("the joint table's nominal positions do not increase: LinuxCNC refuses it",
                           where=where)
    return out


def loaded_joint_tables(machine: Machine, state: str) -> dict[str, tuple[CompTable, CompTable]]:
    """Per axis, the trims (forward, reverse) of the joint tables an INI loads, as LinuxCNC
    holds them (type 0's actual positions converted as nominal − actual)."""
    out: dict[str, tuple[CompTable, CompTable]] = {}
    lines = state.splitlines()
    for i, line in enumerate(lines):
        if (m := COMP_MARK.match(line)) is None:
            continue
        joint = int(m[2])
        axis = _joint_axis(machine, joint, m[1])
        body = lines[i + 1:]
        end = next((k for k, ln in enumerate(body) if FILE_MARK.match(ln)), len(body))
        rows = _triplets(body[:end], m[1])
        if len(rows) > COMP_ENTRIES:
            raise CompgenError(f"the joint table has {len(rows)} lines; LinuxCNC takes {COMP_ENTRIES}",
                               where=m[1])
        nominal, fwd, rev = rows.T
        if m[3] == "0":
            fwd, rev = nominal - fwd, nominal - rev
        unit = "deg" if machine.axis(axis).rotary else "mm"

        def table(v, nominal=nominal, joint=joint, axis=axis, unit=unit):
            return CompTable(f"joint {joint}", "as loaded", axis, axis, float(nominal[0]), float(nominal[-1]),
                             tuple(float(x) for x in v), False, unit, tuple(float(x) for x in nominal))
        out[axis] = (table(fwd), table(rev))
    return out


def _comp_line(state: str, axis: str, machine: Machine) -> str:
    """The INI's COMP_FILE of ``axis``'s joint, as it was (from the resolved ``state``)."""
    return next(f"COMP_FILE = {m[4]}, COMP_FILE_TYPE = {m[3]}" for line in state.splitlines()
                if (m := COMP_MARK.match(line)) is not None and _joint_axis(machine, int(m[2]), m[1]) == axis)


def _joint_axis(machine: Machine, joint: int, where: str) -> str:
    coordinates = _trt(machine)[0][:5].upper()
    if not 0 <= joint < len(coordinates):
        raise CompgenError(f"joint {joint} has a COMP_FILE, and the trt module has joints 0-4", where=where)
    return coordinates[joint]


def read_hal(text: str, module: str, where: str) -> tuple[dict[str, float], dict[str, str]]:
    """A HAL file's values of the module's pins (``setp``, or ``sets`` on the signal a pin is
    netted to) and the signal each netted pin is on. A pin or signal set twice is refused
    (HAL keeps the last: which was meant?)."""
    return _read_hal_lines(text, module, where)[:2]


def _read_hal_lines(text: str, module: str, where: str, nets: dict[str, str] | None = None
                    ) -> tuple[dict[str, float], dict[str, str], dict[str, tuple[str, str]]]:
    """read_hal's values and signals, and where (file:line) each pin's value was set with its
    text as written; ``nets``: the pins netted to signals by files loaded before this one."""
    signal = dict(nets or {})
    for m in NET.finditer(text):
        for word in m[2].split():
            if word.startswith(f"{module}."):
                signal[word[len(module) + 1:]] = m[1]
    on_signal, values, line_of, mine = {}, {}, {}, set()
    k = 0
    for line in text.splitlines():
        k += 1
        if (mark := FILE_MARK.match(line)) is not None:     # the next HAL file of an INI
            where, k, mine = mark[1], 0, set()
            continue
        at = f"{where}:{k}"
        if (m := SETS.match(line)) is not None:
            if ("sets", m[1]) in mine:
                raise CompgenError(f"signal {m[1]} is set twice in one file (lines {on_signal[m[1]][1]} "
                                   f"and {k})", where=at, hint="keep the one the configuration means")
            mine.add(("sets", m[1]))
            on_signal[m[1]] = (number(m[2], f"sets {m[1]}", at), (at, m[2]))
        elif (m := SETP.match(line)) is not None and m[1] == module:
            if m[2] in signal:
                raise CompgenError(f"{module}.{m[2]} is set by setp and netted to {signal[m[2]]}: LinuxCNC "
                                   "refuses to start such a configuration", where=at)
            if ("setp", m[2]) in mine:
                raise CompgenError(f"{module}.{m[2]} is set twice in one file (lines "
                                   f"{line_of[m[2]][0].rsplit(':', 1)[1]} and {k})",
                                   where=at, hint="keep the one the configuration means")
            mine.add(("setp", m[2]))
            values[m[2]], line_of[m[2]] = number(m[3], f"setp {module}.{m[2]}", at), (at, m[3])
    for pin, sig in signal.items():
        if sig in on_signal:
            values[pin], line_of[pin] = on_signal[sig]
    return values, signal, line_of


def pins(machine: Machine, p: Plan, current: str | None,
         where: str) -> tuple[str, list[tuple[str, str, str, str]], list[str]]:
    """The HAL assignments of the trt pins: (``setp`` or ``sets``, pin or signal, new value,
    old value), each pin the way the current file sets it (a netted pin through its signal);
    the current values (the HAL file) or the machine file's nominal, plus the corrections;
    and what the pins cannot express."""
    module, tilt, c = _trt(machine)
    names = _pin_names(tilt)
    nominal = _nominal(machine, tilt, c)
    held, signal = nominal, {}
    if current is not None:
        held, signal, line_of = _read_hal_lines(current, module, where)
        for n in names:
            if n not in held:
                why = (f"is netted to {signal[n]}, which another component drives" if n in signal
                       else "is set neither by setp nor through a signal")
                raise CompgenError(f"in --current, {module}.{n} {why}", where=where,
                                   hint=f"give the HAL file that sets {', '.join(names)}")
            if not abs(held[n] - nominal[n]) * 1e3 <= machine.limits.offset_um:
                raise CompgenError(f"{module}.{n} = {held[n]:g} mm, {held[n] - nominal[n]:+.4f} mm from the "
                                   f"machine file's {nominal[n]:g}: beyond its [limits] offset_um "
                                   f"{machine.limits.offset_um:g} µm", where=line_of[n][0],
                                   hint="is this the configuration of the measured machine? If it is, "
                                        "correct the machine file's offsets or raise [limits]")
    delta_r = p.lines[c.name].offset
    delta_d = p.lines[tilt.name].offset - delta_r
    new = {n: held[n] + (delta_r if n.endswith("rot-point") else delta_d)["xyz".index(n[0])] for n in names}
    other = [f"{n} tilt {line.tilt[i] / ARCSEC:+.2f} arcsec about {'XYZ'[i]}"
             for n, line in p.lines.items() for i in range(3) if line.tilt[i] != 0]
    in_joints = {t.effect for t in joint_tables(machine, p)}
    other += [*p.squareness, *(e for e in p.tables if e not in in_joints), *p.not_compensable]
    was = {n: line_of[n][1] if current is not None else fmt_plain(held[n], 6) for n in names}
    rows = [("sets", signal[n], fmt_plain(new[n], 6), was[n]) if n in signal else
            ("setp", f"{module}.{n}", fmt_plain(new[n], 6), was[n]) for n in names]
    return module, rows, other


def read_lines(text: str, machine: Machine, current: str | None,
               lines: dict[str, AxisLine]) -> dict[str, AxisLine]:
    """The axis lines a trt HAL edit sets, relative to ``current`` (default: nominal)."""
    module, tilt, c = _trt(machine)
    before, nets = read_hal(current, module, "current") if current else (_nominal(machine, tilt, c), {})
    # the edit is loaded after the configuration's files: what it sets wins, through their nets
    now = {**before, **_read_hal_lines(text, module, "edit", nets)[0]}
    r = np.array([now[f"{a}-rot-point"] - before[f"{a}-rot-point"] for a in "xyz"])
    d = np.array([now.get(f"{a}-offset", 0.0) - before.get(f"{a}-offset", 0.0) for a in "xyz"])
    zero = np.zeros(3)
    return {**lines, c.name: AxisLine(c.name, c.direction, lines[c.name].pivot, r, zero),
            tilt.name: AxisLine(tilt.name, tilt.direction, lines[tilt.name].pivot, r + d, zero)}


def joint_number(machine: Machine, axis: str) -> int:
    """The joint of ``axis`` in the trt module's default coordinates (XYZAC, XYZBC)."""
    return _trt(machine)[0][:5].upper().index(axis)


def joint_tables(machine: Machine, p: Plan) -> list[CompTable]:
    """The tables LinuxCNC's joint compensation holds: an axis's error along itself, as the
    joint's trim. A full-turn axis's turn repeats over ±``TURNS_DEG`` within its travel
    (LinuxCNC does not wrap a joint's table)."""
    out = []
    for t in comp_tables(machine, p):
        if t.input != t.output:
            continue                   # a cross table: no joint's own error
        if t.modulo:
            travel = machine.axis(t.input).travel
            first = np.ceil(max(travel[0], -TURNS_DEG) / t.step) * t.step
            grid = np.arange(first, min(travel[1], TURNS_DEG) + t.step / 2, t.step)
            values = np.interp(t.start + np.mod(grid - t.start, t.stop - t.start), t.grid, t.values)
            t = CompTable(t.effect, t.words, t.input, t.output, float(grid[0]), float(grid[-1]),
                          tuple(float(v) for v in values), False, t.unit)
        out.append(t)
    return out


def comp_files(machine: Machine, p: Plan, ctx: EditContext,
               loaded: dict[str, tuple[CompTable, CompTable]]) -> dict[str, tuple[str, str]]:
    """Suffix → (the INI's lines for it, text) of each joint's COMP_FILE: the effects on one
    joint summed, added to the table the joint holds (``loaded``: forward and reverse trims)."""
    by_axis: dict[str, list[CompTable]] = {}
    for t in joint_tables(machine, p):
        by_axis.setdefault(t.input, []).append(t)
    out = {}
    for axis, tables in by_axis.items():
        joint, t = joint_number(machine, axis), tables[0]
        new = CompTable("+".join(tb.effect for tb in tables), "", axis, axis, t.start, t.stop,
                        tuple(np.sum([tb.values for tb in tables], axis=0)), False, t.unit)
        fwd, rev = ((compose_tables([old], [new])[0] for old in loaded[axis]) if axis in loaded
                    else (new, new))
        if len(fwd.values) > COMP_ENTRIES:
            raise CompgenError(f"joint {joint}'s table would need {len(fwd.values)} lines; LinuxCNC takes "
                               f"{COMP_ENTRIES}", hint="the loaded table and this round's together: thin the "
                                                       "loaded one by hand")
        digits = 7 if t.unit == "deg" else 6
        rows = [f"{fmt_plain(x, 6)} {fmt_plain(v, digits)} {fmt_plain(w, digits)}"
                for x, v, w in zip(fwd.grid, fwd.values, rev.values, strict=True)]
        ini = f"[JOINT_{joint}] COMP_FILE = {ctx.stem}.{axis}.comp, COMP_FILE_TYPE = 1"
        notes = [f"compgen joint compensation for LinuxCNC: joint {joint} = {axis} ({t.unit})",
                 *ctx.header[:3],
                 "corrects: " + "; ".join(f"{tb.effect} ({tb.words})" for tb in tables)
                 + (f"; added to the table joint {joint} held" if axis in loaded else ""),
                 f"INI: {ini}",
                 "lines: nominal, trim moving up, trim moving down; the trim is added to the command",
                 f"beyond {t.input} {t.start:g}..{t.stop:g} {t.unit} the end trim holds",
                 "LinuxCNC reads up to the first line that is not three numbers: these notes"]
        out[f".{axis}.comp"] = (ini, "\n".join([*rows, *(f"# {n}" for n in notes)]) + "\n")
    return out


def read_comp(text: str, machine: Machine, where: str) -> CompTable:
    """A joint table compgen wrote, read as LinuxCNC reads it (triplets to the first other
    line), the joint's axis from compgen's closing notes; named by its joint, whose table it
    replaces. Where the trims differ by direction (a loaded table's, kept), the mean stands
    for both: compgen's predictions do not follow the direction of motion."""
    note = COMP_NOTE.search(text)
    if note is None:
        raise CompgenError("a joint compensation file without compgen's closing notes: which joint "
                           "it is for is unknown", where=where, hint="give the .comp file compgen wrote")
    rows = _triplets(text.splitlines(), where)
    axis = note[2]
    if joint_number(machine, axis) != int(note[1]):
        raise CompgenError(f"the table says joint {note[1]} = {axis}; the trt module's joint of {axis} is "
                           f"{joint_number(machine, axis)}", where=where)
    grid, trims = rows[:, 0], (rows[:, 1] + rows[:, 2]) / 2
    # beyond the first and last line LinuxCNC holds the end trims: so does np.interp
    return CompTable(f"joint {note[1]}", "", axis, axis, float(grid[0]), float(grid[-1]),
                     tuple(float(v) for v in trims), False, note[3], tuple(float(x) for x in grid))


POSITION = {"5420": "X", "5421": "Y", "5422": "Z", "5423": "A", "5424": "B", "5425": "C"}


def program_blocks(text: str, tcp: bool) -> list[Block]:
    """A G-code program as LinuxCNC executes it (the blocks compgen writes); ``tcp``: the
    trt kinematics are active (the configuration's choice: the program cannot say it)."""
    out, modal, feed = [Block(0, "kinematics", "tcp", on=tcp)], None, None
    lines = text.splitlines()
    guard_at = None
    for k, raw in enumerate(lines, start=1):
        b = raw.split(";", 1)[0].strip()
        if guard_at is not None and k in (guard_at + 1, guard_at + 2):
            continue                        # the guard's abort and endif, read with it
        if not b:
            continue
        if b == "G21 G90 G94 G17":          # G21: millimetres
            out.append(Block(k, raw, "units"))
        elif b in ("M2", "M30"):
            out.append(Block(k, raw, "end"))
        elif b == "M0" or re.fullmatch(r"\(MSG,[^)]*\)", b):        # the preset check's stop
            out.append(Block(k, raw, "stop"))
        elif (d := re.fullmatch(r"o100 if \[(.*)\]", b)) is not None:
            # compgen's guard: stop unless every named axis is at zero; it stops only if the
            # abort follows it, then its endif
            parts = re.findall(r"\[ABS\[#(\d+)\] GT 0\.0001\]", d[1])
            after = [ln.split(";", 1)[0].strip() for ln in lines[k:k + 2]]
            if (not parts or " OR ".join(f"[ABS[#{p}] GT 0.0001]" for p in parts) != d[1]
                    or any(p not in POSITION for p in parts) or len(after) < 2
                    or not re.fullmatch(r"\(abort,[^)]*\)", after[0]) or after[1] != "o100 endif"):
                raise CompgenError(f"line {k}: {raw.strip()!r} is not compgen's guard (the condition, then "
                                   "an (abort, ...) line and o100 endif)", hint="a guard that does not abort "
                                   "lets the program run from anywhere: give the program compgen wrote")
            guard_at = k
            out.append(Block(k, raw, "require", target={POSITION[p]: 0.0 for p in parts}))
        elif re.fullmatch(r"T\d+ M6", b):
            out.append(Block(k, raw, "tool"))
        elif re.fullmatch(r"G43 H\d+", b) or b == "G49":
            out.append(Block(k, raw, "length", on=b != "G49"))
        elif (d := re.fullmatch(r"G4 P(\S+)", b)) is not None:
            out.append(dwell(d[1], k, raw))
        elif re.fullmatch(r"\((LOGOPEN,[\w.-]+|LOG,[^()]*|LOGCLOSE)\)", b):    # the probe log: no motion
            out.append(Block(k, raw, "log"))
        elif b.startswith("G38.2 "):      # probe towards the target, stop at the touch (error if none)
            move, _, feed = gcode_move(raw, k, ["G1", *b.split()[1:]], None, feed, "G53")
            out.append(replace(move, probe=True))
            modal = None                  # G38.2 stays modal: a bare position would probe again
        else:
            move, modal, feed = gcode_move(raw, k, b.split(), modal, feed, "G53")
            out.append(move)
    return out


class LinuxCNC(Controller):
    name = "linuxcnc"
    family = "linuxcnc"
    words = "LinuxCNC (trt kinematics)"
    program_ext = ".ngc"
    comment = "#"
    tcp_words = "trt kinematics"
    backup = "a copy of the HAL file that sets the trt kinematics pins"
    pose_line = re.compile(r"^G1 X(\S+) Y(\S+) Z(\S+) ((?:[A-C]\S+ )+)F\S+ ; pose (\d+)")
    tcpm_on = re.compile(r"^; mode TCPM", re.MULTILINE)
    tcp_switchable = False
    section = "linuxcnc"
    load_note = ("KIN.hal as a HALFILE after the configuration's own; the COMP_FILE lines its header "
                 "names into the INI")
    holds_tilts = False           # trt kinematics: pivot positions only
    squareness_as = ""

    def tables(self, machine: Machine, p: Plan) -> list[CompTable]:
        return joint_tables(machine, p)

    def main_suffix(self, current: str | None) -> str:
        return ".hal"

    def read_section(self, get, machine: Machine) -> dict:
        """[linuxcnc]: ``conventional_directions``, the trt module's pin of that name. With it
        true, its kinematics turn A (or B) and C the other way (``trtfuncs.c``: every term
        with a single sine of an angle is multiplied by ``con`` = +1, else −1; the pin exists
        from LinuxCNC 2.10, commit bfb687eaa6, and is false by default)."""
        get.only({"conventional_directions"})
        return {"conventional_directions": get.flag("conventional_directions",
                                                    "the trt module's conventional-directions pin")}

    def angle_sense(self, machine: Machine) -> dict[str, int]:
        flip = -1 if (machine.linuxcnc or {}).get("conventional_directions") else 1
        return {a.name: flip for a in machine.rotary_axes}

    def blocks(self, text: str, mode: str | None = None) -> list[Block]:
        written = ("tcpm" if self.tcpm_on.search(text) else
                   "axes" if re.search(r"(?m)^; mode AXES", text) else mode)
        if mode is None:
            raise CompgenError("a LinuxCNC program's kinematics are the configuration's, not the program's: "
                               "say which it runs under", hint="give --mode tcpm (trt kinematics active) or "
                                                               "--mode axes (identity kinematics)")
        if mode != written:
            raise CompgenError(f"the program was written for mode {written.upper()} (its header) and is to "
                               f"run under {mode.upper()}: its positions mean other things there",
                               hint=f"write it again with compgen measure-program --mode {mode}")
        return program_blocks(text, mode == "tcpm")

    def edit(self, machine: Machine, p: Plan, current: str | None, where: str,
             ctx: EditContext) -> EditFiles:
        module, rows, other = pins(machine, p, current, where)
        from_ini = current is not None and INI_MARK in current
        loaded = loaded_joint_tables(machine, current) if current is not None else {}
        comps = comp_files(machine, p, ctx, loaded)
        ini_lines = [ini for ini, _ in comps.values()]
        text = render("linuxcnc/kinematics.hal.j2", header=ctx.header, module=module, lines=ctx.lines,
                      rows=rows, other=other, ini=ini_lines, restore=False)
        notes = [f"{cmd} {target} {v}  (was {w})" for cmd, target, v, w in rows]
        ini = where if from_ini else "the configuration's INI"
        notes.append(f"load it: HALFILE = {ctx.stem}.hal after the last HALFILE of [HAL] in {ini}; the next "
                     "round's --current is that INI, so the next edit adds to this one")
        if ini_lines:
            notes += ["joint compensation tables: in the INI, set (replacing any COMP_FILE or BACKLASH of "
                      "these joints)", *(f"  {line}" for line in ini_lines)]
            notes.append(f"they hold the tables the INI loads plus this round's ({', '.join(sorted(loaded))} "
                         "held one)" if loaded else "no joint had a table in the INI: they hold this round's "
                         "correction" if from_ini else "--current is not the INI, so the joints' loaded "
                         "tables are unknown: these hold this round's correction alone (give the INI to "
                         "add to them)")
        if other:
            notes.append("not expressible in LinuxCNC's trt kinematics and joint tables: " + ", ".join(other))
        if current is not None and "tool-offset" not in read_hal(current, module, where)[1]:
            notes.append(f"{module}.tool-offset is not netted: net it to motion.tooloffset.z, or the "
                         "table turns about the spindle nose instead of the nest (G43 lengths)")
        # the restore: each pin back to the value read, as it was written; each joint's table
        # back to the INI's lines (the files they name are not touched)
        restore_ini = [f"[JOINT_{joint_number(machine, a)}] " + (
            _comp_line(current, a, machine) if a in loaded else "no COMP_FILE (remove the line the edit set)")
            for a in sorted({t.input for t in joint_tables(machine, p)})]
        restore = render("linuxcnc/kinematics.hal.j2", module=module, lines=[], other=[], ini=restore_ini,
                         rows=[(cmd, target, w, w) for cmd, target, _, w in rows], restore=True,
                         header=[f"compgen {ctx.version}: restores the trt pins as they were read",
                                 *ctx.header[1:3], f"load it in place of {ctx.stem}.hal"])
        return EditFiles({".hal": text, "_RESTORE.hal": restore,
                          **{k: body for k, (_, body) in comps.items()}}, tuple(notes))

    def loaded_tables(self, machine: Machine, state: str, where: str) -> list[CompTable]:
        return [replace(fwd, values=tuple((np.add(fwd.values, rev.values) / 2).tolist()))
                for fwd, rev in loaded_joint_tables(machine, state).values()]

    def since(self, machine: Machine, measured: str, current: str, where: str) -> Held:
        return Held(read_lines(current, machine, measured, nominal_lines(machine)), {})

    def state(self, path: str, text: str) -> str | None:
        return resolve_ini(path, text) if re.search(r"(?m)^\s*\[HAL\]\s*$", text) else None

    def reads(self, text: str) -> bool:
        return (SETP.search(text) is not None or COMP_NOTE.search(text) is not None
                or (SETS.search(text) is not None and "kinematics edit" in text))

    def check_setup(self, machine: Machine) -> None:
        if machine.linuxcnc is None:
            raise CompgenError("whether the trt kinematics turn the rotary axes the conventional way is not "
                               "in the machine file: the same program turns them the other way if they do",
                               where=f"{machine.source}: [linuxcnc] conventional_directions",
                               hint="set conventional_directions = false (before LinuxCNC 2.10, or the "
                                    "module's conventional-directions pin at its default 0) or true (pin 1)")
        if not re.fullmatch(r"\d{1,5}", machine.program.tool):
            raise CompgenError(f"LinuxCNC calls tools by number; [program] tool is {machine.program.tool!r}",
                               where=f"{machine.source}: [program] tool", hint='e.g. tool = "99"')

    def read(self, machine: Machine, text: str, current: str | None, held: Held, where: str) -> Held:
        if COMP_NOTE.search(text):     # a joint's table replaces the one it held
            table = read_comp(text, machine, where)
            return Held(held.lines, held.squareness,
                        (*(t for t in held.tables if t.effect != table.effect), table))
        return Held(read_lines(text, machine, current, held.lines), held.squareness, held.tables)
