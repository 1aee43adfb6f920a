"""compgen: find where a five-axis machine's rotary axes really are, from R-test data."""

# the one place the version is written (pyproject reads it): importlib.metadata would cost
# every command 30 ms of start-up
__version__ = "0.1.0"


_program = "compgen-cli"


def me() -> str:
    """How every hint calls compgen: as this run was called, in a form bash does not take
    for its own ``compgen`` builtin (a path, ``python -m compgen``, or the ``compgen-cli``
    alias). The command line sets it (``cli._Group``)."""
    return _program


def called_as(argv0: str, executable: str) -> None:
    """Remember how compgen was called, for ``me``."""
    import os
    import shlex
    import shutil

    global _program
    name = os.path.basename(argv0)
    if name == "__main__.py":
        python = "python" if shutil.which("python") == executable else executable
        _program = f"{python} -m compgen"
    elif name == "compgen" and os.sep in argv0:
        _program = shlex.quote(argv0)
    elif name.startswith("compgen"):
        # the alias where the shell finds this very program by it; else the path it was called
        # by (.venv/bin/compgen-cli with the venv not active: "compgen-cli" is not found)
        found = shutil.which("compgen-cli")
        same = found and os.sep in argv0 and os.path.realpath(found) == os.path.realpath(argv0)
        _program = shlex.quote(argv0) if os.sep in argv0 and not same else "compgen-cli"
