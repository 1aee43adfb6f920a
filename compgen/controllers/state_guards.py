"""What a shop leaves set on a HEIDENHAIN or SINUMERIK control, and the guards compgen's
programs stop at before their tool call and any move (LinuxCNC's, which read its offset
parameters, are in ``linuxcnc``).

compgen's positions are in the machine file's frame: the active preset (HEIDENHAIN) or
settable frame (SINUMERIK) is its origin, the rotary axes' intersection, which the preset
check at the first pose shows the operator. What that check cannot show is a transformation
on top of it that a program run before, or an operator, left: a rotation, a mirrored axis, a
scaling factor, a shift of a rotary axis. Under TCPM/TRAORI they move the ball's place with
the table; without it (the probing programs, mode AXES) compgen's machine positions are
turned, mirrored or scaled away from the ball, and a shifted rotary axis labels every pose
with another angle. The programs reset what they can reset with blocks of their own (the
datum shift, the tilted plane, TCPM) and stop, naming the state, unless the rest is neutral.

Sources (each also in docs/controllers.md):
- HEIDENHAIN FN 18 (system data): ID210 NR1 basic rotation (manual), NR2 programmed rotation,
  NR3 mirrored axes (bit-coded, 0: none), NR4 IDX1-3 scaling factor in X, Y, Z. TNC 426/430
  Technical Manual, 12/2001, p. 7-30 (easymanua.ls/heidenhain/tnc-430-pa/manual/1058355?p=879).
  That the iTNC 530 and TNC 640 keep these numbers, and what an FN 14 error number shows, no
  source read says: UNCONFIRMED U20.
- SINUMERIK: $P_ACTFRAME, the total frame (basic frames, the settable frame, the
  programmable frame); a frame's components are read as [axis, TR|FI|RT|SC|MI]. Programming
  Guide Advanced 04/2000 p. 6-218; Programming Manual 12/2019 p. 636. Reading
  $P_ACTFRAME's components in an IF: UNCONFIRMED U21.
"""

from __future__ import annotations

import re

from .. import me
from ..errors import CompgenError
from ..model.machine import Machine
from ..motion.blocks import Block

# HEIDENHAIN: (what, FN 18 item, the neutral value); each is read into its own Q parameter
HEIDENHAIN_STATES = (("a basic rotation (the preset's ROT)", "ID210 NR1", "+0"),
                     ("a rotation (cycle 10)", "ID210 NR2", "+0"),
                     ("a mirrored axis (cycle 8)", "ID210 NR3", "+0"),
                     ("a scaling factor in X (cycle 11)", "ID210 NR4 IDX1", "+1"),
                     ("a scaling factor in Y (cycle 11)", "ID210 NR4 IDX2", "+1"),
                     ("a scaling factor in Z (cycle 11)", "ID210 NR4 IDX3", "+1"))
Q_FIRST, LBL_FIRST, ERROR_NUMBER = 1901, 91, 1099
HEIDENHAIN_READ = re.compile(r"FN 18: SYSREAD Q(\d{4}) = (ID210 NR\d(?: IDX\d)?)")


def heidenhain_guard() -> list[str]:
    """The blocks (unnumbered, with their comments) that stop a Klartext program unless no
    transformation is active beyond its preset: each state read, a jump over its error when
    neutral, the error (its comment is what the operator reads: U20), the label."""
    out = []
    for k, (what, item, neutral) in enumerate(HEIDENHAIN_STATES):
        q, lbl = f"Q{Q_FIRST + k}", LBL_FIRST + k
        out += [f"FN 18: SYSREAD {q} = {item} ; {what}",
                f"FN 9: IF +{q} EQU {neutral} GOTO LBL {lbl}",
                f"FN 14: ERROR = {ERROR_NUMBER} ; compgen: {what} is active ({q}; it must be "
                f"{neutral.lstrip('+')}). Cancel it, then start again",
                f"LBL {lbl}"]
    return out


HEIDENHAIN_BLOCKS = [ln.split(";", 1)[0].strip() for ln in heidenhain_guard()]


def heidenhain_state(blocks: list[str], k: int) -> int | None:
    """Where compgen's guard starts at ``blocks[k]`` (line k + 1, its number and comment
    off): how many
    blocks it takes; a block that starts it but does not go on as compgen writes it is
    refused (a guard edited is no guard). None where no guard starts."""
    if not HEIDENHAIN_READ.fullmatch(blocks[k]):
        return None
    if blocks[k:k + len(HEIDENHAIN_BLOCKS)] != HEIDENHAIN_BLOCKS:
        raise CompgenError(f"line {k + 1}: {blocks[k]!r} starts a guard that is not compgen's (each state "
                           "read, its jump, its FN 14 and its label)", hint="give the program compgen wrote")
    return len(HEIDENHAIN_BLOCKS)


# SINUMERIK: a frame component's neutral value, and what it is
FRAME_NEUTRAL = {"RT": ("0", "a rotation"), "MI": ("0", "a mirrored axis"), "SC": ("1", "a scaling factor")}
FRAME_TERM = re.compile(r"\(\$P_ACTFRAME\[([A-Z]\d*),([A-Z]{2})\]<>([01])\)")
FRAME_IF = re.compile(rf"IF ({FRAME_TERM.pattern}(?: OR {FRAME_TERM.pattern})*)")


def sinumerik_rows(machine: Machine) -> list[tuple[str, list[tuple[str, str, str]]]]:
    """The frame components a program needs neutral on ``machine``: rotation, mirror and
    scaling of the geometry axes; the rotary axes' shift (coarse and fine)."""
    rows = [(words, [(a, part, neutral) for a in "XYZ"]) for part, (neutral, words) in FRAME_NEUTRAL.items()]
    rotary = [a.name for a in machine.axes if a.rotary]
    rows.append(("a shift of a rotary axis", [(a, part, "0") for a in rotary for part in ("TR", "FI")]))
    return rows


def sinumerik_guard(machine: Machine) -> list[str]:
    """The blocks that stop a SINUMERIK program unless the total frame adds nothing to the
    settable frame's origin that compgen's positions do not hold (read after the settable
    frame is selected and before the tool call)."""
    out = []
    for words, terms in sinumerik_rows(machine):
        cond = " OR ".join(f"($P_ACTFRAME[{a},{part}]<>{neutral})" for a, part, neutral in terms)
        axes = ", ".join(dict.fromkeys(a for a, _, _ in terms))
        out += [f"IF {cond}", f'MSG("compgen: {words} is active in the frame ({axes}). Cancel it, then start '
                              'again")', "M0", "M30", "ENDIF"]
    return out


def sinumerik_terms(condition: str) -> dict[tuple[str, str], str]:
    """What a guard's condition reads: (axis, component) -> the value it must hold."""
    return {(a, part): neutral for a, part, neutral in FRAME_TERM.findall(condition)}


def require_guard(blocks: list[Block], control: str, what: str, before=("tool", "move"),
                  kind: str = "offsets", name: str = "") -> None:
    """Refuse a program that does not ``what`` (a state guard of ``kind`` for ``name``)
    before the first block of a kind in ``before`` (its tool call, its first move)."""
    first = next((b for b in blocks if b.kind in (*before, kind)), None)
    if first is None:
        return                  # nothing to guard: the motion check says what is missing
    if first.kind != kind or first.name != name:
        at = f"line {first.line}: " if first.kind != kind else ""
        said = " and ".join({"tool": "its tool change", "move": "any move"}[k] for k in before)
        raise CompgenError(f"{at}a {control} program must {what} before {said}",
                           hint=f"write it again with {me()} measure-program (or probe-program) for this "
                                "machine file")


def require_frame_guard(machine: Machine, blocks: list[Block]) -> None:
    """A SINUMERIK program's frame guards must read every component ``machine`` needs neutral,
    each against its neutral value, before the tool call."""
    guards = [b for b in blocks if b.kind == "offsets"]
    read = {key: value for b in guards for key, value in b.target.items()}
    missing = [f"{a},{p}" for _, terms in sinumerik_rows(machine) for a, p, neutral in terms
               if read.get((a, p)) != neutral]
    if guards and missing:
        raise CompgenError(f"line {guards[0].line}: the frame guard does not read {', '.join(missing)} "
                           "against its neutral value",
                           hint=f"write it again with {me()} measure-program for this machine file")
    selected = next((b for b in blocks if b.kind == "offset"), None)
    if guards and (selected is None or selected.line > guards[0].line):
        raise CompgenError(f"line {guards[0].line}: the frame guard reads the frame before the program "
                           "selects its settable frame", hint="give the program compgen wrote")
    require_guard(blocks, "SINUMERIK", "stop unless the active frame holds no rotation, mirror, scaling "
                  "or rotary-axis shift")
