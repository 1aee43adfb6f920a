"""A SINUMERIK part program as the control executes it (the blocks compgen writes), its modulo
axes' ways and its guards."""

from __future__ import annotations

import re
from dataclasses import replace

from ...errors import CompgenError
from ...motion.blocks import Block, dwell, gcode_move
from ..state_guards import FRAME_IF, sinumerik_terms

# A 360° modulo rotary axis (MD30310 ROT_IS_MODULO) moves to a plain absolute position the way
# MD30455 bit 2 says: like AC (the sign of target − current, in 0…360) or like DC (shortest);
# so K2 ending at C360 from C357 turns −357° by default. compgen writes the way in the block:
# ACP (+), ACN (−), DC (shortest). Function Manual Axes and Spindles 06/2019, R2 §7.2 p.225.
MODULO_WORD = re.compile(r"([A-C])=(ACP|ACN|DC)\(([+-]?\d+(?:\.\d+)?)\)")
TURN = {"ACP": "+", "ACN": "-", "DC": "short"}


# compgen's guards in a probing program: after each MEAS block, stop unless the probe switched
# (U17); after each WRITE, stop unless it wrote (U15). Each ends the program with a message.
GUARD = re.compile(r"IF (\$AC_MEA\[1\]==0|ERR<>0)")
GUARD_BODY = (re.compile(r'MSG\("[^"]+"\)'), re.compile("M0"), re.compile("M30"), re.compile("ENDIF"))


def _guard_body(lines: list[str], k: int, b: str) -> int:
    """The lines after a guard's IF (line ``k``): compgen's message, M0, M30, ENDIF, or a
    refusal (a guard that does not stop is no guard); how many they are."""
    body = lines[k:k + len(GUARD_BODY)]
    if len(body) < len(GUARD_BODY) or not all(p.fullmatch(t) for p, t in zip(GUARD_BODY, body, strict=True)):
        raise CompgenError(f"line {k}: {b!r} is not compgen's guard (a message, M0, M30, ENDIF)",
                           hint="give the program compgen wrote")
    return len(GUARD_BODY)


# stop unless an axis the PLC positions stands at its target, after the stop that asked for it
INDEX_IF = re.compile(r"IF ABS\(\$AA_IM\[([A-C])\]-\(([+-]?\d{1,4}(?:\.\d{1,9})?)\)\)>0\.001")
_FACTOR = r"\([+-]?\d{1,6}(?:\.\d{1,9})?\)"
TIP = re.compile(rf"TIP_[XYZ]=\$AA_MW\[X\]\*{_FACTOR}\+\$AA_MW\[Y\]\*{_FACTOR}\+\$AA_MW\[Z\]\*{_FACTOR}"
                 rf"\+{_FACTOR}")


def program_blocks(text: str) -> list[Block]:
    """A SINUMERIK part program as the control executes it (the blocks compgen writes). In a
    probing program every MEAS block is followed by STOPRE and the switch's guard, every
    WRITE by the write's guard: without them a lost touch or a full log goes unseen."""
    out, modal, feed = [], None, None
    lines = [raw.split(";", 1)[0].strip() for raw in text.splitlines()]
    skip, expect = 0, []
    for k, raw in enumerate(text.splitlines(), start=1):
        b = lines[k - 1]
        if skip:
            skip -= 1
            continue
        if not b or b in ("ORIWKS", "ORIAXES", "M6", "DEF INT ERR", "DEF REAL TIP_X,TIP_Y,TIP_Z"):
            continue
        if expect:
            if b != expect[0]:
                raise CompgenError(f"line {k}: {raw.strip()!r} where {expect[0]!r} must follow the "
                                   f"{'probing move' if 'MEA' in expect[-1] else 'WRITE'} (line {k - 1})",
                                   hint="a lost touch or an unwritten log line would go unseen: give the "
                                        "program compgen wrote")
            expect.pop(0)
            if b.startswith("IF "):
                skip = _guard_body(lines, k, b)
                out.append(Block(k, raw, "log"))
            continue
        if b == "STOPRE" or re.fullmatch(r"SPOS=\d{1,3}(?:\.\d{1,4})?", b):    # the spindle oriented (U27)
            continue
        if TIP.fullmatch(b):             # a head's latched tip into the machine frame (U25): no motion
            out.append(Block(k, raw, "log"))
            continue
        if re.fullmatch(r'WRITE\(ERR,"\w+","[^"]*"(?:<<(?:\$AA_MW\[[XYZ]\]|TIP_[XYZ])<<"[^"]*")*\)', b):
            out.append(Block(k, raw, "log"))        # a line of the probe log (U15)
            expect = ["IF ERR<>0"]
            continue
        if b.startswith("MEAS=1 G1 "):            # probe towards the target, stop at the touch (U14)
            move, _, feed = gcode_move(raw, k, b.split()[1:], None, feed, "SUPA")
            out.append(replace(move, probe=True))
            expect = ["STOPRE", "IF $AC_MEA[1]==0"]
            continue
        if (d := INDEX_IF.fullmatch(b)) is not None:      # the operator had the PLC turn it (U26)
            skip = _guard_body(lines, k, b)
            out.append(Block(k, raw, "move", target={d[1]: float(d[2])}, rapid=True, plc=True))
            continue
        if (d := FRAME_IF.fullmatch(b)) is not None:         # compgen's frame guard: no motion
            skip = _guard_body(lines, k, b)
            out.append(Block(k, raw, "offsets", target=sinumerik_terms(d[1])))
            continue
        if GUARD.fullmatch(b):
            raise CompgenError(f"line {k}: {b!r} stands where no probing move or WRITE precedes it",
                               hint="give the program compgen wrote")
        if b == "G17 G90 G71 G94":          # G71: metric (G70 would read compgen's mm as inches)
            out.append(Block(k, raw, "units"))
        elif b in ("M30", "M17"):
            out.append(Block(k, raw, "end"))
        elif re.fullmatch(r"G5[4-7]|G50[0-9]", b):
            out.append(Block(k, raw, "offset", name=b))
        elif b == "M0" or re.fullmatch(r'MSG\("[^"]*"\)|MSG\(\)', b):   # the preset check's stop
            out.append(Block(k, raw, "stop"))
        elif b in ("TRAFOOF", "TRAORI"):
            out.append(Block(k, raw, "tcp", on=b == "TRAORI"))
        elif re.fullmatch(r'T="[^"]*"', b):
            out.append(Block(k, raw, "tool"))
        elif b in ("D0", "D1"):
            out.append(Block(k, raw, "length", on=b == "D1"))
        elif (d := re.fullmatch(r"G4 F(\S+)", b)) is not None:
            out.append(dwell(d[1], k, raw))
        else:
            tokens, turn = [], {}
            for t in b.split():       # L=ACP(v), ACN, DC: a modulo axis's position and way
                d = MODULO_WORD.fullmatch(t)
                if d is not None:
                    turn[d[1]] = TURN[d[2]]
                    t = f"{d[1]}{d[3]}"
                tokens.append(t)
            move, modal, feed = gcode_move(raw, k, tokens, modal, feed, "SUPA", skip=("D0",))
            move = replace(move, turn=turn)
            if "D0" in tokens:
                out.append(Block(k, raw, "length", on=False))
            out.append(move)
    return out

