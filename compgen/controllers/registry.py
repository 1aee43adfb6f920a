"""The one list of controllers. The machine loader, the CLI, compare, simulate and the
checklist ask it; none of them tests a controller's name. A new controller is one module
(a ``Controller`` subclass), its templates and its golden files, plus one line here."""

from __future__ import annotations

from collections.abc import Mapping

from ..errors import CompgenError
from ..model.machine import Machine
from .base import Controller, joined
from .correction import Held, nominal_lines
from .heidenhain import ITNC530, TNC640
from .linuxcnc import LinuxCNC
from .sinumerik import Sinumerik840D

CONTROLLERS: dict[str, Controller] = {c.name: c for c in (ITNC530(), TNC640(), Sinumerik840D(), LinuxCNC())}


def register(ctl: Controller) -> None:
    """Add a controller (a plug-in, or a test's toy controller)."""
    if not ctl.name or ctl.name in CONTROLLERS:
        raise CompgenError(f"controller name {ctl.name!r} is empty or taken")
    CONTROLLERS[ctl.name] = ctl


def controller(name: str) -> Controller:
    if name not in CONTROLLERS:
        raise CompgenError(f"unknown controller {name!r}", hint=f"use one of {', '.join(CONTROLLERS)}")
    return CONTROLLERS[name]


def for_machine(name: str, machine: Machine, edit: bool = False) -> Controller:
    """The controller ``name``, to write or read ``machine``'s programs (or, with ``edit``,
    its kinematics edits): refused for a machine whose head turns the tool where compgen
    does not write that control's files for it (a table-table control's would be wrong)."""
    ctl = controller(name)
    inclined = [a for a in machine.rotary_axes if a.inclined]
    if edit and inclined and not ctl.holds_inclined:
        a = inclined[0]
        raise CompgenError(f"compgen does not write {ctl.words} kinematics edits for an inclined axis: "
                           f"{machine.name}'s {a.name} turns about {a.unit_text} "
                           "(UNCONFIRMED U24)", where=machine.source,
                           hint="fit, diagnose and report hold for it; enter the fitted lines by hand, or "
                                "write the edit for a SINUMERIK, whose $TC_CARR vectors take any direction")
    if machine.heads and not (ctl.edits_head(machine) if edit else ctl.writes_programs(machine)):
        what = "kinematics edits" if edit else f"{ctl.words} programs"
        heads = ", ".join(a.name for a in machine.heads)
        raise CompgenError(f"compgen does not write {what} for a head yet: {machine.name}'s {heads} turns "
                           "the tool", where=machine.source,
                           hint="fit, diagnose and report hold for it; write its "
                                + ("kinematics" if edit else "programs") + " by hand from the fitted values")
    return ctl


def for_program(path_suffix: str, machine: Machine) -> Controller:
    """The controller whose programs end in ``path_suffix``: the machine's own if it does."""
    for_machine(machine.controller, machine)
    own = CONTROLLERS.get(machine.controller)
    if own is not None and own.program_ext.lower() == path_suffix.lower():
        return own
    ctl = next((c for c in CONTROLLERS.values() if c.program_ext.lower() == path_suffix.lower()), None)
    if ctl is None:
        raise CompgenError(f"no controller writes programs ending in {path_suffix!r}",
                           hint="name it with --controller")
    return ctl


def read_state(paths: str | tuple[str, ...]) -> str:
    """A control's current state (``--current``, ``--measured-with``) from its files, in the
    order given: each file, or what a control makes of it (LinuxCNC: its INI's HAL files and
    joint tables, in the order it loads them)."""
    from ..files import read_text
    out = []
    for path in (paths,) if isinstance(paths, str) else paths:
        text = read_text(path, "file", ansi_ok=True)[0]
        out.append((path, next((s for c in CONTROLLERS.values() if (s := c.state(path, text)) is not None),
                               text)))
    return joined(out)


def comment_marks() -> str:
    """Every controller's comment character, for recognising compgen's files by content."""
    return "".join(sorted({c.comment for c in CONTROLLERS.values()}))


def read_edits(machine: Machine, texts: Mapping[str, str], current: str | None) -> Held:
    """What a control holds after loading the edit files ``texts`` (where → text), each
    read by the controller that wrote it; ``current`` is the state before, where needed."""
    for_machine(machine.controller, machine, edit=True)
    held = Held(nominal_lines(machine), {}, ())
    for where, text in texts.items():
        ctl = next((c for c in CONTROLLERS.values() if c.reads(text)), None)
        if ctl is None:
            raise CompgenError("not a kinematics edit compgen wrote for any controller it knows",
                               where=where)
        held = ctl.read(machine, text, current, held, where)
    return held
