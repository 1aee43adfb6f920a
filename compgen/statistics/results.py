"""The fit result as a value: fit.json in and out, and the human report.

fit.json (format ``compgen.fit/1``) stores values in inside units (mm, rad) with the unit
beside them; µm and arcsec appear only in ``report()``. Python's json writes floats with
repr, so values round-trip exactly.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .. import me
from ..errors import CompgenError
from ..files import read_json
from ..model.effects import effect_name
from ..model.kinematics import Model
from ..model.poses import Poses
from ..units import LENGTH, shown, three, three_header, to_inside

FORMAT = "compgen.fit/1"
# The finest step any output of a fit prints (fit.json's repr aside): 1 nm and 1e-9 rad
# (0.0002″), a thousandth of the finest a control's table holds (0.1 µm, 0.0001°)
MARKER_QUANTUM = {"mm": 1e-6, "rad": 1e-9}
SHORT_MARKER = len("fit:000000")      # the marker edit files carry: 6 of the record marker's digits

if TYPE_CHECKING:
    from ..model.machine import Machine


def _here(file: str) -> str:
    """A data file as the user names it from here: relative below the working folder."""
    near = os.path.relpath(file) if file else file
    return near if near and not near.startswith("..") else file


@dataclass(frozen=True)
class Estimate:
    """A parameter's value and standard uncertainty, in ``unit`` (mm or rad)."""

    value: float
    std: float
    unit: str
    fixed: bool = False


@dataclass(frozen=True)
class DataRef:
    """A data file a fit was made from: its name, checksum, rows, rows per path and device."""

    file: str
    sha256: str
    rows: int
    paths: dict[str, int] = field(default_factory=dict)
    device: str = "rtest"        # "probe": sphere centres from a touch-probe log
    said: str = ""               # what the user said of the set-up before it (rtest.MOUNTED_AGAIN, UNTOUCHED)
    turned: float = 0.0          # deg the ball was turned on its stem before it (fit --ball-turned)


@dataclass(frozen=True, eq=False)   # eq=False: ndarray fields make the default __eq__ raise
class FitResult:
    """What ``identify`` returns and fit.json holds.

    ``correlation`` is over ``free`` (the fitted parameters, model order);
    ``singular_values`` are those of the column-normalised Jacobian, largest first.
    """

    machine: dict
    data: tuple[DataRef, ...]
    model: tuple[str, ...]
    parameters: dict[str, Estimate]
    free: tuple[str, ...]
    correlation: np.ndarray
    singular_values: np.ndarray
    residual: dict
    method: str
    iterations: int
    sign: str
    version: str
    descriptions: dict[str, str] = field(default_factory=dict)
    # effects these data cannot tell from others of the catalogue: {"effect", "equivalents",
    # "half_range": {parameter: mm or rad}}, already in the parameters' std (``choice.py``)
    choices: tuple[dict, ...] = ()
    # the R-test's calibration in the σ: {"gain_u": relative, "std": {parameter: mm or rad}}
    # (``budget.py``), already in the parameters' std
    device_budget: dict = field(default_factory=dict)

    def __post_init__(self):
        for a in (self.correlation, self.singular_values):
            a.setflags(write=False)

    @property
    def record_marker(self) -> str:
        """``fit:`` and 16 hex digits naming this fit's numbers and data: what the history
        keeps it by, long enough never to collide in a store (a million fits: 3e-8; six
        digits collided once in 4 000).

        The values enter as written (``MARKER_QUANTUM``), never by their last bits: those
        differ with the BLAS kernel numpy picks for the CPU, and the marker must not."""
        import hashlib
        key = json.dumps([self.model, {n: [round(e.value / MARKER_QUANTUM[e.unit]), e.unit]
                                       for n, e in self.parameters.items()},
                          [d.sha256 for d in self.data]], sort_keys=True)
        return "fit:" + hashlib.sha256(key.encode()).hexdigest()[:16]

    @property
    def marker(self) -> str:
        """The record marker's first 6 hex digits: what every edit file carries (a control's
        comment has little room), so that applying the same fit twice can be refused."""
        return self.record_marker[:SHORT_MARKER]

    def holds_marker(self, marker: object) -> bool:
        """Whether a row's marker is this fit's: its record marker, or (a row an older
        compgen wrote) its 6-digit marker."""
        return marker in (self.record_marker, self.marker)

    @property
    def values(self) -> np.ndarray:
        """The fitted values in model order, inside units (mm, rad)."""
        return np.array([self.parameters[n].value for n in self.model])

    def evaluate(self, machine: Machine, poses: Poses) -> np.ndarray:
        """The readings (n, 3) mm, nest minus ball, the fitted model gives at ``poses`` (any
        ball, any axes): what it predicts of a measurement, a path's start side aside."""
        return Model(machine, self.model).deviation(poses, self.values)

    def widened(self, extra: dict[str, float], **why) -> FitResult:
        """This fit with ``extra`` (parameter → mm or rad: a further standard uncertainty)
        added in quadrature to each fitted parameter's σ, and ``why`` (the fields that say
        where it comes from)."""
        params = {n: replace(e, std=math.hypot(e.std, extra[n])) if extra.get(n) and not e.fixed else e
                  for n, e in self.parameters.items()}
        return replace(self, parameters=params, **why)

    @property
    def condition_number(self) -> float:
        s = self.singular_values
        return float(s[0] / s[-1]) if len(s) and s[-1] > 0 else math.inf

    def to_dict(self, folder: str | Path | None = None) -> dict:
        """fit.json's content; with ``folder`` (where it is written), file names relative to
        it, so the job folder can move."""
        def rel(file: str) -> str:
            return os.path.relpath(file, folder) if folder is not None and file else file

        def where(file: str) -> dict:
            # relative, so that the job folder can move; absolute too, so that the fit file can
            # move alone (each is taken only with its checksum unchanged)
            return {"file": rel(file), "absolute": os.path.abspath(file)} if file else {"file": file}

        return {
            "format": FORMAT,
            "compgen_version": self.version,
            "machine": {**self.machine, **({"file": self.machine["file"]} if self.machine.get("bundled")
                                           else where(self.machine["file"]))},
            "data": [{**d.__dict__, **where(d.file)} for d in self.data],
            "sign": self.sign,
            "model": list(self.model),
            "effects": list(dict.fromkeys(effect_name(p) for p in self.model)),
            "method": self.method,
            "iterations": self.iterations,
            "parameters": {
                n: {"value": e.value, "unit": e.unit, "std": e.std,
                    **({"fixed": True} if e.fixed else {}),
                    **({"description": self.descriptions[n]} if n in self.descriptions else {})}
                for n, e in self.parameters.items()},
            "correlation": {"names": list(self.free), "matrix": self.correlation.tolist()},
            "identifiability": {"singular_values": self.singular_values.tolist(),
                                "condition_number": self.condition_number,
                                "normalisation": "columns scaled to unit norm"},
            "residual": self.residual,
            **({"choices": list(self.choices)} if self.choices else {}),
            **({"device_budget": self.device_budget} if self.device_budget else {}),
        }

    def to_json(self, folder: str | Path | None = None) -> str:
        return json.dumps(self.to_dict(folder), indent=2, allow_nan=False, ensure_ascii=False) + "\n"

    @classmethod
    def from_dict(cls, d: dict, where: str = "fit.json") -> FitResult:
        if d.get("format") != FORMAT:
            raise CompgenError(f"not a compgen fit file (format {d.get('format')!r})", where=where,
                               hint=f"make one with `{me()} fit`")
        base = Path(where).parent

        def file(name: str, absolute=None) -> str:
            # relative to the fit file (older fits hold absolute paths); where the fit file moved
            # alone, the absolute path it was written with
            if not name:
                return name
            if not (base / name).exists() and isinstance(absolute, str) and Path(absolute).exists():
                return absolute
            return str(base / name)

        model = d.get("model")
        if not isinstance(model, list) or not model or not all(isinstance(n, str) for n in model):
            raise CompgenError("model must be a non-empty list of parameter names", where=f"{where}: model",
                               hint="give the fit.json compgen fit wrote")
        try:
            params = {n: _estimate(p, f"{where}: parameters.{n}") for n, p in d["parameters"].items()}
            free = d["correlation"]["names"]
            odd = ([n for n in model if n not in params] or [n for n in params if n not in model]
                   or [n for n in free if n not in model])
            if odd or len(set(model)) != len(model):
                raise CompgenError("model, parameters and correlation names do not agree "
                                   f"({(odd or model)[0]})", where=where,
                                   hint="give the fit.json compgen fit wrote")
            return cls(
                machine={**{k: v for k, v in d["machine"].items() if k != "absolute"},
                         "file": d["machine"]["file"] if d["machine"].get("bundled") is True
                         else file(d["machine"]["file"], d["machine"].get("absolute"))},
                data=tuple(DataRef(**{**{k: v for k, v in x.items() if k != "absolute"},
                                      "file": file(x["file"], x.get("absolute"))}) for x in d["data"]),
                model=tuple(d["model"]), parameters=params,
                free=tuple(d["correlation"]["names"]),
                correlation=np.array(d["correlation"]["matrix"], float).reshape(
                    len(d["correlation"]["names"]), -1),
                singular_values=np.array(d["identifiability"]["singular_values"], float),
                residual=_residual(d["residual"], where), method=d["method"], iterations=int(d["iterations"]),
                sign=d["sign"], version=d["compgen_version"],
                descriptions={n: p["description"] for n, p in d["parameters"].items()
                              if "description" in p},
                choices=tuple(_choice(c, f"{where}: choices") for c in d.get("choices", ())),
                device_budget=_device_budget(d.get("device_budget", {}), f"{where}: device_budget"))
        except (KeyError, TypeError, ValueError) as exc:
            raise CompgenError(f"fit file is incomplete or damaged ({exc!r})", where=where) from None

    def report(self) -> str:
        """A table like the seed's Table 4, in µm and arcsec, with uncertainties."""
        r = self.residual
        lines = [f"compgen fit: {self.machine['name']}"]
        for d in self.data:
            counts = ", ".join(f"{k} {v}" for k, v in d.paths.items())
            device = " by touch probe" if d.device == "probe" else ""
            lines.append(f"  data  {_here(d.file)}: {d.rows} poses{device} ({counts})")
        lines.append(f"  model {len(self.model)} parameters ({len(self.free)} fitted), method "
                     f"{self.method}, {self.iterations} iteration(s)")
        lines += ["", f"  {'parameter':<12}{'value':>9}    {'std. unc.':<13}meaning"]
        for n, e in self.parameters.items():
            v, unit = shown(e.value, e.unit)
            s, _ = shown(e.std, e.unit)
            unc = "fixed" if e.fixed else f"± {s:.3f} {unit}"
            lines.append(f"  {n:<12}{v:>9.3f} {unit:<3}{unc:<13}{self.descriptions.get(n, '')}")
        lines += ["", f"  residual RMS {r['rms_um']:.3f} µm over {r['readings']} readings; "
                      f"σ̂ = {r['sigma_um']:.3f} µm with {r['dof']} degrees of freedom",
                  f"  {'path':<8}{'poses':>6} {three_header(('RMS dX', 'dY', 'dZ'))}  "
                  f"{three_header(('range dX', 'dY', 'dZ'))}   (µm)"]
        for name, p in r["per_path"].items():
            lines.append(f"  {name:<8}{p['n']:>6} {three(p['rms_um'])}  {three(p['range_um'])}")
        if r.get("noise") == "ar1":
            rho, where = max((max(p["ar1_rho"]), name) for name, p in r["per_path"].items() if "ar1_rho" in p)
            lines += [f"  the residual follows from reading to reading (AR(1) ρ̂ up to {rho:.2f}, in "
                      f"{where}): a drift of the set-up,", "  or an effect the model lacks (diagnose "
                      "tells); the uncertainties are least squares' under that noise"]
        for c in self.choices:
            moved = sorted(c["half_range"].items(), key=lambda kv: -abs(kv[1]) / self.parameters[kv[0]].std)
            lines += ["", f"  {c['effect']} cannot be told from {', '.join(c['equivalents'])} on these data:",
                      "  the σ above holds what the choice moves (half the range over them):",
                      "    " + ", ".join(f"{n} {shown(v, self.parameters[n].unit)[0]:.2f} "
                                         f"{shown(v, self.parameters[n].unit)[1]}" for n, v in moved[:6])]
        if self.device_budget:
            big = sorted(self.device_budget["std"].items(),
                         key=lambda kv: -kv[1] / self.parameters[kv[0]].std)
            lines += ["", f"  the σ above holds the R-test's sensor gains as its calibration allows "
                          f"(± {100 * self.device_budget['gain_u']:g} %, [rtest] gain_u); their share:",
                      "    " + ", ".join(f"{n} {shown(v, self.parameters[n].unit)[0]:.3f} "
                                         f"{shown(v, self.parameters[n].unit)[1]}" for n, v in big[:6])]
        lines += ["", f"  condition number {self.condition_number:.1f} (columns scaled to unit "
                      f"norm; above 100 the estimates are fragile)"]
        pairs = [(abs(self.correlation[i, j]), self.free[i], self.free[j], self.correlation[i, j])
                 for i in range(len(self.free)) for j in range(i)]
        strong = sorted(p for p in pairs if p[0] >= 0.9)[::-1][:5]
        if strong:
            lines.append("  strongly correlated: " + ", ".join(f"{a}–{b} {c:+.2f}" for _, a, b, c in strong))
        return "\n".join(lines) + "\n"


def _number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _residual(r, where: str) -> dict:
    """fit.json's residual statistics, whole: every later command reads them."""
    per_path = r.get("per_path") if isinstance(r, dict) else None
    if not (isinstance(per_path, dict)
            and all(_number(r.get(k)) for k in ("rms_um", "sigma_um", "readings", "dof"))
            and all(isinstance(p, dict) and _number(p.get("n")) and all(
                isinstance(p.get(k), list) and len(p[k]) == 3 and all(map(_number, p[k]))
                for k in ("rms_um", "range_um", "max_abs_um")) for p in per_path.values())):
        raise CompgenError("fit file's residual statistics are incomplete or damaged",
                           where=f"{where}: residual", hint=f"refit with `{me()} fit`")
    return r


def _estimate(p: dict, where: str) -> Estimate:
    """A parameter of fit.json in inside units, whatever unit it was written in."""
    if not isinstance(p, dict) or not isinstance(p.get("unit"), str) or not all(
            isinstance(p.get(k), int | float) and not isinstance(p.get(k), bool) for k in ("value", "std")):
        raise CompgenError('must be {"value": number, "unit": text, "std": number}', where=where)
    inside = "mm" if p["unit"] in LENGTH else "rad"
    std = to_inside(p["std"], p["unit"], inside, where)
    if std < 0:
        raise CompgenError(f"negative uncertainty {p['std']}", where=where)
    return Estimate(to_inside(p["value"], p["unit"], inside, where), std, inside, p.get("fixed") is True)


def load_fit(path: str | Path) -> FitResult:
    return FitResult.from_dict(read_json(path, "fit file"), str(path))


def _choice(c, where: str) -> dict:
    """A choice as fit.json holds it, checked."""
    if not (isinstance(c, dict) and isinstance(c.get("effect"), str)
            and isinstance(c.get("equivalents"), list) and c["equivalents"]
            and all(isinstance(e, str) for e in c["equivalents"]) and isinstance(c.get("half_range"), dict)
            and all(isinstance(v, (int, float)) and math.isfinite(v) for v in c["half_range"].values())):
        raise CompgenError("a choice must hold effect, equivalents and half_range", where=where,
                           hint="give the fit.json compgen fit wrote")
    return {"effect": c["effect"], "equivalents": list(c["equivalents"]),
            "half_range": {str(k): float(v) for k, v in c["half_range"].items()}}


def _device_budget(b, where: str) -> dict:
    """A device budget as fit.json holds it, checked."""
    if b == {}:
        return {}
    if not (isinstance(b, dict) and isinstance(b.get("gain_u"), (int, float)) and 0 <= b["gain_u"] < 1
            and isinstance(b.get("std"), dict)
            and all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 for v in b["std"].values())):
        raise CompgenError("a device budget must hold gain_u and std", where=where,
                           hint="give the fit.json compgen fit wrote")
    return {"gain_u": float(b["gain_u"]), "std": {str(k): float(v) for k, v in b["std"].items()}}
