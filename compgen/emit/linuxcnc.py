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
from pathlib import Path

import numpy as np

from ..correction import ARCSEC, CompTable, Held, Plan, comp_tables, nominal_lines, pivot_of
from ..errors import CompgenError
from ..files import read_text
from ..lines import AxisLine
from ..machine import Machine
from ..motion import Block, gcode_move, unknown
from ..units import number
from . import fmt_plain, render
from .base import FILE_MARK, Controller, EditContext, EditFiles

SETP = re.compile(r"^\s*setp\s+(\S+?)\.(\S+)\s+(\S+)", re.MULTILINE)
SETS = re.compile(r"^\s*sets\s+(\S+)\s+(\S+)", re.MULTILINE)
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
    return "\n".join(out) + "\n"


def read_hal(text: str, module: str, where: str) -> tuple[dict[str, float], dict[str, str]]:
    """A HAL file's values of the module's pins (``setp``, or ``sets`` on the signal a pin is
    netted to) and the signal each netted pin is on. A pin or signal set twice is refused
    (HAL keeps the last: which was meant?)."""
    return _read_hal_lines(text, module, where)[:2]


def _read_hal_lines(text: str, module: str, where: str, nets: dict[str, str] | None = None
                    ) -> tuple[dict[str, float], dict[str, str], dict[str, str]]:
    """read_hal's values and signals, and where (file:line) each pin's value was set; ``nets``: the
    pins netted to signals by files loaded before this one."""
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
            on_signal[m[1]] = (number(m[2], f"sets {m[1]}", at), at)
        elif (m := SETP.match(line)) is not None and m[1] == module:
            if m[2] in signal:
                raise CompgenError(f"{module}.{m[2]} is set by setp and netted to {signal[m[2]]}: LinuxCNC "
                                   "refuses to start such a configuration", where=at)
            if ("setp", m[2]) in mine:
                raise CompgenError(f"{module}.{m[2]} is set twice in one file (lines "
                                   f"{line_of[m[2]].rsplit(':', 1)[1]} and {k})",
                                   where=at, hint="keep the one the configuration means")
            mine.add(("setp", m[2]))
            values[m[2]], line_of[m[2]] = number(m[3], f"setp {module}.{m[2]}", at), at
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
                                   f"{machine.limits.offset_um:g} µm", where=line_of[n],
                                   hint="is this the configuration of the measured machine? If it is, "
                                        "correct the machine file's offsets or raise [limits]")
    delta_r = p.lines[c.name].offset
    delta_d = p.lines[tilt.name].offset - delta_r
    new = {n: held[n] + (delta_r if n.endswith("rot-point") else delta_d)["xyz".index(n[0])] for n in names}
    other = [f"{n} tilt {line.tilt[i] / ARCSEC:+.2f} arcsec about {'XYZ'[i]}"
             for n, line in p.lines.items() for i in range(3) if line.tilt[i] != 0]
    in_joints = {t.effect for t in joint_tables(machine, p)}
    other += [*p.squareness, *(e for e in p.tables if e not in in_joints), *p.not_compensable]
    rows = [("sets", signal[n], fmt_plain(new[n], 6), fmt_plain(held[n], 6)) if n in signal else
            ("setp", f"{module}.{n}", fmt_plain(new[n], 6), fmt_plain(held[n], 6)) for n in names]
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


def comp_files(machine: Machine, p: Plan, ctx: EditContext) -> dict[str, tuple[str, str]]:
    """Suffix → (the INI's lines for it, text) of each joint's COMP_FILE: the effects on one
    joint summed."""
    by_axis: dict[str, list[CompTable]] = {}
    for t in joint_tables(machine, p):
        by_axis.setdefault(t.input, []).append(t)
    out = {}
    for axis, tables in by_axis.items():
        joint, t = joint_number(machine, axis), tables[0]
        trims = np.sum([tb.values for tb in tables], axis=0)
        if len(trims) > COMP_ENTRIES:      # a guard: the grids above stay within it
            raise CompgenError(f"joint {joint}'s table would need {len(trims)} lines; LinuxCNC takes "
                               f"{COMP_ENTRIES}")
        digits = 7 if t.unit == "deg" else 6
        rows = [f"{fmt_plain(x, 6)} {fmt_plain(v, digits)} {fmt_plain(v, digits)}"
                for x, v in zip(t.grid, trims, strict=True)]
        ini = f"[JOINT_{joint}] COMP_FILE = {ctx.stem}.{axis}.comp, COMP_FILE_TYPE = 1"
        notes = [f"compgen joint compensation for LinuxCNC: joint {joint} = {axis} ({t.unit})",
                 *ctx.header[:3],
                 "corrects: " + "; ".join(f"{tb.effect} ({tb.words})" for tb in tables),
                 f"INI: {ini}",
                 "lines: nominal, trim moving up, trim moving down; the trim is added to the command",
                 f"beyond {t.input} {t.start:g}..{t.stop:g} {t.unit} the end trim holds",
                 "LinuxCNC reads up to the first line that is not three numbers: these notes"]
        out[f".{axis}.comp"] = (ini, "\n".join([*rows, *(f"# {n}" for n in notes)]) + "\n")
    return out


def read_comp(text: str, machine: Machine, where: str) -> CompTable:
    """A joint table compgen wrote, read as LinuxCNC reads it (triplets to the first other
    line), the joint's axis from compgen's closing notes."""
    note = COMP_NOTE.search(text)
    if note is None:
        raise CompgenError("a joint compensation file without compgen's closing notes: which joint "
                           "it is for is unknown", where=where, hint="give the .comp file compgen wrote")
    rows = []
    for k, line in enumerate(text.splitlines(), start=1):
        words = line.split()
        if len(words) != 3 or line.startswith("#"):
            break
        rows.append([number(w, f"line {k}", where) for w in words])
    if not rows or any(r[1] != r[2] for r in rows):
        raise CompgenError("the joint table is empty or its trims differ by direction (compgen writes "
                           "equal ones)", where=where, hint="give the .comp file as compgen wrote it")
    grid, trims = np.array(rows)[:, 0], np.array(rows)[:, 1]
    if np.any(np.diff(grid) <= 0):
        raise CompgenError("the joint table's nominal positions do not increase: LinuxCNC refuses it",
                           where=where)
    axis = note[2]
    if joint_number(machine, axis) != int(note[1]):
        raise CompgenError(f"the table says joint {note[1]} = {axis}; the trt module's joint of {axis} is "
                           f"{joint_number(machine, axis)}", where=where)
    # beyond the first and last line LinuxCNC holds the end trims: so does np.interp
    return CompTable("", "", axis, axis, float(grid[0]), float(grid[-1]), tuple(trims), False, note[3])


POSITION = {"5420": "X", "5421": "Y", "5422": "Z", "5423": "A", "5424": "B", "5425": "C"}


def program_blocks(text: str, tcp: bool) -> list[Block]:
    """A G-code program as LinuxCNC executes it (the blocks compgen writes); ``tcp``: the
    trt kinematics are active (the configuration's choice, stated in compgen's header)."""
    out, modal, feed = [Block(0, "kinematics", "tcp", on=tcp)], None, None
    for k, raw in enumerate(text.splitlines(), start=1):
        b = raw.split(";", 1)[0].strip()
        if not b or b in ("G21 G90 G94 G17", "M2", "M30", "o100 endif") or re.fullmatch(
                r"\(abort,[^)]*\)", b):
            continue
        if b == "M0" or re.fullmatch(r"\(MSG,[^)]*\)", b):        # the preset check's stop
            out.append(Block(k, raw, "stop"))
        elif (d := re.fullmatch(r"o100 if \[(.*)\]", b)) is not None:
            # compgen's guard: stop unless every named axis is at zero
            parts = re.findall(r"\[ABS\[#(\d+)\] GT 0\.0001\]", d[1])
            if not parts or " OR ".join(f"[ABS[#{p}] GT 0.0001]" for p in parts) != d[1]:
                raise unknown(k, raw)
            out.append(Block(k, raw, "require", target={POSITION[p]: 0.0 for p in parts}))
        elif re.fullmatch(r"T\d+ M6", b):
            out.append(Block(k, raw, "tool"))
        elif re.fullmatch(r"G43 H\d+", b) or b == "G49":
            out.append(Block(k, raw, "length", on=b != "G49"))
        elif (d := re.fullmatch(r"G4 P([\d.]+)", b)) is not None:
            out.append(Block(k, raw, "dwell", seconds=float(d[1])))
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

    def blocks(self, text: str) -> list[Block]:
        return program_blocks(text, self.tcpm_on.search(text) is not None)

    def edit(self, machine: Machine, p: Plan, current: str | None, where: str,
             ctx: EditContext) -> EditFiles:
        module, rows, other = pins(machine, p, current, where)
        comps = comp_files(machine, p, ctx)
        ini_lines = [ini for ini, _ in comps.values()]
        text = render("linuxcnc/kinematics.hal.j2", header=ctx.header, module=module, lines=ctx.lines,
                      rows=rows, other=other, ini=ini_lines)
        notes = [f"{cmd} {target} {v}  (was {w})" for cmd, target, v, w in rows]
        ini = where if current is not None and INI_MARK in current else "the configuration's INI"
        notes.append(f"load it: HALFILE = {ctx.stem}.hal after the last HALFILE of [HAL] in {ini}; the next "
                     "round's --current is that INI, so the next edit adds to this one")
        if ini_lines:
            notes += ["joint compensation tables: add to the INI (replacing any COMP_FILE or BACKLASH "
                      "of these joints)", *(f"  {line}" for line in ini_lines),
                      "they hold this fit's correction alone: where a joint had a COMP_FILE loaded while "
                      "measuring, add its trims to the new ones (compgen does not compose tables yet)"]
        if other:
            notes.append("not expressible in LinuxCNC's trt kinematics and joint tables: " + ", ".join(other))
        if current is not None and "tool-offset" not in read_hal(current, module, where)[1]:
            notes.append(f"{module}.tool-offset is not netted: net it to motion.tooloffset.z, or the "
                         "table turns about the spindle nose instead of the nest (G43 lengths)")
        return EditFiles({".hal": text, **{k: body for k, (_, body) in comps.items()}}, tuple(notes))

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
        if COMP_NOTE.search(text):
            return Held(held.lines, held.squareness, (*held.tables, read_comp(text, machine, where)))
        return Held(read_lines(text, machine, current, held.lines), held.squareness, held.tables)
