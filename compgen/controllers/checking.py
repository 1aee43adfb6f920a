"""A program file checked as ``check-program`` checks it: read by its control's reader, with
the ball its header names (else the one given, else the machine file's), the nest it was
written for, and the probe and its sphere where it probes."""

from __future__ import annotations

from dataclasses import dataclass

from ..model.machine import Machine, at_nest
from ..motion.check import Check
from .base import Controller
from .probing import with_sphere
from .programs import at_ball, lines_of, program_ball, program_nest


@dataclass(frozen=True)
class FileCheck:
    """The motion check of one program (``result``), the machine as checked (its nest, the
    probe where it probes), the ball it was checked with and where that came from, and the
    nest's length (None: the machine file's) and whether it was given; ``probing``: a probing
    program (its tool point the stylus tip)."""

    result: Check
    machine: Machine
    ball: tuple[float, ...]
    ball_from: str
    nest: float | None
    nest_given: bool
    probing: bool = False


def check_file(machine: Machine, ctl: Controller, text: str, source: str, ball=None,
               nest: float | None = None, mode: str | None = None) -> FileCheck:
    """``text`` (the program ``source``) moved through the set-up on ``machine``."""
    with lines_of(source):
        header = None if ball is not None else program_ball(text)   # a ball given overrides the header
        # the nest the program was written for: a head's programs and motion follow its length
        nest_given = nest is not None
        nest = nest if nest_given else program_nest(text)
        blocks = ctl.blocks(text, mode)
    at, whence = ((tuple(ball), "--ball") if ball is not None else
                  (header, "the program's header") if header is not None else
                  (machine.ball, "the machine file"))
    machine = at_nest(machine, nest, "--probe-length" if nest is not None else source)
    probing = any(b.probe for b in blocks)     # a probing program: the probe and its sphere
    if probing:
        machine = with_sphere(machine, nest)
    result = ctl.check(at_ball(machine, at), blocks, probe=machine.probe if probing else None)
    return FileCheck(result, machine, tuple(at), whence, nest, nest_given, probing)
