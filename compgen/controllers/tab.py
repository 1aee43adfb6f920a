"""HEIDENHAIN tables (``*.TAB``): fixed-width text, edited in place.

Layout (pyLSV2's table reader documents it): ``BEGIN <name>.TAB [MM|INCH]``; an optional
column-description block (``#STRUCTBEGIN`` … ``#STRUCTEND``, or ``TableDescription (`` …
``)``); the header line, whose column names fix where each column starts (a column runs to
the next one's start, the last to the end of the line); the rows; ``[END]``.

An edit changes only the cells it must: a changed COORD is rewritten inside its column, an
inserted row is laid out in the columns, the NR of the rows after it is renumbered. Every
other byte — the description block, untouched rows, spacing, line ends, anything after
``[END]`` — is kept. A value that does not fit its column is refused, never overflowed.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from ..errors import CompgenError
from ..units import number

KEYS = {"Trans", "MachAxis", "MachBase", "CMO", "ToolAxis", "TOOLFILE", "SUBFILE1", "SUBFILE2"}
BEGIN = re.compile(r"^BEGIN\s+(\S+?)(?:\.TAB)?(?:\s+(MM|INCH))?(?:\s.*)?$", re.IGNORECASE)
MM_PER = {"MM": 1.0, "INCH": 25.4}


@dataclass
class TabTable:
    """A description table as its lines, with the columns' slots and the rows' cells."""

    lines: list[str]
    newline: str
    unit: str                       # MM or INCH: the unit of linear COORD values
    columns: list[str]
    starts: list[int]
    rows: list[dict]                # cells per data row (stripped)
    row_at: list[int]               # index in ``lines`` of each row
    decimals: dict[str, int] = field(default_factory=dict)   # DEC of the description block

    @staticmethod
    def parse(text: str, where: str) -> TabTable:
        # CRLF (the control's own), LF, or CR alone (an old Mac editor): kept as found
        newline = "\r\n" if "\r\n" in text else ("\r" if "\r" in text and "\n" not in text else "\n")
        lines = text.split(newline)
        m = BEGIN.match(lines[0]) if lines else None
        if m is None:
            raise CompgenError("the first line is not 'BEGIN <name>.TAB MM'", where=f"{where}:1",
                               hint="give the kinematics description table (*.TAB) of the machine")
        if m[2] is None:
            raise CompgenError("the BEGIN line states no unit (MM or INCH): compgen will not guess in "
                               "which unit the table's Trans rows are", where=f"{where}:1")
        i, decimals = 1, {}
        if i < len(lines) and lines[i].strip().startswith(("#STRUCTBEGIN", "TableDescription")):
            i, decimals = _description(lines, i, where)
        while i < len(lines) and not lines[i].strip():
            i += 1
        if i >= len(lines) or not (re.match(r"\s*NR\s+", lines[i]) and "KEY" in lines[i]):
            raise CompgenError("no header line with NR and KEY", where=f"{where}:{i + 1}",
                               hint="give the kinematics description table (*.TAB) of the machine")
        head = lines[i]
        found = list(re.finditer(r"\S+", head))
        columns, starts = [c[0] for c in found], [c.start() for c in found]
        table = TabTable(lines, newline, m[2].upper(), columns, starts, [], [], decimals)
        for k in range(i + 1, len(lines)):
            if lines[k].strip().startswith("[END]"):
                return table
            if not lines[k].strip():
                continue
            cells = table.cells(lines[k])
            if cells.get("KEY") not in KEYS:
                raise CompgenError(f"KEY {cells.get('KEY')!r} is not a kinematics key",
                                   where=f"{where}:{k + 1}",
                                   hint="the table's columns must line up with its header line")
            if cells.get("KEY") == "Trans":
                number(cells.get("COORD", ""), "Trans row's COORD", f"{where}:{k + 1}")
            table.rows.append(cells)
            table.row_at.append(k)
        raise CompgenError("no [END] line", where=where)

    def slot(self, column: str) -> tuple[int, int | None]:
        i = self.columns.index(column)
        return self.starts[i], self.starts[i + 1] if i + 1 < len(self.starts) else None

    def cells(self, line: str) -> dict:
        return {c: line[slice(*self.slot(c))].strip() for c in self.columns}

    def mm(self, coord: str, axis: str) -> float:
        """A COORD in mm (linear) or deg (rotary)."""
        return float(coord) * (MM_PER[self.unit] if axis in "XYZ" else 1.0)

    def coord(self, value: float, axis: str, decimals: int) -> str:
        """A value in mm or deg as this table writes it: its unit, at most its decimals."""
        from . import fmt_signed
        if axis in "XYZ":
            value /= MM_PER[self.unit]
            decimals += 1 if self.unit == "INCH" else 0     # the same resolution in inch
        return fmt_signed(value, min(decimals, self.decimals.get("COORD", decimals)))

    def set(self, row: int, values: dict[str, str], where: str = "table") -> None:
        """Rewrite cells of row ``row`` inside their columns; nothing else on the line moves."""
        k = self.row_at[row]
        line = self.lines[k]
        for column, value in values.items():
            start, end = self.slot(column)
            width = None if end is None else end - start - 1      # a space before the next column
            if width is not None and len(value) > width:
                raise CompgenError(f"{column} {value} needs {len(value)} characters; the table's "
                                   f"{column} column holds {width}", where=f"{where}:{k + 1}",
                                   hint="widen the column on the control, or enter the value by hand")
            line = line.ljust(start)
            rest = line[end:] if end is not None else ""
            cell = value.ljust(end - start) if rest.strip() else value   # no padding at the end
            line = line[:start] + cell + (rest if rest.strip() else "")
            self.rows[row][column] = value
        self.lines[k] = line

    def insert(self, row: int, values: dict[str, str]) -> None:
        """A new row before row ``row`` (``len(rows)``: at the end), laid out in the columns;
        the NR of every row from there on is renumbered."""
        k = self.row_at[row] if row < len(self.rows) else self._end()
        self.lines.insert(k, "")
        self.row_at = [j + 1 if j >= k else j for j in self.row_at]
        self.row_at.insert(row, k)
        self.rows.insert(row, {c: "" for c in self.columns})
        self.set(row, {c: v for c, v in values.items() if c in self.columns})
        self.lines[k] = self.lines[k].rstrip()
        if "NR" in self.columns:
            for j in range(row, len(self.rows)):
                if self.rows[j]["NR"] != str(j):
                    self.set(j, {"NR": str(j)})

    def _end(self) -> int:
        return next(k for k in range(self.row_at[-1] if self.row_at else 0, len(self.lines))
                    if self.lines[k].strip().startswith("[END]"))

    def text(self) -> str:
        return self.newline.join(self.lines)


def _description(lines: list[str], i: int, where: str) -> tuple[int, dict[str, int]]:
    """Skip the column-description block at line ``i``; the columns' declared decimals."""
    decimals, name, depth = {}, None, 0
    old = lines[i].strip().startswith("#STRUCTBEGIN")
    for k in range(i, len(lines)):
        s = lines[k].strip()
        if old:
            if s.startswith(("NAME", "DEC")):
                m = re.fullmatch(r"(NAME|DEC)\s*=\s*(\S+)", s)
                if m is None or (m[1] == "DEC" and not re.fullmatch(r"\d{1,2}", m[2], re.ASCII)):
                    raise CompgenError(f"{s!r} in the column description: NAME = a column, DEC = the "
                                       "decimals (0 to 99)", where=f"{where}:{k + 1}",
                                       hint="give the table as the control wrote it")
                if m[1] == "NAME":
                    name = m[2]
                elif name:
                    decimals[name] = int(m[2])
            if s.startswith("#STRUCTEND"):
                return k + 1, decimals
        else:
            key = re.search(r'key\s*:=\s*"?([^",\s]+)', s)
            name = key[1] if key else name
            dec = re.search(r"decimals\s*:=\s*(\d+)", s)
            if dec and name:
                decimals[name] = int(dec[1])
            depth += s.count("(") + s.count("[") - s.count(")") - s.count("]")
            if depth <= 0 and k > i:
                return k + 1, decimals
    raise CompgenError("the column-description block does not end", where=f"{where}:{i + 1}")
