"""The command line: a thin translator over the library. Nothing imports it."""

from __future__ import annotations

import sys

import click
import numpy as np

from .effects import catalogue, location_model
from .errors import CompgenError
from .files import write_atomically
from .identify import identify, parse_fixed
from .machine import load_machine
from .paths import generate
from .rtest import SIGNS, format_rtest, read_rtest
from .simulate import read_truth, simulate


class _Failed(click.ClickException):
    exit_code = 2

    def show(self, file=None):
        click.echo(f"compgen: error: {self.message}", err=True)


class _Group(click.Group):
    """Turns every CompgenError into one line on stderr and exit code 2."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except CompgenError as exc:
            raise _Failed(str(exc)) from None


FILE = click.Path(dir_okay=False)
MACHINE = click.option("--machine", "machine_file", type=FILE, required=True,
                       help="Machine file (TOML), e.g. machines/ac-trunnion-itnc530.toml.")
OUTPUT = click.option("-o", "--output", type=FILE, required=True, help="File to write.")
FORCE = click.option("--force", is_flag=True, help="Overwrite an existing output file.")


@click.group(cls=_Group)
@click.version_option(package_name="compgen")
def main():
    """compgen: find where a five-axis machine's rotary axes really are, from R-test data."""


@main.command("simulate")
@MACHINE
@click.option("--truth", type=FILE, required=True,
              help='JSON {"parameters": {NAME: {"value": v, "unit": u}}}, or a fit.json.')
@click.option("--paths", "path_names", default="K4,K1,K2", show_default=True,
              help="Comma-separated path names from the machine file.")
@click.option("--noise-um", type=float, default=0.0, show_default=True,
              help="White noise σ per reading, µm.")
@click.option("--seed", type=int, default=None, help="Random seed, for a repeatable noise draw.")
@click.option("--ball", default=None, help="Ball centre in the table frame, mm: X,Y,Z "
                                            "(default: the machine file's).")
@OUTPUT
@FORCE
def simulate_cmd(machine_file, truth, path_names, noise_um, seed, ball, output, force):
    """Write the R-test CSV that a machine with the TRUTH errors would give."""
    machine = load_machine(machine_file)
    errors = read_truth(truth, machine)
    names = [p for p in path_names.split(",") if p.strip()]
    if not names:
        raise CompgenError("--paths names no path")
    poses = generate(machine, names, ball=_vec3(ball, "--ball") if ball else None)
    data = simulate(machine, errors, poses, noise_um, np.random.default_rng(seed))
    comments = (f"compgen simulate: machine {machine.name}", f"truth {truth}: "
                + ", ".join(errors) if errors else "truth: nominal machine",
                f"noise {noise_um} µm σ, seed {seed}", "dX dY dZ: nest minus ball, µm")
    write_atomically(output, format_rtest(machine, data, comments), force)
    click.echo(f"wrote {output}: {len(poses)} poses ({', '.join(names)})")


@main.command("fit")
@MACHINE
@click.argument("data", nargs=-1, required=True, type=FILE)
@click.option("--model", "model_names", default=None,
              help="Comma-separated parameters to fit (default: ball offset and the location "
                   "errors of every rotary axis, the seed's 11 on an A/C machine).")
@click.option("--fix", "fixes", multiple=True, metavar="NAME=VALUE",
              help="Hold a parameter, e.g. --fix ZOW=0 or --fix BOA=12.3arcsec. Repeatable.")
@click.option("--method", type=click.Choice(["exact", "linear"]), default="exact", show_default=True,
              help="exact: first-order start then Gauss–Newton on the exact model; linear: the "
                   "seed's first-order least squares only.")
@click.option("--sign", type=click.Choice(SIGNS), default=SIGNS[0], show_default=True,
              help="What the R-test device reports.")
@OUTPUT
@FORCE
def fit_cmd(machine_file, data, model_names, fixes, method, sign, output, force):
    """Identify location errors from R-test DATA files (CSV v1)."""
    machine = load_machine(machine_file)
    sets = [read_rtest(p, machine, sign) for p in data]
    model = [n.strip() for n in model_names.split(",") if n.strip()] if model_names else None
    result = identify(machine, sets, model, parse_fixed(machine, fixes), method, sign)
    write_atomically(output, result.to_json(), force)
    click.echo(result.report(), nl=False)
    click.echo(f"\nwrote {output}")


@main.command("effects")
@MACHINE
def effects_cmd(machine_file):
    """List every effect the machine can carry, with the names `fit --model` accepts."""
    machine = load_machine(machine_file)
    default = set(location_model(machine))
    for e in catalogue(machine):
        mark = "*" if e.name in default else " "
        click.echo(f"{mark} {e.name:<14}{', '.join(e.params):<28}{e.words}")
    click.echo("\n* in the default model")


def _vec3(text: str, option: str) -> list[float]:
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3 or not all(np.isfinite(v)):
        raise CompgenError(f"{option} takes three numbers X,Y,Z in mm, not {text!r}")
    return v


if __name__ == "__main__":
    sys.exit(main())
