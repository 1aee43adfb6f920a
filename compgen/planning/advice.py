"""The measurements compgen may advise, and only those the machine can make.

A measurement is a path of the machine file with the ball somewhere (as now, higher, lower,
nearer the table's axis or farther out), run one way or there and back; on a head, also with
a longer nest. Before one is offered it is checked exactly as ``measure-program`` checks the
program it would write: travel (with the clearance and the safe height), rotary steps and
speeds, and the motion check against the set-up with the ball (and nest) where it would
stand. What fails is not offered. Data from a touch probe get probing programs
(``probe-program``: a probe cannot run a path there and back, and probes a path at
``[probe] poses`` of its poses).
"""

from __future__ import annotations

import shlex
from collections import Counter
from dataclasses import dataclass

import numpy as np

from ..controllers.probing import probe_program
from ..controllers.programs import checked_program
from ..controllers.registry import controller
from ..data.probe import need_probe, probe_poses
from ..errors import CompgenError
from ..model.machine import Machine
from ..model.paths import GAP_S, generate
from ..model.poses import Poses, motion_direction, runs

# Where the ball may go for a further measurement: (label, file-name tag, ball scale in
# x, y; dz mm; there and back). A tilt of an axis scales with radius and height, an offset
# or an axial error motion does not; a reversal shows only where an axis turns back.
PLACES = (
    ("", "", 1.0, 0.0, False),
    (" there and back", "BACK", 1.0, 0.0, True),
    (" with the ball 100 mm higher", "UP100", 1.0, 100.0, False),
    (" with the ball 100 mm lower", "DOWN100", 1.0, -100.0, False),
    (" with the ball at half its radius", "HALFR", 0.5, 0.0, False),
    (" with the ball 50 mm higher", "UP50", 1.0, 50.0, False),
    (" with the ball 50 mm lower", "DOWN50", 1.0, -50.0, False),
    (" with the ball at 1.5 times its radius", "R150", 1.5, 0.0, False),
)
# A head's nest may also go on a longer holder: its angles at the pivot turn the nest by the
# nest's length, a translation of the head (its sag) does not, so a second length tells them
# apart where no ball position can. (label, file-name tag, mm longer)
NESTS = ((" with the nest 100 mm longer", "NEST100", 100.0),)
MODE = "tcpm"      # measure-program's default: the command printed does not name a mode


AGAIN = " again, right after these data"     # a repeat's label, after its run's


@dataclass(frozen=True, eq=False)
class Proposal:
    """A measurement that could be added: a path of the machine file with the ball at
    ``ball`` (mm, table frame, as a CSV's bx, by, bz), run there and back or not, and its
    poses. ``name`` is the file stem its program and data are advised under."""

    label: str
    path: str
    ball: tuple[float, float, float]
    poses: Poses
    back: bool = False
    name: str = ""
    device: str = "rtest"        # "probe": made with a touch probe (probe-program)
    again: bool = False          # a repeat of what was measured, right after it: for time
    nest: float | None = None    # mm below the gauge line, where not the machine file's
    machine_ref: str = ""        # how its command names the machine file: a bundled machine by name
    program_ext: str = ""        # the suffix of its program: the machine's control's
    spindle: float | None = None  # deg the probe is turned to in the spindle (probe-program --spindle-deg)

    @property
    def run_label(self) -> str:
        """The label of the run it makes (a repeat's without "again, right after these data")."""
        return self.label.removesuffix(AGAIN)

    def to_dict(self) -> dict:
        return {"label": self.label, "path": self.path, "ball": [round(v, 4) for v in self.ball],
                "there_and_back": self.back, "name": self.name, "right_after": self.again,
                **({"probe_length_mm": self.nest} if self.nest is not None else {}),
                **({"spindle_deg": self.spindle} if self.spindle is not None else {})}

    def options(self) -> str:
        """The options of ``measure-program`` that write it."""
        ball = ",".join(f"{v:.4f}".rstrip("0").rstrip(".") for v in self.ball)   # as to_dict's
        return (f"--path {self.path} --ball {ball}" + " --there-and-back" * self.back
                + (f" --probe-length {self.nest:g}" if self.nest is not None else "")
                + (f" --spindle-deg {self.spindle:g}" if self.spindle is not None else ""))

    def command(self, me: str) -> str:
        """The whole ``measure-program`` (or ``probe-program``) command, as it runs pasted
        into bash."""
        verb = "probe-program" if self.device == "probe" else "measure-program"
        return (f"{me} {verb} --machine {shlex.quote(self.machine_ref)} {self.options()} "
                f"-o {self.name}{self.program_ext}")


class Advisor:
    """The measurements of one machine not yet made in ``measured``, each checked at most
    once (a check writes the whole program in memory and moves the machine through it)."""

    def __init__(self, machine: Machine, measured: Poses | None = None, device: str = "rtest",
                 run: np.ndarray | None = None):
        self.machine = machine
        # why nothing can be advised on this machine (its programs are not written), if so
        self.unable = ("" if controller(machine.controller).writes_programs(machine) else
                       "compgen does not write measuring programs for a head yet on this control, so it "
                       "advises no measurement")
        self.candidates = [] if self.unable else proposals(machine, measured, device, run)
        self._why: dict[str, str | None] = {}

    def why_not(self, m: Proposal) -> str | None:
        """Why ``measure-program`` would refuse ``m`` on this machine, or None."""
        if m.label not in self._why:
            self._why[m.label] = _refusal(self.machine, m)
        return self._why[m.label]

    def turned(self, path: str, ball: tuple[float, float, float], before: int, degrees: float
               ) -> Proposal | None:
        """``path`` again with the ball at ``ball`` (it stays there), turned ``degrees`` on its
        stem: its own file, K4_TURNED, then K4_TURNED_2 (the data holding one turned already)."""
        return self._again(f"{path} with the ball turned {degrees:g}° on its stem", path, ball,
                           f"{path}_TURNED", before, generate)

    def spindle_turned(self, path: str, ball: tuple[float, float, float], before: int, degrees: float
                       ) -> Proposal | None:
        """``path`` probed again with the sphere at ``ball`` and the probe turned ``degrees`` in the
        spindle: its own file, K4_SPINDLE, then K4_SPINDLE_2."""
        return self._again(f"{path} with the probe turned {degrees:g}° in the spindle", path, ball,
                           f"{path}_SPINDLE", before, probe_poses, device="probe", spindle=degrees)

    def _again(self, label: str, path: str, ball, stem: str, before: int, planned, **more) -> Proposal | None:
        """``path`` measured again with the ball at ``ball`` (``planned``: how its poses are
        made, ``generate`` or ``probe_poses``), under ``stem`` and, after ``before`` such
        runs, ``stem_2``…; None where the machine cannot run it."""
        try:
            poses = planned(self.machine, [path], ball=np.asarray(ball, float))
        except CompgenError:
            return None
        m = Proposal(label, path, tuple(float(v) for v in ball), poses,
                     name=stem + (f"_{before + 1}" if before else ""),
                     machine_ref=self.machine.bundled or self.machine.source,
                     program_ext=controller(self.machine.controller).program_ext, **more)
        return m if self.why_not(m) is None else None

    def runnable(self, ms, most: int | None = None) -> tuple[Proposal, ...]:
        """Those of ``ms`` the machine can make, in their order; at most ``most``."""
        out = []
        for m in ms:
            if most is not None and len(out) >= most:
                break
            if self.why_not(m) is None:
                out.append(m)
        return tuple(out)


def _refusal(machine: Machine, m: Proposal) -> str | None:
    try:
        if m.device == "probe":
            probe_program(machine, m.poses, m.path, machine.controller, "ADVICE", "", "", m.spindle)
        else:
            checked_program(machine, m.poses, m.path, machine.controller, MODE, "ADVICE", "", "")
    except CompgenError as exc:
        return str(exc)
    return None


def proposals(machine: Machine, measured: Poses | None, device: str = "rtest",
              run: np.ndarray | None = None) -> list[Proposal]:
    """Every place for every path, less what would leave the travel and what ``measured``
    holds already (same path, same ball; there and back where the axes turned back).
    ``run``: the runs of ``measured`` as ``poses.runs`` numbers them with each pose's file,
    where known (a repeat in a file of its own continues the last one's path and clock).

    Where ``measured`` gives the time of its readings, each measurement is made after them
    (its clock running on, as the R-test's does when the next program follows), and what
    was measured already is offered again as a repeat: a drift is told by time, never by
    another ball position (a τ of 5 and of 45 min differ only in when the readings were
    made)."""
    ball = np.asarray(machine.ball, dtype=float)
    done, turned, runs_of = set(), set(), Counter()
    timed = measured is not None and len(measured) > 0 and not np.isnan(measured.t).any()
    start = float(measured.t.max()) + GAP_S if timed else 0.0
    if measured is not None:
        # path and ball hold within a run: one look per run, not per pose
        run = runs(measured) if run is None else run
        first = np.flatnonzero(np.r_[True, run[1:] != run[:-1]])
        nest = np.where(np.isnan(measured.nest), machine.probe_length, measured.nest)
        where_ = [(str(measured.path[i]), tuple(np.round(measured.ball[i], 3)), round(float(nest[i]), 3))
                  for i in first]
        done, runs_of = set(where_), Counter(where_)
        for a in machine.rotary_axes:
            d = motion_direction(measured.q[:, machine.index(a.name)], run)
            back = np.add.reduceat(d > 0, first) & np.add.reduceat(d < 0, first)     # both ways in a run
            turned |= {w for w, both in zip(where_, back, strict=True) if both}
    # the tool point a look is made with: a probe's stylus tip on a head (its lever), else the nest
    point = need_probe(machine).length if device == "probe" and machine.heads else machine.probe_length
    places = [(where, tag, scale, dz, back, None) for where, tag, scale, dz, back in PLACES]
    if machine.heads and device == "rtest":
        places += [(where, tag, 1.0, 0.0, False, machine.probe_length + more) for where, tag, more in NESTS]
    out = []
    for where, tag, scale, dz, back, nest in places:
        if back and device == "probe":
            continue
        at = ball * [scale, scale, 1.0] + [0.0, 0.0, dz]
        for name in machine.paths:
            key = (name, tuple(np.round(at, 3)), round(nest or point, 3))
            again = key in (turned if back else done)
            if again and (back or not timed):     # a repeat: the path as it ran, in time
                continue
            try:
                poses = (probe_poses(machine, [name], at) if device == "probe" else
                         generate(machine, [name], ball=at, back=back, nest=nest))
            except CompgenError:
                continue
            poses = poses.starting_at(start)
            label, stem = f"{name}{where}", f"{name}_{tag}" if tag else name
            if again:
                # each repeat its own file: the first K2_AGAIN, then K2_AGAIN_2 (the data holding
                # K2 twice), so that no advised program or reading overwrites one already fitted
                n = runs_of[key]
                label, stem = f"{label}{AGAIN}", f"{stem}_AGAIN" + (f"_{n}" if n > 1 else "")
            out.append(Proposal(label, name, tuple(float(v) for v in at), poses, back, stem, device,
                                   again, nest, machine.bundled or machine.source,
                                   controller(machine.controller).program_ext))
    return out
