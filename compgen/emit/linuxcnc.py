"""LinuxCNC with the trt kinematics (``xyzac-trt-kins``, ``xyzbc-trt-kins``): G-code
programs and HAL edits of the kinematics pins, and their reader.

The pins (``src/emc/kinematics/trtfuncs.c``): C turns about the line through the rot
point, the tilting axis about the line through the rot point plus the offsets. They hold
axis-line positions only: angular location errors cannot be expressed.
"""

from __future__ import annotations

import re

import numpy as np

from ..correction import ARCSEC, Held, Plan, nominal_lines, pivot_of
from ..errors import CompgenError
from ..lines import AxisLine
from ..machine import Machine
from ..motion import Block, gcode_move, unknown
from ..units import number
from . import fmt_plain, render
from .base import Controller, EditContext, EditFiles

SETP = re.compile(r"^\s*setp\s+(\S+?)\.(\S+)\s+(\S+)", re.MULTILINE)
SETS = re.compile(r"^\s*sets\s+(\S+)\s+(\S+)", re.MULTILINE)
NET = re.compile(r"^\s*net\s+(\S+)\s+(.*)$", re.MULTILINE)


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




def read_hal(text: str, module: str, where: str) -> tuple[dict[str, float], dict[str, str]]:
    """A HAL file's values of the module's pins (``setp``, or ``sets`` on the signal a pin is
    netted to) and the signal each netted pin is on."""
    signal = {}
    for m in NET.finditer(text):
        for word in m[2].split():
            if word.startswith(f"{module}."):
                signal[word[len(module) + 1:]] = m[1]
    on_signal = {m[1]: number(m[2], f"sets {m[1]}", where) for m in SETS.finditer(text)}
    values = {}
    for m in SETP.finditer(text):
        if m[1] == module:
            if m[2] in signal:
                raise CompgenError(f"{module}.{m[2]} is set by setp and netted to {signal[m[2]]}: LinuxCNC "
                                   "refuses to start such a configuration", where=where)
            values[m[2]] = number(m[3], f"setp {module}.{m[2]}", where)
    values |= {pin: on_signal[sig] for pin, sig in signal.items() if sig in on_signal}
    return values, signal


def pins(machine: Machine, p: Plan, current: str | None,
         where: str) -> tuple[str, list[tuple[str, str, str, str]], list[str]]:
    """The HAL assignments of the trt pins: (``setp`` or ``sets``, pin or signal, new value,
    old value), each pin the way the current file sets it (a netted pin through its signal);
    the current values (the HAL file) or the machine file's nominal, plus the corrections;
    and what the pins cannot express."""
    module, tilt, c = _trt(machine)
    names = _pin_names(tilt)
    held, signal = _nominal(machine, tilt, c), {}
    if current is not None:
        held, signal = read_hal(current, module, where)
        for n in names:
            if n not in held:
                why = (f"is netted to {signal[n]}, which another component drives" if n in signal
                       else "is set neither by setp nor through a signal")
                raise CompgenError(f"in --current, {module}.{n} {why}", where=where,
                                   hint=f"give the HAL file that sets {', '.join(names)}")
    delta_r = p.lines[c.name].offset
    delta_d = p.lines[tilt.name].offset - delta_r
    new = {n: held[n] + (delta_r if n.endswith("rot-point") else delta_d)["xyz".index(n[0])] for n in names}
    other = [f"{n} tilt {line.tilt[i] / ARCSEC:+.2f} arcsec about {'XYZ'[i]}"
             for n, line in p.lines.items() for i in range(3) if line.tilt[i] != 0]
    other += [*p.squareness, *p.tables, *p.not_compensable]
    rows = [("sets", signal[n], fmt_plain(new[n], 6), fmt_plain(held[n], 6)) if n in signal else
            ("setp", f"{module}.{n}", fmt_plain(new[n], 6), fmt_plain(held[n], 6)) for n in names]
    return module, rows, other


def read_lines(text: str, machine: Machine, current: str | None,
               lines: dict[str, AxisLine]) -> dict[str, AxisLine]:
    """The axis lines a trt HAL edit sets, relative to ``current`` (default: nominal)."""
    module, tilt, c = _trt(machine)
    before = read_hal(current, module, "current")[0] if current else _nominal(machine, tilt, c)
    # the edit is loaded after the configuration's files: its nets are the current file's
    now = {**before, **read_hal(f"{current or ''}\n{text}", module, "edit")[0]}
    r = np.array([now[f"{a}-rot-point"] - before[f"{a}-rot-point"] for a in "xyz"])
    d = np.array([now.get(f"{a}-offset", 0.0) - before.get(f"{a}-offset", 0.0) for a in "xyz"])
    zero = np.zeros(3)
    return {**lines, c.name: AxisLine(c.name, c.direction, lines[c.name].pivot, r, zero),
            tilt.name: AxisLine(tilt.name, tilt.direction, lines[tilt.name].pivot, r + d, zero)}


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
        if (d := re.fullmatch(r"o100 if \[(.*)\]", b)) is not None:
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
    holds_tilts = False           # trt kinematics: pivot positions only
    squareness_as = ""
    holds_tables = False          # joint COMP_FILE tables are not written (yet)

    def main_suffix(self, current: str | None) -> str:
        return ".hal"

    def blocks(self, text: str) -> list[Block]:
        return program_blocks(text, self.tcpm_on.search(text) is not None)

    def edit(self, machine: Machine, p: Plan, current: str | None, where: str,
             ctx: EditContext) -> EditFiles:
        module, rows, other = pins(machine, p, current, where)
        text = render("linuxcnc/kinematics.hal.j2", header=ctx.header, module=module, lines=ctx.lines,
                      rows=rows, other=other)
        notes = [f"{cmd} {target} {v}  (was {w})" for cmd, target, v, w in rows]
        notes.append("not expressible in the trt kinematics: " + ", ".join(other))
        if current is not None and "tool-offset" not in read_hal(current, module, where)[1]:
            notes.append(f"{module}.tool-offset is not netted: net it to motion.tooloffset.z, or the "
                         "table turns about the spindle nose instead of the nest (G43 lengths)")
        return EditFiles({".hal": text}, tuple(notes))

    def since(self, machine: Machine, measured: str, current: str, where: str) -> Held:
        return Held(read_lines(current, machine, measured, nominal_lines(machine)), {})

    def reads(self, text: str) -> bool:
        return SETP.search(text) is not None or (SETS.search(text) is not None and "kinematics edit" in text)

    def check_setup(self, machine: Machine) -> None:
        if not re.fullmatch(r"\d{1,5}", machine.program.tool):
            raise CompgenError(f"LinuxCNC calls tools by number; [program] tool is {machine.program.tool!r}",
                               where=f"{machine.source}: [program] tool", hint='e.g. tool = "99"')

    def read(self, machine: Machine, text: str, current: str | None, held: Held, where: str) -> Held:
        return Held(read_lines(text, machine, current, held.lines), held.squareness, held.tables)
