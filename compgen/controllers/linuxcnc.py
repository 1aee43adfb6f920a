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
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .. import me
from ..errors import CompgenError
from ..model.lines import AxisLine
from ..model.machine import Machine
from ..setup.motion import Block, dwell, gcode_move
from ..units import NUMBER, number
from . import fmt_plain, render
from .base import Controller, EditContext, EditFiles
from .correction import (
    ARCSEC,
    CompTable,
    Held,
    Plan,
    comp_tables,
    compose_tables,
    nominal_lines,
    pivot_of,
    unrolled,
)
from .linuxcnc_config import Configuration, bundle, configuration_files, evaluate, hal_file, is_bundle, then
from .linuxcnc_files import Setting
from .state_guards import require_guard

# the value is the rest of the line (a comment aside): halcmd takes one word, so "1.0 junk"
# is refused as a value rather than read as 1.0
SETP = re.compile(r"^[ \t]*setp[ \t]+(\S+?)\.(\S+)[ \t]+([^#\n]*?)[ \t]*(?:#.*)?$", re.MULTILINE)
SETS = re.compile(r"^[ \t]*sets[ \t]+(\S+)[ \t]+([^#\n]*?)[ \t]*(?:#.*)?$", re.MULTILINE)
PIN_SINCE = (2, 10)          # the trt modules' conventional-directions pin (commit bfb687eaa6)
# Upstream's trtfuncs.c from 2.10 (xyzbc_inverse_math) writes the tilted offsets with the
# signs of conventional-directions 1 whatever the pin says, while its forward kinematics
# follows the pin: at pin 0 the inverse no longer inverts the forward.
XYZBC_PIN0 = ("LinuxCNC 2.10's xyzbc-trt-kins at conventional-directions 0 does not invert its own forward "
              "kinematics: trtfuncs.c xyzbc_inverse_math has 'dpx = -cos(b_rad)*dx + sin(b_rad)*dz + dx' "
              "and 'dpz = -sin(b_rad)*dx - cos(b_rad)*dz + dz' (the signs of pin 1; 2.9 had "
              "'- sin(b_rad)*dz' and '+ sin(b_rad)*dx'), while xyzbc_forward_math turns by con = -1 at "
              "pin 0: under TCP the nest stands off by 2*sin(B)*(z-offset + tool-offset) in X and "
              "2*sin(B)*x-offset in Z")
COMP_ENTRIES = 256           # EMCMOT_COMP_SIZE: the lines a joint's table may hold
TURNS_DEG = 1260.0           # a full-turn axis's table repeats its turn over ±this (≤ 256 lines)
COMP_NOTE = re.compile(r"^# compgen joint compensation for LinuxCNC: joint (\d+) = ([A-Z]) \((mm|deg)\)",
                       re.MULTILINE)


def trt_module(machine: Machine) -> tuple[str, object, object]:
    """The trt module for a two-axis table (A or B tilting, C on it), or a clear refusal."""
    axes = machine.rotary_axes
    if (len(axes) != 2 or any(a.side != "workpiece" for a in axes) or axes[1].direction != "z"
            or axes[0].direction not in "xy"):
        raise CompgenError("LinuxCNC's trt kinematics is for a tilting table (A or B) carrying C",
                           hint="this machine's chain is not one xyzac-/xyzbc-trt-kins can drive")
    return f"xyz{axes[0].name.lower()}c-trt-kins", axes[0], axes[1]


@dataclass(frozen=True)
class HeadModule:
    """A LinuxCNC kinematics module that turns the tool: its name, what machine it is for,
    and how it turns each rotary axis against the machine file (what it holds was run with
    the real module: tests/test_linuxcnc.py). Its one geometry pin, pivot-length, holds the
    pivot to the controlled point: compgen's programs put the nest there (G49)."""
    module: str
    what: str
    active: str                           # when the control runs it
    head: tuple[tuple[str, str], ...]     # the head's axes, base outwards: (name, direction)
    table: tuple[tuple[str, str], ...]    # the table's rotary axes
    sense: tuple[tuple[str, int], ...]    # ±1 a rotary axis: its turn in the module's words
    notes: tuple[str, ...] = ()           # what its programs' headers must tell the operator


# Debian's 2.9: maxkins.c (a B head over a C table, always active; X Y Z in the table frame)
# and 5axiskins.c (a bridge mill's C head carrying B, through switchkins type 0). Both tilt
# B the other way from a right-handed turn of the tool; maxkins turns its table's C the
# other way too, 5axiskins its head's C as the tool turns.
HEAD_MODULES = (
    HeadModule("maxkins", "a B head over a C table", "always active",
               head=(("B", "y"),), table=(("C", "z"),), sense=(("B", -1), ("C", -1)),
               # 2.9's maxkins.c forward kinematics copies the joints (its inverse turns them):
               # switched to joint mode (Manual after an abort), X and Y jump by up to 2 L sin B
               notes=("After an abort or an E-stop: maxkins' forward kinematics do not invert its inverse,",
                      "and Manual mode then moves X and Y by up to 2 x pivot-length x sin B. Stay in MDI:",
                      "take the nest off the ball along its axis, go up to the safe height, G0 B0 C0;",
                      "only then switch to Manual.")),
    HeadModule("5axiskins", "a C head carrying a B fork",
               "at motion.switchkins-type 0 (its start without sparm=identityfirst)",
               head=(("C", "z"), ("B", "y")), table=(), sense=(("B", -1), ("C", 1))),
)


def head_module(machine: Machine) -> tuple[HeadModule, float] | None:
    """LinuxCNC's module for ``machine``'s head and the pivot-length it needs (mm: the pivot
    to the nest centre, the nest's length in it), or None where no module fits: every head
    axis pivoting on the tool axis at one point, a table axis turning about the origin, each
    turning right-handed in the machine file."""
    heads, tables = machine.heads, [a for a in machine.rotary_axes if a.side == "workpiece"]
    for m in HEAD_MODULES:
        if ([(a.name, a.direction) for a in heads] != list(m.head)
                or [(a.name, a.direction) for a in tables] != list(m.table)
                or any(a.sense != 1 for a in machine.rotary_axes)
                or any(any(c.offset) for c in tables) or any(heads[0].offset[:2])
                or any(any(a.offset) for a in heads[1:])):
            continue
        return m, machine.probe_length + heads[0].offset[2]
    return None


def pin_tolerance(machine: Machine) -> float:
    """How far (mm) a head module's pivot-length may stand from the machine file's for its
    programs to run: what an edit may change it by, the machine file's [limits] offset_um
    (the motion check's clearances are millimetres)."""
    return float(f"{machine.limits.offset_um * 1e-3:.4f}")


def module_pins(machine: Machine) -> tuple[str, list[str], dict[str, float]]:
    """The kinematics module compgen edits for ``machine`` (a head module, else trt), its
    geometry pins in the order the edit writes them, and their nominal values (mm)."""
    head = head_module(machine)
    if head is not None:
        return head[0].module, ["pivot-length"], {"pivot-length": head[1]}
    module, tilt, c = trt_module(machine)
    return module, pin_names(tilt), nominal_pins(machine, tilt, c)


def head_correction(machine: Machine, p: Plan) -> tuple[float, list[str]]:
    """What a head module's one pin holds of ``p``: the heads' line offsets along the tool
    axis at the pivot (mm; the true pivot that much farther from the nest lengthens the
    pivot-length by it), and in words all else, which no pin of the module holds."""
    heads = {a.name for a in machine.heads}
    along = sum(float(p.lines[h].offset[2]) for h in heads)
    other = [f"{n} offset {line.offset[i] * 1e3:+.2f} um along {'XYZ'[i]}" for n, line in p.lines.items()
             for i in range(3) if line.offset[i] != 0 and not (n in heads and i == 2)]
    return along, [*other, *_tilts(p), *p.squareness, *p.tables, *p.not_compensable]


def _tilts(p: Plan) -> list[str]:
    """The axis lines' tilts of ``p`` in words: no LinuxCNC pin holds a tilt."""
    return [f"{n} tilt {line.tilt[i] / ARCSEC:+.2f} arcsec about {'XYZ'[i]}"
            for n, line in p.lines.items() for i in range(3) if line.tilt[i] != 0]


def head_lines(machine: Machine, along: float) -> dict[str, AxisLine]:
    """The axis lines a head module holds with its pivot-length ``along`` mm from nominal:
    the tilting head's line that much farther from the nest, every other line nominal."""
    lines = nominal_lines(machine)
    tilt = next(a for a in machine.heads if a.direction != "z")
    line = lines[tilt.name]
    return {**lines, tilt.name: AxisLine(tilt.name, line.nominal, line.pivot, np.array([0.0, 0.0, along]),
                                         np.zeros(3))}


def pin_names(tilt) -> list[str]:
    """The trt module's geometry pins, in the order the edit writes them: C's rotation
    point and the tilt's offset from it (the component along its own line has no pin)."""
    along = "xyz".index(tilt.direction)
    return ["x-rot-point", "y-rot-point", "z-rot-point"] + [
        f"{'xyz'[k]}-offset" for k in range(3) if k != along]


def nominal_pins(machine: Machine, tilt, c) -> dict[str, float]:
    """The pins' values, mm, for the machine file's nominal pivots (no correction)."""
    pivot_c, pivot_t = pivot_of(machine, c.name), pivot_of(machine, tilt.name)
    return {"x-rot-point": pivot_c[0], "y-rot-point": pivot_c[1], "z-rot-point": pivot_c[2],
            **{f"{'xyz'[k]}-offset": (pivot_t - pivot_c)[k] for k in range(3)}}




# usrmotLoadComp (usrmotintf.cc) reads a table with fgets(buffer, LINELEN) — LINELEN 255 in
# config.h, so 254 characters at a time, a longer line read as two — and takes each piece
# with sscanf("%lf %lf %lf"): white space (C's isspace) before each number, each number the
# longest prefix strtod reads, anything after the third ignored; it stops at the first piece
# that does not give three
COMP_LINELEN = 255
SCANNED = re.compile(r"[ \t\n\v\f\r]*([+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)")
STRTOD_ELSE = re.compile(r"[ \t\n\v\f\r]*[+-]?(?:inf|nan|0x)", re.IGNORECASE)   # strtod reads these too


def _pieces(text: str):
    """The pieces fgets(buffer, COMP_LINELEN) reads: up to a line end, at most 254 characters."""
    at = 0
    while at < len(text):
        end = text.find("\n", at, at + COMP_LINELEN - 1)
        end = end + 1 if end >= 0 else min(at + COMP_LINELEN - 1, len(text))
        yield text[at:end]
        at = end


def _scanned(piece: str, where: str) -> list[float] | None:
    """sscanf(piece, "%lf %lf %lf") when it gives three numbers; None where it gives fewer."""
    row, at = [], 0
    for _ in range(3):
        if STRTOD_ELSE.match(piece, at):
            raise CompgenError(f"{piece.strip()!r}: LinuxCNC reads an infinity, a NaN or a hexadecimal "
                               "number here, which compgen does not", where=where,
                               hint="write the table's numbers in decimals")
        m = SCANNED.match(piece, at)
        if m is None:
            return None
        row.append(float(m[1]))
        at = m.end()
    return row


def _triplets(text: str, where: str) -> np.ndarray:
    """A joint table as ``usrmotLoadComp`` reads it (``_pieces``, ``_scanned``): three
    numbers at the start of each piece, up to the first piece that has not."""
    rows = []
    for piece in _pieces(text):
        row = _scanned(piece, where)
        if row is None:
            break
        if not np.all(np.isfinite(row)):
            raise CompgenError(f"{piece.strip()!r} is not three finite numbers", where=where)
        rows.append(row)
    if not rows:
        raise CompgenError("the joint table holds no line of three numbers", where=where)
    out = np.array(rows)
    if np.any(np.diff(out[:, 0]) <= 0):
        raise CompgenError("the joint table's nominal positions do not increase: LinuxCNC refuses it",
                           where=where)
    return out


def configuration(state: str | None, where: str) -> Configuration | None:
    """What LinuxCNC holds from ``state``: a configuration read from its INI, or one HAL
    file run alone."""
    if state is None:
        return None
    return evaluate(state) if is_bundle(state) else hal_file(state, where)


def loaded_joint_tables(machine: Machine, state: str | None) -> dict[str, tuple[CompTable, CompTable]]:
    """Per axis, the trims (forward, reverse) of the joint tables an INI loads, as LinuxCNC
    holds them (type 0's actual positions converted as nominal − actual), each within the
    machine file's [limits] of the axis's own error."""
    return _joint_tables(machine, evaluate(state)) if is_bundle(state) else {}


def _joint_tables(machine: Machine, cfg: Configuration) -> dict[str, tuple[CompTable, CompTable]]:
    out: dict[str, tuple[CompTable, CompTable]] = {}
    if head_module(machine) is not None and cfg.joints:
        raise CompgenError("the INI loads joint compensation tables (COMP_FILE): compgen does not compose "
                           "them for a head module yet", where=str(next(iter(cfg.joints.values()))[0].place),
                           hint="give the configuration without them, or edit the pin by hand")
    for joint, (comp, kind, text) in cfg.joints.items():
        where = f"{comp.place} ({comp.value})"
        axis = _joint_axis(machine, joint, str(comp.place))
        rows = _triplets(text, where)
        if len(rows) > COMP_ENTRIES:
            raise CompgenError(f"the joint table has {len(rows)} lines; LinuxCNC takes {COMP_ENTRIES}",
                               where=where)
        nominal, fwd, rev = rows.T
        if kind == "0":
            fwd, rev = nominal - fwd, nominal - rev
        rotary = machine.axis(axis).rotary
        bound = machine.limits.tilt_arcsec / 3600 if rotary else machine.limits.offset_um * 1e-3
        worst = float(np.abs(np.concatenate([fwd, rev])).max())
        if not worst <= bound:
            unit, key = ("deg", "tilt_arcsec") if rotary else ("mm", "offset_um")
            raise CompgenError(f"joint {joint}'s table trims {axis} by up to {worst:g} {unit}: beyond the "
                               f"machine file's [limits] ({key})",
                               where=where, hint="is this the configuration of the measured machine? If it "
                                                 "is, raise [limits] in the machine file")
        unit = "deg" if rotary else "mm"

        def table(v, nominal=nominal, joint=joint, axis=axis, unit=unit):
            return CompTable(f"joint {joint}", "as loaded", axis, axis, float(nominal[0]), float(nominal[-1]),
                             tuple(float(x) for x in v), False, unit, tuple(float(x) for x in nominal))
        out[axis] = (table(fwd), table(rev))
    return out


def _joint_axis(machine: Machine, joint: int, where: str) -> str:
    coordinates = trt_module(machine)[0][:5].upper()
    if not 0 <= joint < len(coordinates):
        raise CompgenError(f"joint {joint} has a COMP_FILE, and the trt module has joints 0-4", where=where)
    return coordinates[joint]


def read_hal(text: str, module: str, where: str) -> tuple[dict[str, float], dict[str, str]]:
    """A HAL file's values of the module's pins (``setp``, ``PIN = VALUE``, or ``sets`` on
    the signal a pin is netted to) and the signal each netted pin is on, as halcmd runs it.
    A pin or signal set twice in one file is refused (HAL keeps the last: which was meant?)."""
    values, signal, _ = held_pins(configuration(text, where), module)
    return values, signal


def held_pins(cfg: Configuration, module: str
              ) -> tuple[dict[str, float], dict[str, str], dict[str, Setting]]:
    """The module's pins that hold a value in ``cfg``: values, the signal of each netted
    pin, and the setting (value as written, place) of each."""
    values, signal, setting = {}, {}, {}
    names = {p[len(module) + 1:] for p in (*cfg.pins, *cfg.net) if p.startswith(f"{module}.")}
    for n in names:
        pin = f"{module}.{n}"
        if pin in cfg.net:
            signal[n] = cfg.net[pin]
        s = cfg.value(pin)
        if s is not None:
            values[n], setting[n] = number(s.text, f"{pin}", str(s.place)), s
    return values, signal, setting


def pins(machine: Machine, p: Plan, current: Configuration | None, where: str
         ) -> tuple[str, list[tuple[str, str, str, str]], list[str], dict[str, Setting]]:
    """The HAL assignments of the trt pins: (``setp`` or ``sets``, pin or signal, new value,
    old value), each pin the way the current configuration sets it (a netted pin through its
    signal); the current values or the machine file's nominal, plus the corrections; what
    the pins cannot express; and where the configuration sets each pin."""
    module, names, nominal = module_pins(machine)
    held, signal, line_of = nominal, {}, {}
    if current is not None:
        held, signal, line_of = held_pins(current, module)
        for n in names:
            if n not in held:
                why = (f"is netted to {signal[n]}, which another component drives" if n in signal
                       else "is set neither by setp nor through a signal")
                raise CompgenError(f"in --current, {module}.{n} {why}", where=where,
                                   hint=f"give the HAL file that sets {', '.join(names)}")
            if not abs(held[n] - nominal[n]) * 1e3 <= machine.limits.offset_um:
                raise CompgenError(f"{module}.{n} = {held[n]:g} mm, {held[n] - nominal[n]:+.4f} mm from the "
                                   f"machine file's {nominal[n]:g}: beyond its [limits] offset_um "
                                   f"{machine.limits.offset_um:g} µm", where=str(line_of[n].place),
                                   hint="is this the configuration of the measured machine? If it is, "
                                        "correct the machine file's offsets or raise [limits]")
    if head_module(machine) is not None:
        along, other = head_correction(machine, p)
        new = {"pivot-length": held["pivot-length"] + along}
    else:
        _, tilt, c = trt_module(machine)
        delta_r = p.lines[c.name].offset
        delta_d = p.lines[tilt.name].offset - delta_r
        new = {n: held[n] + (delta_r if n.endswith("rot-point") else delta_d)["xyz".index(n[0])]
               for n in names}
        in_joints = {t.effect for t in joint_tables(machine, p)}
        other = [*_tilts(p), *p.squareness, *(e for e in p.tables if e not in in_joints), *p.not_compensable]
    was = {n: line_of[n].text if current is not None else fmt_plain(held[n], 6) for n in names}
    rows = [("sets", signal[n], fmt_plain(new[n], 6), was[n]) if n in signal else
            ("setp", f"{module}.{n}", fmt_plain(new[n], 6), was[n]) for n in names]
    return module, rows, other, {n: line_of[n] for n in names if n in line_of}


def read_lines(text: str, machine: Machine, current: str | None,
               lines: dict[str, AxisLine]) -> dict[str, AxisLine]:
    """The axis lines a trt edit sets, relative to ``current`` (default: nominal): ``text``
    is a configuration to start with (read from its INI), or a HAL file loaded after
    ``current``'s files, whose values reach the pins through their nets."""
    module, _, nominal = module_pins(machine)
    cfg = configuration(current, "current")
    before = held_pins(cfg, module)[0] if cfg is not None else nominal
    if is_bundle(text):
        now = held_pins(evaluate(text), module)[0]
    else:
        now = {**before, **held_pins(then(cfg, text, "edit") if cfg else hal_file(text, "edit"), module)[0]}
    if head_module(machine) is not None:
        return head_lines(machine, now["pivot-length"] - before["pivot-length"])
    _, tilt, c = trt_module(machine)
    r = np.array([now[f"{a}-rot-point"] - before[f"{a}-rot-point"] for a in "xyz"])
    d = np.array([now.get(f"{a}-offset", 0.0) - before.get(f"{a}-offset", 0.0) for a in "xyz"])
    zero = np.zeros(3)
    return {**lines, c.name: AxisLine(c.name, c.direction, lines[c.name].pivot, r, zero),
            tilt.name: AxisLine(tilt.name, tilt.direction, lines[tilt.name].pivot, r + d, zero)}


def joint_number(machine: Machine, axis: str) -> int:
    """The joint of ``axis`` in the trt module's default coordinates (XYZAC, XYZBC)."""
    return trt_module(machine)[0][:5].upper().index(axis)


def joint_tables(machine: Machine, p: Plan) -> list[CompTable]:
    """The tables LinuxCNC's joint compensation holds: an axis's error along itself, as the
    joint's trim. A full-turn axis's turn repeats over ±``TURNS_DEG`` within its travel
    (LinuxCNC does not wrap a joint's table)."""
    out = []
    if head_module(machine) is not None:
        return out                     # its joints' tables: not written for a head yet
    for t in comp_tables(machine, p):
        if t.input != t.output:
            continue                   # a cross table: no joint's own error
        out.append(unrolled(t, machine.axis(t.input).travel, TURNS_DEG) if t.modulo else t)
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
    rows = _triplets(text, where)
    axis = note[2]
    if joint_number(machine, axis) != int(note[1]):
        raise CompgenError(f"the table says joint {note[1]} = {axis}; the trt module's joint of {axis} is "
                           f"{joint_number(machine, axis)}", where=where)
    grid, trims = rows[:, 0], (rows[:, 1] + rows[:, 2]) / 2
    # beyond the first and last line LinuxCNC holds the end trims: so does np.interp
    return CompTable(f"joint {note[1]}", "", axis, axis, float(grid[0]), float(grid[-1]),
                     tuple(float(v) for v in trims), False, note[3], tuple(float(x) for x in grid))


POSITION = {"5420": "X", "5421": "Y", "5422": "Z", "5423": "A", "5424": "B", "5425": "C"}
# rs274ngc reads a line into LINELEN (255) characters with its line end and the string's end:
# a line of 253 characters or more is "Command too long" (rs274, tried: 252 runs)
LINE_MAX = 252
HAL_NAME = re.compile(r"[A-Za-z0-9._+-]+")      # a file name every reader of a configuration carries

# LinuxCNC applies G92 (and G52, which shares its parameters) and the active G5x offset to a
# program's positions before its kinematics: they do not turn with the table, so under TCP
# a G54 touched off on the table centre moves every tilted pose (224 mm at K4's worst), and
# under identity kinematics it moves every position. compgen's positions are the kinematics'
# own coordinates: the programs select G54 and stop, naming what is set, unless G92's and
# G54's offsets (and its XY rotation) are zero on the axes the program moves or the
# kinematics read (W: the head modules lengthen the pivot by it). An abort's text expands
# #n as a DEBUG does (rs274, tried); it holds no ";", which compgen's reader takes for a
# comment. Each line stays within LINE_MAX.
OFFSET_WORDS = {"G92": (5211, "XYZABCW"), "G54": (5221, "XYZABCWR")}
PARAM_OF = dict(zip("XYZABCUVWR", range(10), strict=True))


def _guard(label: str, params: list[tuple[str, int]], then: str) -> list[str]:
    cond = " OR ".join(f"[ABS[#{n}] GT 0.0001]" for _, n in params)
    said = " ".join(f"{w}#{n}" for w, n in params)
    return [f"o{label} if [{cond}]", f"(abort, {then.format(said=said)})", f"o{label} endif"]


def offsets_guard() -> list[str]:
    """The blocks that stop a LinuxCNC program, before any motion, unless the work offsets
    it runs under are zero (compgen's reader takes exactly these)."""
    (g92, w92), (g54, w54) = OFFSET_WORDS["G92"], OFFSET_WORDS["G54"]
    return ["G54 ; LinuxCNC applies G54 and G92 before its kinematics: both must be zero",
            *_guard("102", [(w, g92 + PARAM_OF[w]) for w in w92],
                    "G92 offsets are set: {said}. G92.1 clears them"),
            *_guard("103", [(w, g54 + PARAM_OF[w]) for w in w54],
                    "G54 holds {said}. compgen's positions need it zero: G10 L2 P1 with each of those 0")]


def head_guard(module: str) -> list[str]:
    """A head module's own state, read after the length is off and motion has settled: W
    (both modules compute with pivot-length + W) and, for 5axiskins, the switchable type
    that runs it (0, as LinuxCNC's bridgemill sample's M428 sets it)."""
    lines = _guard("104", [("W", 5428)], f"W stands at {{said}} mm. {module} lengthens the pivot by W: "
                                         "bring W to 0 first")
    if module == "5axiskins":
        lines += ["o105 if [#<_hal[motion.switchkins-type]> NE 0]",
                  "(abort, motion.switchkins-type is #<_hal[motion.switchkins-type]>. 5axiskins runs at 0: "
                  "M428 in LinuxCNC's bridgemill sample)", "o105 endif"]
    return lines


HEAD_PROGRAM = re.compile(r"^; LinuxCNC: (\S+kins) \(", re.MULTILINE)    # a program written for a head
PIN_GUARD = re.compile(r"o101 if \[ABS\[#<_hal\[(\S+kins)\.pivot-length\]> - (\S+)\] GT (\S+)\]")


def _blocks_of(lines: list[str]) -> list[str]:
    """Lines as the reader compares them: the comment after ";" off, white space trimmed."""
    return [ln.split(";", 1)[0].strip() for ln in lines]


# compgen's state guards as the reader compares them: kind, module, their blocks
STATE_GUARDS = (("offsets", "", _blocks_of(offsets_guard())),
                *(("head state", m.module, _blocks_of(head_guard(m.module))) for m in HEAD_MODULES))
GUARD_LINES = max(len(blocks) for _, _, blocks in STATE_GUARDS)


def _state_guard(lines: list[str], k: int) -> tuple[str, str, int] | None:
    """Whether line ``k`` starts one of compgen's state guards (the work offsets, a head
    module's W and type): its kind, module and last line; a line that starts one but does
    not go on as compgen writes it is refused (a guard edited is no guard)."""
    got = _blocks_of(lines[k - 1:k - 1 + GUARD_LINES])
    starts = False
    for kind, module, want in STATE_GUARDS:
        if got[:len(want)] == want:
            return kind, module, k + len(want) - 1
        starts |= got[0] == want[0]
    if starts or re.match(r"o10[2-5] ", got[0]):
        raise CompgenError(f"line {k}: {lines[k - 1].strip()!r} is not compgen's guard (of the work offsets "
                           "or a head module's state: each condition, its abort and endif)",
                           hint="give the program compgen wrote")
    return None


def program_blocks(text: str, tcp: bool, head: str | None = None) -> list[Block]:
    """A G-code program as LinuxCNC executes it (the blocks compgen writes); ``tcp``: the
    trt kinematics are active (the configuration's choice: the program cannot say it).
    Under a ``head`` module (maxkins, 5axiskins) the nest's length is the kinematics'
    pivot-length: G49 leaves it there, a G43 length would act along world Z whatever B is,
    and the program's guard stops unless the pin holds the length (a ``pin`` block)."""
    out, modal, feed = [Block(0, "kinematics", "tcp", on=tcp)], None, None
    lines = text.splitlines()
    guard_at, read_to = None, 0
    for k, raw in enumerate(lines, start=1):
        if len(raw) > LINE_MAX:
            raise CompgenError(f"line {k}: {len(raw)} characters; LinuxCNC reads {LINE_MAX} of a line and "
                               "stops the program there (\"Command too long\")",
                               hint="give the program compgen wrote")
        b = raw.split(";", 1)[0].strip()
        if guard_at is not None and k in (guard_at + 1, guard_at + 2) or k <= read_to:
            continue                        # a guard's abort and endif, read with it
        if not b:
            continue
        if (state := _state_guard(lines, k)) is not None:
            kind, module, read_to = state
            out.append(Block(k, raw, kind, name=module))
        elif b == "G21 G90 G94 G17":          # G21: millimetres
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
        elif (d := PIN_GUARD.fullmatch(b)) is not None:
            # the pin guard: stop unless the head module's pivot-length holds the program's
            after = [ln.split(";", 1)[0].strip() for ln in lines[k:k + 2]]
            if (len(after) < 2 or not re.fullmatch(r"\(abort,[^)]*\)", after[0]) or after[1] != "o101 endif"
                    or not NUMBER.fullmatch(d[2]) or not NUMBER.fullmatch(d[3])):
                raise CompgenError(f"line {k}: {raw.strip()!r} is not compgen's pin guard (the condition, "
                                   "then an (abort, ...) line and o101 endif)",
                                   hint="give the program compgen wrote")
            guard_at = k
            out.append(Block(k, raw, "pin", target={f"{d[1]}.pivot-length": (float(d[2]), float(d[3]))}))
        elif b == "M66 E0 L0":               # waits for motion: the guard reads the pin as it is
            out.append(Block(k, raw, "sync"))
        elif re.fullmatch(r"T\d+ M6", b):
            out.append(Block(k, raw, "tool"))
        elif head and re.fullmatch(r"G43 H\d+", b):
            raise CompgenError(f"line {k}: {raw.strip()!r}: under {head} a G43 length acts along world Z "
                               "whatever B is", hint=f"the nest's length belongs in {head}.pivot-length; "
                                                    "give the program compgen wrote (G49)")
        elif re.fullmatch(r"G43 H\d+", b) or b == "G49":
            out.append(Block(k, raw, "length", on=b != "G49" or head is not None))
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
    name_max = 200            # LinuxCNC runs a program by its path: the file system's name, with room
    comment = "#"
    tcp_words = "trt kinematics"
    backup = "a copy of the configuration's folder (its INI, HAL files and joint tables)"
    pose_line = re.compile(r"^G1 X(\S+) Y(\S+) Z(\S+) ((?:[A-C]\S+ )+)F\S+ ; pose (\d+)")
    tcpm_on = re.compile(r"^; mode TCPM", re.MULTILINE)
    tcp_switchable = False
    section = "linuxcnc"
    load_note = ("start LinuxCNC with KIN.ini, the configuration compgen wrote from the INI given as "
                 "--current (the values changed where the configuration sets them)")
    holds_tilts = False           # trt kinematics: pivot positions only
    squareness_as = ""

    def tables(self, machine: Machine, p: Plan) -> list[CompTable]:
        return joint_tables(machine, p)

    def main_suffix(self, current: str | None) -> str:
        return ".ini" if is_bundle(current) else ".hal"

    def read_section(self, get, machine: Machine) -> dict:
        """[linuxcnc]: ``conventional_directions``, the trt module's pin of that name. With it
        true, its kinematics turn A (or B) and C the other way (``trtfuncs.c``: every term
        with a single sine of an angle is multiplied by ``con`` = +1, else −1; the pin exists
        from LinuxCNC 2.10, commit bfb687eaa6, and is false by default)."""
        get.only({"conventional_directions", "version"})
        conventional = get.flag("conventional_directions", "the trt module's conventional-directions pin")
        version = None
        if "version" in get.doc:
            text = get.doc["version"]
            m = re.fullmatch(r"(\d+)\.(\d+)(?:\.\d+)?", text) if isinstance(text, str) else None
            if m is None:
                raise CompgenError(f"must be LinuxCNC's version as text, e.g. \"2.9\", got {text!r}",
                                   where=get.at("version"),
                                   hint="linuxcnc_info, or the splash screen, shows it")
            version = (int(m[1]), int(m[2]))
        if conventional and version is not None and version < PIN_SINCE:
            raise CompgenError(f"LinuxCNC {get.doc['version']} has no conventional-directions pin (it came "
                               "with 2.10): its kinematics modules, trt or head, turn the axes the "
                               "unconventional way",
                               where=get.at("conventional_directions"), hint="set it false")
        try:
            module = trt_module(machine)[0]
        except CompgenError:
            module = ""
        if module == "xyzbc-trt-kins" and not conventional:
            if version is None:
                raise CompgenError("which LinuxCNC runs xyzbc-trt-kins with conventional-directions 0 "
                                   "decides whether its inverse kinematics inverts its forward kinematics",
                                   where=get.at("version"),
                                   hint='add version = "2.9" (or the one the machine runs)')
            if version >= PIN_SINCE:
                raise CompgenError(XYZBC_PIN0, where=get.at("conventional_directions"),
                                   hint="set the module's conventional-directions pin to 1 in the "
                                        "configuration and conventional_directions = true here")
        return {"conventional_directions": conventional, "version": version}

    def angle_sense(self, machine: Machine) -> dict[str, int]:
        if (head := head_module(machine)) is not None:     # as the module turns them
            return dict(head[0].sense)
        flip = -1 if (machine.linuxcnc or {}).get("conventional_directions") else 1
        return {a.name: flip for a in machine.rotary_axes}

    def programs_for_head(self, machine: Machine) -> bool:
        return head_module(machine) is not None

    def program_context(self, machine: Machine) -> dict:
        head = head_module(machine)
        mirrored = head and [a for a, v in head[0].sense if v == -1]
        return {"offsets_guard": offsets_guard(),
                "head": head and {"module": head[0].module, "what": head[0].what, "active": head[0].active,
                                  "pivot": f"{head[1]:.4f}", "within": f"{pin_tolerance(machine):.4f}",
                                  "mirrored": " and ".join(mirrored)
                                  + (" are" if len(mirrored) > 1 else " is"),
                                  "them": "them" if len(mirrored) > 1 else "it",
                                  "guard": head_guard(head[0].module), "notes": head[0].notes}}

    def check(self, machine: Machine, blocks: list[Block], probe=None):
        """The motion check, where a head module's program checks the module's pin: compgen
        models the machine with the machine file's pivot, so the guard must stop the
        program unless the pin holds that (else the check would be of another machine)."""
        head = head_module(machine)
        pins = [b for b in blocks if b.kind == "pin"]
        want = head and {f"{head[0].module}.pivot-length": (float(f"{head[1]:.4f}"), pin_tolerance(machine))}
        if head and (not pins or any(b.target != want for b in pins)):
            got = "; ".join(f"line {b.line}: {b.text.strip()}" for b in pins) or "no pin guard"
            raise CompgenError(f"a program for this machine must stop unless {head[0].module}.pivot-length "
                               f"holds {head[1]:.4f} mm, the machine file's pivot to the nest, to "
                               f"{pin_tolerance(machine):.4f} mm ({got})",
                               hint=f"write it again with {me()} measure-program for this machine file")
        if pins and not head:
            raise CompgenError(f"line {pins[0].line}: the program was written for a head on "
                               f"{next(iter(pins[0].target)).split('.')[0]}, which this machine file is not",
                               hint="check it against the machine file it was written for")
        require_guard(blocks, "LinuxCNC", "stop unless G54's and G92's offsets are zero (LinuxCNC applies "
                      "them before its kinematics: an offset left set moves every pose)")
        if head:
            switch = " and motion.switchkins-type is 0" if head[0].module == "5axiskins" else ""
            require_guard(blocks, "LinuxCNC", f"stop unless W is at 0 ({head[0].module} lengthens the pivot "
                          f"by W){switch}",
                          before=("move",), kind="head state", name=head[0].module)
        return super().check(machine, blocks, probe)

    def blocks(self, text: str, mode: str | None = None) -> list[Block]:
        written = ("tcpm" if self.tcpm_on.search(text) else
                   "axes" if re.search(r"(?m)^; mode AXES", text) else None)
        # the kinematics are the configuration's: the program's header (compgen's) says which it
        # was written for, and that is what it is checked under; --mode says it where the header
        # does not, or must agree with it
        mode = mode or written
        if mode is None:
            raise CompgenError("a LinuxCNC program's kinematics are the configuration's, and this program's "
                               "header does not say which it was written for",
                               hint="give --mode tcpm (its kinematics module active: trt, maxkins or "
                                    "5axiskins) or --mode axes (identity kinematics)")
        written = written or mode
        if mode != written:
            raise CompgenError(f"the program was written for mode {written.upper()} (its header) and is to "
                               f"run under {mode.upper()}: its positions mean other things there",
                               hint=f"write it again for mode {mode.upper()}: measure-program with --mode "
                                    f"{mode}, and the machine file and path (or --poses) it was written with")
        head = HEAD_PROGRAM.search(text)
        return program_blocks(text, mode == "tcpm", head and head[1])

    def edits_head(self, machine: Machine) -> bool:
        return head_module(machine) is not None

    def label(self, machine: Machine) -> str:
        head = head_module(machine)
        return self.words if head is None else f"LinuxCNC ({head[0].module})"

    def tcp_label(self, machine: Machine) -> str:
        head = head_module(machine)
        return self.tcp_words if head is None else f"{head[0].module} kinematics"

    def corrects(self, machine: Machine, e) -> bool:
        if head_module(machine) is None:
            return super().corrects(machine, e)
        # the one pin: a head's line offset along the tool axis at the pivot (ZOB)
        return e.carrier in {a.name for a in machine.heads} and e.direction == "z"

    def holds(self, machine: Machine, p: Plan) -> Held:
        if head_module(machine) is None:
            return super().holds(machine, p)
        return Held(head_lines(machine, head_correction(machine, p)[0]), {}, ())

    def not_held(self, machine: Machine, p: Plan) -> list[str]:
        if head_module(machine) is None:
            return super().not_held(machine, p)
        return head_correction(machine, p)[1]

    def edit(self, machine: Machine, p: Plan, current: str | None, where: str,
             ctx: EditContext) -> EditFiles:
        if not HAL_NAME.fullmatch(ctx.stem):
            # the name goes into HALFILE values, source lines and the INI: halcmd takes "#" for a
            # comment, "$" and "[" for references; the start script splits a HALFILE at a space
            raise CompgenError(f"-o {ctx.stem!r}: LinuxCNC's start script and halcmd cannot carry this "
                               "name (a space, '#', '$', '[' or another character they read)",
                               hint="give -o a name of letters, digits, '.', '_', '+' and '-', e.g. KIN.ini")
        state = configuration(current, where)       # the configuration, evaluated once
        module, rows, other, settings = pins(machine, p, state, where)
        cfg = state if is_bundle(current) else None
        loaded = _joint_tables(machine, cfg) if cfg is not None else {}
        comps = comp_files(machine, p, ctx, loaded)
        ini_lines = [ini for ini, _ in comps.values()]
        sign = [f"sign check {ctx.name}_SIGN{self.program_ext}, expected change of the reading:", *ctx.expect]
        notes = [f"{cmd} {target} {v}  (was {w})" for cmd, target, v, w in rows]
        head = head_module(machine)
        what = head and head[0].what
        if other:
            notes.append(f"not expressible in LinuxCNC's {module}" + (" (its one pin, pivot-length)"
                                                                      if head else " and joint tables")
                         + ": " + ", ".join(other))
        tool = f"{module}.tool-offset"
        if head is None and state is not None and tool not in state.net:
            notes.append(f"{tool} is not netted: net it to motion.tooloffset.z, or the table turns about the "
                         "spindle nose instead of the nest (G43 lengths)")
        if cfg is not None:
            return self._configuration_edit(machine, cfg, ctx, rows, settings, comps, loaded,
                                            [*ctx.header, *ctx.lines, *sign], notes)
        text = render("linuxcnc/kinematics.hal.j2", header=ctx.header, module=module, head=what,
                      lines=ctx.lines, rows=rows, other=other, ini=ini_lines, sign=sign, restore=False)
        notes.append(f"load it: put these values where the configuration sets the pins. A HALFILE added "
                     "after the others is overwritten by the INI's HALCMD lines and POSTGUI_HALFILE where "
                     f"they set a pin (as LinuxCNC's own trt samples do): give the INI as --current and "
                     f"{ctx.stem}.ini is the configuration to start with")
        if ini_lines:
            notes += ["joint compensation tables: in the INI, set (replacing any COMP_FILE or BACKLASH of "
                      "these joints)", *(f"  {line}" for line in ini_lines),
                      "--current is not the INI, so the joints' loaded tables are unknown: these hold this "
                      "round's correction alone (give the INI to add to them)"]
        restore_ini = [f"[JOINT_{joint_number(machine, a)}] no COMP_FILE (remove the line the edit set)"
                       for a in sorted({t.input for t in joint_tables(machine, p)})]
        restore = render("linuxcnc/kinematics.hal.j2", module=module, head=what, lines=[], other=[],
                         ini=restore_ini,
                         rows=[(cmd, target, w, w) for cmd, target, _, w in rows], restore=True, sign=[],
                         header=[f"compgen {ctx.version}: restores the {module if head else 'trt'} pins as "
                                 "they were read", *ctx.header[1:3], f"load it in place of {ctx.stem}.hal"])
        return EditFiles({".hal": text, "_RESTORE.hal": restore,
                          **{k: body for k, (_, body) in comps.items()}}, tuple(notes))

    def _configuration_edit(self, machine: Machine, cfg: Configuration, ctx: EditContext,
                            rows, settings: dict[str, Setting], comps, loaded, header: list[str],
                            notes: list[str]) -> EditFiles:
        """The configuration to start with: the INI (and each file that sets a changed pin)
        written anew beside it, the joints' tables named in it; its restore, the INI as it was."""
        if ctx.folder and Path(ctx.folder).resolve() != cfg.folder.resolve():
            raise CompgenError("the configuration to start with names its files as the INI does, relative to "
                               f"{cfg.folder}: write it there", where=ctx.folder,
                               hint=f"give -o {cfg.folder / (ctx.stem + '.ini')}")
        module = module_pins(machine)[0]
        values = {f"{module}.{n}": v for (_, _, v, w), n in zip(rows, settings, strict=True)
                  if float(v) != float(w)}
        joints = {joint_number(machine, suffix.split(".")[1]): f"{ctx.stem}{suffix}" for suffix in comps}
        files = configuration_files(cfg, values, joints, ctx.stem, header)
        for suffix, (_, body) in comps.items():
            files[suffix] = body
        start = f"{ctx.stem}.ini"
        files["_RESTORE.ini"] = "\n".join([f"# compgen {ctx.version}: the configuration as it was before "
                                           f"{start}; start LinuxCNC with this file to undo the edit",
                                           cfg.texts[cfg.ini_path].rstrip("\n")]) + "\n"
        changed = sorted(f"{s.place} ({s.text} -> {values[pin]})" for n, s in settings.items()
                         if (pin := f"{module}.{n}") in values)
        notes.append(f"start LinuxCNC with {cfg.folder / start}: the INI's own lines, the values changed "
                     "where the configuration sets them (" + "; ".join(changed) + ")"
                     + ("; " + ", ".join(f"{ctx.stem}{k}" for k in files if k not in (".ini", "_RESTORE.ini")
                                          and not k.endswith(".comp")) + " written anew beside it"
                        if len([k for k in files if not k.endswith(".comp")]) > 2 else ""))
        if comps:
            notes.append("joint compensation tables " + ", ".join(f"{ctx.stem}{k}" for k in comps) + ": "
                         + (f"the tables the INI loads plus this round's ({', '.join(sorted(loaded))} held "
                            "one)" if loaded else "no joint had a table in the INI: they hold this round's "
                                                  "correction"))
        notes.append(f"to undo: start LinuxCNC with {ctx.stem}_RESTORE.ini (the INI as it was); the next "
                     f"round's --current is {start}, so the next edit adds to this one")
        return EditFiles(files, tuple(notes))

    def loaded_tables(self, machine: Machine, state: str, where: str) -> list[CompTable]:
        return [replace(fwd, values=tuple((np.add(fwd.values, rev.values) / 2).tolist()))
                for fwd, rev in loaded_joint_tables(machine, state).values()]

    def since(self, machine: Machine, measured: str, current: str, where: str) -> Held:
        return Held(read_lines(current, machine, measured, nominal_lines(machine)), {})

    def beyond_nominal(self, machine: Machine, current: str, where: str) -> Held:
        return Held(read_lines(current, machine, None, nominal_lines(machine)), {})

    def state(self, path: str, text: str) -> str | None:
        # an INI (inivar finds a section by the start of its line; its [HAL] may come from an
        # #INCLUDE): LinuxCNC's whole configuration. No HAL file (nor another control's
        # table, whose last line is [END]) has a [HAL] or an #INCLUDE line
        ini = re.search(r"(?m)^[ \t]*\[HAL\]|^#INCLUDE[ \t]", text)
        return bundle(path, text) if ini else None

    def reads(self, text: str) -> bool:
        return (is_bundle(text) or SETP.search(text) is not None or COMP_NOTE.search(text) is not None
                or (SETS.search(text) is not None and "kinematics edit" in text))

    def check_tool(self, tool: str, key: str, source: str) -> None:
        if not re.fullmatch(r"\d{1,5}", tool):
            raise CompgenError(f"LinuxCNC calls tools by number; {key} is {tool!r}", where=f"{source}: {key}",
                               hint='e.g. tool = "99"')

    def check_setup(self, machine: Machine) -> None:
        if machine.linuxcnc is None:
            raise CompgenError("whether the trt kinematics turn the rotary axes the conventional way is not "
                               "in the machine file: the same program turns them the other way if they do",
                               where=f"{machine.source}: [linuxcnc] conventional_directions",
                               hint="set conventional_directions = false (before LinuxCNC 2.10, or the "
                                    "module's conventional-directions pin at its default 0) or true (pin 1)")
        if (head := head_module(machine)) is not None and machine.linuxcnc.get("conventional_directions"):
            raise CompgenError(f"{head[0].module} was run without a conventional-directions pin (Debian's "
                               "2.9 has none); a newer one turns B the other way at 1",
                               where=f"{machine.source}: [linuxcnc] conventional_directions",
                               hint="set it false, with the pin at its default 0")
        self.check_tool(machine.program.tool, "[program] tool", machine.source)

    def read(self, machine: Machine, text: str, current: str | None, held: Held, where: str) -> Held:
        if is_bundle(text):            # a configuration to start with: its pins and its joints' tables
            tables = self.loaded_tables(machine, text, where)
            return Held(read_lines(text, machine, current, held.lines), held.squareness,
                        (*(t for t in held.tables if t.effect not in {tb.effect for tb in tables}), *tables))
        if COMP_NOTE.search(text):     # a joint's table replaces the one it held
            table = read_comp(text, machine, where)
            return Held(held.lines, held.squareness,
                        (*(t for t in held.tables if t.effect != table.effect), table))
        return Held(read_lines(text, machine, current, held.lines), held.squareness, held.tables)
