"""LinuxCNC's kinematics modules: the trt modules for a table, and for a head maxkins and
5axiskins (Debian's 2.9), their one geometry pin and how each turns the machine file's axes."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...errors import CompgenError
from ...model.lines import AxisLine
from ...model.machine import Machine
from ..correction import (
    ARCSEC,
    Plan,
    nominal_lines,
    pivot_of,
)


def trt_module(machine: Machine) -> tuple[str, object, object]:
    """The trt module for a two-axis table (A or B tilting, C on it), or a clear refusal."""
    axes = machine.rotary_axes
    if (len(axes) != 2 or any(a.side != "workpiece" for a in axes) or axes[1].direction != "z"
            or axes[0].direction not in "xy" or any(a.inclined for a in axes)):
        raise CompgenError("LinuxCNC's trt kinematics is for a tilting table (A or B) carrying C",
                           hint="this machine's chain is not one xyzac-/xyzbc-trt-kins can drive")
    return f"xyz{axes[0].name.lower()}c-trt-kins", axes[0], axes[1]


@dataclass(frozen=True)
class HeadModule:
    """A LinuxCNC kinematics module that turns the tool: its name, what machine it is for,
    and how it turns each rotary axis against the machine file (what it holds was run with
    the real module: tests/controllers/test_linuxcnc.py). Its one geometry pin, pivot-length, holds the
    pivot to the controlled point: compgen's programs put the nest there (G49)."""
    module: str
    what: str
    active: str                           # when the control runs it
    head: tuple[tuple[str, str], ...]     # the head's axes, base outwards: (name, direction)
    table: tuple[tuple[str, str], ...]    # the table's rotary axes
    sense: tuple[tuple[str, int], ...]    # ±1 a rotary axis: its turn in the module's words
    notes: tuple[str, ...] = ()           # what its programs' headers must tell the operator


# Debian's 2.9: maxkins.c (a B head over a C table, always active; X Y Z in the table frame)
# and 5axiskins.c (a bridge mill's C head carrying B, through switchkins type 0). Both tilt
# B the other way from a right-handed turn of the tool; maxkins turns its table's C the
# other way too, 5axiskins its head's C as the tool turns.
HEAD_MODULES = (
    HeadModule("maxkins", "a B head over a C table", "always active",
               head=(("B", "y"),), table=(("C", "z"),), sense=(("B", -1), ("C", -1)),
               # 2.9's maxkins.c forward kinematics copies the joints (its inverse turns them):
               # switched to joint mode (Manual after an abort), X and Y jump by up to 2 L sin B
               notes=("After an abort or an E-stop: maxkins' forward kinematics do not invert its inverse,",
                      "and Manual mode then moves X and Y by up to 2 x pivot-length x sin B. Stay in MDI:",
                      "take the nest off the ball along its axis, go up to the safe height, G0 B0 C0;",
                      "only then switch to Manual.")),
    HeadModule("5axiskins", "a C head carrying a B fork",
               "at motion.switchkins-type 0 (its start without sparm=identityfirst)",
               head=(("C", "z"), ("B", "y")), table=(), sense=(("B", -1), ("C", 1))),
)


def head_module(machine: Machine) -> tuple[HeadModule, float] | None:
    """LinuxCNC's module for ``machine``'s head and the pivot-length it needs (mm: the pivot
    to the nest centre, the nest's length in it), or None where no module fits: every head
    axis pivoting on the tool axis at one point, a table axis turning about the origin, each
    turning right-handed in the machine file about its letter's axis (none inclined)."""
    heads, tables = machine.heads, [a for a in machine.rotary_axes if a.side == "workpiece"]
    for m in HEAD_MODULES:
        if ([(a.name, a.direction) for a in heads] != list(m.head)
                or [(a.name, a.direction) for a in tables] != list(m.table)
                or any(a.sense != 1 or a.inclined for a in machine.rotary_axes)
                or any(any(c.offset) for c in tables) or any(heads[0].offset[:2])
                or any(any(a.offset) for a in heads[1:])):
            continue
        return m, machine.probe_length + heads[0].offset[2]
    return None


def pin_tolerance(machine: Machine) -> float:
    """How far (mm) a head module's pivot-length may stand from the machine file's for its
    programs to run: what an edit may change it by, the machine file's [limits] offset_um
    (the motion check's clearances are millimetres)."""
    return float(f"{machine.limits.offset_um * 1e-3:.4f}")


def module_pins(machine: Machine) -> tuple[str, list[str], dict[str, float]]:
    """The kinematics module compgen edits for ``machine`` (a head module, else trt), its
    geometry pins in the order the edit writes them, and their nominal values (mm)."""
    head = head_module(machine)
    if head is not None:
        return head[0].module, ["pivot-length"], {"pivot-length": head[1]}
    module, tilt, c = trt_module(machine)
    return module, pin_names(tilt), nominal_pins(machine, tilt, c)


def head_correction(machine: Machine, p: Plan) -> tuple[float, list[str]]:
    """What a head module's one pin holds of ``p``: the heads' line offsets along the tool
    axis at the pivot (mm; the true pivot that much farther from the nest lengthens the
    pivot-length by it), and in words all else, which no pin of the module holds."""
    heads = {a.name for a in machine.heads}
    along = sum(float(p.lines[h].offset[2]) for h in heads)
    other = [f"{n} offset {line.offset[i] * 1e3:+.2f} um along {'XYZ'[i]}" for n, line in p.lines.items()
             for i in range(3) if line.offset[i] != 0 and not (n in heads and i == 2)]
    return along, [*other, *_tilts(p), *p.squareness, *p.tables, *p.not_compensable]


def _tilts(p: Plan) -> list[str]:
    """The axis lines' tilts of ``p`` in words: no LinuxCNC pin holds a tilt."""
    return [f"{n} tilt {line.tilt[i] / ARCSEC:+.2f} arcsec about {'XYZ'[i]}"
            for n, line in p.lines.items() for i in range(3) if line.tilt[i] != 0]


def head_lines(machine: Machine, along: float) -> dict[str, AxisLine]:
    """The axis lines a head module holds with its pivot-length ``along`` mm from nominal:
    the tilting head's line that much farther from the nest, every other line nominal."""
    lines = nominal_lines(machine)
    tilt = next(a for a in machine.heads if a.direction != "z")
    line = lines[tilt.name]
    return {**lines, tilt.name: replace(line, offset=np.array([0.0, 0.0, along]))}


def pin_names(tilt) -> list[str]:
    """The trt module's geometry pins, in the order the edit writes them: C's rotation
    point and the tilt's offset from it (the component along its own line has no pin)."""
    along = "xyz".index(tilt.direction)
    return ["x-rot-point", "y-rot-point", "z-rot-point"] + [
        f"{'xyz'[k]}-offset" for k in range(3) if k != along]


def nominal_pins(machine: Machine, tilt, c) -> dict[str, float]:
    """The pins' values, mm, for the machine file's nominal pivots (no correction)."""
    pivot_c, pivot_t = pivot_of(machine, c.name), pivot_of(machine, tilt.name)
    return {"x-rot-point": pivot_c[0], "y-rot-point": pivot_c[1], "z-rot-point": pivot_c[2],
            **{f"{'xyz'[k]}-offset": (pivot_t - pivot_c)[k] for k in range(3)}}




