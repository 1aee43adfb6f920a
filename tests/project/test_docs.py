"""The README and docs run as printed (issue 71). A block whose lines start with `$ ` is a
transcript: each `$` line, pasted into bash from a copy of the repository's examples and
machines with the venv on PATH (compgen-cli; `.venv` beside them), exits 0, and every
line shown after it — but lines with `…` (or `...`), which stand for lines left out — is
in what the command prints now, in that order: a figure gone stale fails here. The
README's main job, whose command sets up a venv too, is run as its last part and compared
with "What the main job prints". No command line in a doc calls the bash builtin
`compgen`. (The README's loop printed 5 of its 13 lines; docs/discovery.md said "181 tried"
after the catalogue had grown to 193.)"""

import os
import re
import shutil
import sys
from pathlib import Path

import pytest
from conftest import ROOT, pasted

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```[\w-]*\n(.*?)^```", re.M | re.S)
COMMANDS = ("fit", "diagnose", "simulate", "kinematics", "measure-program", "probe-program", "check-program",
            "check", "compare", "report", "predict", "history", "plan", "verdict")
BUILTIN = re.compile(rf"(?:^|\$ |&& |; |\| )compgen (?:{'|'.join(map(re.escape, COMMANDS))})(?: |$)")


def _blocks(path: Path) -> list[str]:
    return FENCE.findall(path.read_text())


def _transcripts() -> list[tuple[str, str]]:
    out = []
    for path in DOCS:
        for k, block in enumerate(_blocks(path)):
            if any(line.startswith("$ ") for line in block.splitlines()):
                out.append((f"{path.name}#{k}", block))
    return out


def _elided(line: str) -> bool:
    return "…" in line or line.strip() == "..."


def _in_order(shown: list[str], printed: list[str], what: str) -> None:
    """Every shown line (elisions aside) among the printed ones, in order."""
    at = 0
    printed = [p.rstrip() for p in printed]
    for line in shown:
        if _elided(line) or not line.strip():
            continue
        try:
            at = printed.index(line.rstrip(), at) + 1
        except ValueError:
            near = [p for p in printed if p.split()[:2] == line.split()[:2]][:3]
            raise AssertionError(f"{what}: {line!r} is not printed (after the lines before it); "
                                 f"printed lines like it: {near}") from None


@pytest.fixture
def workdir(tmp_path):
    """A copy of what the docs' commands read, with compgen-cli on PATH and .venv beside."""
    bin_dir = Path(sys.executable).parent
    if not (bin_dir / "compgen-cli").exists():
        pytest.skip("compgen-cli is not installed beside this Python")
    for folder in ("examples", "machines"):
        shutil.copytree(ROOT / folder, tmp_path / folder)
    (tmp_path / ".venv").symlink_to(Path(sys.prefix))       # PY=.venv/bin/python, as printed
    return tmp_path, {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}"}


def test_the_docs_hold_transcripts():
    """The transcripts this test runs (a doc that lost its `$` lines would pass unrun)."""
    names = [name for name, _ in _transcripts()]
    assert {n.split("#")[0] for n in names} >= {"README.md", "discovery.md", "probing.md"}, names
    loop = next(b for n, b in _transcripts() if n.startswith("README.md"))
    assert sum(line.startswith("$ ") for line in loop.splitlines()) == 13


@pytest.mark.parametrize("name, block", _transcripts(), ids=[n for n, _ in _transcripts()])
def test_a_transcript_runs_as_printed_and_prints_what_it_shows(workdir, name, block):
    cwd, env = workdir
    lines = block.splitlines()
    starts = [i for i, line in enumerate(lines) if line.startswith("$ ")]
    for i, j in zip(starts, [*starts[1:], len(lines)], strict=True):
        command = lines[i][2:]
        done = pasted(command, cwd, env, timeout=600)
        assert done.returncode == 0, (name, command, done.stderr[-800:])
        _in_order(lines[i + 1:j], (done.stdout + done.stderr).splitlines(), f"{name}: {command}")


def test_the_main_job_prints_what_the_readme_shows(workdir):
    cwd, env = workdir
    text = (ROOT / "README.md").read_text()
    setup = _blocks(ROOT / "README.md")[0]
    job = setup.strip().split(" && ")[-1].replace(".venv/bin/compgen ", "compgen-cli ")
    assert job.startswith("compgen-cli fit --machine "), job
    shown = FENCE.findall(text[text.index("## What the main job prints"):])[0]
    done = pasted(job, cwd, env)
    assert done.returncode == 0, done.stderr
    _in_order(shown.splitlines(), done.stdout.splitlines(), "README's main job")


def test_no_doc_calls_the_bash_builtin():
    """A bare `compgen fit …` in bash is the shell's completion builtin: nothing, exit 0."""
    bare = [(path.name, line) for path in DOCS for block in _blocks(path) for line in block.splitlines()
            if BUILTIN.search(line)]
    assert not bare, bare


def test_the_docs_speak_of_the_project_not_of_its_issues():
    """docs/ and the README say what compgen does and why; which issue asked for it is the
    history's (git), not the reader's."""
    said = [(path.name, m.group(0)) for path in DOCS
            for m in re.finditer(r"\b[Ii]ssues? \d+", path.read_text())]
    assert not said, said
