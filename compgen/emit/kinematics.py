"""Kinematics edits and compensation tables from a fit.

What a control can hold of a fit:
* the rotary axis lines (``lines.py``): HEIDENHAIN ``Trans`` rows around ``MachAxis``,
  SINUMERIK ``$TC_CARR`` offset vectors and direction vectors;
* the squareness of the linear axes: HEIDENHAIN rows around ``MachAxis X/Z`` (manual
  p.684 shows ``B0X``/``C0X``), SINUMERIK a linear CEC table;
* position-dependent translation errors of linear axes and positioning errors of rotary
  axes: SINUMERIK CEC tables (Function Manual K3, 03/2013), HEIDENHAIN axis-error tables
  (values only: their file layout is unconfirmed, U8).
Everything else is listed as not compensable on that control. The ball offset (XOW YOW ZOW)
and nest offsets are set-up, not machine errors, and are never written.

A fit of data measured under TCPM/TRAORI gives errors relative to the kinematics the
control held during the measurement, so corrections add to the current values.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..effects import ROT_OF, ROTATIONS, TRANSLATIONS, effect_name, effect_of_param
from ..errors import CompgenError
from ..kinematics import Model, Poses, inverse
from ..lines import AxisLine, axis_lines, controller_inverse
from ..machine import Machine
from ..results import FitResult
from . import Emitted, ascii_text, controller, fmt_plain, fmt_signed, render
from .programs import measure_program, program_name

ARCSEC = np.pi / 648000.0
MM_DECIMALS = 5          # 0.01 µm
DEG_DECIMALS = 7         # 0.0004″
CEC_POINTS = 37          # interpolation points of a generated CEC table
BACKUP = {
    "linuxcnc": "a copy of the HAL file that sets the trt kinematics pins",
    "itnc530": "copy the kinematics description table (*.TAB), or Cycle 450 SAVE KINEMATICS",
    "tnc640": "save the machine configuration, or Cycle 450 SAVE KINEMATICS",
    "sinumerik840d": "a commissioning archive, and keep the _RESTORE program",
}


@dataclass(frozen=True)
class Row:
    """One HEIDENHAIN ``Trans`` row: ``doc`` is its ISO name (``Y0A``, ``-Y0A`` after)."""

    doc: str
    axis: str          # X Y Z (mm) or A B C (deg)
    coord: float


@dataclass(frozen=True, eq=False)
class Plan:
    """Everything a kinematics edit needs, independent of the controller's syntax."""

    lines: dict[str, AxisLine]
    squareness: dict[str, float]           # COX, AOZ, BOZ: rad
    tables: list[dict]                     # compensable position-dependent effects
    not_compensable: list[str]
    setup: list[str]                       # set-up terms left out on purpose
    fit_params: dict[str, float]


def plan(machine: Machine, fit: FitResult, force: bool = False) -> Plan:
    """Split a fit into what a control can hold, checking every correction's size."""
    values = {n: e.value for n, e in fit.parameters.items()}
    lines = axis_lines(machine, values)
    squareness, tables, other, setup = {}, [], [], []
    linear = {a.name for a in machine.axes if not a.rotary}
    effects = {}
    for param in fit.model:
        effects.setdefault(effect_name(param), effect_of_param(machine, param))
    for name, e in effects.items():
        if e.carrier in ("ball", "nest"):
            setup.append(name)
        elif e.basis.kind == "const" and e.carrier in linear:
            squareness[name] = values[name]
        elif e.basis.kind == "const":
            continue                                   # rotary location: in the lines
        elif _compensable_by_table(machine, e):
            tables.append({"effect": name, "axis": e.carrier, "words": e.words})
        else:
            other.append(name)
    _check_bounds(machine, lines, squareness, force)
    return Plan(lines, squareness, tables, other, setup, values)


def held_lines(p: Plan, family: str) -> dict[str, AxisLine]:
    """The axis lines a control of ``family`` can hold: LinuxCNC's trt kinematics takes the
    line positions but no tilt; the others take both."""
    if family != "linuxcnc":
        return p.lines
    return {n: AxisLine(n, line.nominal, line.pivot, line.offset, np.zeros(3)) for n, line in p.lines.items()}


def _compensable_by_table(machine: Machine, e) -> bool:
    """A translation error of a linear axis ahead of every rotary axis in its chain, or the
    positioning error of a rotary axis: single-axis tables hold those exactly."""
    axis = machine.axis(e.carrier)
    if axis.rotary:
        return e.direction == ROT_OF[axis.direction]
    chain = machine.workpiece if axis.side == "workpiece" else machine.tool
    ahead = chain[:chain.index(axis)]
    return e.direction in TRANSLATIONS and not any(a.rotary for a in ahead)


def _check_bounds(machine: Machine, lines, squareness, force: bool) -> None:
    lim = machine.limits
    too_big = []
    for line in lines.values():
        off = np.abs(line.offset).max() * 1e3
        tilt = np.abs(line.tilt).max() / ARCSEC
        if off > lim.offset_um:
            too_big.append(f"{line.axis} line offset {off:.1f} um > {lim.offset_um:g} um")
        if tilt > lim.tilt_arcsec:
            too_big.append(f"{line.axis} line tilt {tilt:.1f} arcsec > {lim.tilt_arcsec:g} arcsec")
    for name, v in squareness.items():
        if abs(v) / ARCSEC > lim.tilt_arcsec:
            too_big.append(f"{name} {v / ARCSEC:.1f} arcsec > {lim.tilt_arcsec:g} arcsec")
    if too_big and not force:
        raise CompgenError("correction beyond the plausibility limits: " + "; ".join(too_big),
                           hint="check the R-test set-up and the fit first; a real error this large "
                                "needs the OEM. Raise [limits] in the machine file or use --force")


# ---------------------------------------------------------------------------------- HEIDENHAIN

def heidenhain_rows(machine: Machine, p: Plan) -> dict[str, tuple[list[Row], list[Row]]]:
    """Rows before and after each ``MachAxis``: error rows, then the inverse in reverse."""
    out = {}
    for name, line in p.lines.items():
        d = line.nominal
        before = [Row(f"{t.upper()}0{name}", t.upper(), line.offset["xyz".index(t)])
                  for t in TRANSLATIONS if t != d]
        before += [Row(f"{r.upper()}0{name}", r.upper(), np.degrees(line.tilt[ROTATIONS.index(r)]))
                   for r in ROTATIONS if r != ROT_OF[d]]
        out[name] = (before, [Row(f"-{r.doc}", r.axis, -r.coord) for r in reversed(before)])
    for name, value in p.squareness.items():       # e.g. COX: Trans C around MachAxis X
        axis, r = name[2], name[0]
        before = [Row(f"{r}0{axis}", r, np.degrees(value))]
        prior = out.get(axis, ([], []))
        out[axis] = (prior[0] + before, [Row(f"-{r}0{axis}", r, -np.degrees(value))] + prior[1])
    return out


KEYS = {"Trans", "MachAxis", "MachBase", "CMO", "ToolAxis", "TOOLFILE", "SUBFILE1", "SUBFILE2"}


@dataclass
class TabTable:
    """A HEIDENHAIN description table as text columns (layout: U4)."""

    name: str
    columns: list[str]
    starts: list[int]
    rows: list[dict]

    @staticmethod
    def parse(text: str, where: str) -> TabTable:
        lines = text.splitlines()
        head = next((i for i, ln in enumerate(lines) if re.match(r"\s*NR\s+", ln) and "KEY" in ln), None)
        if head is None:
            raise CompgenError("no header line with NR and KEY", where=where,
                               hint="give the kinematics description table (*.TAB) of the machine")
        m = re.match(r"BEGIN\s+(\S+?)(?:\.TAB)?\s", lines[0] + " ") if lines else None
        cols = lines[head].split()
        starts = [lines[head].index(c) for c in cols]
        rows = []
        for k, ln in enumerate(lines[head + 1:], start=head + 2):
            if ln.strip().startswith("[END]"):
                break
            if not ln.strip():
                continue
            cells = {c: ln[s:(starts[i + 1] if i + 1 < len(starts) else None)].strip()
                     for i, (c, s) in enumerate(zip(cols, starts, strict=True))}
            if cells.get("KEY") not in KEYS:
                raise CompgenError(f"KEY {cells.get('KEY')!r} is not a kinematics key",
                                   where=f"{where}:{k}",
                                   hint="the table's columns must line up with its header line")
            if cells.get("KEY") == "Trans":
                try:
                    float(cells.get("COORD", ""))
                except ValueError:
                    raise CompgenError(f"Trans row has COORD {cells.get('COORD')!r}, not a number",
                                       where=f"{where}:{k}") from None
            rows.append(cells)
        else:
            raise CompgenError("no [END] line", where=where)
        return TabTable(m[1] if m else Path(where).stem, cols, starts, rows)

    def text(self) -> str:
        widths = [self.starts[i + 1] - self.starts[i] for i in range(len(self.starts) - 1)] + [0]

        def line(cells):
            return "".join(str(cells.get(c, "")).ljust(w)
                           for c, w in zip(self.columns, widths, strict=True)).rstrip()

        body = [line({c: c for c in self.columns})]
        body += [line({**r, "NR": str(i)}) for i, r in enumerate(self.rows)]
        return render("heidenhain/table.TAB.j2", name=self.name, lines=body)


def edit_table(table: TabTable, rows: dict[str, tuple[list[Row], list[Row]]]) -> tuple[TabTable, list[str]]:
    """Add the corrections to the current table: an existing row of the same ISO name (DOC)
    gets its COORD increased; a missing one is inserted next to its ``MachAxis``, the error
    rows just before it in order, the inverse rows just after it in order."""
    if "DOC" not in table.columns:
        raise CompgenError("the current table has no DOC column to name the correction rows",
                           hint="add a DOC column (the enhanced kinematics description has one)")
    new = [dict(r) for r in table.rows]
    diff = []

    def machaxis(axis):
        i = next((i for i, r in enumerate(new) if r.get("KEY") == "MachAxis" and r.get("AXIS") == axis), None)
        if i is None:
            raise CompgenError(f"the current table has no 'MachAxis {axis}' row",
                               hint="is this the table of the machine that was measured?")
        return i

    for axis, (before, after) in rows.items():
        for side, group in (("before", before), ("after", after)):
            for k, row in enumerate(group):
                unit = "mm" if row.axis in "XYZ" else "deg"
                dec = MM_DECIMALS if unit == "mm" else DEG_DECIMALS
                idx = next((i for i, r in enumerate(new) if r.get("DOC") == row.doc), None)
                if idx is not None:
                    old = float(new[idx]["COORD"])
                    new[idx]["COORD"] = fmt_signed(old + row.coord, dec)
                    diff.append(f"{row.doc:<6} Trans {row.axis}  {fmt_signed(old, dec)} -> "
                                f"{new[idx]['COORD']} {unit}")
                    continue
                at = machaxis(axis) if side == "before" else machaxis(axis) + 1 + k
                new.insert(at, {"KEY": "Trans", "AXIS": row.axis, "COORD": fmt_signed(row.coord, dec),
                                "DOC": row.doc})
                diff.append(f"{row.doc:<6} Trans {row.axis}  (new row) -> "
                            f"{fmt_signed(row.coord, dec)} {unit}")
    return TabTable(table.name, table.columns, table.starts, new), diff


# ---------------------------------------------------------------------------------- SINUMERIK

CARR = re.compile(r"^\s*\$TC_CARR(\d+)\[(\d+)\]\s*=\s*(\S+?)\s*(?:;.*)?$")


def read_carr(text: str, where: str, record: int) -> dict[int, float]:
    """``$TC_CARRn[record]=value`` assignments of one record (other lines are ignored)."""
    out = {}
    for k, line in enumerate(text.splitlines(), start=1):
        m = CARR.match(line)
        if m and int(m[2]) == record:
            try:
                out[int(m[1])] = float(m[3])
            except ValueError:
                if m[3].startswith('"'):
                    continue
                raise CompgenError(f"$TC_CARR{m[1]} value {m[3]!r} is not a number",
                                   where=f"{where}:{k}") from None
    return out


FINE = {"l2": (44, 45, 46), "l3": (55, 56, 57), "l4": (58, 59, 60)}
VECTOR = {1: (7, 8, 9), 2: (10, 11, 12)}


def sinumerik_values(machine: Machine, p: Plan,
                     current: dict[int, float]) -> tuple[dict[int, float], list[str]]:
    """New ``$TC_CARR`` values: fine offsets l2, l3, l4 plus the corrections; direction
    vectors v1, v2 as exact unit vectors with the sign the control holds."""
    cfg = machine.sinumerik
    axes = [a for a in machine.rotary_axes]
    if len(axes) != 2 or cfg["kind"] != "P":
        raise CompgenError("compgen writes $TC_CARR for two table axes (kind P) only",
                           hint="this machine's kinematics is not a table-table one")
    t1, t2 = (p.lines[a.name].offset for a in axes)
    delta = {"l2": t1, "l3": t2 - t1, "l4": -t2}
    missing = [n for idx in (*FINE.values(), *VECTOR.values()) for n in idx if n not in current]
    if missing:
        raise CompgenError(f"--current lacks $TC_CARR{missing[0]}[{cfg['tcarr']}] (and "
                           f"{len(missing) - 1} more)",
                           hint="give every fine offset (44-46, 55-60) and vector (7-12) of the "
                                "record as the control holds them")
    new, diff = {}, []
    for vec, idx in FINE.items():
        for k, n in enumerate(idx):
            new[n] = current[n] + delta[vec][k]
            diff.append(f"$TC_CARR{n} ({vec}.{'xyz'[k]} fine) {fmt_plain(current[n], MM_DECIMALS)} -> "
                        f"{fmt_plain(new[n], MM_DECIMALS)} mm")
    for i, a in enumerate(axes, start=1):
        held = cfg["vectors"][a.name]
        now = np.array([current[n] for n in VECTOR[i]])
        if np.abs(now - held).max() > 1e-3:
            raise CompgenError(f"the control's vector for {a.name} {list(now)} is not the one the machine "
                               f"file says it holds {list(held)}", hint="correct [sinumerik] vectors")
        sign = float(held @ np.eye(3)["xyz".index(a.direction)])
        v = sign * p.lines[a.name].direction
        v = v / np.linalg.norm(v)
        for k, n in enumerate(VECTOR[i]):
            new[n] = v[k]
            diff.append(f"$TC_CARR{n} (v{i}.{'xyz'[k]}) {fmt_plain(current[n], 10)} -> {fmt_plain(v[k], 10)}")
    return new, diff


def cec_tables(machine: Machine, p: Plan) -> list[dict]:
    """CEC tables (Function Manual K3): for each compensable effect, the value to add to the
    output axis so the effect's deviation is cancelled, on a grid over the input axis."""
    out = []
    for t in p.tables:
        axis = machine.axis(t["axis"])
        names = [n for n in p.fit_params if effect_name(n) == t["effect"]]
        if axis.rotary:               # an angle error: undo it on the axis itself
            grid = _grid(axis)
            comp = -np.degrees(dev_angle(machine, axis, names, p.fit_params, grid))
            out.append(_table(t["effect"], t["words"], axis, axis.name, grid, comp, "deg"))
        else:
            k = "xyz".index(effect_of_param(machine, names[0]).direction)
            out.append(_cancel_on_linear_axis(machine, axis, names, [p.fit_params[n] for n in names],
                                              t["effect"], t["words"], k))
    return out


def _grid(axis) -> np.ndarray:
    """Table positions over the axis: a whole turn for a full-turn axis, else its travel."""
    lo, hi = (0.0, 360.0) if axis.full_turn else axis.travel
    return np.linspace(lo, hi, CEC_POINTS)


def _table(effect, words, axis, out_axis, grid, values, unit) -> dict:
    return {"effect": effect, "words": words, "input": axis.name, "output": out_axis,
            "min": grid[0], "max": grid[-1], "step": grid[1] - grid[0], "values": values,
            "modulo": axis.full_turn, "unit": unit}


def _cancel_on_linear_axis(machine: Machine, axis, names, values, effect: str, words: str,
                           k: int | None = None) -> dict:
    """A table on the linear axis along machine direction ``k`` (default: the direction the
    effect moves most) cancelling the effect's deviation as ``axis`` alone moves."""
    grid = _grid(axis)
    q = np.zeros((len(grid), len(machine.axes)))
    q[:, machine.index(axis.name)] = grid
    dev = Model(machine, names).deviation(Poses.at(q, machine.ball), np.array(values))
    k = int(np.argmax(np.abs(dev).max(axis=0))) if k is None else k
    out_axis = next(a.name for a in machine.axes if not a.rotary and a.direction == "xyz"[k])
    return _table(effect, words, axis, out_axis, grid, -dev[:, k] / _gain(machine, out_axis, k), "mm")


def dev_angle(machine, axis, names, params, grid) -> np.ndarray:
    """A rotary axis's positioning error (rad) at the grid angles (deg), from its basis."""
    total = np.zeros_like(grid)
    for n in names:
        e = effect_of_param(machine, n)
        total += params[n] * e.basis.values(np.radians(grid))[:, e.params.index(n)]
    return total * axis.sense


def _gain(machine: Machine, axis_name: str, k: int) -> float:
    """∂(nest − ball)_k / ∂q of a linear axis on the nominal machine (+1 on ISO 841 machines)."""
    q = np.zeros((2, len(machine.axes)))
    q[1, machine.index(axis_name)] = 1.0
    rel = Model(machine, ()).relative(Poses.at(q, machine.ball))
    return float(rel[1, k] - rel[0, k])


# ---------------------------------------------------------------------------------- sign check

def sign_check(machine: Machine, p: Plan, controller_name: str, name: str, version: str,
               date: str) -> tuple[str, list[str]]:
    """A short program that turns each rotary axis alone, and the reading change the edit
    should cause at each pose (after minus before, µm): a wrong sign shows in a minute."""
    rows, labels = [], []
    for a in machine.rotary_axes:
        lo, hi = a.travel
        for ang in (0.0, 90.0, 180.0, 270.0) if a.full_turn else (max(lo, -90.0), 0.0, min(hi, 90.0)):
            rot = [np.radians(ang) if b.name == a.name else 0.0 for b in machine.rotary_axes]
            if rot in rows:            # the zero pose is shared by every axis's sweep
                continue
            rows.append(rot)
            labels.append(f"S{len(rows)}_{a.name}{ang:+.0f}")
    rot = np.array(rows)
    ball = np.broadcast_to(machine.ball, (len(rot), 3))
    q_before = inverse(machine, rot, ball)
    q_after = controller_inverse(machine, held_lines(p, controller(controller_name).family), rot, ball)
    truth = Model(machine, list(p.fit_params))
    values = np.array(list(p.fit_params.values()))
    path = np.array(labels, dtype=object)
    at_poses = Poses(q_before, ball, np.zeros(len(rot)), path)
    before = truth.relative(at_poses, values)
    after = truth.relative(Poses(q_after, ball, np.zeros(len(rot)), path), values)
    change = (after - before) * 1e3
    expect = [f"{lab}: dX {c[0]:+.2f}  dY {c[1]:+.2f}  dZ {c[2]:+.2f} um"
              for lab, c in zip(labels, change, strict=True)]
    program = measure_program(machine, at_poses, "sign check",
                              controller_name, "tcpm", name, version, date)
    return program.files[controller(controller_name).program_ext], expect


# ---------------------------------------------------------------------------------- emit

def kinematics_edit(machine: Machine, fit: FitResult, controller_name: str, current: str | None,
                    current_where: str, name: str, version: str, date: str, force: bool = False) -> Emitted:
    """The files of a kinematics edit for one control, with the sign check and notes."""
    ctl = controller(controller_name)
    p = plan(machine, fit, force)
    signcheck, expect = sign_check(machine, p, ctl.name, program_name_for(name, "SIGN"), version, date)
    header = [f"compgen {version} kinematics edit, {date}",
              f"machine: {ascii_text(machine.name)}; controller: {ctl.words}",
              f"from fit: {Path(fit.machine['file']).name} data "
              + ", ".join(Path(d.file).name for d in fit.data),
              "corrections add to the kinematics active while the R-test ran under TCPM/TRAORI",
              "BACKUP FIRST: " + BACKUP[ctl.name],
              f"then run the sign check {program_name_for(name, 'SIGN')}: see its expected changes"]
    lines_txt = [f"{n} line at its pivot: offset " + ", ".join(
        f"{t.upper()} {line.offset[i] * 1e3:+.2f} um" for i, t in enumerate("xyz") if t != line.nominal)
        + "; tilt " + ", ".join(f"about {t.upper()} {line.tilt[i] / ARCSEC:+.2f} arcsec"
                                for i, t in enumerate("xyz") if t != line.nominal)
        for n, line in p.lines.items()]
    lines_txt += [f"{n} squareness {v / ARCSEC:+.2f} arcsec" for n, v in p.squareness.items()]
    notes = [*lines_txt]
    if p.setup:
        notes.append("left out, set-up not machine: " + ", ".join(p.setup))
    files = {}
    if ctl.name == "tnc640" and current is not None:
        raise CompgenError("a TNC 640 keeps its kinematics in the configuration editor, not in a "
                           "*.TAB file", hint="leave out --current: compgen writes the entries to change")
    if ctl.family == "heidenhain":
        rows = heidenhain_rows(machine, p)
        tables = cec_tables(machine, p)
        if current is not None:
            table, diff = edit_table(TabTable.parse(current, current_where), rows)
            files[".TAB"] = table.text()
            notes += ["table changes:", *diff]
        files[".txt"] = render("heidenhain/kinematics.txt.j2", header=header, controller=ctl.name,
                               rows=[{"axis": a, "before": [_row(r) for r in b],
                                      "after": [_row(r) for r in f]} for a, (b, f) in rows.items()],
                               lines=lines_txt, expect=expect,
                               tables=[_table_text(t) for t in tables], other=p.not_compensable,
                               setup=p.setup)
        if tables:
            files[".comp.csv"] = _comp_csv(tables)
    elif ctl.family == "sinumerik":
        if machine.sinumerik is None:
            raise CompgenError(f"machine file {machine.source} has no [sinumerik] section",
                               hint="give tcarr (the record) and the axis vectors the control holds")
        if current is None:
            raise CompgenError("SINUMERIK needs --current: the record's $TC_CARR values as the control "
                               "holds them", hint="copy the $TC_CARR7-12, 44-46, 55-60 lines of the record "
                                                  "from the archive into a file")
        held = read_carr(current, current_where, machine.sinumerik["tcarr"])
        new, diff = sinumerik_values(machine, p, held)
        rec = machine.sinumerik["tcarr"]
        cec = cec_tables(machine, p)
        squares = squareness_tables(machine, p)
        def carr(values):      # vectors are unitless (10 decimals), offsets mm
            return [(n, fmt_plain(v, 10 if n <= 12 else MM_DECIMALS)) for n, v in values.items()]

        files[".MPF"] = render("sinumerik/kinematics.MPF.j2", name=name, header=header, record=rec,
                               values=carr(new), lines=lines_txt, expect=expect)
        files["_RESTORE.MPF"] = render(
            "sinumerik/kinematics.MPF.j2", name=f"{name}_RESTORE", record=rec, lines=[], expect=[],
            header=[f"compgen {version}: restores record {rec} as it was", *header[1:3]],
            values=carr({n: held[n] for n in new}))
        if cec or squares:
            files["_CEC.INI"] = render("sinumerik/cec.INI.j2", header=header,
                                       tables=[_cec_text(t, i) for i, t in enumerate(cec + squares)])
        notes += ["$TC_CARR changes:", *diff]
        if p.squareness:
            notes.append("squareness goes to linear CEC tables: " + ", ".join(p.squareness))
    elif ctl.family == "linuxcnc":
        module, pins, other = linuxcnc_pins(machine, p, current, current_where)
        files[".hal"] = render("linuxcnc/kinematics.hal.j2", header=header, module=module, lines=lines_txt,
                               pins=pins, other=other)
        notes += [f"setp {module}.{n} {v}  (was {w})" for n, v, w in pins]
        notes.append("not expressible in the trt kinematics: " + ", ".join(other))
    files[f"_SIGN{ctl.program_ext}"] = signcheck
    if p.not_compensable:
        notes.append(f"not compensable on {ctl.words} by compgen: " + ", ".join(p.not_compensable))
    notes += ["sign check, expected change of the reading after the edit:", *expect]
    return Emitted(files, tuple(notes))


def program_name_for(name: str, suffix: str) -> str:
    return program_name(f"{name}_{suffix}")


def _row(r: Row) -> dict:
    unit = "mm" if r.axis in "XYZ" else "deg"
    decimals = MM_DECIMALS if unit == "mm" else DEG_DECIMALS
    shown = f"{r.coord * 1e3:+.2f} um" if unit == "mm" else f"{r.coord * 3600:+.2f} arcsec"
    return {"doc": r.doc, "axis": r.axis, "coord": fmt_signed(r.coord, decimals), "unit": unit,
            "shown": shown}


def _table_text(t: dict) -> dict:
    return {**t, "range": f"{t['input']} {t['min']:g}..{t['max']:g} step {t['step']:g}"}


def _comp_csv(tables: list[dict]) -> str:
    out = ["# compgen: values for the control's axis-error compensation tables (U8: the file layout of",
           "# HEIDENHAIN COM tables is unconfirmed: enter these values, this file is not a control file)",
           "effect,input_axis,position,output_axis,compensation,unit"]
    for t in tables:
        for x, v in zip(np.linspace(t["min"], t["max"], len(t["values"])), t["values"], strict=True):
            out.append(f"{t['effect']},{t['input']},{x:.4f},{t['output']},{v:.6f},{t['unit']}")
    return "\n".join(out) + "\n"


def _cec_text(t: dict, index: int) -> dict:
    return {"index": index, "effect": t["effect"], "words": ascii_text(t["words"]), "input": t["input"],
            "output": t["output"], "step": fmt_plain(t["step"], 6), "min": fmt_plain(t["min"], 4),
            "max": fmt_plain(t["max"], 4), "modulo": int(t["modulo"]), "unit": t["unit"],
            "values": [fmt_plain(v, 6) for v in t["values"]]}


def squareness_tables(machine: Machine, p: Plan) -> list[dict]:
    """A squareness as a linear CEC table: output axis along the tilt, input the tilted axis."""
    return [_cancel_on_linear_axis(machine, machine.axis(name[2]), [name], [value], name,
                                   f"squareness {name}") for name, value in p.squareness.items()]


# ---------------------------------------------------------------------------------- readers

def read_heidenhain_lines(text: str, machine: Machine) -> dict[str, AxisLine]:
    """The rotary axis lines a description table (or compgen's change list) holds: the
    ISO-named rows before each ``MachAxis``, checked against their inverse rows after it."""
    rows = []
    for line in text.splitlines():
        m = re.match(r"^\s*(?:\d+\s+)?(?:Trans\s+([XYZABC])\s+(\S+)\s+(-?[XYZABC]0[A-Z])"
                     r"|(-?[XYZABC]0[A-Z])\s+Trans\s+([XYZABC])\s+(\S+))", line)
        if m:
            axis, coord, doc = (m[1], m[2], m[3]) if m[1] else (m[5], m[6], m[4])
            rows.append((doc, axis, float(coord)))
    lines = {}
    for a in machine.rotary_axes:
        mine = {doc: (axis, v) for doc, axis, v in rows if doc.lstrip("-").endswith(a.name)}
        offset, tilt = np.zeros(3), np.zeros(3)
        for doc, (axis, v) in mine.items():
            if doc.startswith("-"):
                continue
            inverse_row = mine.get(f"-{doc}")
            if inverse_row is None or abs(inverse_row[1] + v) > 1e-12:
                raise CompgenError(f"row {doc} has no matching inverse row -{doc}",
                                   hint="error rows before MachAxis need their inverse after it")
            if axis in "XYZ":
                offset["XYZ".index(axis)] = v
            else:
                tilt["ABC".index(axis)] = np.radians(v)
        lines[a.name] = AxisLine(a.name, a.direction, _pivot_of(machine, a.name), offset, tilt)
    return lines


def read_sinumerik_lines(text: str, machine: Machine, current: dict[int, float]) -> dict[str, AxisLine]:
    """The rotary axis lines an emitted ``$TC_CARR`` program sets, relative to ``current``."""
    cfg = machine.sinumerik
    new = read_carr(text, "program", cfg["tcarr"])
    t1 = np.array([new[n] - current[n] for n in FINE["l2"]])
    t2 = t1 + np.array([new[n] - current[n] for n in FINE["l3"]])
    closure = np.array([new[n] - current[n] for n in FINE["l4"]])
    if np.abs(closure + t2).max() > 1.5 * 10.0 ** -MM_DECIMALS:   # three values, each rounded
        raise CompgenError("l4 fine offsets do not close the chain l4 = -(l2 + l3)")
    lines = {}
    for i, (a, t) in enumerate(zip(machine.rotary_axes, (t1, t2), strict=True), start=1):
        held = cfg["vectors"][a.name]
        sign = float(held @ np.eye(3)["xyz".index(a.direction)])
        d = sign * np.array([new[n] for n in VECTOR[i]])
        e = np.eye(3)["xyz".index(a.direction)]
        turn = np.cross(e, d)
        s = np.linalg.norm(turn)
        tilt = np.zeros(3) if s == 0 else turn / s * np.arctan2(s, e @ d)
        lines[a.name] = AxisLine(a.name, a.direction, _pivot_of(machine, a.name), t, tilt)
    return lines


def read_cec(text: str) -> list[dict]:
    """Tables of a CEC file: input and output axis, grid and values."""
    tables: dict[int, dict] = {}
    for line in text.splitlines():
        m = re.match(r"^\$AN_CEC(_[A-Z_]+)?\[(\d+)(?:,(\d+))?\]=\(?([^);\s]+)\)?", line.strip())
        if not m:
            continue
        t = tables.setdefault(int(m[2]), {"values": {}})
        if m[1] is None:
            t["values"][int(m[3])] = float(m[4])
        else:
            t[m[1][1:].lower()] = m[4] if m[1] in ("_INPUT_AXIS", "_OUTPUT_AXIS") else float(m[4])
    for t in tables.values():
        t["values"] = np.array([t["values"][k] for k in sorted(t["values"])])
    return [tables[k] for k in sorted(tables)]


def apply_cec(machine: Machine, tables: list[dict], q: np.ndarray) -> np.ndarray:
    """Commanded poses (mm, rad) with the CEC compensation added, as the control adds it."""
    q = q.copy()
    for t in tables:
        i, o = machine.index(t["input_axis"]), machine.index(t["output_axis"])
        x = np.degrees(q[:, i]) if machine.axes[i].rotary else q[:, i]
        if t["is_modulo"]:
            x = t["min"] + np.mod(x - t["min"], t["max"] - t["min"])
        grid = t["min"] + t["step"] * np.arange(len(t["values"]))
        comp = np.interp(x, grid, t["values"])
        q[:, o] += np.radians(comp) if machine.axes[o].rotary else comp
    return q


def _pivot_of(machine: Machine, name: str) -> np.ndarray:
    for chain in (machine.workpiece, machine.tool):
        names = [a.name for a in chain]
        if name in names:
            return np.sum([np.asarray(a.offset, float) for a in chain[:names.index(name) + 1]], axis=0)
    raise CompgenError(f"no axis {name}")


@dataclass(frozen=True, eq=False)
class ControllerModel:
    """What a control holds after an edit: rotary axis lines, linear squareness (rad) and
    CEC tables; ``drive`` gives the axis positions it commands for nominal poses."""

    lines: dict[str, AxisLine]
    squareness: dict[str, float]
    tables: list[dict]

    def drive(self, machine: Machine, poses: Poses) -> np.ndarray:
        rotary = poses.q[:, [machine.index(a.name) for a in machine.rotary_axes]]
        q = controller_inverse(machine, self.lines, rotary, poses.ball, self.squareness)
        return apply_cec(machine, self.tables, q)


def held_by(machine: Machine, p: Plan, family: str) -> ControllerModel:
    """What a control of ``family`` holds once compgen's edit of plan ``p`` is loaded: the
    lines it can take, the squareness (HEIDENHAIN rows), the CEC tables (SINUMERIK)."""
    if family == "sinumerik":
        tables = cec_tables(machine, p) + squareness_tables(machine, p)
        return ControllerModel(p.lines, {}, [_as_read(t) for t in tables])
    if family == "linuxcnc":
        return ControllerModel(held_lines(p, family), {}, [])
    return ControllerModel(p.lines, dict(p.squareness), [])


def _as_read(t: dict) -> dict:
    """A generated table in the form ``read_cec`` returns, for ``apply_cec``."""
    return {"input_axis": t["input"], "output_axis": t["output"], "min": t["min"], "max": t["max"],
            "step": t["step"], "is_modulo": t["modulo"], "values": np.asarray(t["values"])}


def controller_model(machine: Machine, texts: dict[str, str], current: str | None) -> ControllerModel:
    """Read emitted edit files back as a control would: HEIDENHAIN rows (table or change
    list), a SINUMERIK ``$TC_CARR`` program (relative to ``current``), CEC tables."""
    lines = {a.name: AxisLine(a.name, a.direction, _pivot_of(machine, a.name), np.zeros(3), np.zeros(3))
             for a in machine.rotary_axes}
    squareness, tables = {}, []
    for where, text in texts.items():
        if "$AN_CEC" in text:
            tables += read_cec(text)
        elif "$TC_CARR" in text:
            if current is None or machine.sinumerik is None:
                raise CompgenError("a $TC_CARR program needs --current and the machine's [sinumerik]",
                                   where=where)
            held = read_carr(current, "current", machine.sinumerik["tcarr"])
            lines = read_sinumerik_lines(text, machine, held)
        elif SETP.search(text):
            lines = read_linuxcnc_lines(text, machine, current)
        elif re.search(r"\bTrans\b", text):
            lines = read_heidenhain_lines(text, machine)
            squareness = read_heidenhain_squareness(text, machine)
        else:
            raise CompgenError("not a kinematics edit compgen wrote (no Trans rows, $TC_CARR or $AN_CEC)",
                               where=where)
    return ControllerModel(lines, squareness, tables)


def read_heidenhain_squareness(text: str, machine: Machine) -> dict[str, float]:
    """Squareness rows around a linear ``MachAxis`` (``C0X`` → COX, rad)."""
    out = {}
    linear = {a.name for a in machine.axes if not a.rotary}
    for m in re.finditer(r"(?m)^\s*(?:\d+\s+)?(?:Trans\s+([ABC])\s+(\S+)\s+([ABC])0([XYZ])\b"
                         r"|([ABC])0([XYZ])\s+Trans\s+([ABC])\s+(\S+))", text):
        rot, axis, value = (m[3], m[4], m[2]) if m[1] else (m[5], m[6], m[8])
        if axis in linear:
            out[f"{rot}O{axis}"] = np.radians(float(value))
    return out


# ---------------------------------------------------------------------------------- LinuxCNC

SETP = re.compile(r"^\s*setp\s+(\S+?)\.(\S+)\s+(\S+)", re.MULTILINE)


def _trt(machine: Machine) -> tuple[str, object, object]:
    """The trt module for a two-axis table (A or B tilting, C on it), or a clear refusal."""
    axes = machine.rotary_axes
    if (len(axes) != 2 or any(a.side != "workpiece" for a in axes) or axes[1].direction != "z"
            or axes[0].direction not in "xy"):
        raise CompgenError("LinuxCNC's trt kinematics is for a tilting table (A or B) carrying C",
                           hint="this machine's chain is not one xyzac-/xyzbc-trt-kins can drive")
    return f"xyz{axes[0].name.lower()}c-trt-kins", axes[0], axes[1]


def linuxcnc_pins(machine: Machine, p: Plan, current: str | None,
                  where: str) -> tuple[str, list[tuple[str, str, str]], list[str]]:
    """trt pins (trtfuncs.c): C turns about the line through the rot point, the tilting
    axis about the line through the rot point plus the offsets. Absolute values: the
    current ones (a HAL file) or the machine file's nominal, plus the corrections."""
    module, tilt, c = _trt(machine)
    pivot_c, pivot_t = _pivot_of(machine, c.name), _pivot_of(machine, tilt.name)
    along = "xyz".index(tilt.direction)
    names = ["x-rot-point", "y-rot-point", "z-rot-point"] + [
        f"{'xyz'[k]}-offset" for k in range(3) if k not in (along,)]
    nominal_d = pivot_t - pivot_c
    nominal = {**dict(zip(names[:3], pivot_c, strict=True)),
               **{f"{'xyz'[k]}-offset": nominal_d[k] for k in range(3) if k != along}}
    held = dict(nominal)
    if current is not None:
        found = {m[2]: float(m[3]) for m in map(SETP.match, current.splitlines()) if m and m[1] == module}
        missing = [n for n in names if n not in found]
        if missing:
            raise CompgenError(f"--current sets no {module}.{missing[0]}", where=where,
                               hint=f"give the setp lines of {', '.join(names)}")
        held = found
    delta_r = p.lines[c.name].offset
    delta_d = p.lines[tilt.name].offset - delta_r
    new = {n: held[n] + (delta_r if n.endswith("rot-point") else delta_d)["xyz".index(n[0])] for n in names}
    other = [f"{n} tilt {line.tilt[i] / ARCSEC:+.2f} arcsec about {'XYZ'[i]}"
             for n, line in p.lines.items() for i in range(3) if line.tilt[i] != 0]
    other += list(p.squareness) + [t["effect"] for t in p.tables] + list(p.not_compensable)
    pins = [(n, fmt_plain(new[n], 6), fmt_plain(held[n], 6)) for n in names]
    return module, pins, other


def read_linuxcnc_lines(text: str, machine: Machine, current: str | None = None) -> dict[str, AxisLine]:
    """The axis lines a trt HAL edit sets, relative to ``current`` (default: nominal)."""
    module, tilt, c = _trt(machine)
    now = {m[2]: float(m[3]) for m in map(SETP.match, text.splitlines()) if m and m[1] == module}
    before = ({m[2]: float(m[3]) for m in map(SETP.match, current.splitlines()) if m and m[1] == module}
              if current else None)
    pivot_c, pivot_t = _pivot_of(machine, c.name), _pivot_of(machine, tilt.name)
    if before is None:
        before = {"x-rot-point": pivot_c[0], "y-rot-point": pivot_c[1], "z-rot-point": pivot_c[2],
                  **{f"{'xyz'[k]}-offset": (pivot_t - pivot_c)[k] for k in range(3)}}
    r = np.array([now[f"{a}-rot-point"] - before[f"{a}-rot-point"] for a in "xyz"])
    d = np.array([now.get(f"{a}-offset", 0.0) - before.get(f"{a}-offset", 0.0) for a in "xyz"])
    zero = np.zeros(3)
    return {c.name: AxisLine(c.name, c.direction, pivot_c, r, zero),
            tilt.name: AxisLine(tilt.name, tilt.direction, pivot_t, r + d, zero)}
