"""A diagnosis kept beside its fit (``fit.json`` → ``fit.diagnosis.json``): ``diagnose``
makes it once and keeps it; the report reads it while it is the diagnosis of the same fit
(its record marker: model, values, data), the same machine file, the same options and the
same compgen, and whose content is as it was kept (the marker of the whole diagnosis). Any
other is stale and is made again, never read: a kept diagnosis is a shortcut, not a source.

The file holds every field of the ``Diagnosis`` (the JSON of ``diagnose --json`` leaves out
what only its words need) and each advised measurement with its poses, so what is read back
is the diagnosis as made, to the last digit."""

from __future__ import annotations

import functools
import hashlib
import json
import types
import typing
from collections.abc import Callable, Sequence
from dataclasses import fields, is_dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import CompgenError
from ..files import write_atomically
from ..model.machine import Machine
from ..model.poses import FIELDS, Poses
from .advising import Proposal
from .diagnosis import Diagnosis
from .results import FitResult

FORMAT = "compgen.kept-diagnosis/1"


class _Stale(Exception):
    """What was kept cannot be read as a diagnosis of this compgen."""


def kept_path(fit_file: str | Path) -> Path:
    """Where the diagnosis of ``fit_file`` is kept: beside it, ``NAME.diagnosis.json``."""
    path = Path(fit_file)
    return path.with_name(f"{path.stem}.diagnosis.json")


def key(fit: FitResult, machine: Machine, noise_um: float | None, candidates: Sequence[str] | None,
        advised: bool) -> dict:
    """What a kept diagnosis must have been made of to be this one's."""
    return json.loads(json.dumps({
        "fit": fit.record_marker, "machine_sha256": machine.sha256, "noise_um": noise_um,
        "candidates": None if candidates is None else list(candidates), "advised": advised,
        "compgen": __version__}))


def dumps(found: Diagnosis, made_of: dict) -> str:
    """The kept file's text: the diagnosis with the marker of its whole content (a file
    damaged or changed by hand is made again, never read as it stands)."""
    body = json.loads(json.dumps(_encode(found, Diagnosis), default=_plain))
    return json.dumps({"format": FORMAT, "key": made_of, "sha256": _marker(body), "diagnosis": body}) + "\n"


def _marker(body) -> str:
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def loads(text: str, made_of: dict, proposal: Callable[..., Proposal]) -> Diagnosis | None:
    """The diagnosis kept in ``text`` if it was made of ``made_of``, else None (stale, or not
    a kept diagnosis). ``proposal``: the advised measurements' type, built from its fields and
    its ``poses`` (the caller's: the statistics name no controller's type)."""
    try:
        doc = json.loads(text)
        if not (isinstance(doc, dict) and doc.get("format") == FORMAT and doc.get("key") == made_of
                and doc.get("sha256") == _marker(doc.get("diagnosis"))):
            return None
        return _decode(doc["diagnosis"], Diagnosis, proposal)
    except (ValueError, KeyError, TypeError, RecursionError, _Stale):
        return None


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not kept")


@functools.cache
def _hints(cls) -> dict:
    """A result type's fields' types, read once per type (a diagnosis holds hundreds of
    candidates of one type)."""
    return typing.get_type_hints(cls)


def _inner(hint):
    """``X`` of ``X | None``, else ``hint``."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return next(a for a in typing.get_args(hint) if a is not type(None))
    return hint


def _encode(value, hint):
    hint = _inner(hint)
    if value is None:
        return None
    if hint is Proposal:
        return {"fields": {f.name: getattr(value, f.name) for f in fields(value) if f.name != "poses"},
                "poses": {f: getattr(value.poses, f) for f in FIELDS}}
    if is_dataclass(hint):
        hints = _hints(hint)
        return {f.name: _encode(getattr(value, f.name), hints[f.name]) for f in fields(hint)}
    if typing.get_origin(hint) is tuple:
        return [_encode(v, typing.get_args(hint)[0]) for v in value]
    return value


def _decode(value, hint, proposal):
    hint = _inner(hint)
    if value is None:
        return None
    if hint is Proposal:
        kept = {k: tuple(v) if isinstance(v, list) else v for k, v in value["fields"].items()}
        arrays = {f: np.array(v, dtype=str if f == "path" else float) for f, v in value["poses"].items()}
        return proposal(**kept, poses=Poses(**arrays))
    if is_dataclass(hint):
        hints = _hints(hint)
        if set(value) != {f.name for f in fields(hint)}:
            raise _Stale(hint.__name__)
        return hint(**{f.name: _decode(value[f.name], hints[f.name], proposal) for f in fields(hint)})
    if typing.get_origin(hint) is tuple:
        return tuple(_decode(v, typing.get_args(hint)[0], proposal) for v in value)
    return value


def read_kept(fit_file: str | Path, made_of: dict, proposal: Callable[..., Proposal]) -> Diagnosis | None:
    """The diagnosis kept beside ``fit_file`` if it was made of ``made_of``, else None."""
    try:
        text = kept_path(fit_file).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    return loads(text, made_of, proposal)


def keep(fit_file: str | Path, found: Diagnosis, made_of: dict) -> str:
    """Keep ``found`` beside ``fit_file``; what was done, in a line. A file there that is not
    a kept diagnosis is never replaced."""
    path = kept_path(fit_file)
    try:
        with open(path, "rb") as f:
            ours = f.read(len(FORMAT) + 16).startswith(f'{{"format": "{FORMAT}"'.encode())
    except FileNotFoundError:
        ours = True
    except OSError as e:
        return f"the diagnosis is not kept: {path}: {e.strerror}"
    if not ours:
        return f"the diagnosis is not kept: {path} exists and is not a kept diagnosis"
    try:
        write_atomically(path, dumps(found, made_of), force=True)
    except (OSError, CompgenError) as e:
        return f"the diagnosis is not kept: {path}: {getattr(e, 'strerror', None) or e}"
    return f"kept the diagnosis in {path} (the report reads it while the fit is unchanged)"
