"""Units at the edge: SI-like inside (mm, rad), µm and arcsec for people.

Every quantity inside compgen is in mm or rad; these tables convert at input and output.
"""

from __future__ import annotations

import math
import re

from .errors import CompgenError

TO_INSIDE = {"mm": 1.0, "um": 1e-3, "µm": 1e-3, "rad": 1.0, "urad": 1e-6, "µrad": 1e-6,
             "deg": math.pi / 180.0, "arcsec": math.pi / 648000.0}
LENGTH = {"mm", "um", "µm"}
PLAUSIBLE = {"mm": 10.0, "rad": 0.1}     # far beyond any real error; keeps the model's arithmetic sane
DISPLAY = {"mm": ("um", 1e3), "rad": ("arcsec", 648000.0 / math.pi)}   # inside unit → shown


def to_inside(value: float, unit: str, inside_unit: str, where: str = "") -> float:
    """Convert ``value`` in ``unit`` to ``inside_unit`` (mm or rad), refusing a wrong dimension."""
    if unit not in TO_INSIDE:
        raise CompgenError(f"unknown unit {unit!r}", where=where,
                           hint="use one of mm, um, rad, urad, deg, arcsec")
    if (unit in LENGTH) != (inside_unit == "mm"):
        raise CompgenError(f"unit {unit!r} is not {'a length' if inside_unit == 'mm' else 'an angle'}",
                           where=where)
    if not math.isfinite(value):
        raise CompgenError(f"value {value!r} is not a finite number", where=where)
    inside = value * TO_INSIDE[unit]
    if abs(inside) > PLAUSIBLE[inside_unit]:
        raise CompgenError(f"{value:g} {unit} is not the size of a machine error", where=where,
                           hint=f"errors up to {PLAUSIBLE[inside_unit]:g} {inside_unit} are taken")
    return inside


# A number as every file and option compgen reads writes it: ASCII digits, a point, an
# exponent. Python's float() also takes "1_0", any script's digits, "nan", "inf" and "1e999".
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?", re.ASCII)


def number(text: str, what: str, where: str) -> float:
    """A number read from a user's or a control's file or the command line: finite, written
    as ``NUMBER``, or one clear refusal. The one reader of numbers outside the CSV's fast path."""
    value = float(text) if isinstance(text, str) and NUMBER.fullmatch(text.strip()) else math.nan
    if not math.isfinite(value):
        shown = text if not isinstance(text, str) or len(text) <= 40 else text[:40] + "..."
        raise CompgenError(f"{what} {shown!r} is not a number (a finite one, in ASCII digits)", where=where)
    return value


def shown(value: float, inside_unit: str) -> tuple[float, str]:
    """``value`` in mm or rad as a person reads it: µm or arcsec."""
    unit, factor = DISPLAY[inside_unit]
    return value * factor, ("µm" if unit == "um" else "″")


QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zµ]*)\s*$")


def parse_quantity(text: str, inside_unit: str, where: str) -> float:
    """``"-5um"``, ``"12.3 arcsec"`` or ``"0"`` → mm or rad. A non-zero bare number is refused."""
    m = QUANTITY.match(text)
    if not m:
        raise CompgenError(f"cannot read {text!r} as a number with a unit", where=where,
                           hint="write e.g. 12.3arcsec or -5um")
    value, unit = float(m[1]), m[2]
    if not unit:
        if value != 0.0:
            raise CompgenError(f"{text!r} has no unit", where=where, hint="write e.g. 12.3arcsec or -5um")
        return 0.0
    return to_inside(value, unit, inside_unit, where)


def three(v, width: int = 9) -> str:
    """dX dY dZ (µm) in columns that never run together: each at least one space apart."""
    return "".join(f"{x:{width}.3f}" for x in v)


def three_header(words: tuple[str, str, str], width: int = 9) -> str:
    return "".join(f"{w:>{width}}" for w in words)


# a device's noise per reading beyond this is no measurement compgen reads (its readings stay
# within 5 mm, an R-test's noise is 0.1-5 µm): a larger figure is a unit or a typing error
NOISE_MAX_UM = 1000.0
