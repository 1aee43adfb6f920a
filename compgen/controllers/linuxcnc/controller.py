"""The LinuxCNC controller: its programs, its kinematics edit of a configuration, and its
reader of the configuration's state."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from ... import me
from ...errors import CompgenError
from ...model.machine import Machine
from ...motion.blocks import Block
from .. import render
from ..base import Controller, EditContext, EditFiles
from ..correction import (
    CompTable,
    Held,
    Plan,
    nominal_lines,
)
from ..state_guards import require_guard
from .config import Configuration, bundle, configuration_files, is_bundle
from .files import Setting
from .heads import head_correction, head_lines, head_module, module_pins, pin_tolerance, trt_module
from .pins import PIN_SINCE, SETP, SETS, XYZBC_PIN0, configuration, pins, read_lines
from .reader import HAL_NAME, HEAD_PROGRAM, head_guard, offsets_guard, program_blocks
from .tables import (
    COMP_NOTE,
    _joint_tables,
    comp_files,
    joint_number,
    joint_tables,
    loaded_joint_tables,
    read_comp,
)


class LinuxCNC(Controller):
    """LinuxCNC: G-code programs (.ngc) under the trt kinematics (or a head's module), the edit
    as the module's HAL pins and joint compensation tables, written as LinuxCNC's start
    script reads its configuration."""

    name = "linuxcnc"
    family = "linuxcnc"
    words = "LinuxCNC (trt kinematics)"
    program_ext = ".ngc"
    name_max = 200            # LinuxCNC runs a program by its path: the file system's name, with room
    comment = "#"
    tcp_words = "trt kinematics"
    backup = "a copy of the configuration's folder (its INI, HAL files and joint tables)"
    pose_line = re.compile(r"^G1 X(\S+) Y(\S+) Z(\S+) ((?:[A-C]\S+ )+)F\S+ ; pose (\d+)")
    tcpm_on = re.compile(r"^; mode TCPM", re.MULTILINE)
    tcp_switchable = False
    section = "linuxcnc"
    load_note = ("start LinuxCNC with KIN.ini, the configuration compgen wrote from the INI given as "
                 "--current (the values changed where the configuration sets them)")
    holds_tilts = False           # trt kinematics: pivot positions only
    squareness_as = ""

    def tables(self, machine: Machine, p: Plan) -> list[CompTable]:
        return joint_tables(machine, p)

    def main_suffix(self, current: str | None) -> str:
        return ".ini" if is_bundle(current) else ".hal"

    def read_section(self, get, machine: Machine) -> dict:
        """[linuxcnc]: ``conventional_directions``, the trt module's pin of that name. With it
        true, its kinematics turn A (or B) and C the other way (``trtfuncs.c``: every term
        with a single sine of an angle is multiplied by ``con`` = +1, else −1; the pin exists
        from LinuxCNC 2.10, commit bfb687eaa6, and is false by default)."""
        get.only({"conventional_directions", "version"})
        conventional = get.flag("conventional_directions", "the trt module's conventional-directions pin")
        version = None
        if "version" in get.doc:
            text = get.doc["version"]
            m = re.fullmatch(r"(\d+)\.(\d+)(?:\.\d+)?", text) if isinstance(text, str) else None
            if m is None:
                raise CompgenError(f"must be LinuxCNC's version as text, e.g. \"2.9\", got {text!r}",
                                   where=get.at("version"),
                                   hint="linuxcnc_info, or the splash screen, shows it")
            version = (int(m[1]), int(m[2]))
        if conventional and version is not None and version < PIN_SINCE:
            raise CompgenError(f"LinuxCNC {get.doc['version']} has no conventional-directions pin (it came "
                               "with 2.10): its kinematics modules, trt or head, turn the axes the "
                               "unconventional way",
                               where=get.at("conventional_directions"), hint="set it false")
        try:
            module = trt_module(machine)[0]
        except CompgenError:
            module = ""
        if module == "xyzbc-trt-kins" and not conventional:
            if version is None:
                raise CompgenError("which LinuxCNC runs xyzbc-trt-kins with conventional-directions 0 "
                                   "decides whether its inverse kinematics inverts its forward kinematics",
                                   where=get.at("version"),
                                   hint='add version = "2.9" (or the one the machine runs)')
            if version >= PIN_SINCE:
                raise CompgenError(XYZBC_PIN0, where=get.at("conventional_directions"),
                                   hint="set the module's conventional-directions pin to 1 in the "
                                        "configuration and conventional_directions = true here")
        return {"conventional_directions": conventional, "version": version}

    def angle_sense(self, machine: Machine) -> dict[str, int]:
        if (head := head_module(machine)) is not None:     # as the module turns them
            return dict(head[0].sense)
        flip = -1 if (machine.linuxcnc or {}).get("conventional_directions") else 1
        return {a.name: flip for a in machine.rotary_axes}

    def programs_for_head(self, machine: Machine) -> bool:
        return head_module(machine) is not None

    def program_context(self, machine: Machine) -> dict:
        head = head_module(machine)
        mirrored = head and [a for a, v in head[0].sense if v == -1]
        return {"offsets_guard": offsets_guard(),
                "head": head and {"module": head[0].module, "what": head[0].what, "active": head[0].active,
                                  "pivot": f"{head[1]:.4f}", "within": f"{pin_tolerance(machine):.4f}",
                                  "mirrored": " and ".join(mirrored)
                                  + (" are" if len(mirrored) > 1 else " is"),
                                  "them": "them" if len(mirrored) > 1 else "it",
                                  "guard": head_guard(head[0].module), "notes": head[0].notes}}

    def check(self, machine: Machine, blocks: list[Block], probe=None):
        """The motion check, where a head module's program checks the module's pin: compgen
        models the machine with the machine file's pivot, so the guard must stop the
        program unless the pin holds that (else the check would be of another machine)."""
        head = head_module(machine)
        pins = [b for b in blocks if b.kind == "pin"]
        want = head and {f"{head[0].module}.pivot-length": (float(f"{head[1]:.4f}"), pin_tolerance(machine))}
        if head and (not pins or any(b.target != want for b in pins)):
            got = "; ".join(f"line {b.line}: {b.text.strip()}" for b in pins) or "no pin guard"
            raise CompgenError(f"a program for this machine must stop unless {head[0].module}.pivot-length "
                               f"holds {head[1]:.4f} mm, the machine file's pivot to the nest, to "
                               f"{pin_tolerance(machine):.4f} mm ({got})",
                               hint=f"write it again with {me()} measure-program for this machine file")
        if pins and not head:
            raise CompgenError(f"line {pins[0].line}: the program was written for a head on "
                               f"{next(iter(pins[0].target)).split('.')[0]}, which this machine file is not",
                               hint="check it against the machine file it was written for")
        require_guard(blocks, "LinuxCNC", "stop unless G54's and G92's offsets are zero (LinuxCNC applies "
                      "them before its kinematics: an offset left set moves every pose)")
        if head:
            switch = " and motion.switchkins-type is 0" if head[0].module == "5axiskins" else ""
            require_guard(blocks, "LinuxCNC", f"stop unless W is at 0 ({head[0].module} lengthens the pivot "
                          f"by W){switch}",
                          before=("move",), kind="head state", name=head[0].module)
        return super().check(machine, blocks, probe)

    def blocks(self, text: str, mode: str | None = None) -> list[Block]:
        written = ("tcpm" if self.tcpm_on.search(text) else
                   "axes" if re.search(r"(?m)^; mode AXES", text) else None)
        # the kinematics are the configuration's: the program's header (compgen's) says which it
        # was written for, and that is what it is checked under; --mode says it where the header
        # does not, or must agree with it
        mode = mode or written
        if mode is None:
            raise CompgenError("a LinuxCNC program's kinematics are the configuration's, and this program's "
                               "header does not say which it was written for",
                               hint="give --mode tcpm (its kinematics module active: trt, maxkins or "
                                    "5axiskins) or --mode axes (identity kinematics)")
        written = written or mode
        if mode != written:
            raise CompgenError(f"the program was written for mode {written.upper()} (its header) and is to "
                               f"run under {mode.upper()}: its positions mean other things there",
                               hint=f"write it again for mode {mode.upper()}: measure-program with --mode "
                                    f"{mode}, and the machine file and path (or --poses) it was written with")
        head = HEAD_PROGRAM.search(text)
        return program_blocks(text, mode == "tcpm", head and head[1])

    def edits_head(self, machine: Machine) -> bool:
        return head_module(machine) is not None

    def label(self, machine: Machine) -> str:
        head = head_module(machine)
        return self.words if head is None else f"LinuxCNC ({head[0].module})"

    def tcp_label(self, machine: Machine) -> str:
        head = head_module(machine)
        return self.tcp_words if head is None else f"{head[0].module} kinematics"

    def corrects(self, machine: Machine, e) -> bool:
        if head_module(machine) is None:
            return super().corrects(machine, e)
        # the one pin: a head's line offset along the tool axis at the pivot (ZOB)
        return e.carrier in {a.name for a in machine.heads} and e.direction == "z"

    def holds(self, machine: Machine, p: Plan) -> Held:
        if head_module(machine) is None:
            return super().holds(machine, p)
        return Held(head_lines(machine, head_correction(machine, p)[0]), {}, ())

    def not_held(self, machine: Machine, p: Plan) -> list[str]:
        if head_module(machine) is None:
            return super().not_held(machine, p)
        return head_correction(machine, p)[1]

    def edit(self, machine: Machine, p: Plan, current: str | None, where: str,
             ctx: EditContext) -> EditFiles:
        if not HAL_NAME.fullmatch(ctx.stem):
            # the name goes into HALFILE values, source lines and the INI: halcmd takes "#" for a
            # comment, "$" and "[" for references; the start script splits a HALFILE at a space
            raise CompgenError(f"-o {ctx.stem!r}: LinuxCNC's start script and halcmd cannot carry this "
                               "name (a space, '#', '$', '[' or another character they read)",
                               hint="give -o a name of letters, digits, '.', '_', '+' and '-', e.g. KIN.ini")
        state = configuration(current, where)       # the configuration, evaluated once
        module, rows, other, settings = pins(machine, p, state, where)
        cfg = state if is_bundle(current) else None
        loaded = _joint_tables(machine, cfg) if cfg is not None else {}
        comps = comp_files(machine, p, ctx, loaded)
        ini_lines = [ini for ini, _ in comps.values()]
        sign = [f"sign check {ctx.name}_SIGN{self.program_ext}, expected change of the reading:", *ctx.expect]
        notes = [f"{cmd} {target} {v}  (was {w})" for cmd, target, v, w in rows]
        head = head_module(machine)
        what = head and head[0].what
        if other:
            notes.append(f"not expressible in LinuxCNC's {module}" + (" (its one pin, pivot-length)"
                                                                      if head else " and joint tables")
                         + ": " + ", ".join(other))
        tool = f"{module}.tool-offset"
        if head is None and state is not None and tool not in state.net:
            notes.append(f"{tool} is not netted: net it to motion.tooloffset.z, or the table turns about the "
                         "spindle nose instead of the nest (G43 lengths)")
        if cfg is not None:
            return self._configuration_edit(machine, cfg, ctx, rows, settings, comps, loaded,
                                            [*ctx.header, *ctx.lines, *sign], notes)
        text = render("linuxcnc/kinematics.hal.j2", header=ctx.header, module=module, head=what,
                      lines=ctx.lines, rows=rows, other=other, ini=ini_lines, sign=sign, restore=False)
        notes.append(f"load it: put these values where the configuration sets the pins. A HALFILE added "
                     "after the others is overwritten by the INI's HALCMD lines and POSTGUI_HALFILE where "
                     f"they set a pin (as LinuxCNC's own trt samples do): give the INI as --current and "
                     f"{ctx.stem}.ini is the configuration to start with")
        if ini_lines:
            notes += ["joint compensation tables: in the INI, set (replacing any COMP_FILE or BACKLASH of "
                      "these joints)", *(f"  {line}" for line in ini_lines),
                      "--current is not the INI, so the joints' loaded tables are unknown: these hold this "
                      "round's correction alone (give the INI to add to them)"]
        restore_ini = [f"[JOINT_{joint_number(machine, a)}] no COMP_FILE (remove the line the edit set)"
                       for a in sorted({t.input for t in joint_tables(machine, p)})]
        restore = render("linuxcnc/kinematics.hal.j2", module=module, head=what, lines=[], other=[],
                         ini=restore_ini,
                         rows=[(cmd, target, w, w) for cmd, target, _, w in rows], restore=True, sign=[],
                         header=[f"compgen {ctx.version}: restores the {module if head else 'trt'} pins as "
                                 "they were read", *ctx.header[1:3], f"load it in place of {ctx.stem}.hal"])
        return EditFiles({".hal": text, "_RESTORE.hal": restore,
                          **{k: body for k, (_, body) in comps.items()}}, tuple(notes))

    def _configuration_edit(self, machine: Machine, cfg: Configuration, ctx: EditContext,
                            rows, settings: dict[str, Setting], comps, loaded, header: list[str],
                            notes: list[str]) -> EditFiles:
        """The configuration to start with: the INI (and each file that sets a changed pin)
        written anew beside it, the joints' tables named in it; its restore, the INI as it was."""
        if ctx.folder and Path(ctx.folder).resolve() != cfg.folder.resolve():
            raise CompgenError("the configuration to start with names its files as the INI does, relative to "
                               f"{cfg.folder}: write it there", where=ctx.folder,
                               hint=f"give -o {cfg.folder / (ctx.stem + '.ini')}")
        module = module_pins(machine)[0]
        values = {f"{module}.{n}": v for (_, _, v, w), n in zip(rows, settings, strict=True)
                  if float(v) != float(w)}
        joints = {joint_number(machine, suffix.split(".")[1]): f"{ctx.stem}{suffix}" for suffix in comps}
        files = configuration_files(cfg, values, joints, ctx.stem, header)
        for suffix, (_, body) in comps.items():
            files[suffix] = body
        start = f"{ctx.stem}.ini"
        files["_RESTORE.ini"] = "\n".join([f"# compgen {ctx.version}: the configuration as it was before "
                                           f"{start}; start LinuxCNC with this file to undo the edit",
                                           cfg.texts[cfg.ini_path].rstrip("\n")]) + "\n"
        changed = sorted(f"{s.place} ({s.text} -> {values[pin]})" for n, s in settings.items()
                         if (pin := f"{module}.{n}") in values)
        notes.append(f"start LinuxCNC with {cfg.folder / start}: the INI's own lines, the values changed "
                     "where the configuration sets them (" + "; ".join(changed) + ")"
                     + ("; " + ", ".join(f"{ctx.stem}{k}" for k in files if k not in (".ini", "_RESTORE.ini")
                                          and not k.endswith(".comp")) + " written anew beside it"
                        if len([k for k in files if not k.endswith(".comp")]) > 2 else ""))
        if comps:
            notes.append("joint compensation tables " + ", ".join(f"{ctx.stem}{k}" for k in comps) + ": "
                         + (f"the tables the INI loads plus this round's ({', '.join(sorted(loaded))} held "
                            "one)" if loaded else "no joint had a table in the INI: they hold this round's "
                                                  "correction"))
        notes.append(f"to undo: start LinuxCNC with {ctx.stem}_RESTORE.ini (the INI as it was); the next "
                     f"round's --current is {start}, so the next edit adds to this one")
        return EditFiles(files, tuple(notes))

    def loaded_tables(self, machine: Machine, state: str, where: str) -> list[CompTable]:
        return [replace(fwd, values=tuple((np.add(fwd.values, rev.values) / 2).tolist()))
                for fwd, rev in loaded_joint_tables(machine, state).values()]

    def since(self, machine: Machine, measured: str, current: str, where: str) -> Held:
        return Held(read_lines(current, machine, measured, nominal_lines(machine)), {})

    def beyond_nominal(self, machine: Machine, current: str, where: str) -> Held:
        return Held(read_lines(current, machine, None, nominal_lines(machine)), {})

    def state(self, path: str, text: str) -> str | None:
        # an INI (inivar finds a section by the start of its line; its [HAL] may come from an
        # #INCLUDE): LinuxCNC's whole configuration. No HAL file (nor another control's
        # table, whose last line is [END]) has a [HAL] or an #INCLUDE line
        ini = re.search(r"(?m)^[ \t]*\[HAL\]|^#INCLUDE[ \t]", text)
        return bundle(path, text) if ini else None

    def reads(self, text: str) -> bool:
        return (is_bundle(text) or SETP.search(text) is not None or COMP_NOTE.search(text) is not None
                or (SETS.search(text) is not None and "kinematics edit" in text))

    def check_tool(self, tool: str, key: str, source: str) -> None:
        if not re.fullmatch(r"\d{1,5}", tool):
            raise CompgenError(f"LinuxCNC calls tools by number; {key} is {tool!r}", where=f"{source}: {key}",
                               hint='e.g. tool = "99"')

    def check_setup(self, machine: Machine) -> None:
        if machine.linuxcnc is None:
            raise CompgenError("whether the trt kinematics turn the rotary axes the conventional way is not "
                               "in the machine file: the same program turns them the other way if they do",
                               where=f"{machine.source}: [linuxcnc] conventional_directions",
                               hint="set conventional_directions = false (before LinuxCNC 2.10, or the "
                                    "module's conventional-directions pin at its default 0) or true (pin 1)")
        if (head := head_module(machine)) is not None and machine.linuxcnc.get("conventional_directions"):
            raise CompgenError(f"{head[0].module} was run without a conventional-directions pin (Debian's "
                               "2.9 has none); a newer one turns B the other way at 1",
                               where=f"{machine.source}: [linuxcnc] conventional_directions",
                               hint="set it false, with the pin at its default 0")
        self.check_tool(machine.program.tool, "[program] tool", machine.source)

    def read(self, machine: Machine, text: str, current: str | None, held: Held, where: str) -> Held:
        if is_bundle(text):            # a configuration to start with: its pins and its joints' tables
            tables = self.loaded_tables(machine, text, where)
            return Held(read_lines(text, machine, current, held.lines), held.squareness,
                        (*(t for t in held.tables if t.effect not in {tb.effect for tb in tables}), *tables))
        if COMP_NOTE.search(text):     # a joint's table replaces the one it held
            table = read_comp(text, machine, where)
            return Held(held.lines, held.squareness,
                        (*(t for t in held.tables if t.effect != table.effect), table))
        return Held(read_lines(text, machine, current, held.lines), held.squareness, held.tables)
