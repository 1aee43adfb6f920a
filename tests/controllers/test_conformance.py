"""The conformance suite: every controller in the registry, as it stands when the tests are
collected, passes the same loop (no list of names here: a controller registered tomorrow is
tested by construction). The contract's words, an edit read back by the registry and driven
on the simulated machine to the noise, the comparison as predicted, a measuring and a probing
program passed by the motion check and read back by the controller's own reader, and the
checklist that finds the edit."""

import numpy as np
import pytest
from conftest import ROOT, SEED_MACHINE, TABLE4

from compgen.configuration.machine_file import load_machine
from compgen.controllers.base import Controller
from compgen.controllers.correction import plan
from compgen.controllers.kinematics import kinematics_edit
from compgen.controllers.probing import probe_program
from compgen.controllers.programs import checked_program
from compgen.controllers.registry import CONTROLLERS, read_edits
from compgen.data.probe import probe_poses
from compgen.data.rtest import RTestData
from compgen.data.simulate import simulate
from compgen.model.paths import generate
from compgen.reports.checklist import checklist
from compgen.reports.compare import compare
from compgen.statistics.identify import identify

NOISE_UM = 0.5
REGISTERED = sorted(CONTROLLERS)
# what a control holds before the edit, for those whose edit cannot be written without it
# (``needs_current``): the bundled example of its archive
HELD = {"sinumerik840d": ROOT / "examples" / "bc-tcarr-current.txt"}
TRUTH = {"ac-trunnion-itnc530": TABLE4,
         "bc-table-sinumerik840d": {"XOW": 0.005, "YOW": -0.008, "ZOW": 0.012, "XOB": 0.015, "ZOB": -0.02,
                                    "AOB": 3e-5, "COB": -4e-5, "XOC": -0.007, "YOC": 0.011, "AOC": 2e-5,
                                    "BOC": -2.5e-5}}


@pytest.fixture(params=REGISTERED)
def machine(request, tmp_path):
    """A bundled table machine of the controller ``request.param`` (the seed machine with its
    controller named, where none is bundled), and what the control holds before the edit."""
    own = [p for p in sorted((ROOT / "machines").glob("*.toml")) if p.stem in TRUTH
           and f'controller = "{request.param}"' in p.read_text()]
    path = own[0] if own else tmp_path / f"seed-{request.param}.toml"
    if not own:
        path.write_text(SEED_MACHINE.read_text().replace('controller = "itnc530"',
                                                         f'controller = "{request.param}"'))
    machine = load_machine(path)
    assert machine.controller == request.param
    held = HELD[request.param].read_text() if request.param in HELD else None
    return machine, TRUTH[path.stem if own else SEED_MACHINE.stem], held


def test_the_suite_iterates_the_registry():
    """Every registered controller is here; one that cannot write an edit without the
    control's state has that state here too (else this names it)."""
    assert len(REGISTERED) >= 4 and sorted(CONTROLLERS) == REGISTERED
    assert not [n for n in REGISTERED if CONTROLLERS[n].needs_current and n not in HELD]


def test_each_controller_fulfils_the_contract(machine):
    ctl = CONTROLLERS[machine[0].controller]
    assert ctl.name == machine[0].controller and ctl.words and ctl.backup and ctl.program_ext.startswith(".")
    assert ctl.comment in "#;" and ctl.tcp_words
    assert type(ctl).edit is not Controller.edit and type(ctl).read is not Controller.read
    assert type(ctl).blocks is not Controller.blocks


def test_each_controllers_edit_closes_the_loop(machine, tmp_path):
    """The edit, read back by the controller that wrote it, drives the simulated machine:
    to the noise where the control holds every location error, else to what compare predicts
    of the rest; the checklist sees the edit."""
    machine, truth, current = machine
    name = machine.controller
    poses = generate(machine, ["K4", "K1", "K2"])
    rng = np.random.default_rng(11)
    pre = simulate(machine, truth, poses, NOISE_UM, rng)
    fit = identify(machine, [pre])
    emitted = kinematics_edit(machine, fit, name, current, "current", "KIN", "0", "d")
    main = CONTROLLERS[name].main_suffix(current)
    assert CONTROLLERS[name].reads(emitted.files[main]), f"{name} does not read its own {main}"
    edits = {f"KIN{main}": emitted.files[main]}
    held = read_edits(machine, edits, current)
    post = simulate(machine, truth, poses, NOISE_UM, rng, lambda p: held.drive(machine, p))
    before = identify(machine, [pre], ["XOW", "YOW", "ZOW"]).residual["rms_um"]
    after = identify(machine, [RTestData(poses, post.deviation)], ["XOW", "YOW", "ZOW"]).residual["rms_um"]
    assert after < 0.5 * before, (name, before, after)
    # what the control cannot hold stays, as compare predicts it (to the noise where it holds all)
    result = compare(machine, [pre], fit, name, [post])
    assert result.measured_post["as_predicted"], result.measured_post["statement"]
    if not CONTROLLERS[name].not_held(machine, plan(machine, fit)):
        assert after == pytest.approx(NOISE_UM, rel=0.15), name
    for where, text in edits.items():
        (tmp_path / where).write_text(text)
    steps = {s.title: s for s in checklist(machine, tmp_path)}
    assert steps["Kinematics edit emitted (with backup step and sign check)"].status == "done", name


@pytest.mark.parametrize("mode", ["axes", "tcpm"])
def test_each_controllers_programs_pass_its_own_reader_and_the_motion_check(machine, mode):
    """A measuring program in either mode (where the control has it) and a probing program:
    written, passed by the motion check, and read back as blocks by the controller's reader
    with every pose's axes in them."""
    machine = machine[0]
    ctl = CONTROLLERS[machine.controller]
    poses = generate(machine, ["K4"])
    text, _, solved, _, _ = checked_program(machine, poses, "K4", ctl.name, mode, "CONF", "0", "d")
    blocks = ctl.blocks(text, mode)
    assert len(blocks) >= len(solved), (ctl.name, mode)
    probe = probe_program(machine, probe_poses(machine, ["K4"]), "K4", ctl.name, "PROBE", "0", "d")
    assert len(ctl.blocks(probe.files[ctl.program_ext], "axes")) > 0, ctl.name
