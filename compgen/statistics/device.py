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

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..model.sides import span
from .significance import VISIBLE, beside, explained, p_beside, p_value, rivals

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


def tested_devices(res, ranked: dict, noise, rss_w: float, dof: int,
             alpha: float) -> tuple[list[DeviceCandidate], int]:
    """The device beside the machine, in one Bonferroni family with it: its candidates, and
    how many the family holds."""
    devices = device_candidates(res.pred, res.rtest, res.Q, res.r, noise, rss_w / dof, res.axes)
    tested = (sum(1 for row in ranked.values() if row.k_eff)
              + sum(1 for d in devices if d.visibility >= VISIBLE))
    return [replace(d, p_value=p, significant=bool(d.visibility >= VISIBLE and p < alpha))
            for d in devices for p in [p_value(d.drop_w, 1, rss_w, dof, tested)]], tested


def blamed_device(devices: Sequence[DeviceCandidate], best, sigma2_w: float,
            alpha: float) -> str | None:
    """The device parameter that explains the misfit as well as the best of the machine's
    candidates (its rival by ``significance.rivals``, misfit taken as left), or better, or
    alone: then no machine effect is named found."""
    seen = [d for d in devices if d.significant]
    if not seen:
        return None
    top = max(seen, key=lambda d: d.drop_w)
    if best is None or top.drop_w >= best.drop_w or rivals((best.drop_w, best.k_eff), {
            top.effect: (top.drop_w, 1)}, sigma2_w, alpha, True):
        return top.effect
    return None


def told_beside(devices: list[DeviceCandidate], beside_these: np.ndarray, res, noise,
                 alpha: float, lead: str | None = None) -> list[DeviceCandidate]:
    """The device parameters told beside what explains the misfit first: the blamed gain
    (``lead``), or, where none is, the machine's best candidate and the second effects that
    stay significant beside it (whitened columns ``beside_these``), and then the gain that stays
    most significant beside those. Significant only where they stay so, one after the other,
    and each told as estimated with them (and with the gains that stay). Alone, a gain takes
    a share of a misfit it does not cause: an X gain of 1.5 % made Z's read −0.6 ± 0.15 %
    (p 0.006), and beside a Z gain of −1.5 % read 2.5 % itself; a calibrated R-test beside an
    unmodelled 15″ 2/rev angle of C read X −56 ± 1.7 % (p < 1e-300), and beside the best of
    three machine effects X was significant, where the other two took it back."""
    cols = {e: noise.white(c)[:, None] for e, c in device_columns(res.pred, res.rtest, res.axes).items()}
    rw = noise.residual(res.r)
    machine = span(noise.off(beside_these))     # rivals among second effects are one column

    def tested(names, added):
        """These gains' p-values beside the model and ``added``, Bonferroni over them."""
        basis = span(noise.off(added))
        prods = {e: beside(cols[e], noise, basis, rw) for e in names}
        return p_beside(noise.Q, basis, rw, prods) if prods else {}

    # beside the machine's effects every gain the model leaves visible is tested again: alone,
    # a gain is tested against a residual the misfit it does not cause inflates
    seen = [d.effect for d in devices if (d.significant if lead else d.visibility >= VISIBLE)]
    p = {} if lead else tested(seen, machine)
    lead = lead or min((e for e in seen if p[e] < alpha), key=p.get, default=None)
    if lead:
        p |= tested([e for e in seen if e != lead], np.column_stack([machine, cols[lead]]))
    joint = [lead, *(e for e in seen if e != lead and p[e] < alpha)] if lead else []

    # every gain's column off the model beside the machine's effects (off it already:
    # ``span`` of what was), and their products with each other and the residual,
    # once: each joint fit below is then a few columns' normal equations
    names = list(cols)
    C = [*(noise.off(cols[e]) for e in names), machine]       # side by side, never copied so
    CC, Cr = np.block([[a.T @ b for b in C] for a in C]), np.concatenate([a.T @ rw for a in C])
    rr = float(rw @ rw)
    beside_m = list(range(len(names), len(CC)))

    def together(chosen):
        """Values and σ, %, of these gains fitted at once with the model and the machine's
        effects, σ from the residual all of them leave: the misfit they explain is not noise."""
        at = [names.index(e) for e in chosen] + beside_m
        inv = np.linalg.inv(CC[np.ix_(at, at)])
        amp = inv @ Cr[at]
        left = max(rr - float(Cr[at] @ amp), 0.0)
        std = np.sqrt(np.diag(inv) * left / (res.dof - len(at)))
        return {e: (float(a) * 100.0, float(s) * 100.0) for e, a, s in zip(chosen, amp, std, strict=False)}

    told = together(joint)
    for d in devices:
        if d.effect not in told:
            told[d.effect] = together([*joint, d.effect])[d.effect]
    return [replace(d, value=told[d.effect][0], std=told[d.effect][1], p_value=p.get(d.effect, d.p_value),
                    significant=d.effect in joint) for d in devices]
