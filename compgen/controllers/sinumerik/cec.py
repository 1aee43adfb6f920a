"""CEC compensation tables (``$AN_CEC``): read as the control interpolates them, and written
with the state a loaded table holds (its direction, its multiplying table) kept."""

from __future__ import annotations

from decimal import Decimal

from ...errors import CompgenError, one_line
from ...model.machine import Machine
from ...units import number
from .. import ascii_text, fmt_plain
from ..base import state_lines
from ..correction import (
    CompTable,
)
from .carr import CEC

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


