"""Test paths as pose generators, from the machine file's path definitions.

A label is a name, not a definition (contract §4): the poses come from ``[paths.<name>]``
in the machine file. ISO 10791-6:2014's BK1/BK2/BK4 are accepted as aliases of K1/K2/K4.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .errors import CompgenError
from .kinematics import Poses, inverse
from .machine import Machine, PathDef, check_travel

GAP_S = 20.0   # pause between two paths of one session (re-positioning), s


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


def rotary_positions(machine: Machine, path: PathDef) -> np.ndarray:
    """(n, r) rotary axis positions of a path, deg, in ``machine.rotary_axes`` order."""
    s = np.linspace(0.0, 1.0, path.n)
    cols = []
    for axis in machine.rotary_axes:
        kind, *a = path.rotary[axis.name]
        if kind == "const":
            cols.append(np.full_like(s, a[0]))
        elif kind == "ramp":
            cols.append(a[0] + (a[1] - a[0]) * s)
        else:
            cols.append(a[0] + a[1] * np.sin(2 * np.pi * a[2] * s))
    return np.column_stack(cols)


def generate(machine: Machine, names: Sequence[str], ball: Sequence[float] | None = None,
             start_s: float = 0.0, back: bool = False) -> Poses:
    """Poses of the named paths run one after another, with the nest on the ball (TCPM);
    with ``back``, each path is run there and back (every axis reverses: what a reversal
    error needs to be seen).

    Every pose is checked against the machine's travel; the first one outside is named.
    """
    if not names:
        raise CompgenError("no path is named", hint=f"name one or more of {', '.join(machine.paths)} "
                                                     "(comma-separated), or all")
    ball = np.asarray(machine.ball if ball is None else ball, dtype=float)
    out, t0 = [], start_s
    for name in names:
        path = path_def(machine, name)
        angles = rotary_positions(machine, path)
        if back:
            angles = np.vstack([angles, angles[::-1]])
        n = len(angles)
        q = inverse(machine, np.radians(angles), ball)
        t = t0 + path.seconds_per_pose * np.arange(n)
        t0 = t[-1] + GAP_S
        check_travel(machine, q, name)
        out.append(Poses(q, np.broadcast_to(ball, (n, 3)), t, np.full(n, path.name, dtype=object)))
    return Poses.concat(out)
