"""The ``$TC_CARR`` kinematic record: read from the control's lines, checked against the
machine file, and the values an edit writes (fine offsets, axis vectors)."""

from __future__ import annotations

import re

import numpy as np

from ...errors import CompgenError
from ...model.lines import AxisLine
from ...model.machine import Machine
from ...transforms import rot_exact
from ...units import number
from .. import fmt_plain
from ..base import state_lines
from ..correction import (
    Plan,
)

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
        out[a.name] = AxisLine.of(a, lines[a.name].pivot, t, _turn(was, dv))
    return out


def _turn(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation vector (rad) turning direction ``a`` onto ``b`` by the shortest way."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis)
    return np.zeros(3) if s == 0 else axis / s * np.arctan2(s, a @ b)


