"""A fit's files: reloading what a fit was made from (its machine file and data, checked by
checksum), and what a new fit or a refit fits (the refit policy)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .. import me
from ..data.probe import MAGIC, PROBE_FAMILY, read_probe_log, sphere_centres
from ..data.rtest import MOUNTED_AGAIN, SIGNS, UNTOUCHED, RTestData, read_rtest
from ..errors import CompgenError
from ..model.effects import IN_TIME, compose, effect_of_param, location_model
from ..model.machine import Machine
from ..model.sides import continues
from ..statistics.identify import parse_fixed
from ..statistics.results import FitResult, load_fit
from .machine_file import load_machine


def read_data(path: str | Path, machine: Machine, sign: str = "nest-minus-ball", warn=None) -> RTestData:
    """A measurement file: an R-test CSV, or a touch-probe log (its first line says so),
    as readings for ``identify``. A probe has no sign to choose: its readings are the
    centres it found. ``warn`` receives what a probe log's checks flag without refusing."""
    head = ""            # not a regular file, unreadable: the reader says what is wrong with it
    if Path(path).is_file():     # a FIFO would block the open
        try:
            with open(path, "rb") as f:
                head = f.read(len(MAGIC) + 3).decode("utf-8", "replace")
        except OSError:
            pass
    if not head.lstrip("\ufeff").startswith(PROBE_FAMILY):     # a probe log of any version is one
        return read_rtest(path, machine, sign)
    centres = sphere_centres(read_probe_log(path, machine), machine)
    for w in centres.warnings:
        if warn:
            warn(w)
    return centres.data


def fit_machine(fit: FitResult, machine_file: str | None = None) -> Machine:
    """The machine file of ``fit``, refused if it changed since or does not hold its units."""
    machine = load_machine(machine_file or fit.machine["file"])
    if machine.sha256 != fit.machine["sha256"]:
        if fit.machine.get("bundled") and not machine_file:
            raise CompgenError(f"the bundled machine {fit.machine['file']!r} of this compgen differs from "
                               "the one the fit was made with (checksum)", where=machine.source,
                               hint="give the machine file the fit was made with: --machine FILE, or refit")
        raise CompgenError("machine file changed since the fit", where=machine.source,
                           hint=f"refit with `{me()} fit` on the current machine file")
    for name, e in fit.parameters.items():
        if effect_of_param(machine, name).unit != e.unit:
            raise CompgenError(f"{name} is given in a unit of {'length' if e.unit == 'mm' else 'angle'}",
                               where=f"fit file: parameters.{name}", hint="the fit file is damaged: refit")
    return machine


def machine_ref(fit: FitResult) -> str:
    """How a command names the fit's machine file: a bundled machine by its name, any
    other by its path as the fit file locates it."""
    return fit.machine["file"]


def reload(fit: FitResult, machine_file: str | None = None) -> tuple[Machine, list[RTestData]]:
    """The machine and data sets of ``fit``, refusing any file that changed since."""
    machine = fit_machine(fit, machine_file)
    data = []
    for ref in fit.data:
        if not Path(ref.file).exists():
            raise CompgenError("data file of the fit is gone", where=ref.file,
                               hint="put it back, or refit with the data where it is now")
        d = read_data(ref.file, machine, fit.sign)
        if d.sha256 != ref.sha256:
            raise CompgenError("data file changed since the fit", where=ref.file,
                               hint=f"refit with `{me()} fit`")
        data.append(replace(d, said=ref.said, turned=ref.turned))
    return machine, data


def turned_of(text: str) -> tuple[str, float]:
    """``FILE=DEG`` of ``fit --ball-turned`` as (file, degrees), or one clear refusal."""
    path, _, deg = text.rpartition("=")
    try:
        return path, float(deg) if path else float("x")
    except ValueError:
        raise CompgenError(f"--ball-turned {text}: give the file and the degrees the ball was turned on "
                           "its stem", hint="e.g. --ball-turned K4_TURNED.csv=60") from None


def said_of(machine: Machine, sets: Sequence[RTestData], again: Sequence[str] = (),
            untouched: Sequence[str] = (), turned: Sequence[tuple[str, float]] = ()) -> list[RTestData]:
    """``sets`` with what the user said of the set-up before each: ``again`` the files
    measured after the ball and the nest were taken off and mounted again (at the same place
    too), ``untouched`` those after which nothing was touched, ``turned`` (file, deg) those
    measured after the ball was turned on its stem (and so mounted again). Refused: a file not among
    the sets, the first (nothing comes before it), one said both, and one said untouched
    whose ball or nest is not the file before it's (a ball moved was mounted again)."""
    def index(path: str) -> int:
        at = [k for k, d in enumerate(sets) if d.source and Path(d.source).resolve() == Path(path).resolve()]
        if not at:
            raise CompgenError(f"{path} is not among the fit's data files", hint="name one of them")
        if at[0] == 0:
            raise CompgenError(f"{path} is the fit's first data file: nothing was measured before it",
                               hint="say it of a later file")
        return at[0]

    out = list(sets)
    for words, paths in ((MOUNTED_AGAIN, again), (UNTOUCHED, untouched)):
        for path in paths:
            k = index(path)
            if out[k].said and out[k].said != words:
                raise CompgenError(f"{path} is said both {out[k].said} and {words}", hint="say one")
            if words == UNTOUCHED and not all(continues(machine, sets[k - 1].poses, sets[k].poses)):
                raise CompgenError(f"{path} is said not touched, but its ball or nest is not where the file "
                                   "before it left them: a ball moved, or another nest, was mounted again",
                                   hint="leave --not-touched out for it")
            out[k] = replace(out[k], said=words)
    for path, deg in turned:
        k = index(path)
        if out[k].said == UNTOUCHED:
            raise CompgenError(f"{path} is said both {UNTOUCHED} and turned on its stem", hint="say one")
        if not (np.isfinite(deg) and 0 < abs(deg) < 360):
            raise CompgenError(f"--ball-turned {path}={deg:g}: the turn is between −360 and 360° and not 0",
                               hint="the degrees the ball was turned on its stem since the file before")
        out[k] = replace(out[k], said=MOUNTED_AGAIN, turned=float(deg))
    return out


@dataclass(frozen=True)
class FitRequest:
    """What one fit fits: the machine, the data sets, the model's effects, the values held
    fixed, and the sign the R-test data were read with."""

    machine: Machine
    sets: list[RTestData]
    model: list[str]
    fixed: dict[str, float]
    sign: str


def fit_request(machine_file: str | None = None, data: Sequence[str] = (), base: str | None = None,
                more: Sequence[str] = (), model: Sequence[str] | None = None, add: Sequence[str] = (),
                remove: Sequence[str] = (), fixes: Sequence[str] = (), sign: str | None = None,
                warn: Callable[[str], None] | None = None, again: Sequence[str] = (),
                untouched: Sequence[str] = (), turned: Sequence[tuple[str, float]] = ()) -> FitRequest:
    """The refit policy. A new fit: ``machine_file`` and ``data``, the seed's location errors,
    the contract's sign. A refit of the fit file ``base``: its machine and data (refused if
    either changed), ``more`` data read with its sign, its model and the values it held
    fixed that stay in the model. Then ``model`` replaces the model, ``add``/``remove``
    compose it, and ``fixes`` ("NAME=VALUE") hold values fixed; ``warn`` receives what a
    probe log's checks flag; ``again`` and ``untouched`` say what happened to the set-up
    before those files (``said_of``)."""
    if more and not base:
        raise CompgenError("--data adds to a fit's data: give --from FIT.json too",
                           hint=f"without a fit: {me()} fit --machine M DATA.csv … -o fit.json")
    if base:
        if data:
            raise CompgenError("with --from, the fit's own data are used; data to add go with --data",
                               hint=f"{me()} fit --from {base} --data {data[0]} … -o NEW.json; for "
                                    "other data alone, fit them with --machine")
        start = load_fit(base)
        machine, sets = reload(start, machine_file)
        sign = sign or start.sign
        sets += [read_data(p, machine, sign, warn) for p in more]
        names = list(start.model)
        fixed = {n: e.value for n, e in start.parameters.items() if e.fixed}
    else:
        if not machine_file or not data:
            raise CompgenError("give --machine and DATA files, or --from a fit.json")
        machine = load_machine(machine_file)
        sign = sign or SIGNS[0]
        sets = [read_data(p, machine, sign, warn) for p in data]
        names, fixed = location_model(machine), {}
    sets = said_of(machine, sets, again, untouched, turned)
    names = compose(machine, list(model) if model is not None else names, add, remove)
    fixed = {n: v for n, v in fixed.items() if n in names} | parse_fixed(machine, fixes)
    if warn is not None:
        clock = one_clock(machine, names, sets)
        if clock:
            warn(clock)
    return FitRequest(machine, sets, names, fixed, sign)


def one_clock(machine: Machine, names: Sequence[str], sets: Sequence[RTestData]) -> str | None:
    """What to say when a model with a drift is fitted to files whose times overlap: a drift
    is a function of one session's clock, and a file whose t starts again at 0 (a device
    that restarts its clock) would be taken as read at the session's start."""
    timed = sorted({e.name for e in (effect_of_param(machine, n) for n in names)
                    if e.carrier == "time" or e.basis.kind in IN_TIME})
    spans = [(float(np.nanmin(s.poses.t)), float(np.nanmax(s.poses.t)), s.source) for s in sets
             if len(s.poses) and not np.isnan(s.poses.t).all()]
    late = [(b, a) for a, b in zip(spans, spans[1:], strict=False) if b[0] <= a[1]]
    if not timed or not late:
        return None
    (start, _, later), (_, end, earlier) = late[0]
    return (f"{', '.join(timed)} drift with the session's clock, but {later} starts at t = {start:g} s, "
            f"before {earlier} ends (t = {end:g} s): its readings are taken as made then. If the "
            "R-test restarted its clock, give t continuing the earlier file's")
