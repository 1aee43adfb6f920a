"""The nominal chain's frames where a program puts the machine: the table frame, the nest
centre and the tool axis in it, the TCP coordinates a control is given, and the height at
which nothing of the set-up can be touched. Geometry of the set-up, no program: what the
motion check, the program writers and the probe's simulation share."""

from __future__ import annotations

import numpy as np

from ..transforms import apply
from .kinematics import chain_transform, head_offset, inverse, nest_centre
from .machine import Machine
from .poses import Poses


def safe_height(machine: Machine) -> float:
    """The height of the nest centre above the rotary axes' intersection at which nothing
    of the set-up can be touched at any orientation: every solid lies within R of the
    intersection, and the housing reaches ``nest_below`` and its radius below the centre
    (with a head, whatever of the tool reaches lowest as the head turns about the nest)."""
    s = machine.setup
    table = frames(machine, np.zeros((1, len(machine.axes))))[0][0]
    normal = table[:3, 2]
    reach = np.linalg.norm(apply(table, np.asarray(machine.ball))) + s.ball_diameter / 2
    for z in (s.table_top, s.table_top - s.table_thickness):
        # the rim's farthest point: |c + R·u|² = |c|² + R² + 2R c·u, greatest for the unit u
        # in the table's plane along c's part in that plane
        c = table[:3, 3] + z * normal
        across = np.linalg.norm(c - (c @ normal) * normal)
        reach = max(reach, np.sqrt(c @ c + s.table_radius**2 + 2 * s.table_radius * across))
    return float(np.ceil(reach + _below_nest(machine) + s.margin))


def _below_nest(machine: Machine) -> float:
    """How far below the nest centre the tool reaches at any orientation it takes: the
    housing's end and radius for a tool that never tilts (a table-table machine); a head
    tilts it through its travel (under TCP about the nest), so every part along the tool axis
    — housing, spindle, the head's body about its pivot — reaches ``t·cos θ`` below, θ up to
    the tilt the head's travel allows."""
    s = machine.setup
    tilt = min(np.pi, sum(_tilt(a) for a in machine.heads))
    c = np.cos(tilt)
    pivots = np.linalg.norm(head_pivots(machine, np.zeros((1, len(machine.axes))))[0], axis=1)
    parts = [(-s.nest_below, machine.probe_length, s.nest_radius),
             (machine.probe_length, machine.probe_length + s.spindle_length, s.spindle_radius),
             *((d, d, s.head_radius) for d in pivots)]
    return max(r - min(lo, hi, lo * c, hi * c) for lo, hi, r in parts)


def _tilt(axis) -> float:
    """The most a head axis turns the tool away from its own line, rad: a turn by θ about a
    line at α to the tool leaves it at arccos(cos²α + sin²α cos θ) (θ itself across, 0
    along, 90° at 180° of a 45° nutating head)."""
    theta = min(np.pi, np.radians(max(map(abs, axis.travel))))
    cos_a = abs(axis.unit[2])
    return float(np.arccos(np.clip(cos_a**2 + (1 - cos_a**2) * np.cos(theta), -1, 1)))


def frames(machine: Machine, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nominal table frame (n, 4, 4), and in it the nest centre and the tool axis (n, 3)."""
    poses = Poses.at(q, np.zeros(3))
    zero = np.zeros((len(q), 6))
    table = chain_transform(machine, machine.workpiece, poses, {}, zero)
    tool = chain_transform(machine, machine.tool, poses, {}, zero)
    R = table[:, :3, :3]
    return (table, np.einsum("nji,nj->ni", R, nest_centre(machine, tool) - table[:, :3, 3]),
            np.einsum("nji,nj->ni", R, tool[:, :3, 2]))


def table_turn(machine: Machine, q: np.ndarray) -> np.ndarray:
    """(n, 3, 3): the nominal table frame's orientation in the machine frame at poses ``q``
    (its columns the table's x, y, z): the turns of the table's rotary axes about their own
    lines, in the chain's order (a linear axis turns nothing), where the whole chain's 4 × 4
    walk costs a second at 723 000 poses."""
    R = None
    for axis in machine.workpiece:
        if axis.rotary:            # Rodrigues about the axis's fixed line: c·I + s·[k]× + (1 − c)·kkᵀ
            k = np.asarray(axis.unit, float)
            cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
            angle = axis.sense * q[:, machine.index(axis.name)]
            c, s, kk = np.cos(angle), np.sin(angle), np.outer(k, k)
            turn = np.empty((len(q), 3, 3))
            for i, j in np.ndindex(3, 3):      # entry by entry: no (n, 3, 3) temporaries
                turn[:, i, j] = kk[i, j] + (float(i == j) - kk[i, j]) * c + cross[i, j] * s
            R = turn if R is None else R @ turn
    return np.broadcast_to(np.eye(3), (len(q), 3, 3)) if R is None else R


def sensor_axes(machine: Machine, q: np.ndarray) -> np.ndarray | None:
    """The R-test nest's sensor directions at poses ``q`` (n, 3, 3: column s is sensor s, in
    the machine frame): they turn with the tool, so on a head they are the tool's turned
    axes; None where no head turns the tool (the machine's own X, Y, Z)."""
    if not machine.heads:
        return None
    zero = np.zeros((len(q), 6))
    return chain_transform(machine, machine.tool, Poses.at(q, np.zeros(3)), {}, zero)[:, :3, :3]


def sensors_on_ball(machine: Machine, q: np.ndarray,
                    axes: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each R-test sensor's direction at poses ``q`` (n, 3, 3: column s sensor s) in the
    machine frame (``sensor_axes``, the machine's X, Y, Z under a fixed spindle) and in the
    nominal table frame, where the ball and its stem stand. ``axes``: ``sensor_axes`` where
    the caller has them already (on a head, a walk of the tool's chain)."""
    axes = sensor_axes(machine, q) if axes is None else axes
    if axes is None:           # the machine's X, Y, Z: in the table frame, the table's turn's rows
        return np.broadcast_to(np.eye(3), (len(q), 3, 3)), table_turn(machine, q).transpose(0, 2, 1)
    return axes, np.einsum("nji,njs->nis", table_turn(machine, q), axes)


def along_tool(machine: Machine, q: np.ndarray, d: float) -> np.ndarray:
    """Poses ``q`` (n, k) with the nest moved ``d`` mm along the tool axis, away from the
    table (the rotary axes held): machine Z where no head tilts the tool."""
    zero = np.zeros((len(q), 6))
    axis = chain_transform(machine, machine.tool, Poses.at(q, np.zeros(3)), {}, zero)[:, :3, 2]
    out = np.array(q, float)
    out[:, [machine.index(c) for c in "XYZ"]] += d * axis
    return out


def at_height(machine: Machine, q: np.ndarray, z: float) -> np.ndarray:
    """Poses ``q`` (n, k) with the nest centre at height ``z`` mm of the machine frame (the
    rotary axes held): Z itself where no head turns the nest away from the axes' position."""
    out = np.array(q, float)
    rotary = [machine.index(a.name) for a in machine.rotary_axes]
    out[:, machine.index("Z")] = z - head_offset(machine, out[:, rotary])[:, 2]
    return out


def head_pivots(machine: Machine, q: np.ndarray) -> np.ndarray:
    """Each head's pivot at poses ``q`` (n, k), in the table frame: (n, heads, 3) mm, where
    its body stands (``[rtest] head_radius`` about it)."""
    poses = Poses.at(q, np.zeros(3))
    zero = np.zeros((len(q), 6))
    table = chain_transform(machine, machine.workpiece, poses, {}, zero)
    out = []
    for i, axis in enumerate(machine.tool):
        if axis.rotary:
            before = chain_transform(machine, machine.tool[:i], poses, {}, zero)
            pivot = machine.gauge + before[:, :3, 3] + np.einsum("nij,j->ni", before[:, :3, :3], axis.offset)
            out.append(np.einsum("nji,nj->ni", table[:, :3, :3], pivot - table[:, :3, 3]))
    return np.stack(out, axis=1) if out else np.zeros((len(q), 0, 3))


def table_axis_down(machine: Machine, q: np.ndarray) -> np.ndarray:
    """(n, 3): the table frame's −z in the machine frame at poses ``q``: where a stem
    standing on the table points from the ball."""
    return -frames(machine, q)[0][:, :3, 2]


def table_point(machine: Machine, q: np.ndarray) -> np.ndarray:
    """The table-frame point under the nest centre at poses ``q`` (n, k), mm."""
    return frames(machine, q)[1]


def world(machine: Machine, q: np.ndarray) -> np.ndarray:
    """The TCP coordinates of poses ``q``: the linear axes that put the nest on the same
    table point with the rotary axes at zero (what compgen writes under TCPM/TRAORI/trt)."""
    rot = np.zeros((len(q), len(machine.rotary_axes)))
    linear = [machine.index(c) for c in "XYZ"]
    return inverse(machine, rot, table_point(machine, q))[:, linear]


def from_world(machine: Machine, xyz: np.ndarray, rot_rad: np.ndarray) -> np.ndarray:
    """Poses that put the nest on the table point with TCP coordinates ``xyz`` at ``rot_rad``."""
    q0 = np.zeros((len(xyz), len(machine.axes)))
    q0[:, [machine.index(c) for c in "XYZ"]] = xyz
    return inverse(machine, rot_rad, table_point(machine, q0))
