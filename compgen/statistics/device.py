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
log is read).

The ball the R-test reads is a device too. A ball not round, its radius R + a·sinᵏθ·cos k(φ − φ₀)
about its stem (θ from the stem's axis, φ about it: k lobes; an oval's k is 2), is read by each
sensor where it touches, along that sensor: a pattern that turns with the table, as a
rotary axis's radial error motion of order k does, and on most paths is nearly one (three
lobes against a radial 3/rev of C differ by 0.04 µm on the seed's K4, K1, K2). Turned on its
stem by β (``fit --ball-turned``) the ball's form turns by β and the machine's does not:
180°/k makes the form read the other way round. Where the form and the machine's best
explain the data alike, neither is named: the ball turned tells them apart
(``blamed_device``).

A touch probe's centres carry its trigger instead: the radius at which it triggers, varying in
lobes about the stylus by the direction it moves (``probe.trigger_lobes``), moves each
centre by what the pose's touches make of it. It is a device parameter as a gain is: blamed
where it explains the misfit as well as the machine's best, never added to a model; its
remedy is the probe's calibration (or the probe turned in the spindle), then probing again."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..data.probe import TRIGGER_LOBES
from ..model.frames import sensors_on_ball
from ..model.sides import span
from .significance import VISIBLE, beside, explained, p_beside, p_value, rivals

SENSORS = "XYZ"
LOBES = (2, 3, 4)          # a ball's form about its stem: an oval, three lobes, four
FORM = "ball_lobes"        # its candidates' names: ball_lobes2, ball_lobes3, ball_lobes4
TRIGGER = "probe_lobes"    # a probe's trigger lobes: probe_lobes3 (``probe.TRIGGER_LOBES``)
SHOWN = {"gain": ("%", 100.0), "ball": ("µm", 1e3), "probe": ("µm", 1e3)}   # unit, per 1 (a gain) or per mm


@dataclass(frozen=True)
class DeviceCandidate:
    """One device parameter's numbers on a diagnosis's data, its value in its shown unit."""

    effect: str             # gain_X, gain_Y, gain_Z, or the ball's form ball_lobes2 … 4
    description: str
    unit: str               # "%" (a gain), "µm" (the form's amplitude: its radius off round)
    value: float
    std: float
    visibility: float
    drop: float             # the residual sum of squares it removes, mm² (plain)
    drop_w: float           # the same, whitened: what its test uses
    p_value: float = 1.0
    significant: bool = False
    columns: int = 1        # a form's two: its lobes' cos and sin

    def text(self) -> str:
        """The parameter as every text says it: "gain_X +1.31 ± 0.21 %", "ball_lobes3 0.80 ± 0.03 µm"."""
        return f"{self.effect} {self.value:+.2f} ± {self.std:.2f} {self.unit}"

    @property
    def form(self) -> bool:
        """The ball's form, not the R-test's sensors."""
        return self.effect.startswith(FORM)

    @property
    def trigger(self) -> bool:
        """The probe's trigger lobes."""
        return self.effect.startswith(TRIGGER)

    def to_dict(self) -> dict:
        return {"effect": self.effect, "description": self.description, "value": self.value,
                "std": self.std, "unit": self.unit, "visibility": self.visibility,
                "p_value": self.p_value, "significant": self.significant}


def device_columns(pred: np.ndarray, rtest: np.ndarray,
                   axes: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Each gain's column (3n, 1), mm per 1 of gain, from the fit's prediction ``pred`` (n, 3)
    on the readings an R-test made (``rtest``, (n,)). A sensor reads along its own axis:
    ``axes`` (n, 3, 3, column s sensor s in the machine frame) where the nest turns with a
    head, else the machine's X, Y, Z. Empty where the fit predicts no displacement to scale."""
    y = np.where(rtest[:, None], pred, 0.0)
    out = {}
    if not rtest.any() or not np.any(y):
        return out
    for a, s in enumerate(SENSORS):
        if axes is None:
            c = np.zeros_like(y)
            c[:, a] = y[:, a]
        else:                   # the displacement's share along the sensor, read along it
            u = axes[:, :, a]
            c = u * np.einsum("ni,ni->n", u, y)[:, None]
        out[f"gain_{s}"] = c.reshape(-1, 1)
    return out


def form_columns(machine, poses, rtest: np.ndarray, axes: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Each lobe order's two columns (3n, 2), mm per mm of the form's cos and sin amplitude:
    sensor s (``frames.sensors_on_ball``) touches the ball on its side
    along s, so a radius larger there by δ reads the ball nearer that sensor, nest minus ball
    −δ along s; δ in the ball's own frame, the table's turned by ``poses.turn`` about the
    stem (its z). ``axes``: the sensors' ``sensor_axes``, where known already."""
    n = len(poses)
    if not rtest.any():
        return {}
    axes, on_table = sensors_on_ball(machine, poses.q, axes)
    turn = np.exp(-1j * poses.turn)
    flat = [(on_table[:, 0, s] + 1j * on_table[:, 1, s]) * turn for s in range(3)]   # sinθ·e^{iφ}, ball frame
    power, out = [np.ones(n, complex) for _ in range(3)], {}
    for k in range(1, max(LOBES) + 1):
        power = [p * w for p, w in zip(power, flat, strict=True)]
        if k not in LOBES:
            continue
        lobe = np.stack([np.stack([wk.real, wk.imag], axis=-1) for wk in power], axis=1)    # (n, s, 2)
        c = np.einsum("nds,nsk->ndk", axes, -lobe) if machine.heads else -lobe    # else the axes are X, Y, Z
        c[~rtest] = 0.0
        out[f"{FORM}{k}"] = c.reshape(-1, 2)
    return out


def trigger_columns(lobes: np.ndarray | None, bad: np.ndarray) -> dict[str, np.ndarray]:
    """The probe trigger's lobes as a candidate's two columns (3n, 2), mm per mm, from the
    readings' ``Measurements.lobes``, the outlying readings ``bad`` left out as the
    diagnosis leaves them; none where no reading is a probe's."""
    if lobes is None:
        return {}
    return {f"{TRIGGER}{TRIGGER_LOBES}": np.delete(lobes, bad, axis=0).reshape(-1, 2)}


def _shown(name: str, amp: np.ndarray, cov: np.ndarray) -> tuple[float, float]:
    """A parameter's value and σ in its shown unit from its columns' amplitudes and their
    covariance: a gain's one; a form's size, √(c² + s²), and its σ along that direction."""
    scale = SHOWN[name.split("_")[0]][1]
    if len(amp) == 1:
        return float(amp[0]) * scale, float(np.sqrt(max(cov[0, 0], 0.0))) * scale
    size = float(np.hypot(*amp))
    u = amp / size if size > 0 else np.array([1.0, 0.0])
    return size * scale, float(np.sqrt(max(u @ cov @ u, 0.0))) * scale


def device_candidates(columns: dict[str, np.ndarray], Q: np.ndarray, r: np.ndarray, noise,
                      sigma2_w: float) -> list[DeviceCandidate]:
    """The device parameters' numbers (p-values left to the caller, who knows the family)
    from their ``columns`` (``device_columns``, ``form_columns``): ``Q``, ``r`` the model's
    columns and the residual beyond them; ``noise`` the diagnosis's ``Whitening``;
    ``sigma2_w`` the whitened residual's variance."""
    rw = noise.residual(r) if columns else None
    out = []
    for name, c in columns.items():
        qc = Q.T @ c
        vis, drop, amp = explained(c.T @ c, qc, c.T @ r)
        cw = noise.white(c)
        qw = noise.Q.T @ cw if noise.rho.any() else qc          # white noise: the same products
        perp = cw - noise.Q @ qw
        drop_w = explained(cw.T @ cw, qw, cw.T @ rw)[1] if noise.rho.any() else drop
        value, std = _shown(name, amp, sigma2_w * np.linalg.pinv(perp.T @ perp))
        k = name[len(FORM):] if name.startswith(FORM) else ""
        out.append(DeviceCandidate(
            effect=name, unit=SHOWN[name.split("_")[0]][0], value=value, std=std,
            visibility=float(vis.min()), drop=float(drop), drop_w=float(drop_w), columns=c.shape[1],
            description=f"the ball's form, {k} lobes about its stem (its radius off round)" if k else
                        f"the probe's trigger, {name[len(TRIGGER):]} lobes about the stylus (its radius by "
                        "the direction it moves)" if name.startswith(TRIGGER) else
                        f"the R-test's {name[-1]} sensor reads its displacement scaled (a gain error)"))
    return out


def tested_devices(res, columns: dict[str, np.ndarray], ranked: dict, noise, rss_w: float, dof: int,
                   alpha: float) -> tuple[list[DeviceCandidate], int]:
    """The device beside the machine, in one Bonferroni family with it: its candidates (of
    ``columns``), and how many the family holds."""
    devices = device_candidates(columns, res.Q, res.r, noise, rss_w / dof)
    tested = (sum(1 for row in ranked.values() if row.k_eff)
              + sum(1 for d in devices if d.visibility >= VISIBLE))
    return [replace(d, p_value=p, significant=bool(d.visibility >= VISIBLE and p < alpha))
            for d in devices for p in [p_value(d.drop_w, d.columns, rss_w, dof, tested)]], tested


def blamed_device(devices: Sequence[DeviceCandidate], best, sigma2_w: float,
                  alpha: float) -> tuple[str | None, str | None]:
    """The device parameter blamed for the misfit, and the ball's form tied with the
    machine's best (``significance.rivals``, misfit taken as left). A sensor's gain, or a
    probe's trigger, is blamed where it explains as well as the best of the machine's
    candidates, or better, or alone:
    then no machine effect is named found. The ball's form is blamed only where the best is
    no rival of it; where each is the other's rival, neither is named: a ball turned on its
    stem tells them apart."""
    gains = [d for d in devices if d.significant and not d.form]
    forms = [d for d in devices if d.significant and d.form]
    if gains:
        top = max(gains, key=lambda d: d.drop_w)
        if best is None or top.drop_w >= best.drop_w or rivals((best.drop_w, best.k_eff), {
                top.effect: (top.drop_w, top.columns)}, sigma2_w, alpha, True):
            return top.effect, None
    if not forms:
        return None, None
    top = max(forms, key=lambda d: d.drop_w)
    if best is None or not rivals((top.drop_w, top.columns), {"best": (best.drop_w, best.k_eff)},
                                  sigma2_w, alpha, True):
        return top.effect, None
    tied = rivals((best.drop_w, best.k_eff), {top.effect: (top.drop_w, top.columns)}, sigma2_w, alpha, True)
    return None, (top.effect if tied else None)


def told_beside(devices: list[DeviceCandidate], columns: dict[str, np.ndarray], beside_these: np.ndarray,
                res, noise, alpha: float, lead: str | None = None) -> list[DeviceCandidate]:
    """The device parameters told beside what explains the misfit first: the blamed one
    (``lead``), or, where none is, the machine's best candidate and the second effects that
    stay significant beside it (whitened columns ``beside_these``), and then the parameter
    that stays most significant beside those. Significant only where they stay so, one after
    the other, and each told as estimated with them (and with those that stay). Alone, a gain
    takes a share of a misfit it does not cause: an X gain of 1.5 % made Z's read −0.6 ± 0.15 %
    (p 0.006), and beside a Z gain of −1.5 % read 2.5 % itself; a calibrated R-test beside an
    unmodelled 15″ 2/rev angle of C read X −56 ± 1.7 % (p < 1e-300), and beside the best of
    three machine effects X was significant, where the other two took it back."""
    cols = {e: noise.white(c) for e, c in columns.items()}
    qc = {e: noise.Q.T @ c for e, c in cols.items()}          # one pass over Q for each
    rw = noise.residual(res.r)
    machine = span(noise.off(beside_these))     # rivals among second effects are one column

    def tested(names, added):
        """These parameters' p-values beside the model and ``added``, Bonferroni over them."""
        basis = span(noise.off(added))
        prods = {e: beside(cols[e], noise, basis, rw, qc[e]) for e in names}
        return p_beside(noise.Q, basis, rw, prods) if prods else {}

    # beside the machine's effects every parameter the model leaves visible is tested again:
    # alone, one is tested against a residual the misfit it does not cause inflates
    seen = [d.effect for d in devices if (d.significant if lead else d.visibility >= VISIBLE)]
    p = {} if lead else tested(seen, machine)
    lead = lead or min((e for e in seen if p[e] < alpha), key=p.get, default=None)
    if lead:
        p |= tested([e for e in seen if e != lead], np.column_stack([machine, cols[lead]]))
    joint = [lead, *(e for e in seen if e != lead and p[e] < alpha)] if lead else []

    # every parameter's columns off the model beside the machine's effects (off it already:
    # ``span`` of what was), and their products with each other and the residual,
    # once: each joint fit below is then a few columns' normal equations
    names = list(cols)
    C = [*(cols[e] - noise.Q @ qc[e] for e in names), machine]       # side by side, never copied so
    CC, Cr = np.block([[a.T @ b for b in C] for a in C]), np.concatenate([a.T @ rw for a in C])
    rr = float(rw @ rw)
    first = np.cumsum([0, *(c.shape[1] for c in C)])
    where = {e: list(range(first[i], first[i + 1])) for i, e in enumerate(names)}
    beside_m = list(range(first[len(names)], len(CC)))

    def together(chosen):
        """Values and σ (shown units) of these parameters fitted at once with the model and the
        machine's effects, σ from the residual all of them leave: the misfit they explain is not
        noise."""
        at = [j for e in chosen for j in where[e]] + beside_m
        inv = np.linalg.inv(CC[np.ix_(at, at)])
        amp = inv @ Cr[at]
        left = max(rr - float(Cr[at] @ amp), 0.0)
        cov = inv * left / (res.dof - len(at))
        out, i = {}, 0
        for e in chosen:
            k = len(where[e])
            out[e] = _shown(e, amp[i:i + k], cov[i:i + k, i:i + k])
            i += k
        return out

    told = together(joint)
    for d in devices:
        if d.effect not in told:
            told[d.effect] = together([*joint, d.effect])[d.effect]
    return [replace(d, value=told[d.effect][0], std=told[d.effect][1], p_value=p.get(d.effect, d.p_value),
                    significant=d.effect in joint) for d in devices]
