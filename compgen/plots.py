"""PNG plots of a fit: measured vs model along each path (as the seed's figures 7–9), and
residual against each rotary axis angle; an earlier fit of the same data drawn beside."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")   # files only: no display on a machine-side laptop or CI
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .errors import CompgenError  # noqa: E402
from .kinematics import Model, Poses  # noqa: E402
from .machine import Machine  # noqa: E402
from .results import FitResult  # noqa: E402
from .rtest import RTestData  # noqa: E402

DIRECTIONS = ("dX", "dY", "dZ")


def _predicted(machine: Machine, poses: Poses, fit: FitResult) -> np.ndarray:
    model = Model(machine, fit.model)
    return model.deviation(poses, np.array([fit.parameters[n].value for n in fit.model])) * 1e3


def write_plots(folder: str | Path, machine: Machine, data: Sequence[RTestData], fit: FitResult,
                before: FitResult | None = None) -> list[Path]:
    """Write the plots into ``folder`` (made if missing); returns the files written."""
    folder = Path(folder)
    images = figures(machine, data, fit, before)
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
            before: FitResult | None = None) -> dict[str, bytes]:
    """PNG images by file name: measured vs model per path, residual vs each rotary axis."""
    if before is not None and [d.sha256 for d in before.data] != [d.sha256 for d in fit.data]:
        raise CompgenError("--before must be a fit of the same data files",
                           hint="compare fits made from the same R-test session")
    poses = Poses.concat([d.poses for d in data])
    measured = np.concatenate([d.deviation for d in data]) * 1e3
    model = _predicted(machine, poses, fit)
    earlier = _predicted(machine, poses, before) if before else None
    label = f"model ({len(fit.model)} parameters)"
    images = {}
    for path in dict.fromkeys(poses.path):
        sel = poses.path == path
        fig, axes = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
        for k, ax in enumerate(axes):
            ax.plot(measured[sel, k], ".", ms=3, color="0.25", label="measured")
            if earlier is not None:
                ax.plot(earlier[sel, k], "--", color="tab:orange",
                        label=f"before ({len(before.model)} parameters)")
            ax.plot(model[sel, k], "-", color="tab:blue", label=label)
            ax.set_ylabel(f"{DIRECTIONS[k]} (µm)")
            ax.grid(alpha=0.3)
        axes[0].set_title(f"{path or 'data'}: measured vs model, {machine.name}")
        axes[0].legend(loc="best", fontsize=8)
        axes[-1].set_xlabel("pose")
        images[f"measured-vs-model-{_safe(path)}.png"] = _png(fig)
    for axis in machine.rotary_axes:
        angle = np.degrees(poses.q[:, machine.index(axis.name)])
        fig, axes = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
        for k, ax in enumerate(axes):
            if earlier is not None:
                ax.plot(angle, measured[:, k] - earlier[:, k], ".", ms=2, color="tab:orange",
                        label=f"before: RMS {before.residual['rms_um']:.2f} µm")
            ax.plot(angle, measured[:, k] - model[:, k], ".", ms=2, color="tab:blue",
                    label=f"residual: RMS {fit.residual['rms_um']:.2f} µm")
            ax.set_ylabel(f"{DIRECTIONS[k]} (µm)")
            ax.grid(alpha=0.3)
        axes[0].set_title(f"residual against {axis.name}, {machine.name}")
        axes[0].legend(loc="best", fontsize=8)
        axes[-1].set_xlabel(f"{axis.name} (deg)")
        images[f"residual-vs-{axis.name}.png"] = _png(fig)
    return images


def _safe(label: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in label) or "data"


def _png(fig) -> bytes:
    buffer = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    return buffer.getvalue()
