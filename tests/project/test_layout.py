"""The repository's top level holds the design card's entries and the project's own folders,
nothing else: a stray copy of a machine file (m2.toml, the seed machine's twin) sat there
unnoticed for days, a file a user might take for a bundled machine."""

import subprocess

import pytest
from conftest import ROOT

TOP_LEVEL = {
    # the design card's
    "pyproject.toml", "compgen", "templates", "tests", "machines", "examples", "README.md",
    # the project's own
    ".ci", ".gitignore", "CHANGELOG.md", "benchmarks", "docs",
}


def test_the_top_level_holds_only_what_the_design_card_and_the_project_name():
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: the tracked files are unknown")
    files = subprocess.run(["git", "-C", str(ROOT), "ls-files"], capture_output=True, text=True,
                           check=True).stdout.split()
    extra = sorted({f.split("/")[0] for f in files} - TOP_LEVEL)
    assert not extra, f"files at the top level outside the layout: {extra}; move or remove them"
