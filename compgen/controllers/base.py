"""The contract every controller module fulfils (scikit-rf's calibration classes are the
model): its program syntax, its kinematics edit, its reader of the current state and of its
own edits, and what the control holds once the edit is loaded. Nothing outside a controller
module tests a controller's name."""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import CompgenError
from ..model.machine import Machine, ProbeSetup
from ..motion.blocks import Block
from ..motion.check import Check, run
from . import fmt_plain
from .correction import CompTable, Held, Plan, comp_tables, squareness_tables

# A control's state read from several files is one text, each file after this line (LinuxCNC's
# INI resolution writes "HAL file"): every reader names a line by its own file and number.
FILE_MARK = re.compile(r"^# compgen: (?:HAL )?file (.+?)(?: \(.*\))?$")


def state_lines(text: str, where: str) -> Iterator[tuple[str, str]]:
    """(``file:line``, line) of a state's text, numbered within each of its files."""
    k = 0
    for line in text.splitlines():
        if (mark := FILE_MARK.match(line)) is not None:
            where, k = mark[1], 0
            continue
        k += 1
        yield f"{where}:{k}", line


def joined(files: list[tuple[str, str]]) -> str:
    """Several files' states as one text (``state_lines`` numbers each by its own file)."""
    if len(files) == 1:
        return files[0][1]
    return "".join(f"# compgen: file {path}\n{text}{'' if text.endswith(chr(10)) else chr(10)}"
                   for path, text in files)


@dataclass(frozen=True)
class EditContext:
    """What every edit file says in its header, and the sign check it points to."""

    name: str                 # program name of the edit (its stem)
    header: tuple[str, ...]
    lines: tuple[str, ...]    # the corrections in words (``correction.lines_text``)
    expect: tuple[str, ...]   # the sign check's expected reading changes
    version: str
    date: str
    marker: str = ""          # the fit's marker (``FitResult.marker``)
    stem: str = ""            # the file stem the edit's files are written under (default: name)
    sigma: tuple = ()         # (parameter, σ in mm or rad) of the fit: what a file's rounding may lose
    folder: str = ""          # where the files go ("": beside the state read): files that name files


@dataclass(frozen=True)
class EditFiles:
    """An edit's files (suffix → text) and what the user must read on the terminal."""

    files: dict[str, str]
    notes: tuple[str, ...] = field(default_factory=tuple)


class Controller:
    """A control. Subclasses set the class attributes and override the methods."""

    name = ""                 # the machine file's ``controller`` and ``--controller``
    family = ""               # folder of its templates
    words = ""                # how people name it
    program_ext = ""          # suffix of its programs
    name_max = 24             # characters of a program name it keeps (HEIDENHAIN, SINUMERIK: 24)
    comment = ";"             # what starts a comment line in its files
    tcp_words = ""            # its name for tool-centre-point control
    backup = ""               # what to save before an edit
    pose_line: re.Pattern     # one measuring pose of a program it wrote
    tcpm_on: re.Pattern       # a program it wrote switches TCP on
    tcp_switchable = True     # a program switches TCP on and off (else: the configuration's)
    section = ""              # its own table of the machine file, read by ``read_section``
    load_note = ""            # what loading its edit takes beyond the files (the checklist says it)
    state_files = ""          # what its state is read from, where that is more than one file

    def read_section(self, get, machine: Machine) -> dict:
        """This control's table of the machine file, checked (``get`` names file and key in
        every complaint, as ``machine_file`` reads every table)."""
        raise NotImplementedError

    @staticmethod
    def number(value: float, decimals: int) -> str:
        return fmt_plain(value, decimals)

    def angle_sense(self, machine: Machine) -> dict[str, int]:
        """Per rotary axis, ±1: the sense in which this control's program words turn it
        against compgen's (the machine file's) sense."""
        return {a.name: 1 for a in machine.rotary_axes}

    def modulo_axes(self, machine: Machine) -> tuple[str, ...]:
        """The rotary axes this control positions modulo 360° on this machine."""
        return ()

    def axis_word(self, letter: str, value: float, before: float | None, feed: bool, decimals: int,
                  machine: Machine) -> str:
        """An axis's word in a move: ``before`` is its value in the last block that wrote it
        (None: not yet), ``feed`` whether the block is a feed move (a pose) or a rapid."""
        return f"{letter}{self.number(value * self.angle_sense(machine).get(letter, 1), decimals)}"

    def blocks(self, text: str, mode: str | None = None) -> list[Block]:
        """A program as this control executes it, block by block (``motion.Block``);
        ``mode`` (tcpm, axes): where the configuration, not the program, decides whether
        TCP is active (``tcp_switchable`` False), the mode it runs under."""
        raise NotImplementedError

    def check(self, machine: Machine, blocks: list[Block], probe: ProbeSetup | None = None) -> Check:
        """The motion check of ``blocks`` (``self.blocks``) as this control runs them: with
        its modulo rule and its sense of the rotary axes (``motion.run``)."""
        return run(machine, blocks, self.modulo_axes(machine), self.angle_sense(machine), probe=probe)

    def program_context(self, machine: Machine) -> dict:
        """What this control's program template needs of ``machine`` beyond the steps."""
        return {}

    def programs_for_head(self, machine: Machine) -> bool:
        """Whether compgen writes this control's programs for ``machine``, whose head turns
        the tool: a control that switches TCP in its program holds the nest there through
        the whole program (``programs._steps``; the control's kinematics places the head's
        pivot, U22); a control whose TCP is its configuration only where compgen ran the
        configuration's kinematics for it."""
        return self.tcp_switchable

    def corrects(self, machine: Machine, e) -> bool:
        """Whether an edit of this control corrects the constant effect ``e``
        (``model.effects.Effect``) of ``machine``: a rotary axis's offsets always, its tilts
        where the control holds tilts, the linear axes' squareness where it holds it."""
        if machine.axis(e.carrier).rotary:
            return e.unit == "mm" or self.holds_tilts
        return bool(self.squareness_as)

    def label(self, machine: Machine) -> str:
        """The control as its files and messages for ``machine`` name it."""
        return self.words

    def tcp_label(self, machine: Machine) -> str:
        """What carries the nest under TCP on ``machine``, as a program's header says it."""
        return self.tcp_words

    holds_inclined = False    # its kinematics holds an inclined axis as compgen writes it (U24)

    def edits_head(self, machine: Machine) -> bool:
        """Whether compgen writes this control's kinematics edits for ``machine``, whose head
        turns the tool (only where the control's kinematics for it was run: none by default)."""
        return False

    def writes_programs(self, machine: Machine) -> bool:
        """Whether compgen writes this control's programs for ``machine``: every table-table
        machine; a head only where ``programs_for_head`` says so."""
        return not machine.heads or self.programs_for_head(machine)

    # how its programs have the PLC turn an axis (the OEM's M-function, U26): "m-function" (the
    # target handed over, the call in the program), "stop" (the operator calls it at a stop and
    # the program stops unless the axis stands there), "" (not written: its kinematics move every
    # axis themselves)
    plc_index = ""

    def plc_words(self, axis) -> str:
        """How this control's programs hand the PLC an axis's target (the header's words)."""
        return ("at a stop the operator calls it, and the program stops unless the axis stands there "
                "(no source says how this control passes the target)")

    def writes_probing(self, machine: Machine) -> bool:
        """Whether compgen writes this control's probing programs for ``machine``: every
        table-table machine; a head is probed under TCP, switched on in the program."""
        return not machine.heads or self.tcp_switchable

    def check_setup(self, machine: Machine) -> None:
        """Refuse a [program] set-up this control cannot run (e.g. a tool it cannot call)."""

    def tool_word(self, tool: str) -> str:
        """A tool as this control's tool call names it."""
        return tool

    def check_tool(self, tool: str, key: str, source: str) -> None:
        """Refuse a tool this control's tool call cannot name (``key``: the machine file's, e.g.
        "[probe] tool", in the file ``source``)."""

    def log_files(self, head: list[str], paths, rotary: list[str], ball: str) -> dict[str, str]:
        """Files (suffix → text) a probing program needs to write its log on this control, beside
        its message files: the log's ``head`` lines, a line per touch of each of ``paths``."""
        return {}

    def message_files(self, name: str, messages: list[str]) -> dict[str, str]:
        """Files (suffix → text) a program ``name`` needs to show ``messages`` to the operator."""
        return {}

    def state(self, path: str, text: str) -> str | None:
        """The control's state from the file ``path`` (its ``text``) when the file is this
        control's configuration to be resolved (LinuxCNC's INI), else None: the file is the
        state as it is."""
        return None

    def main_suffix(self, current: str | None) -> str:
        """Suffix of the file ``-o`` names; the others go beside it with the same stem."""
        raise NotImplementedError

    def edit(self, machine: Machine, p: Plan, current: str | None, where: str,
             ctx: EditContext) -> EditFiles:
        """The edit's files. ``current`` is the control's state as a text (or None)."""
        raise NotImplementedError

    # What its edit loads, declared: compare, report and simulate --edit predict from these
    holds_tilts = True        # its axis lines tilt (else: their positions only)
    squareness_as = "rows"    # "rows" of its kinematics, "tables" (compensation), or "" (none)
    tables_by_hand = False    # its tables' values are entered by hand (no file compgen writes loads)
    takes_current = True      # its edit reads the control's state as --current (a file it holds)
    needs_current = False     # and cannot write an edit without it

    def tables(self, machine: Machine, p: Plan) -> list[CompTable]:
        """The compensation tables its edit loads, as the control applies them (none of a
        head's own error motions yet: they stay not compensated)."""
        heads = {a.name for a in machine.heads}
        return [t for t in comp_tables(machine, p) + (squareness_tables(machine, p)
                                                       if self.squareness_as == "tables" else [])
                if t.input not in heads and t.output not in heads]

    def holds(self, machine: Machine, p: Plan) -> Held:
        """What the control holds once compgen's edit of ``p`` is loaded: the one function
        every prediction of every control goes through."""
        lines = p.lines if self.holds_tilts else {
            n: replace(line, tilt=np.zeros(3)) for n, line in p.lines.items()}
        return Held(lines, dict(p.squareness) if self.squareness_as == "rows" else {},
                    tuple(self.tables(machine, p)))

    def not_held(self, machine: Machine, p: Plan) -> list[str]:
        """What of ``p`` stays in the machine after the edit, in words."""
        tilts = [] if self.holds_tilts else [f"{n} tilt" for n, line in p.lines.items() if line.tilt.any()]
        return [*tilts, *([] if self.squareness_as else p.squareness), *self.not_tabled(machine, p),
                *p.not_compensable]

    def not_tabled(self, machine: Machine, p: Plan) -> list[str]:
        """The effects of ``p`` a table would hold that its edit writes no table for (a
        head's own error motions): they stay in the machine, and its edit says so."""
        in_tables = {t.effect for t in self.tables(machine, p)}
        return [e for e in p.tables if e not in in_tables]

    def loaded_tables(self, machine: Machine, state: str, where: str) -> list[CompTable]:
        """The compensation tables the control holds in ``state``, each named (``effect``) by
        its place in the control, which an edit's table for the same axes takes over."""
        return []

    def since(self, machine: Machine, measured: str, current: str, where: str) -> Held:
        """What the control holds now (``current``) beyond the state the data were measured
        in (``measured``): lines and squareness, relative."""
        raise NotImplementedError

    def beyond_nominal(self, machine: Machine, current: str, where: str) -> Held:
        """What the control holds now (``current``) beyond the machine file's geometry: lines
        and squareness, relative. Data measured without TCP (a probing program) measured the
        machine against the machine file, so their edit sets the control to that geometry
        plus the fit: this is taken off it."""
        raise CompgenError(f"compgen does not read what the {self.words} holds beyond the machine file's "
                           "geometry", hint="give data measured under TCP, or no --current")

    def reads(self, text: str) -> bool:
        """Whether ``text`` is one of the edit files this controller writes."""
        return False

    def read(self, machine: Machine, text: str, current: str | None, held: Held, where: str) -> Held:
        """``held`` with the edit file ``text`` loaded, as the control reads it."""
        raise NotImplementedError
