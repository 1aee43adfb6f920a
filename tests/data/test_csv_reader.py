"""The R-test CSV's two readers: numpy's path for a well-formed file and the careful reader
that names the first fault. They must give the same table wherever the fast one answers,
and the fast one must step aside (None) wherever a file is not plainly well formed."""

import numpy as np
import pytest
from conftest import SEED_MACHINE

from compgen.configuration.machine_file import load_machine
from compgen.data import rtest
from compgen.data.rtest import RTestData, format_rtest, read_poses, read_rtest
from compgen.errors import CompgenError
from compgen.model.paths import generate

MACHINE = load_machine(SEED_MACHINE)


def _session(labels=("K4", "K1", "K2")) -> str:
    poses = generate(MACHINE, list(labels))
    dev = np.random.default_rng(1).normal(0, 1e-3, (len(poses), 3))
    return format_rtest(MACHINE, RTestData(poses, dev), ("a comment",))


def _both(tmp_path, text: str, monkeypatch):
    f = tmp_path / "s.csv"
    f.write_bytes(text.encode())
    used = []
    original = rtest._fast_table
    monkeypatch.setattr(rtest, "_fast_table", lambda *a: used.append(original(*a)) or used[-1])
    fast = read_rtest(f, MACHINE)
    monkeypatch.setattr(rtest, "_fast_table", lambda *a: None)
    careful = read_rtest(f, MACHINE)
    return fast, careful, used[-1] is not None


def _move_column(text: str, name: str, to: int) -> str:
    out = []
    for line in text.splitlines():
        if line.startswith("#"):
            out.append(line)
            continue
        cells = line.split(",")
        i = text.splitlines()[1].split(",").index(name)
        cell = cells.pop(i)
        cells.insert(to if to >= 0 else len(cells) + 1 + to, cell)
        out.append(",".join(cells))
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("variant", ["as written", "path in the middle", "path last", "CRLF",
                                     "labels of several widths", "no trailing newline",
                                     "path last, the widest label first, no trailing newline",
                                     "every label empty", "a µ in a comment", "a UTF-8 BOM",
                                     "many newlines at the end", "CRLF in the comments only"])
def test_the_fast_reader_gives_the_careful_readers_table(tmp_path, monkeypatch, variant):
    text = _session()
    if variant == "path in the middle":
        text = _move_column(text, "path", 4)
    elif variant == "path last":
        text = _move_column(text, "path", -1)
    elif variant == "CRLF":
        text = text.replace("\n", "\r\n")
    elif variant == "labels of several widths":
        text = text.replace("\nK1,", "\nK1long,").replace("\nK2,", "\n  K,")
    elif variant == "no trailing newline":
        text = text.rstrip("\n")
    elif variant == "a µ in a comment":      # as compgen simulate writes: the rows are still ASCII
        text = "# dX dY dZ in µm, 20 °C\n" + text
    elif variant == "a UTF-8 BOM":
        text = "\ufeff" + text
    elif variant == "many newlines at the end":
        text = text + "\n" * 10_000
    elif variant == "CRLF in the comments only":
        text = "# one\r\n# two\r\n" + text
    elif variant == "every label empty":     # a path column written but never filled in
        text = "\n".join(line if line.startswith(("#", "path")) else line[line.index(","):]
                         for line in text.splitlines()) + "\n"
    else:       # the last row's cells reach past the file's end but for the widest label's width
        text = _move_column(text, "path", -1).replace(",K4\n", ",K4long\n", 1).rstrip("\n")
    fast, careful, answered = _both(tmp_path, text, monkeypatch)
    assert answered, "the fast reader stepped aside on a well-formed file"
    np.testing.assert_array_equal(fast.deviation, careful.deviation)
    np.testing.assert_array_equal(fast.poses.q, careful.poses.q)
    np.testing.assert_array_equal(fast.poses.t, careful.poses.t)
    assert fast.poses.path.tolist() == careful.poses.path.tolist()
    assert list(fast.lines) == list(careful.lines)
    assert fast.sha256 == careful.sha256


@pytest.mark.parametrize("fault, line", [
    ("two rows swap a field (same number of commas in all)", 4),
    ("a quoted cell", 3),
    ("a blank line inside", 5),
    ("a comment inside", 5),
    ("a µ in a row", 3),
])
def test_the_fast_reader_steps_aside_and_the_careful_one_names_the_line(tmp_path, monkeypatch, fault, line):
    lines = _session().splitlines()
    first = next(i for i, x in enumerate(lines) if not x.startswith("#")) + 1   # 0-based first data row
    if fault.startswith("two rows"):
        a, b = lines[first + 1].split(","), lines[first + 2].split(",")
        lines[first + 1] = ",".join(a + ["1"])        # one field too many here ...
        lines[first + 2] = ",".join(b[:-1])           # ... and one too few here
    elif fault == "a quoted cell":
        lines[first] = '"' + lines[first].replace(",", '",', 1)
    elif fault == "a blank line inside":
        lines.insert(first + 2, "")
    elif fault == "a µ in a row":
        lines[first + 1] = lines[first + 1].replace(",", ",µ", 1)
    else:
        lines.insert(first + 2, "# a note")
    f = tmp_path / "s.csv"
    f.write_text("\n".join(lines) + "\n")
    used = []
    original = rtest._fast_table
    monkeypatch.setattr(rtest, "_fast_table", lambda *a: used.append(original(*a)) or used[-1])
    if fault.startswith("two rows") or "µ" in fault:
        with pytest.raises(CompgenError) as exc:
            read_rtest(f, MACHINE)
        assert f"s.csv:{line + 1 if 'µ' in fault else line}" in str(exc.value), exc.value
        assert ("fields" if "µ" not in fault else "not a number") in str(exc.value), exc.value
    else:
        data = read_rtest(f, MACHINE)
        assert len(data) == len(generate(MACHINE, ["K4", "K1", "K2"]))
    assert used == [None]


def test_each_axis_side_is_read_as_written_and_nothing_else_is_taken(tmp_path):
    """A_side / C_side round trip through the file (both readers), and a value that is not
    +1 or -1 is refused with its line, on the fast path and the careful one."""
    poses = generate(MACHINE, ["K4", "K1"], back=True)
    text = format_rtest(MACHINE, RTestData(poses, np.zeros((len(poses), 3))))
    f = tmp_path / "s.csv"
    for body in (text, text.replace("\n", "\r\n")):          # fast path, then the careful reader
        f.write_bytes(body.encode())
        np.testing.assert_array_equal(read_rtest(f, MACHINE).poses.side, poses.side)
    assert {-1.0, 1.0} <= set(np.unique(poses.side[:, 3]))
    lines = text.splitlines()
    at = len(lines) - 3
    for bad in ("0", "2", "0.5"):
        for careful in (False, True):
            edited = [*lines[:at], lines[at].rsplit(",", 1)[0] + "," + bad, *lines[at + 1:]]
            f.write_bytes(("\r\n" if careful else "\n").join(edited).encode() + b"\n")
            with pytest.raises(CompgenError, match=rf"column C_side: {bad} is neither \+1 nor -1") as e:
                read_rtest(f, MACHINE)
            assert e.value.where == f"{f}:{at + 1}", e.value.where


@pytest.mark.parametrize("fast", [True, False], ids=["fast reader", "careful reader"])
def test_a_sessions_own_nest_length_is_read_back_and_a_wrong_one_named(tmp_path, monkeypatch, fast):
    """A session made with another nest (compgen's probe_length column) is written and read
    back with it, by both readers, on a head (where it moves the axes); a length no nest
    can have, or a text, is refused with its line and column, the file's nothing taken."""
    from conftest import HEAD_MACHINE
    head = load_machine(HEAD_MACHINE)
    if not fast:
        monkeypatch.setattr(rtest, "_fast_table", lambda *a: None)
    poses = generate(head, ["K4"], nest=220.0)
    dev = np.random.default_rng(2).normal(0, 1e-3, (len(poses), 3))
    text = format_rtest(head, RTestData(poses, dev))
    assert text.splitlines()[0].split(",")[-3:] == ["probe_length", "C_side", "B_side"]
    f = tmp_path / "n.csv"
    f.write_text(text)
    back = read_rtest(f, head)
    assert (back.poses.nest == 220.0).all()
    # the CSV's angles to 1e-6° (1.7e-8 rad) move the axes by up to that times the 370 mm lever
    np.testing.assert_allclose(back.poses.q, poses.q, rtol=0, atol=1e-5)
    np.testing.assert_allclose(back.deviation, dev, rtol=0, atol=1e-9)
    header, first, *rest = text.splitlines()
    col = header.split(",").index("probe_length") + 1
    for bad, says in [("5.000000", "is no nest's distance below the gauge line"),
                      ("2200.000000", "is no nest's distance below the gauge line"),
                      ("long", "is not a number")]:
        cells = first.split(",")
        cells[col - 1] = bad
        f.write_text("\n".join([header, ",".join(cells), *rest]) + "\n")
        with pytest.raises(CompgenError, match=says) as caught:
            read_rtest(f, head)
        assert caught.value.where.endswith((":2", f":2:{col}")), caught.value.where


def test_a_row_whose_x_y_z_miss_the_ball_and_a_ball_given_in_part_are_refused(tmp_path):
    """X, Y, Z a file gives are checked against where the nest meets the ball (0.5 mm off at
    the fourth row: named at its line, by the session's reader and the pose list's); bx
    alone is refused (the ball in part would be taken
    for the machine file's with one coordinate moved)."""
    lines = _session().splitlines()
    cells = lines[5].split(",")
    cells[2] = f"{float(cells[2]) + 0.5:.6f}"
    lines[5] = ",".join(cells)
    f = tmp_path / "s.csv"
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(CompgenError, match=r"s\.csv:6: commanded X, Y, Z are 0\.500 mm from the nominal "
                                           r"ball centre at these rotary positions \(1 rows like this\)"):
        read_rtest(f, MACHINE)
    with pytest.raises(CompgenError, match=r"s\.csv:6: X, Y, Z are 0\.500 mm from where the nest meets"):
        read_poses(f, MACHINE)       # as a pose list (predict's input): the same row named
    lines = _session().splitlines()
    lines[1] += ",bx"
    lines[2:] = [line + ",-217.504" for line in lines[2:]]
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(CompgenError, match=r"s\.csv:2: give all of bx, by, bz or none"):
        read_rtest(f, MACHINE)


def test_the_reader_takes_no_sign_it_does_not_know_and_the_writer_no_label_a_cell_breaks(tmp_path):
    f = tmp_path / "s.csv"
    f.write_text(_session())
    with pytest.raises(CompgenError, match="sign must be one of nest-minus-ball, ball-minus-nest, "
                                           "not 'nest'"):
        read_rtest(f, MACHINE, "nest")
    poses = generate(MACHINE, ["K2"])
    poses = type(poses)(poses.q, poses.ball, poses.t, np.array(['K2,"x"'] * len(poses)), poses.side,
                        poses.nest)
    with pytest.raises(CompgenError, match="path label 'K2,\"x\"' cannot be written into a CSV cell"):
        format_rtest(MACHINE, RTestData(poses, np.zeros((len(poses), 3))), ())


@pytest.mark.parametrize("text", ["", "# only a comment\n\n   \n# and another\n", "\ufeff\n"])
def test_a_file_with_no_header_is_refused_as_empty(tmp_path, text):
    f = tmp_path / "s.csv"
    f.write_text(text)
    with pytest.raises(CompgenError, match=r"s\.csv: empty file: no header and no data"):
        read_rtest(f, MACHINE)


@pytest.mark.parametrize("where", ["in a comment", "in a row", "past the first 64 kB"])
def test_a_file_not_utf8_is_refused_naming_its_byte_wherever_it_lies(tmp_path, where):
    """The reader decodes only a file's head where its rows are ASCII: a byte that is no
    UTF-8 is still refused, at its place in the file, in the head or in the rows."""
    raw = _session().encode()
    at = {"in a comment": 2, "in a row": raw.index(b"\nK1,") + 3,
          "past the first 64 kB": raw.index(b"\n", 70_000) + 3}[where]
    assert where != "past the first 64 kB" or len(raw) > 70_000
    f = tmp_path / "s.csv"
    f.write_bytes(raw[:at] + b"\xff" + raw[at + 1:])
    with pytest.raises(CompgenError, match=rf"s\.csv: data file is not UTF-8 text \(byte {at}\)"):
        read_rtest(f, MACHINE)
