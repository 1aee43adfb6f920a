"""Hostile inputs against the command line: does anything wrong reach a controller file?

    python benchmarks/fuzz.py [--jobs 2] [--seed 1] [--generated 60] [--show]

Each case is a file or option a user (or an accident) could give: R-test CSVs, machine
files, fit.json files, the control's current state, text meant to be injected, and output
paths. Each runs the real command in a fresh process (so a hang is seen: 60 s) and is
judged against what it must do:

* ``refuse``: exit 2, one line on stderr, no traceback, no output file;
* ``accept``: exit 0, and no emitted file holds a line that starts with the injected text;
* ``either`` (a generated variant that may still be good input: a line deleted, duplicated
  or swapped, a number in another format): a refusal as above, or an acceptance.

Besides the written cases, every valid input (the R-test CSV, the machine file, a pose
list, the three controls' states, the three controls' programs, the wings' files, a head's
machine file, a session measured on it, its iTNC 530 table and its maxkins program) gets
``--generated`` variants each: a line deleted, duplicated or swapped, a number written
another way, a control character inside a number (which must be refused).

Counted: tracebacks (or exit 3, an internal error), silent accepts (exit 0 where a refusal
was due), injected lines, hangs, and wrong refusals of good input. Outside CI: a benchmark.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SEED = ROOT / "machines" / "ac-trunnion-itnc530.toml"
HEAD = ROOT / "machines" / "bc-swivel-head-table.toml"
BC = ROOT / "machines" / "bc-table-sinumerik840d.toml"
HEAD_TAB = (ROOT / "examples" / "swivel-head-itnc530.TAB").read_text()
SESSION = ROOT / "examples" / "seed-session.csv"
TAB = ROOT / "examples" / "itnc530-current.TAB"
EVIL = "G0 Z-500 INJECTED"          # what an injection would make a block of
CONTROLLERS = ("itnc530", "tnc640", "sinumerik840d", "linuxcnc")


@dataclass
class Case:
    kind: str
    name: str
    files: dict[str, str | bytes]         # file name in the case folder → content
    args: list[str]                       # the command; {dir} is the case folder
    expect: str                           # "refuse" or "accept"
    outputs: list[str] = field(default_factory=list)   # files that must not exist after a refusal
    special: str = ""                     # "fifo": the data file is a FIFO; "fifo-store",
                                          # "dangling": the store is a FIFO, a link to nowhere
    secret: str = ""                      # must appear in no output, message or file name
    unchanged: list[str] = field(default_factory=list)  # files byte for byte as given, after a refusal


# the suffix of an edit's main file with a --current state, as -o must name it
MAIN = {"itnc530": ".TAB", "tnc640": ".TAB", "sinumerik840d": ".MPF", "linuxcnc": ".hal"}


def _csv_rows():
    lines = SESSION.read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("path,"))
    return lines[:head + 1], [ln.split(",") for ln in lines[head + 1:]], lines[head].split(",")


def _csv(rows, top):
    return "\n".join([*top, *(",".join(r) for r in rows)]) + "\n"


def csv_cases(rng: random.Random) -> list[Case]:
    top, rows, cols = _csv_rows()
    fit = ["fit", "--machine", str(SEED), "{dir}/data.csv", "-o", "{dir}/new.json"]
    out = []

    def cell(name, column, value, expect="refuse"):
        r = [list(x) for x in rows]
        r[rng.randrange(len(r))][cols.index(column)] = value
        out.append(Case("csv", name, {"data.csv": _csv(r, top)}, fit, expect, ["new.json"]))

    for column in ("X", "Y", "Z", "A", "C", "dX", "dY", "dZ"):
        for value in ("nan", "inf", "-inf", "1e308", "", "abc", "0x10", "1e999", "--1", "١٢"):
            cell(f"{column}={value!r}", column, value)
    for value in ("K4\rG0", "K4 G0 Z-500", "K4;" + EVIL, "K4(" + EVIL + ")", "4K", "K" * 40, "K4\x1b[2J"):
        cell(f"path={value!r}", "path", value)
    cell("huge cell", "dX", "1" * 200_000)
    # compgen's own column: a session's nest length, mm (10 to 2000); on the seed a lever only
    nested = [[*r, "184.670000"] for r in rows]
    ntop = [*top[:-1], top[-1] + ",probe_length"]
    for value in ("nan", "inf", "", "abc", "0", "-184.67", "5", "1e6", "١٨٤", "184.67e999"):
        r = [list(x) for x in nested]
        r[rng.randrange(len(r))][-1] = value
        out.append(Case("csv", f"probe_length={value!r}", {"data.csv": _csv(r, ntop)}, fit, "refuse",
                        ["new.json"]))
    out.append(Case("csv", "probe_length 284.67 (good)", {"data.csv": _csv(
        [[*r[:-1], "284.670000"] for r in nested], ntop)}, fit, "accept"))
    whole = _csv(rows, top)
    out += [
        Case("csv", "empty", {"data.csv": ""}, fit, "refuse", ["new.json"]),
        Case("csv", "header only", {"data.csv": "\n".join(top) + "\n"}, fit, "refuse", ["new.json"]),
        Case("csv", "NUL byte", {"data.csv": whole[:500].encode() + b"\x00" + whole[500:].encode()}, fit,
             "refuse", ["new.json"]),
        Case("csv", "latin-1 byte", {"data.csv": whole.encode() + b"K4,\xe9\n"}, fit, "refuse", ["new.json"]),
        Case("csv", "swapped header", {"data.csv": whole.replace("dX,dY,dZ", "dY,dX,dZ", 1)},
             [*fit, "&&", "kinematics", "--from", "{dir}/new.json", "-o", "{dir}/K.txt"], "refuse",
             ["K.txt"]),
        Case("csv", "duplicate column", {"data.csv": whole.replace("dX,dY,dZ", "dX,dX,dZ", 1)}, fit, "refuse",
             ["new.json"]),
        Case("csv", "ragged row", {"data.csv": whole + "K4,1,2\n"}, fit, "refuse", ["new.json"]),
        Case("csv", "a FIFO", {}, fit, "refuse", ["new.json"], special="fifo"),
        Case("csv", "BOM and CRLF (good)", {"data.csv": ("\ufeff" + whole).replace("\n", "\r\n")}, fit,
             "accept"),
        # the reader decodes a file's head and parses its rows from the bytes: each way round it
        Case("csv", "a µ in a comment (good)", {"data.csv": "# dX in µm\n" + whole}, fit, "accept"),
        Case("csv", "a µ in a row", {"data.csv": whole.replace("\nK4,", "\nK4µ,", 1)}, fit, "refuse",
             ["new.json"]),
        Case("csv", "a byte not UTF-8 past 64 kB", {"data.csv": whole.encode()[:70_000] + b"\xff"
                                                    + whole.encode()[70_001:]}, fit, "refuse", ["new.json"]),
        Case("csv", "lines ending in CR alone (good)", {"data.csv": whole.replace("\n", "\r")}, fit,
             "accept"),
        Case("csv", "a label of 70 letters", {"data.csv": whole.replace("\nK4,", "\n" + "K" * 70 + ",", 1)},
             fit, "refuse", ["new.json"]),
        Case("csv", "10 000 newlines at the end (good)", {"data.csv": whole + "\n" * 10_000}, fit, "accept"),
    ]
    for _ in range(6):     # a file cut short: a row cut inside its last number cannot be told
        cut = rng.randrange(len(whole) // 3, len(whole))
        text = whole[:cut]
        last = text.rstrip("\n").splitlines()[-1].split(",")
        # a cell cut to its sign alone ("+" of a side's +1, "-") or to "1." is no number: refused
        ok = len(last) == len(cols) and not text.endswith((",", "-", ".", "+"))
        out.append(Case("csv", f"cut at byte {cut}", {"data.csv": text}, fit, "accept" if ok else "refuse",
                        ["new.json"]))
    # readings in mm: fit warns, the edit is refused
    mm = [list(r) for r in rows]
    for r in mm:
        for c in ("dX", "dY", "dZ"):
            r[cols.index(c)] = f"{float(r[cols.index(c)]) / 1000:.9f}"
    out.append(Case("csv", "readings in mm", {"data.csv": _csv(mm, top)},
                    [*fit, "&&", "kinematics", "--from", "{dir}/new.json", "-o", "{dir}/K.txt"], "refuse",
                    ["K.txt"]))
    swapped = [list(r) for r in rows]
    for r in swapped:
        r[cols.index("dX")], r[cols.index("dY")] = r[cols.index("dY")], r[cols.index("dX")]
    out.append(Case("csv", "dX and dY swapped", {"data.csv": _csv(swapped, top)},
                    [*fit, "&&", "kinematics", "--from", "{dir}/new.json", "-o", "{dir}/K.txt"], "refuse",
                    ["K.txt"]))
    return out


MACHINE_EDITS = [
    # (name, before, after, expect)
    ("typo sense", "sense = -1 ", "sence = -1 ", "refuse"),
    ("typo offset", "offset = [0.0, 0.0, 29.794]", "ofset = [0.0, 0.0, 29.794]", "refuse"),
    ("typo travel", "travel = [-120.0, 120.0]", "travle = [-120.0, 120.0]", "refuse"),
    ("typo feed_max", "feed_max = 5400.0", "feedmax = 5400.0", "refuse"),
    ("typo ball", "ball = [", "bal = [", "refuse"),
    ("typo top-level", 'controller = "itnc530"', 'controler = "itnc530"', "refuse"),
    ("typo limits", "offset_um = 100.0", "ofset_um = 100.0", "refuse"),
    ("nan offset", "offset = [0.0, 0.0, 29.794]", "offset = [0.0, 0.0, nan]", "refuse"),
    ("inf travel", "travel = [-720.0, 720.0]", "travel = [-720.0, inf]", "refuse"),
    ("nan ramp", "C = { from = 0.0, to = 360.0 }", "C = { from = nan, to = 360.0 }", "refuse"),
    ("nan sine", "amplitude = -90.0", "amplitude = nan", "refuse"),
    ("nan const", "C = 0.0", "C = nan", "refuse"),
    ("string number", "feed = 500.0", 'feed = "500"', "refuse"),
    ("negative feed", "feed = 500.0", "feed = -500.0", "refuse"),
    ("zero n", "n = 121", "n = 0", "refuse"),
    ("bool sense", "sense = -1 ", "sense = true ", "refuse"),
    ("sense 2", "sense = -1 ", "sense = 2 ", "refuse"),
    ("reversed travel", "travel = [-120.0, 120.0]", "travel = [120.0, -120.0]", "refuse"),
    ("axis injection", 'axis = "C"', f'axis = "C0 {EVIL} C"', "refuse"),
    ("axis newline", 'axis = "C"', f'axis = "C\\n{EVIL}"', "refuse"),
    ("axis lower", 'axis = "C"', 'axis = "c"', "refuse"),
    ("tool injection", 'tool = "99"', f'tool = "99\\n{EVIL}"', "refuse"),
    ("tool spaces", 'tool = "99"', 'tool = "99 M3"', "refuse"),
    ("work offset injection", "clearance = 20.0", f'clearance = 20.0\nwork_offset = "{EVIL}"', "refuse"),
    ("path comma", "[paths.K2]", '[paths."K2,x"]', "refuse"),
    ("path newline", "[paths.K2]", f'[paths."K2\\n{EVIL}"]', "refuse"),
    ("unknown controller", 'controller = "itnc530"', 'controller = "fanuc"', "refuse"),
    ("duplicate axis", 'axis = "Y"', 'axis = "X"', "refuse"),
    ("safe_z", "clearance = 20.0", "clearance = 20.0\nsafe_z = -500", "refuse"),
    ("tolerance of no path", "K2 = 8.0", "K2 = 8.0\nK9 = 1.0", "refuse"),
    ("vector not unit", "C = [0.0, 0.0, -1.0] }", "C = [0.0, 0.0, -2.0] }", "refuse"),
    ("name injection (free text, kept in one comment)", 'name = "A/C trunnion, iTNC 530 (seed report)"',
     f'name = "x\\n{EVIL}\\r\\n) {EVIL} ("', "accept"),
    ("unicode name (good)", 'name = "A/C trunnion, iTNC 530 (seed report)"', 'name = "Fräse µ 5-Achs ″"',
     "accept"),
]


def machine_cases() -> list[Case]:
    text = SEED.read_text()
    out = []
    for name, before, after, expect in MACHINE_EDITS:
        assert before in text, name
        for ctl in CONTROLLERS:
            ext = {"itnc530": ".H", "tnc640": ".H", "sinumerik840d": ".MPF", "linuxcnc": ".ngc"}[ctl]
            out.append(Case("machine", f"{name} [{ctl}]", {"m.toml": text.replace(before, after, 1)},
                            ["measure-program", "--machine", "{dir}/m.toml", "--path", "K2",
                             "--controller", ctl, "-o", f"{{dir}}/P{ext}"], expect, [f"P{ext}"]))
    out.append(Case("machine", "not TOML", {"m.toml": "name = [\n"},
                    ["effects", "--machine", "{dir}/m.toml"], "refuse"))
    out.append(Case("machine", "binary", {"m.toml": b"\x89PNG\x00\x00"},
                    ["effects", "--machine", "{dir}/m.toml"], "refuse"))
    return out


FIT = Path()      # set in main: a good fit.json of the example session with EXC:h2 added


def _absolute(doc: dict) -> dict:
    """The fit with absolute file names, so that a case's copy elsewhere still finds them."""
    if not doc["machine"].get("bundled"):          # a bundled machine is named, not located
        doc["machine"]["file"] = str((FIT.parent / doc["machine"]["file"]).resolve())
    for d in doc["data"]:
        d["file"] = str((FIT.parent / d["file"]).resolve())
    return doc


def fit_cases() -> list[Case]:
    good = json.dumps(_absolute(json.loads(FIT.read_text())))
    d = json.loads(good)
    out = []

    def variant(name, change, expect="refuse", raw=None):
        doc = json.loads(good)
        if change:
            change(doc)
        text = raw if raw is not None else json.dumps(doc)
        for cmd in (["kinematics", "--from", "{dir}/fit.json", "-o", "{dir}/K.txt"],
                    ["compare", "--from", "{dir}/fit.json"]):
            out.append(Case("fit.json", f"{name} [{cmd[0]}]", {"fit.json": text}, cmd, expect, ["K.txt"]))

    def param(k, v):
        return lambda doc: doc["parameters"]["XOC"].update({k: v})

    xoc, boa = d["parameters"]["XOC"]["value"], d["parameters"]["BOA"]["std"]
    variant("NaN value", None, raw=good.replace(f'"value": {xoc!r}', '"value": NaN', 1))
    variant("Infinity std", None, raw=good.replace(f'"std": {boa!r}', '"std": Infinity', 1))
    for k, v in (("value", 1e300), ("value", "0.001"), ("value", None), ("value", True), ("unit", "furlong"),
                 ("unit", "arcsec"), ("unit", 5), ("std", -1.0)):
        variant(f"XOC {k}={v!r}", param(k, v))
    variant("value in µm (good: unit honoured)", lambda doc: doc["parameters"]["XOC"].update(
        value=doc["parameters"]["XOC"]["value"] * 1e3, std=doc["parameters"]["XOC"]["std"] * 1e3, unit="um"),
        "accept")
    variant("unknown parameter",
            lambda doc: doc["parameters"].update(XOQ={"value": 0, "std": 0, "unit": "mm"}))
    variant("no parameters", lambda doc: doc.pop("parameters"))
    variant("residual empty", lambda doc: doc.update(residual={}))
    variant("residual NaN-free but text", lambda doc: doc["residual"].update(sigma_um="0.5"))
    variant("format", lambda doc: doc.update(format="compgen.fit/9"))
    variant("machine gone", lambda doc: doc["machine"].update(file="nowhere.toml"))
    # a fit keeps each file's absolute path beside its relative one (taken only with its
    # checksum): the data are gone only where both lead nowhere
    variant("data gone", lambda doc: doc["data"][0].update(file="nowhere.csv", absolute="/nowhere/data.csv"))
    variant("data found by its absolute path (good)", lambda doc: doc["data"][0].update(file="nowhere.csv"),
            "accept")
    variant("checksum", lambda doc: doc["data"][0].update(sha256="0" * 64))
    variant("deep nesting", None, raw="[" * 100_000 + "]" * 100_000)
    variant("not an object", None, raw="[1, 2, 3]")
    variant("not JSON", None, raw="{'a': 1}")
    variant("empty", None, raw="")
    return out


def hal_good() -> str:
    return (ROOT / "tests" / "golden" / "ac-trunnion-itnc530" / "linuxcnc" / "kinematics.hal").read_text()


def current_cases() -> list[Case]:
    tab = TAB.read_text()
    vectors = {7: -1.0, 8: 0.0, 9: 0.0, 10: 0.0, 11: 0.0, 12: -1.0}
    carr_good = "".join(f"$TC_CARR{k}[1]={vectors.get(k, 0.0)}\n"
                        for k in (*vectors, 44, 45, 46, *range(55, 61)))
    out = []

    def case(name, ctl, text, expect="refuse"):
        assert expect == "accept" or ctl == "tnc640" or text not in (tab, carr_good, hal_good()), name
        main = f"K{MAIN[ctl]}"          # the edit's main file as -o must name it
        out.append(Case("current", f"{name} [{ctl}]", {"current.txt": text},
                        ["kinematics", "--from", "{dir}/fit.json", "--controller", ctl, "--current",
                         "{dir}/current.txt", "-o", "{dir}/" + main], expect, [main]))

    case("a table for a TNC 640 (it keeps no *.TAB)", "tnc640", tab)
    for ctl in ("itnc530",):
        case("good table", ctl, tab, "accept")
        case("NaN COORD", ctl, tab.replace("+29.794", "nan     "))
        case("inf COORD", ctl, tab.replace("+29.794", "inf     "))
        case("text COORD", ctl, tab.replace("+29.794", "abc     "))
        case("no END", ctl, tab.replace("[END]", ""))
        case("no MachAxis C", ctl, tab.replace("MachAxis  C", "MachAxis  W"))
        case("wrong pivot", ctl, tab.replace("+29.794", "+30.500"))
        case("no unit", ctl, tab.replace(" MM\n", "\n", 1))
        case("misaligned columns", ctl, tab.replace("Trans     Z     +29.794", "Trans Z +29.794"))
        case("binary", ctl, b"\x00\x01\x02")
        case("CRLF (good)", ctl, tab.replace("\n", "\r\n"), "accept")
    case("good record", "sinumerik840d", carr_good, "accept")
    case("NaN", "sinumerik840d", carr_good.replace("$TC_CARR7[1]=-1.0", "$TC_CARR7[1]=nan"))
    case("inf", "sinumerik840d", carr_good.replace("$TC_CARR44[1]=0.0", "$TC_CARR44[1]=inf"))
    case("text", "sinumerik840d", carr_good.replace("$TC_CARR44[1]=0.0", "$TC_CARR44[1]=abc"))
    case("missing entry", "sinumerik840d", carr_good.replace("$TC_CARR44[1]=0.0\n", ""))
    case("other record only", "sinumerik840d", carr_good.replace("[1]", "[2]"))
    case("wrong vector", "sinumerik840d", carr_good.replace("$TC_CARR7[1]=-1.0", "$TC_CARR7[1]=0.0")
         .replace("$TC_CARR8[1]=0.0", "$TC_CARR8[1]=-1.0"))
    hal = hal_good()
    case("good HAL (an edit of another fit)", "linuxcnc", hal, "accept")
    for bad in ("abc", "nan", "-inf", "1e999"):
        case(f"HAL {bad}", "linuxcnc", re.sub(r"(setp \S+z-rot-point\s+)\S+", rf"\g<1>{bad}", hal))
    return out


def output_cases() -> list[Case]:
    k = ["kinematics", "--from", "{dir}/fit.json", "--controller", "itnc530"]
    return [
        Case("output", "-o is --current", {"current.TAB": TAB.read_text()},
             [*k, "--current", "{dir}/current.TAB", "-o", "{dir}/current.TAB", "--force"], "refuse"),
        Case("output", "-o is the fit", {}, [*k, "-o", "{dir}/fit.json", "--force"], "refuse"),
        Case("output", "-o /dev/null", {}, [*k, "-o", "/dev/null", "--force"], "refuse"),
        Case("output", "-o a folder", {}, [*k, "-o", "{dir}", "--force"], "refuse"),
        Case("output", "-o in a missing folder", {}, [*k, "-o", "{dir}/no/such/K.txt"], "refuse"),
        Case("output", "-o in /proc", {}, [*k, "-o", "/proc/K.txt"], "refuse"),
        Case("output", "-o exists, no --force", {"K.txt": "the user's"}, [*k, "-o", "{dir}/K.txt"], "refuse"),
        Case("output", "-o over-long program name", {}, [*k, "-o", "{dir}/" + "K" * 40 + ".txt"], "refuse",
             ["K" * 40 + ".txt"]),
        Case("output", "-o name with a newline", {}, [*k, "-o", "{dir}/K\nG0.txt"], "refuse", ["K\nG0.txt"]),
        Case("output", "simulate -o is the machine file", {"m.toml": SEED.read_text()},
             ["simulate", "--machine", "{dir}/m.toml", "--truth",
              str(ROOT / "examples" / "truth-table4.json"), "-o", "{dir}/m.toml", "--force"], "refuse"),
        Case("output", "measure-program -o is --poses", {"p.csv": "path,A,C\nK2,0,0\nK2,0,5\n"},
             ["measure-program", "--machine", str(SEED), "--poses", "{dir}/p.csv", "-o", "{dir}/p.csv",
              "--force"], "refuse"),
        Case("output", "good (accept)", {}, [*k, "-o", "{dir}/K.txt"], "accept"),
        Case("output", "simulate --probe-length with --device probe", {},
             ["simulate", "--machine", str(SEED), "--truth", str(ROOT / "examples" / "truth-table4.json"),
              "--device", "probe", "--probe-length", "220", "-o", "{dir}/p.log"], "refuse", ["p.log"]),
    ]


SECRET = "s3cr3t-Pw"


def history_cases() -> list[Case]:
    """Dates, serials and stores as a user (or an attacker) gives them to the history."""
    add = ["history", "add", "{dir}/fit.json", "--db", "{dir}/h.sqlite"]
    out = []
    for date, expect in (("2026-03-01", "accept"), ("2026-03-01T10:00+02:00", "accept"),
                         ("2026-03-01T10:00:00.5-05:30", "accept"), ("2026-03-01T10:00Z", "accept"),
                         ("9999-01-01", "refuse"), ("1969-12-31T23:59Z", "refuse"), ("2026-02-30", "refuse"),
                         ("2026-03-01T25:00", "refuse"), ("yesterday", "refuse"), ("", "accept"),
                         ("\u0662\u0660\u0662\u0666-03-01", "refuse"), ("2026-03-01\n2027", "refuse"),
                         ("+2026-03-01", "refuse"), ("2026-03-01T10:00+25:00", "refuse"),
                         ("2026-W09", "either"), ("20260301", "either"), ("3000-01-01T00:00Z", "refuse")):
        out.append(Case("history", f"--date {date!r}", {}, [*add, "--date", date], expect,
                        ["h.sqlite"]))
    for serial, expect in (("DMU-50/1234", "accept"), ("A\nB", "refuse"), ("A B", "refuse"),
                           ("x" * 41, "refuse"), ("$(reboot)", "refuse"), ("-rf", "refuse"),
                           ("A\x1b[2J", "refuse")):
        out.append(Case("history", f"--serial {serial!r}", {}, [*add, "--serial", serial], expect,
                        ["h.sqlite"]))
    for dsn in (f"user=x password={SECRET} host=/nonexistent dbname=y",
                f"postgresql://u:{SECRET}@127.0.0.1:1/db", f"POSTGRESQL://u:{SECRET}@127.0.0.1:1/db",
                f"postgres://u:p@{SECRET}@127.0.0.1:1/db", f"port=1 password={SECRET} host=127.0.0.1",
                f"password='{SECRET} x' host=127.0.0.1 port=1", f"password={SECRET}",
                f"sslmode=require password={SECRET} host=127.0.0.1 port=1",
                f"{SECRET}=x", f"host=127.0.0.1 port=1 password = {SECRET}", f"dbname=x password={SECRET} ="):
        for command in (["history", "list"], ["history", "init"], add):
            out.append(Case("dsn", f"{command[1]} --db {dsn!r}", {},
                            [*(c for c in command if c not in ("--db", "{dir}/h.sqlite")), "--db", dsn],
                            "refuse", secret=SECRET))
    return out


# -- hostile variants derived from valid inputs: each valid file, each edit a slip makes

CONTROL_CHARS = ("\x07", "\x1b", "\x0b", "\x0c", "\x85", "\u2028", "\r", "\x00")
NUMBER = re.compile(r"(?<![\w.])[-+]?\d+\.\d+(?:[eE][-+]?\d+)?(?![\w.])")
NUMBER_FORMATS = (lambda v: v.replace(".", ","), lambda v: v + ".", lambda v: v.replace(".", ".."),
                  lambda v: v.replace(".", "_"), lambda v: "".join(chr(0xFF10 + int(c)) if c.isdigit() else c
                                                                  for c in v),
                  lambda v: v + "e999", lambda v: "0x" + v, lambda v: v.replace(".", " . "),
                  lambda v: "1" * 400, lambda v: "nan", lambda v: "--" + v.lstrip("+-"))


def _variants(text: str, rng: random.Random, n: int) -> list[tuple[str, str, str]]:
    """``n`` hostile variants of ``text``: (what was done, the new text, what is expected).
    A line deleted, duplicated or swapped may still be good input ("either": refused in one
    clear line, or accepted); a number spoilt or a control character inside a number must
    be refused."""
    lines = text.split("\n")
    body = [i for i, ln in enumerate(lines) if ln.strip()]
    numbered = [i for i in body if NUMBER.search(lines[i])]
    out = []
    while len(out) < n:
        op = rng.choice(("delete", "duplicate", "swap", "number", "control"))
        new = list(lines)
        i = rng.choice(body)
        if op == "delete":
            del new[i]
            what, expect = f"line {i + 1} deleted", "either"
        elif op == "duplicate":
            new.insert(i, lines[i])
            what, expect = f"line {i + 1} twice", "either"
        elif op == "swap":
            j = rng.choice(body)
            new[i], new[j] = new[j], new[i]
            what, expect = f"lines {i + 1} and {j + 1} swapped", "either"
        elif op == "number" and numbered:
            i = rng.choice(numbered)
            m = rng.choice(list(NUMBER.finditer(lines[i])))
            k = rng.randrange(len(NUMBER_FORMATS))
            new[i] = lines[i][:m.start()] + NUMBER_FORMATS[k](m[0]) + lines[i][m.end():]
            what, expect = f"line {i + 1}: {m[0]} written as format {k}", "either"
        elif op == "control" and numbered:
            i = rng.choice(numbered)
            m = rng.choice(list(NUMBER.finditer(lines[i])))
            at = rng.randrange(m.start() + 1, m.end())
            ch = rng.choice(CONTROL_CHARS)
            new[i] = lines[i][:at] + ch + lines[i][at:]
            what, expect = f"line {i + 1}: {ch!r} inside {m[0]}", "refuse"
        else:
            continue
        variant = "\n".join(new)
        if variant != text:
            out.append((what, variant, expect))
    return out


def derived_cases(rng: random.Random, programs: dict[str, Path], per_surface: int,
                  wings: dict[str, Path]) -> list[Case]:
    """Hostile variants of every valid input, run through the command that reads it."""
    out = []
    vectors = {7: -1.0, 8: 0.0, 9: 0.0, 10: 0.0, 11: 0.0, 12: -1.0}
    carr = "".join(f"$TC_CARR{k}[1]={vectors.get(k, 0.0)}\n" for k in (*vectors, 44, 45, 46, *range(55, 61)))
    kin = ["kinematics", "--from", "{dir}/fit.json", "--current", "{dir}/state.txt", "-o"]
    surfaces = [
        ("csv", "data.csv", SESSION.read_text(),
         ["fit", "--machine", str(SEED), "{dir}/data.csv", "-o", "{dir}/out.json"], ["out.json"]),
        ("machine", "m.toml", SEED.read_text(),
         ["measure-program", "--machine", "{dir}/m.toml", "--path", "K2", "-o", "{dir}/P.H"], ["P.H"]),
        ("poses", "poses.csv", "path,A,C\n" + "".join(
            f"P,{a:.1f},{c:.1f}\n" for a, c in zip(range(-60, 61, 15), range(0, 361, 45), strict=True)),
         ["predict", "--from", "{dir}/fit.json", "--poses", "{dir}/poses.csv", "-o", "{dir}/pred.csv"],
         ["pred.csv"]),
        *(("state", "state.txt", text, [*kin[:3], "--controller", ctl, *kin[3:], f"{{dir}}/K{MAIN[ctl]}"],
           [f"K{MAIN[ctl]}"])
          for ctl, text in (("itnc530", TAB.read_text()), ("sinumerik840d", carr), ("linuxcnc", hal_good()))),
    ]
    for ctl, path in programs.items():
        mode = ["--mode", "tcpm"] if ctl == "linuxcnc" else []
        surfaces.append(("program", path.name, path.read_text(),
                         ["check-program", "--machine", str(SEED), "--controller", ctl, *mode,
                          "{dir}/" + path.name], []))
    # the wings: a probe log, a history export, a CEC table as state, LinuxCNC's own INI
    target = wings["target"].read_bytes()           # an existing store: a refusal leaves it as it was
    beside = {"probe": {}, "import": {"target.sqlite": target}, "cec": {"A.MPF": wings["carr"].read_text()},
              "ini": {str(p.relative_to(wings["trt"])): p.read_bytes() for p in wings["trt"].rglob("*")
                      if p.is_file() and p.name != "xyzac-trt.ini"}}
    surfaces += [
        ("probe", "log.csv", wings["probe"].read_text(),
         ["fit", "--machine", str(SEED), "{dir}/log.csv", "-o", "{dir}/out.json"], ["out.json"]),
        ("import", "h.json", wings["export"].read_text(),
         ["history", "import", "{dir}/h.json", "--db", "{dir}/target.sqlite"], []),
        ("cec", "cec.INI", wings["cec"].read_text(),
         ["kinematics", "--from", str(wings["bcfit"]), "--current", "{dir}/A.MPF", "--current",
          "{dir}/cec.INI", "-o", "{dir}/K.MPF"], ["K.MPF"]),
        ("ini", "xyzac-trt.ini", (wings["trt"] / "xyzac-trt.ini").read_text(),
         ["kinematics", "--from", "{dir}/fit.json", "--controller", "linuxcnc", "--current",
          "{dir}/xyzac-trt.ini", "-o", "{dir}/KIN.ini"], ["KIN.ini"]),
        # a head's machine file (its chain's new rules) and a session measured on it, fitted
        ("head", "m.toml", HEAD.read_text(),
         ["fit", "--machine", "{dir}/m.toml", str(wings["head"]), "-o", "{dir}/out.json"], ["out.json"]),
        ("head-csv", "data.csv", wings["head"].read_text(),
         ["fit", "--machine", str(HEAD), "{dir}/data.csv", "-o", "{dir}/out.json"], ["out.json"]),
        # a head's edit over an iTNC 530 table (rows from the tool reference point to its B),
        # and a head's program under LinuxCNC's maxkins (its pin guard)
        ("head-tab", "state.txt", HEAD_TAB,
         ["kinematics", "--from", str(wings["hfit"]), "--controller", "itnc530", "--current",
          "{dir}/state.txt", "-o", "{dir}/K.TAB"], ["K.TAB"]),
        ("head-program", "K4.ngc", wings["hprogram"].read_text(),
         ["check-program", "--machine", str(wings["maxkins"]), "--mode", "tcpm", "{dir}/K4.ngc"], []),
    ]
    for kind, name, text, args, outputs in surfaces:
        for what, variant, expect in _variants(text, rng, per_surface):
            files = {**beside.get(kind, {}), name: variant}
            out.append(Case(f"gen-{kind}", f"{name} [{args[0]}]: {what}", files, args, expect,
                            outputs, unchanged=["target.sqlite"] if kind == "import" else []))
    return out


def nest_cases(wings: dict[str, Path]) -> list[Case]:
    """A second nest length on LinuxCNC's maxkins head: --probe-length as a user may mistype
    it, and a program whose header names one nest and whose pin guard another."""
    maxkins = str(wings["maxkins"])
    out = [Case("nest", f"measure-program --probe-length {v!r}", {},
                ["measure-program", "--machine", maxkins, "--path", "K4", "--probe-length", v, "-o",
                 "{dir}/N.ngc"], "refuse", ["N.ngc", "N.poses.csv"])
           for v in ("nan", "inf", "-220", "0", "1e999", "abc", "220mm", "5", "2500", "", " ")]
    out.append(Case("nest", "measure-program --probe-length 220 (good)", {},
                    ["measure-program", "--machine", maxkins, "--path", "K4", "--probe-length", "220", "-o",
                     "{dir}/N.ngc"], "accept"))
    text = wings["nprogram"].read_text()
    check = ["check-program", "--machine", maxkins, "--mode", "tcpm", "{dir}/N.ngc"]
    nest = ", 220.0000 mm below the gauge line"
    other = "; nest on tool 7, 250.0000 mm below the gauge line\n; active"
    for name, variant in [("header 320 mm, guard 370", text.replace(nest, nest.replace("220", "320"))),
                          ("header without the nest", text.replace(nest, "")),
                          ("two nests in the header", text.replace("; active", other, 1))]:
        out.append(Case("nest", f"check-program: {name}", {"N.ngc": variant}, check, "refuse"))
    out.append(Case("nest", "check-program --probe-length 120 on a 220 program", {"N.ngc": text},
                    [*check, "--probe-length", "120"], "refuse"))
    out.append(Case("nest", "check-program of the 220 program (good)", {"N.ngc": text}, check, "accept"))
    return out


def second_look_cases() -> list[Case]:
    """The second look's inputs, each a rule at its input: a location error's own limit
    ([drift] each), a path named twice, verdict's and checklist's options, an import's
    --same-machine."""
    seed = SEED.read_text()
    truth = str(ROOT / "examples" / "truth-table4.json")
    out = [Case("second-look", f"[drift] each = {each}", {"m.toml": seed + f"\n[drift]\neach = {each}\n"},
                ["effects", "--machine", "{dir}/m.toml"], expect)
           for each, expect in (("{ QOZ = 1.0 }", "refuse"), ("{ BOA = -1.0 }", "refuse"),
                                ('{ BOA = "5" }', "refuse"), ("{ BOA = { x = 1 } }", "refuse"),
                                ("{ BOA = nan }", "refuse"), ("{ XOW = 1.0 }", "accept"),
                                ("{ BOA = 5.0, XOC = 3.0 }", "accept"))]
    out += [Case("second-look", f"{args[0]} {args[-3]} {args[-2]}", {}, args, "refuse", [args[-1][6:]])
            for args in (["measure-program", "--machine", str(SEED), "--path", "K2,K2", "-o", "{dir}/P.H"],
                         ["probe-program", "--machine", str(SEED), "--path", "K1,K2,K1", "-o", "{dir}/Q.H"],
                         ["simulate", "--machine", str(SEED), "--truth", truth, "--paths", "K4,K4",
                          "-o", "{dir}/s.csv"])]
    out += [Case("second-look", "checklist --device nope", {},
                 ["checklist", "--machine", str(SEED), "--device", "nope", "--dir", "{dir}"], "refuse"),
            Case("second-look", "verdict --post a ragged CSV", {"post.csv": "path,A,C,dX\nK4,0,0\n"},
                 ["verdict", "--from", "{dir}/fit.json", "--post", "{dir}/post.csv"], "refuse"),
            Case("second-look", "verdict --controller fanuc", {},
                 ["verdict", "--from", "{dir}/fit.json", "--controller", "fanuc"], "refuse"),
            Case("second-look", "verdict (good)", {}, ["verdict", "--from", "{dir}/fit.json"], "accept"),
            Case("second-look", "history import --same-machine of no export", {"x.json": "{}"},
                 ["history", "import", "{dir}/x.json", "--same-machine", "A", "--db", "{dir}/h.sqlite"],
                 "refuse", ["h.sqlite"])]
    # what a user says of a file's set-up: of a file not in the fit, of the first, both at
    # once, and as meant (a moved ball said untouched: tests/statistics/test_diagnose.py)
    session = SESSION.read_text()
    two = {"a.csv": session, "b.csv": session.replace("K4,", "K4b,")}
    fit = ["fit", "--machine", str(SEED), "{dir}/a.csv", "{dir}/b.csv", "-o", "{dir}/f.json"]
    again, untouched = "--mounted-again", "--not-touched"
    out += [Case("second-look", f"fit {' '.join(said)}", two, [*fit, *said], expect, ["f.json"])
            for said, expect in (([again, "{dir}/zz.csv"], "refuse"), ([again, "{dir}/a.csv"], "refuse"),
                                 ([untouched, "{dir}/a.csv"], "refuse"),
                                 ([again, "{dir}/b.csv", untouched, "{dir}/b.csv"], "refuse"),
                                 ([again, "{dir}/b.csv"], "accept"), ([untouched, "{dir}/b.csv"], "accept"))]
    turned = "--ball-turned"    # FILE=DEG: its syntax, its range, its file, beside another saying
    said_turned = [([f"{{dir}}/{f}"], "refuse") for f in ("b.csv", "b.csv=0", "b.csv=360", "b.csv=inf",
                                                          "b.csv=6O", "a.csv=60", "zz.csv=60")]
    said_turned += [(["=60"], "refuse"), (["{dir}/b.csv=-60"], "accept"), (["{dir}/b.csv=60"], "accept")]
    out += [Case("second-look", f"fit {turned} {said[0]}", two, [*fit, turned, *said], expect, ["f.json"])
            for said, expect in said_turned]
    out.append(Case("second-look", f"fit {untouched} and {turned} b.csv", two,
                    [*fit, untouched, "{dir}/b.csv", turned, "{dir}/b.csv=60"], "refuse", ["f.json"]))
    return out


def shop_cases(wings: dict[str, Path]) -> list[Case]:
    """Issue 65's kinds, each a rule at its input: store paths and URLs, INI corners as the
    start script reads them, CEC states, number options out of range, and long names."""
    add = ["history", "add", "{dir}/fit.json", "--db"]
    stores = ((":memory:", ""), ("", ""), ("file:h.sqlite", ""), ("{dir}/gone/h.sqlite", ""),
              ("{dir}/link.sqlite", "dangling"), ("{dir}/pipe.sqlite", "fifo-store"), ("{dir}", ""))
    out = [Case("store", f"--db {db!r}", {}, [*add, db], "refuse", special=special) for db, special in stores]
    at = "@127.0.0.1:1/db"
    out += [Case("store", f"--db {url!r}", {}, [*add, url], "refuse", secret=SECRET)
            for url in (f"postgresql+psycopg://u:{SECRET}{at}", f"postgresql:/u:{SECRET}{at}",
                        f"postgresql:u:{SECRET}{at}", f"mysql://u:{SECRET}{at}")]
    out.append(Case("store", "--db a new file (good)", {}, [*add, "{dir}/h.sqlite"], "accept"))
    # number options: finite, within their range
    sim = ["simulate", "--machine", str(SEED), "--truth", str(ROOT / "examples" / "truth-table4.json"),
           "-o", "{dir}/s.csv"]
    fleet = ["history", "fleet", "--db", "{dir}/h.sqlite", "--every-days"]
    for args in (["diagnose", "--from", "{dir}/fit.json", "--noise-um", "1e308"],
                 ["diagnose", "--from", "{dir}/fit.json", "--noise-um", "nan"],
                 [*fleet, "inf"], [*fleet, "nan"], [*sim, "--noise-rho", "nan"],
                 [*sim, "--device", "probe", "--stylus-error-um", "inf"],
                 [*add, "{dir}/h.sqlite", "--temperature", "spindle=1e6"],
                 [*add, "{dir}/h.sqlite", "--temperature", "hall=-500"]):
        out.append(Case("number", " ".join(args[:1] + args[-2:]), {}, args, "refuse", ["s.csv", "h.sqlite"]))
    # machine files asking for hours of work, or for another record than meant
    seed, bc = SEED.read_text(), BC.read_text()
    knots = ", ".join(str(k) for k in range(-200, 201, 2))
    for name, text in (("touches = 100000", seed.replace("touches = 5", "touches = 100000")),
                       ("poses = 5000", seed.replace("poses = 12", "poses = 5000")),
                       ("a spline of 201 knots", seed + f"\n[effects.shapes.many]\nat = [{knots}]\n"),
                       ("tcarr = 1.5", bc.replace("tcarr = 1 ", "tcarr = 1.5 "))):
        out.append(Case("limits", name, {"m.toml": text}, ["effects", "--machine", "{dir}/m.toml"], "refuse"))
    # a 300-character machine name: programs LinuxCNC reads, a probe log without it
    long = re.sub(r'(?m)^name = ".*"$', 'name = "Machine ' + "x" * 292 + '"', seed)
    for command in (["measure-program", "--controller", "linuxcnc", "--path", "K2", "-o", "{dir}/RT.ngc"],
                    ["probe-program", "--controller", "linuxcnc", "--path", "K2", "-o", "{dir}/PR.ngc"],
                    ["measure-program", "--path", "K2", "-o", "{dir}/RT.H"]):
        out.append(Case("long", f"a 300-character name: {command[0]} {command[-1][6:]}", {"m.toml": long},
                        [command[0], "--machine", "{dir}/m.toml", *command[1:]], "accept"))
    # LinuxCNC's configuration as its start script reads it
    hal = hal_good()
    rot = "".join(ln + "\n" for ln in hal.splitlines() if "rot-point" in ln)
    rest = "".join(ln + "\n" for ln in hal.splitlines() if "rot-point" not in ln)
    kin = ["kinematics", "--from", "{dir}/fit.json", "--controller", "linuxcnc", "--current",
           "{dir}/m.ini", "-o"]
    plain = {"m.ini": "[HAL]\nHALFILE = a.hal\n", "a.hal": hal}
    inc = "[HAL]\nHALFILE = a.hal\n#INCLUDE x.inc\n"
    for name, files, o, expect in (
            ("good", plain, "KIN.ini", "accept"),
            ("#INCLUDE, last line without its end",
             {"m.ini": inc + "[KINS]\nX = 1", "a.hal": hal, "x.inc": "[TRT]\n"}, "KIN.ini", "refuse"),
            ("#INCLUDE and a backslash",
             {"m.ini": inc + "[X]\nY = a\\b\n", "a.hal": hal, "x.inc": "[TRT]\n"}, "KIN.ini", "refuse"),
            ("an included file without its last line end",
             {"m.ini": inc, "a.hal": hal, "x.inc": "[TRT]\nX = 1"}, "KIN.ini", "refuse"),
            ("a tab before HALFILE arguments",
             {"m.ini": "[HAL]\nHALFILE = a.hal\targ\n", "a.hal": hal}, "KIN.ini", "refuse"),
            ("a source loop",
             {**plain, "a.hal": hal + "source b.hal\n", "b.hal": "source a.hal\n"}, "KIN.ini", "refuse"),
            ("two files of one name (good)",
             {"m.ini": "[HAL]\nHALFILE = x/p.hal\nHALFILE = y/p.hal\n", "x/p.hal": rot, "y/p.hal": rest},
             "KIN.ini", "accept"),
            ("[HAL] from an #INCLUDE (good)",
             {"m.ini": "[EMC]\nVERSION = 1.1\n#INCLUDE h.inc\n", "h.inc": "[HAL]\nHALFILE = a.hal\n",
              "a.hal": hal}, "KIN.ini", "accept"),
            ("-o with a '#'", plain, "K#1.ini", "refuse"),
            ("-o a .hal for an INI", plain, "KIN.hal", "refuse")):
        out.append(Case("ini-corner", name, files, [*kin, "{dir}/" + o], expect, [o]))
    # CEC state kept whole, the record's kind compared
    cec, carr = wings["cec"].read_text(), wings["carr"].read_text()
    first = next(ln for ln in cec.splitlines() if ln.startswith("$AN_CEC_DIRECTION["))
    extra = ("".join(f"$AN_CEC[7,{k}]=0.00{k}\n" for k in range(3))
             + "$AN_CEC_INPUT_AXIS[7]=(X1)\n$AN_CEC_OUTPUT_AXIS[7]=(Z1)\n$AN_CEC_STEP[7]=100\n"
               "$AN_CEC_MIN[7]=-100\n$AN_CEC_MAX[7]=100\n$AN_CEC_DIRECTION[7]=1\n"
               "$AN_CEC_MULT_BY_TABLE[7]=2\n$AN_CEC_IS_MODULO[7]=0\n")
    cecs = ["kinematics", "--from", str(wings["bcfit"]), "--current", "{dir}/A.MPF", "--current",
            "{dir}/cec.INI", "-o", "{dir}/K.MPF"]
    for name, c, r, expect in (
            ("a table this round adds to acts one way", cec.replace(first, first.replace("=0", "=1")), carr,
             "refuse"),
            ("an untouched table acts one way (good)", cec.removesuffix("M17\n") + extra + "M17\n", carr,
             "accept"),
            ("the record of another kind", cec, carr + '$TC_CARR23[1]="T"\n', "refuse")):
        out.append(Case("cec-state", name, {"cec.INI": c, "A.MPF": r}, cecs, expect, ["K.MPF"]))
    return out


# a column another writer fills, and what it may hold (JSON of any shape, or no JSON at all)
FOREIGN = {("fits", "parameters"): "json", ("fits", "model"): "json", ("fits", "fit_json"): "json",
           ("fits", "sigma_um"): "number", ("fits", "verdict"): "text", ("fits", "marker"): "text",
           ("sessions", "taken"): "text", ("sessions", "temperatures"): "json",
           ("sessions", "device"): "text", ("edits", "corrects"): "json", ("edits", "written"): "json",
           ("edits", "taken"): "text", ("edits", "controller"): "text", ("checks", "summary"): "json",
           ("checks", "passed"): "number", ("machines", "name"): "text"}
FOREIGN_TEXT = ("not a date", "2026-13-01", "", "x" * 5000, "a\nb", "\x1b[2J", "2026-04-01T00:00+14:00",
                "9999-12-31T23:59:59+00:00", "fit:000000")


def _foreign_value(rng: random.Random, what: str):
    """A value a writer outside compgen may append: well-typed for the column, any content."""
    def json_value(depth=0):
        shapes = [lambda: None, lambda: True, lambda: rng.choice([0, -1, 1e308, 2.5]), lambda: "x\n\x1b",
                  lambda: [json_value(depth + 1)], lambda: {"XOC": json_value(depth + 1)},
                  lambda: {"XOC": {"value": json_value(depth + 1), "std": json_value(depth + 1),
                                   "unit": "mm"}}]
        return rng.choice(shapes[:4] if depth >= 2 else shapes)()
    if what == "json":
        return rng.choice([json.dumps(json_value()), json.dumps(json_value()), "{", "", "NaN"])
    if what == "number":
        return rng.choice([float("nan"), float("inf"), -1, 2, "text", 1e30])
    return rng.choice(FOREIGN_TEXT)


def _foreign_store(store: Path, folder: Path, table: str, column: str, value) -> bytes:
    """``store`` with a session, its fit, an edit and a check of its machine (or a machine)
    appended by another writer, ``table``'s ``column`` holding ``value``."""
    import sqlite3
    db = folder / "h.sqlite"
    shutil.copy(store, db)
    with contextlib.closing(sqlite3.connect(db)) as raw, raw:
        raw.row_factory = sqlite3.Row
        fit = dict(raw.execute("SELECT * FROM fits ORDER BY id").fetchone())
        ids: dict[str, int] = {}
        for t in ("sessions", "fits", "edits", "checks", "machines"):
            if t in ("checks", "machines") and t != table:
                continue
            row = {"sessions": {"machine_id": 1, "taken": "2026-04-01T00:00:00+00:00", "device": "rtest",
                                "operator": "", "temperatures": "{}", "machine_sha256": "x", "data": "[]",
                                "recorded": "x"},
                   "fits": {**{k: v for k, v in fit.items() if k not in ("id", "content_sha256")},
                            "session_id": ids.get("sessions"), "marker": "fit:" + "0" * 16},
                   "edits": {"machine_id": 1, "fit_id": ids.get("fits"), "controller": "itnc530",
                             "corrects": "{}", "written": "{}", "loaded": "{}",
                             "taken": "2026-04-02T00:00:00+00:00", "recorded": "x"},
                   "checks": {"machine_id": 1, "fit_id": ids.get("fits"), "against_fit_id": fit["id"],
                              "passed": 1, "summary": "{}", "recorded": "x"},
                   "machines": {"name": "other", "serial": "", "recorded": "x"}}[t]
            if t == table:
                row[column] = value
            marks = ", ".join("?" * len(row))
            ids[t] = raw.execute(f"INSERT INTO {t} ({', '.join(row)}) VALUES ({marks})", list(row.values())
                                 ).lastrowid
    return db.read_bytes()


def foreign_row_cases(rng: random.Random, wings: dict[str, Path], per_column: int = 2) -> list[Case]:
    """A row another writer appended to an SQLite store (its writers are not held by the
    database), one column hostile: every command that reads the store either works or
    names the row in one line."""
    import sqlite3
    reads = (["history", "show", "--machine", str(SEED)], ["history", "trend", "--machine", str(SEED)],
             ["history", "fleet"], ["history", "list"], ["history", "export", "-o", "{dir}/x.json"],
             ["check", "--machine", str(SEED), str(wings["k4"]), "--date", "2026-06-01"])
    out = []
    folder = Path(tempfile.mkdtemp(dir=wings["store"].parent))
    for (table, column), what in FOREIGN.items():
        for _ in range(per_column):
            value = _foreign_value(rng, what)
            try:
                store = _foreign_store(wings["store"], folder, table, column, value)
            except sqlite3.IntegrityError:       # the database holds this one itself (NOT NULL)
                continue
            out += [Case("foreign-row", f"{table}.{column} = {str(value)[:40]!r}: {' '.join(args[:2])}",
                         {"h.sqlite": store}, [*args, "--db", "{dir}/h.sqlite"], "either") for args in reads]
    return out


def wing_inputs(work: Path, compgen: list[str]) -> dict[str, Path]:
    """The wings' valid inputs, made as a user makes them: a probe log, a history export and
    another store to import it into, a B/C machine's CEC tables and the fit for a second
    round, and LinuxCNC's own xyzac-trt sample with the seed machine's pins."""
    sys.path[:0] = [str(ROOT / "tests"), *(str(t.parent) for t in ROOT.glob("tests/*/test_linuxcnc.py"))]
    from test_linuxcnc import sample_copy  # the tests' copy of Debian's sample

    from compgen.configuration.machine_file import load_machine

    def run(*args):
        subprocess.run([*compgen, *map(str, args)], check=True, capture_output=True, cwd=work)

    truth = ROOT / "examples" / "truth-table4.json"
    run("simulate", "--machine", SEED, "--truth", truth, "--device", "probe", "--noise-um", "1",
        "-o", "probe.log")
    run("history", "add", FIT, "--db", "a.sqlite", "--date", "2026-03-01")
    run("kinematics", "--from", FIT, "-o", "E.txt", "--record", "--db", "a.sqlite", "--date", "2026-03-02",
        "--despite-gate")
    run("history", "export", "--db", "a.sqlite", "-o", "h.json")
    run("simulate", "--machine", SEED, "--truth", truth, "--paths", "K4", "-o", "k4.csv")
    run("history", "init", "--db", "target.sqlite")
    (work / "bt.json").write_text('{"parameters": {"ECC:h2c": {"value": 4e-5, "unit": "rad"}, '
                                  '"EYY:p1": {"value": 0.015, "unit": "mm"}}}')
    bc = "bc-table-sinumerik840d"
    for k in (1, 2):
        run("simulate", "--machine", bc, "--truth", "bt.json", "--paths", "K4,K1,K2", "--noise-um", "0.5",
            "--seed", k, "-o", f"bc{k}.csv")
        run("fit", "--machine", bc, f"bc{k}.csv", "-o", f"bc{k}0.json")
        run("fit", "--from", f"bc{k}0.json", "--add", "ECC:h2", "--add", "EYY:p1", "-o", f"bcfit{k}.json")
    run("kinematics", "--from", "bcfit1.json", "--current", ROOT / "examples" / "bc-tcarr-current.txt",
        "-o", "A.MPF")
    sample_copy(work / "trt", load_machine(str(SEED)))
    (work / "ht.json").write_text(json.dumps({"parameters": {
        "XOB": {"value": 0.01, "unit": "mm"}, "COB": {"value": 4e-5, "unit": "rad"},
        "YOC": {"value": -0.008, "unit": "mm"}}}))
    run("simulate", "--machine", HEAD, "--truth", "ht.json", "--noise-um", "0.5", "-o", "head.csv")
    run("fit", "--machine", HEAD, "head.csv", "-o", "hfit.json")
    from conftest import on_linuxcnc
    maxkins = on_linuxcnc(work)
    run("measure-program", "--machine", maxkins, "--path", "K4", "-o", "HK4.ngc")
    run("measure-program", "--machine", maxkins, "--path", "K4", "--probe-length", "220", "-o", "N.ngc")
    return {"hfit": work / "hfit.json", "maxkins": maxkins, "hprogram": work / "HK4.ngc",
            "nprogram": work / "N.ngc",
            "probe": work / "probe.log", "export": work / "h.json", "target": work / "target.sqlite",
            "cec": work / "A_CEC.INI", "carr": work / "A.MPF", "bcfit": work / "bcfit2.json",
            "trt": work / "trt", "head": work / "head.csv", "store": work / "a.sqlite", "k4": work / "k4.csv"}


def plan_cases() -> list[Case]:
    """compgen plan's inputs and the diagnosis kept beside a fit: minutes, noise and ρ at and
    past their edges, a folder that is a file, a machine without [program]; a kept file of
    any damage beside the fit the report reads (made again, never a crash)."""
    seed = SEED.read_text()
    plan = ["plan", "--machine", str(SEED), "--noise-um", "0.5"]
    out = [Case("plan", f"plan --minutes {m}", {}, [*plan, "--minutes", m, "-o", "{dir}/p"], expect, ["p"])
           for m, expect in (("nan", "refuse"), ("-inf", "refuse"), ("0", "refuse"), ("1e-9", "refuse"),
                             ("1e300", "refuse"), ("1,5", "refuse"), ("0.5", "refuse"), ("3", "accept"))]
    out += [Case("plan", f"plan {opt} {v}", {}, ["plan", "--machine", str(SEED), "--minutes", "3", opt, v,
                                                 "-o", "{dir}/p"], "refuse", ["p"])
            for opt, v in (("--noise-um", "0"), ("--noise-um", "nan"), ("--noise-um", "1e9"), ("--rho", "1"),
                           ("--rho", "-0.5"), ("--rho", "inf"))]
    out += [Case("plan", "plan -o a file", {"p": b"mine\n"}, [*plan, "--minutes", "3", "-o", "{dir}/p"],
                 "refuse", unchanged=["p"]),
            Case("plan", "plan without [program]", {"m.toml": re.sub(r"(?ms)^\[program\].*?\n\n", "", seed)},
                 ["plan", "--machine", "{dir}/m.toml", "--noise-um", "0.5", "--minutes", "5",
                  "-o", "{dir}/p"], "refuse", ["p"])]
    out += [Case("plan", f"plan --effects {e[:40]!r}", {},
                 [*plan, "--minutes", "5", "--effects", e, "-o", "{dir}/p"], expect, ["p"])
            for e, expect in (("", "refuse"), (",", "refuse"), ("ECC:h2", "refuse"),
                              ("ECC:h2,ECC:h2", "refuse"), ("ECC:h2,ECC:r1", "refuse"),
                              ("ECC:h2,EQQ:h9", "refuse"), ("ECC:h2,\n", "refuse"),
                              ("ECC:h2," + "E" * 5000, "refuse"), ("ECC:h2,EXC+EYC:h2", "accept"))]
    out += [Case("plan", "diagnose --plan into a file", {"p": b"mine\n"},
                 ["diagnose", "--from", "{dir}/fit.json", "--plan", "{dir}/p"], "refuse", unchanged=["p"])]
    kept = {"garbage": b"\x00\xff{", "empty": b"", "NaN": b"NaN", "object": b"{}",
            "wrong key": b'{"format": "compgen.kept-diagnosis/1", "key": {}, "diagnosis": {}}',
            "deep": b"[" * 100000, "foreign format": b'{"format": "compgen.fit/1"}'}
    out += [Case("plan", f"report with a kept diagnosis: {what}", {"fit.diagnosis.json": body},
                 ["report", "--from", "{dir}/fit.json", "-o", "{dir}/r.html"], "accept")
            for what, body in kept.items()]
    return out


def run_case(case: Case, work: Path, compgen: list[str]) -> tuple[Case, str, str]:
    folder = Path(tempfile.mkdtemp(dir=work))
    (folder / "fit.json").write_text(json.dumps(_absolute(json.loads(FIT.read_text()))))
    for name, content in case.files.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))
    if case.special == "fifo":
        os.mkfifo(folder / "data.csv")
    elif case.special == "fifo-store":
        os.mkfifo(folder / "pipe.sqlite")
    elif case.special == "dangling":
        (folder / "link.sqlite").symlink_to(folder / "nowhere" / "x.sqlite")
    args = [a.replace("{dir}", str(folder)) for a in case.args]
    steps, current = [], []
    for a in args:
        if a == "&&":
            steps.append(current)
            current = []
        else:
            current.append(a)
    steps.append(current)
    code, err = 0, ""
    before = {p.name for p in folder.iterdir()}
    for step in steps:
        try:
            done = subprocess.run([*compgen, *step], capture_output=True, text=True, timeout=60,
                                  cwd=folder, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return case, "hang", ""
        code, err = done.returncode, done.stderr
        if code != 0:
            break
    if "Traceback" in err or code == 3 or code not in (0, 1, 2):
        return case, "traceback", err.strip().splitlines()[-1] if err.strip() else f"exit {code}"
    if case.secret and (case.secret in err + done.stdout
                        or any(case.secret in p.name for p in folder.rglob("*"))):
        return case, "leaked", (err + done.stdout)[:200]
    written = [p for p in folder.iterdir() if p.name not in before and p.is_file()]
    block = re.compile(rf"(?m)^\s*\d*\s*{re.escape(EVIL)}")      # the text as a block of its own
    injected = [p.name for p in written if block.search(p.read_text("latin-1"))]
    if injected:
        return case, "injected", ", ".join(injected)
    if code == 1 and case.args[0] in ("check-program", "check") and done.stdout.strip():
        return case, "ok", done.stdout.strip().splitlines()[0][:160]     # the check's own verdict: found
    if case.expect in ("refuse", "either") and code != 0:
        lines = [ln for ln in err.splitlines() if ln.strip() and "warning" not in ln]
        if len(lines) != 1 or not lines[0].startswith("compgen: error:"):
            return case, "unclear refusal", err.strip()[:200]
        left = [o for o in case.outputs if (folder / o).exists() and o not in before]
        changed = [u for u in case.unchanged if (folder / u).read_bytes() != case.files[u]]
        if left or changed:
            return case, "half-written", ", ".join(left + changed)
        return case, "ok", lines[0][:160]
    if case.expect == "refuse":
        return case, "silent accept", ""
    if code != 0 and case.expect != "either":
        return case, "wrong refusal", err.strip()[:200]
    return case, "ok", ""


def main() -> None:
    global FIT
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--show", action="store_true", help="print every case's outcome")
    ap.add_argument("--generated", type=int, default=60, help="hostile variants per valid input (15 inputs)")
    args = ap.parse_args()
    compgen = [sys.executable, "-m", "compgen"]
    work = Path(tempfile.mkdtemp(prefix="compgen-fuzz-"))
    FIT = work / "fit.json"
    for step in (["fit", "--machine", str(SEED), str(SESSION), "-o", str(work / "fit0.json")],
                 ["fit", "--from", str(work / "fit0.json"), "--add", "EXC:h2", "-o", str(FIT)]):
        subprocess.run([*compgen, *step], check=True, capture_output=True, cwd=ROOT)
    programs = {}
    for ctl, ext in (("itnc530", "H"), ("sinumerik840d", "MPF"), ("linuxcnc", "ngc")):
        programs[ctl] = work / f"P{ctl[:3]}.{ext}"     # each its own pose list beside it
        subprocess.run([*compgen, "measure-program", "--machine", str(SEED), "--path", "K2",
                        "--controller", ctl, "-o", str(programs[ctl])],
                       check=True, capture_output=True, cwd=ROOT)
    wings = wing_inputs(work, compgen)
    rng = random.Random(args.seed)
    cases = [*csv_cases(rng), *machine_cases(), *fit_cases(), *current_cases(), *output_cases(),
             *history_cases(), *nest_cases(wings), *shop_cases(wings), *second_look_cases(),
             *foreign_row_cases(rng, wings), *plan_cases(),
             *derived_cases(rng, programs, args.generated, wings)]
    t0 = time.perf_counter()
    with ThreadPoolExecutor(args.jobs) as pool:
        results = list(pool.map(lambda c: run_case(c, work, compgen), cases))
    shutil.rmtree(work, ignore_errors=True)
    kinds = sorted({c.kind for c in cases})
    outcomes = ["ok", "traceback", "silent accept", "injected", "hang", "wrong refusal", "unclear refusal",
                "half-written", "leaked"]
    print(f"{len(cases)} cases in {time.perf_counter() - t0:.0f} s (seed {args.seed})")
    print(f"{'kind':<12}{'cases':>6}" + "".join(f"{o:>16}" for o in outcomes))
    for k in kinds:
        mine = [r for r in results if r[0].kind == k]
        print(f"{k:<12}{len(mine):>6}" + "".join(f"{sum(r[1] == o for r in mine):>16}" for o in outcomes))
    print(f"{'all':<12}{len(results):>6}"
          + "".join(f"{sum(r[1] == o for r in results):>16}" for o in outcomes))
    for case, outcome, detail in results:
        if outcome != "ok" or args.show:
            print(f"  {outcome:<16}{case.kind}: {case.name!r}: {detail}")
    sys.exit(0 if all(r[1] == "ok" for r in results) else 1)


if __name__ == "__main__":
    main()
