"""``python -m compgen``: the same CLI, immune to bash's ``compgen`` builtin."""

from .cli import main

main()
