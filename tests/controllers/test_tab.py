"""HEIDENHAIN description tables as a control keeps them: fixed-width columns, a column
description block, CRLF line ends, columns compgen does not use, INCH units. An edit changes
only the cells it must and keeps every other byte."""

import re
from dataclasses import replace

import numpy as np
import pytest
from conftest import ARCSEC, UM

from compgen.controllers import heidenhain
from compgen.controllers.correction import nominal_lines, plan
from compgen.controllers.kinematics import kinematics_edit
from compgen.controllers.tab import TabTable
from compgen.data.simulate import simulate
from compgen.errors import CompgenError
from compgen.model.paths import generate
from compgen.statistics.identify import identify

TRUTH = {"YOA": 20.5 * UM, "ZOA": 32.5 * UM, "BOA": 12.3 * ARCSEC, "COA": -7.2 * ARCSEC,
         "XOC": 1.4 * UM, "YOC": -15.9 * UM, "AOC": -6.5 * ARCSEC, "BOC": -4.6 * ARCSEC}
COLS = "NR   KEY        AXIS  COORD         FILE                DOC               COMPTAB"
STRUCT = ["#STRUCTBEGIN", "   NAME = NR", "     TYPE = C", "     WIDTH = 4", "     DEC = 0",
          "   NAME = COORD", "     TYPE = N", "     WIDTH = 13", "     DEC = 5",
          "     DIA-GERMAN = Wert", "#STRUCTEND"]


def _table(unit="MM", zc="+29.794", y0a="+0.01000", newline="\r\n"):
    rows = [
        "0    Trans      Z     +0                                spindle gauge line",
        "1    MachAxis   Z",
        "2    MachAxis   Y",
        "3    MachBase",
        "4    MachAxis   X                   PLC:\\KINEMAT\\X.CMO",
        "5    Trans      Z     +0                                to A/C",
        f"6    Trans      Y     {y0a:<13} {'':<19} Y0A",
        "7    MachAxis   A                                                         COMP_A.COM",
        f"8    Trans      Y     {'-' + y0a[1:]:<13} {'':<19} -Y0A",
        f"9    Trans      Z     {zc:<13} {'':<19} Zc",
        "10   MachAxis   C",
        "[END]", "; kept after END", ""]
    return newline.join([f"BEGIN KINEMATIC_AC.TAB {unit}".rstrip(), *STRUCT, COLS, *rows])


@pytest.fixture(scope="module")
def fit(seed_machine):
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    return identify(seed_machine, [simulate(seed_machine, TRUTH, poses)])


def _edit(machine, fit, text):
    return kinematics_edit(machine, fit, "itnc530", text, "KIN.TAB", "KIN", "0", "d").files[".TAB"]


def test_an_edit_keeps_every_byte_it_does_not_change(seed_machine, fit):
    before = _table()
    after = _edit(seed_machine, fit, before)
    assert after.count("\r\n") == after.count("\n"), "line ends are the table's own (CRLF)"
    old, new = before.split("\r\n"), after.split("\r\n")
    assert new[:len(STRUCT) + 2] == old[:len(STRUCT) + 2]          # BEGIN, description, header
    assert new[-3:] == old[-3:]                                     # [END] and what follows
    kept = [ln for ln in old if ln not in new]
    # only Y0A/-Y0A (COORD increased) and the renumbered rows after the insertions differ
    assert all(("Y0A" in ln) or ln[:5].strip().isdigit() for ln in kept), kept
    table = TabTable.parse(after, "new")
    assert table.columns == COLS.split() and table.unit == "MM"
    for r in table.rows:                       # inserted rows sit in the columns
        assert r["KEY"] in ("Trans", "MachAxis", "MachBase")
        if r["DOC"].lstrip("-")[:1] in "XYZABC" and r["DOC"][-2:-1] == "0":
            assert r["FILE"] == "" and r["COMPTAB"] == "" and float(r["COORD"]) != 0
    assert [int(r["NR"]) for r in table.rows] == list(range(len(table.rows)))
    machaxis_a = next(r for r in table.rows if r["KEY"] == "MachAxis" and r["AXIS"] == "A")
    assert machaxis_a["COMPTAB"] == "COMP_A.COM"
    assert sum(r["DOC"].split()[:1] == ["Y0A"] for r in table.rows) == 1
    for k, r in enumerate(table.rows):         # untouched cells are untouched
        if r["DOC"].split()[:1] == ["Y0A"]:
            assert float(r["COORD"]) == pytest.approx(0.01 + plan(seed_machine, fit).lines["A"].offset[1],
                                                      abs=0.5e-5)
            line = after.split("\r\n")[table.row_at[k]]
            # the same columns; the name gains the fit's marker
            assert len(line) == len(before.split("\r\n")[len(STRUCT) + 2 + 6]) + len(f" {fit.marker}")


def test_inch_tables_get_inch_and_read_back_in_mm(seed_machine, fit):
    mm = _edit(seed_machine, fit, _table())
    inch = _edit(seed_machine, fit, _table(unit="INCH", zc=f"+{29.794 / 25.4:.6f}",
                                         y0a=f"+{0.01 / 25.4:.6f}"))
    nominal = nominal_lines(seed_machine)
    a, b = (heidenhain.read_lines(t, seed_machine, nominal) for t in (mm, inch))
    for axis in a:
        # the description block gives COORD 5 decimals: 1e-5 inch = 0.254 µm, rounded to half
        np.testing.assert_allclose(b[axis].offset, a[axis].offset, atol=0.5e-5 * 25.4 + 0.5e-5)
        np.testing.assert_allclose(b[axis].tilt, a[axis].tilt, atol=1e-12)
    x0c = next(r for r in TabTable.parse(inch, "i").rows if r["DOC"].split()[:1] == ["X0C"])
    assert float(x0c["COORD"]) == pytest.approx(plan(seed_machine, fit).lines["C"].offset[0] / 25.4,
                                                abs=0.5e-5)


@pytest.mark.parametrize("text, message", [
    (_table(unit=""), "states no unit"),
    (_table(zc="+30.500"), "the table puts the C axis at (0.0000, 0.0000, 30.5000) mm"),
    (_table().replace("COORD         FILE", "COORD FILE        "), "holds 5"),
])
def test_tables_that_would_mislead_are_refused(seed_machine, fit, text, message):
    with pytest.raises(CompgenError, match=message.replace("(", r"\(").replace(")", r"\)")):
        _edit(seed_machine, fit, text)


def test_a_small_pivot_difference_passes(seed_machine, fit):
    assert _edit(seed_machine, fit, _table(zc="+29.7945"))


NEW_STYLE = [
    "TableDescription (",
    "  columns:=[",
    "    CfgColumnDescription (",
    '      key:="COORD"',
    "      width:=13",
    "      decimals:=3",
    "    )",
    "    CfgColumnDescription (",
    '      key:="DOC"',
    "      decimals:=0",
    "    )",
    "  ]",
    ")",
]


def test_a_new_style_description_block_is_kept_and_its_decimals_honoured(seed_machine, fit):
    before = _table(newline="\n").split("\n")
    old_block = len(STRUCT)
    text = "\n".join([before[0], *NEW_STYLE, "", *before[1 + old_block:]])   # a blank line too
    table = TabTable.parse(text, "t")
    assert table.decimals == {"COORD": 3, "DOC": 0} and table.columns == COLS.split()
    # 3 decimals (1 µm) lose 0.5 µm of Y0A: beyond this noiseless fit's uncertainty, refused
    with pytest.raises(CompgenError, match=r"round Y0A to \+0\.030: 0\.5 um of the correction lost"):
        kinematics_edit(seed_machine, fit, "itnc530", text, "KIN.TAB", "KIN", "0", "d")
    # with uncertainties of 1 µm and 2″ the same rounding (0.5 µm, 1.8″ at most) is within them
    fit = replace(fit, parameters={n: replace(e, std=1e-3 if e.unit == "mm" else 2 * ARCSEC)
                                   for n, e in fit.parameters.items()})
    emitted = kinematics_edit(seed_machine, fit, "itnc530", text, "KIN.TAB", "KIN", "0", "d")
    after = emitted.files[".TAB"].split("\n")
    assert after[:len(NEW_STYLE) + 3] == text.split("\n")[:len(NEW_STYLE) + 3]
    y0a = next(r for r in TabTable.parse(emitted.files[".TAB"], "n").rows if r["DOC"].split()[:1] == ["Y0A"])
    assert re.fullmatch(r"[+-]\d+\.\d{3}", y0a["COORD"]), y0a["COORD"]
    assert any("3 decimals" in n and "1 um" in n for n in emitted.notes), emitted.notes


def test_an_old_style_block_gives_each_column_its_decimals():
    table = TabTable.parse(_table(newline="\n"), "t")
    assert table.decimals == {"NR": 0, "COORD": 5}


def test_an_inch_table_without_declared_decimals_gets_one_more_decimal(seed_machine, fit):
    text = _table(unit="INCH", zc=f"+{29.794 / 25.4:.6f}", y0a="+0.000394", newline="\n")
    text = "\n".join(ln for ln in text.split("\n") if not ln.startswith(("#", "   ", "     ")))
    assert TabTable.parse(text, "t").decimals == {}
    tab = kinematics_edit(seed_machine, fit, "itnc530", text, "KIN.TAB", "KIN", "0", "d").files[".TAB"]
    x0c = next(r for r in TabTable.parse(tab, "n").rows if r["DOC"].split()[:1] == ["X0C"])
    assert re.fullmatch(r"[+-]\d+\.\d{6}", x0c["COORD"]), x0c["COORD"]      # 1e-6 inch = 0.0254 µm


@pytest.mark.parametrize("unit, dec, noted", [
    ("MM", 5, False),       # 1e-5 mm = 0.01 µm: compgen's own resolution
    ("MM", 4, True),        # 0.1 µm
    ("INCH", 6, True),      # 1e-6 inch = 0.0254 µm, coarser than 0.01 µm
    ("INCH", 7, False),     # 0.00254 µm
])
def test_the_resolution_note_appears_exactly_when_the_table_is_coarser(seed_machine, fit, unit, dec, noted):
    zc = f"+{29.794:.{dec}f}" if unit == "MM" else f"+{29.794 / 25.4:.{dec}f}"
    text = _table(unit=unit, zc=zc, y0a=f"+{0.01 / (25.4 if unit == 'INCH' else 1):.{dec}f}",
                  newline="\n").replace("     DEC = 5", f"     DEC = {dec}")
    notes = kinematics_edit(seed_machine, fit, "itnc530", text, "KIN.TAB", "KIN", "0", "d").notes
    assert any(f"COORD has {dec} decimals (table description): linear" in n for n in notes) == noted, notes
    # rotations (deg, 7 decimals = 0.00036″ in compgen) are rounded coarser below 7 decimals
    assert any(f"COORD has {dec} decimals: rotations" in n for n in notes) == (dec < 7), notes


def test_the_pivot_check_takes_offsets_up_to_the_limit(seed_machine, fit):
    """[limits] offset_um = 100: a table 80 µm off the machine file passes, 120 µm does not."""
    assert _edit(seed_machine, fit, _table(zc="+29.874"))
    with pytest.raises(CompgenError, match="puts the C axis at"):
        _edit(seed_machine, fit, _table(zc="+29.914"))


def test_rotation_rows_turn_the_frame_and_every_pivot_is_checked(seed_machine, fit):
    """A rotation row turns the frame the later rows act in; the check goes on through it
    (before, it stopped at the first one, so on an edited table C was never checked)."""
    small = _table(newline="\n").replace("5    Trans      Z     +0                                to A/C",
                                         "5    Trans      B     +0.0015                           OEM tilt")
    notes = kinematics_edit(seed_machine, fit, "itnc530", small, "KIN.TAB", "KIN", "0", "d").notes
    assert not any("pivot check" in n for n in notes), notes      # 5.4″ over 30 mm: 0.8 µm
    # 0.5° left in the chain puts C 0.26 mm off its place in X: refused, as any misplaced axis
    turned = small.replace("+0.0015 ", "+0.5    ")
    with pytest.raises(CompgenError, match=r"the table puts the C axis at \(0\.26"):
        kinematics_edit(seed_machine, fit, "itnc530", turned, "KIN.TAB", "KIN", "0", "d")
    # an edited table (its tilt rows in pairs about each axis) is checked whole the next round
    edited = _edit(seed_machine, fit, _table(newline="\n"))
    assert "Trans      B" in edited or "Trans B" in edited.replace("  ", " ")
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    again = identify(seed_machine, [simulate(seed_machine, TRUTH, poses, 0.5, np.random.default_rng(4))])
    notes = kinematics_edit(seed_machine, again, "itnc530", edited, "KIN.TAB", "KIN", "0", "d",
                            force=True).notes
    assert not any("pivot check" in n for n in notes), notes


SQUARE = {"COX": 5 * ARCSEC, "BOZ": -4 * ARCSEC}


@pytest.fixture(scope="module")
def square_fit(seed_machine):
    from compgen.model.effects import location_model
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    return identify(seed_machine, [simulate(seed_machine, TRUTH | SQUARE, poses)],
                    [*location_model(seed_machine), *SQUARE])


def test_the_change_list_reads_back_as_the_table_does(seed_machine, square_fit):
    """The .txt change list and the edited .TAB of one edit hold the same lines and
    squareness when read (the change list is what `simulate --edit` and --measured-with
    may be given)."""
    files = kinematics_edit(seed_machine, square_fit, "itnc530", _table(newline="\n"), "KIN.TAB", "KIN",
                            "0", "d").files
    nominal = nominal_lines(seed_machine)
    from_txt = heidenhain.read_lines(files[".txt"], seed_machine, nominal)
    want = plan(seed_machine, square_fit).lines
    for axis, line in want.items():
        np.testing.assert_allclose(from_txt[axis].offset, line.offset, atol=0.5e-5)
        np.testing.assert_allclose(from_txt[axis].tilt, line.tilt, atol=1e-9)
    # the change list has 7 decimals of a degree; this table declares 5 (half of 1e-5°)
    for text, tol in ((files[".txt"], 0.5e-7), (files[".TAB"], 0.5e-5)):
        square = heidenhain.read_squareness(text, seed_machine)
        assert set(square) == set(SQUARE)
        for name, value in SQUARE.items():
            assert square[name] == pytest.approx(value, abs=np.radians(tol) * 1.01), name


def test_since_is_what_the_control_holds_beyond_the_measured_state(seed_machine, square_fit):
    """--measured-with: the table then, the table now; their difference row by row."""
    then = _table(newline="\n")
    now = kinematics_edit(seed_machine, square_fit, "itnc530", then, "KIN.TAB", "KIN", "0", "d").files[".TAB"]
    held = heidenhain.ITNC530().since(seed_machine, then, now, "now")
    want = plan(seed_machine, square_fit)
    for axis, line in want.lines.items():
        np.testing.assert_allclose(held.lines[axis].offset, line.offset, atol=0.5e-5)
        np.testing.assert_allclose(held.lines[axis].tilt, line.tilt, atol=np.radians(0.5e-5) * 1.01)
    assert held.squareness == pytest.approx(want.squareness, abs=np.radians(0.5e-5) * 1.01)
    back = heidenhain.ITNC530().since(seed_machine, now, then, "then")       # and the other way
    assert back.squareness == pytest.approx({k: -v for k, v in want.squareness.items()},
                                            abs=np.radians(0.5e-5) * 1.01)
    for axis, line in want.lines.items():
        np.testing.assert_allclose(back.lines[axis].tilt, -line.tilt, atol=np.radians(0.5e-5) * 1.01)


def test_a_positioning_table_goes_to_the_comp_csv_with_the_values_that_cancel(seed_machine):
    """ECC:h2 (C's angle error 8″·cos 2C) on an iTNC 530: a table over C, -8″·cos 2C in deg."""
    from compgen.model.effects import location_model
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    truth = {"XOC": 2 * UM, "ECC:h2c": 8 * ARCSEC}
    fit = identify(seed_machine, [simulate(seed_machine, truth, poses)],
                   [*location_model(seed_machine), "ECC:h2c", "ECC:h2s"])
    csv = kinematics_edit(seed_machine, fit, "itnc530", None, "", "KIN", "0", "d").files[".comp.csv"]
    rows = [ln.split(",") for ln in csv.strip().splitlines() if ln.startswith("ECC:h2,")]
    assert {(r[1], r[3], r[5]) for r in rows} == {("C", "C", "deg")}
    c = np.array([float(r[2]) for r in rows])
    value = np.array([float(r[4]) for r in rows])
    assert c[0] == 0 and c[-1] == 360 and len(c) == 37
    np.testing.assert_allclose(value, -8 / 3600 * np.cos(np.radians(2 * c)), atol=0.6e-6)   # 6 decimals


@pytest.mark.parametrize("width, carries", [(16, True), (15, False)])
def test_the_fit_marker_goes_into_the_doc_only_where_it_fits(seed_machine, fit, width, carries):
    """"-X0A fit:xxxxxx" is 15 characters; a column keeps a space before the next one."""
    cols = COLS.replace("DOC               ", "DOC".ljust(width))
    text = _table(newline="\n").replace(COLS, cols)
    lines = text.split("\n")
    doc_at = cols.index("DOC")
    for i, ln in enumerate(lines):      # move the COMPTAB cells to the new column start
        if ln.rstrip().endswith("COMP_A.COM"):
            lines[i] = ln.rstrip()[:-len("COMP_A.COM")].rstrip().ljust(doc_at + width) + "COMP_A.COM"
    emitted = kinematics_edit(seed_machine, fit, "itnc530", "\n".join(lines), "KIN.TAB", "KIN", "0", "d")
    rows = TabTable.parse(emitted.files[".TAB"], "n").rows
    y0a = next(r for r in rows if r["DOC"].split()[:1] == ["Y0A"])
    assert (y0a["DOC"] == f"Y0A {fit.marker}") == carries, y0a["DOC"]
    assert any("cannot carry the fit's marker" in n for n in emitted.notes) != carries


def test_table_rows_without_their_header_read_as_the_table(seed_machine, square_fit):
    """Rows copied out of a table (no BEGIN line, NR first, the name last) read as the table."""
    tab = kinematics_edit(seed_machine, square_fit, "itnc530", _table(newline="\n"), "KIN.TAB", "KIN", "0",
                          "d").files[".TAB"]
    rows = "\n".join(ln for ln in tab.split("\n") if ln[:1].isdigit())
    nominal = nominal_lines(seed_machine)
    whole, part = (heidenhain.read_lines(t, seed_machine, nominal) for t in (tab, rows))
    for axis in whole:
        np.testing.assert_allclose(part[axis].offset, whole[axis].offset, atol=1e-12)
        np.testing.assert_allclose(part[axis].tilt, whole[axis].tilt, atol=1e-12)
    assert heidenhain.read_squareness(rows, seed_machine) == pytest.approx(
        heidenhain.read_squareness(tab, seed_machine), abs=1e-15)


def test_a_table_whose_decimals_round_the_correction_away_is_refused(seed_machine, fit):
    """COORD declared with 0 decimals: the 16 rows would be written +0 while the sign check
    expects the change (issue 21)."""
    text = _table(newline="\n").replace("     DEC = 5", "     DEC = 0")
    with pytest.raises(CompgenError, match="of the correction lost, beyond its uncertainty"):
        kinematics_edit(seed_machine, fit, "itnc530", text, "KIN.TAB", "KIN", "0", "d")


@pytest.mark.parametrize("line", ["     DEC = abc", "     DEC = -2", "     DEC", "   NAME"])
def test_a_damaged_column_description_is_refused_with_its_line(line):
    text = _table(newline="\n").replace("     DEC = 5", line)
    k = 1 + text.split("\n").index(line)
    with pytest.raises(CompgenError, match="in the column description") as e:
        TabTable.parse(text, "t.TAB")
    assert e.value.where == f"t.TAB:{k}"


def test_a_table_with_cr_line_ends_is_edited_and_keeps_them(seed_machine, fit):
    after = _edit(seed_machine, fit, _table(newline="\r"))
    assert "\n" not in after and after.count("\r") > 20
    assert TabTable.parse(after, "new").rows


def test_a_latin1_table_is_written_back_in_latin1(seed_machine, fit, tmp_path):
    from conftest import run

    from compgen.data.rtest import format_rtest
    data = simulate(seed_machine, TRUTH, generate(seed_machine, ["K4"]), 0.3, np.random.default_rng(3))
    (tmp_path / "k4.csv").write_text(format_rtest(seed_machine, data))
    rc, _, err = run("fit", "--machine", "ac-trunnion-itnc530", tmp_path / "k4.csv",
                     "-o", tmp_path / "fit.json")
    assert rc == 0, err
    text = _table().replace("spindle gauge line", "Spindel Meßlinie 0°")
    (tmp_path / "KIN.TAB").write_bytes(text.encode("latin-1"))
    rc, out, err = run("kinematics", "--from", tmp_path / "fit.json", "--current", tmp_path / "KIN.TAB",
                       "-o", tmp_path / "NEW.TAB", "--force")
    raw = (tmp_path / "NEW.TAB").read_bytes()
    assert rc == 0, out + err
    assert "Spindel Meßlinie 0°".encode("latin-1") in raw and "ß".encode() not in raw
    assert raw.decode("latin-1").count("\r\n") > 20


def test_an_angle_rounded_away_is_told_in_arcseconds(seed_machine, fit):
    """An angle row the declared decimals round beyond its uncertainty: the loss and the bound
    are printed in arcseconds (3 decimals of a degree lose at most 1.8″; the bound is compgen's
    own 0.25″ where the fit's σ is smaller)."""
    before = _table(newline="\n").split("\n")
    text = "\n".join([before[0], *NEW_STYLE, "", *before[1 + len(STRUCT):]])
    fit = replace(fit, parameters={n: replace(e, std=1e-3 if e.unit == "mm" else 0.1 * ARCSEC)
                                   for n, e in fit.parameters.items()})
    with pytest.raises(CompgenError) as caught:
        kinematics_edit(seed_machine, fit, "itnc530", text, "KIN.TAB", "KIN", "0", "d")
    said = re.search(r"round (-?[ABC]0[A-Z]) to (\S+): (\S+) arcsec of the correction lost, beyond its "
                     r"uncertainty (\S+) arcsec", caught.value.message)
    assert said, caught.value.message
    assert 0.25 < float(said[3]) <= 1.8 and said[4] == "0.25"


@pytest.mark.parametrize("cut, message, line", [
    (lambda t: t.replace(COLS + "\n", ""), "no header line with NR and KEY", 13),
    (lambda t: t.split("[END]")[0], "no [END] line", None),
    (lambda t: t.replace("#STRUCTEND\n", "").split(COLS)[0], "the column-description block does not end", 2),
    (lambda t: t.replace("#STRUCTBEGIN", "TableDescription (").split(COLS)[0],
     "the column-description block does not end", 2),
])
def test_a_table_cut_short_is_refused_where_it_ends(cut, message, line):
    """A table without its header line, its [END] or the end of its column description
    (either style) is refused at the line where what is missing was looked for."""
    text = cut(_table(newline="\n"))
    with pytest.raises(CompgenError, match=re.escape(message)) as e:
        TabTable.parse(text, "t.TAB")
    assert e.value.where == ("t.TAB" if line is None else f"t.TAB:{line}")


def test_blank_lines_between_rows_are_no_rows():
    """A blank line among the rows (an editor's, or the control's after a deleted row) is
    passed over: the table's rows and their line numbers are those of the rows."""
    text = _table(newline="\n").replace("3    MachBase\n", "3    MachBase\n\n   \n")
    table = TabTable.parse(text, "t.TAB")
    lines = text.split("\n")
    assert [r["NR"] for r in table.rows] == [str(k) for k in range(11)]
    assert [lines[k].split()[0] for k in table.row_at] == [str(k) for k in range(11)]
