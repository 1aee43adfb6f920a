"""The README's loop runs as printed: every `$` line of its block, pasted into bash from the
repository root with the venv's bin on PATH (compgen-cli, never the shell's own `compgen`),
exits 0, and each VERDICT line the README prints is the one the command prints now (issue
71: 5 of its 13 lines ran, and its output had gone stale)."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT


def _block(heading: str) -> str:
    text = (ROOT / "README.md").read_text()
    after = text[text.index(heading):]
    start = after.index("```") + 3
    return after[start:after.index("```", start)]


def test_the_readme_loop_runs_as_printed_and_prints_what_it_shows(tmp_path):
    bin_dir = Path(sys.executable).parent
    if not (bin_dir / "compgen-cli").exists():
        pytest.skip("compgen-cli is not installed beside this Python")
    for folder in ("examples", "machines"):
        shutil.copytree(ROOT / folder, tmp_path / folder)
    block = _block("## The loop: from K4 alone")
    lines = block.splitlines()
    commands = [(i, ln[2:]) for i, ln in enumerate(lines) if ln.startswith("$ ")]
    assert len(commands) == 13, commands
    env = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}"}
    for i, command in commands:
        done = subprocess.run(["bash", "-c", command], capture_output=True, text=True, cwd=tmp_path, env=env,
                              timeout=300)
        assert done.returncode == 0, (command, done.stderr[-500:])
        shown = lines[i + 1] if i + 1 < len(lines) else ""
        if shown.startswith("VERDICT:"):           # the README shows the command's first line
            assert done.stdout.splitlines()[0] == shown, (command, done.stdout.splitlines()[0])
