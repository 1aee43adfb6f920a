"""THE catalogue of physical effects: every error compgen can model is declared here, once.

An effect is a named error with a basis in one coordinate. Names (ISO 230 symbols, with the
letter O as in the seed report; ``X0C`` and ``E_X0C`` are accepted at input):

=====================  ====================================================================
``XOC``                constant: a location error (``<dir>O<axis>``), or a set-up offset
``ECC:h2``             2nd harmonic of a component error of a rotary axis; parameters
                       ``ECC:h2c`` (× cos 2C) and ``ECC:h2s`` (× sin 2C). On a tilting axis
                       the shapes are taken from angle 0: ``EZA:h1c`` × (cos A − 1) (gravity
                       and bearings: sin A and 1 − cos A)
``EXC+EYC:h2``         a 2-D error motion of a rotary axis as ISO 230-7 describes it: the
                       radial (or tilt) vector of size r turning *with* the axis at 2/rev,
                       (EXC, EYC) = r·(cos(2C + φ), sin(2C + φ)) with C the angle turned (the
                       coordinate times the axis's sense); ``:h-2`` turns against it.
                       Parameters ``…:h2c`` = r·cos φ and ``…:h2s`` = r·sin φ; the pair is
                       named in the axis's right-handed order (``EYA+EZA``, ``EZB+EXB``)
``EAA:p1``             1st-order polynomial of a component error of a tilting axis, in the
                       axis angle in rad; of a linear axis, in its position per 1000 mm
                       (so ``EXX:p1`` in µm is a scale error in µm/m)
``drift_Z:t1``         thermal drift of the tool relative to the table along machine Z,
                       polynomial in the session time per hour (µm/h for ``t1``)
``ECC:r1``             reversal of an axis's positioning (backlash): ± the parameter (half
                       the reversal value) by the direction the axis last moved; seen only
                       where the axis moves both ways (a path run there and back)
``XOC:e15``            a location error (or ``drift_Z``) growing as 1 − exp(−t/τ) with τ =
                       15 min: thermal growth that saturates (the value it tends to)
``XOC:t1``             an axis's location error growing linearly in the session time, per
                       hour: a growth that has not begun to saturate
``nest_X``             R-test nest (tool side) set-up offset along the spindle frame X
``EXX:w5``             declared, never in the candidate list unless the machine file's
                       ``[effects] declared`` names it: a periodic component error of a
                       linear axis with a pitch in mm (a ball-screw or scale period),
                       ``EXX:w5c`` × cos(2π·X/5 mm) and ``EXX:w5s`` × sin(2π·X/5 mm)
``EXX:s.screw``        declared: a component error of any axis as a spline through the
                       knots of the machine file's ``[effects.shapes.screw] at`` (mm or deg),
                       linear between, held beyond, zero at the first knot; parameters
                       ``EXX:s.screw.2`` … its value at each later knot
``EXX:l.laser``        declared: the shape of a lookup table (``at``, ``values``: a laser
                       run's, say), scaled to a largest |value| of 1; the parameter is its
                       size there
=====================  ====================================================================

Order 0 of a component error does not exist here on purpose: a constant error motion *is*
a location error (or a set-up offset), and declaring it twice would make the model singular.

Placement in the chain (``kinematics.py``):
* rotary axis: ``Trans(offset)·Trans(loc)·Rot(loc)·Trans(comp)·Rot(comp)·R(angle + E_own)``
  (contract §3, seed eq. 2);
* linear axis: ``Trans(offset)·Trans(comp + q·Rot(loc)·e)·Rot(comp)`` (seed eq. 1): a
  squareness tilts the direction of motion only, not the carried frame;
* component errors displace the carried frame in its parent frame, whatever the axis sense.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import me
from ..errors import CompgenError
from .machine import Axis, Machine

TRANSLATIONS, ROTATIONS = "xyz", "abc"
ROT_OF = dict(zip(TRANSLATIONS, ROTATIONS, strict=True))  # rotation about a direction
POLY_SCALE_MM = 1000.0       # linear-axis polynomials run in q / 1 m
TIME_SCALE_S = 3600.0        # drift polynomials run in t / 1 h
# the candidate list offered by catalogue(), for every axis: a tilting axis's harmonics too
# (an encoder's 4/rev shows over any tilt range of a quarter turn; where the travel is too
# short to see an order, visibility says so and it is never named)
MAX_ORDER = {"h": 4, "p": 3, "t": 2}
TAUS_MIN = (5, 15, 45)       # saturating thermal growth offered: time constants, min
IN_TIME = ("e", "t", "g")    # the bases that run in the readings' time: each needs t
SHAPE_NAME = r"[a-z][a-z0-9_]{0,31}"   # a declared shape's name ([effects.shapes.NAME])


@dataclass(frozen=True)
class Basis:
    """Shape of an effect in its coordinate: constant, harmonic k, polynomial k, time
    polynomial k, saturating in time with τ = ``order`` minutes, a scale (linear in the
    axis's position) saturating in time with τ = ``order`` minutes, periodic along a linear
    axis with a pitch of ``pitch`` mm, or a shape the machine file declares (``label``):
    a spline through ``at`` (a value per knot) or a lookup table (``table`` at ``at``,
    scaled to a largest |value| of 1: the parameter is its size)."""

    kind: str            # "const", "h", "p", "t", "e", "g", "r", "w", "s" or "l"
    order: int = 0       # a compound's harmonic is signed: − turns against the axis
    origin: bool = False  # harmonics of a tilting axis: taken from angle 0 (cos kθ − 1)
    pitch: float = 0.0   # "w": the period along the axis, mm
    label: str = ""      # "s", "l": the shape's name in the machine file
    at: tuple[float, ...] = ()      # "s", "l": its positions, in the coordinate
    table: tuple[float, ...] = ()   # "l": its values, largest |value| 1

    @property
    def suffix(self) -> str:
        if self.kind == "w":
            return f":w{self.pitch:g}"
        if self.kind in ("s", "l"):
            return f":{self.kind}.{self.label}"
        return "" if self.kind == "const" else f":{self.kind}{self.order}"

    @property
    def terms(self) -> tuple[str, ...]:
        if self.kind in ("h", "w"):
            return (f"{self.suffix}c", f"{self.suffix}s")
        if self.kind == "s":           # none at the first knot: zero there (see ``values``)
            return tuple(f"{self.suffix}.{i}" for i in range(2, len(self.at) + 1))
        return (self.suffix,)

    def values(self, x: np.ndarray) -> np.ndarray:
        """(n, len(terms)) basis values at coordinate ``x`` (rad, scaled length or hours)."""
        x = np.asarray(x, dtype=float)
        if self.kind == "const":
            return np.ones(x.shape + (1,))
        if self.kind == "h":
            return np.stack([np.cos(self.order * x) - self.origin, np.sin(self.order * x)], axis=-1)
        if self.kind == "w":              # x: a linear axis's position per POLY_SCALE_MM
            turn = 2 * np.pi * x * (POLY_SCALE_MM / self.pitch)
            return np.stack([np.cos(turn), np.sin(turn)], axis=-1)
        if self.kind == "e":
            return (1 - np.exp(-x * (60.0 / self.order)))[..., None]
        if self.kind in ("r", "g"):       # ±1 by the direction of motion (0: never moved); a
            return x[..., None]           # scale in time: position × growth (``coordinate``)
        if self.kind == "s":              # a hat per knot, linear between, held beyond; none
            # at the first knot: a constant error motion is a location error (order 0 above)
            return np.stack([np.interp(x, self.at, row) for row in np.eye(len(self.at))[1:]], axis=-1)
        if self.kind == "l":
            return np.interp(x, self.at, self.table)[..., None]
        return (x**self.order)[..., None]


CONSTANT = Basis("const")


@dataclass(frozen=True)
class Effect:
    """One physical effect.

    ``carrier`` is the axis whose transform carries it, or ``"ball"``, ``"nest"``,
    ``"time"``; ``slot`` is ``"loc"`` (before the motion) or ``"comp"`` (component error,
    a function of the axis coordinate); ``direction`` is ``x y z`` for a translation (mm)
    and ``a b c`` for a rotation (rad) about x, y, z, or two of them for a vector that
    turns (a compound).
    """

    symbol: str
    carrier: str
    slot: str
    direction: str
    basis: Basis
    words: str
    cause: str = ""
    sense: int = 1       # a compound turns with the axis's physical angle: sense × coordinate

    @property
    def name(self) -> str:
        return self.symbol + self.basis.suffix

    @property
    def params(self) -> tuple[str, ...]:
        return tuple(self.symbol + t for t in self.basis.terms)

    @property
    def unit(self) -> str:
        """Inside unit of each parameter: mm for a translation, rad for a rotation."""
        return "mm" if self.direction[0] in TRANSLATIONS else "rad"

    def parts(self, x: np.ndarray) -> list[tuple[str, np.ndarray]]:
        """(direction, (n, len(params)) values) of each direction the effect moves: one,
        or the two of a compound, whose vector r·(cos, sin)(kθ + φ) is c·(cos kθ, sin kθ) +
        s·(−sin kθ, cos kθ)."""
        return self.split(self.basis.values(x))

    def split(self, b: np.ndarray) -> list[tuple[str, np.ndarray]]:
        """``parts`` from the basis values ``b`` (n, len(terms)) at the coordinate."""
        if len(self.direction) == 1:
            return [(self.direction, b)]
        cos, sin = b[..., 0], self.sense * b[..., 1]
        return [(self.direction[0], np.stack([cos, -sin], axis=-1)),
                (self.direction[1], np.stack([sin, cos], axis=-1))]


def _symbols(machine: Machine) -> dict[str, tuple[str, str, str, tuple[str, ...], str, str, int]]:
    """symbol → (carrier, slot, direction, allowed basis kinds, words, cause, lowest order)."""
    out: dict = {}
    for d in TRANSLATIONS:
        D = d.upper()
        # with a time constant: the set-up in time (the ball's stem or clamp warming after
        # mounting), moving in the table frame, not the machine's (drift_X/Y/Z)
        out[f"{D}OW"] = ("ball", "loc", d, ("const", "e"), f"ball centre offset in {D} (table frame)",
                         "ball not where the machine file says: set-up, not a machine error; "
                         "growing with time: the ball's stem or clamp warming after mounting", 0)
        # with a time constant, along the tool axis: the spindle, or the nest's holder, warming
        # grows along it, and a head turns it, where drift_Z stays along the machine's Z
        out[f"nest_{D}"] = ("nest", "loc", d, ("const", "e") if D == "Z" else ("const",),
                            f"R-test nest offset in {D} (tool frame)",
                            "nest centre off the spindle axis or wrong probe length" + (
                                "; growing with time: the spindle or the nest's holder warming along the "
                                "tool axis" if D == "Z" else ""), 0)
        out[f"drift_{D}"] = ("time", "loc", d, ("t", "e"), f"thermal drift of tool to table in {D}",
                             "warm-up of spindle, column or table during the test", 1)
    for axis in machine.axes:
        out.update(_axis_symbols(axis))
    return out


def _axis_symbols(axis: Axis) -> dict:
    L, d, out = axis.name, axis.direction, {}
    head = axis.rotary and axis.side == "tool"
    tilting = head and abs(axis.unit[2]) < 1 - 1e-9    # it tilts the tool: its weight bends it across
    kinds = ("h",) if axis.full_turn else ("p", "h") if axis.rotary else ("p",)
    for e in TRANSLATIONS + ROTATIONS:
        E = e.upper()
        own = e in (d, ROT_OF[d])
        if axis.rotary:
            if not own:
                about = "tilt about" if e in ROTATIONS else "offset in"
                ref = TRANSLATIONS[ROTATIONS.index(e)].upper() if e in ROTATIONS else E
                if axis.inclined:      # in its own frame: say where that points
                    t = ref.lower()
                    about = about.replace(" in", " along")
                    ref = f"{L}'s own {t} {_shown(axis.frame[:, 'xyz'.index(t)])}"
                out[f"{E}O{L}"] = (L, "loc", e, ("const", "e", "t"), f"{L} axis line {about} {ref}",
                                   "assembly or kinematics table not matching the machine; "
                                   "with a time constant: its thermal growth; in time (t1): a "
                                   "growth that has not begun to saturate", 0)
            if e == ROT_OF[d]:
                words = f"angular positioning error of {L}"
                cause = "encoder eccentricity (1/rev), worm or scale error (2/rev and up)" + (
                    # the tool's weight across its axis bends it as an angle at the pivot
                    # would turn it: one nest length cannot tell the two apart
                    "; a head's sag under its weight (1/rev, as the nest's lever sees it)" if tilting else "")
            elif e == d:
                words, cause = f"axial error motion of {L}", "bearing or face runout"
            elif e in TRANSLATIONS:
                words, cause = f"radial error motion of {L} in {E}", (
                    "the head's sag under its weight as it tilts (2/rev: sin 2θ across, 1 − cos 2θ along); "
                    "bearing runout" if tilting else
                    f"bearing runout, eccentric {'head' if head else 'table'}" if axis.full_turn else
                    "gravity sag of the trunnion and table as the axis tilts (1/rev: sin and 1 − cos); "
                    "bearing runout")
            else:
                about = TRANSLATIONS[ROTATIONS.index(e)].upper()
                words, cause = f"tilt error motion of {L} about {about}", "wobble of the bearing"
        else:
            if e == d:
                words, cause = f"positioning error of {L}", "scale error, thermal growth of the scale"
            elif e in TRANSLATIONS:
                # the linear part of a straightness is a squareness (ISO 230-1), declared
                # once below as COX, AOZ, BOZ; offering both would make them tie
                out[f"E{E}{L}"] = (L, "comp", e, kinds, f"straightness of {L} in {E}",
                                   "guideway straightness (bow)", 2)
                continue
            else:
                names = {"a": "roll", "b": "pitch", "c": "yaw"} if d == "x" else \
                        {"a": "pitch", "b": "roll", "c": "yaw"} if d == "y" else \
                        {"a": "pitch", "b": "yaw", "c": "roll"}
                words, cause = f"{names[e]} of {L}", "guideway twist or bending"
        positioning = e == (ROT_OF[d] if axis.rotary else d)
        # a positioning error linear in position (a scale) may grow in time: the scale or the
        # screw warming (gN); a full turn's angle has no scale
        timed = ("g",) * (positioning and "p" in kinds)
        out[f"E{E}{L}"] = (L, "comp", e, kinds + ("r",) * positioning + timed, words, cause, 1)
    if axis.rotary:
        u, w = turning_pair(d)
        for pair, kind in (((u, w), "radial"), ((ROT_OF[u], ROT_OF[w]), "tilt")):
            out["+".join(f"E{e.upper()}{L}" for e in pair)] = (
                L, "comp", "".join(pair), ("h",), f"{kind} error motion of {L}, a vector turning",
                ("the head's sag under its weight (2/rev), bearing runout" if tilting else
                 "bearing runout or wobble (1/rev: eccentric, 2/rev: oval)" if axis.full_turn else
                 "gravity sag of the trunnion and table turning with the axis (1/rev), bearing runout")
                if kind == "radial" else
                "bearing wobble" if axis.full_turn else
                f"bearing wobble; gravity bending the {'head' if head else 'trunnion'}", 1)
    else:
        # ISO 230-1 squareness with Y as the reference (the seed's COX, AOZ, BOZ):
        # X is squared to Y about Z, Z to X and Y about X and Y.
        about = {"x": "c", "z": "ab"}.get(d, "")
        for r in about:
            other = {"c": "Y", "a": "Y", "b": "X"}[r]
            out[f"{r.upper()}O{L}"] = (L, "loc", r, ("const",), f"squareness of {L} to {other}",
                                       "assembly or thermal bending of the frame", 0)
    return out


def _shown(v) -> str:
    """A direction as words show it: (0, -0.7071, 0.7071)."""
    return "(" + ", ".join(f"{x + 0.0:.4g}" for x in np.round(v, 12)) + ")"


def turning_pair(d: str) -> tuple[str, str]:
    """The two directions across axis direction ``d``, in right-handed order about it."""
    i = TRANSLATIONS.index(d)
    return TRANSLATIONS[(i + 1) % 3], TRANSLATIONS[(i + 2) % 3]


ALIAS = re.compile(r"^(?:E_?)?([XYZABC])0([A-Z])$")


def canonical(name: str) -> str:
    """Map input spellings to the canonical one: ``X0C``, ``E_X0C``, ``EX0C`` → ``XOC``."""
    name = name.strip()
    m = ALIAS.match(name.split(":")[0])
    if m:
        return f"{m[1]}O{m[2]}" + name[len(name.split(":")[0]):]
    return name


def _order_ok(kind: str, order: int, first: int, compound: bool) -> bool:
    if kind in ("e", "g"):
        return order >= 1                 # τ, minutes (three digits at most: the name's pattern)
    if kind == "r":
        return order == 1
    return first <= abs(order) <= 99 and (order > 0 or compound)


def resolve(machine: Machine, name: str, table: dict | None = None) -> Effect:
    """The effect called ``name`` (canonical or alias) on this machine, or a clear error
    (``table``: the machine's ``_symbols``, when resolving many)."""
    text = canonical(name)
    symbol, _, order_txt = text.partition(":")
    table = table or _symbols(machine)
    if symbol not in table:
        raise CompgenError(f"unknown effect {name!r} on machine {machine.name!r}",
                           hint=f"`{me()} effects --machine M` lists them")
    carrier, slot, direction, kinds, words, cause, first = table[symbol]
    if not order_txt:
        if "const" not in kinds:
            raise CompgenError(f"{symbol} needs an order, e.g. {symbol}:{kinds[0]}1",
                               where=name)
        basis = CONSTANT
    elif (d := re.fullmatch(rf"([sl])\.({SHAPE_NAME})", order_txt)) is not None:
        return _declared_shape(machine, name, symbol, table[symbol], d[1], d[2])
    elif (w := re.fullmatch(r"w(\d{1,5}(?:\.\d{1,4})?)", order_txt)) is not None:
        pitch = float(w[1])
        if "p" not in kinds or carrier not in machine.axis_names or machine.axis(carrier).rotary \
                or not 0.5 <= pitch <= 10000:
            raise CompgenError(f"{symbol}:wP (periodic, pitch P mm) is declared for a component error of a "
                               "linear axis, 0.5 ≤ P ≤ 10000", where=name,
                               hint="e.g. EXX:w5 for a 5 mm ball-screw period of X")
        return Effect(symbol, carrier, slot, direction, Basis("w", pitch=pitch),
                      f"{words}, periodic with a pitch of {pitch:g} mm",
                      "a periodic error along the axis: ball-screw pitch or scale interpolation")
    else:
        m = re.fullmatch(r"([hpterg])(-?)(\d{1,3})", order_txt)
        compound = len(direction) == 2
        if not m or m[1] not in kinds or not _order_ok(m[1], int(m[2] + m[3]), first, compound):
            turns = " (N < 0 turns against the axis)" if compound else ""
            raise CompgenError(f"{symbol} takes {' or '.join(k + 'N' for k in kinds)} with N ≥ {first}"
                               f"{turns}, not {order_txt!r}"
                               + (" (eN, gN: τ = N min, 1…999)" if {"e", "g"} & set(kinds) else ""),
                               where=name,
                               hint="an order-1 straightness is a squareness: use COX, AOZ or BOZ"
                               if first == 2 else None)
        kind, order = m[1], int(m[2] + m[3])
        tilting = carrier in machine.axis_names and machine.axis(carrier).rotary \
            and not machine.axis(carrier).full_turn
        basis = Basis(kind, order, origin=kind == "h" and tilting)
        if basis == Basis("p", 1) and words.startswith("positioning error"):   # a linear axis's
            words += " (scale: linear in position)"
        if compound:
            words = words.replace("turning", f"turning {'with' if order > 0 else 'against'} the axis "
                                             f"at {abs(order)}/rev")
        if kind == "e":
            words += f", growing as 1 − exp(−t/{order} min)"
        if kind == "g":
            words += f", a scale (linear in position) growing as 1 − exp(−t/{order} min)"
            cause = "the scale or the screw warming as the axis works"
        if kind == "r":
            words = words.replace("positioning error", "reversal (backlash)") + \
                ": ± half the reversal value by the direction of motion"
            cause = "backlash, or friction and stick-slip at reversal"
    sense = machine.axis(carrier).sense if len(direction) == 2 else 1
    return Effect(symbol, carrier, slot, direction, basis, words, cause, sense)


def effect_name(param: str) -> str:
    """The name of the effect a parameter belongs to: ``ECC:h2c`` → ``ECC:h2``."""
    param = canonical(param)
    if re.search(rf":s\.{SHAPE_NAME}\.\d+$", param):       # a spline's value at knot N
        return param.rsplit(".", 1)[0]
    return param[:-1] if re.search(r":(?:h-?\d+|w[\d.]+)[cs]$", param) else param


def effect_of_param(machine: Machine, param: str) -> Effect:
    """The effect a parameter name belongs to (``ECC:h2c`` → effect ``ECC:h2``)."""
    param = canonical(param)
    effect = resolve(machine, effect_name(param))
    if param not in effect.params:
        raise CompgenError(f"unknown parameter {param!r}",
                           hint=f"effect {effect.name} has parameters {', '.join(effect.params)}")
    return effect


def _declared_shape(machine: Machine, name: str, symbol: str, entry: tuple, kind: str, label: str) -> Effect:
    """``EXX:s.screw`` (a spline through the knots of ``[effects.shapes.screw]``) or
    ``EXX:l.laser`` (its lookup table, fitted in size), for a component error of an axis."""
    carrier, slot, direction, _, words, _, _ = entry
    shape = machine.shapes.get(label)
    what = "spline through knots (at)" if kind == "s" else "lookup table (at, values)"
    if shape is None or shape.kind != kind:
        raise CompgenError(f"{name}: the machine file declares no {what} named {label!r}", where=name,
                           hint=f"declare it as [effects.shapes.{label}]: "
                                + ("at = [positions]" if kind == "s" else "at = [positions], values = [...]"))
    if slot != "comp" or carrier not in machine.axis_names or len(direction) != 1:
        raise CompgenError(f"{name}: a declared shape is for a component error of an axis (e.g. EXX, ECC)",
                           where=name)
    axis = machine.axis(carrier)
    at = np.radians(shape.at) if axis.rotary else np.asarray(shape.at) / POLY_SCALE_MM
    unit = "deg" if axis.rotary else "mm"
    if kind == "s":
        return Effect(symbol, carrier, slot, direction, Basis("s", label=label, at=tuple(at.tolist())),
                      f"{words}, a spline through {len(at)} knots from {shape.at[0]:g} to "
                      f"{shape.at[-1]:g} {unit} ({label}; zero at the first, linear between, held beyond)",
                      "declared by the user")
    peak = max(abs(v) for v in shape.values)
    return Effect(symbol, carrier, slot, direction,
                  Basis("l", label=label, at=tuple(at.tolist()), table=tuple(v / peak for v in shape.values)),
                  f"{words}, shaped as the lookup table {label} ({len(at)} points from {shape.at[0]:g} to "
                  f"{shape.at[-1]:g} {unit}): its size at the table's largest value", "declared by the user")


def catalogue(machine: Machine) -> tuple[Effect, ...]:
    """Every effect this machine can carry, orders up to ``MAX_ORDER``, and those its machine
    file declares: the candidate list."""
    out, table = [], _symbols(machine)
    for symbol, (_, _, direction, kinds, _, _, first) in table.items():
        for kind in kinds:
            if kind == "const":
                orders: list = [None]
            elif kind in ("e", "g"):
                orders = list(TAUS_MIN)
            elif kind == "r":
                orders = [1]
            elif kind == "t" and first == 0:
                orders = [1]        # a location error in time: linear (its constant is the error)
            else:
                orders = list(range(first, MAX_ORDER[kind] + 1))
                if len(direction) == 2:
                    orders += [-k for k in orders]
            out.extend(resolve(machine, symbol if k is None else f"{symbol}:{kind}{k}", table)
                       for k in orders)
    known = {e.name for e in out}
    return tuple(out) + tuple(e for e in (resolve(machine, d, table) for d in machine.declared)
                              if e.name not in known)


def one_error_in_time(names: Sequence[str]) -> bool:
    """Whether effects are one error growing in time by different shapes (``AOC:t1``,
    ``AOC:e45``): what no set-up of some minutes tells apart, more minutes do."""
    return (len(names) > 1 and len({n.partition(":")[0] for n in names}) == 1
            and all(n.partition(":")[2][:1] in IN_TIME for n in names))


def location_model(machine: Machine) -> tuple[str, ...]:
    """The seed's model generalised: ball offset plus the four location errors of each
    rotary axis (for the seed machine exactly XOW YOW ZOW, YOA ZOA BOA COA, XOC YOC AOC BOC).
    """
    names = ["XOW", "YOW", "ZOW"]
    for axis in machine.rotary_axes:
        names += [f"{e.upper()}O{axis.name}" for e in TRANSLATIONS if e != axis.direction]
        names += [f"{e.upper()}O{axis.name}" for e in ROTATIONS if e != ROT_OF[axis.direction]]
    return tuple(names)


def compose(machine: Machine, params: Sequence[str], add: Sequence[str] = (),
            remove: Sequence[str] = ()) -> tuple[str, ...]:
    """``params`` with the effects ``add`` appended and the effects ``remove`` taken out
    (effect names, e.g. ``ECC:h2``; a parameter name takes out its whole effect). ``params``
    take both words too: an effect's name stands for all its parameters (``EXC:h2`` for
    ``EXC:h2c, EXC:h2s``), as ``--add`` reads it."""
    out = []
    for p in params:
        if ":" in p and effect_name(p) == p:       # an effect's name, not one of its parameters
            out += resolve(machine, p).params
        else:
            out.append(canonical(p))
    present = {effect_name(p) for p in out}
    for name in add:
        effect = resolve(machine, name)
        if effect.name in present:
            raise CompgenError(f"{effect.name} is already in the model")
        out += effect.params
        present.add(effect.name)
    for name in remove:
        gone = resolve(machine, effect_name(name)).name
        if gone not in present:
            raise CompgenError(f"{gone} is not in the model", hint=f"the model has {', '.join(present)}")
        out = [p for p in out if effect_name(p) != gone]
        present.discard(gone)
    if not out:
        raise CompgenError("the model would be empty")
    return tuple(out)
