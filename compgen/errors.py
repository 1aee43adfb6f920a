"""The one exception type compgen raises for bad input or an impossible request."""

from __future__ import annotations

import re

# a line break or other control character: in an emitted file it would start a block of its
# own, in a message a second line
CONTROL = re.compile(r"[\x00-\x1f\x7f\x85\u2028\u2029]")


def one_line(text: str) -> str:
    """``text`` (a file name, a label) kept on one line of an output: each control character
    written as its escape, ``\\n``, ``\\x07``."""
    return CONTROL.sub(lambda m: m[0].encode("unicode_escape").decode("ascii"), text)


class CompgenError(Exception):
    """What is wrong and where, in one line a person can act on.

    ``where`` is ``file:line:column`` (or a parameter name); ``hint`` says what to do next.
    """

    def __init__(self, message: str, where: str | None = None, hint: str | None = None):
        self.message = message
        self.where = where
        self.hint = hint
        super().__init__(str(self))

    def __str__(self) -> str:
        text = f"{self.where}: {self.message}" if self.where else self.message
        return f"{text}. {self.hint[:1].upper()}{self.hint[1:]}" if self.hint else text
