"""The trt modules' pins in a configuration: the HAL a configuration runs, read as halcmd
reads it, and the pins compgen's edit sets."""

from __future__ import annotations

import re

import numpy as np

from ...errors import CompgenError
from ...model.lines import AxisLine
from ...model.machine import Machine
from ...units import number
from .. import fmt_plain
from ..correction import (
    Plan,
)
from .config import Configuration, evaluate, hal_file, is_bundle, then
from .files import Setting
from .heads import _tilts, head_correction, head_lines, head_module, module_pins, trt_module
from .tables import joint_tables

# the value is the rest of the line (a comment aside): halcmd takes one word, so "1.0 junk"
# is refused as a value rather than read as 1.0
SETP = re.compile(r"^[ \t]*setp[ \t]+(\S+?)\.(\S+)[ \t]+([^#\n]*?)[ \t]*(?:#.*)?$", re.MULTILINE)
SETS = re.compile(r"^[ \t]*sets[ \t]+(\S+)[ \t]+([^#\n]*?)[ \t]*(?:#.*)?$", re.MULTILINE)
PIN_SINCE = (2, 10)          # the trt modules' conventional-directions pin (commit bfb687eaa6)
# Upstream's trtfuncs.c from 2.10 (xyzbc_inverse_math) writes the tilted offsets with the
# signs of conventional-directions 1 whatever the pin says, while its forward kinematics
# follows the pin: at pin 0 the inverse no longer inverts the forward.
XYZBC_PIN0 = ("LinuxCNC 2.10's xyzbc-trt-kins at conventional-directions 0 does not invert its own forward "
              "kinematics: trtfuncs.c xyzbc_inverse_math has 'dpx = -cos(b_rad)*dx + sin(b_rad)*dz + dx' "
              "and 'dpz = -sin(b_rad)*dx - cos(b_rad)*dz + dz' (the signs of pin 1; 2.9 had "
              "'- sin(b_rad)*dz' and '+ sin(b_rad)*dx'), while xyzbc_forward_math turns by con = -1 at "
              "pin 0: under TCP the nest stands off by 2*sin(B)*(z-offset + tool-offset) in X and "
              "2*sin(B)*x-offset in Z")



def configuration(state: str | None, where: str) -> Configuration | None:
    """What LinuxCNC holds from ``state``: a configuration read from its INI, or one HAL
    file run alone."""
    if state is None:
        return None
    return evaluate(state) if is_bundle(state) else hal_file(state, where)



def read_hal(text: str, module: str, where: str) -> tuple[dict[str, float], dict[str, str]]:
    """A HAL file's values of the module's pins (``setp``, ``PIN = VALUE``, or ``sets`` on
    the signal a pin is netted to) and the signal each netted pin is on, as halcmd runs it.
    A pin or signal set twice in one file is refused (HAL keeps the last: which was meant?)."""
    values, signal, _ = held_pins(configuration(text, where), module)
    return values, signal


def held_pins(cfg: Configuration, module: str
              ) -> tuple[dict[str, float], dict[str, str], dict[str, Setting]]:
    """The module's pins that hold a value in ``cfg``: values, the signal of each netted
    pin, and the setting (value as written, place) of each."""
    values, signal, setting = {}, {}, {}
    names = {p[len(module) + 1:] for p in (*cfg.pins, *cfg.net) if p.startswith(f"{module}.")}
    for n in names:
        pin = f"{module}.{n}"
        if pin in cfg.net:
            signal[n] = cfg.net[pin]
        s = cfg.value(pin)
        if s is not None:
            values[n], setting[n] = number(s.text, f"{pin}", str(s.place)), s
    return values, signal, setting


def pins(machine: Machine, p: Plan, current: Configuration | None, where: str
         ) -> tuple[str, list[tuple[str, str, str, str]], list[str], dict[str, Setting]]:
    """The HAL assignments of the trt pins: (``setp`` or ``sets``, pin or signal, new value,
    old value), each pin the way the current configuration sets it (a netted pin through its
    signal); the current values or the machine file's nominal, plus the corrections; what
    the pins cannot express; and where the configuration sets each pin."""
    module, names, nominal = module_pins(machine)
    held, signal, line_of = nominal, {}, {}
    if current is not None:
        held, signal, line_of = held_pins(current, module)
        for n in names:
            if n not in held:
                why = (f"is netted to {signal[n]}, which another component drives" if n in signal
                       else "is set neither by setp nor through a signal")
                raise CompgenError(f"in --current, {module}.{n} {why}", where=where,
                                   hint=f"give the HAL file that sets {', '.join(names)}")
            if not abs(held[n] - nominal[n]) * 1e3 <= machine.limits.offset_um:
                raise CompgenError(f"{module}.{n} = {held[n]:g} mm, {held[n] - nominal[n]:+.4f} mm from the "
                                   f"machine file's {nominal[n]:g}: beyond its [limits] offset_um "
                                   f"{machine.limits.offset_um:g} µm", where=str(line_of[n].place),
                                   hint="is this the configuration of the measured machine? If it is, "
                                        "correct the machine file's offsets or raise [limits]")
    if head_module(machine) is not None:
        along, other = head_correction(machine, p)
        new = {"pivot-length": held["pivot-length"] + along}
    else:
        _, tilt, c = trt_module(machine)
        delta_r = p.lines[c.name].offset
        delta_d = p.lines[tilt.name].offset - delta_r
        new = {n: held[n] + (delta_r if n.endswith("rot-point") else delta_d)["xyz".index(n[0])]
               for n in names}
        in_joints = {t.effect for t in joint_tables(machine, p)}
        other = [*_tilts(p), *p.squareness, *(e for e in p.tables if e not in in_joints), *p.not_compensable]
    was = {n: line_of[n].text if current is not None else fmt_plain(held[n], 6) for n in names}
    rows = [("sets", signal[n], fmt_plain(new[n], 6), was[n]) if n in signal else
            ("setp", f"{module}.{n}", fmt_plain(new[n], 6), was[n]) for n in names]
    return module, rows, other, {n: line_of[n] for n in names if n in line_of}


def read_lines(text: str, machine: Machine, current: str | None,
               lines: dict[str, AxisLine]) -> dict[str, AxisLine]:
    """The axis lines a trt edit sets, relative to ``current`` (default: nominal): ``text``
    is a configuration to start with (read from its INI), or a HAL file loaded after
    ``current``'s files, whose values reach the pins through their nets."""
    module, _, nominal = module_pins(machine)
    cfg = configuration(current, "current")
    before = held_pins(cfg, module)[0] if cfg is not None else nominal
    if is_bundle(text):
        now = held_pins(evaluate(text), module)[0]
    else:
        now = {**before, **held_pins(then(cfg, text, "edit") if cfg else hal_file(text, "edit"), module)[0]}
    if head_module(machine) is not None:
        return head_lines(machine, now["pivot-length"] - before["pivot-length"])
    _, tilt, c = trt_module(machine)
    r = np.array([now[f"{a}-rot-point"] - before[f"{a}-rot-point"] for a in "xyz"])
    d = np.array([now.get(f"{a}-offset", 0.0) - before.get(f"{a}-offset", 0.0) for a in "xyz"])
    zero = np.zeros(3)
    return {**lines, c.name: AxisLine.of(c, lines[c.name].pivot, r, zero),
            tilt.name: AxisLine.of(tilt, lines[tilt.name].pivot, r + d, zero)}


