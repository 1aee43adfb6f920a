"""A LinuxCNC program as LinuxCNC executes it (the blocks compgen writes), and the guards its
programs stop at before any motion: the work offsets, a head module's state."""

from __future__ import annotations

import re
from dataclasses import replace

from ...errors import CompgenError
from ...motion.blocks import Block, dwell, gcode_move
from ...units import NUMBER
from .heads import HEAD_MODULES

POSITION = {"5420": "X", "5421": "Y", "5422": "Z", "5423": "A", "5424": "B", "5425": "C"}
# rs274ngc reads a line into LINELEN (255) characters with its line end and the string's end:
# a line of 253 characters or more is "Command too long" (rs274, tried: 252 runs)
LINE_MAX = 252
HAL_NAME = re.compile(r"[A-Za-z0-9._+-]+")      # a file name every reader of a configuration carries

# LinuxCNC applies G92 (and G52, which shares its parameters) and the active G5x offset to a
# program's positions before its kinematics: they do not turn with the table, so under TCP
# a G54 touched off on the table centre moves every tilted pose (224 mm at K4's worst), and
# under identity kinematics it moves every position. compgen's positions are the kinematics'
# own coordinates: the programs select G54 and stop, naming what is set, unless G92's and
# G54's offsets (and its XY rotation) are zero on the axes the program moves or the
# kinematics read (W: the head modules lengthen the pivot by it). An abort's text expands
# #n as a DEBUG does (rs274, tried); it holds no ";", which compgen's reader takes for a
# comment. Each line stays within LINE_MAX.
OFFSET_WORDS = {"G92": (5211, "XYZABCW"), "G54": (5221, "XYZABCWR")}
PARAM_OF = dict(zip("XYZABCUVWR", range(10), strict=True))


def _guard(label: str, params: list[tuple[str, int]], then: str) -> list[str]:
    cond = " OR ".join(f"[ABS[#{n}] GT 0.0001]" for _, n in params)
    said = " ".join(f"{w}#{n}" for w, n in params)
    return [f"o{label} if [{cond}]", f"(abort, {then.format(said=said)})", f"o{label} endif"]


def offsets_guard() -> list[str]:
    """The blocks that stop a LinuxCNC program, before any motion, unless the work offsets
    it runs under are zero (compgen's reader takes exactly these)."""
    (g92, w92), (g54, w54) = OFFSET_WORDS["G92"], OFFSET_WORDS["G54"]
    return ["G54 ; LinuxCNC applies G54 and G92 before its kinematics: both must be zero",
            *_guard("102", [(w, g92 + PARAM_OF[w]) for w in w92],
                    "G92 offsets are set: {said}. G92.1 clears them"),
            *_guard("103", [(w, g54 + PARAM_OF[w]) for w in w54],
                    "G54 holds {said}. compgen's positions need it zero: G10 L2 P1 with each of those 0")]


def head_guard(module: str) -> list[str]:
    """A head module's own state, read after the length is off and motion has settled: W
    (both modules compute with pivot-length + W) and, for 5axiskins, the switchable type
    that runs it (0, as LinuxCNC's bridgemill sample's M428 sets it)."""
    lines = _guard("104", [("W", 5428)], f"W stands at {{said}} mm. {module} lengthens the pivot by W: "
                                         "bring W to 0 first")
    if module == "5axiskins":
        lines += ["o105 if [#<_hal[motion.switchkins-type]> NE 0]",
                  "(abort, motion.switchkins-type is #<_hal[motion.switchkins-type]>. 5axiskins runs at 0: "
                  "M428 in LinuxCNC's bridgemill sample)", "o105 endif"]
    return lines


HEAD_PROGRAM = re.compile(r"^; LinuxCNC: (\S+kins) \(", re.MULTILINE)    # a program written for a head
PIN_GUARD = re.compile(r"o101 if \[ABS\[#<_hal\[(\S+kins)\.pivot-length\]> - (\S+)\] GT (\S+)\]")


def _blocks_of(lines: list[str]) -> list[str]:
    """Lines as the reader compares them: the comment after ";" off, white space trimmed."""
    return [ln.split(";", 1)[0].strip() for ln in lines]


# compgen's state guards as the reader compares them: kind, module, their blocks
STATE_GUARDS = (("offsets", "", _blocks_of(offsets_guard())),
                *(("head state", m.module, _blocks_of(head_guard(m.module))) for m in HEAD_MODULES))
GUARD_LINES = max(len(blocks) for _, _, blocks in STATE_GUARDS)


def _state_guard(lines: list[str], k: int) -> tuple[str, str, int] | None:
    """Whether line ``k`` starts one of compgen's state guards (the work offsets, a head
    module's W and type): its kind, module and last line; a line that starts one but does
    not go on as compgen writes it is refused (a guard edited is no guard)."""
    got = _blocks_of(lines[k - 1:k - 1 + GUARD_LINES])
    starts = False
    for kind, module, want in STATE_GUARDS:
        if got[:len(want)] == want:
            return kind, module, k + len(want) - 1
        starts |= got[0] == want[0]
    if starts or re.match(r"o10[2-5] ", got[0]):
        raise CompgenError(f"line {k}: {lines[k - 1].strip()!r} is not compgen's guard (of the work offsets "
                           "or a head module's state: each condition, its abort and endif)",
                           hint="give the program compgen wrote")
    return None


def program_blocks(text: str, tcp: bool, head: str | None = None) -> list[Block]:
    """A G-code program as LinuxCNC executes it (the blocks compgen writes); ``tcp``: the
    trt kinematics are active (the configuration's choice: the program cannot say it).
    Under a ``head`` module (maxkins, 5axiskins) the nest's length is the kinematics'
    pivot-length: G49 leaves it there, a G43 length would act along world Z whatever B is,
    and the program's guard stops unless the pin holds the length (a ``pin`` block)."""
    out, modal, feed = [Block(0, "kinematics", "tcp", on=tcp)], None, None
    lines = text.splitlines()
    guard_at, read_to = None, 0
    for k, raw in enumerate(lines, start=1):
        if len(raw) > LINE_MAX:
            raise CompgenError(f"line {k}: {len(raw)} characters; LinuxCNC reads {LINE_MAX} of a line and "
                               "stops the program there (\"Command too long\")",
                               hint="give the program compgen wrote")
        b = raw.split(";", 1)[0].strip()
        if guard_at is not None and k in (guard_at + 1, guard_at + 2) or k <= read_to:
            continue                        # a guard's abort and endif, read with it
        if not b:
            continue
        if (state := _state_guard(lines, k)) is not None:
            kind, module, read_to = state
            out.append(Block(k, raw, kind, name=module))
        elif b == "G21 G90 G94 G17":          # G21: millimetres
            out.append(Block(k, raw, "units"))
        elif b in ("M2", "M30"):
            out.append(Block(k, raw, "end"))
        elif b == "M0" or re.fullmatch(r"\(MSG,[^)]*\)", b):        # the preset check's stop
            out.append(Block(k, raw, "stop"))
        elif (d := re.fullmatch(r"o100 if \[(.*)\]", b)) is not None:
            # compgen's guard: stop unless every named axis is at zero; it stops only if the
            # abort follows it, then its endif
            parts = re.findall(r"\[ABS\[#(\d+)\] GT 0\.0001\]", d[1])
            after = [ln.split(";", 1)[0].strip() for ln in lines[k:k + 2]]
            if (not parts or " OR ".join(f"[ABS[#{p}] GT 0.0001]" for p in parts) != d[1]
                    or any(p not in POSITION for p in parts) or len(after) < 2
                    or not re.fullmatch(r"\(abort,[^)]*\)", after[0]) or after[1] != "o100 endif"):
                raise CompgenError(f"line {k}: {raw.strip()!r} is not compgen's guard (the condition, then "
                                   "an (abort, ...) line and o100 endif)", hint="a guard that does not abort "
                                   "lets the program run from anywhere: give the program compgen wrote")
            guard_at = k
            out.append(Block(k, raw, "require", target={POSITION[p]: 0.0 for p in parts}))
        elif (d := PIN_GUARD.fullmatch(b)) is not None:
            # the pin guard: stop unless the head module's pivot-length holds the program's
            after = [ln.split(";", 1)[0].strip() for ln in lines[k:k + 2]]
            if (len(after) < 2 or not re.fullmatch(r"\(abort,[^)]*\)", after[0]) or after[1] != "o101 endif"
                    or not NUMBER.fullmatch(d[2]) or not NUMBER.fullmatch(d[3])):
                raise CompgenError(f"line {k}: {raw.strip()!r} is not compgen's pin guard (the condition, "
                                   "then an (abort, ...) line and o101 endif)",
                                   hint="give the program compgen wrote")
            guard_at = k
            out.append(Block(k, raw, "pin", target={f"{d[1]}.pivot-length": (float(d[2]), float(d[3]))}))
        elif re.fullmatch(r"M19 R\d{1,3}(?:\.\d{1,4})?", b):     # the spindle oriented: no axis moves
            continue
        elif b == "M66 E0 L0":               # waits for motion: the guard reads the pin as it is
            out.append(Block(k, raw, "sync"))
        elif re.fullmatch(r"T\d+ M6", b):
            out.append(Block(k, raw, "tool"))
        elif head and re.fullmatch(r"G43 H\d+", b):
            raise CompgenError(f"line {k}: {raw.strip()!r}: under {head} a G43 length acts along world Z "
                               "whatever B is", hint=f"the nest's length belongs in {head}.pivot-length; "
                                                    "give the program compgen wrote (G49)")
        elif re.fullmatch(r"G43 H\d+", b) or b == "G49":
            out.append(Block(k, raw, "length", on=b != "G49" or head is not None))
        elif (d := re.fullmatch(r"G4 P(\S+)", b)) is not None:
            out.append(dwell(d[1], k, raw))
        elif re.fullmatch(r"\((LOGOPEN,[\w.-]+|LOG,[^()]*|LOGCLOSE)\)", b):    # the probe log: no motion
            out.append(Block(k, raw, "log"))
        elif b.startswith("G38.2 "):      # probe towards the target, stop at the touch (error if none)
            move, _, feed = gcode_move(raw, k, ["G1", *b.split()[1:]], None, feed, "G53")
            out.append(replace(move, probe=True))
            modal = None                  # G38.2 stays modal: a bare position would probe again
        else:
            move, modal, feed = gcode_move(raw, k, b.split(), modal, feed, "G53")
            out.append(move)
    return out

