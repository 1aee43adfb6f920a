"""A machine: two kinematic chains of axes, the R-test set-up and the test paths, from TOML.

The workpiece chain runs from the machine frame out to the table that carries the ball; the
tool chain from the machine frame out to the spindle that carries the nest. Machine frame
origin and orientation are the machine file's: on the seed machine, the nominal A/C
intersection (``shared/spec/rtest-format.md`` §2).
"""

from __future__ import annotations

import hashlib
import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from .errors import CompgenError
from .files import read_text

LINEAR, ROTARY = "linear", "rotary"
DIRECTIONS = ("x", "y", "z")
# Strings that become words of an NC block are checked, never cleaned: an axis letter as
# DIN 66025 names them, a tool number or name, a SINUMERIK settable frame, a path label
IDENTIFIERS = {
    "axis": (r"[XYZABCUVW]", "one of the letters X Y Z A B C U V W"),
    "tool": (r"\d{1,5}|[A-Za-z][A-Za-z0-9_.]{0,31}", "a tool number or a name of letters, digits, _ and ."),
    "work_offset": (r"G5[4-7]|G50[5-9]|G5[1-9]\d", "a settable frame G54…G57 or G505…G599"),
    "path": (r"[A-Za-z][A-Za-z0-9_]{0,15}", "a letter, then up to 15 letters, digits or _"),
}
TOP_KEYS = {"name", "controller", "workpiece", "tool", "rtest", "paths", "program", "limits",
            "sinumerik", "tolerances"}


def identifier(kind: str, text, where: str) -> str:
    """``text`` if it is a valid ``kind`` of identifier, else one clear refusal."""
    pattern, words = IDENTIFIERS[kind]
    if not isinstance(text, str) or not re.fullmatch(pattern, text):
        raise CompgenError(f"{text!r} is not a valid {kind.replace('_', ' ')} name: it must be {words}",
                           where=where)
    return text


@dataclass(frozen=True)
class Axis:
    """One numerically controlled axis.

    ``sense`` is the sign between the commanded coordinate and the motion of the carried
    frame: a table axis that moves the table in -x for a +X command (ISO 841) has -1.
    ``offset`` (mm) places the axis frame in its parent at zero command: for a rotary axis,
    the reference point of its location errors. ``travel`` and ``feed_max`` are in mm and
    mm/min (linear) or deg and deg/min (rotary), as on the machine's data plate.
    """

    name: str
    kind: str
    direction: str
    side: str
    sense: int = 1
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    travel: tuple[float, float] = (-math.inf, math.inf)
    feed_max: float = math.inf

    @property
    def rotary(self) -> bool:
        return self.kind == ROTARY

    @property
    def full_turn(self) -> bool:
        """A rotary axis that can turn a whole revolution: its errors repeat every 360°."""
        return self.rotary and self.travel[1] - self.travel[0] >= 360.0


@dataclass(frozen=True)
class PathDef:
    """A test path as data: ``n`` poses, each rotary axis a function of s ∈ [0, 1].

    ``rotary[name]`` is ``("const", value)``, ``("ramp", start, end)`` or
    ``("sine", offset, amplitude, cycles)`` meaning offset + amplitude·sin(2π·cycles·s), deg.
    """

    name: str
    n: int
    seconds_per_pose: float
    rotary: dict[str, tuple]


@dataclass(frozen=True)
class ProgramSetup:
    """How a measurement program runs on this machine (``[program]`` in the machine file).

    ``clearance`` is the approach height above the first and last pose along the nest's
    axis, mm. The safe height for turning the rotary axes is not given: compgen derives it
    from the set-up (``motion.safe_height``).
    """

    tool: str
    feed: float          # mm/min along the nest's path
    dwell: float         # s at each pose, while the R-test samples
    clearance: float
    work_offset: str = "G54"   # SINUMERIK settable frame holding the machine-frame origin


@dataclass(frozen=True)
class Setup:
    """The R-test set-up as solids, mm (``[rtest]``), for the motion check: a ball on a stem
    standing on the table top, the nest housing and the spindle around the tool axis.
    ``table_top`` and the table's axis are in the frame the ball is given in (the last
    workpiece axis's); ``table_radius`` defaults to the ball's distance from that axis plus
    50 mm. ``nest_range`` is how far from the ball's centre the nest still measures (its
    sensors' range): there, and on the straight approach along the nest's axis, the nest
    and housing may surround the ball and its stem."""

    ball_diameter: float = 25.4
    stem_diameter: float = 10.0
    table_top: float = 0.0
    table_radius: float = 0.0
    table_thickness: float = 50.0
    nest_radius: float = 30.0
    nest_below: float = 5.0       # the housing reaches this far below the nest centre
    spindle_radius: float = 60.0  # spindle and holder, from the gauge line up
    spindle_length: float = 250.0
    nest_range: float = 1.0
    margin: float = 5.0           # kept between the set-up and the nest at the safe height


@dataclass(frozen=True)
class Limits:
    """Plausibility bounds for a kinematics edit (``[limits]``): larger is refused without
    --force. Defaults are deliberately tight; a machine file can widen them."""

    offset_um: float = 100.0
    tilt_arcsec: float = 60.0
    max_step_deg: float = 10.0   # largest rotary step between two poses of a program


@dataclass(frozen=True)
class Machine:
    name: str
    controller: str
    workpiece: tuple[Axis, ...]
    tool: tuple[Axis, ...]
    ball: tuple[float, float, float]
    probe_length: float
    setup: Setup = Setup()
    paths: dict[str, PathDef] = field(default_factory=dict)
    program: ProgramSetup | None = None
    limits: Limits = Limits()
    sinumerik: dict | None = None   # tcarr record and the axis vectors the control holds
    tolerances: dict[str, float] = field(default_factory=dict)   # path → max range, µm
    source: str = ""
    sha256: str = ""
    bundled: str = ""    # the name of the bundled machine file it was read from, if it was one

    @cached_property
    def axes(self) -> tuple[Axis, ...]:
        """Linear axes in X, Y, Z order, then rotary axes from the base outwards.

        This is the column order of every pose array: ``poses.q[:, machine.index('C')]``.
        """
        linear = sorted((a for a in self.workpiece + self.tool if not a.rotary),
                        key=lambda a: a.direction)
        rotary = [a for a in self.workpiece + self.tool if a.rotary]
        return tuple(linear + rotary)

    @cached_property
    def axis_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.axes)

    @cached_property
    def rotary_axes(self) -> tuple[Axis, ...]:
        return tuple(a for a in self.axes if a.rotary)

    def axis(self, name: str) -> Axis:
        for a in self.axes:
            if a.name == name:
                return a
        raise CompgenError(f"machine {self.name!r} has no axis {name!r}",
                           hint=f"its axes are {', '.join(self.axis_names)}")

    def index(self, name: str) -> int:
        return self.axis_names.index(self.axis(name).name)


def bundled_machines() -> dict[str, Path]:
    """The machine files that come with compgen, by name: ``compgen/machines`` in an
    installed wheel, the top-level ``machines/`` of a source checkout."""
    package = Path(__file__).resolve().parent
    for folder in (package / "machines", package.parent / "machines"):
        if folder.is_dir():
            return {f.stem: f for f in sorted(folder.glob("*.toml"))}
    return {}


def machine_path(name: str | Path) -> Path:
    """A path as given, or a bundled machine's file for a bare name (``ac-trunnion-itnc530``)."""
    path = Path(name)
    if path.exists() or len(path.parts) > 1 or path.suffix:
        return path
    bundled = bundled_machines()
    if str(name) in bundled:
        return bundled[str(name)]
    raise CompgenError(f"no machine file {str(name)!r} here, and no bundled machine of that name",
                       hint=f"give a path, or one of {', '.join(bundled) or '(none installed)'}")


def load_machine(path: str | Path) -> Machine:
    """Read and check a machine file (a path, or a bundled machine's name); every problem
    names the file and the key."""
    path = machine_path(path)
    text, raw = read_text(path, "machine file")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CompgenError(f"not valid TOML: {exc}", where=str(path)) from None
    machine = _machine_from_dict(doc, str(path), hashlib.sha256(raw).hexdigest())
    name = next((n for n, f in bundled_machines().items() if f.resolve() == path.resolve()), "")
    return replace(machine, bundled=name) if name else machine


def _machine_from_dict(doc: dict, source: str, sha256: str) -> Machine:
    get = _Getter(doc, source)
    from .emit.registry import CONTROLLERS  # the registry's modules build on this one

    get.only(TOP_KEYS)

    controller = get.str("controller")
    if controller not in CONTROLLERS:
        raise CompgenError(f"unknown controller {controller!r}", where=f"{source}: controller",
                           hint=f"use one of {', '.join(CONTROLLERS)}")
    chains = {side: tuple(_axis(get.sub(side, i), side) for i in range(len(get.list(side))))
              for side in ("workpiece", "tool")}
    axes = chains["workpiece"] + chains["tool"]
    names = [a.name for a in axes]
    if len(set(names)) != len(names):
        raise CompgenError("an axis name appears twice", where=f"{source}: axes {names}")
    linear_dirs = sorted(a.direction for a in axes if not a.rotary)
    if linear_dirs != ["x", "y", "z"]:
        raise CompgenError(f"need exactly one linear axis along each of x, y, z, found "
                           f"{linear_dirs}", where=source)
    if not any(a.rotary for a in axes):
        raise CompgenError("the machine has no rotary axis", where=source)
    rtest = get.sub("rtest")
    ball = rtest.vec3("ball")
    fields = set(Setup.__dataclass_fields__)
    rtest.only(fields | {"ball", "probe_length"})
    solids = {k: rtest.number(k) if k == "table_top" else _positive(rtest, k)
              for k in fields if k in rtest.doc}
    solids.setdefault("table_radius", math.hypot(ball[0], ball[1]) + 50.0)
    setup = Setup(**solids)
    check_ball(setup, ball, rtest.at("ball"))
    machine = Machine(
        name=get.str("name"), controller=controller,
        workpiece=chains["workpiece"], tool=chains["tool"],
        ball=ball, probe_length=_positive(rtest, "probe_length"), setup=setup,
        source=source, sha256=sha256,
    )
    paths = {}
    for name in get.table("paths", optional=True):
        paths[name] = _path(get.sub("paths").sub(name), name, machine)
    program = None
    if "program" in doc:
        g = get.sub("program")
        if "safe_z" in g.doc:
            raise CompgenError("safe_z (a height in machine coordinates) is no longer read: compgen "
                               "derives the safe height from the [rtest] set-up and checks it",
                               where=g.at("safe_z"), hint="delete the line; describe the set-up in [rtest]")
        g.only(set(ProgramSetup.__dataclass_fields__))
        tool = g._get("tool")
        program = ProgramSetup(tool=identifier("tool", str(tool) if isinstance(tool, int) else tool,
                                               g.at("tool")),
                               feed=_positive(g, "feed"), dwell=_positive(g, "dwell", zero_ok=True),
                               clearance=_positive(g, "clearance"),
                               work_offset=identifier("work_offset", g.doc.get("work_offset", "G54"),
                                                      g.at("work_offset")))
    limits = Limits()
    if "limits" in doc:
        g = get.sub("limits")
        g.only(set(Limits.__dataclass_fields__))
        limits = Limits(**{k: _positive(g, k) for k in Limits.__dataclass_fields__ if k in g.doc})
    sinumerik = None
    if "sinumerik" in doc:
        g = get.sub("sinumerik")
        g.only({"tcarr", "vectors", "machine_axes"})
        g.sub("vectors").only({a.name for a in machine.rotary_axes})
        record = int(g.number("tcarr"))
        kinds = {a.name: "P" if a.side == "workpiece" else "T" for a in machine.rotary_axes}
        vectors = {}
        for a in machine.rotary_axes:
            v = np.array(g.sub("vectors").vec3(a.name))
            if abs(np.linalg.norm(v) - 1) > 1e-9 or abs(abs(v @ _unit(a.direction)) - 1) > 1e-9:
                raise CompgenError(f"must be the unit vector ±{a.direction} the control holds for "
                                   f"{a.name}, got {v.tolist()}", where=g.sub("vectors").at(a.name))
            vectors[a.name] = v
        kind = "".join(sorted(set(kinds.values())))
        names = {}
        if "machine_axes" in g.doc:     # channel axis -> machine axis, for CEC tables (K3 p.248)
            m = g.sub("machine_axes")
            m.only(set(machine.axis_names))
            for axis in machine.axes:
                name = m.str(axis.name)
                if not re.fullmatch(r"[A-Z][A-Z0-9_]{0,15}", name):
                    raise CompgenError(f"machine-axis name {name!r} is not a SINUMERIK axis name "
                                       "(letters, digits, _; e.g. X1, AX1)", where=m.at(axis.name))
                names[axis.name] = name
        sinumerik = {"tcarr": record, "kind": {"P": "P", "T": "T"}.get(kind, "M"), "vectors": vectors,
                     "machine_axes": names}
    tolerances = {}
    if "tolerances" in doc:
        g = get.sub("tolerances")
        g.only(set(paths))
        tolerances = {name: _positive(g, name) for name in g.doc}
    return replace(machine, paths=paths, program=program, limits=limits, sinumerik=sinumerik,
                   tolerances=tolerances)


def check_ball(setup: Setup, ball, where: str) -> None:
    """Refuse a ball (mm, table frame) that cannot stand where it is said to: inside or below
    the table top, or with its stem off the table."""
    if ball[2] - setup.ball_diameter / 2 <= setup.table_top:
        raise CompgenError(f"the ball (z {ball[2]:g} mm, diameter {setup.ball_diameter:g}) does not stand "
                           f"above the table top (z {setup.table_top:g})", where=where)
    if math.hypot(ball[0], ball[1]) + setup.stem_diameter / 2 > setup.table_radius:
        raise CompgenError(f"the ball's stem ({math.hypot(ball[0], ball[1]):g} mm from the table's axis) "
                           f"does not stand on the table (radius {setup.table_radius:g} mm)", where=where)


def _positive(g: _Getter, key: str, zero_ok: bool = False) -> float:
    v = g.number(key)
    if v < 0 or (v == 0 and not zero_ok):
        raise CompgenError(f"must be {'≥' if zero_ok else '>'} 0", where=g.at(key))
    return v


def _unit(direction: str) -> np.ndarray:
    return np.eye(3)["xyz".index(direction)]


def _axis(get: _Getter, side: str) -> Axis:
    get.only({"axis", "type", "direction", "sense", "offset", "travel", "feed_max"})
    name = identifier("axis", get._get("axis"), get.at("axis"))
    kind = get.str("type")
    if kind not in (LINEAR, ROTARY):
        raise CompgenError(f"type must be {LINEAR!r} or {ROTARY!r}, not {kind!r}", where=get.at("type"))
    direction = get.str("direction")
    if direction not in DIRECTIONS:
        raise CompgenError(f"direction must be one of x, y, z, not {direction!r}",
                           where=get.at("direction"))
    sense = int(get.number("sense", default=1))
    if sense not in (1, -1):
        raise CompgenError("sense must be +1 or -1", where=get.at("sense"))
    travel = tuple(get.numbers("travel", 2))
    if not travel[0] < travel[1]:
        raise CompgenError(f"travel must be [min, max] with min < max, got {list(travel)}",
                           where=get.at("travel"))
    feed = get.number("feed_max")
    if not feed > 0:
        raise CompgenError("feed_max must be positive", where=get.at("feed_max"))
    return Axis(name=name, kind=kind, direction=direction, side=side, sense=sense,
                offset=get.vec3("offset", default=(0.0, 0.0, 0.0)), travel=travel, feed_max=feed)


def _path(get: _Getter, name: str, machine: Machine) -> PathDef:
    identifier("path", name, get.where)
    n = int(get.number("n"))
    if n < 2:
        raise CompgenError("a path needs n ≥ 2 poses", where=get.at("n"))
    rotary = {}
    for axis in machine.rotary_axes:
        spec = get.doc.get(axis.name, 0.0)
        where = get.at(axis.name)
        sub = _Getter(spec, where) if isinstance(spec, dict) else None
        if isinstance(spec, int | float) and not isinstance(spec, bool):
            rotary[axis.name] = ("const", get.number(axis.name))
        elif sub and set(spec) == {"from", "to"}:
            rotary[axis.name] = ("ramp", sub.number("from"), sub.number("to"))
        elif sub and {"amplitude", "cycles"} <= set(spec) <= {"amplitude", "cycles", "offset"}:
            rotary[axis.name] = ("sine", sub.number("offset", 0.0), sub.number("amplitude"),
                                 sub.number("cycles"))
        else:
            raise CompgenError(f"cannot read {spec!r}", where=where,
                               hint="give a number (deg), {from=…, to=…} or "
                                    "{amplitude=…, cycles=…, offset=…}")
    get.only({"n", "seconds_per_pose", *rotary})
    return PathDef(name=name, n=n, seconds_per_pose=get.number("seconds_per_pose", default=1.0),
                   rotary=rotary)


class _Getter:
    """Typed access to a TOML table that names file and key in every complaint."""

    def __init__(self, doc: dict, where: str):
        self.doc, self.where = doc, where

    def at(self, key: str) -> str:
        return f"{self.where}: {key}" if key else self.where

    def only(self, keys: set[str]) -> None:
        """Refuse a key this table does not take: a typo (``sence``, ``ofset``) is not ignored."""
        unknown = sorted(set(self.doc) - keys)
        if unknown:
            raise CompgenError(f"unknown key{'s' * (len(unknown) > 1)} {', '.join(unknown)}",
                               where=self.where, hint=f"the table takes {', '.join(sorted(keys))}")

    def _get(self, key: str, default=None):
        if key not in self.doc:
            if default is not None:
                return default
            raise CompgenError(f"missing key {key!r}", where=self.where)
        return self.doc[key]

    def str(self, key: str) -> str:
        v = self._get(key)
        if not isinstance(v, str) or not v:
            raise CompgenError("must be a non-empty string", where=self.at(key))
        return v

    def number(self, key: str, default: float | None = None) -> float:
        v = self._get(key, default)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise CompgenError(f"must be a finite number, got {v!r}", where=self.at(key))
        return float(v)

    def numbers(self, key: str, count: int, default=None) -> list[float]:
        v = self._get(key, default)
        if (not isinstance(v, list | tuple) or len(v) != count
                or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
                or not all(math.isfinite(x) for x in v)):
            raise CompgenError(f"must be a list of {count} finite numbers, got {v!r}",
                               where=self.at(key))
        return [float(x) for x in v]

    def vec3(self, key: str, default=None) -> tuple[float, float, float]:
        return tuple(self.numbers(key, 3, default))

    def list(self, key: str) -> list:
        v = self._get(key)
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            raise CompgenError("must be an array of tables ([[…]])", where=self.at(key))
        return v

    def table(self, key: str, optional: bool = False) -> dict:
        v = self.doc.get(key, {} if optional else None)
        if not isinstance(v, dict):
            raise CompgenError("must be a table", where=self.at(key))
        return v

    def sub(self, key: str, index: int | None = None) -> _Getter:
        if index is None:
            return _Getter(self.table(key), self.at(key))
        return _Getter(self.list(key)[index], f"{self.at(key)}[{index}]")


def travel_violations(machine: Machine, q: np.ndarray) -> np.ndarray:
    """Boolean (n, k): which pose coordinates (mm, rad) leave the machine's travel."""
    lo = np.array([a.travel[0] if not a.rotary else math.radians(a.travel[0]) for a in machine.axes])
    hi = np.array([a.travel[1] if not a.rotary else math.radians(a.travel[1]) for a in machine.axes])
    return (q < lo - 1e-9) | (q > hi + 1e-9)
