"""The measuring device as a candidate cause of misfit, beside the machine's effects.

An R-test's sensor that reads (1 + g) of the ball's displacement (a gain error) adds g·yₐ
to each reading in its own direction: the machine's X, Y or Z under a fixed spindle, the
tool's turned axis where the nest turns with a head (``frames.sensor_axes``). To first
order the column of a gain is that share of the true displacement, which the fit's
prediction ŷ estimates without the readings' noise (the readings themselves would
correlate with their own noise and look significant on any dense session). The three gains
are tested as the machine's candidates are (visible beyond the model, the residual each
removes, an F test in the same Bonferroni family), and never added to a model: a device
out of calibration is calibrated and its data measured again; a control is never corrected
for it.

What the data cannot show: all three gains equal (the readings scaled) is exactly a scale
of the location errors; it stays in the budget (``budget.py``: ``[rtest] gain_u``). Two
sensors out of square (γ) add γ/2 of the other direction's displacement: with displacements
of tens of µm, a γ of 0.1° moves a reading by about 0.02 µm (σ of γ ≈ 400″ on the seed's
K4 + K1 + K2 at 0.5 µm noise), so no R-test session resolves a nest's squareness and it is
not a candidate. A probe's centres carry no gain (its stylus radius is checked where its
log is read)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .significance import explained

SENSORS = "XYZ"


@dataclass(frozen=True)
class DeviceCandidate:
    """One device parameter's numbers on a diagnosis's data, its value in its shown unit."""

    effect: str             # gain_X, gain_Y, gain_Z
    description: str
    unit: str               # "%"
    value: float
    std: float
    visibility: float
    drop: float             # the residual sum of squares it removes, mm² (plain)
    drop_w: float           # the same, whitened: what its test uses
    p_value: float = 1.0
    significant: bool = False

    def text(self) -> str:
        """The gain as every text says it: "gain_X +1.31 ± 0.21 %"."""
        return f"{self.effect} {self.value:+.2f} ± {self.std:.2f} %"

    def to_dict(self) -> dict:
        return {"effect": self.effect, "description": self.description, "value": self.value,
                "std": self.std, "unit": self.unit, "visibility": self.visibility,
                "p_value": self.p_value, "significant": self.significant}


def device_columns(pred: np.ndarray, rtest: np.ndarray,
                   axes: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Each gain's column (3n,), mm per 1 of gain, from the fit's prediction ``pred`` (n, 3)
    on the readings an R-test made (``rtest``, (n,)). A sensor reads along its own axis:
    ``axes`` (n, 3, 3, column s sensor s in the machine frame) where the nest turns with a
    head, else the machine's X, Y, Z."""
    y = np.where(rtest[:, None], pred, 0.0)
    out = {}
    for a, s in enumerate(SENSORS):
        if axes is None:
            c = np.zeros_like(y)
            c[:, a] = y[:, a]
        else:                   # the displacement's share along the sensor, read along it
            u = axes[:, :, a]
            c = u * np.einsum("ni,ni->n", u, y)[:, None]
        out[f"gain_{s}"] = c.ravel()
    return out


def device_candidates(pred: np.ndarray, rtest: np.ndarray, Q: np.ndarray, r: np.ndarray, noise,
                      sigma2_w: float, axes: np.ndarray | None = None) -> list[DeviceCandidate]:
    """The device parameters' numbers (p-values left to the caller, who knows the family):
    ``Q``, ``r`` the model's columns and the residual beyond them; ``noise`` the diagnosis's
    ``Whitening``; ``sigma2_w`` the whitened residual's variance. None when no reading is an
    R-test's, or the fit predicts no displacement to scale."""
    if not rtest.any() or not np.any(pred[rtest]):
        return []
    rw = noise.residual(r)
    out = []
    for name, c in device_columns(pred, rtest, axes).items():
        cc, qc, cr = np.array([[c @ c]]), (Q.T @ c)[:, None], np.array([c @ r])
        vis, drop, amp = explained(cc, qc, cr)
        cw = noise.white(c)
        perp = noise.off(cw)
        drop_w = explained(np.array([[cw @ cw]]), (noise.Q.T @ cw)[:, None], np.array([cw @ rw]))[1] \
            if noise.rho.any() else drop
        out.append(DeviceCandidate(
            effect=name, unit="%", value=float(amp[0]) * 100.0,
            std=float(np.sqrt(sigma2_w / max(float(perp @ perp), 1e-300))) * 100.0,
            visibility=float(vis[0]), drop=float(drop), drop_w=float(drop_w),
            description=f"the R-test's {name[-1]} sensor reads its displacement scaled (a gain error)"))
    return out
