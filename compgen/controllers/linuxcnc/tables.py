"""LinuxCNC's joint compensation tables (``[JOINT_n] COMP_FILE``): read as usrmotLoadComp
reads them, and written from a round's corrections."""

from __future__ import annotations

import re

import numpy as np

from ...errors import CompgenError
from ...model.machine import Machine
from .. import fmt_plain
from ..base import EditContext
from ..correction import (
    CompTable,
    Plan,
    comp_tables,
    compose_tables,
    unrolled,
)
from .config import Configuration, evaluate, is_bundle
from .heads import head_module, trt_module

COMP_ENTRIES = 256           # EMCMOT_COMP_SIZE: the lines a joint's table may hold
TURNS_DEG = 1260.0           # a full-turn axis's table repeats its turn over ±this (≤ 256 lines)
COMP_NOTE = re.compile(r"^# compgen joint compensation for LinuxCNC: joint (\d+) = ([A-Z]) \((mm|deg)\)",
                       re.MULTILINE)



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


