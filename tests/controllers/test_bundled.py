"""Every bundled machine runs as shipped: it carries [program], every path it defines is
written in one program for its own control and passes check-program, and so does its probing
program (a head's under the control's TCP). A control it has a section for besides its own runs
the same, or refuses in one line what the [program] cannot be on it (LinuxCNC calls tools by
number; the B/C table's SINUMERIK tool is a name). simulate's default paths are the machine
file's own."""

from pathlib import Path

import pytest
from conftest import ROOT, run

from compgen.configuration.machine_file import load_machine
from compgen.controllers.registry import CONTROLLERS

BUNDLED = sorted((ROOT / "machines").glob("*.toml"))
SECTIONS = {"sinumerik840d": "sinumerik", "linuxcnc": "linuxcnc"}     # a control's own section


def _controls(path: Path) -> list[str]:
    machine = load_machine(path)
    own = [machine.controller]
    return own + [c for c, section in SECTIONS.items() if c not in own and getattr(machine, section)]


@pytest.mark.parametrize("path", BUNDLED, ids=[p.stem for p in BUNDLED])
def test_a_bundled_machine_runs_every_path_it_defines(path, tmp_path):
    machine = load_machine(path)
    assert machine.program is not None, f"{path.name} has no [program]"
    assert machine.probe is not None, f"{path.name} has no [probe]"
    for ctl in _controls(path):
        out = tmp_path / f"ALL{CONTROLLERS[ctl].program_ext}"
        code, _, err = run("measure-program", "--machine", path, "--path", "all", "--controller", ctl,
                           "-o", out, "--force")
        if ctl != machine.controller and code == 2 and "[program] tool" in err:
            assert len(err.strip().splitlines()) == 1 and not out.exists(), err
            continue
        assert code == 0, (ctl, err)
        code, said, err = run("check-program", "--machine", path, "--controller", ctl, out)
        assert code == 0 and "OK" in said, (ctl, err)
        probe = tmp_path / f"P{CONTROLLERS[ctl].program_ext}"
        code, _, err = run("probe-program", "--machine", path, "--path", "all", "--controller", ctl,
                           "-o", probe, "--force")
        assert code == 0, (ctl, err)
        code, said, err = run("check-program", "--machine", path, "--controller", ctl, probe)
        assert code == 0 and "OK" in said, (ctl, err)


@pytest.mark.parametrize("path", BUNDLED, ids=[p.stem for p in BUNDLED])
def test_simulate_measures_the_machine_files_own_paths(path, tmp_path):
    machine = load_machine(path)
    (tmp_path / "none.json").write_text('{"parameters": {}}')
    code, out, err = run("simulate", "--machine", path, "--truth", tmp_path / "none.json",
                         "-o", tmp_path / "s.csv")
    assert code == 0, err
    assert f"({', '.join(machine.paths)})" in out + err, out + err
