"""A head probed as its program runs (issue 69): the HEIDENHAIN probing program of each bundled
head, read block by block as the control would run it on a machine with location errors —
TCP coordinates turned into the axes by the control's (nominal) kinematics, each probing move
stopped where the erroneous machine's stylus tip meets the sphere, the latched TCP position
turned into the machine frame by the program's own FN 3 / FN 1 arithmetic, each F-PRINT a log
line — gives a probe log whose centres are the model's readings, and whose fit returns the
errors. Nothing here uses compgen's touch simulation: the program's numbers are the truth's
only way into the log."""

import re

import numpy as np
import pytest
from conftest import ROOT, run

from compgen.configuration.machine_file import load_machine
from compgen.controllers.probing import probe_program, with_sphere
from compgen.data.probe import probe_poses, read_probe_log, sphere_centres
from compgen.model.frames import from_world
from compgen.model.kinematics import Model
from compgen.model.poses import Poses
from compgen.statistics.identify import identify

HEADS = ["bc-fork-head", "bc-swivel-head-table", "bc-nutating-head-table"]
# location errors of every head's rotary axes and the ball: µm and arcsec as a shop would see them
TRUTH = {"XOW": 5e-3, "YOW": -3e-3, "XOC": 12e-3, "YOC": -8e-3, "AOC": np.radians(15 / 3600),
         "BOC": np.radians(-10 / 3600), "ZOB": -6e-3, "AOB": np.radians(12 / 3600)}
NUMBER = r"([+-]\d+(?:\.\d+)?)"


def _run(machine, text: str, truth: dict[str, float]) -> list[str]:
    """The program's log lines, as the control would print them on the erroneous machine."""
    rotary = [a.name for a in machine.rotary_axes]
    model = Model(machine, list(truth))
    values = np.array(list(truth.values()))
    rho = (machine.probe.sphere_diameter + machine.probe.stylus_diameter) / 2
    at = {"X": np.nan, "Y": np.nan, "Z": np.nan, **dict.fromkeys(rotary, 0.0)}
    Q: dict[int, float] = {}
    direction, lines = None, []
    for raw in text.splitlines():
        b = re.sub(r"^\d+ ", "", raw.split(";", 1)[0].strip())
        if b.startswith("L "):
            at.update({w[0]: float(w[1:]) for w in b.split()[1:] if w[0] in "XYZBC"})
        elif (d := re.fullmatch(rf"TCH PROBE 4\.2 IX{NUMBER} IY{NUMBER} IZ{NUMBER}", b)):
            direction = np.array([float(v) for v in d.groups()])
        elif (d := re.fullmatch(rf"TCH PROBE 4\.3 ABST{NUMBER} .*", b)):
            Q[1], Q[2], Q[3] = _touch(machine, model, values, at, rotary, direction, float(d[1]), rho)
        elif (d := re.fullmatch(rf"FN 3: Q(\d+) = \+Q(\d+) \* {NUMBER}", b)):
            Q[int(d[1])] = Q[int(d[2])] * float(d[3])
        elif (d := re.fullmatch(rf"FN 1: Q(\d+) = \+Q(\d+) \+ (?:\+Q(\d+)|{NUMBER})", b)):
            Q[int(d[1])] = Q[int(d[2])] + (Q[int(d[3])] if d[3] else float(d[4]))
        elif (d := re.fullmatch(rf"FN 0: Q(\d+) = (?:\+Q(\d+)|{NUMBER})", b)):
            Q[int(d[1])] = Q[int(d[2])] if d[2] else float(d[3])
        elif re.fullmatch(r"FN 16: F-PRINT TNC:\\\w+_K\d\.A / TNC:\\\w+\.CSV", b):
            path = re.search(r"_(K\d)\.A", b)[1]
            lines.append(f"{path},{Q[10]:.0f},{Q[11]:.4f},{Q[12]:.4f},{Q[1]:.5f},{Q[2]:.5f},{Q[3]:.5f},"
                         f"{Q[13]:.6f},{Q[14]:.6f},{Q[15]:.6f},"
                         + ",".join(f"{v:.4f}" for v in machine.ball))
    return lines


def _touch(machine, model, values, at, rotary, direction, distance, rho):
    """The TCP position the control latches where the erroneous machine's tip meets the
    sphere on the way from ``at`` along ``direction`` (the secant on the true nest−ball's
    length less ρ, nearly straight along a touch: 1e-9 mm in a few steps)."""
    rot = np.radians([[at[a] for a in rotary]])
    p0 = np.array([at["X"], at["Y"], at["Z"]])

    def gap(s: float) -> float:
        q = from_world(machine, (p0 + s * direction)[None], rot)
        return float(np.linalg.norm(model.relative(Poses.at(q, np.asarray(machine.ball)), values)[0])) - rho

    a, b = 0.0, distance
    ga, gb = gap(a), gap(b)
    assert ga > 0 > gb
    for _ in range(8):
        a, b, ga = b, b - gb * (b - a) / (gb - ga), gb
        gb = gap(b)
        if abs(gb) < 1e-10:
            break
    assert abs(gb) < 1e-9, gb
    return tuple(p0 + b * direction)


@pytest.mark.parametrize("name", HEADS)
def test_a_heads_probing_program_run_on_an_erroneous_machine_reads_its_errors(name, tmp_path):
    machine = load_machine(ROOT / "machines" / f"{name}.toml")
    truth = {k: v for k, v in TRUTH.items() if k in ("XOW", "YOW") or k[-1] in machine.axis_names}
    poses = probe_poses(machine, ["K4", "K1", "K2"])
    emitted = probe_program(machine, poses, "K4+K1+K2", "tnc640", "P", "test", "2026-12-07")
    text = emitted.files[".H"]
    assert "FUNCTION TCPM" in text and "FN 3: Q20" in text or name == "bc-fork-head", \
        "a table's turn enters the TCP coordinates: the log turns them back"
    log = [line.strip('";') for line in emitted.files["_HEAD.A"].splitlines()]
    log += _run(with_sphere(machine), text, truth)
    (tmp_path / "p.csv").write_text("\n".join(log) + "\n")
    data = sphere_centres(read_probe_log(tmp_path / "p.csv", machine), machine).data
    assert len(data.poses) == len(poses)
    predicted = Model(machine, list(truth)).deviation(data.poses, np.array(list(truth.values())))
    # the log's 5 decimals (0.01 µm) and the touches' first order in the errors
    assert np.abs(data.deviation - predicted).max() < 0.1e-3, np.abs(data.deviation - predicted).max()
    result = identify(machine, [data], list(truth))
    for k, v in truth.items():
        unit = 1e-3 if k[0] in "XYZ" else np.radians(1 / 3600)      # 1 µm, 1″
        assert abs(result.parameters[k].value - v) < 0.05 * unit, (k, result.parameters[k].value, v)


def test_a_heads_probe_fit_edits_on_the_kinematics_the_probe_ran_under(tmp_path):
    """A head is probed under TCP: its probe fit adds to the control's kinematics, as an
    R-test's does (a table's probe fit, measured without TCP, sets the machine file's)."""
    machine = ROOT / "machines" / "bc-swivel-head-table.toml"
    (tmp_path / "t.json").write_text('{"parameters": {"XOC": {"value": 12, "unit": "um"}, '
                                     '"AOB": {"value": 12, "unit": "arcsec"}}}')
    for args in (("simulate", "--machine", machine, "--truth", tmp_path / "t.json", "--device", "probe",
                  "--noise-um", "0.5", "--seed", "2", "-o", tmp_path / "p.csv"),
                 ("fit", "--machine", machine, tmp_path / "p.csv", "-o", tmp_path / "f.json"),
                 ("kinematics", "--from", tmp_path / "f.json", "-o", tmp_path / "KIN.txt")):
        code, _, err = run(*args)
        assert code == 0, err
    text = (tmp_path / "KIN.txt").read_text()
    assert "add to the kinematics active while the probe ran under TCPM" in text
    assert "without TCP" not in text
    code, _, err = run("simulate", "--machine", machine, "--truth", tmp_path / "t.json", "--device", "probe",
                       "--edit", tmp_path / "KIN.txt", "-o", tmp_path / "q.csv")
    assert code == 2 and "not simulated" in err and len(err.strip().splitlines()) == 1, err
