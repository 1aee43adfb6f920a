"""A diagnosis's follow-up written as a plan (``compgen diagnose --plan DIR``): the
measurements it advises, in its order, as ``compgen plan`` writes set-ups (each program
checked and timed), with what they bring beside the data already measured: each location
error's σ and the separations of the best candidate and its rivals (``apart.py``), with
the follow-ups and without them. ``plan --check DIR`` reads the fit's data again for its σ."""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from ..controllers.programs import checked_program
from ..data.rtest import Measurements, RTestData
from ..errors import CompgenError
from ..model.effects import Effect, resolve
from ..model.machine import Machine
from ..model.poses import Poses
from ..model.sides import SETUP
from ..statistics.device import form_columns
from ..statistics.diagnosis import Diagnosis
from .advice import MODE
from .plan import (
    MOUNT_MINUTES,
    Plan,
    Setup,
    covariance,
    fitted_columns,
    judged,
    scales,
    sigmas_of,
    told_by,
    worst_scaled,
)


def advised(found: Diagnosis) -> tuple[Sequence, list[str]]:
    """The measurements the diagnosis advises, in order, and the effects they are to tell
    apart: the path with the ball turned on its stem where the ball's form ties with the
    best (told beside it as the form's own columns, ``information``); the plan telling the
    best and its rivals apart; else the one measurement that shows most of what the data
    cannot see, and those effects."""
    if found.form_rival is not None and found.form_turned is not None:
        return (found.form_turned,), [found.significant[0].effect]
    if found.rivals_separated_by:
        return found.rivals_separated_by, [found.significant[0].effect, *found.rivals]
    m, shows = found.next_measurement
    if m is None:
        raise CompgenError("this diagnosis advises no measurement: there is no follow-up to plan",
                           hint="its text says why (explained, unexplained, or nothing this machine can "
                                "measure would tell more)")
    return (m,), list(shows)


class Form(NamedTuple):
    """The ball's form of ``k`` lobes as a plan tells it beside the machine's effects: its
    name and its two columns' (cos, sin of the lobes in the ball's frame)."""

    name: str
    params: tuple[str, str] = ("cos", "sin")


def information(machine: Machine, poses: Poses, effects: Sequence[Effect | Form]) -> np.ndarray:
    """Per unit noise, over the location errors (``judged``) and the effects' parameters:
    every mounting's ball offset and each later nest's taken out (their columns projected out,
    the first mounting's by a Schur complement), as a fit of these poses would have them. A
    ``Form``'s columns turn with the ball on its stem (``poses.turn``)."""
    effects_ = [e for e in effects if not isinstance(e, Form)]
    names = [*SETUP, *judged(machine), *(n for e in effects_ for n in e.params)]
    flat = fitted_columns(machine, poses, names).reshape(-1, len(names))
    forms = form_columns(machine, poses, np.ones(len(poses), bool))
    flat = np.hstack([flat, *(forms[e.name] for e in effects if isinstance(e, Form))])
    G = flat.T @ flat
    k = len(SETUP)
    return G[k:, k:] - G[k:, :k] @ np.linalg.pinv(G[:k, :k], rcond=1e-12) @ G[:k, k:]


def follow_up(machine: Machine, data: Sequence[RTestData], found: Diagnosis, noise_um: float, fit_file: str,
              rho: float = 0.0) -> Plan:
    """The diagnosis's advice as a plan after ``data`` (the fit ``fit_file``'s): each set-up
    checked and timed as ``plan`` does, a ball moved from where the data left it costing a
    mounting; σ and separations with the follow-ups beside the data, and the data's alone
    as its ``default``."""
    measurements, named = advised(found)
    measured = Measurements.concat(data).poses
    # the ball turned on its stem: mounted again where it stands, its form read turned
    turned = found.form_rival is not None and measurements == (found.form_turned,)
    effects = [*(resolve(machine, n) for n in named), *((Form(found.form_rival),) if turned else ())]
    turn = float(measured.turn[-1]) + (np.radians(found.turn_degrees) if turned else 0.0)
    setups = []
    for m in measurements:
        done = checked_program(machine, m.poses, m.path, machine.controller, MODE, "PLAN", "", "")
        setups.append(Setup(m, done.seconds / 60.0, {}))
    after = Poses.concat([measured, *(s.proposal.poses.with_setup(int(measured.setup[-1]), turn)
                                      for s in setups)])
    names = judged(machine)
    unit = scales(machine, names)
    now_cov = covariance(machine, measured, noise_um, rho)
    then_cov = covariance(machine, after, noise_um, rho)
    moves = len({s.ball for s in setups} - {tuple(measured.ball[-1])}) + turned
    minutes = sum(s.minutes for s in setups) + MOUNT_MINUTES * moves
    told = told_by(information(machine, after, effects), len(names), effects, noise_um)
    was = told_by(information(machine, measured, effects), len(names), effects, noise_um)
    return Plan(tuple(setups), minutes, sigmas_of(names, then_cov), worst_scaled(then_cov, unit), (),
                (0.0, sigmas_of(names, now_cov), worst_scaled(now_cov, unit)), noise_um, rho, told, was, True,
                after=fit_file)

