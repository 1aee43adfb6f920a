"""A machine: two kinematic chains of axes, the R-test set-up and the test paths (the
machine file's reader is ``machine_file.py``).

The workpiece chain runs from the machine frame out to the table that carries the ball; the
tool chain from the machine frame out to the spindle that carries the nest. Machine frame
origin and orientation are the machine file's: on the seed machine, the nominal A/C
intersection (``docs/rtest-csv.md``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from ..errors import CompgenError
from ..transforms import rodrigues

LINEAR, ROTARY = "linear", "rotary"
DIRECTIONS = ("x", "y", "z")
# Strings that become words of an NC block are checked, never cleaned: an axis letter as
# DIN 66025 names them, a tool number or name, a SINUMERIK settable frame, a path label
IDENTIFIERS = {
    "axis": (r"[XYZABCUVW]", "one of the letters X Y Z A B C U V W"),
    "tool": (r"\d{1,5}|[A-Za-z][A-Za-z0-9_.]{0,31}", "a tool number or a name of letters, digits, _ and ."),
    "work_offset": (r"G5[4-7]|G50[5-9]|G5[1-9]\d", "a settable frame G54…G57 or G505…G599"),
    "path": (r"[A-Za-z][A-Za-z0-9_]{0,15}", "a letter, then up to 15 letters, digits or _"),
    "serial": (r"[A-Za-z0-9][A-Za-z0-9_./-]{0,39}", "up to 40 letters, digits and _ . / -"),
}


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
    mm/min (linear) or deg and deg/min (rotary), as on the machine's data plate. A rotary
    axis with ``hirth_deg`` is Hirth-coupled: it rests only on that grid (its teeth), and is
    measured only there. One with ``m_function`` is positioned by the PLC when a program
    calls that M-function (the OEM's), never interpolated by the NC: it turns only between
    poses, at rest while measured.

    An inclined (nutating) rotary axis turns about a unit vector that is none of x, y, z:
    ``direction`` is then the letter of its name (B: y), ``incline`` the rotation vector
    (rad) that turns that letter's unit vector onto the true one. Its own frame is the
    machine's turned by ``incline``: its location and error motions are named and act in
    it (XOB, ZOB across a B tilted about X), as the seed's are in the machine's.
    """

    name: str
    kind: str
    direction: str
    side: str
    sense: int = 1
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    travel: tuple[float, float] = (-math.inf, math.inf)
    feed_max: float = math.inf
    hirth_deg: float | None = None    # a Hirth-coupled rotary axis: it rests only on this grid, deg
    m_function: int | None = None     # positioned by the OEM's M-function of this number (the PLC)
    incline: tuple[float, float, float] = (0.0, 0.0, 0.0)   # an inclined axis's own frame, rad

    @property
    def inclined(self) -> bool:
        return any(self.incline)

    @cached_property
    def frame(self) -> np.ndarray:
        """The axis's own frame in its parent's orientation, (3, 3): its columns are its
        x, y, z (the identity but on an inclined axis)."""
        return _frozen(rodrigues(np.asarray(self.incline, float)))

    @property
    def unit(self) -> np.ndarray:
        """The direction it moves along or turns about, a unit vector in the parent's frame."""
        return self.frame[:, "xyz".index(self.direction)]

    @property
    def unit_text(self) -> str:
        """``unit`` as programs and messages write it: (0.000000, 0.707107, 0.707107)."""
        return "(" + ", ".join(f"{x:.6f}" for x in self.unit) + ")"

    def on_grid(self, deg: np.ndarray) -> np.ndarray:
        """Positions (deg) as the axis can hold them: on its Hirth grid (nearest), or as given."""
        return deg if self.hirth_deg is None else np.round(np.asarray(deg) / self.hirth_deg) * self.hirth_deg

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
class ProbeSetup:
    """A touch probe and calibration sphere (``[probe]`` in the machine file), mm, mm/min
    and deg: what ``probe-program`` writes and ``check-program`` checks. The sphere stands
    where ``[rtest] ball`` says, on a stem of ``[rtest] stem_diameter``.

    ``length`` runs from the spindle gauge line to the stylus tip's centre (the tool length
    the control holds); ``stylus_length`` from the tip's centre up to the probe body. Each
    pose is touched once from above and ``touches − 1`` times around at ``elevation`` above
    the horizontal; each touch starts ``approach`` from the surface and fails ``overtravel``
    beyond it. A path is probed at ``poses`` of its poses, evenly spread."""

    sphere_diameter: float
    stylus_diameter: float
    length: float
    tool: str = "1"
    stylus_length: float = 40.0
    shaft_diameter: float = 2.0
    body_diameter: float = 40.0
    touches: int = 5
    elevation: float = 30.0
    poses: int = 12
    approach: float = 5.0
    overtravel: float = 2.0
    feed: float = 2000.0
    probe_feed: float = 100.0
    margin: float = 1.0


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
    head_radius: float = 0.0      # a head's body, a sphere about each head's pivot (heads only)
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
class Shape:
    """A shape the user declares for an effect along an axis (``[effects.shapes.NAME]``),
    positions in the axis's unit (mm, deg), increasing: a spline through ``at`` with a free
    value at each knot (``values`` empty), or a lookup table of ``values`` at ``at`` (a shape
    known from elsewhere, fitted in size); linear between the points, held beyond them."""

    at: tuple[float, ...]
    values: tuple[float, ...] = ()

    @property
    def kind(self) -> str:
        return "l" if self.values else "s"


@dataclass(frozen=True)
class Drift:
    """How far the machine's location errors may move between calibrations (``[drift]``):
    ``compgen check`` fails a change beyond these (and beyond ``k_sigma`` of its σ), the
    history flags a step or a steady drift. The defaults are a starting point for a
    mid-size machine, not a standard's: set your own acceptance."""

    offset_um: float = 5.0
    tilt_arcsec: float = 10.0
    per_month_um: float = 1.0      # a steady drift of an offset beyond this per 30 days
    per_month_arcsec: float = 2.0
    k_sigma: float = 3.0
    every_days: float = 90.0       # a check is due this long after the last measurement
    # a location error's own limit, in place of its class's (µm for an offset, ″ for a tilt):
    # (name, limit) pairs, e.g. (("BOA", 5.0),)
    each: tuple[tuple[str, float], ...] = ()


@dataclass(frozen=True)
class Machine:
    """A machine as its machine file describes it: the chain of axes from the table
    (``workpiece``) and from the spindle (``tool``), the R-test set-up, its paths, programs,
    probe, limits, drift limits and tolerances, and its control."""

    name: str
    controller: str
    workpiece: tuple[Axis, ...]
    tool: tuple[Axis, ...]
    ball: tuple[float, float, float]
    probe_length: float
    setup: Setup = Setup()
    paths: dict[str, PathDef] = field(default_factory=dict)
    program: ProgramSetup | None = None
    probe: ProbeSetup | None = None
    limits: Limits = Limits()
    drift: Drift = Drift()
    serial: str = ""                # the machine's serial number: one history per machine
    sinumerik: dict | None = None   # tcarr record and the axis vectors the control holds
    linuxcnc: dict | None = None    # the trt kinematics' switches ([linuxcnc])
    tolerances: dict[str, float] = field(default_factory=dict)   # path → max range, µm
    noise_um: float | None = None   # the R-test's own noise, 1σ per reading ([rtest] noise_um)
    gain_u: float = 0.0             # its sensors' gain, relative standard uncertainty ([rtest] gain_u)
    declared: tuple[str, ...] = ()  # effects the user declares beyond the catalogue ([effects])
    shapes: dict[str, Shape] = field(default_factory=dict)   # their shapes ([effects.shapes.NAME])
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

    @cached_property
    def heads(self) -> tuple[Axis, ...]:
        """The rotary axes that turn the tool (a swivel or fork head), base outwards."""
        return tuple(a for a in self.tool if a.rotary)

    @cached_property
    def hirth_axes(self) -> tuple[Axis, ...]:
        """The rotary axes coupled by a Hirth ring: they rest only on their grid."""
        return tuple(a for a in self.rotary_axes if a.hirth_deg is not None)

    @cached_property
    def plc_axes(self) -> tuple[Axis, ...]:
        """The rotary axes the PLC positions by the OEM's M-function: at rest while measured."""
        return tuple(a for a in self.rotary_axes if a.m_function is not None)

    @cached_property
    def at_rest_axes(self) -> tuple[Axis, ...]:
        """The rotary axes measured only at rest (Hirth-coupled or PLC-positioned): a path
        turning one is measured pose by pose, never on the fly, and takes no backlash side."""
        return tuple(a for a in self.rotary_axes if a.hirth_deg is not None or a.m_function is not None)

    @cached_property
    def gauge(self) -> np.ndarray:
        """The spindle's gauge line on the tool axis with every axis at zero, mm: where the
        tool chain's frames start (the nest centre is at the origin)."""
        return _frozen(np.array([0.0, 0.0, self.probe_length]))

    @cached_property
    def nest_point(self) -> np.ndarray:
        """The nest centre in the tool chain's last frame, mm: ``probe_length`` below the
        gauge line, and below every head's pivot by its offset (the pivot length), so that
        at the zero pose the nest centre is at the linear axes' position."""
        heads = np.sum([np.asarray(a.offset, float) for a in self.heads], axis=0, initial=0.0)
        return _frozen(-(self.gauge + heads))

    def axis(self, name: str) -> Axis:
        for a in self.axes:
            if a.name == name:
                return a
        raise CompgenError(f"machine {self.name!r} has no axis {name!r}",
                           hint=f"its axes are {', '.join(self.axis_names)}")

    def index(self, name: str) -> int:
        return self.axis_names.index(self.axis(name).name)


def _frozen(a: np.ndarray) -> np.ndarray:
    """``a`` made read-only: a machine's cached arrays are shared by every caller."""
    a.setflags(write=False)
    return a


NEST_RANGE_MM = (10.0, 2000.0)     # a nest on a tool holder below the gauge line: no shorter, no longer


def at_nest(machine: Machine, length: float | None, where: str = "") -> Machine:
    """The machine with its R-test nest ``length`` mm below the gauge line instead of the
    machine file's ``probe_length`` (None: that one): for a session made with a longer or
    shorter nest, whose programs, travel and motion check follow the nest."""
    if length is None or length == machine.probe_length:
        return machine
    if not (math.isfinite(length) and NEST_RANGE_MM[0] <= length <= NEST_RANGE_MM[1]):
        raise CompgenError(f"{length:g} mm is no nest's distance below the gauge line ({NEST_RANGE_MM[0]:g} "
                           f"to {NEST_RANGE_MM[1]:g} mm)", where=where,
                           hint="give the nest's length in mm (the machine file's [rtest] probe_length is "
                                f"{machine.probe_length:g})")
    return replace(machine, probe_length=float(length))


def check_ball(setup: Setup, ball, where: str) -> None:
    """Refuse a ball (mm, table frame) that cannot stand where it is said to: inside or below
    the table top, or with its stem off the table."""
    if ball[2] - setup.ball_diameter / 2 <= setup.table_top:
        raise CompgenError(f"the ball (z {ball[2]:g} mm, diameter {setup.ball_diameter:g}) does not stand "
                           f"above the table top (z {setup.table_top:g})", where=where)
    if math.hypot(ball[0], ball[1]) + setup.stem_diameter / 2 > setup.table_radius:
        raise CompgenError(f"the ball's stem ({math.hypot(ball[0], ball[1]):g} mm from the table's axis) "
                           f"does not stand on the table (radius {setup.table_radius:g} mm)", where=where)


def travel_violations(machine: Machine, q: np.ndarray) -> np.ndarray:
    """Boolean (n, k): which pose coordinates (mm, rad) leave the machine's travel."""
    lo = np.array([a.travel[0] if not a.rotary else math.radians(a.travel[0]) for a in machine.axes])
    hi = np.array([a.travel[1] if not a.rotary else math.radians(a.travel[1]) for a in machine.axes])
    return (q < lo - 1e-9) | (q > hi + 1e-9)


def check_travel(machine: Machine, q: np.ndarray, label: str, lines: Sequence[int] | None = None) -> None:
    """Refuse poses (mm, rad) that leave the travel, naming the first: as pose k of ``label``,
    or, for poses read from the file ``label``, by its line in ``lines``."""
    bad = travel_violations(machine, q)
    if not bad.any():
        return
    i, j = np.argwhere(bad)[0]
    axis = machine.axes[j]
    value, unit = (math.degrees(q[i, j]), "deg") if axis.rotary else (q[i, j], "mm")
    span = f"[{axis.travel[0]:g}, {axis.travel[1]:g}] {unit} ({int(bad.any(axis=1).sum())} poses"
    at = f"puts {axis.name} at {value:.3f} {unit}, outside its travel {span}"
    if lines is not None:
        raise CompgenError(f"this pose {at} do)", where=f"{label}:{lines[i]}",
                           hint="the machine cannot take the pose: give poses within its travel")
    raise CompgenError(f"pose {i + 1} of {label} {at} outside)",
                       hint="move the ball, shorten the path or correct the machine file's travel")
