"""What a fit asks of any control, in no controller's syntax.

A control can hold:
* the rotary axis lines (``lines.py``);
* the squareness of the linear axes;
* position-dependent translation errors of linear axes and positioning errors of rotary
  axes, as single-axis compensation tables (SINUMERIK CEC, HEIDENHAIN axis-error tables).
Everything else is not compensable. The ball offset (XOW YOW ZOW) and nest offsets are
set-up, not machine errors, and are never written. Every effect is evaluated through the
model (``Model``), never by re-implementing its basis.

A fit of data measured under TCPM/TRAORI gives errors relative to the kinematics the
control held during the measurement, so corrections add to the values held then.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import CompgenError
from ..model.effects import POLY_SCALE_MM, ROT_OF, TRANSLATIONS, effect_name, effect_of_param
from ..model.kinematics import Model
from ..model.lines import AxisLine, axis_lines, controller_inverse, nominal_pivot
from ..model.machine import Machine
from ..model.poses import Poses
from ..statistics.results import FitResult
from ..transforms import rot_exact

ARCSEC = np.pi / 648000.0
TABLE_POINTS = 37        # interpolation points of a generated compensation table
PER_PITCH = 8            # table points a periodic error needs per pitch


@dataclass(frozen=True)
class CompTable:
    """A single-axis compensation table: ``values`` (in ``unit``, mm or deg) are added to
    the ``output`` axis as a function of the ``input`` axis on an even grid."""

    effect: str
    words: str
    input: str
    output: str
    start: float
    stop: float
    values: tuple[float, ...]
    modulo: bool
    unit: str
    points: tuple[float, ...] = ()   # the input positions where they are uneven (a LinuxCNC table's)

    def __post_init__(self):
        # uneven positions and the range must say the same: start and stop are what every
        # control's writer and the composing of rounds read
        if self.points and (len(self.points) != len(self.values) or self.points[0] != self.start
                            or self.points[-1] != self.stop or any(np.diff(self.points) <= 0)):
            raise ValueError(f"{self.effect}: its positions {self.points[:3]}… do not run from {self.start} "
                             f"to {self.stop} over its {len(self.values)} values")

    @property
    def step(self) -> float:
        return (self.stop - self.start) / (len(self.values) - 1)

    @property
    def grid(self) -> np.ndarray:
        return np.array(self.points) if self.points else np.linspace(self.start, self.stop, len(self.values))

    def at(self, x: np.ndarray) -> np.ndarray:
        """Its values at input positions ``x`` as a control interpolates them: linearly, the
        end values held beyond the ends, a modulo table's input wrapped into its range."""
        if self.modulo:
            x = self.start + np.mod(x - self.start, self.stop - self.start)
        return np.interp(x, self.grid, self.values)


def unrolled(t: CompTable, travel: tuple[float, float], span: float) -> CompTable:
    """A modulo table as a plain one over the axis's ``travel`` (within ±``span``), for a
    control that does not wrap the table's input: its turn repeated on the same step."""
    first = np.ceil(max(travel[0], -span) / t.step) * t.step
    grid = np.arange(first, min(travel[1], span) + t.step / 2, t.step)
    values = np.interp(t.start + np.mod(grid - t.start, t.stop - t.start), t.grid, t.values)
    return CompTable(t.effect, t.words, t.input, t.output, float(grid[0]), float(grid[-1]),
                     tuple(float(v) for v in values), False, t.unit)


def compose_tables(loaded: list[CompTable], new: list[CompTable]) -> list[CompTable]:
    """The tables a control holds once an edit's ``new`` tables are added to the ``loaded``
    ones (an earlier round's, the OEM's): the new tables of one input and output axis are
    summed into the loaded table of those axes, which keeps its place (``effect`` is the
    control's slot) — on its own grid where the new ones share it, else on the finer step
    over both ranges, each interpolated as the control does (``CompTable.at``); a loaded
    table no new one adds to stays as it is; a new pair takes a new place."""
    out, fresh = list(loaded), {n.effect for n in new}
    for t in new:
        k = next((i for i, o in enumerate(out) if (o.input, o.output) == (t.input, t.output)
                  and o.effect not in fresh), None)
        if k is None:
            out.append(t)
            continue
        old = out[k]
        if old.modulo != t.modulo or old.unit != t.unit:
            raise CompgenError(f"the loaded table of {old.input} -> {old.output} ({old.effect}) is "
                               f"{'modulo' if old.modulo else 'not modulo'} in {old.unit}; the new one "
                               f"{'is' if t.modulo else 'is not'} modulo in {t.unit}: compgen does not add "
                               "them",
                               hint="write this round's table to a free place by hand, or remove the old one")
        grid = old.grid
        if len(grid) == len(t.grid) and np.allclose(grid, t.grid, rtol=0, atol=2e-6):
            values = np.add(old.values, t.values)
        else:
            lo, hi = min(old.start, t.start), max(old.stop, t.stop)
            if old.points or t.points:     # both tables' points, one where they agree to a file's rounding
                grid = np.unique(np.concatenate([old.grid, t.grid]))
                grid = grid[np.concatenate([[True], np.diff(grid) > 2e-6])]
            else:
                grid = np.linspace(lo, hi, int(round((hi - lo) / min(old.step, t.step))) + 1)
            values = old.at(grid) + t.at(grid)
        even = not (old.points or t.points)
        out[k] = CompTable(old.effect, f"{old.words} + {t.effect}".strip(" +"), old.input, old.output,
                           float(grid[0]), float(grid[-1]), tuple(float(v) for v in values), old.modulo,
                           old.unit, () if even else tuple(float(x) for x in grid))
    return out


@dataclass(frozen=True, eq=False)
class Plan:
    """Everything a kinematics edit needs, independent of the controller's syntax."""

    lines: dict[str, AxisLine]
    squareness: dict[str, float]           # COX, AOZ, BOZ: rad
    tables: tuple[str, ...]                # effects a single-axis table holds exactly
    not_compensable: tuple[str, ...]
    setup: tuple[str, ...]                 # set-up terms left out on purpose
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
            tables.append(name)
        else:
            other.append(name)
    bad = [n for n, v in values.items() if not np.isfinite(v)]
    if bad:
        raise CompgenError(f"{', '.join(bad)} {'is' if len(bad) == 1 else 'are'} not a finite number",
                           hint="refit: no edit is written from a damaged fit")
    p = Plan(lines, squareness, tuple(tables), tuple(other), tuple(setup), values)
    _check_bounds(machine, p, force)
    return p


def _compensable_by_table(machine: Machine, e) -> bool:
    """A translation error of a linear axis ahead of every rotary axis in its chain, or the
    positioning error of a rotary axis: single-axis tables hold those exactly."""
    axis = machine.axis(e.carrier)
    step = float(np.diff(_grid(axis))[0])
    if e.basis.kind in ("s", "l"):      # a declared shape's corners: two table steps apart at least
        at = np.degrees(e.basis.at) if axis.rotary else np.asarray(e.basis.at) * POLY_SCALE_MM
        if step > np.diff(at).min() / 2:
            return False
    if axis.rotary:
        return e.direction == ROT_OF[axis.direction]
    if e.basis.kind == "w" and step > e.basis.pitch / PER_PITCH:
        return False              # a table this coarse would alias the period
    chain = machine.workpiece if axis.side == "workpiece" else machine.tool
    ahead = chain[:chain.index(axis)]
    return e.direction in TRANSLATIONS and not any(a.rotary for a in ahead)


def _check_bounds(machine: Machine, p: Plan, force: bool) -> None:
    """Every correction the edit writes against [limits]: lines, squareness and tables
    (``not <=`` so that a NaN is never within bounds)."""
    lim = machine.limits
    too_big = []

    def check(what: str, value: float, unit: str) -> None:
        limit = lim.offset_um if unit == "um" else lim.tilt_arcsec
        if not value <= limit:
            too_big.append(f"{what} {value:.1f} {unit} > {limit:g} {unit}")
    for line in p.lines.values():
        check(f"{line.axis} line offset", np.abs(line.offset).max() * 1e3, "um")
        check(f"{line.axis} line tilt", np.abs(line.tilt).max() / ARCSEC, "arcsec")
    for name, v in p.squareness.items():
        check(name, abs(v) / ARCSEC, "arcsec")
    for t in comp_tables(machine, p):
        peak = np.abs(t.values).max()
        check(f"{t.effect} table", *((peak * 3600, "arcsec") if t.unit == "deg" else (peak * 1e3, "um")))
    if too_big and not force:
        raise CompgenError("correction beyond the plausibility limits: " + "; ".join(too_big),
                           hint="Check the R-test set-up and the fit first; a real error this large "
                                "needs the OEM. Raise [limits] in the machine file or use --beyond-limits")


def rest(machine: Machine, p: Plan, held: Held, force: bool = False) -> Plan:
    """The part of ``p`` still to write when the control already holds ``held`` (relative to
    the state the data were measured in): offsets and tilts add to first order."""
    lines = {n: replace(line, offset=line.offset - held.lines[n].offset, tilt=line.tilt - held.lines[n].tilt)
             for n, line in p.lines.items()}
    squareness = {k: p.squareness.get(k, 0.0) - held.squareness.get(k, 0.0)
                  for k in {**p.squareness, **held.squareness}}
    p = Plan(lines, squareness, p.tables, p.not_compensable, p.setup, p.fit_params)
    _check_bounds(machine, p, force)
    return p


def lines_text(p: Plan) -> list[str]:
    """The corrections in words, µm and arcsec, for every file's header."""
    out = []
    for n, line in p.lines.items():
        # an inclined line in its own frame, as the fit names its errors (XOB along B's own x)
        frame = rot_exact(line.incline)[:3, :3]
        offset, tilt = line.offset @ frame, line.tilt @ frame
        own = f"{n}'s own " if line.inclined else ""
        out.append(f"{n} line at its pivot: offset " + ", ".join(
            f"{own}{t.upper()} {offset[i] * 1e3:+.2f} um" for i, t in enumerate("xyz") if t != line.nominal)
            + "; tilt " + ", ".join(f"about {own}{t.upper()} {tilt[i] / ARCSEC:+.2f} arcsec"
                                    for i, t in enumerate("xyz") if t != line.nominal))
    return out + [f"{n} squareness {v / ARCSEC:+.2f} arcsec" for n, v in p.squareness.items()]


def pivot_of(machine: Machine, name: str) -> np.ndarray:
    """Nominal pivot of a rotary axis at the zero pose: the sum of the offsets up to it."""
    for chain in (machine.workpiece, machine.tool):
        names = [a.name for a in chain]
        if name in names:
            return nominal_pivot(chain, names.index(name))
    raise CompgenError(f"no axis {name}")


def nominal_lines(machine: Machine) -> dict[str, AxisLine]:
    return {a.name: AxisLine.of(a, pivot_of(machine, a.name)) for a in machine.rotary_axes}


# ---------------------------------------------------------------------------- compensation tables

def comp_tables(machine: Machine, p: Plan) -> list[CompTable]:
    """For each compensable effect, the table that cancels its deviation: on a grid over
    its axis, the value to add to the output axis."""
    out = []
    for effect in p.tables:
        names = [n for n in p.fit_params if effect_name(n) == effect]
        e = effect_of_param(machine, names[0])
        axis = machine.axis(e.carrier)
        if axis.rotary:               # an angle error: undo it on the axis itself
            grid = _grid(axis)
            comp = -np.degrees(_positioning_error(machine, axis, names, p.fit_params, grid))
            out.append(_table(effect, e.words, axis, axis.name, grid, comp, "deg"))
        else:
            out.append(_cancel_on_linear_axis(machine, axis, names, [p.fit_params[n] for n in names],
                                              effect, e.words, "xyz".index(e.direction)))
    return out


def squareness_tables(machine: Machine, p: Plan) -> list[CompTable]:
    """A squareness as a linear table: output axis along the tilt, input the tilted axis."""
    return [_cancel_on_linear_axis(machine, machine.axis(name[2]), [name], [value], name,
                                   f"squareness {name}") for name, value in p.squareness.items()]


def _grid(axis) -> np.ndarray:
    """Table positions over the axis (a whole turn for a full-turn axis, else its travel) on
    a round step, the finest of 1, 2, 2.5, 5 × 10^k that needs at most TABLE_POINTS: one
    whose multiples are both ends where there is one, else from a multiple at or below the
    start to one at or above the end. Controls place each value at MIN + n·STEP: a round
    step that divides the range is written exactly."""
    lo, hi = (0.0, 360.0) if axis.full_turn else axis.travel
    steps = [m * 10.0 ** k for k in range(-3, 7) for m in (1.0, 2.0, 2.5, 5.0)]
    for exact in (True, False):
        for step in steps:
            first, last = np.floor(lo / step + 1e-9), np.ceil(hi / step - 1e-9)
            if exact and (abs(first * step - lo) > 1e-9 or abs(last * step - hi) > 1e-9):
                continue
            if last - first + 1 <= TABLE_POINTS:
                return np.arange(first, last + 1) * step
    raise CompgenError(f"{axis.name}'s travel {lo:g}..{hi:g} is too long for a compensation table")


def _table(effect, words, axis, out_axis, grid, values, unit) -> CompTable:
    return CompTable(effect, words, axis.name, out_axis, float(grid[0]), float(grid[-1]),
                     tuple(float(v) for v in values), axis.full_turn, unit)


def _alone(machine: Machine, axis, grid_deg_or_mm: np.ndarray) -> Poses:
    """Poses with ``axis`` alone moved over the grid (deg for a rotary axis, mm otherwise)."""
    q = np.zeros((len(grid_deg_or_mm), len(machine.axes)))
    q[:, machine.index(axis.name)] = np.radians(grid_deg_or_mm) if axis.rotary else grid_deg_or_mm
    return Poses.at(q, machine.ball)


def _cancel_on_linear_axis(machine: Machine, axis, names, values, effect: str, words: str,
                           k: int | None = None) -> CompTable:
    """A table on the linear axis along machine direction ``k`` (default: the direction the
    effect moves most) cancelling the effect's deviation as ``axis`` alone moves."""
    grid = _grid(axis)
    dev = Model(machine, names).deviation(_alone(machine, axis, grid), np.array(values))
    k = int(np.argmax(np.abs(dev).max(axis=0))) if k is None else k
    out_axis = next(a.name for a in machine.axes if not a.rotary and a.direction == "xyz"[k])
    return _table(effect, words, axis, out_axis, grid, -dev[:, k] / _gain(machine, out_axis, k), "mm")


def _positioning_error(machine: Machine, axis, names, params, grid_deg) -> np.ndarray:
    """A rotary axis's positioning error (rad, in the sense of its commanded angle) at the
    grid angles, through the model: the angle the axis must be turned back by so that the
    model's reading equals the nominal one."""
    model = Model(machine, names)
    values = np.array([params[n] for n in names])
    # the error enters as the angle turned in addition to the command: its gain is the
    # model's own derivative with respect to the commanded angle
    poses = _alone(machine, axis, grid_deg)
    dev = model.deviation(poses, values)
    i = machine.index(axis.name)
    step = 1e-6
    q_up = poses.q.copy()
    q_up[:, i] += step
    nominal = Model(machine, ())
    gain = (nominal.relative(Poses.at(q_up, machine.ball)) - nominal.relative(poses)) / step
    lever = np.sum(gain**2, axis=1)
    return np.where(lever > 0, np.sum(dev * gain, axis=1) / np.where(lever > 0, lever, 1.0), 0.0)


def _gain(machine: Machine, axis_name: str, k: int) -> float:
    """∂(nest − ball)_k / ∂q of a linear axis on the nominal machine (+1 on ISO 841 machines)."""
    q = np.zeros((2, len(machine.axes)))
    q[1, machine.index(axis_name)] = 1.0
    rel = Model(machine, ()).relative(Poses.at(q, machine.ball))
    return float(rel[1, k] - rel[0, k])


def apply_tables(machine: Machine, tables, q: np.ndarray) -> np.ndarray:
    """Commanded poses (mm, rad) with the tables' compensation added, as a control adds it."""
    q = q.copy()
    for t in tables:
        i, o = machine.index(t.input), machine.index(t.output)
        comp = t.at(np.degrees(q[:, i]) if machine.axes[i].rotary else q[:, i])
        q[:, o] += np.radians(comp) if machine.axes[o].rotary else comp
    return q


# ---------------------------------------------------------------------------- what a control holds

@dataclass(frozen=True, eq=False)
class Held:
    """What a control holds: rotary axis lines, linear squareness (rad) and compensation
    tables; ``drive`` gives the axis positions it commands for nominal poses."""

    lines: dict[str, AxisLine]
    squareness: dict[str, float]
    tables: tuple[CompTable, ...] = ()

    def drive(self, machine: Machine, poses: Poses) -> np.ndarray:
        rotary = poses.q[:, [machine.index(a.name) for a in machine.rotary_axes]]
        q = controller_inverse(machine, self.lines, rotary, poses.ball, self.squareness, poses.nest)
        return apply_tables(machine, self.tables, q)
