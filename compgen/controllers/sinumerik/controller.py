"""The SINUMERIK 840D sl controller: programs under TRAORI, the ``$TC_CARR`` edit with its CEC
tables, and their readers."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from ...errors import CompgenError
from ...model.machine import Machine
from ...motion.blocks import Block
from .. import fmt_plain, render
from ..base import Controller, EditContext, EditFiles, state_lines
from ..correction import (
    CompTable,
    Held,
    Plan,
    compose_tables,
    nominal_lines,
    unrolled,
)
from ..state_guards import require_frame_guard, sinumerik_guard
from .carr import (
    CEC,
    CHAIN,
    COARSE,
    FINE,
    MM_DECIMALS,
    SPAN_DEG,
    VECTOR,
    VECTOR_DECIMALS,
    _carr_lines,
    carr_axes,
    carr_values,
    check_current,
    read_carr,
    read_lines,
)
from .cec import _cec_text, _machine_axes, cec_modes, cec_places, read_cec
from .reader import program_blocks


def _cec_files(machine: Machine, tables: list[CompTable], loaded: list[CompTable], current: str, where: str,
               ctx: EditContext) -> tuple[dict[str, str], list[str]]:
    """This round's CEC tables composed with those loaded (``tables``), their file and the
    file that restores them, and what loading them needs; refused where a loaded table acts
    one way or through another's factor (this round's trims act both ways and alone)."""
    files: dict[str, str] = {}
    notes: list[str] = []
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
    return files, notes


class Sinumerik840D(Controller):
    """The SINUMERIK 840D sl: programs (.MPF) under TRAORI, the edit as the orientable
    toolholder's $TC_CARR record and CEC compensation tables."""

    name = "sinumerik840d"
    family = "sinumerik"
    words = "SIEMENS SINUMERIK 840D sl"
    program_ext = ".MPF"
    comment = ";"
    tcp_words = "TRAORI"
    plc_index = "stop"
    backup = "a commissioning archive, and keep the _RESTORE program"
    pose_line = re.compile(r"^G1 X(\S+) Y(\S+) Z(\S+) ((?:[A-C]\S+ )+)F\S+ ; pose (\d+)")
    tcpm_on = re.compile(r"^TRAORI\b", re.MULTILINE)
    tcp_switchable = True
    holds_inclined = True         # the generic transformations' axis vectors, $TC_CARR7-12
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
            # an inclined axis's vector is written to the digits a user has (0.707107): a
            # unit vector to 1e-6, along the axis to 1e-6 rad (0.2″)
            if abs(np.linalg.norm(v) - 1) > 1e-6 or np.linalg.norm(np.cross(v, a.unit)) > 1e-6:
                words = f"±{a.direction}" if not a.inclined else f"±{a.unit_text}"
                raise CompgenError(f"must be the unit vector {words} the control holds for "
                                   f"{a.name}, got {v.tolist()}", where=get.sub("vectors").at(a.name))
            vectors[a.name] = v / np.linalg.norm(v)
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
            cec, more = _cec_files(machine, tables, loaded, current, where, ctx)
            files.update(cec)
            notes += more
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
