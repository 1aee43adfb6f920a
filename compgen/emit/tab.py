"""HEIDENHAIN tables (``*.TAB``): fixed-width text read and written back.

The first line is ``BEGIN <name>.TAB [MM|INCH]``; an optional column-description block may
follow; the header line fixes each column's start; rows; ``[END]``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import CompgenError
from . import render

KEYS = {"Trans", "MachAxis", "MachBase", "CMO", "ToolAxis", "TOOLFILE", "SUBFILE1", "SUBFILE2"}


@dataclass
class TabTable:
    """A HEIDENHAIN description table as text columns (layout: U4)."""

    name: str
    columns: list[str]
    starts: list[int]
    rows: list[dict]

    @staticmethod
    def parse(text: str, where: str) -> TabTable:
        lines = text.splitlines()
        head = next((i for i, ln in enumerate(lines) if re.match(r"\s*NR\s+", ln) and "KEY" in ln), None)
        if head is None:
            raise CompgenError("no header line with NR and KEY", where=where,
                               hint="give the kinematics description table (*.TAB) of the machine")
        m = re.match(r"BEGIN\s+(\S+?)(?:\.TAB)?\s", lines[0] + " ") if lines else None
        cols = lines[head].split()
        starts = [lines[head].index(c) for c in cols]
        rows = []
        for k, ln in enumerate(lines[head + 1:], start=head + 2):
            if ln.strip().startswith("[END]"):
                break
            if not ln.strip():
                continue
            cells = {c: ln[s:(starts[i + 1] if i + 1 < len(starts) else None)].strip()
                     for i, (c, s) in enumerate(zip(cols, starts, strict=True))}
            if cells.get("KEY") not in KEYS:
                raise CompgenError(f"KEY {cells.get('KEY')!r} is not a kinematics key",
                                   where=f"{where}:{k}",
                                   hint="the table's columns must line up with its header line")
            if cells.get("KEY") == "Trans":
                try:
                    float(cells.get("COORD", ""))
                except ValueError:
                    raise CompgenError(f"Trans row has COORD {cells.get('COORD')!r}, not a number",
                                       where=f"{where}:{k}") from None
            rows.append(cells)
        else:
            raise CompgenError("no [END] line", where=where)
        return TabTable(m[1] if m else Path(where).stem, cols, starts, rows)

    def text(self) -> str:
        widths = [self.starts[i + 1] - self.starts[i] for i in range(len(self.starts) - 1)] + [0]

        def line(cells):
            return "".join(str(cells.get(c, "")).ljust(w)
                           for c, w in zip(self.columns, widths, strict=True)).rstrip()

        body = [line({c: c for c in self.columns})]
        body += [line({**r, "NR": str(i)}) for i, r in enumerate(self.rows)]
        return render("heidenhain/table.TAB.j2", name=self.name, lines=body)
