"""The program commands: measure-program, probe-program, check-program (a thin layer over
``controllers.programs``, ``controllers.probing`` and each control's reader)."""

from __future__ import annotations

import json
import shlex
from datetime import date
from pathlib import Path

import click

from .. import __version__, me
from ..configuration.machine_file import load_machine
from ..controllers.checking import check_file
from ..controllers.probing import probe_program
from ..controllers.programs import (
    MODES,
    NAME_MAX,
    measure_program,
    program_name,
)
from ..controllers.registry import controller, for_machine, for_program
from ..data.probe import probe_poses
from ..data.rtest import read_poses
from ..errors import CompgenError
from ..files import STDOUT, read_text, write_all
from ..model.paths import generate
from ..units import NOISE_MAX_UM
from .cli_common import (
    CONTROLLER_NAMES,
    FILE,
    FORCE,
    MACHINE,
    PROBE_LENGTH,
    Finite,
    named_paths,
    nest_mm,
    vec3,
)


def program_suffix(output: str | None, ctl) -> None:
    """A program is written under its control's suffix (.H, .MPF, .ngc): the control lists
    and runs it by that, and check-program takes the control from it."""
    if output and Path(output).suffix.lower() != ctl.program_ext.lower():
        raise CompgenError(f"-o {Path(output).name}: a {ctl.words} program is a {ctl.program_ext} file",
                           hint=f"give -o {Path(output).stem}{ctl.program_ext}")


@click.command("measure-program")
@MACHINE
@click.option("--path", "path_names", default=None,
              help="K1, K2, K4 (or BK1…), a comma list, or 'all': paths of the machine file.")
@click.option("--poses", "poses_file", type=FILE, default=None,
              help="A CSV of poses (rotary axes in deg; path, bx, by, bz optional) instead of --path.")
@click.option("--ball", default=None, help="With --path: the ball centre in the table frame, mm, "
                                            "X,Y,Z (default: the machine file's).")
@click.option("--there-and-back", "back", is_flag=True,
              help="With --path: run each path there and back, so that every axis reverses "
                   "(what a reversal error, backlash, needs to be seen).")
@PROBE_LENGTH
@click.option("--controller", "controller_name", default=None, metavar="NAME",
              help=f"{CONTROLLER_NAMES}. Default: the machine file's.")
@click.option("--mode", type=click.Choice(MODES), default="tcpm", show_default=True,
              help="tcpm: the control's kinematics (FUNCTION TCPM / TRAORI); axes: compgen's.")
@click.option("-o", "--output", type=FILE, default=None,
              help="Program file; its pose list goes beside it as <stem>.poses.csv. Default: stdout.")
@FORCE
def measure_program_cmd(machine_file, path_names, poses_file, ball, back, nest, controller_name, mode,
                        output, force):
    """Write an R-test measurement program for the control, checked against travel and feed."""
    machine = load_machine(machine_file)
    if bool(path_names) == bool(poses_file):
        raise CompgenError("give either --path or --poses")
    if (ball or back or nest) and poses_file:
        raise CompgenError("--ball, --there-and-back and --probe-length go with --path: a pose list gives "
                           "its own poses, ball and nest")
    if poses_file:
        poses, label = read_poses(poses_file, machine), Path(poses_file).stem
    else:
        names = named_paths(machine, path_names)
        poses = generate(machine, names, ball=vec3(ball, "--ball") if ball is not None else None, back=back,
                         nest=nest_mm(nest))
        label = "+".join(names) + "_BACK" * back
    ctl = for_machine(controller_name or machine.controller, machine)
    output = None if output == STDOUT else output      # -o - is stdout, as no -o
    program_suffix(output, ctl)
    name = program_name(Path(output).stem if output else f"RTEST_{label}"[:NAME_MAX], most=ctl.name_max)
    emitted = measure_program(machine, poses, label, ctl.name, mode, name, __version__,
                              date.today().isoformat(), Path(output).stem if output else None)
    program = emitted.files[ctl.program_ext]
    if not output:
        click.echo(program, nl=False)
        click.echo("compgen: the pose list was not written" + "".join(f" (nor {name}{k}, which the program "
                                                                      "shows its messages from)"
                                                                      for k in sorted(emitted.named))
                   + "; give -o FILE to get it beside the program", err=True)
        return
    out = Path(output)
    files = emitted.paths(out, name, ctl.program_ext)
    write_all(files, force, inputs=(machine_file, poses_file))
    click.echo(f"wrote {', '.join(str(p) for p in files)}: {len(poses)} poses, {mode} mode, "
               f"{ctl.label(machine)}", err=True)


@click.command("probe-program")
@MACHINE
@click.option("--path", "path_names", required=True,
              help="K1, K2, K4, a comma list, or 'all': paths of the machine file, each probed at "
                   "[probe] poses of its poses.")
@click.option("--ball", default=None, help="The sphere's centre in the table frame, mm, X,Y,Z (default: "
                                            "the machine file's [rtest] ball).")
@click.option("--controller", "controller_name", default=None, metavar="NAME",
              help=f"{CONTROLLER_NAMES}. Default: the machine file's.")
@click.option("--spindle-deg", "spindle_deg", type=Finite(), default=None, metavar="DEG",
              help="Orient the spindle to DEG (0 to 360) before the first touch, said in the log: the probe "
                   "and its trigger's lobes turn with it, the machine does not (what diagnose advises where "
                   "the trigger explains the misfit).")
@click.option("-o", "--output", type=FILE, required=True,
              help="Program file; its pose list goes beside it as <stem>.poses.csv (HEIDENHAIN: and the "
                   "F-PRINT format files <stem>_<path>.A).")
@FORCE
def probe_program_cmd(machine_file, path_names, ball, controller_name, spindle_deg, output, force):
    """Write a probing program: a touch probe on the calibration sphere at each pose, every
    touch logged on the control as a probe log v1; checked with the probe in the set-up."""
    machine = load_machine(machine_file)
    ctl = for_machine(controller_name or machine.controller, machine)
    program_suffix(output, ctl)
    names = named_paths(machine, path_names)
    poses = probe_poses(machine, names, vec3(ball, "--ball") if ball is not None else None)
    out = Path(output)
    name = program_name(out.stem, room=4, most=ctl.name_max)
    emitted = probe_program(machine, poses, "+".join(names), ctl.name, name, __version__,
                            date.today().isoformat(), spindle_deg)
    files = emitted.paths(out, name, ctl.program_ext)
    write_all(files, force, inputs=(machine_file,))
    click.echo(f"wrote {', '.join(str(p) for p in files)}: {len(poses)} poses, "
               f"{machine.probe.touches} touches "
               f"each, {ctl.words}; check it: {me()} check-program --machine {shlex.quote(machine_file)} "
               f"{shlex.quote(str(out))}"
               + (" --mode axes" if not ctl.tcp_switchable else ""), err=True)


@click.command("check-program")
@MACHINE
@click.argument("program", type=FILE)
@click.option("--controller", "controller_name", default=None, metavar="NAME",
              help=f"{CONTROLLER_NAMES}. Default: from the file's suffix.")
@click.option("--ball", default=None,
              help="The ball centre in the table frame, mm, X,Y,Z (default: the one the program's "
                   "header names, else the machine file's).")
@PROBE_LENGTH
@click.option("--mode", type=click.Choice(MODES), default=None,
              help="LinuxCNC: the kinematics the configuration runs the program under (tcpm: trt "
                   "kinematics; axes: identity). The other controls' programs switch TCP themselves.")
@click.option("--json", "as_json", is_flag=True, help="Print the check as JSON.")
def check_program_cmd(machine_file, program, controller_name, ball, nest, mode, as_json):
    """Simulate PROGRAM block by block against the R-test set-up, travel and feeds."""
    machine = load_machine(machine_file)
    ctl = (for_machine(controller_name, machine) if controller_name
           else for_program(Path(program).suffix, machine))
    if mode is not None and ctl.tcp_switchable:
        raise CompgenError(f"--mode is for controls whose configuration decides TCP; {ctl.words} programs "
                           "switch it themselves", hint="leave --mode out")
    text = read_text(program, "program", ansi_ok=True)[0]
    checked = check_file(machine, ctl, text, program, vec3(ball, "--ball") if ball is not None else None,
                         nest_mm(nest) if nest is not None else None, mode)
    result, machine, at, source = checked.result, checked.machine, checked.ball, checked.ball_from
    nest, nest_given = checked.nest, checked.nest_given
    if as_json:
        click.echo(json.dumps({
            "format": "compgen.check-program/1", "program": program, "controller": ctl.name,
            "ok": not result.findings,
            "ball_mm": list(at), "ball_from": source, "probe_length_mm": machine.probe_length,
            "moves": result.blocks, "seconds": result.seconds,
            "closest_mm": result.closest_mm, "closest_at": result.closest_at,
            "findings": [{**f.__dict__, "text": f.text(program)} for f in result.findings]},
            indent=2, ensure_ascii=False))
        if result.findings:
            raise SystemExit(1)
        return
    for finding in result.findings:
        click.echo(finding.text(program))
    where = f"ball at {', '.join(f'{v:g}' for v in at)} mm (from {source})" + (
        "" if nest is None else f"; {'stylus tip' if checked.probing else 'nest'} {nest:g} mm below the "
        "gauge line (from "
        f"{'--probe-length' if nest_given else 'the program' + chr(39) + 's header'})")
    if result.findings:
        click.echo(f"{program}: checked with the {where}", err=True)
        raise SystemExit(1)
    click.echo(f"{program}: OK ({ctl.label(machine)}): {result.blocks} moves, about "
               f"{result.seconds / 60:.1f} min; closest approach {result.closest_mm:.1f} mm "
               f"({result.closest_at}); {where}")


@click.command("plan")
@MACHINE
@click.option("--minutes", type=Finite(min=0, max=10000, min_open=True), default=None,
              help="The machine's minutes for the measurement (the programs' time, as check-program "
                   "counts it, and each mounting of the ball elsewhere).")
@click.option("--noise-um", "noise_um", type=Finite(min=0, max=NOISE_MAX_UM, min_open=True), default=None,
              help="The R-test's noise, 1σ per reading, µm (default: the machine file's [rtest] noise_um); "
                   "with --device probe, the probe's trigger noise, 1σ per touch (its repeatability).")
@click.option("--device", type=click.Choice(["rtest", "probe"]), default="rtest", show_default=True,
              help="What measures: the R-test, or a touch probe on the sphere ([probe] in the machine file).")
@click.option("--rho", type=Finite(min=0, max=0.99), default=0.0, show_default=True,
              help="AR(1) correlation of the noise from reading to reading within a run.")
@click.option("--effects", default=None, metavar="NAMES",
              help="Effects the plan must tell apart where the machine file's paths do, comma-separated "
                   "(e.g. ECC:h2,EXC+EYC:h2); default: each rotary axis's angular 1/rev and 2/rev, "
                   "radial 2/rev, and a tilting axis's sag.")
@click.option("-o", "--output", "folder", type=click.Path(file_okay=False), default=None,
              help="Folder for plan.json and each set-up's program and pose list.")
@click.option("--check", "check_dir", type=click.Path(file_okay=False), default=None,
              help="A plan written before: its programs and σ against the machine file as it is now "
                   "(exit 1 where it no longer holds).")
@FORCE
def plan_cmd(machine_file, minutes, noise_um, device, rho, effects, folder, check_dir, force):
    """Design the measurement before the machine moves: the set-ups this machine can run
    that tell its location errors best within the minutes given, each program checked."""
    from ..planning.plan import checked, files, plan, text
    machine = load_machine(machine_file)
    if check_dir is not None:
        if minutes is not None or folder is not None:
            raise CompgenError("--check takes a plan's folder alone", hint="leave --minutes and -o out")
        lines, ok, made = checked(machine, Path(check_dir))
        again = (f"{me()} plan --machine {shlex.quote(machine_file)} --minutes {made['minutes'] or 10:g} "
                 f"--noise-um {made['noise_um']:g}" + (f" --rho {made['rho']:g}" if made["rho"] else "")
                 + (" --device probe" if made["device"] == "probe" else "")
                 + f" -o {shlex.quote(str(Path(check_dir).with_name(Path(check_dir).name + '-again')))}")
        click.echo("\n".join([f"compgen plan --check: {check_dir} against {machine_file}", *lines,
                               "the plan holds" if ok else "the plan does not hold on this machine file: "
                               f"write it again: {again}"]))
        if not ok:
            raise SystemExit(1)
        return
    if minutes is None or folder is None:
        raise CompgenError("give --minutes and -o DIR (or --check DIR for a plan written before)")
    noise = noise_um if noise_um is not None or device == "probe" else machine.noise_um
    if noise is None:
        what = "probe" if device == "probe" else "R-test"
        more = ", 1σ per touch)" if device == "probe" else "), or [rtest] noise_um in the machine file"
        raise CompgenError(f"the {what}'s noise is not known: the plan's σ scale with it",
                           hint=f"give --noise-um (the device's calibration{more}")
    named = None if effects is None else [n.strip() for n in effects.split(",") if n.strip()]
    if named is not None and len(named) < 2:
        raise CompgenError(f"--effects {effects!r}: name two effects or more, comma-separated, to tell "
                           "apart", hint=f"list the catalogue with {me()} effects --machine "
                                         f"{shlex.quote(machine_file)}")
    result = plan(machine, minutes, noise, rho, effects=named, device=device)
    out = files(machine, result, Path(folder), __version__, date.today().isoformat())
    from ..reports.plots import front_png  # matplotlib only when a plan is written
    out[Path(folder) / "front.png"] = front_png(machine, result)
    Path(folder).mkdir(parents=True, exist_ok=True)
    write_all(out, force, inputs=(machine_file,))
    click.echo(text(machine, result), nl=False)
    ext = controller(machine.controller).program_ext
    click.echo(f"wrote {len(out)} files in {folder}: plan.json, front.png (worst σ against minutes) and each "
               "set-up's program; check them:",
               err=True)
    for path in (p for p in out if p.suffix == ext):
        click.echo(f"  {me()} check-program --machine {shlex.quote(machine_file)} {shlex.quote(str(path))}",
                   err=True)
