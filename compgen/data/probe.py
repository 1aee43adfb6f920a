"""Touch-probe logs on a calibration sphere (``docs/probe-log.md``): reading, each pose's
sphere centre with its covariance, and the checks a metrologist expects before a centre
is used.

A touch's tip centre lies on the sphere of radius ρ = (sphere + stylus diameter)/2 about
the true centre. Each pose's centre is the least-squares point on that known radius; the
trigger noise is pooled over every touch of the log (one probe, one stylus), so a pose's
covariance s²(JᵀJ)⁻¹ has the log's degrees of freedom, not its own two or three. The
centre then stands where the nest would have read the ball: its reading, nest minus
ball, is the commanded (nominal) centre minus the probed one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import CompgenError, one_line
from ..files import read_text
from ..model.frames import sensor_axes, table_axis_down
from ..model.kinematics import head_offset, inverse
from ..model.machine import Machine, ProbeSetup
from ..model.poses import Poses
from ..units import number
from .rtest import BALL, READING_MAX_MM, RTestData, axis_cells, read_table

MAGIC = "# compgen probe log v1"
PROBE_FAMILY = "# compgen probe log"
DIRECTION = ("nx", "ny", "nz")
MIN_TOUCHES = 4              # a centre on a known radius needs three; one more shows the noise
FLAT = 0.1                   # touch directions spreading less than this (rms) out of a plane: no centre
RADIAL_COS = 0.5             # a touch moving more than 60° off the centre did not come radially
OUTLIER_K, OUTLIER_UM = 5.0, 2.0     # a touch this many σ and µm off its pose's sphere: a bad trigger
OUTLIER_ALPHA = 1e-3         # and beyond Student's t of the log's touches at this rate for a clean log
RADIUS_K, RADIUS_UM = 4.0, 2.0       # the touches' sphere this many σ and µm off ρ: a wrong stylus
ITERATIONS = 8
NOISELESS_MM = 5e-5           # triggers scattering less (0.05 µm): a simulation; exact repeats are real
TOUCH_S = 3.0                # s from one touch to the next, as a simulated log times them
# A kinematic probe triggers on its three contacts: its pre-travel, and so the radius at which
# it triggers, varies in three lobes about the stylus (the spindle's axis, the spindle held at
# one orientation): R + a·sin³θ·cos 3(φ − φ₀), θ from the spindle axis, φ about it, of the
# direction the stylus moves. A fixed spindle keeps that frame the machine's.
TRIGGER_LOBES = 3


@dataclass(frozen=True, eq=False)
class ProbeLog:
    """A probe log as read: one row per touch, mm and rad, with its CSV line."""

    source: str
    sha256: str
    keys: dict[str, str]
    key_lines: dict[str, int]
    path: np.ndarray          # (m,) label of each touch
    pose: np.ndarray          # (m,) pose number
    rotary: np.ndarray        # (m, r) rad, machine.rotary_axes order
    tip: np.ndarray           # (m, 3) stylus tip centre at the trigger, machine frame
    direction: np.ndarray     # (m, 3) unit direction of motion at the trigger
    t: np.ndarray             # (m,) s, NaN where not recorded
    ball: np.ndarray          # (m, 3) nominal sphere centre, table frame
    lines: np.ndarray         # (m,) CSV line of each touch

    @property
    def spindle(self) -> float:
        """The spindle's orientation while probing, rad (the log's ``spindle_deg``, 0 where it
        does not say): the probe's trigger lobes turn with it."""
        if "spindle_deg" not in self.keys:
            return 0.0
        where = f"{self.source}:{self.key_lines['spindle_deg']}"
        v = number(self.keys["spindle_deg"], "spindle_deg", where)
        if not (math.isfinite(v) and -360.0 <= v <= 360.0):
            raise CompgenError(f"spindle_deg {self.keys['spindle_deg']!r} is no spindle orientation in "
                               "degrees", where=where)
        return math.radians(v)

    @property
    def radius(self) -> float:
        """ρ, mm: the tip centre's distance from the sphere's centre at a touch."""
        return (number(self.keys["sphere_diameter"], "sphere_diameter", self.source)
                + number(self.keys["stylus_diameter"], "stylus_diameter", self.source)) / 2


@dataclass(frozen=True, eq=False)
class Centres:
    """The sphere centre of every pose (machine frame, mm) and what backs it."""

    data: RTestData           # the centres as readings: nominal minus probed, with covariance
    centre: np.ndarray        # (n, 3) mm
    sigma_um: float           # pooled trigger noise, 1σ per touch
    dof: int
    radius_offset_um: float   # the touches' sphere minus ρ, pooled, and its σ
    radius_sigma_um: float
    warnings: tuple[str, ...]


def is_probe_log(text: str) -> bool:
    """The first line is the version line, exactly (``v10`` is not ``v1``)."""
    return text.lstrip("\ufeff").split("\n", 1)[0].rstrip() == MAGIC


def read_probe_log(path, machine: Machine) -> ProbeLog:
    """A probe log v1 for ``machine``, every cell checked; a problem names file and line."""
    where = str(path)
    text, _ = read_text(path, "probe log")
    if not is_probe_log(text):
        first = one_line(text.lstrip("\ufeff").split("\n", 1)[0].rstrip()[:60])
        raise CompgenError(f"not a probe log v1: its first line is {first!r}, not {MAGIC!r}",
                           where=f"{where}:1",
                           hint="a probing program compgen wrote starts its log with that line; a newer "
                                "version needs the compgen that wrote it")
    keys, key_lines = {}, {}
    for i, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if s and not s.startswith("#"):
            break
        name, eq, value = s.lstrip("#").partition("=")
        name = name.strip()
        if eq and i > 1:
            if name in keys:       # which of two values the probe had is not for compgen to guess
                raise CompgenError(f"the log's set-up gives {name} twice (line {key_lines[name]} and "
                                   f"line {i})", where=f"{where}:{i}",
                                   hint="keep the one the probe was calibrated with")
            keys[name], key_lines[name] = value.strip(), i
    for key in ("sphere_diameter", "stylus_diameter"):
        if key not in keys:
            raise CompgenError(f"the log's set-up does not give {key} (mm)", where=where,
                               hint=f"add a comment line '# {key} = VALUE' before the header")
        v = number(keys[key], key, f"{where}:{key_lines[key]}")
        if not 0 < v < 1000:
            raise CompgenError(f"{key} {keys[key]!r} is not a diameter in mm",
                               where=f"{where}:{key_lines[key]}")
    if "machine" in keys and keys["machine"] != machine.name:
        raise CompgenError(f"the log was written for machine {keys['machine']!r}, not {machine.name!r}",
                           where=f"{where}:{key_lines['machine']}",
                           hint="give the machine file the log was measured on with --machine")
    rotary = [a.name for a in machine.rotary_axes]
    table = read_table(path, machine, ["pose", "X", "Y", "Z", *rotary, *DIRECTION])
    lines = np.array(table.lines)
    pose = table.columns["pose"]
    bad = np.flatnonzero((pose < 1) | (pose != np.round(pose)))
    if bad.size:
        raise CompgenError(f"pose {pose[bad[0]]:g} is not a whole number from 1",
                           where=f"{where}:{lines[bad[0]]}")
    direction = np.column_stack([table.columns[c] for c in DIRECTION])
    norm = np.linalg.norm(direction, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1) > 1e-3)
    if bad.size:
        raise CompgenError(f"nx, ny, nz has length {norm[bad[0]]:.4g}, not 1: not a direction",
                           where=f"{where}:{lines[bad[0]]}", hint="give the unit vector the tip moved along")
    return ProbeLog(where, table.sha256, keys, key_lines, table.labels, pose.astype(int),
                    np.radians(np.column_stack([table.columns[a] for a in rotary])),
                    np.column_stack([table.columns[c] for c in "XYZ"]), direction / norm[:, None],
                    table.columns.get("t", np.full(len(pose), np.nan)), table.ball(machine), lines)


def sphere_centres(log: ProbeLog, machine: Machine) -> Centres:
    """Each pose's centre on the known radius, its covariance from the pooled touch
    residuals, and every check; a failed check is refused naming the pose and line."""
    where, rho = log.source, log.radius
    groups = _poses(log)
    centres, normals, residuals, warnings = [], [], [], []
    counts = np.array([len(g) for g in groups])
    usual = int(np.median(counts))
    for g in groups:
        if len(g) < MIN_TOUCHES:
            raise CompgenError(f"{_at(log, g)} has {len(g)} touch{'es' * (len(g) != 1)}; a sphere centre "
                               f"needs {MIN_TOUCHES} not in one plane", where=f"{where}:{log.lines[g[0]]}",
                               hint="re-probe the pose, or delete its lines")
    fitted = _centres(log, groups, rho)
    for g, (c, u, weakest) in zip(groups, fitted, strict=True):
        _check_pose(log, g, u, weakest, usual, warnings)
        p = log.tip[g]
        centres.append(c)
        normals.append(u)
        residuals.append(np.linalg.norm(p - c, axis=1) - rho)
    dof = int(counts.sum() - 3 * len(groups))      # ≥ 1 a pose: each has MIN_TOUCHES ≥ 4
    r_all = np.concatenate(residuals)
    s2 = float(r_all @ r_all) / dof
    inverse_info = [np.linalg.inv(u.T @ u) for u in normals]     # (JᵀJ)⁻¹ of each pose
    _check_outliers(log, groups, normals, residuals, inverse_info, float(r_all @ r_all), dof)
    # one stylus for the whole log: its radius error is common to every pose
    num = den = 0.0
    for u, r, G in zip(normals, residuals, inverse_info, strict=True):
        ones = np.ones(len(u))
        perp = ones - u @ (G @ (u.T @ ones))
        num, den = num + perp @ r, den + perp @ perp
    radius_offset = num / den
    radius_sigma = math.sqrt(s2 / den)
    if abs(radius_offset) * 1e3 > RADIUS_UM and abs(radius_offset) > RADIUS_K * radius_sigma:
        key = "stylus_diameter"
        raise CompgenError(f"the touches lie on a sphere {radius_offset * 1e3:+.1f} ± "
                           f"{radius_sigma * 1e3:.1f} µm "
                           f"off the calibrated radius (sphere + stylus)/2 = {rho:.4f} mm",
                           where=f"{where}:{log.key_lines[key]}",
                           hint=f"the stylus diameter in the log ({log.keys[key]} mm) or the sphere's is not "
                                "what "
                                "the probe has: calibrate the stylus on the control and probe again")
    copy = _copies(log, groups)
    scatter = math.sqrt(max(float(r_all @ r_all) - num * num / den, 0.0) / max(dof - 1, 1))
    if copy and scatter > NOISELESS_MM:        # the triggers' scatter, the stylus's common error taken out
        i, j = copy
        raise CompgenError(f"this pose's touches repeat those from line {log.lines[j]} in every number, "
                           f"though the log's triggers scatter {scatter * 1e3:.2f} µm: a pose logged twice "
                           "(or copied) would count as two", where=f"{where}:{log.lines[i]}",
                           hint="delete the repeated pose's lines")
    centre = np.array(centres)
    cov = s2 * np.array(inverse_info)
    first = np.array([g[0] for g in groups])
    rotary = log.rotary[first]
    ball = log.ball[first]
    nest = stylus_nest(machine, len(groups))
    q = inverse(machine, rotary, ball, nest=nest)
    reading = tip_centres(machine, q, nest) - centre
    far = np.flatnonzero(np.abs(reading).max(axis=1) > READING_MAX_MM)
    if far.size:
        k = far[0]
        raise CompgenError(f"the sphere of {_at(log, groups[k])} is {np.abs(reading[k]).max():.3f} mm from "
                           "where the "
                           "machine file puts it", where=f"{where}:{log.lines[groups[k][0]]}",
                           hint="the machine file's ball position does not match the sphere: give its "
                                "place in [rtest] ball, or per row in bx, by, bz")
    t = np.array([np.nanmin(log.t[g]) if not np.isnan(log.t[g]).all() else np.nan for g in groups])
    poses = Poses(q, ball, t, log.path[first], nest=nest)
    data = RTestData(poses, reading, log.source, log.sha256, tuple(int(log.lines[i]) for i in first),
                     device="probe", cov=cov, cov_dof=dof,
                     lobes=trigger_lobes(log, groups, normals, inverse_info, sensor_axes(machine, q)),
                     spindle=math.degrees(log.spindle))
    return Centres(data, centre, math.sqrt(s2) * 1e3, dof, radius_offset * 1e3, radius_sigma * 1e3,
                   tuple(warnings))


def trigger_lobes(log: ProbeLog, groups: list[np.ndarray], normals: list[np.ndarray],
                  inverse_info: list[np.ndarray], stylus: np.ndarray | None = None) -> np.ndarray:
    """(n, 3, 2): each pose's reading per mm of the trigger's lobes' cos and sin amplitude
    (``TRIGGER_LOBES``): a touch triggering δ farther out along its normal moves the centre
    on the known radius by N⁺δ (N = −u the touches' outward normals, u their unit vectors to
    the centre, first order), and the reading, nominal minus probed, by −N⁺δ = (uᵀu)⁻¹uᵀδ
    (``inverse_info``: each pose's (uᵀu)⁻¹); δ by the direction each touch moved
    (``log.direction``) in the probe's own frame: ``stylus`` (n, 3, 3), the tool's axes
    where a head turns the probe (``frames.sensor_axes``), None where they are the machine's,
    turned by the spindle's orientation (``log.spindle``: the probe turns with the spindle)."""
    out = np.zeros((len(groups), 3, 2))
    turn = log.spindle
    for k, (g, u, G) in enumerate(zip(groups, normals, inverse_info, strict=True)):
        d = log.direction[g] if stylus is None else log.direction[g] @ stylus[k]
        lobe = (np.hypot(d[:, 0], d[:, 1]) ** TRIGGER_LOBES
                * np.exp(1j * TRIGGER_LOBES * (np.arctan2(d[:, 1], d[:, 0]) - turn)))   # sin³θ·e^{3i(φ−s)}
        out[k] = G @ (u.T @ np.stack([lobe.real, lobe.imag], axis=1))
    return out


def _check_pose(log: ProbeLog, g: np.ndarray, u: np.ndarray, weakest: float, usual: int,
                warnings: list[str]) -> None:
    """One pose's touches as one centre needs them: one rotary position, one sphere place,
    directions that span space, each touch radial to the fitted centre; a pose with fewer
    touches than the others is warned of."""
    where = log.source
    at = _at(log, g)
    if np.ptp(log.rotary[g], axis=0).max() > math.radians(1e-4):
        off = np.abs(log.rotary[g] - np.median(log.rotary[g], axis=0)).max(axis=1)
        raise CompgenError(f"the touches of {at} are at different rotary positions",   # the odd one named
                           where=f"{where}:{log.lines[g[np.argmax(off)]]}",
                           hint="every touch of one pose shares its rotary axes; number the poses apart")
    moved = np.flatnonzero(np.abs(log.ball[g] - log.ball[g[0]]).max(axis=1) > 1e-6)
    if moved.size:      # one centre is fitted from all its touches: one sphere, one place
        raise CompgenError(f"the touches of {at} name different sphere centres (bx, by, bz)",
                           where=f"{where}:{log.lines[g[moved[0]]]}",
                           hint="every touch of one pose probes one sphere where it stands; "
                                "number the poses apart")
    # on a known radius, touches in one plane still fix the centre (four side touches
    # without the top one) unless they all look at it from one plane through it: the
    # directions, not the points, must span space
    if weakest < FLAT:
        raise CompgenError(f"the {len(g)} touches of {at} all come from about one plane through the "
                           f"centre (out of it by {weakest:.2f} rms of a unit direction): the centre is "
                           "not fixed across it",
                           where=f"{where}:{log.lines[g[0]]}",
                           hint="probe it from above as well as around (compgen probe-program does)")
    off = np.einsum("ij,ij->i", u, log.direction[g])
    if off.min() < RADIAL_COS:
        k = int(np.argmin(off))
        raise CompgenError(f"touch of {at} moved {math.degrees(math.acos(np.clip(off[k], -1, 1))):.0f}° "
                           "off the line to the fitted centre: not a radial touch of this sphere",
                           where=f"{where}:{log.lines[g[k]]}",
                           hint="check nx, ny, nz (the direction the tip moved) and that the line "
                                "belongs to this pose")
    if len(g) < usual:
        warnings.append(f"{where}:{log.lines[g[0]]}: {at} has {len(g)} touches where the others have "
                        f"{usual}: a touch is missing (its centre is fitted from the rest)")


def _check_outliers(log: ProbeLog, groups, normals, residuals, inverse_info, rss: float, dof: int) -> None:
    """No touch off the sphere its pose's other touches fit by more than OUTLIER_K of the
    trigger scatter the log's other touches show and OUTLIER_UM (a chip, a bad trigger): each
    touch's residual studentized by the pooled scatter without it (a bad trigger does not
    inflate the σ it is judged by). A median's scale of one path's 60 touches, as it was,
    read 0.25 µm for a 0.5 µm trigger one log in a hundred and refused a clean touch. The
    bound is OUTLIER_K or, where more, Student's t at OUTLIER_ALPHA over the log's touches
    (each studentized residual is t with dof − 1): 5.4 for one path's 60 touches."""
    from scipy.special import stdtrit  # here: only a probe log's reading pays its import

    where = log.source
    bound = max(OUTLIER_K, float(stdtrit(max(dof - 1, 1), 1 - OUTLIER_ALPHA / (2 * sum(map(len, groups))))))
    for g, u, r, G in zip(groups, normals, residuals, inverse_info, strict=True):
        h = np.einsum("ij,jk,ik->i", u, G, u)
        room = np.maximum(1 - h, 1e-6)
        deleted = np.where(1 - h > 1e-6, r / room, 0.0)
        others = np.sqrt(np.maximum(rss - r * deleted, 1e-14) / max(dof - 1, 1))    # σ without the touch
        z = np.where(1 - h > 1e-6, np.abs(r) / (others * np.sqrt(room)), 0.0)
        k = int(np.argmax(z))
        if z[k] > bound and abs(deleted[k]) * 1e3 > OUTLIER_UM:
            raise CompgenError(f"a touch of {_at(log, g)} lies {deleted[k] * 1e3:+.1f} µm off the sphere its "
                               f"other touches fit ({z[k]:.0f}σ of the {others[k] * 1e3:.2f} µm trigger "
                               "noise the log's other touches show): a chip on the sphere or a bad trigger",
                               where=f"{where}:{log.lines[g[k]]}",
                               hint="clean the sphere and re-probe the pose, or delete the line")


def _poses(log: ProbeLog) -> list[np.ndarray]:
    """The touch indices of each (path, pose), in order of first appearance; a pose whose
    touches are not together in the log is refused (two poses numbered alike)."""
    keys = list(zip(log.path.tolist(), log.pose.tolist(), strict=True))
    order = dict.fromkeys(keys)
    groups = {k: [] for k in order}
    for i, k in enumerate(keys):
        groups[k].append(i)
    for k, g in groups.items():
        if g[-1] - g[0] + 1 != len(g):
            gap = next(i for i in range(g[0], g[-1]) if keys[i] != k)
            raise CompgenError(f"the touches of {k[0] or 'path'} pose {k[1]} are not together: another "
                               "pose's "
                               "touch is among them", where=f"{log.source}:{log.lines[gap]}",
                               hint="number each pose once, or give it another path label")
    return [np.array(g) for g in groups.values()]


def _copies(log: ProbeLog, groups: list[np.ndarray]) -> tuple[int, int] | None:
    """A touch logged twice, or a pose copied under another number, would count as more
    touches than were made (one pose copied 4000 times outweighs the rest of the log). A
    touch repeating another of its own pose in every number is refused here (their
    directions differ). A pose whose every touch repeats another pose's is returned (its
    first line, the other's), for the caller to refuse when the log shows trigger noise:
    one touch may repeat another by chance (a control reports a touch from above at the X
    and Y it commanded, 0.1 µm digits), a whole pose does not; a noise-free simulation
    repeats a pose exactly."""
    touch = [log.tip[i].tobytes() + log.direction[i].tobytes() for i in range(len(log.lines))]
    poses: dict[bytes, int] = {}
    across = None
    for g in groups:
        mine: dict[bytes, int] = {}
        for i in g:
            if touch[i] in mine:
                raise CompgenError(f"this touch of {_at(log, g)} repeats line {log.lines[mine[touch[i]]]} in "
                                   "every number: a touch logged twice counts twice",
                                   where=f"{log.source}:{log.lines[i]}", hint="delete the repeated line")
            mine[touch[i]] = int(i)
        whole = b"".join(touch[i] for i in g)
        if whole in poses and across is None:
            across = (int(g[0]), poses[whole])
        poses.setdefault(whole, int(g[0]))
    return across


def _at(log: ProbeLog, g: np.ndarray) -> str:
    label = log.path[g[0]]
    return f"{label + ' ' if label else ''}pose {log.pose[g[0]]}"


def _centres(log: ProbeLog, groups: list[np.ndarray],
             rho: float) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Each pose's centre at distance ρ from its tip centres (least squares, Gauss-Newton
    started where each touch says it is, one radius along its direction of motion), the
    unit vectors from its touches to it, and how well they span space (the smallest
    singular value over √m). Poses with as many touches are solved together: a 20 MB log
    in seconds."""
    out: list = [None] * len(groups)
    by_count: dict[int, list[int]] = {}
    for k, g in enumerate(groups):
        by_count.setdefault(len(g), []).append(k)
    for m, ks in by_count.items():
        idx = np.array([groups[k] for k in ks])
        p = log.tip[idx]                                            # (k, m, 3)
        c = (p + rho * log.direction[idx]).mean(axis=1)
        for _ in range(ITERATIONS):
            d = c[:, None, :] - p
            dist = np.linalg.norm(d, axis=2)
            u = d / dist[..., None]
            step = (np.linalg.pinv(u) @ (rho - dist)[..., None])[..., 0]
            c = c + step
            if np.abs(step).max() < 1e-10:
                break
        d = c[:, None, :] - p
        u = d / np.linalg.norm(d, axis=2)[..., None]
        weakest = np.linalg.svd(u, compute_uv=False)[:, 2] / math.sqrt(m)
        for j, k in enumerate(ks):
            out[k] = (c[j], u[j], float(weakest[j]))
    return out


# ---------------------------------------------------------------------------- touching plan

def probe_poses(machine: Machine, names, ball=None) -> Poses:
    """The poses a probing program stops at: each named path's poses thinned to the
    machine file's ``[probe] poses``, evenly spread, first and last kept. (A touch takes
    seconds: a path's hundreds of R-test poses would take hours.)"""
    from ..model.paths import generate

    setup = need_probe(machine)
    if not names:
        raise CompgenError("no path is named", hint=f"name one or more of {', '.join(machine.paths)} "
                                                     "(comma-separated), or all")
    out = []
    for name in names:
        p = generate(machine, [name], ball=ball, nest=setup.length if machine.heads else None)
        keep = np.unique(np.round(np.linspace(0, len(p) - 1, min(setup.poses, len(p)))).astype(int))
        out.append(p.take(keep))
    return Poses.concat(out)


def need_probe(machine: Machine) -> ProbeSetup:
    if machine.probe is None:
        raise CompgenError(f"machine file {machine.source} has no [probe] section",
                           hint="add the probe's tool, length, sphere_diameter and stylus_diameter "
                                "(see the bundled machines)")
    return machine.probe


def stylus_nest(machine: Machine, n: int) -> np.ndarray | None:
    """Each of ``n`` probed poses' tool point below the gauge line (``Poses.nest``), mm: on
    a head the stylus tip, ``[probe] length`` down the tool, is what the head's angles turn
    (their lever); None where no head tilts the tool (the linear axes carry the tip)."""
    return np.full(n, need_probe(machine).length) if machine.heads else None


def tip_centres(machine: Machine, q: np.ndarray, nest: np.ndarray | None) -> np.ndarray:
    """The stylus tip's centre (n, 3) on the nominal machine at poses ``q``, machine frame,
    mm: the linear axes' position, and on a head where its turn puts the tip from there
    (``nest``: ``stylus_nest``'s lengths)."""
    rotary = [machine.index(a.name) for a in machine.rotary_axes]
    return q[:, [machine.index(c) for c in "XYZ"]] + head_offset(machine, q[:, rotary], nest)


def simulate_touches(machine: Machine, poses: Poses, reading: np.ndarray, noise_um: float = 0.0,
                     rng: np.random.Generator | None = None, stylus_error_um: float = 0.0):
    """Tip centres and directions (n, m, 3) of probing ``poses`` where the sphere's
    readings (nest minus ball, mm, as ``simulate`` gives them) are ``reading``: each touch
    radial, its trigger off the true radius by noise of σ ``noise_um``; the stylus's real
    diameter ``stylus_error_um`` larger than calibrated."""
    setup = need_probe(machine)
    rng = rng or np.random.default_rng()
    centre = tip_centres(machine, poses.q, stylus_nest(machine, len(poses))) - reading
    u = touch_directions(machine, poses, setup)
    rho = (setup.sphere_diameter + setup.stylus_diameter + stylus_error_um * 1e-3) / 2
    radius = rho + rng.normal(0.0, noise_um * 1e-3, u.shape[:2])
    return centre[:, None, :] + radius[..., None] * u, -u

def touch_directions(machine: Machine, poses: Poses, setup: ProbeSetup) -> np.ndarray:
    """(n, m, 3): for each pose, the unit vectors from the sphere's centre to where the
    probe touches it (machine frame). One touch along the stylus (from above where the tool
    does not tilt), the rest around it at ``elevation`` above the plane across it, turned so
    that the stem, wherever the rotary axes point it, lies midway between two of them. On a
    head the stylus turns with the tool: the touches turn with it."""
    up = stylus_up(machine, poses.q)
    across = np.where(np.abs(up[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = across - np.einsum("ni,ni->n", across, up)[:, None] * up
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(up, e1)                     # (x, y) where the stylus points down Z
    stem = table_axis_down(machine, poses.q)
    s1, s2 = np.einsum("ni,ni->n", stem, e1), np.einsum("ni,ni->n", stem, e2)
    around = setup.touches - 1
    el = math.radians(setup.elevation)
    azimuth0 = np.arctan2(s2, s1) + math.pi / around
    flat = np.hypot(s1, s2) < 1e-9            # stem straight down the stylus: any turn will do
    azimuth0 = np.where(flat, 0.0, azimuth0)
    k = np.arange(around)
    az = azimuth0[:, None] + 2 * math.pi * k[None, :] / around
    side = (math.cos(el) * (np.cos(az)[..., None] * e1[:, None, :] + np.sin(az)[..., None] * e2[:, None, :])
            + math.sin(el) * up[:, None, :])
    return np.concatenate([up[:, None, :], side], axis=1)


def stylus_up(machine: Machine, q: np.ndarray) -> np.ndarray:
    """(n, 3): the unit vector up the stylus, from its tip to the spindle, machine frame:
    +Z where no head tilts the tool, the tool's turned axis on a head."""
    axes = sensor_axes(machine, q)
    if axes is None:
        return np.broadcast_to([0.0, 0.0, 1.0], (len(q), 3))
    return np.ascontiguousarray(axes[:, :, 2])


def format_probe_log(machine: Machine, setup: ProbeSetup, poses: Poses, tips: np.ndarray,
                     directions: np.ndarray, comments: tuple[str, ...] = ()) -> str:
    """A probe log v1: ``tips`` and ``directions`` (n, m, 3) per pose and touch."""
    rotary = [machine.index(a.name) for a in machine.rotary_axes]
    names = [a.name for a in machine.rotary_axes]
    out = [MAGIC, *(f"# {one_line(c)}" for c in comments),
           f"# sphere_diameter = {setup.sphere_diameter:.4f}",
           f"# stylus_diameter = {setup.stylus_diameter:.4f}",
           f"# machine = {machine.name}",
           ",".join(["path", "pose", "t", *names, "X", "Y", "Z", *DIRECTION, *BALL])]
    timed = not np.isnan(poses.t).any()
    if not timed:
        out[-1] = out[-1].replace(",t,", ",")
    number = {}
    for i in range(len(poses)):
        label = str(poses.path[i])
        number[label] = number.get(label, 0) + 1
        angles = axis_cells(machine, poses.q[i])
        for j in range(tips.shape[1]):
            out.append(",".join([label, str(number[label]), *([f"{poses.t[i] + TOUCH_S * j:.3f}"] * timed),
                                 *(angles[r] for r in rotary), *(f"{v:.5f}" for v in tips[i, j]),
                                 *(f"{v:.6f}" for v in directions[i, j]),
                                 *(f"{v:.4f}" for v in poses.ball[i])]))
    return "\n".join(out) + "\n"
