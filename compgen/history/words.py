"""The history as a person reads it: the trend as text and JSON, the store's machines."""

from __future__ import annotations

from ..errors import one_line
from ..statistics.results import SHORT_MARKER
from ..units import shown
from .drift import Trend, timeline
from .store import Store


def machines_text(store: Store) -> str:
    """Every machine in the store, with its number of fits and its last one, a line each."""
    rows = store.rows("SELECT m.name, m.serial, COUNT(f.id) AS fits, MAX(s.taken) AS last FROM machines m "
                      "LEFT JOIN sessions s ON s.machine_id = m.id LEFT JOIN fits f ON f.session_id = s.id "
                      "GROUP BY m.id, m.name, m.serial ORDER BY m.name, m.serial")
    if not rows:
        return f"{store.where}: no machine recorded yet"
    lines = []
    for r in rows:
        serial = f" ({one_line(r['serial'])})" if r["serial"] else ""
        lines.append(f"{one_line(r['name'])}{serial}: {r['fits']} fit(s), last {str(r['last'])[:16]}")
    return "\n".join(lines)


def trend_dict(t: Trend) -> dict:
    return {"format": "compgen.trend/1", "machine": t.machine, "serial": t.serial,
            "parameters": list(t.params),
            "fits": [{"taken": e.taken, "fit": e.marker, "kind": e.kind, "device": e.device,
                      "verdict": e.verdict, "sigma_um": e.sigma_um,
                      "values": {n: {"measured": e.values[n], "machine": e.machine_value(n), "std": e.std[n],
                                     "unit": e.units[n]} for n in t.params if n in e.values}}
                     for e in t.entries],
            "edits": [{"taken": e["taken"], "fit": e["marker"], "controller": e["controller"],
                       "corrects": e["corrects"], "written": e["written"], "loaded": e["loaded"]}
                      for e in t.edits],
            "flags": [{"kind": f.kind, "parameter": f.param, "taken": f.taken, "change": f.change,
                       "std": f.std, "unit": f.unit, "since": f.since, "text": f.text()} for f in t.flags]}


def trend_text(t: Trend) -> str:
    """One row per fit: each location error's machine value ± σ (µm, ″); edits between."""
    units = {n: shown(1.0, next(e.units[n] for e in t.entries if n in e.units))[1] for n in t.params}
    head = "".join(f"{n + ' ' + units[n]:>18}" for n in t.params)
    serial = f" ({one_line(t.serial)})" if t.serial else ""
    lines = [f"{one_line(t.machine)}{serial}: machine values (measured + corrections "
             "written before), ± σ", f"{'date':<12}{'fit':<11}{'kind':<12}{head}"]
    for e in timeline(t.entries, t.edits):
        if isinstance(e, dict):
            lines.append(f"{e['taken'][:10]:<12}{'edit':<11}{e['controller'][:11]:<12}corrects "
                         + ", ".join(map(one_line, e["corrects"]))
                         + f" (from {one_line(e['marker'][:SHORT_MARKER])}"
                         + (f", written despite the fit gate: {one_line(e['verdict'])})"
                            if e["verdict"] != "accepted"
                            else ")"))
            continue
        cells = []
        for n in t.params:
            if n not in e.values:
                cells.append(f"{'-':>18}")
                continue
            v, _ = shown(e.machine_value(n), e.units[n])
            s, _ = shown(e.std[n], e.units[n])
            mark = "*" if any(f.param == n and f.taken == e.taken for f in t.flags) else " "
            cells.append(f"{v:>10.2f} ± {s:<4.2f}{mark}")
        # the marker as the edit files carry it (6 digits): the column's width
        lines.append(f"{e.taken[:10]:<12}{one_line(e.marker[:SHORT_MARKER]):<11}{e.kind:<12}{''.join(cells)}")
    lines.append("")
    lines += [f"flagged: {f.text()}" for f in t.flags] or ["nothing flagged against [drift]"]
    return "\n".join(lines) + "\n"
