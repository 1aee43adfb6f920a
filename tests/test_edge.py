"""Nothing wrong reaches the controller: every input is checked at the edge, every string
that enters an emitted file is checked or cleaned, every edit is guarded. Each case here
failed before its fix (issue 9)."""

import pytest
from conftest import SEED_MACHINE, run

from compgen.emit.registry import CONTROLLERS

# (replace this, with that) in the seed machine file → the one line that must come back
BAD_MACHINE_EDITS = {
    "typo sense": ("sense = -1 ", "sence = -1 ", "unknown key sence"),
    "typo offset": ("offset = [0.0, 0.0, 29.794]", "ofset = [0.0, 0.0, 29.794]", "unknown key ofset"),
    "top-level typo": ('controller = "itnc530"', 'controller = "itnc530"\nlimit = 3', "unknown key limit"),
    "NaN ramp": ("C = { from = 0.0, to = 360.0 }", "C = { from = nan, to = 360.0 }", "finite number"),
    "inf amplitude": ("amplitude = -90.0", "amplitude = -inf", "finite number"),
    "injected axis": ('axis = "C"', 'axis = "C0 Z-500 C"', "not a valid axis name"),
    "axis with newline": ('axis = "C"', 'axis = "C\\nG0 Z-500"', "not a valid axis name"),
    "injected work offset": ("clearance = 20.0", 'clearance = 20.0\nwork_offset = "G0 Z-500"',
                             "not a valid work offset name"),
    "injected tool": ('tool = "99"', 'tool = "99\\nG0 Z-500"', "not a valid tool name"),
    "path label with a comma": ("[paths.K2]", '[paths."K2,x"]', "not a valid path name"),
    "tolerance of no path": ("K2 = 8.0", "K2 = 8.0\nK7 = 3.0", "unknown key K7"),
    "program typo": ("dwell = 1.0 ", "dwel = 1.0 ", "unknown key dwel"),
    "vector of no axis": ("C = [0.0, 0.0, -1.0] }", "C = [0.0, 0.0, -1.0], B = [0.0, 1.0, 0.0] }",
                          "unknown key B"),
}


@pytest.mark.parametrize("case", BAD_MACHINE_EDITS)
def test_machine_file_mistakes_are_refused_with_their_key(tmp_path, case):
    before, after, expected = BAD_MACHINE_EDITS[case]
    text = SEED_MACHINE.read_text()
    assert before in text
    machine = tmp_path / "m.toml"
    machine.write_text(text.replace(before, after, 1))
    out = tmp_path / "P.H"
    code, _, err = run("measure-program", "--machine", machine, "--path", "K2", "-o", out)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert expected in err, err
    assert not out.exists()


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_free_text_cannot_add_a_block(tmp_path, controller):
    """A machine name with line breaks and comment terminators stays inside one comment."""
    text = SEED_MACHINE.read_text().replace(
        'name = "A/C trunnion, iTNC 530 (seed report)"', 'name = "evil\\nG0 Z-500\\r\\n) G0 Z-500 ("')
    machine = tmp_path / "m.toml"
    machine.write_text(text)
    ext = CONTROLLERS[controller].program_ext
    out = tmp_path / f"P{ext}"
    code, _, err = run("measure-program", "--machine", machine, "--path", "K2", "--controller",
                       controller, "-o", out)
    assert code == 0, err
    lines = out.read_text().splitlines()
    evil = [ln for ln in lines if "Z-500" in ln]
    assert len(evil) == 1, evil
    assert evil[0].startswith(";") or evil[0].split(" ", 1)[1].startswith(";"), evil[0]
    injected = evil[0][evil[0].index("evil"):evil[0].index("; controller")]
    assert "(" not in injected and ")" not in injected, injected
