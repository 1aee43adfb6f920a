"""Test paths as pose generators, from the machine file's path definitions.

A label is a name, not a definition (contract §4): the poses come from ``[paths.<name>]``
in the machine file. ISO 10791-6:2014's BK1/BK2/BK4 are accepted as aliases of K1/K2/K4.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..errors import CompgenError
from ..files import MAX_DATA_BYTES
from .kinematics import inverse
from .machine import Machine, PathDef, at_nest, check_travel
from .poses import Poses
from .sides import program_sides

GAP_S = 20.0   # pause between two paths of one session (re-positioning), s
MAX_POSES = MAX_DATA_BYTES // 96   # a CSV v1 row of five axes is ~96 bytes: ~2.8 million readings


def path_def(machine: Machine, name: str) -> PathDef:
    """The machine's definition of path ``name`` (``BK4`` finds ``K4``)."""
    key = name.strip()
    if key not in machine.paths and key.upper().startswith("BK") and key[1:] in machine.paths:
        key = key[1:]
    if key not in machine.paths:
        raise CompgenError(f"machine {machine.name!r} defines no path {name!r}",
                           hint=f"it defines {', '.join(machine.paths) or 'none'}; add "
                                f"[paths.{name}] to the machine file")
    return machine.paths[key]


def rotary_positions(machine: Machine, path: PathDef, n: int | None = None) -> np.ndarray:
    """(n, r) rotary axis positions of a path, deg, in ``machine.rotary_axes`` order, at its
    own ``n`` poses or at ``n`` evenly spread."""
    s = np.linspace(0.0, 1.0, path.n if n is None else n)
    cols = []
    for axis in machine.rotary_axes:
        kind, *a = path.rotary[axis.name]
        if kind == "const":
            cols.append(np.full_like(s, a[0]))
        elif kind == "ramp":
            cols.append(a[0] + (a[1] - a[0]) * s)
        else:
            cols.append(a[0] + a[1] * np.sin(2 * np.pi * a[2] * s))
    return np.column_stack([axis.on_grid(c) for axis, c in zip(machine.rotary_axes, cols, strict=True)])


def generate(machine: Machine, names: Sequence[str], ball: Sequence[float] | None = None,
             start_s: float = 0.0, back: bool = False, rate_hz: float | None = None,
             feed: float | None = None, nest: float | None = None) -> Poses:
    """Poses of the named paths run one after another, with the nest on the ball (TCPM);
    with ``back``, each path is run there and back (every axis reverses: what a reversal
    error needs to be seen).

    With ``rate_hz`` the session is continuous, as an R-test sampling on the fly records
    it: a reading every 1/rate_hz s while each path runs at ``feed`` (deg/min, the mean
    speed of its most-travelled rotary axis; default the path's own pace, n poses of
    seconds_per_pose). Every pose is checked against the machine's travel; the first one
    outside is named. ``nest``: the nest's length below the gauge line, mm, where it is not
    the machine file's ``probe_length`` (on a head, the axes follow it).
    """
    if not names:
        raise CompgenError("no path is named", hint=f"name one or more of {', '.join(machine.paths)} "
                                                     "(comma-separated), or all")
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise CompgenError(f"the sampling rate must be a finite number > 0 Hz, not {rate_hz}")
    if feed is not None and not (math.isfinite(feed) and feed > 0):
        raise CompgenError(f"the feed must be a finite number > 0 deg/min, not {feed}")
    ball = np.asarray(machine.ball if ball is None else ball, dtype=float)
    at = at_nest(machine, nest, "--probe-length")
    out, t0 = [], start_s
    for name in names:
        path = path_def(machine, name)
        if rate_hz is None:
            angles, step = rotary_positions(machine, path), path.seconds_per_pose
            if machine.hirth_axes:
                # a Hirth axis rests on its grid: poses the grid makes one are measured once
                angles = angles[np.r_[True, np.any(np.diff(angles, axis=0) != 0, axis=1)]]
        else:
            rest = [a.name for a in machine.at_rest_axes if path.rotary[a.name][0] != "const"]
            if rest:
                raise CompgenError(f"path {path.name} turns {', '.join(rest)}, Hirth-coupled or positioned "
                                   "by the PLC: it is measured at rest, not on the fly",
                                   hint="leave --rate-hz out")
            steps = _fine_steps(machine, path)
            seconds = path.n * path.seconds_per_pose if feed is None else 60 * steps.sum(axis=0).max() / feed
            _check_speed(machine, path, steps, seconds)
            n = round(seconds * rate_hz) + 1
            if n < 2:
                raise CompgenError(f"path {path.name} takes {seconds:.4g} s: at {rate_hz:g} Hz that is "
                                   "fewer than two readings",
                                   hint="give a higher --rate-hz or a lower --feed")
            if n + sum(len(o) for o in out) > MAX_POSES:
                raise CompgenError(f"{rate_hz:g} Hz over these paths makes more than {MAX_POSES} readings: "
                                   f"its data file would pass the {MAX_DATA_BYTES >> 20} MB compgen reads",
                                   hint="give a lower --rate-hz or a higher --feed")
            angles, step = rotary_positions(machine, path, n), 1.0 / rate_hz
        if back:
            angles = np.vstack([angles, angles[::-1]])
        n = len(angles)
        q = inverse(at, np.radians(angles), ball)
        t = t0 + step * np.arange(n)
        t0 = t[-1] + GAP_S
        check_travel(at, q, name)
        out.append(Poses(q, np.broadcast_to(ball, (n, 3)), t, np.full(n, path.name, dtype=object),
                         program_sides(machine, q, np.zeros(n)),    # as compgen's programs run it
                         np.full(n, np.nan if at is machine else at.probe_length)))
    return Poses.concat(out)


FINE = 10_000      # steps a path is cut into to measure its arc and its axes' peak speed


def _fine_steps(machine: Machine, path: PathDef) -> np.ndarray:
    """(FINE, r) each rotary axis's |step|, deg, over the path cut into FINE equal steps of s."""
    return np.abs(np.diff(rotary_positions(machine, path, FINE + 1), axis=0))


def arc(machine: Machine, path: PathDef) -> float:
    """Degrees travelled by the path's most-travelled rotary axis, there only."""
    return float(_fine_steps(machine, path).sum(axis=0).max())


def _check_speed(machine: Machine, path: PathDef, steps: np.ndarray, seconds: float) -> None:
    """Refuse a pace at which a rotary axis would pass its ``feed_max`` somewhere (``steps``
    as ``_fine_steps`` gives them)."""
    peak = steps.max(axis=0) * FINE / seconds * 60
    for axis, speed in zip(machine.rotary_axes, peak, strict=True):
        if speed > axis.feed_max:
            raise CompgenError(f"path {path.name} in {seconds:.4g} s would turn {axis.name} at up to "
                               f"{speed:.0f} deg/min, above its feed_max {axis.feed_max:g} deg/min",
                               hint="give a lower --feed")
