"""What the statistics read of the measurements they may advise. The caller hands in an
advisor (``planning.advice.Advisor``), which proposes the measurements a machine can
make and checks each as its program would be checked; the statistics name only these
protocols, so no controller's type reaches them, even for a type checker."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from ..model.poses import Poses


class Proposal(Protocol):
    """A measurement that could be added: a path of the machine file with the ball at
    ``ball`` (mm, table frame) and its poses; ``label`` is how a text names it, ``nest`` the
    nest's length where it is not the machine file's (mm), ``again`` a repeat of a run
    already made, right after it."""

    label: str
    path: str
    name: str
    ball: tuple[float, float, float]
    poses: Poses
    again: bool
    nest: float | None

    def to_dict(self) -> dict: ...

    def command(self, me: str) -> str: ...


class Advising(Protocol):
    """The measurements one machine can make (``candidates``), each naming its own command,
    and which of a list it can (``runnable``); ``unable`` says why it advises none."""

    unable: str
    candidates: Sequence[Proposal]

    def runnable(self, ms: Sequence[Proposal], most: int | None = None) -> tuple[Proposal, ...]: ...

    def turned(self, path: str, ball: tuple[float, float, float], before: int, degrees: float
               ) -> Proposal | None:
        """``path`` again with the ball where it is, turned ``degrees`` on its stem (after
        ``before`` turns), if the machine can run it."""

    def spindle_turned(self, path: str, ball: tuple[float, float, float], before: int, degrees: float
                       ) -> Proposal | None:
        """``path`` probed again with the ball where it is and the spindle, and the probe with it,
        turned ``degrees`` (after ``before`` such logs), if the machine can probe it."""
