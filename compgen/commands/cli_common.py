"""What every command shares: one line for every refusal (exit 2), the options, small
readers of option values. The commands are cli.py's and cli_history.py's."""


from __future__ import annotations

import math
import os
import sys

import click

from .. import called_as, me
from ..configuration.machine_file import bundled_machines
from ..controllers.registry import CONTROLLERS
from ..errors import CompgenError, one_line
from ..files import STDOUT, new_command, read_text
from ..model.machine import identifier
from ..units import number


class Failed(click.ClickException):
    """A refusal: one line on stderr, ``compgen: error: …``, exit 2."""

    exit_code = 2

    def show(self, file=None):
        click.echo(f"compgen: error: {one_line(self.message)}", err=True)


class Internal(Failed):
    """An error compgen did not foresee: one line naming it as a bug, exit 3."""

    exit_code = 3


class Group(click.Group):
    """Turns every CompgenError into one line on stderr and exit code 2."""

    def main(self, *args, **kwargs):
        # usage lines and hints name compgen so that, pasted into bash, it is compgen that runs
        called_as(sys.argv[0], sys.executable)
        kwargs["prog_name"] = me() if kwargs.get("prog_name") in (None, "compgen") else kwargs["prog_name"]
        standalone = kwargs.pop("standalone_mode", True)
        try:
            return super().main(*args, standalone_mode=False, **kwargs)
        except click.UsageError as exc:    # one line too, with the way to the usage
            if not standalone:
                raise
            command = f"{exc.ctx.command_path} --help" if exc.ctx else f"{me()} --help"
            click.echo(f"compgen: error: {one_line(exc.format_message())} (see {command})", err=True)
            sys.exit(exc.exit_code)
        except click.ClickException as exc:
            if not standalone:
                raise
            exc.show()
            sys.exit(exc.exit_code)
        except click.Abort:          # Ctrl-C: the shell's 128 + SIGINT, never check's 1 for a fail
            if not standalone:
                raise
            click.echo("compgen: interrupted", err=True)
            sys.exit(130)

    def invoke(self, ctx):
        new_command()
        try:
            done = super().invoke(ctx)
            sys.stdout.flush()           # a full disk or a closed pipe shows here, not at exit
            return done
        except BrokenPipeError:          # `compgen effects | head -1`: ordinary use, quietly done
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            raise SystemExit(0) from None
        except CompgenError as exc:
            raise Failed(str(exc)) from None
        except OSError as exc:           # the system's refusal (a full disk, no permission): not a bug
            raise Failed(f"{exc.filename or 'standard output'}: {exc.strerror or exc}") from None
        except (click.exceptions.Exit, click.ClickException, click.Abort, SystemExit, KeyboardInterrupt):
            raise
        except ModuleNotFoundError as exc:   # another Python than compgen's (a hint pasted elsewhere)
            raise Failed(f"this Python ({sys.executable}) lacks the package {exc.name!r} compgen needs: run "
                         "compgen from the environment it was installed in, or install it there: "
                         f"{sys.executable} -m pip install {exc.name}") from None
        except Exception as exc:     # a bug of compgen's: one line, and the way to the details
            if os.environ.get("COMPGEN_DEBUG"):
                raise
            raise Internal(f"internal error ({type(exc).__name__}: {exc}); this is a bug in compgen. "
                            "Run again with COMPGEN_DEBUG=1 for the traceback and report it") from None


def said(output: str, text: str) -> None:
    """What a command says once it has written ``output``: on stdout, unless the output
    itself went there (-o -)."""
    click.echo(text, err=output == STDOUT)


def warn(message: str) -> None:
    click.echo(f"compgen: warning: {message}", err=True)


def progress(message: str) -> None:
    """One line on stderr before work that can take seconds, for a person at a terminal
    (a pipe or a script gets nothing)."""
    if sys.stderr.isatty():
        click.echo(f"compgen: {message} ...", err=True)


FILE = click.Path(dir_okay=False)
CONTROLLER_NAMES = " | ".join(CONTROLLERS)
MACHINE = click.option("--machine", "machine_file", type=FILE, required=True,
                       help="Machine file (TOML), or a bundled machine by name: "
                            + ", ".join(bundled_machines()) + ".")
OUTPUT = click.option("-o", "--output", type=FILE, required=True, help="File to write.")
FORCE = click.option("--force", is_flag=True, help="Overwrite an existing output file.")


class Finite(click.FloatRange):
    """A number option: finite, within its range. click's ranges let NaN through (every
    comparison with it is false), and an unbounded float takes inf and nan as numbers."""

    def convert(self, value, param, ctx):
        v = super().convert(value, param, ctx)
        if not math.isfinite(v):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return v


DB = click.option("--db", default=None, metavar="STORE",
                  help="The history store: an SQLite file (default: $COMPGEN_DB, else "
                       "compgen-history.sqlite here) or postgresql://user@host/db.")
SERIAL = click.option("--serial", default=None, help="The machine's serial (default: the machine file's).",
                      callback=lambda _c, _p, v: v and identifier("serial", v, "--serial"))
RECORD = click.option("--record", is_flag=True, help="Also record it in the machine's history (--db).")
DATE = click.option("--date", "taken", default=None,
                    help="With --record: when the data were measured or the edit written (ISO 8601; "
                         "default now).")


def encoded_like(source: str, body: str) -> str | bytes:
    """A file edited from a user's ANSI (Latin-1) file goes back in Latin-1: a control's
    export stays what the control reads. UTF-8 (and ASCII) files stay UTF-8."""
    raw = read_text(source, "state file", ansi_ok=True)[1]
    try:
        raw.decode("utf-8")
        return body
    except UnicodeDecodeError:
        try:
            return body.encode("latin-1")
        except UnicodeEncodeError as exc:
            raise CompgenError(f"the edit holds {body[exc.start]!r}, which the Latin-1 file {source} "
                               "cannot hold", hint="report this: compgen writes ASCII into tables") from None


def sha256_of(body: str | bytes) -> str:
    import hashlib
    return hashlib.sha256(body.encode() if isinstance(body, str) else body).hexdigest()


def named_paths(machine, text: str) -> list[str]:
    """--path: a comma list of the machine file's paths, or 'all'. A path named twice is
    refused: a file's runs are told apart by their path (and ball), so two runs of one path
    in one file would be read as one, its 360° turn between them refused."""
    if text.strip().lower() == "all":
        return list(machine.paths)
    names = [p.strip() for p in text.split(",") if p.strip()]
    twice = next((p for i, p in enumerate(names) if p in names[:i]), None)
    if twice is not None:
        raise CompgenError(f"{twice} is named twice: one file holds one run of a path",
                           hint="to measure it twice, write and run it again, and save each run's readings "
                                "in a file of its own")
    return names


PROBE_LENGTH = click.option(
    "--probe-length", "nest", default=None, metavar="MM",
    help="The nest centre's distance below the gauge line in this session, mm, where it is not the machine "
         "file's [rtest] probe_length. On a head it is the lever of the head's angles: a session with "
         "another length tells an angle at the pivot from the head's sag.")


def nest_mm(text: str | None) -> float | None:
    """``--probe-length``'s value, mm, or None where it is not given."""
    return None if text is None else number(text, "--probe-length", "")


def vec3(text: str, option: str) -> list[float]:
    parts = text.split(",")
    if len(parts) != 3:
        raise CompgenError(f"{option} takes three numbers X,Y,Z in mm, not {text!r}")
    return [number(x, f"{option} {'XYZ'[k]}", "") for k, x in enumerate(parts)]

