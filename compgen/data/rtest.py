"""R-test CSV v1 in and out (``docs/rtest-csv.md``).

Reading converts to inside units (mm, rad; deviations in mm) and checks every cell; a
problem names file, line and column. Writing keeps enough digits to round-trip to 1 pm.
"""

from __future__ import annotations

import codecs
import csv
import hashlib
import io
import re
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ..errors import CompgenError, one_line
from ..files import MAX_DATA_BYTES, decoded, read_bytes
from ..model.kinematics import head_offset, inverse, nominal, solved
from ..model.machine import IDENTIFIERS, NEST_RANGE_MM, Machine, check_ball, check_travel, identifier
from ..model.poses import Poses
from ..units import NUMBER

DEVIATION = ("dX", "dY", "dZ")
BALL = ("bx", "by", "bz")
# compgen's own column beside the contract's (which keeps and ignores what it does not name):
# the nest centre's distance below the gauge line where a session's nest is not the machine
# file's ``probe_length``, mm. A head's angle at its pivot turns the nest by this lever, its
# sag does not: two lengths tell them apart
NEST = "probe_length"
SIGNS = ("nest-minus-ball", "ball-minus-nest")
CELL_MAX = 1e6               # mm, deg or µm: beyond any machine's coordinates
READING_MAX_MM = 5.0          # no R-test nest measures further from the ball's centre
NOMINAL_TOLERANCE_MM = 0.01   # commanded XYZ vs nominal ball: far above 4-decimal rounding


@dataclass(frozen=True, eq=False)
class RTestData:
    """One R-test file: poses and readings. ``deviation`` (n, 3) mm, nest minus ball."""

    poses: Poses
    deviation: np.ndarray
    source: str = ""
    sha256: str = ""
    lines: tuple[int, ...] = ()     # the CSV line of each reading (header = 1), when read from one
    device: str = "rtest"           # "probe": readings are sphere centres from a probe log
    cov: np.ndarray | None = None   # (n, 3, 3) mm², each reading's covariance when it is known
    cov_dof: int | None = None      # the degrees of freedom cov's scale was estimated with (a probe
                                    # log's pooled touches), None where it is known
    said: str = ""                  # what the user said of the set-up before it: MOUNTED_AGAIN,
                                    # UNTOUCHED, or nothing
    turned: float = 0.0             # deg the ball was turned on its stem before it (then said
                                    # MOUNTED_AGAIN too: its clamp was loosened)
    lobes: np.ndarray | None = None  # (n, 3, 2): a probe log's readings per mm of its trigger's
                                    # lobes (``probe.trigger_lobes``), None for an R-test's
    spindle: float = 0.0            # deg the spindle was oriented to while a probe log was made

    def __len__(self) -> int:
        return len(self.poses)


# what a user may say of the set-up before a file (fit --mounted-again, --not-touched)
MOUNTED_AGAIN, UNTOUCHED = "mounted again", "not touched"


@dataclass(frozen=True, eq=False)
class Measurements:
    """Measurement sets taken together, in order: their poses and readings joined once, and
    each reading's set. What every fit, diagnosis, comparison and check reads."""

    sets: tuple[RTestData, ...]

    @classmethod
    def concat(cls, sets) -> Measurements:
        """The sets in the order given (a ``Measurements`` passes through as it is)."""
        return sets if isinstance(sets, Measurements) else cls(tuple(sets))

    def __len__(self) -> int:
        return sum(len(d) for d in self.sets)

    @cached_property
    def poses(self) -> Poses:
        """The sets' poses in order, each set said mounted again one set-up event after the
        sets before it (``Poses.setup``)."""
        count = np.cumsum([d.said == MOUNTED_AGAIN for d in self.sets])
        turn = np.radians(np.cumsum([d.turned for d in self.sets]))
        if not count[-1:].any():
            return Poses.concat([d.poses for d in self.sets])
        return Poses.concat([d.poses.with_setup(int(k), float(a))
                             for d, k, a in zip(self.sets, count, turn, strict=True)])

    @cached_property
    def deviation(self) -> np.ndarray:
        """(n, 3) mm, nest minus ball."""
        return np.concatenate([d.deviation for d in self.sets])

    @cached_property
    def set_of(self) -> np.ndarray:
        """(n,) the index of each reading's set."""
        return np.repeat(np.arange(len(self.sets)), [len(d) for d in self.sets])

    @property
    def device(self) -> str:
        return device_of(self.sets)

    @cached_property
    def cov_known(self) -> np.ndarray:
        """(n,) whether each reading's covariance is known (a probe log's sphere centres)."""
        return np.array([d.cov is not None for d in self.sets], bool)[self.set_of]

    @cached_property
    def rtest(self) -> np.ndarray:
        """(n,) whether each reading is an R-test's (a probe's sphere centres carry no sensor gain)."""
        return np.array([d.device == "rtest" for d in self.sets], bool)[self.set_of]

    @cached_property
    def lobes(self) -> np.ndarray | None:
        """(n, 3, 2) each reading per mm of the probe trigger's lobes (0 for an R-test's), or
        None where no set is a probe log's."""
        if all(d.lobes is None for d in self.sets):
            return None
        return np.concatenate([np.zeros((len(d), 3, 2)) if d.lobes is None else d.lobes for d in self.sets])

    def covariance(self, prior: np.ndarray) -> np.ndarray:
        """(n, 3, 3) mm²: each reading's own covariance where its set gives it, else ``prior``."""
        return np.concatenate([d.cov if d.cov is not None else np.broadcast_to(prior, (len(d), 3, 3))
                               for d in self.sets])


def refuse_twice(sets) -> None:
    """The same readings twice would be fitted as independent: every σ √2 too small. Sets
    read from files are compared by their checksums."""
    seen = {}
    for d in sets:
        if d.sha256 and d.sha256 in seen:
            raise CompgenError(f"{d.source} holds the same readings as {seen[d.sha256]} (equal checksums)",
                               hint="give each measurement once")
        seen[d.sha256] = d.source


def device_of(data) -> str:
    """The device of measurements (``RTestData`` or a fit's data entries): "probe" when
    every one is from a probe log, else "rtest"."""
    return "probe" if all(d.device == "probe" for d in data) else "rtest"


def read_rtest(path: str | Path, machine: Machine, sign: str = "nest-minus-ball") -> RTestData:
    """Read an R-test CSV v1 file for ``machine``.

    ``sign`` says what the device reports; the contract's is nest minus ball. A device that
    reports ball minus nest needs ``sign="ball-minus-nest"``: compgen never guesses it.
    """
    if sign not in SIGNS:
        raise CompgenError(f"sign must be one of {', '.join(SIGNS)}, not {sign!r}")
    table = read_table(path, machine, ["X", "Y", "Z", *(a.name for a in machine.rotary_axes),
                                        *DEVIATION])
    poses = table.poses(machine)
    deviation = np.column_stack([table.columns[c] for c in DEVIATION]) * 1e-3
    beyond = np.flatnonzero(np.abs(deviation).max(axis=1) > READING_MAX_MM)
    if beyond.size:
        k = beyond[0]
        raise CompgenError(f"a reading of {np.abs(deviation[k]).max() * 1e3:.4g} µm is beyond any R-test's "
                           f"measuring range ({READING_MAX_MM * 1e3:g} µm)",
                           where=f"{table.where}:{table.lines[k]}", hint="readings are µm; check the "
                           "column's unit and the row")
    if sign == "ball-minus-nest":
        deviation = -deviation
    off = np.linalg.norm(nominal(machine, poses), axis=1)
    bad = np.flatnonzero(off > NOMINAL_TOLERANCE_MM)
    if bad.size:
        k = bad[0]
        raise CompgenError(
            f"commanded X, Y, Z are {off[k]:.3f} mm from the nominal ball centre at these "
            f"rotary positions ({bad.size} rows like this)", where=f"{table.where}:{table.lines[k]}",
            hint="the machine file's geometry or ball position does not match this data; "
                 "give the ball per row in bx, by, bz if it moved")
    return RTestData(poses, deviation, table.where, table.sha256, tuple(table.lines))


def read_poses(path: str | Path, machine: Machine) -> Poses:
    """A pose list: rotary axes (deg) required; ``path`` and ``bx,by,bz`` optional. The linear
    axes follow the ball by inverse kinematics; X, Y, Z, if given, must agree with it."""
    table = read_table(path, machine, [a.name for a in machine.rotary_axes])
    rotary = np.radians(np.column_stack([table.columns[a.name] for a in machine.rotary_axes]))
    ball = table.ball(machine)
    # a ball that cannot stand on the table, a pose the machine cannot take: not a prediction
    # each place the ball stood, at its first row (sorting only the rows where it moved)
    moved = np.flatnonzero(np.r_[True, (ball[1:] != ball[:-1]).any(axis=1)])
    _, first = np.unique(ball[moved], axis=0, return_index=True)
    for k in moved[np.sort(first)]:
        check_ball(machine.setup, ball[k], f"{table.where}:{table.lines[k]}")
    q = inverse(machine, rotary, ball, nest=table.nest)
    check_travel(machine, q, table.where, table.lines)
    if all(c in table.columns for c in "XYZ"):
        given = np.column_stack([table.columns[c] for c in "XYZ"])
        off = np.linalg.norm(given - commanded(machine, q, table.nest)[:, :3], axis=1)
        bad = np.flatnonzero(off > NOMINAL_TOLERANCE_MM)
        if bad.size:
            raise CompgenError(f"X, Y, Z are {off[bad[0]]:.3f} mm from where the nest meets the ball",
                               where=f"{table.where}:{table.lines[bad[0]]}",
                               hint="drop the X, Y, Z columns (compgen computes them) or fix the ball")
    return solved(machine, Poses(q, ball, table.columns.get("t", np.full(len(q), np.nan)), table.labels,
                                 table.side(machine), table.nest))


@dataclass(frozen=True, eq=False)
class Table:
    """An R-test CSV as read, before it is checked into poses: its columns (by header name),
    the path label of each row, each row's line in the file, and the file's checksum."""

    where: str
    sha256: str
    columns: dict[str, np.ndarray]
    labels: np.ndarray
    lines: list[int]

    def ball(self, machine: Machine) -> np.ndarray:
        if all(c in self.columns for c in BALL):
            return np.column_stack([self.columns[c] for c in BALL])
        return np.broadcast_to(machine.ball, (len(self.labels), 3)).copy()

    @property
    def nest(self) -> np.ndarray | None:
        return self.columns.get(NEST)

    def side(self, machine: Machine) -> np.ndarray:
        out = np.full((len(self.labels), len(machine.axes)), np.nan)
        for name, axis in side_columns(machine).items():
            if name in self.columns:
                out[:, machine.index(axis)] = self.columns[name]
        return out

    def poses(self, machine: Machine) -> Poses:
        q = np.column_stack([self.columns[a.name] if not a.rotary else np.radians(self.columns[a.name])
                             for a in machine.axes])
        q[:, :3] -= head_offset(machine, q[:, 3:], self.nest)     # X, Y, Z are the nest's position
        return Poses(q, self.ball(machine), self.columns.get("t", np.full(len(q), np.nan)), self.labels,
                     self.side(machine), self.nest)


def side_columns(machine: Machine) -> dict[str, str]:
    """The optional column of each rotary axis that says the direction it last moved before
    the row's pose (+1 or -1: the side of its backlash), as compgen's pose lists carry it."""
    return {f"{a.name}_side": a.name for a in machine.rotary_axes}


def _checked(table: Table) -> Table:
    """The table, its side columns ±1 and its nest lengths where a nest can be."""
    nest = table.nest
    if nest is not None:
        bad = np.flatnonzero((nest < NEST_RANGE_MM[0]) | (nest > NEST_RANGE_MM[1]))
        if bad.size:
            raise CompgenError(f"column {NEST}: {nest[bad[0]]:g} mm is no nest's distance below the gauge "
                               f"line ({NEST_RANGE_MM[0]:g} to {NEST_RANGE_MM[1]:g} mm)",
                               where=f"{table.where}:{table.lines[bad[0]]}",
                               hint="give the nest's length in mm, or drop the column (the machine file's "
                                    "probe_length)")
    for name, v in table.columns.items():
        if name.endswith("_side"):
            bad = np.flatnonzero(np.abs(v) != 1)
            if bad.size:
                raise CompgenError(f"column {name}: {v[bad[0]]:g} is neither +1 nor -1 (the direction "
                                   f"{name[:-5]} last moved before the pose)",
                                   where=f"{table.where}:{table.lines[bad[0]]}",
                                   hint="write +1 or -1, or drop the column if the history is not known")
    return table


def _cells(line: str, where: str) -> list[str]:
    try:
        return next(csv.reader([line]))
    except csv.Error as exc:
        raise CompgenError(f"not a CSV row ({exc})", where=where) from None


def read_table(path: str | Path, machine: Machine, required: list[str]) -> Table:
    """A CSV v1 table with every cell checked: numbers finite, rows whole, columns present.
    An ASCII file, as every R-test writes, is parsed from its bytes, not decoded whole."""
    where = str(path)
    raw = read_bytes(path, "data file", limit=MAX_DATA_BYTES)
    header_line, header_text, at = _header(raw, where)
    header = [h.strip() for h in _cells(header_text, f"{where}:{header_line}")]
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise CompgenError(f"column {dup[0]!r} appears twice in the header", where=f"{where}:{header_line}")
    missing = [c for c in required if c not in header]
    if missing:
        raise CompgenError(f"missing column{'s' if len(missing) > 1 else ''} {', '.join(missing)}",
                           where=f"{where}:{header_line}",
                           hint=f"machine {machine.name!r} needs {', '.join(required)}; found "
                                f"{', '.join(header)}")
    has_ball = [c in header for c in BALL]
    if any(has_ball) and not all(has_ball):
        raise CompgenError("give all of bx, by, bz or none", where=f"{where}:{header_line}")
    numeric = required + [c for c in ("X", "Y", "Z", "t", *BALL, NEST, *side_columns(machine))
                          if c in header and c not in required]
    col = {c: header.index(c) for c in header}
    digest = hashlib.sha256(raw).hexdigest()
    fast = _fast_table(raw, at, header, numeric, col)
    if fast is not None:
        values, labels = fast
        return _checked(Table(where, digest, {name: values[:, j] for j, name in enumerate(numeric)},
                              labels, range(header_line + 1, header_line + 1 + len(labels))))

    try:
        body = raw[at:].decode("utf-8")
    except UnicodeDecodeError:
        decoded(raw, "data file", path)                  # the refusal, naming the file's byte
        raise
    lines = [(i, line) for i, line in enumerate(body.splitlines(), start=header_line + 1)
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise CompgenError("header only: no data rows", where=where)
    values = np.empty((len(lines), len(numeric)))
    labels, line_no = [], []
    for r, (i, line) in enumerate(lines):
        cells = _cells(line, f"{where}:{i}")
        if len(cells) != len(header):
            raise CompgenError(f"{len(cells)} fields where the header has {len(header)}",
                               where=f"{where}:{i}")
        for j, name in enumerate(numeric):
            cell = cells[col[name]].strip()
            at = f"{where}:{i}:{col[name] + 1}"
            if not NUMBER.fullmatch(cell):     # ASCII digits only: float() takes any script's
                raise CompgenError(f"column {name}: {cell or 'an empty cell'!r} is not a number", where=at)
            v = float(cell)
            if not abs(v) < CELL_MAX:          # no coordinate or reading is this large
                raise CompgenError(f"column {name}: {cell!r} is not a finite number of a sensible size",
                                   where=at)
            values[r, j] = v
        label = cells[col["path"]].strip() if "path" in col else ""
        if label:     # a label is written into programs' comments and pose lists
            identifier("path", label, f"{where}:{i}:{col['path'] + 1}")
        labels.append(label)
        line_no.append(i)
    columns = {name: values[:, j] for j, name in enumerate(numeric)}
    return _checked(Table(where, digest, columns, np.array(labels, dtype=object), line_no))


def _header(raw: bytes, where: str) -> tuple[int, str, int]:
    """The first line that is neither blank nor a comment (its number and text) and the
    byte the text after it starts at; only the file's head is decoded (line ends as
    ``str.splitlines`` takes them). A file without one, or not UTF-8 there, is refused."""
    bom = len(codecs.BOM_UTF8) if raw.startswith(codecs.BOM_UTF8) else 0
    for limit in (1 << 16, len(raw)):
        try:   # a character cut at the limit waits for the next try
            text = codecs.getincrementaldecoder("utf-8")().decode(raw[bom:limit], final=limit >= len(raw))
        except UnicodeDecodeError:
            decoded(raw, "data file", where)          # the refusal, naming the file's byte
            raise
        lines = text.splitlines(keepends=True)
        if limit < len(raw):
            lines = lines[:-1]                 # the last may be cut short
        offset = 0
        for number, line in enumerate(lines, start=1):
            offset += len(line)
            content = (line.splitlines() or [""])[0]
            if content.strip() and not content.lstrip().startswith("#"):
                return number, content, bom + len(text[:offset].encode("utf-8"))
    raise CompgenError("empty file: no header and no data", where=where)


ROWS_A_STEP = 1 << 16      # rows whose commas are found at once (a few MB of positions)
BYTES_A_STEP = 1 << 22     # bytes whose line ends are found at once: a mask of the whole file is 70 MB
LABEL_MAX = 64             # bytes of a path label's cell: 16 characters (``IDENTIFIERS``) and its spaces


def _fast_table(buf: bytes, at: int, header: list[str], numeric: list[str],
                col: dict[str, int]) -> tuple[np.ndarray, np.ndarray] | None:
    """The careful reader's result for a well-formed table, at numpy's speed, from ``buf``'s
    bytes from ``at`` (the rows after the header): plain ASCII, no quotes, no comment or
    blank line, every row as many fields as the header, every numeric cell what ``NUMBER``
    takes (numpy's parser refuses "1_0", "0x10", "--1" and empty cells; nan, inf and 1e999
    fail the size check) and of a sensible size. Anything else returns None: the careful
    reader then finds and names the first fault. No copy of the file's text is made where
    its lines end in LF (at 723 000 rows each copy is 70 MB, and a process's new memory
    costs ~2 ms a MB on a virtual machine)."""
    if buf.find(b"\r", at) >= 0:
        buf, at = buf[at:].replace(b"\r\n", b"\n"), 0
    elif buf.find(b"\r", 0, at) >= 0:                 # loadtxt would end a line there
        buf, at = buf[at:], 0
    end = len(buf)
    while end > at and buf[end - 1] == 10:           # the last row's line end(s), 4 kB at a time
        tail = buf[max(at, end - 4096):end]
        end -= len(tail) - len(tail.rstrip(b"\n"))
    if end == at or any(buf.find(c, at, end) >= 0 for c in (b'"', b"#", b"\r", b"\n\n")) or buf[at] == 10:
        return None
    raw = np.frombuffer(buf, np.uint8, count=end - at, offset=at)
    if raw.max() >= 128:
        return None
    cells = _fields(raw, len(header) - 1, col.get("path"))
    if cells is None:
        return None
    try:
        # from the bytes where they lie (a BytesIO of bytes shares them), past the header
        values = np.loadtxt(io.BytesIO(buf), delimiter=",", usecols=[col[c] for c in numeric], ndmin=2,
                            comments=None, dtype=float, skiprows=buf.count(b"\n", 0, at),
                            max_rows=len(cells[0]))
    except ValueError:
        return None
    if values.shape[0] != len(cells[0]) or not -CELL_MAX < values.min() <= values.max() < CELL_MAX:
        return None                                    # (NaN fails both)
    if "path" not in col:
        return values, np.full(len(values), "", dtype=object)
    names, which = _labels(raw, *cells)
    pattern = IDENTIFIERS["path"][0]              # a label is written into programs' comments
    if which is None or any(name and not re.fullmatch(pattern, name) for name in names):
        return None
    return values, np.array(names, dtype=object)[which]


def _fields(raw: np.ndarray, per_row: int, k: int | None) -> tuple[np.ndarray, np.ndarray] | None:
    """Where field k of each row starts and ends (every row's starts where there is no k),
    found with the check that every row holds ``per_row`` commas; None where one does not.
    Line ends and commas are found a step at a time: a mask of the whole file, or the
    positions of all its commas (8 bytes each), would be new memory of the file's size
    and more."""
    starts = np.concatenate([[0], *(np.flatnonzero(raw[lo:lo + BYTES_A_STEP] == 10) + lo + 1
                                    for lo in range(0, len(raw), BYTES_A_STEP))])
    bounds = np.r_[starts, len(raw) + 1]                 # a row ends one before the next starts
    first, last = starts.copy(), bounds[1:] - 1
    for lo in range(0, len(starts), ROWS_A_STEP):
        part = bounds[lo:lo + ROWS_A_STEP + 1]
        commas = np.flatnonzero(raw[part[0]:part[-1] - 1] == 44) + part[0]
        if not (np.diff(np.searchsorted(commas, part)) == per_row).all():
            return None
        if k is not None and per_row:
            row = commas.reshape(-1, per_row)
            if k:
                first[lo:lo + ROWS_A_STEP] = row[:, k - 1] + 1
            if k < per_row:
                last[lo:lo + ROWS_A_STEP] = row[:, k]
    return first, last


def _labels(raw: np.ndarray, first: np.ndarray, last: np.ndarray) -> tuple[list[str], np.ndarray | None]:
    """The cells from ``first`` to ``last`` of every row as their distinct texts and each
    row's index into them; None where one is wider than ``LABEL_MAX``."""
    width = int((last - first).max()) if len(first) else 0
    if width > LABEL_MAX:
        return [], None
    width = max(width, 1)
    cells = np.zeros((len(first), width), np.uint8)
    for k in range(width):                               # a column of the cells at a time
        live = first + k < last
        cells[live, k] = raw[first[live] + k]
    distinct, which = np.unique(cells.view(f"S{width}").ravel(), return_inverse=True)
    return [b.decode("ascii").strip() for b in distinct.tolist()], which.ravel()


def commanded(machine: Machine, q: np.ndarray, nest: np.ndarray | None = None) -> np.ndarray:
    """Poses (n, k) as CSV v1 gives them: X, Y, Z the nominal nest centre (under TCPM, where
    the ball is), which a head's turn moves from the linear axes' position; mm and rad.
    ``nest``: each pose's nest length (``Poses.nest``), if not the machine file's."""
    out = np.array(q, float)
    out[:, :3] += head_offset(machine, out[:, 3:], nest)
    return out


def axis_cells(machine: Machine, q: np.ndarray) -> list[str]:
    """One pose's axis positions as CSV v1 cells: mm and deg, to 1 nm and 1e-6 deg."""
    return [f"{np.degrees(v) if a.rotary else v:.6f}"
            for a, v in zip(machine.axes, commanded(machine, q[None])[0], strict=True)]


ROWS_AT_ONCE = 20_000     # rows formatted by one %: a few MB of text at a time


def format_rtest(machine: Machine, data: RTestData, comments: tuple[str, ...] = ()) -> str:
    """CSV v1 text: path, t, linear axes, rotary axes (deg), dX dY dZ (µm), ball if not
    default, the nest's length where a pose's is not the machine file's, and each rotary
    axis's side where every pose's is known."""
    p = data.poses
    ball_default = np.allclose(p.ball, machine.ball, rtol=0, atol=1e-12)
    nest = not np.isnan(p.nest).all()
    timed = not np.isnan(p.t).any()
    sides = {name: machine.index(axis) for name, axis in side_columns(machine).items()
             if not np.isnan(p.side[:, machine.index(axis)]).any()}
    header = ["path", *(["t"] if timed else []), *machine.axis_names, *DEVIATION] + (
        [] if ball_default else list(BALL)) + [NEST] * nest + list(sides)
    out = io.StringIO()
    for c in comments:
        out.write(f"# {one_line(c)}\n")
    w = csv.writer(out, lineterminator="\n")
    w.writerow(header)
    # one format for a row's numbers (what axis_cells writes, then µm, then the ball); the
    # labels are identifiers (no comma, no quote), so the row needs no CSV quoting
    scale = np.array([180.0 / np.pi if a.rotary else 1.0 for a in machine.axes])
    numbers = [commanded(machine, p.q, p.nest) * scale, data.deviation * 1e3,
               *([] if ball_default else [p.ball]),
               *([np.where(np.isnan(p.nest), machine.probe_length, p.nest)[:, None]] if nest else []),
               p.side[:, list(sides.values())]]
    if timed:
        numbers.insert(0, p.t[:, None])
    cells = len(machine.axes) + 3 + 3 * (not ball_default) + nest
    fmt = ",".join(["%s", *(["%.3f"] if timed else []), *["%.6f"] * cells, *["%+.0f"] * len(sides)]) + "\n"
    for label in set(p.path.tolist()):
        if not re.fullmatch(r"[^,\"\r\n]*", str(label)):
            raise CompgenError(f"path label {label!r} cannot be written into a CSV cell")
    # one % over a block of rows: the per-row tuples and calls were half of the time at
    # a million poses (the number formatting itself is the other half)
    for i in range(0, len(p), ROWS_AT_ONCE):
        block = np.empty((min(ROWS_AT_ONCE, len(p) - i), 1 + sum(a.shape[1] for a in numbers)), object)
        block[:, 0] = p.path[i:i + ROWS_AT_ONCE]
        block[:, 1:] = np.column_stack([a[i:i + ROWS_AT_ONCE] for a in numbers])
        out.write(fmt * len(block) % tuple(block.ravel().tolist()))
    return out.getvalue()
