"""HEIDENHAIN iTNC 530 and TNC 640: Klartext programs, kinematics description-table edits
(iTNC 530) and change lists (TNC 640), and their readers.

HEIDENHAIN's scheme for position errors: error rows before ``MachAxis``, their inverse after
it (iTNC 530 HSCI Technical Manual p.684, ``B0X``/``C0X`` for squareness); the ``DOC``
column names each row by its ISO symbol, so a later edit finds and increases it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from .. import me
from ..errors import CompgenError
from ..model.effects import ROT_OF, ROTATIONS, TRANSLATIONS
from ..model.lines import AxisLine
from ..model.machine import Machine
from ..motion.blocks import Block, dwell, unknown, words
from ..transforms import rot_axis
from ..units import number
from . import fmt_signed, render
from .base import Controller, EditContext, EditFiles
from .correction import Held, Plan, nominal_lines, pivot_of
from .plc import PLC_TARGET
from .state_guards import heidenhain_guard, heidenhain_state, require_guard
from .tab import MM_PER, TabTable

MM_DECIMALS = 5          # 0.01 µm
DEG_DECIMALS = 7         # 0.0004″
# a table's rounding may lose up to the correction's uncertainty, and never less than this:
# half a typical R-test's noise (0.5 µm), which no re-measurement could tell; 0.25″ moves a
# ball 200 mm from the axis by 0.24 µm. Both lie far above compgen's own rounding (half of
# 10⁻⁵ mm, 10⁻⁶ inch or 10⁻⁷ °), so that never decides.
LOSS_FLOOR_MM, LOSS_FLOOR_DEG = 0.25e-3, 0.25 / 3600.0
# a Trans row naming its ISO symbol, in a table (``NR KEY AXIS COORD DOC``) or a change list
ISO = re.compile(r"-?[XYZABC]0[A-Z]")
ROW = re.compile(r"^\s*(?:\d+\s+)?(?:Trans\s+([XYZABC])\s+(\S+)\s+(-?[XYZABC]0[A-Z])\b"
                 r"|(-?[XYZABC]0[A-Z])\s+Trans\s+([XYZABC])\s+(\S+))", re.MULTILINE)


# the entries a description table takes: reported by a user, in no manual read (U19)
DESCRIPTION_ROWS = 50


@dataclass(frozen=True)
class Row:
    """One ``Trans`` row: the ISO symbol of what it holds (``iso``, ``YOA``), written in the
    table's DOC column as the KinematicsOpt rows are (``doc``: ``Y0A``, ``-Y0A`` for the
    inverse after the axis)."""

    iso: str
    axis: str          # X Y Z (mm) or A B C (deg)
    coord: float
    inverse: bool = False

    @property
    def doc(self) -> str:
        return f"{'-' if self.inverse else ''}{self.iso[0]}0{self.iso[2:]}"


def rows_of(machine: Machine, p: Plan) -> dict[str, tuple[list[Row], list[Row]]]:
    """Rows before and after each ``MachAxis``: error rows, then the inverse in reverse."""
    out = {}
    for name, line in p.lines.items():
        d = line.nominal
        before = [Row(f"{t.upper()}O{name}", t.upper(), line.offset["xyz".index(t)])
                  for t in TRANSLATIONS if t != d]
        before += [Row(f"{r.upper()}O{name}", r.upper(), np.degrees(line.tilt[ROTATIONS.index(r)]))
                   for r in ROTATIONS if r != ROT_OF[d]]
        out[name] = (before, [Row(r.iso, r.axis, -r.coord, inverse=True) for r in reversed(before)])
    for name, value in p.squareness.items():       # e.g. COX: Trans C around MachAxis X
        axis, r = name[2], name[0]
        before = [Row(f"{r}O{axis}", r, np.degrees(value))]
        prior = out.get(axis, ([], []))
        out[axis] = (prior[0] + before, [Row(f"{r}O{axis}", r, -np.degrees(value), inverse=True)] + prior[1])
    return out


def _decimals(axis: str) -> int:
    return MM_DECIMALS if axis in "XYZ" else DEG_DECIMALS


def edit_table(table: TabTable, rows: dict[str, tuple[list[Row], list[Row]]], where: str,
               marker: str = "", sigma: dict[str, float] | None = None) -> list[str]:
    """Add the corrections to the table in place: an existing row of the same ISO name (the
    DOC's first word) gets its COORD increased; a missing one is inserted next to its
    ``MachAxis``, the error rows just before it in order, the inverse rows just after it in
    order. Each row written carries ``marker`` after its name where the DOC column holds it
    (the table has no comments). A value the table's declared decimals round by more than
    the fit's uncertainty of it (``sigma``, mm or rad by ISO name; at least compgen's own
    rounding) is refused: the edit would not hold the correction. The changes, in the
    table's units."""
    sigma = sigma or {}

    def written(text: str, want: float, row: Row) -> str:
        lost = abs(table.mm(text, row.axis) - want)
        std = sigma.get(row.iso, 0.0)
        floor = LOSS_FLOOR_MM if row.axis in "XYZ" else LOSS_FLOOR_DEG
        allowed = max(floor, std if row.axis in "XYZ" else np.degrees(std)) * 1.001
        if lost > allowed:
            unit = "um" if row.axis in "XYZ" else "arcsec"
            scale = 1e3 if row.axis in "XYZ" else 3600.0
            raise CompgenError(f"the table's COORD decimals round {row.doc} to {text}: {lost * scale:.3g} "
                               f"{unit} of the correction lost, beyond its uncertainty {allowed * scale:.3g} "
                               f"{unit}",
                               where=where, hint="raise DEC of COORD in the table's description (the control "
                                                 "holds 5 decimals in mm), or enter the rows by hand from "
                                                 "the change list")
        return text
    if "DOC" not in table.columns:
        raise CompgenError("the current table has no DOC column to name the correction rows",
                           hint="add a DOC column (the enhanced kinematics description has one)")
    _check_pairs(table, where)
    diff = []
    start, end = table.slot("DOC")
    room = None if end is None else end - start - 1
    if marker and room is not None and room < len(f"-X0A {marker}"):
        diff.append(f"the DOC column ({room} characters) cannot carry the fit's marker {marker}: "
                    "compgen cannot tell later that this table holds this fit's correction")
        marker = ""

    def machaxis(axis):
        i = next((i for i, r in enumerate(table.rows)
                  if r.get("KEY") == "MachAxis" and r.get("AXIS") == axis), None)
        if i is None:
            raise CompgenError(f"the current table has no 'MachAxis {axis}' row",
                               hint="is this the table of the machine that was measured?")
        return i

    for axis, (before, after) in rows.items():
        for side, group in (("before", before), ("after", after)):
            for k, row in enumerate(group):
                unit = table.unit.lower() if row.axis in "XYZ" else "deg"
                doc = f"{row.doc} {marker}".strip()
                idx = next((i for i, r in enumerate(table.rows) if _name(r) == row.doc), None)
                if idx is not None:
                    old = table.rows[idx]["COORD"]
                    want = table.mm(old, row.axis) + row.coord
                    new = written(table.coord(want, row.axis, _decimals(row.axis)), want, row)
                    table.set(idx, {"COORD": new, "DOC": doc}, where)
                    diff.append(f"{row.doc:<6} Trans {row.axis}  {old} -> {new} {unit}")
                    continue
                at = machaxis(axis) if side == "before" else machaxis(axis) + 1 + k
                new = written(table.coord(row.coord, row.axis, _decimals(row.axis)), row.coord, row)
                table.insert(at, {"NR": str(at), "KEY": "Trans", "AXIS": row.axis, "COORD": new,
                                  "DOC": doc})
                diff.append(f"{row.doc:<6} Trans {row.axis}  (new row) -> {new} {unit}")
    return diff


def _check_pairs(table: TabTable, where: str) -> None:
    """An ISO-named row and its inverse come together and cancel (the error before its
    MachAxis, the inverse after it): adding a correction to one half of a broken pair would
    write an inconsistent table, so it is refused."""
    rows = {_name(r): r for r in table.rows if r.get("KEY") == "Trans" and ISO.fullmatch(_name(r))}
    for name, row in rows.items():
        pair = name[1:] if name.startswith("-") else f"-{name}"
        if pair not in rows:
            raise CompgenError(f"row {name} has no partner row {pair}: compgen's rows come in pairs "
                               "that cancel around their MachAxis", where=where,
                               hint=f"add the {pair} row, or rename the row if it is the OEM's own geometry")
        # both rounded to the table's decimals: they may differ by one unit of the last one
        unit = 10.0 ** -table.decimals.get("COORD", _decimals(row["AXIS"]))
        if abs(float(row["COORD"]) + float(rows[pair]["COORD"])) > 1.01 * unit:
            raise CompgenError(f"rows {name} ({row['COORD']}) and {pair} ({rows[pair]['COORD']}) do not "
                               "cancel", where=where, hint="correct the table by hand before a new edit")


def _name(row: dict) -> str:
    """A row's ISO name: the first word of its DOC (compgen's marker may follow)."""
    words = (row.get("DOC") or "").split()
    return words[0] if words else ""


def _resolution(table: TabTable) -> list[str]:
    """Say so where the table's declared decimals round the corrections coarser than compgen."""
    dec = table.decimals.get("COORD")
    if dec is None:
        return []
    out = []
    linear_um = 10.0 ** -dec * MM_PER[table.unit] * 1e3
    if linear_um > 10.0 ** -MM_DECIMALS * 1e3 * 1.001:
        out.append(f"COORD has {dec} decimals (table description): linear values rounded to "
                   f"{linear_um:.3g} um")
    if dec < DEG_DECIMALS:
        out.append(f"COORD has {dec} decimals: rotations rounded to {10.0 ** -dec * 3600:.3g} arcsec")
    return out


def check_pivots(table: TabTable, machine: Machine, where: str) -> str | None:
    """The table-side rotary axes must sit where the machine file puts them: the ``Trans``
    rows from ``MachBase`` to each ``MachAxis`` compose to its pivot (within [limits]
    offset_um; same sign convention as the rows compgen writes, U3). Rotation rows turn the
    frame the later rows act in (an edited table's tilt pairs, a 90° mounting rotation), so
    every axis is checked. Returns why the check could not be made, if so."""
    rotary = {a.name for a in machine.rotary_axes}
    frame, after_base, checked = np.eye(4), False, 0
    for r in table.rows:
        if r.get("KEY") == "MachBase":
            after_base = True
        elif after_base and r.get("KEY") == "Trans":
            frame = frame @ _trans(table, r)
        elif after_base and r.get("KEY") == "MachAxis" and r.get("AXIS") in rotary:
            at, want = frame[:3, 3], pivot_of(machine, r["AXIS"])
            checked += 1
            if np.abs(at - want).max() * 1e3 > machine.limits.offset_um:
                raise CompgenError(
                    f"the table puts the {r['AXIS']} axis at ({', '.join(f'{v:.4f}' for v in at)}) mm "
                    f"from MachBase, the machine file at ({', '.join(f'{v:.4f}' for v in want)}) mm",
                    where=where, hint="is this the table of the measured machine? If it is, correct the "
                                      "machine file's offsets")
    if not after_base:
        return "pivot check not made: the table has no MachBase row"
    _check_head_pivots(table, machine, where)
    return None if checked else "pivot check not made: no MachAxis row of a rotary axis follows MachBase"


def _check_head_pivots(table: TabTable, machine: Machine, where: str) -> None:
    """A head's axes must sit where the machine file puts them: the chain starts at the tool
    reference point (the gauge line), and its ``Trans`` rows up to each head's ``MachAxis``
    (before ``MachBase``) compose to that head's pivot above it (the head offsets, base
    outwards, summed: the manual's example p.670, ``Trans Z 250.051`` from the tool reference
    point to its B head; U18)."""
    pivots, at = {}, np.zeros(3)
    for a in machine.heads:
        at = at + np.asarray(a.offset, float)
        pivots[a.name] = at
    frame = np.eye(4)
    for r in table.rows:
        if r.get("KEY") == "MachBase":
            return
        if r.get("KEY") == "Trans":
            frame = frame @ _trans(table, r)
        elif r.get("KEY") == "MachAxis" and r.get("AXIS") in pivots:
            got, want = frame[:3, 3], pivots[r["AXIS"]]
            if np.abs(got - want).max() * 1e3 > machine.limits.offset_um:
                shown = [", ".join(f"{v:.4f}" for v in x) for x in (got, want)]
                raise CompgenError(f"the table puts the head's {r['AXIS']} axis at ({shown[0]}) mm from the "
                                   f"tool reference point, the machine file at ({shown[1]}) mm", where=where,
                                   hint="is this the table of the measured machine? If it is, correct the "
                                        "machine file's head offsets")


def _trans(table: TabTable, r: dict) -> np.ndarray:
    """The 4×4 step of a ``Trans`` row: along X, Y or Z by its COORD in mm (the table's unit
    converted), about A, B or C by it in degrees; any other axis, none."""
    step = np.eye(4)
    if r.get("AXIS") in ("X", "Y", "Z"):
        step["XYZ".index(r["AXIS"]), 3] = table.mm(r["COORD"], r["AXIS"])
    elif r.get("AXIS") in ("A", "B", "C"):
        step = rot_axis("xyz"["ABC".index(r["AXIS"])], np.radians(float(r["COORD"])))
    return step


def _iso_rows(text: str) -> list[tuple[str, str, float]]:
    """(DOC, AXIS, value in mm or deg) of the ISO-named Trans rows of a table (in its unit)
    or of compgen's change list (mm)."""
    if text.lstrip().startswith("BEGIN"):
        t = TabTable.parse(text, "table")
        return [(_name(r), r["AXIS"], t.mm(r["COORD"], r["AXIS"])) for r in t.rows
                if r.get("KEY") == "Trans" and ISO.fullmatch(_name(r))]
    return [((m[3], m[1], number(m[2], "change-list value", "change list")) if m[1] else
             (m[4], m[5], number(m[6], "change-list value", "change list"))) for m in ROW.finditer(text)]


def read_lines(text: str, machine: Machine, lines: dict[str, AxisLine]) -> dict[str, AxisLine]:
    """The rotary axis lines a description table (or compgen's change list) holds: the
    ISO-named rows before each ``MachAxis``, checked against their inverse rows after it."""
    rows = _iso_rows(text)
    out = dict(lines)
    for a in machine.rotary_axes:
        mine = {doc: (axis, v) for doc, axis, v in rows if doc.lstrip("-").endswith(a.name)}
        offset, tilt = np.zeros(3), np.zeros(3)
        for doc, (axis, v) in mine.items():
            if doc.startswith("-"):
                continue
            inverse_row = mine.get(f"-{doc}")
            if inverse_row is None or abs(inverse_row[1] + v) > 1e-9:
                raise CompgenError(f"row {doc} has no matching inverse row -{doc}",
                                   hint="error rows before MachAxis need their inverse after it")
            if axis in "XYZ":
                offset["XYZ".index(axis)] = v
            else:
                tilt["ABC".index(axis)] = np.radians(v)
        out[a.name] = AxisLine.of(a, lines[a.name].pivot, offset, tilt)
    return out


def read_squareness(text: str, machine: Machine) -> dict[str, float]:
    """Squareness rows around a linear ``MachAxis`` (``C0X`` → COX, rad)."""
    out = {}
    linear = {a.name for a in machine.axes if not a.rotary}
    for doc, axis, value in _iso_rows(text):
        if doc[0] != "-" and doc[2] in linear and axis in "ABC":
            out[f"{doc[0]}O{doc[2]}"] = np.radians(float(value))
    return out


def _row(r: Row) -> dict:
    unit = "mm" if r.axis in "XYZ" else "deg"
    shown = f"{r.coord * 1e3:+.2f} um" if unit == "mm" else f"{r.coord * 3600:+.2f} arcsec"
    return {"doc": r.doc, "axis": r.axis, "coord": fmt_signed(r.coord, _decimals(r.axis)), "unit": unit,
            "shown": shown}


def _comp_csv(tables) -> str:
    out = ["# compgen: values for the control's axis-error compensation tables (U8: the file layout of",
           "# HEIDENHAIN COM tables is unconfirmed: enter these values, this file is not a control file)",
           "effect,input_axis,position,output_axis,compensation,unit"]
    for t in tables:
        for x, v in zip(t.grid, t.values, strict=True):
            # rounded, + 0.0: what rounds to zero is written 0.000000, never -0.000000
            out.append(f"{t.effect},{t.input},{round(x, 4) + 0.0:.4f},{t.output},"
                       f"{round(v, 6) + 0.0:.6f},{t.unit}")
    return "\n".join(out) + "\n"


# TCPM as compgen writes it: F CONT, the programmed feed is the contouring feed of the axes in
# the block (a pose block turns the table only: F TCP, the tool point's speed relative to the
# workpiece, is zero there); AXIS POS, rotary words are axis positions; PATHCTRL AXIS.
# TNC 640 ISO user's manual 5/2013 p. 400; TNC 620 user's manual 2/2015 p. 446.
TCPM = "FUNCTION TCPM F CONT AXIS POS PATHCTRL AXIS"


PROBE_DIRECTION = re.compile(r"TCH PROBE 4\.2 IX([+-]\d{1,3}\.\d{1,9}) IY([+-]\d{1,3}\.\d{1,9}) "
                             r"IZ([+-]\d{1,3}\.\d{1,9})")
# MB: how far the cycle retracts the stylus after the touch; MB0 leaves it deflected
PROBE_RUN = re.compile(r"TCH PROBE 4\.3 ABST\+?(\d{1,4}(?:\.\d{1,6})?) F(\d{1,6}(?:\.\d{1,6})?) "
                       r"MB\+?(\d{1,4}(?:\.\d{1,6})?) REFERENCE SYSTEM:0")
# a tool by number, or by name in double quotes (TOOL CALL "NAME" Z): the control rejects a bare name
TOOL_CALL = re.compile(r'TOOL CALL (?:\d{1,9}|"[^"]+") Z( S\S*)?')
# an axis's target for the OEM's M-function: Q120-Q122 for A, B, C (U26)
PLC_TARGET_LINE = re.compile(r"FN 0: Q(12[0-2]) = ([+-]\d{1,4}(?:\.\d{1,9})?)")
# a head's logged tip turned from TCP coordinates into the machine frame (U25): scratch Q20-Q26,
# the result back into Q1-Q3 that the log's format file prints; no motion
_NUM = r"[+-]\d{1,6}(?:\.\d{1,9})?"
LOG_ARITHMETIC = re.compile(rf"FN 3: Q2[01] = \+Q[1-3] \* {_NUM}|FN 1: Q2[0-6] = \+Q20 \+ (?:\+Q21|{_NUM})"
                            r"|FN 0: Q[1-3] = \+Q2[4-6]")
MESSAGE = re.compile(r"FN 16: F-PRINT TNC:\\[\w.]+_MSG\.A / SCREEN:")


def program_blocks(text: str) -> list[Block]:
    """A Klartext program as the control executes it (the blocks compgen writes). A
    touch-probe cycle 4 (U12) probes from where the last L block left the stylus, along its
    direction, at most ABST: a probing move to that point."""
    out, name = [], None
    at: dict[str, float] = {}          # the linear axes' last written values
    direction = None
    plc: dict[str, float] = {}        # the targets handed to the OEM's M-function (U26)
    raws = text.splitlines()
    bodies = [raw.split(";", 1)[0].strip() for raw in raws]
    numbered = [re.fullmatch(r"\d+\s*(.*)", body) for body in bodies]
    blocks = [m[1].strip() if m else "" for m in numbered]
    skip = 0
    for k, raw in enumerate(raws, start=1):
        if skip:
            skip -= 1
            continue
        if numbered[k - 1] is None:
            if bodies[k - 1]:
                raise unknown(k, raw)
            continue
        b = blocks[k - 1]
        if (taken := heidenhain_state(blocks, k - 1)) is not None:
            out.append(Block(k, raw, "offsets"))        # compgen's state guard: no motion
            skip = taken - 1
            continue
        if (d := re.fullmatch(r"(BEGIN|END) PGM (\S+) (\S+)", b)) is not None:
            if d[3] != "MM":       # compgen's positions are mm; an INCH program reads them as inches
                raise CompgenError(f"line {k}: {b!r}: only programs in MM are checked", where=None,
                                   hint=f"write the program with {me()} measure-program")
            if d[1] == "BEGIN":
                name = d[2]
                out.append(Block(k, raw, "units"))
            elif d[2] != name:
                raise CompgenError(f"line {k}: {b!r} ends a program other than {name}" if name else
                                   f"line {k}: {b!r} ends a program no BEGIN PGM began",
                                   hint=f"write the program with {me()} measure-program")
            else:
                out.append(Block(k, raw, "end"))
            continue
        if (plain := _plain_block(k, raw, b)) is not None:
            out += plain
        elif b.startswith("L "):
            tokens = b.split()[1:]
            rapid, m91 = "FMAX" in tokens, "M91" in tokens
            w = words([t for t in tokens if t not in ("FMAX", "M91", "R0")], k)
            feed = w.pop("F", None)
            out.append(Block(k, raw, "move", target=w, rapid=rapid, feed=feed, machine_coords=m91))
            at.update({c: v for c, v in w.items() if c in "XYZ"})
        elif (d := PROBE_DIRECTION.fullmatch(b)) is not None:
            direction = np.array([float(v) for v in d.groups()])
            if not 0.999 < np.linalg.norm(direction) < 1.001:
                raise CompgenError(f"line {k}: the probing direction is not a unit vector")
        elif (d := PLC_TARGET_LINE.fullmatch(b)) is not None:
            plc["ABC"[int(d[1]) - 120]] = float(d[2])
            out.append(Block(k, raw, "log"))
        elif plc and (d := re.fullmatch(r"M(\d{1,4})", b)) is not None:    # the PLC turns them (U26)
            out.append(Block(k, raw, "move", target=plc, rapid=True, plc=True, name=f"M{d[1]}"))
            plc = {}
        elif (d := PROBE_RUN.fullmatch(b)) is not None:
            if float(d[3]) == 0:
                raise CompgenError(f"line {k}: MB0: cycle 4 leaves the stylus deflected at the touch",
                                   hint="give a retraction (MB) of a few mm, as compgen writes it")
            if direction is None or len(at) < 3:
                raise CompgenError(f"line {k}: a probing cycle without its direction (TCH PROBE 4.2) or "
                                   "from a place no block gave", hint="give the program compgen wrote")
            target = {c: at[c] + float(d[1]) * v for c, v in zip("XYZ", direction, strict=True)}
            out.append(Block(k, raw, "move", target=target, feed=float(d[2]), probe=True))
            at, direction = {}, None            # where it stopped is the touch's: unknown here
        else:
            raise unknown(k, raw)
    return out


def _plain_block(k: int, raw: str, b: str) -> list[Block] | None:
    """A block whose meaning holds alone (no axis position or probing direction carried from
    the blocks before): what it is ([] for a block that does nothing checked), or None."""
    if not b or b in ("M30", "M126", "PLANE RESET STAY", "CYCL DEF 7.0 DATUM SHIFT",
                      "CYCL DEF 9.0 DWELL TIME", "TCH PROBE 4.0 MEASURING IN 3-D", "TCH PROBE 4.1 Q1",
                      "CYCL DEF 13.0 ORIENTATION"):
        return []
    if b == "STOP":                    # the preset check: the operator continues (U11)
        return [Block(k, raw, "stop")]
    if b == "FUNCTION RESET TCPM":
        return [Block(k, raw, "tcp", on=False)]
    if b == TCPM:
        return [Block(k, raw, "tcp", on=True)]
    if b.startswith("FUNCTION TCPM"):
        # F TCP: the feed is the tool point's speed relative to the workpiece, which is
        # zero where only the table turns (undefined there); AXIS SPAT: rotary words are
        # spatial angles. Neither is what this check models.
        raise CompgenError(f"line {k}: {b!r}: only {TCPM!r} is modelled (F CONT: the feed of the "
                           "axes programmed; AXIS POS: rotary words are axis positions)",
                           hint=f"write the program with {me()} measure-program")
    if (d := re.fullmatch(r"CYCL DEF 7\.[123] [XYZ]([+-]?\d{1,7}(?:\.\d{0,9})?)", b)) is not None:
        if float(d[1]) != 0:
            raise CompgenError(f"line {k}: a datum shift moves the preset compgen's positions are in")
        return []
    if TOOL_CALL.fullmatch(b):
        return [Block(k, raw, "tool"), Block(k, raw, "length", on=True)]
    if b.startswith("TOOL CALL "):
        raise CompgenError(f"line {k}: {b!r}: a tool called by name needs double quotes (TOOL CALL "
                           "\"NAME\" Z): the control rejects the block",
                           hint="write the program with compgen")
    if MESSAGE.fullmatch(b):              # the preset check's message, shown in a window (U16)
        return [Block(k, raw, "log")]
    if re.fullmatch(r"CYCL DEF 13\.1 ANGLE \d{1,3}(?:\.\d{1,4})?", b):    # the spindle oriented (U27)
        return []
    if (d := re.fullmatch(r"CYCL DEF 9\.1 DWELL (\S+)", b)) is not None:
        return [dwell(d[1], k, raw)]
    if re.fullmatch(r"FN 0: Q1[0-5] = [+-]\d{1,6}(?:\.\d{1,9})?", b) or re.fullmatch(
            r"FN 16: F-PRINT TNC:\\[\w.]+ / TNC:\\[\w.]+", b) or LOG_ARITHMETIC.fullmatch(b):
        return [Block(k, raw, "log")]
    return None


class Heidenhain(Controller):
    """HEIDENHAIN's controls: programs in conversational dialog (.H) under FUNCTION TCPM, the
    kinematics edit as rows of the kinematics description around each MachAxis, position-
    dependent errors as the values of a .comp.csv entered by hand."""

    family = "heidenhain"
    tcp_switchable = True
    plc_index = "m-function"
    program_ext = ".H"
    comment = ";"
    tcp_words = "FUNCTION TCPM"
    pose_line = re.compile(r"^\d+ L X(\S+) Y(\S+) Z(\S+) ((?:[A-C]\S+ )+)R0 F\S+ ; pose (\d+)")
    tcpm_on = re.compile(r"^\d+ FUNCTION TCPM F", re.MULTILINE)
    number = staticmethod(fmt_signed)
    tables_by_hand = True     # comp.csv: values for its compensation tables (layout unconfirmed, U8)

    def main_suffix(self, current: str | None) -> str:
        return ".TAB" if current is not None else ".txt"

    def blocks(self, text: str, mode: str | None = None) -> list[Block]:
        return program_blocks(text)

    def program_context(self, machine: Machine) -> dict:
        return {"state_guard": heidenhain_guard()}

    def check(self, machine: Machine, blocks: list[Block], probe=None):
        require_guard(blocks, "HEIDENHAIN", "stop unless no basic rotation, rotation, mirrored axis or "
                      "scaling is active")
        return super().check(machine, blocks, probe)

    def edits_head(self, machine: Machine) -> bool:
        # pairs around a head's MachAxis as around a table's (U18)
        return True

    def edit(self, machine: Machine, p: Plan, current: str | None, where: str,
             ctx: EditContext) -> EditFiles:
        rows = rows_of(machine, p)
        tables = self.tables(machine, p)
        files, notes = {}, []
        if current is not None:
            table = TabTable.parse(current, where)
            skipped = check_pivots(table, machine, where)
            diff = edit_table(table, rows, where, ctx.marker, dict(ctx.sigma))
            files[".TAB"] = table.text()
            notes += ["table changes:", *diff, *([skipped] if skipped else []), *_resolution(table)]
            if len(table.rows) > DESCRIPTION_ROWS:
                notes.append(f"the table holds {len(table.rows)} entries, more than the {DESCRIPTION_ROWS} a "
                             "kinematics description is reported to take (UNCONFIRMED U19): check that the "
                             "control loads it before the sign check, else thin the OEM's rows with the OEM")
        files[".txt"] = render(
            "heidenhain/kinematics.txt.j2", header=ctx.header, controller=self.name,
            rows=[{"axis": a, "before": [_row(r) for r in b], "after": [_row(r) for r in f]}
                  for a, (b, f) in rows.items()],
            lines=ctx.lines, expect=ctx.expect,
            tables=[{"effect": t.effect, "words": t.words, "output": t.output, "unit": t.unit,
                     "range": f"{t.input} {t.start:g}..{t.stop:g} step {t.step:g}"} for t in tables],
            other=[*p.not_compensable, *self.not_tabled(machine, p)], setup=p.setup, head=bool(machine.heads))
        if tables:
            files[".comp.csv"] = _comp_csv(tables)
        return EditFiles(files, tuple(notes))

    def since(self, machine: Machine, measured: str, current: str, where: str) -> Held:
        nominal = nominal_lines(machine)
        now, then = (read_lines(t, machine, nominal) for t in (current, measured))
        lines = {n: replace(line, offset=line.offset - then[n].offset, tilt=line.tilt - then[n].tilt)
                 for n, line in now.items()}
        sq_now, sq_then = (read_squareness(t, machine) for t in (current, measured))
        return Held(lines, {k: sq_now.get(k, 0.0) - sq_then.get(k, 0.0) for k in {**sq_now, **sq_then}})

    def beyond_nominal(self, machine: Machine, current: str, where: str) -> Held:
        # the ISO-named rows hold the deviations from the machine's geometry: none is nominal
        return Held(read_lines(current, machine, nominal_lines(machine)), read_squareness(current, machine))

    def plc_words(self, axis) -> str:
        return f"in Q{PLC_TARGET[axis.name]} (iTNC 530 MP6602, TNC 640 mStrobeRotAxPos)"

    def tool_word(self, tool: str) -> str:
        return tool if tool.isdigit() else f'"{tool}"'

    def message_files(self, name: str, messages: list[str]) -> dict[str, str]:
        # FN 16: F-PRINT to SCREEN: shows the format file's text in a window (U16)
        return {"_MSG.A": render("heidenhain/probe.A.j2", head=messages)}

    def log_files(self, head: list[str], paths, rotary: list[str], ball: str) -> dict[str, str]:
        # FN 16 prints through format files: the head, and a line per touch of each path
        return {"_HEAD.A": render("heidenhain/probe.A.j2", head=head),
                **{f"_{path}.A": render("heidenhain/probe.A.j2", path=path, rotary=rotary, head=None,
                                        ball=ball) for path in paths}}

    def reads(self, text: str) -> bool:
        return ROW.search(text) is not None

    def read(self, machine: Machine, text: str, current: str | None, held: Held, where: str) -> Held:
        return Held(read_lines(text, machine, held.lines),
                    {**held.squareness, **read_squareness(text, machine)}, held.tables)


class ITNC530(Heidenhain):
    """The iTNC 530: its kinematics in a description table (*.TAB), which --current edits."""

    name = "itnc530"
    words = "HEIDENHAIN iTNC 530"
    backup = "copy the kinematics description table (*.TAB), or Cycle 450 SAVE KINEMATICS"


class TNC640(Heidenhain):
    """The TNC 640: its kinematics in the configuration editor, entered by hand from the edit's
    .txt (no file of the control to edit)."""

    name = "tnc640"
    words = "HEIDENHAIN TNC 640"
    backup = "save the machine configuration, or Cycle 450 SAVE KINEMATICS"
    takes_current = False     # its kinematics live in the configuration editor, not in a file

    def edit(self, machine: Machine, p: Plan, current: str | None, where: str,
             ctx: EditContext) -> EditFiles:
        if current is not None:
            raise CompgenError("a TNC 640 keeps its kinematics in the configuration editor, not in a "
                               "*.TAB file", hint="leave out --current: compgen writes the entries to change")
        return super().edit(machine, p, current, where, ctx)
