"""The machine file (TOML): read, checked key by key, every complaint naming the file and
the key. A controller's own section (``[sinumerik]``) is read by that controller's module."""

from __future__ import annotations

import hashlib
import math
import re
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..controllers.registry import CONTROLLERS
from ..errors import CompgenError
from ..files import read_text
from ..model.effects import SHAPE_NAME, location_model, resolve
from ..model.machine import (
    DIRECTIONS,
    LINEAR,
    ROTARY,
    Axis,
    Drift,
    Limits,
    Machine,
    PathDef,
    ProbeSetup,
    ProgramSetup,
    Setup,
    Shape,
    check_ball,
    identifier,
)
from ..transforms import UNIT
from ..units import NOISE_MAX_UM

TOP_KEYS = {"name", "serial", "drift", "controller", "workpiece", "tool", "rtest", "paths", "program",
            "probe", "limits",
            "tolerances", "effects"}


def bundled_machines() -> dict[str, Path]:
    """The machine files that come with compgen, by name: ``compgen/machines`` in an
    installed wheel, the top-level ``machines/`` of a source checkout."""
    package = Path(__file__).resolve().parents[1]
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
    get.only(TOP_KEYS | {ctl.section for ctl in CONTROLLERS.values() if ctl.section})

    controller, chains = _chains(get, source)
    rtest = get.sub("rtest")
    ball = rtest.vec3("ball")
    fields = set(Setup.__dataclass_fields__)
    rtest.only(fields | {"ball", "probe_length", "noise_um", "gain_u"})
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
        noise_um=_noise(rtest) if "noise_um" in rtest.doc else None,
        gain_u=_gain_u(rtest) if "gain_u" in rtest.doc else 0.0,
    )
    paths = {}
    for name in get.table("paths", optional=True):
        paths[name] = _path(get.sub("paths").sub(name), name, machine)
    program = _program(get.sub("program")) if "program" in doc else None
    probe = _probe(get.sub("probe")) if "probe" in doc else None
    limits = Limits()
    if "limits" in doc:
        g = get.sub("limits")
        g.only(set(Limits.__dataclass_fields__))
        limits = Limits(**{k: _positive(g, k) for k in Limits.__dataclass_fields__ if k in g.doc})
    drift = Drift()
    if "drift" in doc:
        g = get.sub("drift")
        g.only(set(Drift.__dataclass_fields__))
        limits_ = {k: _positive(g, k) for k in Drift.__dataclass_fields__ if k in g.doc and k != "each"}
        drift = Drift(**limits_, each=_each(g, machine) if "each" in g.doc else ())
    sections = {ctl.section: ctl.read_section(get.sub(ctl.section), machine)   # each control its own
                for ctl in CONTROLLERS.values() if ctl.section and ctl.section in doc}
    tolerances = {}
    if "tolerances" in doc:
        g = get.sub("tolerances")
        g.only(set(paths))
        tolerances = {name: _positive(g, name) for name in g.doc}
    declared, shapes = (), {}
    if "effects" in doc:
        machine, declared, shapes = _effects(get.sub("effects"), machine)
    serial = identifier("serial", doc["serial"], get.at("serial")) if "serial" in doc else ""
    return replace(machine, paths=paths, program=program, probe=probe, limits=limits, tolerances=tolerances,
                   declared=declared, shapes=shapes, drift=drift, serial=serial, **sections)


def _chains(get: _Getter, source: str) -> tuple[str, dict]:
    """The controller and the two chains of axes, each checked: one linear axis along each
    of x, y, z, a rotary axis at least, a head's rotary axes after its linear ones."""
    controller = get.str("controller")
    if controller not in CONTROLLERS:
        raise CompgenError(f"unknown controller {controller!r}", where=f"{source}: controller",
                           hint=f"use one of {', '.join(CONTROLLERS)}")
    # a machine whose head does all the turning has no [[workpiece]] axis: the ball stands
    # in the machine frame
    chains = {side: tuple(_axis(get.sub(side, i), side)
                          for i in range(len(get.list(side)) if side == "tool" or side in get.doc else 0))
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
    tool = chains["tool"]
    head = next((i for i, a in enumerate(tool) if a.rotary), len(tool))
    if any(not a.rotary for a in tool[head:]):
        raise CompgenError(f"a linear axis follows the head {tool[head].name} in the [[tool]] chain: compgen "
                           "models heads carried by the linear axes", where=f"{source}: tool",
                           hint="list the tool side's linear axes first, then its rotary axes")
    return controller, chains


def _program(g: _Getter) -> ProgramSetup:
    """``[program]``: how measurement programs run."""
    if "safe_z" in g.doc:
        raise CompgenError("safe_z (a height in machine coordinates) is no longer read: compgen "
                           "derives the safe height from the [rtest] set-up and checks it",
                           where=g.at("safe_z"), hint="delete the line; describe the set-up in [rtest]")
    g.only(set(ProgramSetup.__dataclass_fields__))
    tool = g._get("tool")
    return ProgramSetup(tool=identifier("tool", str(tool) if isinstance(tool, int) else tool, g.at("tool")),
                        feed=_positive(g, "feed"), dwell=_positive(g, "dwell", zero_ok=True),
                        clearance=_positive(g, "clearance"),
                        work_offset=identifier("work_offset", g.doc.get("work_offset", "G54"),
                                               g.at("work_offset")))


def _effects(g: _Getter, machine: Machine) -> tuple[Machine, tuple[str, ...], dict]:
    """``[effects]``: the shapes a user declares and the effects diagnose tries beside the
    catalogue's, each resolved on ``machine`` (which the shapes are added to)."""
    shapes = {}
    g.only({"declared", "shapes"})
    if "shapes" in g.doc:
        shapes = _shapes(g.sub("shapes"))
        machine = replace(machine, shapes=shapes)
    declared = tuple(g.names("declared")) if "declared" in g.doc else ()
    for i, name in enumerate(declared):
        try:
            resolve(machine, name)
        except CompgenError as exc:
            raise CompgenError(exc.message, where=f"{g.at('declared')}[{i}]", hint=exc.hint) from None
    return machine, declared, shapes


def _probe(g: _Getter) -> ProbeSetup:
    fields = ProbeSetup.__dataclass_fields__
    g.only(set(fields))
    values = {k: _positive(g, k) for k in fields if k in g.doc and k != "tool"}
    for k in ("sphere_diameter", "stylus_diameter", "length"):
        if k not in values:
            raise CompgenError(f"[probe] needs {k} (mm)", where=g.at(k))
    for k in ("touches", "poses"):
        if k in values:
            if values[k] != int(values[k]):
                raise CompgenError("must be a whole number", where=g.at(k))
            values[k] = int(values[k])
    if values.get("touches", 5) < 5:
        raise CompgenError("a pose needs 5 touches or more (4 fix a centre; the fifth finds a bad one)",
                           where=g.at("touches"))
    if values.get("touches", 5) > TOUCHES_MAX:
        raise CompgenError(f"at most {TOUCHES_MAX} touches a pose (more add hours of probing, not accuracy: "
                           "repeat a path instead)", where=g.at("touches"))
    if not 4 <= values.get("poses", 12) <= POSES_MAX:
        raise CompgenError(f"a path needs 4 to {POSES_MAX} poses", where=g.at("poses"))
    if not 10 <= values.get("elevation", 30.0) <= 60:
        raise CompgenError("the side touches' elevation must be 10° to 60° above the horizontal",
                           where=g.at("elevation"))
    tool = g.doc.get("tool", "1")
    tool = identifier("tool", str(tool) if isinstance(tool, int) else tool, g.at("tool"))
    return ProbeSetup(tool=tool, **values)


GAIN_U_MAX = 0.05     # 5 %: a sensor whose gain is known no better is not calibrated


def _gain_u(g: _Getter) -> float:
    v = _positive(g, "gain_u", zero_ok=True)
    if v > GAIN_U_MAX:
        raise CompgenError(f"gain_u is a fraction (0.002 for 0.2 %); {v:g} is more than {GAIN_U_MAX:g}",
                           where=g.at("gain_u"), hint="give the relative standard uncertainty of the "
                                                      "sensors' gain from the R-test's calibration")
    return v


def _each(g: _Getter, machine) -> tuple[tuple[str, float], ...]:
    """``[drift] each``: a location error's own limit (µm for an offset, ″ for a tilt)."""
    e = g.sub("each")
    names = location_model(machine)
    e.only(set(names))
    return tuple((n, _positive(e, n)) for n in names if n in e.doc)


def _positive(g: _Getter, key: str, zero_ok: bool = False) -> float:
    v = g.number(key)
    if v < 0 or (v == 0 and not zero_ok):
        raise CompgenError(f"must be {'≥' if zero_ok else '>'} 0", where=g.at(key))
    return v


def _noise(g: _Getter) -> float:
    v = _positive(g, "noise_um")
    if not v <= NOISE_MAX_UM:
        raise CompgenError(f"{v:g} µm is no device's noise per reading (at most {NOISE_MAX_UM:g} µm)",
                           where=g.at("noise_um"), hint="give the device's calibrated noise in µm, e.g. 0.5")
    return v


def _axis(get: _Getter, side: str) -> Axis:
    get.only({"axis", "type", "direction", "sense", "offset", "travel", "feed_max", "hirth_deg",
              "positioning", "m_function"})
    name = identifier("axis", get._get("axis"), get.at("axis"))
    kind = get.str("type")
    if kind not in (LINEAR, ROTARY):
        raise CompgenError(f"type must be {LINEAR!r} or {ROTARY!r}, not {kind!r}", where=get.at("type"))
    direction, incline = _direction(get, name, kind)
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
    hirth = get.number("hirth_deg") if "hirth_deg" in get.doc else None
    if hirth is not None:
        teeth = 360.0 / hirth if hirth > 0 else 0.0
        if kind != ROTARY or not (hirth > 0 and abs(teeth - round(teeth)) < 1e-9 and teeth >= 2):
            raise CompgenError(f"hirth_deg = {hirth:g}: a Hirth coupling's grid is a rotary axis's 360° "
                               "over a whole number of teeth (e.g. 1, 2.5, 3 or 5)",
                               where=get.at("hirth_deg"))
    return Axis(name=name, kind=kind, direction=direction, side=side, sense=sense,
                offset=get.vec3("offset", default=(0.0, 0.0, 0.0)), travel=travel, feed_max=feed,
                hirth_deg=hirth, incline=incline, m_function=_m_function(get, kind))


def _m_function(get: _Getter, kind: str) -> int | None:
    """``positioning = "m-function"`` with ``m_function = N``: a rotary axis the NC does not
    interpolate, positioned by the OEM's M-function N (the PLC); "nc" (default): the NC's."""
    how = get.str("positioning") if "positioning" in get.doc else "nc"
    if how not in ("nc", "m-function"):
        raise CompgenError(f'positioning must be "nc" or "m-function", not {how!r}',
                           where=get.at("positioning"))
    if how == "nc":
        if "m_function" in get.doc:
            raise CompgenError('m_function is the number of the OEM\'s M-function of an axis with '
                               'positioning = "m-function"', where=get.at("m_function"),
                               hint='add positioning = "m-function", or leave m_function out')
        return None
    if kind != ROTARY:
        raise CompgenError("only a rotary axis is positioned by an M-function here",
                           where=get.at("positioning"))
    if "m_function" not in get.doc:
        raise CompgenError('positioning = "m-function" needs the M-function\'s number: m_function = N',
                           where=get.at("positioning"), hint="the OEM's M number that positions the axis "
                                                             "(iTNC 530 MP6602, TNC 640 mStrobeRotAxPos)")
    n = get.number("m_function")
    if not (n == int(n) and 0 <= n <= 9999):
        raise CompgenError(f"m_function = {n:g}: an M-function's number is a whole number 0 to 9999",
                           where=get.at("m_function"))
    return int(n)


# the letter a rotary axis's name gives it (DIN 66217): an inclined axis is that letter's
# axis tilted, its own frame the machine's turned by the shortest rotation onto it
NAME_LETTER = {"A": "x", "B": "y", "C": "z"}


def _direction(get: _Getter, name: str, kind: str) -> tuple[str, tuple[float, float, float]]:
    """``direction``: x, y or z; or, for a rotary axis A, B or C, any vector within 90° of
    its letter's (an inclined axis): its letter and the incline (rad) turning it there."""
    raw = get._get("direction")
    if isinstance(raw, str):
        if raw not in DIRECTIONS:
            raise CompgenError(f"direction must be one of x, y, z or a vector [x, y, z], not {raw!r}",
                               where=get.at("direction"))
        return raw, (0.0, 0.0, 0.0)
    v = np.array(get.vec3("direction"))
    letter = NAME_LETTER.get(name)
    if kind != ROTARY or letter is None:
        raise CompgenError(f"direction {v.tolist()}: only a rotary axis A, B or C may be inclined; "
                           f"{name} moves along x, y or z", where=get.at("direction"),
                           hint='write direction = "x", "y" or "z"')
    size = float(np.linalg.norm(v))
    e = UNIT[letter]
    if not size > 0 or not v @ e > 1e-9 * size:
        raise CompgenError(f"direction {v.tolist()} of {name} is not within 90° of its letter's +{letter}",
                           where=get.at("direction"),
                           hint=f"give the vector {name} turns about right-handed, on the +{letter} side "
                                "(a turn the other way is sense = -1)")
    v = v / size
    axis = np.cross(e, v)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return letter, (0.0, 0.0, 0.0)
    w = axis / s * math.atan2(s, float(e @ v))
    return letter, (float(w[0]), float(w[1]), float(w[2]))


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
        if not _finite(v):
            raise CompgenError(f"must be a finite number, got {_shown(v)}", where=self.at(key))
        return float(v)

    def numbers(self, key: str, count: int, default=None) -> list[float]:
        v = self._get(key, default)
        if not isinstance(v, list | tuple) or len(v) != count or not all(_finite(x) for x in v):
            raise CompgenError(f"must be a list of {count} finite numbers, got {_shown(v)}",
                               where=self.at(key))
        return [float(x) for x in v]

    def series(self, key: str, least: int) -> list[float]:
        """A list of ``least`` or more finite numbers."""
        v = self._get(key)
        if not isinstance(v, list | tuple) or len(v) < least or not all(_finite(x) for x in v):
            raise CompgenError(f"must be a list of {least} or more finite numbers, got {_shown(v)}",
                               where=self.at(key))
        return [float(x) for x in v]

    def vec3(self, key: str, default=None) -> tuple[float, float, float]:
        return tuple(self.numbers(key, 3, default))

    def flag(self, key: str, meaning: str) -> bool:
        v = self._get(key)
        if not isinstance(v, bool):
            raise CompgenError(f"must be true or false ({meaning})", where=self.at(key))
        return v

    def names(self, key: str) -> list[str]:
        v = self._get(key)
        if not isinstance(v, list) or not all(isinstance(x, str) and x for x in v):
            raise CompgenError('must be a list of names, e.g. ["EXX:w5"]', where=self.at(key))
        return v

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


TOUCHES_MAX = 25      # touches a probed pose
POSES_MAX = 120       # probed poses a path
KNOTS_MAX = 64        # a spline's knots: one parameter each


def _shapes(get: _Getter) -> dict[str, Shape]:
    """``[effects.shapes.NAME]``: ``at`` alone (a spline's knots) or ``at`` and ``values``
    (a lookup table), positions strictly increasing in the axis's unit (mm, deg)."""
    out = {}
    for name in get.doc:
        if not re.fullmatch(SHAPE_NAME, name):
            raise CompgenError(f"a shape's name is lower-case letters, digits and _, starting with a "
                               f"letter, not {name!r}", where=get.at(name))
        g = get.sub(name)
        g.only({"at", "values"})
        at = g.series("at", 2 if "values" in g.doc else 3)     # a spline is zero at its first knot
        if "values" not in g.doc and len(at) > KNOTS_MAX:
            raise CompgenError(f"a spline of {len(at)} knots: at most {KNOTS_MAX} (each knot is a parameter "
                               "of the fit: more are not determined by a session, and take minutes)",
                               where=g.at("at"), hint="give fewer knots, or a lookup table (at and values)")
        if not all(b > a for a, b in zip(at[:-1], at[1:], strict=True)):
            raise CompgenError("positions must increase strictly", where=g.at("at"))
        values = tuple(g.numbers("values", len(at))) if "values" in g.doc else ()
        if values and not any(values):
            raise CompgenError("a lookup table of zeros has no shape", where=g.at("values"))
        out[name] = Shape(tuple(at), values)
    return out


def _finite(v) -> bool:
    """A TOML number a float can hold: not a bool, not NaN or ±inf, not a 400-digit integer."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def _shown(v) -> str:
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."
