"""Where the rotary axes really are: the one place that converts compgen's location errors
into what a controller's kinematics holds.

compgen (the seed, the contract) places a location error *before* its axis,
``Trans(loc)·Rot(loc)·R(θ)``, so it also moves everything downstream at θ = 0. Controllers
hold the axis *line*: HEIDENHAIN writes the error rows before the axis and their inverse
after it (``Trans·Rot·R(θ)·Rot⁻¹·Trans⁻¹``, a rotation about the true line with no effect at
θ = 0; iTNC 530 Technical Manual p.684), SINUMERIK an offset vector to a pivot point on
the line and a direction vector (Commissioning Manual 12/2017 p.572). The two forms agree
on every pose up to where the ball sits on the table, a set-up term.

An ``AxisLine`` is expressed at the zero pose in machine coordinates, at the controller's
pivot: the point where the true line crosses the plane through the nominal pivot
perpendicular to the nominal direction (``shared/research/controllers.md`` §3.6).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..transforms import UNIT, rot_exact
from .effects import effect_of_param
from .kinematics import Model, inverse
from .machine import Axis, Machine
from .poses import Poses


@dataclass(frozen=True, eq=False)
class AxisLine:
    """A rotary axis line at the zero pose, machine coordinates.

    ``nominal`` is the letter of the nominal direction ('x', 'y' or 'z'), turned by
    ``incline`` (rad) on an inclined axis (``Axis.incline``); ``pivot`` the nominal pivot
    (mm); ``offset`` (mm) and ``tilt`` (rad, a rotation vector turning the nominal direction
    onto the true one) are both perpendicular to the nominal direction.
    """

    axis: str
    nominal: str
    pivot: np.ndarray
    offset: np.ndarray
    tilt: np.ndarray
    incline: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def of(cls, axis: Axis, pivot: np.ndarray, offset: np.ndarray | None = None,
           tilt: np.ndarray | None = None) -> AxisLine:
        """The line of ``axis`` at ``pivot``, moved by ``offset`` and turned by ``tilt``
        (none: its nominal line)."""
        return cls(axis.name, axis.direction, pivot, np.zeros(3) if offset is None else offset,
                   np.zeros(3) if tilt is None else tilt, np.asarray(axis.incline, float))

    @property
    def inclined(self) -> bool:
        return bool(np.any(self.incline))

    @property
    def unit(self) -> np.ndarray:
        """The nominal direction, a unit vector in machine coordinates."""
        return rot_exact(self.incline)[:3, :3] @ UNIT[self.nominal]

    @property
    def direction(self) -> np.ndarray:
        return rot_exact(self.tilt)[:3, :3] @ self.unit


def location_params(machine: Machine, params: Mapping[str, float]) -> dict[str, float]:
    """The constant location errors of the rotary axes among ``params`` (name → mm or rad)."""
    rotary = {a.name for a in machine.rotary_axes}
    out = {}
    for name, value in params.items():
        e = effect_of_param(machine, name)
        if e.basis.kind == "const" and e.slot == "loc" and e.carrier in rotary:
            out[name] = value
    return out


def axis_lines(machine: Machine, params: Mapping[str, float]) -> dict[str, AxisLine]:
    """The true line of every rotary axis implied by the location errors in ``params``."""
    loc = location_params(machine, params)
    model = Model(machine, list(loc))
    values = np.array(list(loc.values()))
    zero = Poses.at(np.zeros((1, len(machine.axes))), np.zeros(3))
    lines = {}
    for chain in (machine.workpiece, machine.tool):
        for i, axis in enumerate(chain):
            if not axis.rotary:
                continue
            frame = model.frame_before_motion(zero, values, chain, i)[0]
            nominal = nominal_pivot(chain, i)
            e = axis.unit     # the frame before its motion is its own: inclined, if it is
            point, d = frame[:3, 3], frame[:3, :3] @ UNIT[axis.direction]
            # where the true line crosses the plane through the nominal pivot ⟂ e
            point = point - ((point - nominal) @ e) / (d @ e) * d
            axis_of_turn = np.cross(e, d)
            s = np.linalg.norm(axis_of_turn)
            tilt = np.zeros(3) if s == 0 else axis_of_turn / s * np.arctan2(s, e @ d)
            lines[axis.name] = AxisLine.of(axis, nominal, point - nominal, tilt)
    return lines


def nominal_pivot(chain, i) -> np.ndarray:
    """Nominal pivot of axis ``i`` at the zero pose: the sum of the nominal offsets up to it
    (every link is a pure translation at the zero pose of a nominal machine)."""
    return np.sum([np.asarray(a.offset, float) for a in chain[:i + 1]], axis=0)


def controller_inverse(machine: Machine, lines: Mapping[str, AxisLine], rotary_rad: np.ndarray,
                       ball: np.ndarray, squareness: Mapping[str, float] | None = None,
                       nest: np.ndarray | None = None) -> np.ndarray:
    """The linear axis positions a controller holding ``lines`` (and the linear axes'
    ``squareness``, name → rad) commands under TCPM/TRAORI to put the nest on the nominal
    ball: (n, k) poses, mm and rad; ``nest``: each pose's nest length, where not the machine
    file's (the control is given the nest's length)."""
    return inverse(machine, rotary_rad, ball, lines=_as_conjugations(machine, lines),
                   params=dict(squareness or {}), nest=nest)


def _as_conjugations(machine: Machine, lines: Mapping[str, AxisLine]) -> dict[str, tuple]:
    return {name: (line.offset, line.tilt) for name, line in lines.items()}
