"""A program's blocks as a control executes them (``Block``: each controller module turns its
program text into these, with its own meaning of each word), and the words compgen's readers
take from a G-code line."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from ..errors import CompgenError


@dataclass(frozen=True)
class Block:
    """One line as the control executes it. ``target`` maps axis letters to the written
    values (mm, deg) of a move; ``on`` is the state a tcp or length block switches to."""

    line: int
    text: str
    kind: str                    # move, dwell, tcp, tool, length, require, stop, units, offset, end;
                                 # a control's own guards (offsets, head state, pin, sync)
    target: dict = field(default_factory=dict)
    rapid: bool = False
    feed: float | None = None    # mm/min (deg/min for a block that only turns)
    machine_coords: bool = False
    seconds: float = 0.0
    on: bool = False             # tcp / length: switched on (True) or off
    turn: dict = field(default_factory=dict)   # modulo axis letter → "+", "-" or "short"
    name: str = ""               # offset: the work offset the block selects (G54, ...)
    probe: bool = False          # a probing move: it stops where the stylus touches the sphere
    plc: bool = False            # a turn the PLC makes (the OEM's M-function ``name``, "" where the
                                 # operator calls it), not the NC: never under TCP (U26)



WORD = re.compile(r"^([A-Z])([+-]?(?:\d{1,7}(?:\.\d{0,9})?|\.\d{1,9}))$", re.ASCII)
SECONDS = re.compile(r"\d{1,5}(?:\.\d{0,6})?", re.ASCII)     # a dwell, as compgen writes it


def words(tokens: list[str], line: int, allowed: str = "XYZABCF") -> dict[str, float]:
    """Address words (``X+1.5``, ``A-90``, ``F500``) of a block; anything else is refused:
    a malformed or over-long number, a word twice, a feed that is not positive."""
    out = {}
    for t in tokens:
        m = WORD.match(t)
        if not m or m[1] not in allowed or m[1] in out:
            raise CompgenError(f"line {line}: {_cut(t)!r} is not a word this check reads in a move",
                               hint="check-program reads the blocks compgen writes; edit nothing else in")
        out[m[1]] = float(m[2])
    if "F" in out and not out["F"] > 0:
        raise CompgenError(f"line {line}: F{out['F']:g}: a feed must be above zero", hint="write the feed in "
                           "mm/min (deg/min for a block that only turns)")
    return out


def dwell(text: str, line: int, raw: str) -> Block:
    """A dwell block of ``text`` seconds, as compgen writes it, or a refusal."""
    if not SECONDS.fullmatch(text):
        raise unknown(line, raw)
    return Block(line, raw, "dwell", seconds=float(text))


def gcode_move(raw: str, line: int, tokens: list[str], modal: str | None, feed: float | None,
               machine_word: str, skip: tuple[str, ...] = ()) -> tuple[Block, str, float | None]:
    """A G-code move block (modal G0/G1, modal F); ``machine_word`` (SUPA, G53) marks a
    block in machine coordinates. Returns the block and the modal state after it."""
    modal = next((t for t in reversed(tokens) if t in ("G0", "G1")), modal)
    w = words([t for t in tokens if t not in ("G0", "G1", machine_word, *skip)], line)
    feed = w.pop("F", feed)
    if not w or modal is None:
        raise unknown(line, raw)
    return (Block(line, raw, "move", target=w, rapid=modal == "G0", feed=feed,
                  machine_coords=machine_word in tokens), modal, feed)


def _cut(text: str, most: int = 60) -> str:
    """A user's text in a message: no longer than a line can show."""
    return text if len(text) <= most else text[:most] + "..."


def unknown(line: int, text: str) -> CompgenError:
    return CompgenError(f"line {line}: {_cut(text.strip())!r} is not a block this check knows",
                        hint="check-program reads the blocks compgen writes; a program with other "
                             "blocks cannot be shown safe")
