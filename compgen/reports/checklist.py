"""The commissioning checklist, ticked from the artefacts found in a work folder.

A step is ``done`` only when a file proves it (recognised by content, not by name), ``open``
when none does yet, and ``by hand`` when no file can prove it (warm-up, sensor check, loading
the edit, signing off): compgen never ticks those for the engineer. Its steps are the
device's: an R-test's, or a touch probe's on a calibration sphere (the folder's probing
programs, probe logs or a fit of probe data say which, or ``device``).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from shlex import quote

from .. import me
from ..controllers.registry import comment_marks, controller
from ..data.probe import MAGIC as PROBE_LOG
from ..errors import CompgenError
from ..model.machine import Machine

DONE, OPEN, BY_HAND = "done", "open", "by hand"
MAX_READ = 5_000_000   # bytes: larger files are not R-test artefacts


@dataclass(frozen=True)
class Step:
    """One step of the commissioning checklist: its title, its status (done, open, by hand),
    the files that show it (``evidence``), the command that does it and a note."""

    title: str
    status: str
    evidence: tuple[str, ...] = ()
    command: str = ""
    note: str = ""


# a head's steps that compgen does not write for yet: no command is printed that would refuse
HEAD_PROGRAMS = ("compgen does not write programs for a head yet: write one for the machine file's "
                 "paths (under TCPM, the nest on the ball)")
HEAD_PROBING = ("compgen probes a head under TCP switched on in the program (HEIDENHAIN, SINUMERIK), not on "
                "this control: measure it with an R-test, or write the probing program by hand")
HEAD_EDIT = ("compgen does not write edits for a head yet: enter the fitted location errors in the "
             "control's kinematics by hand, and keep its backup")


@dataclass
class _Found:
    programs: list[Path] = field(default_factory=list)
    data: list[Path] = field(default_factory=list)
    fits: list[tuple[Path, dict]] = field(default_factory=list)
    diagnoses: list[Path] = field(default_factory=list)
    edits: list[Path] = field(default_factory=list)
    signchecks: list[Path] = field(default_factory=list)
    compares: list[tuple[Path, dict]] = field(default_factory=list)
    probe_programs: list[Path] = field(default_factory=list)
    probe_logs: list[Path] = field(default_factory=list)


def _scan(folder: Path) -> _Found:
    found = _Found()
    marks = re.escape(comment_marks())
    for path in sorted(p for p in folder.rglob("*") if p.is_file() and p.stat().st_size < MAX_READ):
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue
        head = text[:2000]
        if re.search(rf"(?m)^(?:\d+ )?[{marks}] compgen \S+ R-test measurement program", head):
            (found.signchecks if "path sign check" in head else found.programs).append(path)
        elif re.search(rf"(?m)^(?:\d+ )?[{marks}] compgen \S+ probing program", head):
            found.probe_programs.append(path)
        elif path.suffix.lower() == ".csv" and head.startswith(PROBE_LOG):
            found.probe_logs.append(path)
        elif re.search(rf"(?m)^[{marks}] compgen \S+ kinematics edit", head):
            found.edits.append(path)
        elif path.suffix.lower() == ".csv" and _is_rtest(head):
            found.data.append(path)
        elif path.suffix.lower() == ".json":
            try:
                doc = json.loads(text)
            except (json.JSONDecodeError, RecursionError):   # a stray file is not compgen's
                continue
            kind = doc.get("format") if isinstance(doc, dict) else None
            if kind == "compgen.fit/1":
                found.fits.append((path, doc))
            elif kind == "compgen.diagnose/1":
                found.diagnoses.append(path)
            elif kind == "compgen.compare/1":
                found.compares.append((path, doc))
    return found


def _is_rtest(head: str) -> bool:
    header = next((ln for ln in head.splitlines() if ln.strip() and not ln.startswith("#")), "")
    return {"dX", "dY", "dZ"} <= {c.strip() for c in header.split(",")}


def device_of(f: _Found, fit: dict | None) -> str:
    """The device the folder's work is done with: the newest fit's data's, else a probe's
    where only probing programs or logs are there, else the R-test's."""
    devices = {d.get("device", "rtest") for d in (fit or {}).get("data", []) if isinstance(d, dict)}
    if devices:
        return "probe" if devices == {"probe"} else "rtest"
    return "probe" if (f.probe_programs or f.probe_logs) and not (f.programs or f.data) else "rtest"


def checklist(machine: Machine, folder: str | Path, comparison: dict | None = None,
              device: str | None = None) -> list[Step]:
    """The steps, ticked from the files in ``folder`` (and from ``comparison``, a compare
    result's dict, when the caller has just made one); every command it suggests writes
    into ``folder``. ``device``: "rtest" or "probe" (default: what the folder shows)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise CompgenError("no such folder", where=str(folder), hint="give the work folder with --dir")
    f = _scan(folder)
    newest = max(f.fits, key=lambda x: x[0].stat().st_mtime, default=None)
    if (device or device_of(f, newest and newest[1])) == "probe":
        return _probe_steps(machine, folder, f, newest)
    m = quote(machine.source)
    fit = max(f.fits, key=lambda x: x[0].stat().st_mtime, default=None)
    fit_path = quote(str(fit[0])) if fit else quote(str(folder / "fit.json"))

    def out(name: str) -> str:
        return quote(str(folder / name))
    edit_time = max((p.stat().st_mtime for p in f.edits), default=None)
    post = [p for p in f.data if edit_time is not None and p.stat().st_mtime > edit_time]
    fitted = [(p.parent / d["file"]).resolve() for p, doc in f.fits for d in doc.get("data", [])
              if isinstance(d, dict) and isinstance(d.get("file"), str) and (p.parent / d["file"]).is_file()]
    post = [p.resolve() for p in post]
    pre = list(dict.fromkeys([p.resolve() for p in f.data if p.resolve() not in post]
                             + [p for p in fitted if p not in post]))
    # the newest comparison decides the sign-off, as the newest fit is the one ticked
    measured = [doc for _, doc in sorted(f.compares, key=lambda x: x[0].stat().st_mtime)
                if "measured_post" in doc]
    if comparison and "measured_post" in comparison:
        measured.append(comparison)
    passed = measured and measured[-1]["measured_post"].get("as_predicted") and all(
        v.startswith("PASS") for v in measured[-1]["measured_post"].get("verdicts", {}).values())
    steps = [
        Step("Warm-up: spindle and axes at working temperature", BY_HAND,
             note="thermal drift over a K4 run can reach several µm"),
        Step("R-test set-up: ball on the table, nest in the spindle, sensors checked", BY_HAND,
             note=f"ball where [rtest] says: {machine.ball} mm; nest length gauge line to centre"),
        Step("Measurement programs written", BY_HAND, note=HEAD_PROGRAMS)
        if not controller(machine.controller).writes_programs(machine) else
        Step("Measurement programs written", DONE if f.programs else OPEN, _names(f.programs),
             f"{me()} measure-program --machine {m} --path all -o {out('RTEST' + _ext(machine))}"),
        Step("Preset checked at the program's stop: the ball centred under the nest", BY_HAND,
             note="every program stops once, the nest off the ball along its axis, before it goes onto it"
             if machine.heads else
             "every program stops once, the nest at its clearance above the ball, before it goes down"),
        Step("K4, K1, K2 measured (R-test CSV with dX dY dZ)", DONE if pre else OPEN, _names(pre),
             "run the program; export the readings as CSV v1 beside the pose list"),
        Step("Fit", DONE if fit else OPEN, _names([fit[0]] if fit else []),
             f"{me()} fit --machine {m} {' '.join(map(quote, _names(pre))) or 'DATA.csv'} "
             f"-o {out('fit.json')}"),
        Step("Diagnose: where the model fails", DONE if f.diagnoses else OPEN, _names(f.diagnoses),
             f"{me()} diagnose --from {fit_path} --json > {out('diagnose.json')}"),
        Step("Review confounded effects and fragile parameters", BY_HAND,
             note="diagnose lists what these data cannot see and what would separate it"),
        Step("Kinematics edit emitted (with backup step and sign check)", BY_HAND, note=HEAD_EDIT)
        if machine.heads and not controller(machine.controller).edits_head(machine) else
        Step("Kinematics edit emitted (with backup step and sign check)", DONE if f.edits else OPEN,
             _names(f.edits + f.signchecks),
             f"{me()} kinematics --from {fit_path}"
             + (" --current CURRENT" if controller(machine.controller).takes_current else "")
             + f" -o {out('KIN')}"),
        Step("Backup taken, edit loaded, sign check run with the R-test", BY_HAND,
             note="" if machine.heads and not controller(machine.controller).edits_head(machine) else
             "; ".join(n for n in ("the expected reading changes are in the edit's header",
                                   controller(machine.controller).load_note) if n)),
        Step("Re-measured after the edit", DONE if post else OPEN, _names(post),
             "run the measurement program again; save the CSV after the edit file"),
        Step("Compared: predicted against measured", DONE if measured else OPEN,
             _names([p for p, d in f.compares if "measured_post" in d])
             + (("this report's comparison",) if comparison and "measured_post" in comparison else ()),
             f"{me()} compare --from {fit_path} --post POST.csv --json > {out('compare.json')}"),
        Step("Sign-off", BY_HAND,
             note="ready: improved as predicted, every path within tolerance" if passed else
                  "not ready: no comparison yet, or a path out of tolerance or not as predicted"),
    ]
    return steps


def _probe_steps(machine: Machine, folder: Path, f: _Found, fit: tuple[Path, dict] | None) -> list[Step]:
    """A touch probe's steps: its programs run without the control's kinematics (they measure
    the machine against the machine file), its log is the data, and no compgen program
    checks a loaded edit with a probe yet (the sign check is an R-test's)."""
    ctl = controller(machine.controller)
    m = quote(machine.source)
    fit_path = quote(str(fit[0])) if fit else quote(str(folder / "fit.json"))

    def out(name: str) -> str:
        return quote(str(folder / name))
    writes = ctl.writes_probing(machine)
    return [
        Step("Warm-up: spindle and axes at working temperature", BY_HAND,
             note="thermal drift over a probing run can reach several µm"),
        Step("Probe set-up: calibration sphere on the table, touch probe calibrated (stylus ball, trigger)",
             BY_HAND, note=f"sphere where [rtest] ball says: {machine.ball} mm; [probe] in the machine file "
                           "holds the sphere's and the stylus's diameters"),
        Step("Probing programs written", DONE if f.probe_programs else OPEN, _names(f.probe_programs),
             f"{me()} probe-program --machine {m} --path all -o {out('PROBE' + _ext(machine))}")
        if writes else Step("Probing programs written", BY_HAND, note=HEAD_PROBING),
        Step("Preset checked at the program's stop: the stylus above the sphere's centre", BY_HAND,
             note="every probing program stops once before its first touch"),
        Step("Probed: the program's probe log saved (probe log v1)", DONE if f.probe_logs else OPEN,
             _names(f.probe_logs), "run the program; copy the log it writes on the control beside it"),
        Step("Fit", DONE if fit else OPEN, _names([fit[0]] if fit else []),
             f"{me()} fit --machine {m} {' '.join(map(quote, _names(f.probe_logs))) or 'PROBE_LOG.csv'} "
             f"-o {out('fit.json')}"),
        Step("Diagnose: where the model fails", DONE if f.diagnoses else OPEN, _names(f.diagnoses),
             f"{me()} diagnose --from {fit_path} --json > {out('diagnose.json')}"),
        Step("Kinematics edit emitted (with backup step)", DONE if f.edits else OPEN, _names(f.edits),
             f"{me()} kinematics --from {fit_path}" + (" --current CURRENT" if ctl.takes_current else "")
             + f" -o {out('KIN')}"),
        Step("Backup taken, edit loaded", BY_HAND,
             note="; ".join(n for n in ("the edit sets the control to the machine file's geometry plus the "
                                        "fit: a second probing round then changes nothing", ctl.load_note)
                            if n)),
        Step("Sign check of the loaded edit", BY_HAND,
             note="compgen's sign check runs with an R-test (the edit's _SIGN program): a probing program "
                  "runs without the control's kinematics and cannot see the edit. With a probe only, check "
                  "the loaded kinematics with the control's own cycle, or an R-test"),
        Step("Sign-off", BY_HAND, note="after the sign check"),
    ]


def _names(paths) -> tuple[str, ...]:
    return tuple(str(p) for p in paths)


def _ext(machine: Machine) -> str:
    return controller(machine.controller).program_ext


def markdown(machine: Machine, steps: list[Step]) -> str:
    lines = [f"# Commissioning checklist: {machine.name}", ""]
    nxt = next((s for s in steps if s.status == OPEN), None)
    for i, s in enumerate(steps, 1):
        box = {DONE: "[x]", OPEN: "[ ]", BY_HAND: "[ ] (by hand)"}[s.status]
        lines.append(f"{i}. {box} {s.title}")
        for e in s.evidence:
            lines.append(f"   - found: `{e}`")
        if s.note:
            lines.append(f"   - {s.note}")
    lines += ["", f"Next: `{nxt.command}`" if nxt else "Every step a file can prove is done."]
    return "\n".join(lines) + "\n"
