"""One self-contained HTML report: fit, diagnosis, plots, comparison, files, checklist."""

from __future__ import annotations

import base64
import hashlib
from collections.abc import Sequence
from pathlib import Path
from shlex import quote

from ..controllers import template_dir
from ..model.machine import Machine
from ..statistics.diagnose_text import conclusion, next_name
from ..statistics.diagnosis import Diagnosis
from ..statistics.results import FitResult
from ..units import shown
from .checklist import Step
from .compare import Comparison


def report_html(machine: Machine, fit: FitResult, diagnosis: Diagnosis, images: dict[str, bytes],
                comparison: Comparison | None, emitted: Sequence[str], steps: Sequence[Step],
                version: str, date: str, history=None, history_png: bytes | None = None,
                screen=None, fit_file: str = "fit.json") -> str:
    """The report; with ``history`` (a ``history.Trend``) and its plot, the machine's history
    too; with ``screen`` (a ``verdict.Verdict``), the one screen on its first page. Where the
    diagnosis names nothing found and is no plain tie of machine effects (the device, the
    ball's form, a set-up step, the unexplained), it says diagnose's own first line, its
    commands on ``fit_file``."""
    from jinja2 import Environment, FileSystemLoader, StrictUndefined, select_autoescape

    env = Environment(loader=FileSystemLoader(template_dir()), undefined=StrictUndefined,
                      autoescape=select_autoescape(["html", "j2"]), trim_blocks=True, lstrip_blocks=True)
    params = []
    for name, e in fit.parameters.items():
        v, unit = shown(e.value, e.unit)
        s, _ = shown(e.std, e.unit)
        params.append({"name": name, "value": f"{v:+.3f}", "unit": unit,
                       "std": "fixed" if e.fixed else f"± {s:.3f}",
                       "words": fit.descriptions.get(name, "")})
    n = len(fit.free)
    corr = [[{"text": f"{fit.correlation[i, j]:+.2f}".replace("-0.00", "+0.00"),
              "strong": i != j and abs(fit.correlation[i, j]) >= 0.9} for j in range(n)] for i in range(n)]
    compare_rows = comparison.rows() if comparison is not None else []
    files = []
    for path in emitted:
        raw = Path(path).read_bytes()
        files.append({"name": Path(path).name, "sha256": hashlib.sha256(raw).hexdigest(),
                      "bytes": len(raw)})
    return env.get_template("report/report.html.j2").render(
        machine=machine, fit=fit, params=params, corr=corr, names=list(fit.free),
        diagnosis=diagnosis, visible=[c for c in diagnosis.candidates if c.visible][:8],
        said=conclusion(diagnosis, quote(fit_file), quote(next_name(fit_file))).removeprefix("VERDICT: ")
        .replace(" (below)", " (diagnose prints how)"),
        hidden=[c for c in diagnosis.candidates if not c.visible and (not c.silent or c.separated_by)],
        images={k: base64.b64encode(v).decode("ascii") for k, v in images.items()},
        comparison=comparison, compare_rows=compare_rows, files=files, steps=steps, version=version,
        verdict=screen,
        date=date, history={"trend": history, "png": base64.b64encode(history_png).decode("ascii")}
        if history is not None and history_png else None)
