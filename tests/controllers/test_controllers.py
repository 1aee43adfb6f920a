"""The controller seam: a controller is one module. A toy controller, declared here and
nowhere else, goes through the whole loop (edit, read back, drive, compare, checklist)
without a line of compgen changing (every registered controller passes test_conformance.py)."""

import json
import os
import re

import numpy as np
import pytest
from conftest import ROOT, SEED_MACHINE, TABLE4, UM, run

from compgen.configuration.machine_file import load_machine
from compgen.controllers.base import Controller, EditContext, EditFiles
from compgen.controllers.correction import Held, Plan
from compgen.controllers.kinematics import kinematics_edit
from compgen.controllers.linuxcnc import LinuxCNC
from compgen.controllers.registry import CONTROLLERS, read_edits, register
from compgen.data.rtest import RTestData
from compgen.data.simulate import simulate
from compgen.model.lines import AxisLine
from compgen.model.paths import generate
from compgen.reports.checklist import checklist, markdown
from compgen.reports.compare import compare
from compgen.statistics.identify import identify

NOISE_UM = 0.5
LINE = re.compile(r"^TOYLINE (\w) ((?:\S+ ){5}\S+)$", re.MULTILINE)


class Toy(Controller):
    """Speaks LinuxCNC's G-code for programs; holds axis lines as plain numbers, mm and rad."""

    name = "toy"
    family = "linuxcnc"
    words = "a toy control"
    program_ext = ".ngc"
    comment = "#"
    tcp_words = "toy TCP"
    backup = "nothing to back up: it is a toy"
    pose_line = LinuxCNC.pose_line
    tcpm_on = LinuxCNC.tcpm_on
    tcp_switchable = False

    def blocks(self, text, mode=None):
        return LinuxCNC().blocks(text, mode)

    def program_context(self, machine):       # LinuxCNC's template, with what it needs
        return LinuxCNC().program_context(machine)

    def main_suffix(self, current):
        return ".toy"

    def edit(self, machine, p: Plan, current, where, ctx: EditContext) -> EditFiles:
        body = [f"# {h}" for h in ctx.header]
        body += [f"TOYLINE {n} " + " ".join(f"{v:.12e}" for v in (*line.offset, *line.tilt))
                 for n, line in p.lines.items()]
        return EditFiles({".toy": "\n".join(body) + "\n"}, ("toy lines written",))

    squareness_as = ""            # it holds axis lines only: no squareness, no tables

    def tables(self, machine, p: Plan) -> list:
        return []

    def reads(self, text):
        return LINE.search(text) is not None

    def read(self, machine, text, current, held, where):
        lines = dict(held.lines)
        for m in LINE.finditer(text):
            v = np.array([float(x) for x in m[2].split()])
            old = lines[m[1]]
            lines[m[1]] = AxisLine(old.axis, old.nominal, old.pivot, v[:3], v[3:])
        return Held(lines, held.squareness, held.tables)


@pytest.fixture
def toy():
    register(Toy())
    yield CONTROLLERS["toy"]
    del CONTROLLERS["toy"]


def test_a_toy_controller_in_one_module_runs_the_whole_loop(seed_machine, toy, tmp_path):
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    rng = np.random.default_rng(5)
    pre = simulate(seed_machine, TABLE4, poses, NOISE_UM, rng)
    fit = identify(seed_machine, [pre])
    emitted = kinematics_edit(seed_machine, fit, "toy", None, "", "KIN", "0", "d")
    assert set(emitted.files) == {".toy", "_SIGN.ngc"}
    held = read_edits(seed_machine, {"KIN.toy": emitted.files[".toy"]}, None)
    post = simulate(seed_machine, TABLE4, poses, NOISE_UM, rng, lambda p: held.drive(seed_machine, p))
    after = identify(seed_machine, [RTestData(poses, post.deviation)], ["XOW", "YOW", "ZOW"])
    assert after.residual["rms_um"] == pytest.approx(NOISE_UM, rel=0.1)
    result = compare(seed_machine, [pre], fit, "toy", [post])
    assert result.measured_post["as_predicted"], result.measured_post["statement"]
    (tmp_path / "KIN.toy").write_text(emitted.files[".toy"])
    steps = {s.title: s for s in checklist(seed_machine, tmp_path)}
    assert steps["Kinematics edit emitted (with backup step and sign check)"].status == "done"


@pytest.fixture
def linuxcnc_machine(tmp_path):
    path = tmp_path / "seed-linuxcnc.toml"
    path.write_text(SEED_MACHINE.read_text().replace('controller = "itnc530"', 'controller = "linuxcnc"'))
    return load_machine(path)


def test_checklist_knows_each_controllers_files(linuxcnc_machine, tmp_path):
    """LinuxCNC's edit starts with '#', its programs end in .ngc: the checklist asks the
    registry instead of assuming HEIDENHAIN's ';' and '.H'."""
    work = tmp_path / "work"
    work.mkdir()
    fit = identify(linuxcnc_machine, [simulate(linuxcnc_machine, {"XOC": 5 * UM},
                                               generate(linuxcnc_machine, ["K4", "K1", "K2"]))])
    emitted = kinematics_edit(linuxcnc_machine, fit, "linuxcnc", None, "", "KIN", "0", "d")
    text = markdown(linuxcnc_machine, checklist(linuxcnc_machine, work))
    assert "RTEST.ngc" in text and "RTEST.H" not in text
    (work / "KIN.hal").write_text(emitted.files[".hal"])
    steps = {s.title: s for s in checklist(linuxcnc_machine, work)}
    assert steps["Kinematics edit emitted (with backup step and sign check)"].status == "done"


def test_a_probing_folder_gets_the_probes_checklist(tmp_path):
    """A folder of probing work (a probing program, its log, a fit of it) is ticked against a
    probe's steps: no R-test set-up or R-test CSV asked for, and the sign check said to
    need what a probe cannot give (a probing program runs without the control's
    kinematics). --device rtest forces the R-test's steps."""
    for args in (["probe-program", "--path", "K1", "-o", tmp_path / "P.H"],
                 ["simulate", "--truth", ROOT / "examples" / "truth-table4.json", "--device", "probe",
                  "--paths", "K4,K1,K2", "-o", tmp_path / "P_LOG.csv"]):
        assert run(args[0], "--machine", SEED_MACHINE, *args[1:])[0] == 0
    code, out, err = run("checklist", "--machine", SEED_MACHINE, "--dir", tmp_path)
    assert code == 0, err
    assert "Probing programs written" in out and "R-test" not in out.split("Sign check")[0], out
    assert "[x] Probed: the program's probe log saved" in out and "Next: " in out and " fit --machine " in out
    assert run("fit", "--machine", SEED_MACHINE, tmp_path / "P_LOG.csv", "-o", tmp_path / "fit.json")[0] == 0
    steps = {s.title: s for s in checklist(load_machine(SEED_MACHINE), tmp_path)}
    assert steps["Fit"].status == "done"
    assert "cannot see the edit" in steps["Sign check of the loaded edit"].note
    forced = {s.title for s in checklist(load_machine(SEED_MACHINE), tmp_path, device="rtest")}
    assert "K4, K1, K2 measured (R-test CSV with dX dY dZ)" in forced


def _written(folder, docs):
    """``docs`` (name → JSON document) written oldest first, a minute apart."""
    for age, (name, doc) in enumerate(reversed(list(docs.items()))):
        (folder / name).write_text(json.dumps(doc))
        os.utime(folder / name, (1.7e9 - 60 * age, 1.7e9 - 60 * age))


def _compared(as_predicted, verdict):
    return {"format": "compgen.compare/1",
            "measured_post": {"as_predicted": as_predicted, "verdicts": {"K4": f"{verdict}: 3.1 µm"}}}


@pytest.mark.parametrize("files, now, ready", [
    # the newest file passes, the oldest not: ready; the other way round: not
    ([("b.json", False, "FAIL"), ("a.json", True, "PASS")], None, True),
    ([("c.json", True, "PASS"), ("b.json", True, "PASS"), ("a.json", False, "FAIL")], None, False),
    # the comparison just made comes after every file, in either of its two conditions
    ([("a.json", True, "PASS"), ("b.json", True, "PASS")], (False, "PASS"), False),
    ([("a.json", True, "FAIL"), ("b.json", True, "FAIL")], (True, "PASS"), True),
    ([("a.json", True, "PASS"), ("b.json", True, "PASS")], (True, "FAIL"), False),
])
def test_the_sign_off_follows_the_newest_comparison(seed_machine, tmp_path, files, now, ready):
    """The checklist says "ready" only if the newest comparison improved as predicted with
    every path within tolerance: a file written later overrules an earlier one whatever
    their names; a comparison the caller has just made overrules them all."""
    _written(tmp_path, {name: _compared(as_predicted, verdict) for name, as_predicted, verdict in files})
    steps = checklist(seed_machine, tmp_path, None if now is None else _compared(*now))
    note = next(s.note for s in steps if s.title == "Sign-off")
    assert note.startswith("ready" if ready else "not ready"), note
    numbered = [ln for ln in markdown(seed_machine, steps).splitlines() if re.match(r"\d+\. ", ln)]
    assert [int(ln.split(".")[0]) for ln in numbered] == list(range(1, len(steps) + 1))


def test_the_fit_step_names_the_newest_fit_whatever_the_names(seed_machine, tmp_path):
    _written(tmp_path, {name: {"format": "compgen.fit/1", "data": []} for name in ("b.json", "a.json")})
    step = next(s for s in checklist(seed_machine, tmp_path) if s.title == "Fit")
    assert step.status == "done" and step.evidence == (str(tmp_path / "a.json"),), step
