"""PNG plots of a fit: measured vs model along each path (as the seed's figures 7–9), and
residual against each axis's position (rotary: angle; linear: where a scale or screw error
shows its pitch), with the residual's strongest line against it; an earlier fit of the same
data drawn beside."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")   # files only: no display on a machine-side laptop or CI
# a machine's name, a path label or a serial is text, never mathtext: "$x_1$" in a name is
# drawn as written (a lone "$" would otherwise stop the plot); compgen's own labels use none
matplotlib.rcParams["text.parse_math"] = False
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..data.rtest import Measurements, RTestData  # noqa: E402
from ..errors import CompgenError, one_line  # noqa: E402
from ..model.effects import effect_of_param, resolve  # noqa: E402
from ..model.machine import Machine  # noqa: E402
from ..model.poses import Poses  # noqa: E402
from ..planning.advice import Proposal  # noqa: E402
from ..statistics.diagnosis import Diagnosis  # noqa: E402
from ..statistics.identify import Normal, fitted  # noqa: E402
from ..statistics.results import FitResult  # noqa: E402
from ..statistics.signature import columns  # noqa: E402
from ..statistics.spectrum import MIN_PITCH_MM  # noqa: E402
from ..units import shown  # noqa: E402

DIRECTIONS = ("dX", "dY", "dZ")
# rivals may lie on each other: each is drawn in its own colour, line style and marker
STYLES = ("-", "--", ":", "-.")
MARKERS = ("o", "s", "^", "v", "D", "x")
ON_EACH_OTHER_UM = 0.01   # two curves closer than this everywhere are said to coincide
DRAWN = 4000              # points a series draws at most: a dense session's are thinned evenly (the
                          # figures' numbers, RMS and fits, always use every reading)
STYLE = "report/plots.mplstyle"   # the look (sizes, fonts, grid), in the templates: no number here
PANEL_IN, TITLE_IN = 1.8, 0.6     # the trend's height: inches per parameter, and for its title


def _drawn(index: np.ndarray) -> np.ndarray:
    """The poses of ``index`` a series draws: all, or every k-th where there are more than
    ``DRAWN`` (a plot of 289 000 dots shows what one of 4000 shows, 70 times slower)."""
    return index[::-(-len(index) // DRAWN)] if len(index) > DRAWN else index


def _thinned(n: int) -> str:
    return f" (every {-(-n // DRAWN)}th of {n} readings drawn)" if n > DRAWN else ""


def write_plots(folder: str | Path, machine: Machine, data: Sequence[RTestData], fit: FitResult,
                before: FitResult | None = None, found: Diagnosis | None = None) -> list[Path]:
    """Write the plots into ``folder`` (made if missing); returns the files written."""
    folder = Path(folder)
    images = figures(machine, data, fit, before, found)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CompgenError(f"cannot make the plot folder: {exc.strerror}", where=str(folder)) from None
    written = []
    for name, png in images.items():
        path = folder / name
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_bytes(png)
        tmp.replace(path)
        written.append(path)
    return written


def figures(machine: Machine, data: Sequence[RTestData], fit: FitResult,
            before: FitResult | None = None, found: Diagnosis | None = None) -> dict[str, bytes]:
    """PNG images by file name (``drawings``, each as a PNG)."""
    return {name: _png(fig) for name, fig in drawings(machine, data, fit, before, found).items()}


def _styled(draw):
    """``draw`` with compgen's look (``STYLE``) in force while its figure is made."""
    def styled(*args, **kwargs):
        from ..controllers import template_dir
        with plt.style.context(template_dir() / STYLE):
            return draw(*args, **kwargs)
    return styled


@_styled
def drawings(machine: Machine, data: Sequence[RTestData], fit: FitResult,
             before: FitResult | None = None, found: Diagnosis | None = None) -> dict:
    """The figures (matplotlib's, by PNG file name; the caller closes them): measured vs
    model per path, residual vs each axis per path (a linear axis where the data move it
    ``MIN_PITCH_MM`` or more; the title names the strongest line ``found`` saw against it),
    and, when ``found`` has rivals, what each would leave on the measurement that tells
    them apart. Every value drawn is in µm (deviations) and in deg or mm (axes)."""
    if before is not None and [d.sha256 for d in before.data] != [d.sha256 for d in fit.data]:
        raise CompgenError("--before must be a fit of the same data files",
                           hint="compare fits made from the same R-test session")
    joined = Measurements.concat(data)
    poses, measured = joined.poses, joined.deviation * 1e3
    model = fitted(machine, fit, data) * 1e3         # with the start sides it fitted, if any
    earlier = fitted(machine, before, data) * 1e3 if before else None
    label = f"model ({len(fit.model)} parameters)"
    images = {}
    # each path's poses, found once (the figures ask for them 1 + 3 × axes times: 0.4 s of
    # comparisons at 723 000 readings)
    paths = list(dict.fromkeys(poses.path))
    selected = {path: np.flatnonzero(poses.path == path) for path in paths}
    for path in paths:
        sel = selected[path]
        shown_at = _drawn(np.arange(len(sel)))
        at = sel[shown_at]
        fig, axes = plt.subplots(3, 1, sharex=True)
        for k, ax in enumerate(axes):
            ax.plot(shown_at, measured[at, k], ".", color="0.25", label="measured")
            if earlier is not None:
                ax.plot(shown_at, earlier[at, k], "--", color="tab:orange",
                        label=f"before ({len(before.model)} parameters)")
            ax.plot(shown_at, model[at, k], "-", color="tab:blue", label=label)
            ax.set_ylabel(f"{DIRECTIONS[k]} (µm)")
        name = one_line(machine.name)
        axes[0].set_title(f"{path or 'data'}: measured vs model, {name}{_thinned(len(sel))}")
        axes[0].legend()
        axes[-1].set_xlabel("pose")
        images[f"measured-vs-model-{_safe(path)}.png"] = fig
    everywhere = _drawn(np.arange(len(poses)))
    thinned = _thinned(max(len(sel) for sel in selected.values()))
    for axis in machine.axes:     # rotary: per revolution; linear: scale and screw periods
        where = poses.q[:, machine.index(axis.name)]
        where = np.degrees(where) if axis.rotary else where
        if not axis.rotary and np.ptp(where) < MIN_PITCH_MM:
            continue
        fig, axes = plt.subplots(3, 1, sharex=True)
        for k, ax in enumerate(axes):
            if earlier is not None:
                ax.plot(where[everywhere], measured[everywhere, k] - earlier[everywhere, k], ".",
                        color="0.7", label=f"before: RMS {before.residual['rms_um']:.2f} µm")
            for i, path in enumerate(paths):        # a path that holds the axis still is a column
                sel = selected[path]
                res = measured[sel, k] - model[sel, k]
                at = _drawn(np.arange(len(sel)))
                ax.plot(where[sel[at]], res[at], ".", color=f"C{i}",       # C10 is C0 again
                        label=f"{path or 'data'}: RMS {np.sqrt((res**2).mean()):.2f} µm")
            ax.set_ylabel(f"{DIRECTIONS[k]} (µm)")
        line = next((x for x in (found.lines if found is not None else ()) if x.against == axis.name), None)
        axes[0].set_title(f"residual against {axis.name} per path, {one_line(machine.name)}{thinned}"
                          + (f"\nstrongest line: {line.text()}" if line is not None else ""))
        axes[0].legend()
        axes[-1].set_xlabel(f"{axis.name} ({'deg' if axis.rotary else 'mm'})")
        images[f"residual-vs-{axis.name}.png"] = fig
    if found is not None and found.rivals and found.rivals_separated_by:
        images["rivals.png"] = _rivals(machine, poses, fit, found, measured - model)
    return images


def _rivals(machine: Machine, poses: Poses, fit: FitResult, found: Diagnosis, residual: np.ndarray):
    extra = found.rivals_separated_by[0]
    curves = rival_curves(machine, poses, fit, found, extra)
    labels = {}
    for name, (_, after) in curves.items():   # say so where two lie on each other there
        same = [o for o in labels if np.abs(curves[o][1] - after).max() < ON_EACH_OTHER_UM]
        labels[name] = name + (f" (= {', '.join(same)} on {extra.label})" if same else "")
    fig, axes = plt.subplots(3, 2, sharex="col", gridspec_kw={"width_ratios": [3, 1]})
    for k in range(3):
        at = _drawn(np.arange(len(residual)))
        axes[k, 0].plot(at, residual[at, k], ".", color="0.6", label="residual")
        for i, (name, (now, after)) in enumerate(curves.items()):
            for ax, curve in ((axes[k, 0], now), (axes[k, 1], after)):
                at = _drawn(np.arange(len(curve)))
                # where rivals lie on each other only their markers tell them: each curve marks
                # every (3n + 1)-th pose from 3i on, so no two mark the same pose
                ax.plot(at, curve[at, k], STYLES[i % len(STYLES)], lw=1.2 + 0.6 * (len(curves) - 1 - i),
                        color=f"C{i}", marker=MARKERS[i % len(MARKERS)],
                        markevery=(3 * i, 3 * len(curves) + 1), label=labels[name])
        axes[k, 0].set_ylabel(f"{DIRECTIONS[k]} (µm)")
    axes[0, 0].set_title("measured: the rivals explain the misfit alike")
    axes[0, 1].set_title(f"{extra.label}:\nwhat each would leave")
    axes[0, 0].legend()
    axes[-1, 0].set_xlabel("pose (measured)")
    axes[-1, 1].set_xlabel("pose (to measure)")
    return fig


def rival_curves(machine: Machine, poses: Poses, fit: FitResult, found: Diagnosis,
                 extra: Proposal) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """For the best candidate and each rival at its fitted size: the misfit (µm, (n, 3)) the
    fit's model leaves of it on the measured poses, and the misfit it would leave on
    ``extra`` once that is measured too (first order): alike on the first, apart on the
    second when ``extra`` tells them apart."""
    model_effects = list(dict.fromkeys(effect_of_param(machine, n) for n in fit.free))
    both = Poses.concat([poses, extra.poses])
    n3 = 3 * len(poses)
    drawn = (found.significant[0].effect, *found.rivals)
    named = {c.effect: c for c in found.candidates if c.effect in drawn}
    # one walk of the chains (in blocks) for the model's columns and every rival's, each
    # rival kept as its curve at the fitted size (one column, not its parameters')
    rivals = [resolve(machine, n) for n in named]
    C = columns(machine, both, [*model_effects, *rivals])
    p = sum(len(e.params) for e in model_effects)
    J, at, v = C[:, :p], p, {}
    for e in rivals:
        v[e.name] = C[:, at:at + len(e.params)] @ (np.array(named[e.name].amplitude) / shown(1.0, e.unit)[0])
        at += len(e.params)
    # the misfit left is the part of a curve off the model's span, on the measured poses
    # alone and on both: normal equations of p columns (a QR of millions of rows took 0.8 s,
    # the walk of every pose at once 1.9 s at 723 000 readings)
    now_fit, both_fit = Normal(J[:n3]), Normal(J)
    out = {}
    for name in named:
        now = v[name][:n3] - J[:n3] @ now_fit.solve(v[name][:n3])
        after = v[name][n3:] - J[n3:] @ both_fit.solve(v[name])
        out[name] = (now.reshape(-1, 3) * 1e3, after.reshape(-1, 3) * 1e3)
    return out


def _safe(label: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in label) or "data"


def _png(fig) -> bytes:
    buffer = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buffer, format="png")           # at the figure's dpi (STYLE's)
    plt.close(fig)
    return buffer.getvalue()


def trend_png(t, limits: dict[str, float] | None = None, tolerances: dict[str, float] | None = None) -> bytes:
    """A machine's history (``history.Trend``) as a PNG (``trend_figure``)."""
    return _png(trend_figure(t, limits, tolerances))


@_styled
def trend_figure(t, limits: dict[str, float] | None = None, tolerances: dict[str, float] | None = None):
    """A machine's history (``history.Trend``): each location error's machine value over
    time (in the unit it is shown in) with its ±2σ band; edits as vertical lines, flagged
    fits circled in red. ``limits`` (parameter → the ``[drift]`` limit of its class, mm or
    rad): the band a check judges against, the last accepted calibration's machine value ±
    the limit, a step at each calibration. ``tolerances`` (path → µm, the machine file's
    ``[tolerances]``): a panel per path that checks measured, its largest deviation range at
    each check against the tolerance. One panel each, each as tall whatever their number."""
    from datetime import datetime

    paths = [p for p in (tolerances or {}) if any(p in r for _, r in t.ranges)]
    n = len(t.params) + len(paths)
    width = plt.rcParams["figure.figsize"][0]
    fig, axes = plt.subplots(n, 1, figsize=(width, PANEL_IN * n + TITLE_IN), sharex=True, squeeze=False)
    for ax, path in zip(axes[len(t.params):, 0], paths, strict=True):
        seen = [(datetime.fromisoformat(taken), r[path]) for taken, r in t.ranges if path in r]
        ax.plot([w for w, _ in seen], [v for _, v in seen], "s-", label="check")
        ax.axhline(tolerances[path], color="0.4", lw=0.8, ls=":", label="[tolerances]")
        ax.set_ylabel(f"{path} range (µm)")
    for ax, name in zip(axes[:len(t.params), 0], t.params, strict=True):
        rows = [e for e in t.entries if name in e.values]
        when = [datetime.fromisoformat(e.taken) for e in rows]
        v = np.array([shown(e.machine_value(name), e.units[name])[0] for e in rows])
        s = np.array([shown(e.std[name], e.units[name])[0] for e in rows])
        unit = shown(1.0, rows[0].units[name])[1] if rows else ""
        ax.fill_between(when, v - 2 * s, v + 2 * s, alpha=0.25, step=None, label="±2σ")
        ax.plot(when, v, "o-")
        if limits and name in limits and rows:
            # the reference of each fit: the last accepted calibration at or before it
            ref, refs = None, []
            for e, value in zip(rows, v, strict=True):
                if e.kind == "calibration" and e.verdict == "accepted":
                    ref = value
                refs.append(np.nan if ref is None else ref)
            lim = shown(limits[name], rows[0].units[name])[0]
            refs = np.array(refs)
            for sign in (-1, 1):
                ax.step(when, refs + sign * lim, where="post", color="0.4", lw=0.8, ls=":",
                        label="[drift] limit" if sign == 1 else None)
        for e in t.edits:
            ax.axvline(datetime.fromisoformat(e["taken"]), color="k", ls="--", lw=0.8)
        bad = [i for i, e in enumerate(rows) if any(f.param == name and f.taken == e.taken for f in t.flags)]
        if bad:
            ax.plot([when[i] for i in bad], v[bad], "o", ms=10, mfc="none", mec="red")
        ax.set_ylabel(f"{name} ({unit})")
    axes[0, 0].set_title(f"{one_line(t.machine)}: machine values over time (dashed: edits; red: flagged"
                         + ("; dotted: the [drift] limit about the last calibration" if limits else "")
                         + ("; a path's range against its [tolerances]" if paths else "") + ")")
    fig.autofmt_xdate()
    return fig


def front_png(machine: Machine, p) -> bytes:
    """A plan's front (``planning.plan.Plan``) as a PNG: the worst σ of the location errors
    over their ``[limits]`` against minutes, for the sets the search met; the plan chosen and
    the machine file's own paths marked: what five more minutes buy."""
    return _png(_front_figure(machine, p))


@_styled
def _front_figure(machine: Machine, p):
    from matplotlib.ticker import FuncFormatter

    fig, ax = plt.subplots()
    if p.front:
        # the front's points buy 5 % or more each; it runs on to the plan chosen
        points = [*p.front, *([(p.minutes, p.worst)] if p.minutes > p.front[-1][0] else [])]
        minutes, worst = zip(*points, strict=True)
        ax.step(minutes, worst, where="post", marker="o", label="the best set within the minutes")
    ax.plot([p.minutes], [p.worst], "s", ms=9, label=f"the plan ({p.minutes:.1f} min)")
    ax.plot([p.default[0]], [p.default[2]], "D", ms=9,
            label=f"the machine file's paths ({', '.join(machine.paths)}, {p.default[0]:.1f} min)")
    ax.set_xlabel("minutes (programs, and 5 min each mounting of the ball elsewhere)")
    ax.set_ylabel("worst σ over its [limits]")
    ax.set_yscale("log")
    plain = FuncFormatter(lambda v, _: f"{v:g}")     # numbers as numbers (mathtext is off)
    ax.yaxis.set_major_formatter(plain)
    ax.yaxis.set_minor_formatter(plain)
    ax.set_title(f"{one_line(machine.name)}: what more minutes buy (noise {p.noise_um:g} µm)")
    ax.legend()
    return fig
