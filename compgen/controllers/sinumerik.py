"""SIEMENS SINUMERIK 840D sl: G-code programs under TRAORI, ``$TC_CARR`` kinematic-record
edits (fine offsets and axis vectors), CEC compensation tables, and their readers.

References: Commissioning Manual 12/2017 p.572–573 (``$TC_CARR``, table axes entered
reversed); Function Manual K3 03/2013 §4.4 (CEC, machine-axis names p.248).
"""

from __future__ import annotations

import re
from dataclasses import replace
from decimal import Decimal

import numpy as np

from ..errors import CompgenError, one_line
from ..model.lines import AxisLine
from ..model.machine import Machine
from ..setup.motion import Block, dwell, gcode_move
from ..transforms import rot_exact
from ..units import number
from . import ascii_text, fmt_plain, render
from .base import Controller, EditContext, EditFiles, state_lines
from .correction import (
    CompTable,
    Held,
    Plan,
    compose_tables,
    nominal_lines,
    unrolled,
)
from .state_guards import FRAME_IF, require_frame_guard, sinumerik_guard, sinumerik_terms

MM_DECIMALS = 5
VECTOR_DECIMALS = 10
CARR = re.compile(r"^\s*\$TC_CARR(\d+)\[(\d+)\]\s*=\s*(\S+?)\s*(?:;.*)?$")
KIND = re.compile(r"""^\s*\$TC_CARR23\[(\d+)\]\s*=\s*"([A-Za-z])"\s*(?:;.*)?$""")
CEC = re.compile(r"^\$AN_CEC(_[A-Z_]+)?\[(\d+)(?:,(\d+))?\]=\(?([^);\s]+)\)?")
FINE = {"l1": (41, 42, 43), "l2": (44, 45, 46), "l3": (55, 56, 57), "l4": (58, 59, 60)}
# Which offset vectors each kinematic type ($TC_CARR23) chains, and what they join
# (Commissioning Manual 03/2013 p.502): rotary axis 1 carries axis 2; a mixed machine's axis 1
# turns the tool. A pivot is any point of its axis's line.
#   P, table: l2 machine reference point -> pivot 1, l3 pivot 1 -> pivot 2, l4 = -(l2 + l3)
#   T, head:  l3 tool adapter -> pivot 2, l2 pivot 2 -> pivot 1, l1 = -(l2 + l3)
#   M, mixed: l2 tool adapter -> pivot 1 (head), l1 = -l2; l3 machine reference point ->
#             pivot 2 (table), l4 = -l3
CHAIN = {"P": ("l2", "l3", "l4"), "T": ("l1", "l2", "l3"), "M": ("l1", "l2", "l3", "l4")}
# the coarse (base) offsets the OEM set: l1 $TC_CARR1-3, l2 4-6, l3 15-17, l4 18-20
COARSE = {"l1": (1, 2, 3), "l2": (4, 5, 6), "l3": (15, 16, 17), "l4": (18, 19, 20)}
VECTOR = {1: (7, 8, 9), 2: (10, 11, 12)}
SPAN_DEG = 1260.0       # a non-modulo axis's table repeats its turn over its travel within ±this
SAME_AXIS_DEG = 1.0     # a record's vector further than this from the machine file's: wrong record


def read_carr(text: str, where: str, record: int) -> dict[int, float]:
    """``$TC_CARRn[record]=value`` assignments of one record (other lines are ignored); a
    parameter assigned twice is refused (the control would keep the last: which was meant?)."""
    return {n: v for n, (v, _, _) in _carr_lines(text, where, record).items()}


def _carr_lines(text: str, where: str, record: int) -> dict[int, tuple[float, str, str]]:
    """Each parameter's value, its text as written, and its file:line."""
    out: dict[int, tuple[float, str, str]] = {}
    for at, line in state_lines(text, where):
        m = CARR.match(line)
        if m and int(m[2]) == record and not m[3].startswith('"'):
            n = int(m[1])
            if n in out:
                raise CompgenError(f"$TC_CARR{n}[{record}] is assigned twice ({out[n][2]} and {at})",
                                   where=at, hint="keep the one the control holds")
            out[n] = (number(m[3], f"$TC_CARR{n} value", at), m[3], at)
    return out


def check_current(text: str, where: str, machine: Machine) -> None:
    """The record as read is plausible for this machine: every fine offset within [limits]
    offset_um of the machine file's geometry (a fine offset is a correction of it), and
    within MD20188 where the machine file gives it; every coarse offset within [limits]
    offset_um of the one the machine file says the control holds ([sinumerik] offsets), a
    record that holds one the machine file does not give refused; each vector within
    SAME_AXIS_DEG of the machine file's. Refused with its file and line."""
    record = machine.sinumerik["tcarr"]
    bound_mm = machine.limits.offset_um * 1e-3
    limit = machine.sinumerik.get("fine_limit_mm")
    fine = {i for idx in FINE.values() for i in idx}
    lines = _carr_lines(text, where, record)
    for at, line in state_lines(text, where):
        # the record's kind ($TC_CARR23, a character: T head, P table, M mixed) decides which
        # offset vectors chain which pivots: another kind's record is another chain
        m = KIND.match(line)
        if m and int(m[1]) == record and m[2].upper() != machine.sinumerik["kind"]:
            want = machine.sinumerik["kind"]
            raise CompgenError(f"$TC_CARR23[{record}] = \"{m[2]}\": a record of kind {m[2].upper()}; the "
                               f"machine file's rotary axes make a kind {want} record "
                               f"({ {'P': 'table', 'T': 'head', 'M': 'head and table'}[want]})", where=at,
                               hint="is this the record of the measured machine ([sinumerik] tcarr)?")
    declared = machine.sinumerik.get("offsets") or {}
    for vec, idx in COARSE.items():
        for k, n in enumerate(idx):
            if n not in lines:
                continue
            value, _, at = lines[n]
            if vec not in declared:
                raise CompgenError(f"$TC_CARR{n}[{record}] ({vec}.{'xyz'[k]}) = {value:g} mm: the machine "
                                   f"file does not say which {vec} the control holds, so this record cannot "
                                   "be told to be the measured machine's", where=at,
                                   hint=f"add offsets = {{ {vec} = [x, y, z] }} to [sinumerik], as the OEM "
                                        "set the record")
            want = declared[vec][k]
            if not abs(value - want) <= bound_mm:
                raise CompgenError(f"$TC_CARR{n}[{record}] ({vec}.{'xyz'[k]}) = {value:g} mm, "
                                   f"{value - want:+.4f} mm from the machine file's {want:g}: beyond its "
                                   "[limits] offset_um "
                                   f"{machine.limits.offset_um:g} µm", where=at,
                                   hint="is this the record of the measured machine? If it is, correct "
                                        "[sinumerik] offsets")
    for i, a in enumerate(carr_axes(machine), start=1):
        if not all(n in lines for n in VECTOR[i]):
            continue
        now = np.array([lines[n][0] for n in VECTOR[i]])
        held = machine.sinumerik["vectors"][a.name]
        size = np.linalg.norm(now)
        if size == 0 or np.degrees(np.arccos(np.clip(now @ held / size, -1, 1))) > SAME_AXIS_DEG:
            raise CompgenError(f"the record's vector for {a.name} {now.tolist()} is not the one the "
                               f"machine file says the control holds {held.tolist()}",
                               where=lines[VECTOR[i][0]][2],
                               hint="is this the record of the measured machine? else correct [sinumerik] "
                                    "vectors")
    for n, (value, _, at) in lines.items():
        if n not in fine:
            continue
        if not abs(value) <= bound_mm:
            raise CompgenError(f"$TC_CARR{n}[{record}] = {value:g} mm: a fine offset beyond the "
                               f"{machine.limits.offset_um:g} µm the machine file's [limits] allow",
                               where=at, hint="is this the record of the measured machine? If it "
                               "is, raise [limits] offset_um in the machine file")
        if limit is not None and abs(value) > limit:
            raise CompgenError(f"$TC_CARR{n}[{record}] = {value:g} mm exceeds MD20188 = {limit:g} mm",
                               where=at)


def carr_axes(machine: Machine) -> list:
    """The machine's rotary axes in the record's order: rotary axis 1 carries axis 2 (table
    or head, base outwards); on a mixed machine axis 1 is the head's."""
    heads = list(machine.heads)
    tables = [a for a in machine.rotary_axes if a.side == "workpiece"]
    return heads + tables if heads and tables else heads or tables


def fine_deltas(kind: str, t1: np.ndarray, t2: np.ndarray) -> dict[str, np.ndarray]:
    """How each offset vector of a ``kind`` record changes (mm) when pivot 1 moves by ``t1``
    and pivot 2 by ``t2`` (``CHAIN``: each vector joins two points, closures follow)."""
    if kind == "P":
        return {"l2": t1, "l3": t2 - t1, "l4": -t2}
    if kind == "T":
        return {"l3": t2, "l2": t1 - t2, "l1": -t1}
    return {"l2": t1, "l1": -t1, "l3": t2, "l4": -t2}


def carr_values(machine: Machine, p: Plan, current: dict[int, float]) -> tuple[dict[int, float], list[str]]:
    """New ``$TC_CARR`` values: the fine offsets of the vectors the record's kind chains, plus
    the corrections; direction vectors v1, v2 as exact unit vectors with the sign the control
    holds."""
    cfg = machine.sinumerik
    axes = carr_axes(machine)
    kind = cfg["kind"]
    if len(axes) != 2 or (kind == "M" and len(machine.heads) != 1):
        raise CompgenError(f"compgen writes $TC_CARR for two rotary axes only (kind {kind})",
                           hint="this machine's kinematics is not one $TC_CARR record of two axes")
    delta = fine_deltas(kind, *(p.lines[a.name].offset for a in axes))
    fine = {vec: FINE[vec] for vec in CHAIN[kind]}
    missing = [n for idx in (*fine.values(), *VECTOR.values()) for n in idx if n not in current]
    if missing:
        raise CompgenError(f"--current lacks $TC_CARR{missing[0]}[{cfg['tcarr']}] (and "
                           f"{len(missing) - 1} more)",
                           hint="give every fine offset (" + ", ".join(f"{i[0]}-{i[-1]}"
                                                                       for i in fine.values())
                                + ") and vector (7-12) of the record as the control holds them")
    new, diff = {}, []
    for vec, idx in fine.items():
        for k, n in enumerate(idx):
            new[n] = current[n] + delta[vec][k]
            diff.append(f"$TC_CARR{n} ({vec}.{'xyz'[k]} fine) {fmt_plain(current[n], MM_DECIMALS)} -> "
                        f"{fmt_plain(new[n], MM_DECIMALS)} mm")
    for i, a in enumerate(axes, start=1):
        now = np.array([current[n] for n in VECTOR[i]])     # within SAME_AXIS_DEG (check_current)
        size = np.linalg.norm(now)
        # compose: turn what the record holds (the OEM's or an earlier edit's tilt included)
        # by the tilt the fit found, measured relative to that state
        v = rot_exact(p.lines[a.name].tilt)[:3, :3] @ (now / size)
        for k, n in enumerate(VECTOR[i]):
            new[n] = v[k]
            diff.append(f"$TC_CARR{n} (v{i}.{'xyz'[k]}) {fmt_plain(current[n], VECTOR_DECIMALS)} -> "
                        f"{fmt_plain(v[k], VECTOR_DECIMALS)}")
    return new, diff


def read_lines(text: str, machine: Machine, current: dict[int, float],
               lines: dict[str, AxisLine]) -> dict[str, AxisLine]:
    """The rotary axis lines an emitted ``$TC_CARR`` program sets, relative to ``current``."""
    new = read_carr(text, "program", machine.sinumerik["tcarr"])
    kind = machine.sinumerik["kind"]
    d = {vec: np.array([new[n] - current[n] for n in FINE[vec]]) for vec in CHAIN[kind]}
    if kind == "P":
        t1 = d["l2"]
        t2 = t1 + d["l3"]
    elif kind == "T":
        t2 = d["l3"]
        t1 = t2 + d["l2"]
    else:
        t1, t2 = d["l2"], d["l3"]
    closes = fine_deltas(kind, t1, t2)
    for vec in CHAIN[kind]:               # three values each, each rounded
        if np.abs(closes[vec] - d[vec]).max() > 1.5 * 10.0 ** -MM_DECIMALS:
            raise CompgenError(f"the {vec} fine offsets do not close the chain of a kind {kind} record")
    out = dict(lines)
    for i, (a, t) in enumerate(zip(carr_axes(machine), (t1, t2), strict=True), start=1):
        dv = np.array([new[n] for n in VECTOR[i]])
        was = np.array([current[n] for n in VECTOR[i]])
        out[a.name] = AxisLine(a.name, a.direction, lines[a.name].pivot, t, _turn(was, dv))
    return out


def _turn(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation vector (rad) turning direction ``a`` onto ``b`` by the shortest way."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis)
    return np.zeros(3) if s == 0 else axis / s * np.arctan2(s, a @ b)


CEC_KEYS = {"input_axis", "output_axis", "step", "min", "max", "is_modulo"}


def read_cec(text: str, machine: Machine, where: str = "CEC file") -> list[CompTable]:
    """Tables of a CEC file as the control interpolates them (from MIN in steps of STEP), each
    named by its place, ``CEC table k``; an entry assigned twice or a table lacking one the
    control needs is refused with its file and line."""
    found: dict[int, dict] = {}
    seen: dict[str, str] = {}
    for at, line in state_lines(text, where):
        m = CEC.match(line.strip())
        if not m:
            if line.strip().upper().startswith("$AN_CEC"):    # skipped, it would be lost from the next round
                raise CompgenError(f"{one_line(line.strip())[:60]!r} is no CEC entry compgen reads "
                                   "($AN_CEC…[table] or $AN_CEC[table,point] = value, table and point whole "
                                   "numbers from 0)", where=at, hint="give the table as the control holds it")
            continue
        key = line.strip().split("=", 1)[0]
        if key in seen:
            raise CompgenError(f"{key} is assigned twice ({seen[key]} and {at})", where=at,
                               hint="keep the one the control holds")
        seen[key] = at
        t = found.setdefault(int(m[2]), {"values": {}, "at": at})
        if m[1] is None:
            t["values"][int(m[3])] = number(m[4], "$AN_CEC value", at)
        else:
            t[m[1][1:].lower()] = (m[4] if m[1] in ("_INPUT_AXIS", "_OUTPUT_AXIS")
                                   else number(m[4], f"$AN_CEC{m[1]}", at))
    channel = {m: a for a, m in _machine_axes(machine).items()}
    out = []
    for k in sorted(found):
        t = found[k]
        missing = sorted(CEC_KEYS - set(t))
        values = tuple(t["values"][i] for i in sorted(t["values"]))
        if missing or sorted(t["values"]) != list(range(len(values))) or len(values) < 2:
            raise CompgenError(f"CEC table {k} lacks " + (f"$AN_CEC_{missing[0].upper()}" if missing else
                                                         "values 0, 1, 2, ... without a gap"),
                               where=t["at"], hint="give the table as the control holds it")
        # the control places value n at MIN + n·STEP up to MAX: the three must agree with the values
        steps = (t["max"] - t["min"]) / t["step"] if t["step"] > 0 else float("nan")
        if not (t["min"] < t["max"] and t["step"] > 0 and abs(steps - round(steps)) < 1e-6
                and round(steps) == len(values) - 1):
            raise CompgenError(f"CEC table {k}: MIN {t['min']:g}, MAX {t['max']:g}, STEP {t['step']:g} "
                               f"do not span its {len(values)} values in whole steps", where=t["at"],
                               hint="give the table as the control holds it")
        if t["is_modulo"] not in (0, 1):
            raise CompgenError(f"CEC table {k}: $AN_CEC_IS_MODULO is {t['is_modulo']:g}, not 0 or 1",
                               where=t["at"])
        unknown = [n for n in (t["input_axis"], t["output_axis"]) if n not in channel]
        if unknown:
            raise CompgenError(f"CEC table {k} names machine axis {unknown[0]!r}, which the machine file's "
                               "[sinumerik] machine_axes does not name", where=t["at"])
        inp, out_axis = channel[t["input_axis"]], channel[t["output_axis"]]
        output = machine.axis(out_axis)
        out.append(CompTable(f"CEC table {k}", "as loaded", inp, out_axis, t["min"],
                             t["min"] + t["step"] * (len(values) - 1), values, bool(t["is_modulo"]),
                             "deg" if output.rotary else "mm"))
    return out


# what a loaded table holds beyond its values (K3 03/2013 4.4): DIRECTION (0 both ways, 1 or
# -1 one way only) and MULT_BY_TABLE (its output multiplied by another table's); kept as read
MODES = ("_DIRECTION", "_MULT_BY_TABLE")


def cec_modes(text: str, where: str) -> dict[int, dict[str, str]]:
    """Each loaded table's DIRECTION and MULT_BY_TABLE as written (table -> key -> text)."""
    out: dict[int, dict[str, str]] = {}
    for at, line in state_lines(text, where):
        m = CEC.match(line.strip())
        if m and m[1] in MODES:
            number(m[4], f"$AN_CEC{m[1]}", at)
            out.setdefault(int(m[2]), {})[m[1]] = m[4]
    return out


def cec_places(tables: list[CompTable]) -> list[tuple[int, CompTable]]:
    """Each table's place in the control: a loaded one's own, a new one the next free."""
    taken = {int(t.effect.split()[-1]) for t in tables if t.effect.startswith("CEC table ")}
    free = (k for k in range(10_000) if k not in taken)
    return [(int(t.effect.split()[-1]) if t.effect.startswith("CEC table ") else next(free), t)
            for t in tables]


def _machine_axes(machine: Machine) -> dict[str, str]:
    names = machine.sinumerik["machine_axes"]
    if not names:
        raise CompgenError("CEC tables address machine axes (X1, AX1, ...), and the machine file does "
                           "not name them", where=f"{machine.source}: [sinumerik]",
                           hint='add machine_axes = { X = "X1", ... } (MD10000 AXCONF_MACHAX_NAME_TAB)')
    return names


def _cec_text(t: CompTable, index: int, names: dict[str, str], modes: dict[str, str] | None = None) -> dict:
    """A table's entries as written: MIN, STEP and MAX such that (MAX − MIN) / STEP is the
    whole number of steps the values span, in the decimals written (the control derives
    each value's position from them)."""
    if t.points:
        raise CompgenError(f"CEC table {index} would need uneven steps", hint="give tables on even steps")
    low, step = Decimal(fmt_plain(t.start, 6)), Decimal(fmt_plain(t.step, 6))
    high = low + step * (len(t.values) - 1)
    if step <= 0 or abs(float(high) - t.stop) > 1e-6 * max(1.0, abs(t.stop)):
        raise CompgenError(f"CEC table {index}'s step {t.step!r} does not divide {t.start:g}..{t.stop:g} "
                           "into "
                           f"{len(t.values) - 1} whole steps at 6 decimals")
    return {"index": index, "effect": t.effect, "words": ascii_text(t.words), "input": names[t.input],
            "output": names[t.output], "step": str(step), "min": str(low), "max": str(high),
            "modulo": int(t.modulo), "unit": t.unit, "values": [fmt_plain(v, 6) for v in t.values],
            "direction": (modes or {}).get("_DIRECTION", "0"),
            "mult": (modes or {}).get("_MULT_BY_TABLE", "0")}


# A 360° modulo rotary axis (MD30310 ROT_IS_MODULO) moves to a plain absolute position the way
# MD30455 bit 2 says: like AC (the sign of target − current, in 0…360) or like DC (shortest);
# so K2 ending at C360 from C357 turns −357° by default. compgen writes the way in the block:
# ACP (+), ACN (−), DC (shortest). Function Manual Axes and Spindles 06/2019, R2 §7.2 p.225.
MODULO_WORD = re.compile(r"([A-C])=(ACP|ACN|DC)\(([+-]?\d+(?:\.\d+)?)\)")
TURN = {"ACP": "+", "ACN": "-", "DC": "short"}


# compgen's guards in a probing program: after each MEAS block, stop unless the probe switched
# (U17); after each WRITE, stop unless it wrote (U15). Each ends the program with a message.
GUARD = re.compile(r"IF (\$AC_MEA\[1\]==0|ERR<>0)")
GUARD_BODY = (re.compile(r'MSG\("[^"]+"\)'), re.compile("M0"), re.compile("M30"), re.compile("ENDIF"))


def program_blocks(text: str) -> list[Block]:
    """A SINUMERIK part program as the control executes it (the blocks compgen writes). In a
    probing program every MEAS block is followed by STOPRE and the switch's guard, every
    WRITE by the write's guard: without them a lost touch or a full log goes unseen."""
    out, modal, feed = [], None, None
    lines = [raw.split(";", 1)[0].strip() for raw in text.splitlines()]
    skip, expect = 0, []
    for k, raw in enumerate(text.splitlines(), start=1):
        b = lines[k - 1]
        if skip:
            skip -= 1
            continue
        if not b or b in ("ORIWKS", "ORIAXES", "M6", "DEF INT ERR"):
            continue
        if expect:
            if b != expect[0]:
                raise CompgenError(f"line {k}: {raw.strip()!r} where {expect[0]!r} must follow the "
                                   f"{'probing move' if 'MEA' in expect[-1] else 'WRITE'} (line {k - 1})",
                                   hint="a lost touch or an unwritten log line would go unseen: give the "
                                        "program compgen wrote")
            expect.pop(0)
            if b.startswith("IF "):
                body = lines[k:k + len(GUARD_BODY)]
                if len(body) < len(GUARD_BODY) or not all(
                        p.fullmatch(t) for p, t in zip(GUARD_BODY, body, strict=True)):
                    raise CompgenError(f"line {k}: {b!r} is not compgen's guard (a message, M0, M30, ENDIF)",
                                       hint="give the program compgen wrote")
                skip = len(GUARD_BODY)
                out.append(Block(k, raw, "log"))
            continue
        if b == "STOPRE":
            continue
        if re.fullmatch(r'WRITE\(ERR,"\w+","[^"]*"(?:<<\$AA_MW\[[XYZ]\]<<"[^"]*")*\)', b):
            out.append(Block(k, raw, "log"))        # a line of the probe log (U15)
            expect = ["IF ERR<>0"]
            continue
        if b.startswith("MEAS=1 G1 "):            # probe towards the target, stop at the touch (U14)
            move, _, feed = gcode_move(raw, k, b.split()[1:], None, feed, "SUPA")
            out.append(replace(move, probe=True))
            expect = ["STOPRE", "IF $AC_MEA[1]==0"]
            continue
        if (d := FRAME_IF.fullmatch(b)) is not None:         # compgen's frame guard: no motion
            body = lines[k:k + len(GUARD_BODY)]
            if len(body) < len(GUARD_BODY) or not all(
                    p.fullmatch(t) for p, t in zip(GUARD_BODY, body, strict=True)):
                raise CompgenError(f"line {k}: {b!r} is not compgen's guard (a message, M0, M30, ENDIF)",
                                   hint="give the program compgen wrote")
            skip = len(GUARD_BODY)
            out.append(Block(k, raw, "offsets", target=sinumerik_terms(d[1])))
            continue
        if GUARD.fullmatch(b):
            raise CompgenError(f"line {k}: {b!r} stands where no probing move or WRITE precedes it",
                               hint="give the program compgen wrote")
        if b == "G17 G90 G71 G94":          # G71: metric (G70 would read compgen's mm as inches)
            out.append(Block(k, raw, "units"))
        elif b in ("M30", "M17"):
            out.append(Block(k, raw, "end"))
        elif re.fullmatch(r"G5[4-7]|G50[0-9]", b):
            out.append(Block(k, raw, "offset", name=b))
        elif b == "M0" or re.fullmatch(r'MSG\("[^"]*"\)|MSG\(\)', b):   # the preset check's stop
            out.append(Block(k, raw, "stop"))
        elif b in ("TRAFOOF", "TRAORI"):
            out.append(Block(k, raw, "tcp", on=b == "TRAORI"))
        elif re.fullmatch(r'T="[^"]*"', b):
            out.append(Block(k, raw, "tool"))
        elif b in ("D0", "D1"):
            out.append(Block(k, raw, "length", on=b == "D1"))
        elif (d := re.fullmatch(r"G4 F(\S+)", b)) is not None:
            out.append(dwell(d[1], k, raw))
        else:
            tokens, turn = [], {}
            for t in b.split():       # L=ACP(v), ACN, DC: a modulo axis's position and way
                d = MODULO_WORD.fullmatch(t)
                if d is not None:
                    turn[d[1]] = TURN[d[2]]
                    t = f"{d[1]}{d[3]}"
                tokens.append(t)
            move, modal, feed = gcode_move(raw, k, tokens, modal, feed, "SUPA", skip=("D0",))
            move = replace(move, turn=turn)
            if "D0" in tokens:
                out.append(Block(k, raw, "length", on=False))
            out.append(move)
    return out


class Sinumerik840D(Controller):
    name = "sinumerik840d"
    family = "sinumerik"
    words = "SIEMENS SINUMERIK 840D sl"
    program_ext = ".MPF"
    comment = ";"
    tcp_words = "TRAORI"
    backup = "a commissioning archive, and keep the _RESTORE program"
    pose_line = re.compile(r"^G1 X(\S+) Y(\S+) Z(\S+) ((?:[A-C]\S+ )+)F\S+ ; pose (\d+)")
    tcpm_on = re.compile(r"^TRAORI\b", re.MULTILINE)
    tcp_switchable = True
    squareness_as = "tables"      # CEC tables hold squareness and every single-axis table
    section = "sinumerik"
    state_files = "the record's $TC_CARR lines, and the CEC tables' file"
    needs_current = True
    load_note = ("SD42974 $SC_TOCARR_FINE_CORRECTION = 1, or the fine offsets do nothing; each within "
                 "MD20188 $MC_TOCARR_FINE_LIM_LIN (W1 function manual 08/2005 p. 2-91)")

    def read_section(self, get, machine: Machine) -> dict:
        """[sinumerik]: the $TC_CARR record, the axis vectors as the control holds them, and
        the machine-axis names of the CEC tables."""
        get.only({"tcarr", "vectors", "machine_axes", "modulo", "fine_correction", "fine_limit_mm",
                  "offsets"})
        get.sub("vectors").only({a.name for a in machine.rotary_axes})
        number_given = get.number("tcarr")
        if not (number_given == int(number_given) and 1 <= number_given <= 9999):
            # a record is a whole number: int() read 1.5 as record 1, another record than meant
            raise CompgenError(f"must be the record's number, a whole number from 1, not {number_given:g}",
                               where=get.at("tcarr"), hint="the n of $TC_CARR1[n]")
        record = int(number_given)
        kinds = {a.name: "P" if a.side == "workpiece" else "T" for a in machine.rotary_axes}
        vectors = {}
        for a in machine.rotary_axes:
            v = np.array(get.sub("vectors").vec3(a.name))
            if abs(np.linalg.norm(v) - 1) > 1e-9 or abs(abs(v["xyz".index(a.direction)]) - 1) > 1e-9:
                raise CompgenError(f"must be the unit vector ±{a.direction} the control holds for "
                                   f"{a.name}, got {v.tolist()}", where=get.sub("vectors").at(a.name))
            vectors[a.name] = v
        kind = "".join(sorted(set(kinds.values())))
        names = {}
        if "machine_axes" in get.doc:     # channel axis -> machine axis, for CEC tables (K3 p.248)
            m = get.sub("machine_axes")
            m.only(set(machine.axis_names))
            for axis in machine.axes:
                name = m.str(axis.name)
                if not re.fullmatch(r"[A-Z][A-Z0-9_]{0,15}", name):
                    raise CompgenError(f"machine-axis name {name!r} is not a SINUMERIK axis name "
                                       "(letters, digits, _; e.g. X1, AX1)", where=m.at(axis.name))
                names[axis.name] = name
        modulo = None
        if "modulo" in get.doc:    # MD30310 ROT_IS_MODULO of each rotary axis: its programs differ
            modulo = tuple(get.names("modulo"))
            for name in modulo:
                if name not in machine.axis_names or not machine.axis(name).full_turn:
                    raise CompgenError(f"{name} is not a rotary axis that turns a whole revolution",
                                       where=get.at("modulo"))
        # SD42974 $SC_TOCARR_FINE_CORRECTION: the fine offsets count only at 1
        fine = (get.flag("fine_correction", "SD42974 $SC_TOCARR_FINE_CORRECTION = 1 or 0")
                if "fine_correction" in get.doc else None)
        limit = get.number("fine_limit_mm") if "fine_limit_mm" in get.doc else None    # MD20188
        offsets = {}          # the coarse offsets as the control holds them (the OEM's), mm
        if "offsets" in get.doc:
            g = get.sub("offsets")
            g.only(set(COARSE))
            offsets = {k: np.array(g.vec3(k)) for k in COARSE if k in g.doc}
        return {"tcarr": record, "kind": {"P": "P", "T": "T"}.get(kind, "M"), "vectors": vectors,
                "machine_axes": names, "modulo": modulo, "fine_correction": fine, "fine_limit_mm": limit,
                "offsets": offsets}

    def main_suffix(self, current: str | None) -> str:
        return ".MPF"

    def edits_head(self, machine: Machine) -> bool:
        # a T or M record of two axes: its offset vectors join the head's pivots (CHAIN)
        return machine.sinumerik is not None and len(carr_axes(machine)) == 2

    def tables(self, machine: Machine, p: Plan) -> list[CompTable]:
        return [self._plain(machine, t) for t in super().tables(machine, p)]

    def program_context(self, machine: Machine) -> dict:
        return {"state_guard": sinumerik_guard(machine)}

    def check(self, machine: Machine, blocks: list[Block], probe=None):
        require_frame_guard(machine, blocks)
        return super().check(machine, blocks, probe)

    def check_setup(self, machine: Machine) -> None:
        turning = [a.name for a in machine.rotary_axes if a.full_turn]
        if turning and (machine.sinumerik is None or machine.sinumerik.get("modulo") is None):
            raise CompgenError(f"whether {', '.join(turning)} {'is a' if len(turning) == 1 else 'are'} 360° "
                               "modulo axis on this control is not in the machine file: a program reads "
                               "differently on one", where=f"{machine.source}: [sinumerik] modulo",
                               hint=f'set modulo = ["{turning[0]}"] where MD30310 ROT_IS_MODULO = 1, or '
                                    "modulo = [] where no axis is")

    def modulo_axes(self, machine: Machine) -> tuple[str, ...]:
        return tuple((machine.sinumerik or {}).get("modulo") or ())

    def axis_word(self, letter: str, value: float, before: float | None, feed: bool, decimals: int,
                  machine: Machine) -> str:
        if letter not in self.modulo_axes(machine):
            return super().axis_word(letter, value, before, feed, decimals, machine)
        # a pose's turn the way the path goes (ACP/ACN); a turn at the safe height the short
        # way; where it stays, a plain position (no turn whatever MD30455 says)
        at = self.number(value % 360.0, decimals)
        if before is not None and value == before:
            return f"{letter}{at}"
        way = "DC" if before is None or not feed else "ACP" if value > before else "ACN"
        return f"{letter}={way}({at})"

    def blocks(self, text: str, mode: str | None = None) -> list[Block]:
        return program_blocks(text)

    def edit(self, machine: Machine, p: Plan, current: str | None, where: str,
             ctx: EditContext) -> EditFiles:
        if machine.sinumerik is None:
            raise CompgenError(f"machine file {machine.source} has no [sinumerik] section",
                               hint="give tcarr (the record) and the axis vectors the control holds")
        if current is None:
            raise CompgenError("SINUMERIK needs --current: the record's $TC_CARR values as the control "
                               "holds them", hint="copy the $TC_CARR7-12, 44-46, 55-60 lines of the record "
                                                  "from the archive into a file")
        fine = machine.sinumerik.get("fine_correction")
        if not fine:
            raise CompgenError("compgen's edit writes fine offsets ($TC_CARR41-65), which the control adds "
                               "only with SD42974 $SC_TOCARR_FINE_CORRECTION = 1; "
                               + ("the machine file says it is 0" if fine is False else
                                  "the machine file does not say whether it is"),
                               where=f"{machine.source}: [sinumerik] fine_correction",
                               hint="set SD42974 = 1 on the control and fine_correction = true here")
        check_current(current, where, machine)
        was = _carr_lines(current, where, machine.sinumerik["tcarr"])   # value, text as written, line
        held = {n: v for n, (v, _, _) in was.items()}
        new_carr, diff = carr_values(machine, p, held)
        rec = machine.sinumerik["tcarr"]
        largest = max(abs(v) for n, v in new_carr.items() if n > 12)
        limit = machine.sinumerik.get("fine_limit_mm")
        if limit is not None and largest > limit:
            raise CompgenError(f"a fine offset would be {largest:.4f} mm, beyond MD20188 "
                               f"$MC_TOCARR_FINE_LIM_LIN = {limit:g} mm (the machine file's fine_limit_mm): "
                               "the control would refuse it",
                               hint="move the excess into the base offsets with the OEM, then edit again")
        loaded = self.loaded_tables(machine, current, where)
        new = self.tables(machine, p)
        tables = compose_tables(loaded, new)
        for t in tables:
            if t.modulo and t.input not in (machine.sinumerik.get("modulo") or ()):
                raise CompgenError(f"{t.effect} is a modulo table on {t.input}, which the machine file says "
                                   "is "
                                   "not a modulo axis ([sinumerik] modulo)", where=where,
                                   hint=f"is {t.input} modulo (MD30310)? Correct [sinumerik] modulo, or the "
                                        "table")

        def carr(values):      # vectors are unitless, offsets mm
            return [(n, fmt_plain(v, VECTOR_DECIMALS if n <= 12 else MM_DECIMALS)) for n, v in values.items()]

        chain = ", ".join(f"{v} ({FINE[v][0]}-{FINE[v][-1]})" for v in CHAIN[machine.sinumerik["kind"]])
        files = {".MPF": render("sinumerik/kinematics.MPF.j2", name=ctx.name, header=ctx.header, record=rec,
                                values=carr(new_carr), lines=ctx.lines, expect=ctx.expect, chain=chain,
                                kind=machine.sinumerik["kind"], by_hand=not self.writes_programs(machine))}
        files["_RESTORE.MPF"] = render(
            "sinumerik/kinematics.MPF.j2", name=f"{ctx.name}_RESTORE", record=rec, lines=[], expect=[],
            chain=chain, kind=machine.sinumerik["kind"],
            header=[f"compgen {ctx.version}: restores record {rec} as it was", *ctx.header[1:3]],
            values=[(n, was[n][1]) for n in new_carr])          # each value as it was written
        notes = ["$TC_CARR changes:", *diff,
                 f"the fine offsets act with SD42974 = 1 only, each within MD20188 $MC_TOCARR_FINE_LIM_LIN: "
                 f"the largest here is {largest:.4f} mm"
                 + ("" if limit is not None else " (give fine_limit_mm in [sinumerik] to have it checked)")]
        if new:
            names = _machine_axes(machine)
            placed = cec_places(tables)
            modes = cec_modes(current, where)
            for k, t in placed:
                if t not in loaded and any(float(v) != 0 for v in modes.get(k, {}).values()):
                    # this round's trims act both ways and alone: added to a table that acts one
                    # way, or is multiplied by another, they would not be what compgen predicts
                    raise CompgenError(f"CEC table {k} ({t.input}->{t.output}) acts "
                                       + " and ".join(f"with $AN_CEC{key}[{k}]={v}"
                                                      for key, v in modes[k].items() if float(v) != 0)
                                       + ": compgen does not add this round's correction to it",
                                       where=where, hint="give this round a table of its own with the "
                                                         "OEM, or correct that table by hand")
            files["_CEC.INI"] = render("sinumerik/cec.INI.j2", header=ctx.header, raw=[],
                                       points=max(len(t.values) for t in tables),
                                       tables=[_cec_text(t, k, names, modes.get(k)) for k, t in placed])
            slots = {t.effect for t in loaded}
            zero = [_cec_text(replace(t, values=(0.0,) * len(t.values), effect="(none)", words="not loaded"),
                              k, names) for k, t in placed if t.effect not in slots]
            raw = [line.strip() for _, line in state_lines(current, where) if CEC.match(line.strip())]
            files["_CEC_RESTORE.INI"] = render(
                "sinumerik/cec.INI.j2", raw=raw, tables=zero, points=max(len(t.values) for t in tables),
                header=[f"compgen {ctx.version}: restores the CEC tables as they were read"
                        + (" (tables not loaded before: zero)" if zero else ""), *ctx.header[1:3]])
            notes.append("CEC tables: " + "; ".join(
                f"table {k} {t.input}->{t.output}: "
                + (f"{t.words} (the loaded table with this round's added)" if t.effect in slots else t.effect)
                for k, t in placed if t.effect not in slots or t not in loaded))
            if not loaded:
                notes.append("no CEC tables were read from --current: they hold this round's correction "
                             "alone; if the control holds CEC tables, give their file as a further --current")
            outputs = sorted({names[t.output] for _, t in placed})
            notes.append("load the CEC file with MD32710 $MA_CEC_ENABLE = 0 on " + ", ".join(outputs)
                         + " (K3 03/2013 p.237: tables load only with the compensation off), then set it to "
                           "1 "
                           "and NEWCONF")
            for k, t in placed:
                if t.effect not in slots:      # a table the control has not held: its data first
                    notes.append(f"CEC table {k} is new: MD18342 $MN_MM_CEC_MAX_POINTS[{k}] >= "
                                 f"{len(t.values)} "
                                 "(static memory, formatted at the next run-up: archive first), SD41300 "
                                 f"$SN_CEC_TABLE_ENABLE[{k}] = 1 (K3 03/2013 p.245)")
        if p.squareness:
            notes.append("squareness goes to linear CEC tables: " + ", ".join(p.squareness))
        return EditFiles(files, tuple(notes))

    def loaded_tables(self, machine: Machine, state: str, where: str) -> list[CompTable]:
        return read_cec(state, machine, where) if "$AN_CEC" in state else []

    @staticmethod
    def _plain(machine: Machine, t: CompTable) -> CompTable:
        """A table as the control can hold it: a turn of a full-turn axis is a modulo table
        only on a modulo axis (MD30310); on another it repeats over the axis's travel."""
        if not t.modulo:
            return t
        modulo = machine.sinumerik.get("modulo")
        if modulo is None:
            raise CompgenError(f"a table over {t.input}'s turn ({t.effect}) is modulo only on a modulo axis, "
                               "and "
                               "the machine file does not say whether it is",
                               where=f"{machine.source}: [sinumerik] modulo",
                               hint=f'add modulo = ["{t.input}"] (MD30310 ROT_IS_MODULO = 1) or modulo = []')
        return t if t.input in modulo else unrolled(t, machine.axis(t.input).travel, SPAN_DEG)

    def since(self, machine: Machine, measured: str, current: str, where: str) -> Held:
        if machine.sinumerik is None:
            raise CompgenError(f"machine file {machine.source} has no [sinumerik] section")
        then = read_carr(measured, where, machine.sinumerik["tcarr"])
        return Held(read_lines(current, machine, then, nominal_lines(machine)), {})

    def beyond_nominal(self, machine: Machine, current: str, where: str) -> Held:
        # the record at the machine file's geometry: fine offsets zero, the vectors it holds
        if machine.sinumerik is None:
            raise CompgenError(f"machine file {machine.source} has no [sinumerik] section")
        nominal = {n: 0.0 for idx in FINE.values() for n in idx}
        for i, a in enumerate(carr_axes(machine), start=1):
            nominal.update(zip(VECTOR[i], machine.sinumerik["vectors"][a.name], strict=True))
        return Held(read_lines(current, machine, nominal, nominal_lines(machine)), {})

    def reads(self, text: str) -> bool:
        return "$TC_CARR" in text or "$AN_CEC" in text

    def read(self, machine: Machine, text: str, current: str | None, held: Held, where: str) -> Held:
        if "$AN_CEC" in text:      # a table loaded into a place replaces the one there
            tables = read_cec(text, machine, where)
            places = {t.effect for t in tables}
            return Held(held.lines, held.squareness,
                        (*(t for t in held.tables if t.effect not in places), *tables))
        if current is None or machine.sinumerik is None:
            raise CompgenError("a $TC_CARR program needs --current and the machine's [sinumerik]",
                               where=where)
        state = read_carr(current, "current", machine.sinumerik["tcarr"])
        return Held(read_lines(text, machine, state, held.lines), held.squareness, held.tables)
