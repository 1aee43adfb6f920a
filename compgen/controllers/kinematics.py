"""A kinematics edit for any control: the correction plan, the control's own files (its
module writes them), the sign-check program and the notes every edit carries."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import CompgenError
from ..model.effects import effect_name, effect_of_param
from ..model.kinematics import Model, inverse
from ..model.lines import controller_inverse
from ..model.machine import Machine
from ..model.poses import Poses
from ..statistics.results import FitResult
from ..units import shown
from . import Emitted, ascii_text
from .base import Controller, EditContext
from .correction import Plan, lines_text, plan, rest
from .programs import measure_program, program_name
from .registry import controller, for_machine

SIGN_SEEN_UM = 1.0     # a change of the reading an R-test shows for certain at a sign-check pose


def sign_check(machine: Machine, p: Plan, ctl: Controller, name: str, version: str,
               date: str) -> tuple[Emitted | None, list[str]]:
    """A short program that turns each rotary axis alone (with the files it names), and the
    reading change the edit should cause at each pose (after minus before, µm): a wrong sign
    shows in a minute. No program where compgen writes none of this control's for the
    machine (a head): the poses are named, to be run by hand."""
    rows, labels = [], []
    for a in machine.rotary_axes:
        lo, hi = a.travel
        # a head tilted to 90° takes its body towards the table (the reference heads' enter it
        # with the ball 80 mm up): half that shows a pivot's error along the tool as well
        tilt = 45.0 if a.side == "tool" and not a.full_turn else 90.0
        for ang in (0.0, 90.0, 180.0, 270.0) if a.full_turn else (max(lo, -tilt), 0.0, min(hi, tilt)):
            rot = [np.radians(ang) if b.name == a.name else 0.0 for b in machine.rotary_axes]
            if rot in rows:            # the zero pose is shared by every axis's sweep
                continue
            rows.append(rot)
            labels.append(f"S{len(rows)}_{a.name}{ang:+.0f}")
    rot = np.array(rows)
    ball = np.broadcast_to(machine.ball, (len(rot), 3))
    q_before = inverse(machine, rot, ball)
    q_after = controller_inverse(machine, ctl.holds(machine, p).lines, rot, ball)
    truth = Model(machine, list(p.fit_params))
    values = np.array(list(p.fit_params.values()))
    path = np.array(labels, dtype=object)
    at_poses = Poses(q_before, ball, np.zeros(len(rot)), path)
    before = truth.relative(at_poses, values)
    after = truth.relative(Poses(q_after, ball, np.zeros(len(rot)), path), values)
    change = (after - before) * 1e3
    # a pose whose reading the edit does not change tests nothing: left out, unless none would
    seen = np.abs(change).max(axis=1) >= SIGN_SEEN_UM
    keep = seen if seen.any() else np.ones(len(change), bool)
    expect = [f"{lab}: dX {c[0]:+.2f}  dY {c[1]:+.2f}  dZ {c[2]:+.2f} um"
              for lab, c, k in zip(labels, change, keep, strict=True) if k]
    if not seen.any():
        expect.append(f"the edit changes no reading by {SIGN_SEEN_UM:g} um or more: this check cannot "
                      "show its sign")
    if not ctl.writes_programs(machine):     # a head compgen writes no program of this control for
        expect.append(f"compgen writes no {ctl.words} program for this head: move to these poses by hand "
                      "(the nest on the ball under TCPM, the other rotary axes at 0)")
        return None, expect
    program = measure_program(machine, at_poses.take(np.flatnonzero(keep)), "sign check", ctl.name, "tcpm",
                              name, version, date,
                              notes=("expected change of the reading after the edit:", *expect))
    return program, expect


def corrected_by(machine: Machine, fit: FitResult, ctl: Controller) -> dict[str, float]:
    """The location errors an edit of ``fit`` corrects on ``ctl`` (name → mm or rad): after
    it is loaded the control should measure each of them less by as much. Offsets of the
    rotary axes always; their tilts where the control holds tilts; squareness where it
    holds it; never the ball's or the nest's set-up."""
    out = {}
    for n in fit.model:
        e = effect_of_param(machine, n)
        if e.basis.kind != "const" or e.carrier in ("ball", "nest"):
            continue
        if ctl.corrects(machine, e):
            out[n] = fit.parameters[n].value
    return out


NOTHING_K = 3.0       # a correction within this many σ of zero is the fit's noise, not the machine's


def nothing_to_correct(machine: Machine, fit: FitResult, controller_name: str) -> str | None:
    """One line where no correction an edit of ``fit`` would write on the control is beyond
    NOTHING_K σ of zero (an edit of noise moves the table by noise: a second calibration of a
    machine that needs nothing would write one every time), else None."""
    ctl = controller(controller_name)
    p = plan(machine, fit, force=True)
    written = [*corrected_by(machine, fit, ctl),
               *(n for n in fit.model if effect_name(n) in p.tables and n in fit.free)]
    if not written:
        return "nothing to correct: the fit holds no correction this control takes"
    score = {n: abs(fit.parameters[n].value) / fit.parameters[n].std if fit.parameters[n].std > 0
             else float("inf") for n in written}
    worst = max(score, key=score.get)
    if score[worst] > NOTHING_K:
        return None
    value, unit = shown(fit.parameters[worst].value, fit.parameters[worst].unit)
    return (f"nothing to correct: every correction an edit would write is within {NOTHING_K:g} σ of zero "
            f"(the largest, {worst} {value:+.2f} {unit}, is {score[worst]:.1f} σ)")


def kinematics_edit(machine: Machine, fit: FitResult, controller_name: str, current: str | None,
                    current_where: str, name: str, version: str, date: str, force: bool = False,
                    measured: str | None = None, stem: str | None = None,
                    measured_where: str = "--measured-with", folder: str = "",
                    despite: tuple[str, ...] = ()) -> Emitted:
    """The files of a kinematics edit for one control, with the sign check and notes.

    ``measured`` is the control's state while the data were measured, when it differs from
    ``current`` (part of a correction already loaded, say): the edit then writes the rest.
    ``stem``: the file stem its files are written under, where one file names another;
    ``folder``: the folder they are written to; ``despite``: the fit gate's reasons, where the
    edit is written although the fit does not explain its data (its header says so).

    Probe data of a table-table machine are measured without the control's kinematics acting
    (a probing program moves the axes by compgen's inverse of the machine file), so they hold
    the machine against the machine file: their edit sets the control to the machine file's
    geometry plus the fit, taking off what ``current`` holds beyond that geometry, where R-test
    data, measured under TCP, add to what the control held while measuring; so do a head's
    probe data, probed under TCP.
    """
    devices = {d.device for d in fit.data}
    # a head is probed under TCP (probing.py), as an R-test measures: against the control's kinematics
    without_tcp = devices == {"probe"} and not machine.heads
    if len(devices) > 1 and not machine.heads:   # a probe measures against the machine file, an R-test
        # against the control's kinematics
        raise CompgenError("the fit joins data measured under TCP (R-test) and without (probe log): they "
                           "measured against different geometries, so no edit holds both",
                           hint="fit each device's data alone, and write the edit from one of them")
    ctl = for_machine(controller_name, machine, edit=True)
    for text in (current, measured):
        if text is not None and re.search(rf"\b{fit.marker}\b", text):
            raise CompgenError(f"the current state already carries this fit's correction ({fit.marker}): "
                               "applying it again would double it",
                               hint="measure again and fit the new data; or give the state the data "
                                    "were measured in with --measured-with")
    p = _plan_against(machine, fit, ctl, current, current_where, measured, measured_where, without_tcp,
                      force, name, version, date, stem)
    sign_name = program_name(f"{name}_SIGN", most=ctl.name_max)
    signcheck, expect = sign_check(machine, p, ctl, sign_name, version, date)
    # the sign check and the files it names by its name (NAME_SIGN_MSG.A)
    named = {f"_SIGN{k}": v for k, v in signcheck.files.items() if k in signcheck.named} if signcheck else {}
    header = _header(machine, ctl, fit, sign_name, signcheck, despite, without_tcp, version, date)
    words = lines_text(p)
    ctx = EditContext(name, header, tuple(words), tuple(expect), version, date, fit.marker, stem or name,
                      tuple((n, e.std) for n, e in fit.parameters.items()), folder)
    edit = ctl.edit(machine, p, current, current_where, ctx)
    notes = [*words]
    if p.setup:
        notes.append("left out, set-up not machine: " + ", ".join(p.setup))
    notes += edit.notes
    # a table's effect the edit writes no table for (a head's own error motion) is said too
    unheld = [*p.not_compensable, *ctl.not_tabled(machine, p)]
    if unheld:
        notes.append(f"not compensable on {ctl.words} by compgen: " + ", ".join(unheld))
    whose = " (an R-test's: a probing program cannot see the edit)" if without_tcp else ""
    notes += [f"sign check, expected change of the reading after the edit{whose}:", *expect]
    sign = {f"_SIGN{ctl.program_ext}": signcheck.files[ctl.program_ext]} if signcheck else {}
    return Emitted({**edit.files, **sign, **named}, tuple(notes), frozenset(named))


def _plan_against(machine: Machine, fit: FitResult, ctl: Controller, current: str | None, current_where: str,
                  measured: str | None, measured_where: str, without_tcp: bool, force: bool, name: str,
                  version: str, date: str, stem: str | None) -> Plan:
    """What the edit corrects, against what the control holds: probe data against the machine
    file's geometry (what ``current`` holds beyond it taken off), R-test data on what the
    control held while measuring (``measured``, where it differs from ``current``)."""
    p = plan(machine, fit, force)
    if without_tcp and measured is not None:
        raise CompgenError("data measured without TCP (a probing program) are the machine against the "
                           "machine file, whatever the control held: --measured-with does not apply",
                           hint="leave out --measured-with; give the state the control holds now as "
                                "--current")
    if without_tcp and current is not None:
        p = rest(machine, p, ctl.beyond_nominal(machine, current, current_where), force)
    if measured is not None:
        if current is None:
            raise CompgenError("the state the data were measured in only counts against --current",
                               hint="give --current as well")
        # the state measured with passes every check --current does, and is this control's:
        # an edit over it is written (and dropped) before anything is read from it
        ctl.edit(machine, p, measured, measured_where,
                 EditContext(name, (), (), (), version, date, stem=stem or name))
        p = rest(machine, p, ctl.since(machine, measured, current, current_where), force)
        then, now = (ctl.loaded_tables(machine, s, current_where) for s in (measured, current))
        if then != now:       # the tables are composed over --current: the data must have seen them
            raise CompgenError("the compensation tables of --current differ from those the data were "
                               "measured with: compgen adds this round's tables to the ones loaded while "
                               "measuring", hint="measure again with the tables now loaded, or give the "
                                                 "same tables in both")
    return p


def _header(machine: Machine, ctl: Controller, fit: FitResult, sign_name: str, signcheck,
            despite: tuple[str, ...], without_tcp: bool, version: str, date: str) -> tuple[str, ...]:
    """What every file of the edit says first: what it is, from which fit, what it adds to,
    and what comes next."""
    return (f"compgen {version} kinematics edit, {date}",
              f"machine: {ascii_text(machine.name)}; controller: {ctl.label(machine)}",
              f"from {fit.marker}: machine file {ascii_text(Path(fit.machine['file']).name)}, data "
              + ", ".join(ascii_text(Path(d.file).name) for d in fit.data),
              *(f"WRITTEN DESPITE THE FIT GATE: {ascii_text(r)}" for r in despite),
              ("measured without TCP (a probing program): the machine against the machine file's geometry; "
               "the edit sets the control to that geometry plus the fit" if without_tcp else
               "corrections add to the kinematics active while the "
               + ("probe" if {d.device for d in fit.data} == {"probe"} else "R-test")
               + " ran under TCPM/TRAORI"),
              "BACKUP FIRST: " + ctl.backup,
              f"then run the sign check {sign_name}: see its expected changes" if signcheck else
              "then make the sign check by hand at the poses named: see their expected changes",
              *(("the sign check runs with an R-test nest: a probing program runs without the control's "
                 "kinematics and cannot see the edit (with a probe only: the control's own check)",)
                if without_tcp else ()))
