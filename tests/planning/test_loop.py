"""The user's loop as a user runs it: K4 data of a machine with a hidden effect, then only
the commands compgen prints, pasted into bash verbatim, until diagnose has nothing left.
Every measurement advised is written by the printed measure-program command and passes
check-program; the machine is compgen's simulator with the truth the fit does not know."""

import json
import os
import re
import shlex
import subprocess
import sys

import numpy as np
import pytest
from conftest import ARCSEC, ROOT, TABLE4, UM, pasted

from compgen.configuration.machine_file import load_machine
from compgen.model.effects import effect_name, effect_of_param
from compgen.model.sides import SETUP

NOISE_UM = 0.5
SIGMA_AT_NOISE = 1.1                   # a final σ̂ within 10 % of the noise: nothing left
STEPS = 6

CASES = {
    # the case: with K4 alone a 2/rev tilt of C rivals ECC:h1, radial 2/rev, A wobble
    "tilt of C, 2/rev": ("ac-trunnion-itnc530", {"EAC+EBC:h2c": 8 * ARCSEC}),
    # an X scale error looks like a 1/rev radial motion of C on K4
    "X scale": ("ac-trunnion-itnc530", {"EXX:p1": 10 * UM}),
    "radial motion of C turning with it, 2/rev": ("ac-trunnion-itnc530", {"EXC+EYC:h2c": 3 * UM}),
    # a B/C table on a SINUMERIK: its programs (.MPF) through the same loop
    "B/C table, tilt of C, 2/rev": ("bc-table-sinumerik840d", {"EAC+EBC:h2c": 8 * ARCSEC}),
}
LOCATION = {"ac-trunnion-itnc530": TABLE4,
            "bc-table-sinumerik840d": {"XOW": 5 * UM, "YOW": -8 * UM, "ZOW": 12 * UM, "XOB": 15 * UM,
                                       "ZOB": -20 * UM, "AOB": 6 * ARCSEC, "COB": -9 * ARCSEC, "XOC": -7 * UM,
                                       "YOC": 11 * UM, "AOC": 4 * ARCSEC, "BOC": -5 * ARCSEC}}


def _bash(line: str, cwd) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return pasted(line, cwd, env)


def _printed(text: str, command: str) -> list[str]:
    """Every command line of ``text`` that runs compgen's ``command``, as printed."""
    return [m[0] for m in re.finditer(rf"\S*(?:compgen-cli|compgen| -m compgen) {command} [^\n]*", text)]


@pytest.mark.parametrize("case", CASES)
def test_the_printed_commands_take_a_k4_session_to_the_noise(tmp_path, case):
    machine_name, hidden = CASES[case]           # a bundled machine: the printed commands name it so
    machine = load_machine(machine_name)
    truth = {n: {"value": v, "unit": effect_of_param(machine, n).unit}
             for n, v in {**LOCATION[machine_name], **hidden}.items()}
    cg = f"{shlex.quote(sys.executable)} -m compgen"
    seed = iter(range(100, 200))
    mounted = {"ball": None}

    def machine_measures(path, ball, back, name):      # the machine: not a printed command
        # a ball moved is mounted again: off its nominal centre by what that mounting left
        if mounted["ball"] not in (None, ball):
            again = np.random.default_rng(len(followed)).normal(0, 20, 3)        # µm
            truth.update({n: {"value": v, "unit": "um"} for n, v in zip(SETUP, again, strict=True)})
        mounted["ball"] = ball
        (tmp_path / "truth.json").write_text(json.dumps({"parameters": truth}))
        done = _bash(f"{cg} simulate --machine {machine_name} --truth truth.json --paths {path} --ball {ball}"
                     f"{' --there-and-back' if back else ''} --noise-um {NOISE_UM} --seed {next(seed)} "
                     f"-o {name}.csv", tmp_path)
        assert done.returncode == 0, done.stderr

    followed: list[str] = []
    machine_measures("K4", ",".join(f"{v:g}" for v in machine.ball), False, "K4")
    done = _bash(f"{cg} fit --machine {machine_name} K4.csv -o fit.json", tmp_path)
    assert done.returncode == 0, done.stderr
    fit = "fit.json"
    for _ in range(STEPS):
        shown = _bash(f"{cg} diagnose --from {fit}", tmp_path)
        assert shown.returncode == 0, shown.stderr
        text = shown.stdout
        if "No candidate is significant" in text:
            break
        measures = _printed(text.split("To tell them apart")[1].split("\n\n")[0], "measure-program") \
            if "To tell them apart" in text else []
        adds = [c for c in _printed(text, "fit") if "--add" in c]
        if measures:
            for command in measures:
                done = _bash(command, tmp_path)                       # as printed
                assert done.returncode == 0, (command, done.stderr)
                program = command.split(" -o ")[1].split()[0]
                checked = _bash(f"{cg} check-program --machine {machine_name} {program}", tmp_path)
                assert checked.returncode == 0, (command, checked.stdout, checked.stderr)
                args = shlex.split(command)
                machine_measures(args[args.index("--path") + 1], args[args.index("--ball") + 1],
                                 "--there-and-back" in args, program.rsplit(".", 1)[0])
                followed.append(program)
            then = [c for c in _printed(text.split("To tell them apart")[1], "fit") if "--data" in c][0]
        else:
            assert adds, text                   # something significant, nothing to measure: add it
            then = adds[0]
        done = _bash(then, tmp_path)                                  # as printed
        assert done.returncode == 0, (then, done.stderr)
        fit = shlex.split(then)[shlex.split(then).index("-o") + 1]
    else:
        pytest.fail(f"not at the noise after {STEPS} steps; followed {followed}")
    final = json.loads((tmp_path / fit).read_text())
    print(case, followed, final["effects"], final["residual"]["sigma_um"])
    assert final["residual"]["sigma_um"] < SIGMA_AT_NOISE * NOISE_UM, (followed, final["model"])
    assert {effect_name(n) for n in hidden} <= set(final["effects"]), (final["effects"], followed)


def test_an_unexplained_period_is_declared_with_the_printed_command(tmp_path):
    """A 5 mm ball-screw period of X (no catalogue effect has that shape): diagnose, told the
    R-test's noise, says unexplained and prints the declaration; pasted, it takes the fit to
    the noise, and diagnose then says so against that noise."""
    machine = load_machine("ac-trunnion-itnc530")
    hidden = {"EXX:w5c": 1.2 * UM, "EXX:w5s": -1.6 * UM}          # never in the candidate list
    truth = {n: {"value": v, "unit": effect_of_param(machine, n).unit}
             for n, v in {**TABLE4, **hidden}.items()}
    (tmp_path / "truth.json").write_text(json.dumps({"parameters": truth}))
    cg = f"{shlex.quote(sys.executable)} -m compgen"
    for line in (f"{cg} simulate --machine ac-trunnion-itnc530 --truth truth.json --noise-um {NOISE_UM} "
                 "--seed 5 -o session.csv",
                 f"{cg} fit --machine ac-trunnion-itnc530 session.csv -o fit.json"):
        assert _bash(line, tmp_path).returncode == 0
    shown = _bash(f"{cg} diagnose --from fit.json --noise-um {NOISE_UM}", tmp_path)
    assert shown.returncode == 0 and "UNEXPLAINED" in shown.stdout, shown.stdout
    assert "dX against X: pitch 5.00" in shown.stdout
    declare = [c for c in _printed(shown.stdout, "fit") if "--add EXX:w" in c]
    assert len(declare) == 1, shown.stdout
    assert _bash(declare[0], tmp_path).returncode == 0                 # as printed
    final = json.loads((tmp_path / "fit+1.json").read_text())
    assert final["residual"]["sigma_um"] < SIGMA_AT_NOISE * NOISE_UM
    again = _bash(f"{cg} diagnose --from fit+1.json --noise-um {NOISE_UM}", tmp_path)
    assert "explains these data to the R-test's noise" in again.stdout, again.stdout
