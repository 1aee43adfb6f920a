"""What a shop leaves set on a HEIDENHAIN or SINUMERIK control stops compgen's programs
before their tool call: a basic rotation, a rotation, a mirrored axis, a scaling factor, a
shift of a rotary axis (LinuxCNC's offsets: test_work_offsets.py, with rs274). No HEIDENHAIN
or SINUMERIK interpreter runs here: the guards are run by the small readers below, which
take the blocks as the manuals define them (FN 18 reads a system datum, FN 9 jumps when
equal, FN 14 stops with an error; an IF's condition, MSG, M0, M30) and are written apart
from compgen's. check-program refuses a program without its guard, with one edited or with
the guard after the tool call."""

import re

import pytest
from conftest import BC_MACHINE, SEED_MACHINE, run

NEUTRAL_TNC = {"ID210 NR1": 0.0, "ID210 NR2": 0.0, "ID210 NR3": 0.0,
               "ID210 NR4 IDX1": 1.0, "ID210 NR4 IDX2": 1.0, "ID210 NR4 IDX3": 1.0}
LEFT_TNC = {"basic rotation 0.5 deg": ("ID210 NR1", 0.5, "a basic rotation"),
            "cycle 10 ROT 90": ("ID210 NR2", 90.0, "a rotation (cycle 10)"),
            "mirrored X": ("ID210 NR3", 1.0, "a mirrored axis"),
            "scaling 0.9999 in Z": ("ID210 NR4 IDX3", 0.9999, "a scaling factor in Z")}


def _tnc_run(text: str, state: dict[str, float]) -> tuple[str, str]:
    """Run a Klartext program's blocks up to its tool call: ("tool", "") when it gets there,
    ("error", the FN 14 block's comment) when it stops."""
    blocks = [re.sub(r"^\d+\s*", "", ln) for ln in text.splitlines()]
    q: dict[str, float] = {}
    k = 0
    while k < len(blocks):
        b = blocks[k]
        code = b.split(";", 1)[0].strip()
        if code.startswith("TOOL CALL"):
            return "tool", ""
        if code.startswith("L "):
            return "move", b
        if (m := re.fullmatch(r"FN 18: SYSREAD (Q\d+) = (.+)", code)) is not None:
            q[m[1]] = state[m[2]]
        elif (m := re.fullmatch(r"FN 9: IF \+(Q\d+) EQU \+(\S+) GOTO LBL (\d+)", code)) is not None:
            if q[m[1]] == float(m[2]):
                k = blocks.index(f"LBL {m[3]}")
        elif code.startswith("FN 14: ERROR"):
            return "error", b.split(";", 1)[1]
        k += 1
    return "end", ""


@pytest.fixture(scope="module")
def programs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("guards")
    out = {}
    for machine, name, kind in ((SEED_MACHINE, "RT.H", "measure-program"),
                                (SEED_MACHINE, "PR.H", "probe-program"),
                                (BC_MACHINE, "RT.MPF", "measure-program"),
                                (BC_MACHINE, "PR.MPF", "probe-program")):
        mode = ["--mode", "axes"] if kind == "measure-program" else []
        (folder / name).mkdir()                   # each beside its own pose list
        code, _, err = run(kind, "--machine", machine, "--path", "K1", *mode, "-o", folder / name / name)
        assert code == 0, err
        out[name] = (folder / name / name).read_text()
    return out


@pytest.mark.parametrize("name", ["RT.H", "PR.H"])
def test_a_heidenhain_program_stops_on_each_state_a_shop_leaves(programs, name):
    assert _tnc_run(programs[name], NEUTRAL_TNC) == ("tool", "")
    for item, value, said in LEFT_TNC.values():
        got, comment = _tnc_run(programs[name], {**NEUTRAL_TNC, item: value})
        assert got == "error" and said in comment and "Cancel it" in comment, (item, got, comment)


def _frame_run(text: str, frame: dict[tuple[str, str], float]) -> tuple[str, str]:
    """Run a SINUMERIK program up to its tool call: each IF's condition on the total frame
    ($P_ACTFRAME[axis, component]: 0 unless given, 1 for SC); ("stop", its MSG) when one holds."""
    lines = [ln.split(";", 1)[0].strip() for ln in text.splitlines()]
    for k, b in enumerate(lines):
        if b.startswith("T="):
            return "tool", ""
        if re.match(r"G[01] ", b):
            return "move", b
        if b.startswith("IF ($P_ACTFRAME"):
            terms = re.findall(r"\(\$P_ACTFRAME\[(\w+),(\w+)\]<>(\S+?)\)", b)
            if any(frame.get((a, c), 1.0 if c == "SC" else 0.0) != float(v) for a, c, v in terms):
                assert lines[k + 2:k + 4] == ["M0", "M30"], lines[k:k + 5]
                return "stop", lines[k + 1]
    return "end", ""


@pytest.mark.parametrize("name", ["RT.MPF", "PR.MPF"])
def test_a_sinumerik_program_stops_on_each_frame_state_a_shop_leaves(programs, name):
    assert _frame_run(programs[name], {}) == ("tool", "")
    left = {("Z", "RT"): (0.5, "a rotation"), ("X", "MI"): (1.0, "a mirrored axis"),
            ("Y", "SC"): (0.9999, "a scaling factor"), ("C", "TR"): (10.0, "a shift of a rotary axis"),
            ("B", "FI"): (0.001, "a shift of a rotary axis")}
    for key, (value, said) in left.items():
        got, msg = _frame_run(programs[name], {key: value})
        assert got == "stop" and said in msg and key[0] in msg, (key, got, msg)


EDITS = {
    ".H": [("no guard", lambda t: "\n".join(ln for ln in t.splitlines()
                                           if not re.match(r"\d+ (FN (18|9|14)|LBL 9)", ln)) + "\n",
            "must stop unless no basic rotation"),
           ("scaling let through", lambda t: t.replace("EQU +1 GOTO LBL 96", "EQU +0 GOTO LBL 96"),
            "starts a guard that is not compgen's"),
           ("guard after the tool call",
            lambda t: _after_tool(t, r"\d+ (FN (18|9|14)|LBL 9)", r"\d+ TOOL CALL"),
            "must stop unless no basic rotation")],
    ".MPF": [("no guard", lambda t: re.sub(r"IF \(\$P_ACTFRAME.*?ENDIF\n", "", t, flags=re.S),
              "must stop unless the active frame"),
             ("scaling read against 0", lambda t: t.replace("[Z,SC]<>1", "[Z,SC]<>0"),
              "does not read Z,SC against its neutral value"),
             ("C's fine shift left out", lambda t: t.replace(" OR ($P_ACTFRAME[C,FI]<>0)", ""),
              "does not read C,FI"),
             ("guard after the tool call", lambda t: _after_tool(t, None, r"T=\""),
              "must stop unless the active frame")],
}


def _after_tool(text: str, guard: str | None, tool: str) -> str:
    """The program with its guard blocks moved after its tool call (M6, D1 for SINUMERIK)."""
    lines = text.splitlines()
    if guard is None:
        first = next(i for i, ln in enumerate(lines) if ln.startswith("IF ($P_ACTFRAME"))
        last = max(i for i, ln in enumerate(lines) if ln == "ENDIF" and i < first + 40)
        block, rest = lines[first:last + 1], lines[:first] + lines[last + 1:]
        at = next(i for i, ln in enumerate(rest) if re.match(tool, ln)) + 3
    else:
        block = [ln for ln in lines if re.match(guard, ln)]
        rest = [ln for ln in lines if not re.match(guard, ln)]
        at = next(i for i, ln in enumerate(rest) if re.match(tool, ln)) + 1
    return "\n".join(rest[:at] + block + rest[at:]) + "\n"


@pytest.mark.parametrize("ext, what, change, says", [(ext, *c) for ext, cs in EDITS.items() for c in cs],
                         ids=[f"{ext}-{c[0]}" for ext, cs in EDITS.items() for c in cs])
def test_check_program_refuses_a_program_without_its_state_guard(programs, tmp_path, ext, what, change, says):
    machine = SEED_MACHINE if ext == ".H" else BC_MACHINE
    text = programs[f"RT{ext}"]
    path = tmp_path / f"X{ext}"
    path.write_text(text)
    assert run("check-program", "--machine", machine, path)[0] == 0
    changed = change(text)
    assert changed != text
    path.write_text(changed)
    code, _, err = run("check-program", "--machine", machine, path)
    assert code == 2 and says in err and len(err.strip().splitlines()) == 1, (what, err)
