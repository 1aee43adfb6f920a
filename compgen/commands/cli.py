"""The command line: a thin translator over the library. Nothing imports it."""


from __future__ import annotations

import json
import shlex
from dataclasses import replace
from datetime import date
from functools import partial
from pathlib import Path

import click
import numpy as np

from .. import __version__, me
from ..configuration.machine_file import load_machine
from ..configuration.session import fit_machine, fit_request, machine_ref, read_data, reload, turned_of
from ..controllers.kinematics import corrected_by, kinematics_edit, nothing_to_correct
from ..controllers.programs import (
    program_name,
)
from ..controllers.registry import for_machine, read_edits, read_state
from ..data.probe import format_probe_log, probe_poses, simulate_touches
from ..data.rtest import SIGNS, Measurements, format_rtest, read_poses
from ..data.simulate import read_truth, simulate
from ..errors import CompgenError
from ..files import STDOUT, read_text, write_all, write_atomically
from ..model.effects import catalogue, compose, location_model
from ..model.paths import generate
from ..model.sides import unknown_sides, unpredicted_sides
from ..planning.advice import Advisor, Proposal
from ..reports.checklist import checklist, markdown
from ..reports.compare import compare
from ..reports.report import report_html
from ..statistics.budget import with_budget
from ..statistics.diagnose import diagnose
from ..statistics.diagnose_text import report as diagnosis_text
from ..statistics.gate import gate_edit, unit_suspicion
from ..statistics.identify import identify, mountings_note
from ..statistics.kept import keep, kept_path, key, read_kept
from ..statistics.results import load_fit
from ..units import NOISE_MAX_UM
from .cli_common import (
    CONTROLLER_NAMES,
    DATE,
    DB,
    FILE,
    FORCE,
    MACHINE,
    OUTPUT,
    PROBE_LENGTH,
    RECORD,
    SERIAL,
    Finite,
    Group,
    encoded_like,
    named_paths,
    nest_mm,
    progress,
    said,
    sha256_of,
    vec3,
    warn,
)
from .cli_history import check_cmd, history_cmd, history_store, record_fit_file
from .cli_programs import check_program_cmd, measure_program_cmd, plan_cmd, probe_program_cmd


@click.group(cls=Group)
@click.version_option(__version__, prog_name="compgen")
def main():
    """compgen: find where a five-axis machine's rotary axes really are, from R-test data."""


@main.command("simulate")
@MACHINE
@click.option("--truth", type=FILE, required=True,
              help='JSON {"parameters": {NAME: {"value": v, "unit": u}}}, or a fit.json.')
@click.option("--paths", "path_names", default="all", show_default=True,
              help="Comma-separated path names from the machine file, or 'all': every path it defines.")
@click.option("--noise-um", type=Finite(min=0, max=NOISE_MAX_UM), default=0.0, show_default=True,
              help="Noise σ per reading, µm (white unless --noise-rho).")
@click.option("--noise-rho", type=Finite(), default=0.0, show_default=True,
              help="Correlation of the noise from one reading to the next, AR(1), 0 ≤ ρ < 1: "
                   "drift of a real set-up.")
@click.option("--seed", type=int, default=None, help="Random seed, for a repeatable noise draw.")
@click.option("--ball", default=None, help="Ball centre in the table frame, mm: X,Y,Z "
                                            "(default: the machine file's).")
@click.option("--there-and-back", "back", is_flag=True, help="Run each path there and back.")
@PROBE_LENGTH
@click.option("--rate-hz", type=Finite(), default=None,
              help="A continuous session: a reading every 1/RATE s while each path runs (an R-test "
                   "sampling on the fly), instead of the path's n poses.")
@click.option("--feed", type=Finite(), default=None,
              help="With --rate-hz: each path's pace, deg/min of its most-travelled rotary axis "
                   "(default the path's own: n poses of seconds_per_pose).")
@click.option("--edit", "edits", type=FILE, multiple=True,
              help="A kinematics edit compgen wrote (table, change list, $TC_CARR program, CEC "
                   "file): simulate the measurement after the control has loaded it. Repeatable.")
@click.option("--current", type=FILE, multiple=True,
              help="With a $TC_CARR program: the record's values before the edit (and the CEC tables "
                   "then loaded, as a further --current).")
@click.option("--device", type=click.Choice(["rtest", "probe"]), default="rtest", show_default=True,
              help="probe: a touch-probe log v1 of the machine file's [probe] (its poses per path, "
                   "its touches); --noise-um is then the trigger noise per touch.")
@click.option("--stylus-error-um", type=Finite(), default=0.0, show_default=True,
              help="With --device probe: the stylus's real diameter minus the one the log states, µm.")
@click.option("--start-s", "start_s", type=Finite(), default=0.0, show_default=True,
              help="Time of the first reading, s on the session's clock: a follow-up measured right "
                   "after an earlier file, its clock running on (a drift needs one clock).")
@OUTPUT
@FORCE
def simulate_cmd(machine_file, truth, path_names, noise_um, noise_rho, seed, ball, back, nest, rate_hz, feed,
                 edits, current, device, stylus_error_um, start_s, output, force):
    """Write the R-test CSV (or, with --device probe, the probe log) that a machine with the
    TRUTH errors would give."""
    machine = load_machine(machine_file)
    errors = read_truth(truth, machine)
    names = named_paths(machine, path_names)
    if not names:
        raise CompgenError("--paths names no path")
    at = vec3(ball, "--ball") if ball is not None else None
    if not (np.isfinite(start_s) and start_s >= 0):
        raise CompgenError(f"--start-s is the time of the first reading, a number ≥ 0 s, not {start_s:g}")
    if device == "probe":
        if back or noise_rho or rate_hz is not None or feed is not None or nest is not None:
            raise CompgenError("--there-and-back, --noise-rho, --rate-hz, --feed and --probe-length are for "
                               "R-test sessions",
                               hint="a probe touches each pose standing still")
        poses = probe_poses(machine, names, at).starting_at(start_s)
    else:
        if feed is not None and rate_hz is None:
            raise CompgenError("--feed sets the pace of a continuous session", hint="give --rate-hz too")
        poses = generate(machine, names, ball=at, start_s=start_s, back=back, rate_hz=rate_hz, feed=feed,
                         nest=nest_mm(nest))
    drive = None
    if edits and device == "probe" and machine.heads:
        raise CompgenError("--edit with --device probe on a head is not simulated: its probing program runs "
                           "under the control's TCP, which the edit moves, and the log's turn into the "
                           "machine frame is the machine file's",
                           hint="simulate the edited machine with an R-test session "
                                "(leave out --device probe)")
    if edits and device == "probe":
        # the probing program moves the axes by compgen's inverse of the machine file, without
        # TCP: no kinematics edit moves it, and the probe reads the machine against that file
        warn("a probing program runs without TCP: the edit does not move its axes, and the session reads "
             "the machine against the machine file as before")
    elif edits:
        held = read_edits(machine, {e: read_state(e) for e in edits},
                          read_state(current) if current else None)
        drive = partial(held.drive, machine)
    rng = np.random.default_rng(seed)
    if device == "probe":
        data = simulate(machine, errors, poses, 0.0, rng, drive)
        tips, directions = simulate_touches(machine, poses, data.deviation, noise_um, rng, stylus_error_um)
        comments = (f"compgen simulate --device probe: truth {truth}: " + (", ".join(errors) or "nominal"),
                    *(f"after the edit {e}" for e in edits),
                    f"trigger noise {noise_um} µm σ, stylus {stylus_error_um:+g} µm off its diameter, "
                    f"seed {seed}")
        text = format_probe_log(machine, machine.probe, poses, tips, directions, comments)
    else:
        data = simulate(machine, errors, poses, noise_um, rng, drive, noise_rho)
        comments = (f"compgen simulate: machine {machine.name}", f"truth {truth}: "
                    + ", ".join(errors) if errors else "truth: nominal machine",
                    *(f"after the edit {e}" for e in edits),
                    f"noise {noise_um} µm σ{f', AR(1) ρ = {noise_rho:g}' if noise_rho else ''}, seed {seed}",
                    "dX dY dZ: nest minus ball, µm")
        text = format_rtest(machine, data, comments)
    write_atomically(output, text, force, inputs=(machine_file, truth, *edits, *current))
    touches = f", {machine.probe.touches} touches each" if device == "probe" else ""
    said(output, f"wrote {output}: {len(poses)} poses{touches} ({', '.join(names)})")


@main.command("fit")
@click.option("--machine", "machine_file", type=FILE, default=None,
              help="Machine file (TOML); with --from, the fit's own by default.")
@click.argument("data", nargs=-1, type=FILE)
@click.option("--from", "base", type=FILE, default=None,
              help="Start from this fit.json: its machine, data, model and fixed parameters.")
@click.option("--data", "more", type=FILE, multiple=True, metavar="CSV",
              help="With --from: R-test data to add to the fit's own (a follow-up measurement). "
                   "Repeatable.")
@click.option("--model", "model_names", default=None,
              help="Comma-separated parameters to fit (default: ball offset and the location "
                   "errors of every rotary axis, the seed's 11 on an A/C machine).")
@click.option("--add", "add", multiple=True, metavar="EFFECT",
              help="Add an effect to the model, e.g. --add ECC:h2 (see `compgen-cli effects`). Repeatable.")
@click.option("--remove", "remove", multiple=True, metavar="EFFECT", help="Take an effect out. Repeatable.")
@click.option("--fix", "fixes", multiple=True, metavar="NAME=VALUE",
              help="Hold a parameter, e.g. --fix ZOW=0 or --fix BOA=12.3arcsec. Repeatable.")
@click.option("--method", type=click.Choice(["exact", "linear"]), default="exact", show_default=True,
              help="exact: first-order start then Gauss–Newton on the exact model; linear: the "
                   "seed's first-order least squares only.")
@click.option("--sign", type=click.Choice(SIGNS), default=None,
              help="What the R-test device reports (default nest-minus-ball, or the --from fit's).")
@click.option("--mounted-again", "again", multiple=True, type=FILE, metavar="CSV",
              help="A data file measured after the ball and the nest were taken off and mounted again, "
                   "at the same place too: its readings get offsets of their own. Repeatable.")
@click.option("--not-touched", "untouched", multiple=True, type=FILE, metavar="CSV",
              help="A data file measured with the set-up as the file before it left it: no step of the "
                   "set-up is tried before it. Repeatable.")
@click.option("--ball-turned", "turned", multiple=True, metavar="CSV=DEG",
              help="A data file measured after the ball was turned DEG degrees on its stem (at the same "
                   "place): its form turns with it, the machine does not. Repeatable.")
@OUTPUT
@FORCE
@RECORD
@SERIAL
@DATE
@DB
def fit_cmd(machine_file, data, base, more, model_names, add, remove, fixes, method, sign, again, untouched,
            turned, output, force, record, serial, taken, db):
    """Identify location errors (and any added effects) from R-test DATA files (CSV v1)."""
    if record:
        from ..history import taken_at
        taken = taken_at(taken)      # a bad --date is refused before fit.json is written
    names = [n.strip() for n in model_names.split(",") if n.strip()] if model_names else None
    asked = fit_request(machine_file, data, base, more, names, add, remove, fixes, sign, warn,
                        again=again, untouched=untouched, turned=[turned_of(t) for t in turned])
    machine, sets = asked.machine, asked.sets
    progress(f"fitting {len(asked.model)} effects to {sum(len(s) for s in sets)} poses")
    result = identify(machine, sets, asked.model, asked.fixed, method, asked.sign, advisor=Advisor)
    result = with_budget(machine, sets, result)    # σ holding the choices and the device's calibration
    write_atomically(output, result.to_json(Path(output).resolve().parent), force,
                     inputs=(machine.source, base, *(s.source for s in sets)))
    said(output, result.report() + f"\nwrote {output}")
    _warn_about_data(machine, result.model, sets)
    suspicion = unit_suspicion(sets)
    if suspicion:
        click.echo(f"compgen: warning: {suspicion}; kinematics will refuse this fit", err=True)
    if record and output != STDOUT:
        _, _, fid, reasons = record_fit_file(db, output, None, serial, taken, None, "", ())
        click.echo(f"recorded as calibration #{fid}" + (": NOT accepted as a reference" if reasons else ""))


def _warn_about_data(machine, names, sets) -> None:
    """What a fit of ``names`` to these data rests on that the data cannot show, each said
    once (the sides no column gives), and what it reports of a ball mounted more than once."""
    poses = [s.poses for s in sets]
    message = unknown_sides(machine, names, *poses)
    if message:
        warn(message)
    note = mountings_note(machine, names, Measurements.concat(sets).poses)   # as the fit joins them
    if note:
        click.echo(f"compgen: note: {note}", err=True)


@main.command("diagnose")
@click.option("--from", "base", type=FILE, required=True, help="A fit.json.")
@click.option("--json", "as_json", is_flag=True, help="Print the diagnosis as JSON.")
@click.option("--candidates", default=None,
              help="Comma-separated effects to try (default: the whole catalogue).")
@click.option("--plots", "plots_dir", type=click.Path(file_okay=False), default=None,
              help="Write PNG plots here: measured vs model per path, residual vs axis angle per path, "
                   "and the rivals on the measurement that tells them apart.")
@click.option("--before", type=FILE, default=None,
              help="An earlier fit.json of the same data, drawn beside this one in the plots.")
@click.option("--noise-um", "noise_um", type=Finite(min=0, max=NOISE_MAX_UM, min_open=True),
              default=None,
              help="The R-test's own noise, 1σ per reading, µm (default: the machine file's "
                   "[rtest] noise_um). With it, the residual is tested against it per path and "
                   "direction, and what no catalogue effect explains is called unexplained.")
@click.option("--plan", "plan_dir", type=click.Path(file_okay=False), default=None,
              help="Write the follow-up it advises as a plan here (plan.json and each program, checked): "
                   "what it brings beside these data; check it later with plan --check.")
@FORCE
def diagnose_cmd(base, as_json, candidates, plots_dir, before, noise_um, plan_dir, force):
    """Where the model fails, and which effects would explain the misfit."""
    fit = load_fit(base)
    machine, sets = reload(fit)
    names = [c.strip() for c in candidates.split(",") if c.strip()] if candidates else None
    progress(f"trying {'the catalogue' if names is None else len(names)} effects against "
              f"{sum(len(s) for s in sets)} poses")
    result = diagnose(machine, sets, fit, names, fit_file=base,
                      noise_um=noise_um, advisor=Advisor)
    named = compose(machine, fit.model, [c.effect for c in result.candidates if c.significant])
    _warn_about_data(machine, named, sets)
    if plots_dir:
        from ..reports.plots import write_plots  # matplotlib only when asked for
        earlier = load_fit(before) if before else None
        for path in write_plots(plots_dir, machine, sets, fit, earlier, result):
            click.echo(f"wrote {path}", err=as_json)
    click.echo(json.dumps(result.to_dict(), indent=2, ensure_ascii=False) if as_json
               else diagnosis_text(result, base), nl=as_json)
    click.echo(f"compgen: {keep(base, result, key(fit, machine, noise_um, names, True))}", err=True)
    if plan_dir:
        _follow_up_plan(machine, sets, fit, result, base, noise_um, Path(plan_dir), force)


def _follow_up_plan(machine, sets, fit, found, base, noise_um, folder: Path, force: bool) -> None:
    """The diagnosis's follow-up as a plan in ``folder``, at the device's noise (given, or the
    machine file's; else the fit's σ̂, said so)."""
    from ..planning.follow_up import follow_up
    from ..planning.plan import files, text
    noise = noise_um if noise_um is not None else machine.noise_um
    if noise is None:
        noise = fit.residual["sigma_um"]
        warn(f"the plan's σ at the fit's σ̂ {noise:.3f} µm: give --noise-um (the device's calibration) for "
             "the device's own")
    p = follow_up(machine, sets, found, noise, str(Path(base).resolve()))
    out = files(machine, p, folder, __version__, date.today().isoformat())
    folder.mkdir(parents=True, exist_ok=True)
    write_all(out, force, inputs=(base, machine.source, *(s.source for s in sets)))
    click.echo(text(machine, p), nl=False, err=True)
    click.echo(f"wrote {len(out)} files in {folder}: the follow-up as a plan; check it again with\n"
               f"  {me()} plan --machine {shlex.quote(machine_ref(fit))} --check {shlex.quote(str(folder))}",
               err=True)


@main.command("predict")
@click.option("--from", "base", type=FILE, required=True, help="A fit.json.")
@click.option("--poses", "poses_file", type=FILE, required=True,
              help="A CSV of poses: rotary axes in deg; path, bx, by, bz (ball, mm) optional.")
@OUTPUT
@FORCE
def predict_cmd(base, poses_file, output, force):
    """Write what the fitted model predicts an R-test would read at other poses or balls."""
    fit = load_fit(base)
    machine = fit_machine(fit)
    poses = read_poses(poses_file, machine)
    values = {n: fit.parameters[n].value for n in fit.model}
    data = simulate(machine, values, poses)
    comments = (f"compgen predict: {fit.marker} ({base}) on machine {machine.name}",
                f"poses {poses_file}; dX dY dZ: nest minus ball, µm, as the fitted model predicts them",
                "the fit's ball offset (XOW YOW ZOW) is its first mounting's: a ball mounted again is off "
                "by its own, a translation in the table frame (compgen compare fits it per mounting)")
    write_atomically(output, format_rtest(machine, data, comments), force, inputs=(base, poses_file))
    said(output, f"wrote {output}: {len(poses)} poses predicted by {fit.marker}")
    sides = unpredicted_sides(machine, fit.model, poses)
    if sides:
        warn(sides)


@main.command("kinematics")
@click.option("--from", "base", type=FILE, required=True, help="A fit.json.")
@click.option("--controller", "controller_name", default=None, metavar="NAME",
              help=f"{CONTROLLER_NAMES}. Default: the machine file's.")
@click.option("--current", type=FILE, multiple=True,
              help="The control's current state: the iTNC 530 description table (*.TAB); the SINUMERIK "
                   "record's $TC_CARR lines, and its CEC tables' file as a second --current; "
                   "LinuxCNC's INI (its HAL files and joint tables are read from it).")
@click.option("--measured-with", "measured", type=FILE, multiple=True,
              help="The control's state while the data were measured, if it is not --current "
                   "(part of a correction already loaded): the edit writes the rest. Repeatable.")
@click.option("-o", "--output", type=FILE, required=True,
              help="Main file (the new table, the change list or the .MPF); the sign check and any "
                   "tables go beside it with the same stem.")
@FORCE
@click.option("--despite-gate", "despite", is_flag=True,
              help="Write the edit although the fit does not explain its data (said on the terminal, in the "
                   "edit's header and in the history).")
@click.option("--beyond-limits", "beyond", is_flag=True,
              help="Write corrections larger than the machine file's [limits].")
@click.option("--anyway", is_flag=True,
              help="Write the edit although every correction is within its noise (nothing to correct).")
@RECORD
@SERIAL
@DATE
@DB
def kinematics_cmd(base, controller_name, current, measured, output, force, despite, beyond, anyway, record,
                   serial, taken, db):
    """Write the controller's kinematics edit for a fit, with a sign check and a backup step."""
    fit = load_fit(base)
    machine, sets = reload(fit)
    ctl = for_machine(controller_name or machine.controller, machine, edit=True)
    for given in (current, measured):
        if len(given) > 1 and not ctl.state_files:
            raise CompgenError(f"{ctl.words} reads its state from one file; {len(given)} were given",
                               hint=f"give --current (and --measured-with) once: {ctl.backup}")
    text = read_state(current) if current else None
    progress("checking that the fit explains its data")
    reasons = gate_edit(machine, sets, fit, base, despite)
    if reasons:
        warn("writing an edit despite the fit gate: " + "; ".join(reasons))
    nothing = nothing_to_correct(machine, fit, ctl.name)
    if nothing and not anyway:     # an edit of noise moves the control by noise, round after round
        if record:
            from ..history import record_fit, taken_at
            store = history_store(db)
            fid = record_fit(store, fit, machine, serial=serial, taken=taken_at(taken), verdict=reasons,
                             exist_ok=True)
            nothing += f"; recorded the fit as calibration #{fid} in {store.where}"
        click.echo(f"{nothing}; no edit written (--anyway writes it)")
        return
    out = Path(output)
    name = program_name(out.stem, room=len("_SIGN"), most=ctl.name_max)
    emitted = kinematics_edit(machine, fit, ctl.name, text, ", ".join(current), name, __version__,
                              date.today().isoformat(), beyond,
                              read_state(measured) if measured else None, out.stem, ", ".join(measured),
                              str(out.absolute().parent), despite=tuple(reasons))
    main_key = ctl.main_suffix(text)
    if output != STDOUT and out.suffix.lower() != main_key.lower():
        # the file the notes name is the file written: a .hal holding an INI would be started as
        # neither, and a .TAB holding a change list is no table
        raise CompgenError(f"-o {out.name}: this edit's main file is a {main_key} file ({ctl.words}"
                           + (", from --current" if current else ", no --current given") + ")",
                           hint=f"give -o {out.stem}{main_key}")
    files = emitted.paths(out, name, main_key)
    if len(current) == 1 and main_key in emitted.files:   # the edited state keeps its encoding
        files[out] = encoded_like(current[0], files[out])
    written = {str(p): sha256_of(body) for p, body in files.items()}
    recorded = None
    if record:         # refused before anything is written: a fit's correction is recorded once
        from ..history import Recorded, record_edit, record_fit, refuse_second_edit, taken_at
        taken = taken_at(taken)      # before a store is opened (or made) for it
        store = history_store(db)
        try:
            refuse_second_edit(store, fit, machine, written, serial, taken)
        except Recorded as exc:
            recorded = exc.message
    write_all(files, force, inputs=(base, *current, *measured, machine.source, *(d.file for d in fit.data)))
    click.echo("\n".join(emitted.notes))
    click.echo("wrote " + ", ".join(str(p) for p in files))
    if record and recorded is None:
        record_fit(store, fit, machine, serial=serial, taken=taken, verdict=reasons, exist_ok=True)
        try:
            eid = record_edit(store, fit, machine, ctl.name, corrected_by(machine, fit, ctl), written,
                              {p: sha256_of(read_text(p, "state file", ansi_ok=True)[1]) for p in current},
                              serial=serial, taken=taken)
            recorded = f"recorded the edit as #{eid}"
        except Recorded as exc:
            recorded = exc.message
    if record:
        click.echo(f"{recorded} in {store.where}")


@main.command("compare")
@click.option("--from", "base", type=FILE, required=True, help="A fit.json.")
@click.option("--controller", "controller_name", default=None, metavar="NAME",
              help=f"{CONTROLLER_NAMES}. Default: the machine file's.")
@click.option("--post", "post_files", type=FILE, multiple=True,
              help="R-test data measured after the edit (CSV v1). Repeatable.")
@click.option("--json", "as_json", is_flag=True, help="Print the comparison as JSON.")
def compare_cmd(base, controller_name, post_files, as_json):
    """What the kinematics edit will achieve, and, with --post data, whether it did."""
    fit = load_fit(base)
    machine, sets = reload(fit)
    post = [read_data(p, machine, fit.sign, warn) for p in post_files]
    result = compare(machine, sets, fit, controller_name or machine.controller, post)
    click.echo(json.dumps(result.to_dict(), indent=2, ensure_ascii=False) if as_json
               else result.report(), nl=as_json)


@main.command("verdict")
@click.option("--from", "base", type=FILE, required=True, help="A fit.json.")
@click.option("--controller", "controller_name", default=None, metavar="NAME",
              help=f"{CONTROLLER_NAMES}. Default: the machine file's.")
@click.option("--post", "post_files", type=FILE, multiple=True,
              help="R-test data after the edit. Repeatable.")
@click.option("--json", "as_json", is_flag=True)
def verdict_cmd(base, controller_name, post_files, as_json):
    """One screen: each location error before and after the edit against its limit, each
    path's range against its tolerance, what stays, and the next step."""
    from ..reports.verdict import verdict, verdict_json
    fit = load_fit(base)
    machine, sets = reload(fit)
    post = [read_data(p, machine, fit.sign, warn) for p in post_files]
    v = verdict(machine, sets, fit, base, controller_name or machine.controller, post)
    click.echo(verdict_json(v) if as_json else v.text(), nl=as_json)


@main.command("checklist")
@MACHINE
@click.option("--dir", "folder", type=click.Path(file_okay=False), default=".", show_default=True,
              help="Work folder whose artefacts tick the steps.")
@click.option("--device", type=click.Choice(["rtest", "probe"]), default=None,
              help="The device's steps: R-test or touch probe (default: what the folder's files show).")
@click.option("--json", "as_json", is_flag=True, help="Print the checklist as JSON.")
def checklist_cmd(machine_file, folder, device, as_json):
    """The commissioning checklist as Markdown, ticked from the files in --dir."""
    machine = load_machine(machine_file)
    steps = checklist(machine, folder, device=device)
    if as_json:
        click.echo(json.dumps({"format": "compgen.checklist/1", "machine": machine.name,
                               "steps": [s.__dict__ for s in steps]}, indent=2, ensure_ascii=False))
        return
    click.echo(markdown(machine, steps), nl=False)


@main.command("report")
@click.option("--from", "base", type=FILE, required=True, help="A fit.json.")
@click.option("--controller", "controller_name", default=None, metavar="NAME",
              help=f"{CONTROLLER_NAMES}. For the predicted comparison. Default: the machine file's.")
@click.option("--post", "post_files", type=FILE, multiple=True, help="R-test data after the edit.")
@click.option("--before", type=FILE, default=None, help="An earlier fit of the same data, for the plots.")
@click.option("--emitted", "emitted", type=FILE, multiple=True,
              help="Files sent to the control, listed with their checksums. Repeatable.")
@click.option("--dir", "folder", type=click.Path(file_okay=False), default=None,
              help="Work folder for the checklist (default: the fit file's folder).")
@click.option("--history", "with_history", is_flag=True,
              help="Add the machine's history from the store (--db): trend plots and the last edits.")
@DB
@OUTPUT
@FORCE
def report_cmd(base, controller_name, post_files, before, emitted, folder, with_history, db, output, force):
    """One self-contained HTML report: fit, diagnose, plots, comparison, files, checklist."""
    from ..reports.plots import figures  # matplotlib only when asked for
    fit = load_fit(base)
    machine, sets = reload(fit)
    for path in emitted:
        read_text(path, "file", ansi_ok=True)   # a missing file fails before anything is drawn
    post = [read_data(p, machine, fit.sign, warn) for p in post_files]
    made_of = key(fit, machine, None, None, True)         # what report's own diagnose is made of
    found = read_kept(base, made_of, Proposal)
    progress("1/3 diagnose" + (f": kept beside the fit ({kept_path(base).name})" if found else ""))
    made = found is None
    found = replace(found, fit_file=base) if found else \
        diagnose(machine, sets, fit, fit_file=base, advisor=Advisor)
    progress("2/3 compare")
    comparison = compare(machine, sets, fit, controller_name or machine.controller, post)
    progress("3/3 plots")
    images = figures(machine, sets, fit, load_fit(before) if before else None, found)
    steps = checklist(machine, folder or Path(base).parent, comparison.to_dict())
    from ..reports.verdict import verdict
    screen = verdict(machine, sets, fit, base, controller_name or machine.controller, post, comparison, found)
    past = png = None
    if with_history:
        from ..history import drift_limits, trend
        from ..reports.plots import trend_png
        past = trend(history_store(db, create=False), machine)
        png = trend_png(past, drift_limits(machine, past), machine.tolerances)
    html = report_html(machine, fit, found, images, comparison, emitted, steps, __version__,
                       date.today().isoformat(), past, png, screen, base)
    write_atomically(output, html, force, inputs=(base, before, *post_files, *emitted))
    said(output, f"wrote {output}")
    if made:                                # kept once the report is written, never before
        click.echo(f"compgen: {keep(base, found, made_of)}", err=True)


@main.command("effects")
@MACHINE
@click.option("--json", "as_json", is_flag=True, help="Print the catalogue as JSON.")
def effects_cmd(machine_file, as_json):
    """List every effect the machine can carry, with the names `fit --model` accepts."""
    machine = load_machine(machine_file)
    default = set(location_model(machine))
    if as_json:
        click.echo(json.dumps({"format": "compgen.effects/1", "machine": machine.name, "effects": [
            {"effect": e.name, "parameters": list(e.params), "unit": e.unit, "words": e.words,
             "cause": e.cause, "default": e.name in default} for e in catalogue(machine)]},
            indent=2, ensure_ascii=False))
        return
    for e in catalogue(machine):
        mark = "*" if e.name in default else " "
        click.echo(f"{mark} {e.name:<14}{', '.join(e.params):<27} {e.words}")
    click.echo("\n* in the default model")



main.add_command(history_cmd)
main.add_command(check_cmd)
main.add_command(measure_program_cmd)
main.add_command(probe_program_cmd)
main.add_command(check_program_cmd)
main.add_command(plan_cmd)
