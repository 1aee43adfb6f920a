"""Rotary axes the PLC positions (``positioning = "m-function"``): the NC never writes their
word; each change of one is a step of its own in a program, the OEM's M-function with its
target where the control has a way to hand it over (``Controller.plc_index``), at the safe
height with TCP off (U26). What every program writer (measuring, probing) shares of them."""

from __future__ import annotations

import numpy as np

from ..errors import CompgenError
from ..model.machine import Machine
from .base import Controller

# the Q parameters HEIDENHAIN's OEM macro for PLC-positioned rotary axes reads its targets from
# (iTNC 530 MP6602, TNC 640 mStrobeRotAxPos: Q120-Q122 for A, B, C; KinematicsOpt's convention)
PLC_TARGET = {"A": 120, "B": 121, "C": 122}
SAME_DEG = 0.5e-4          # half the 0.0001° a program writes: the same position


def plc_runs(machine: Machine, path: np.ndarray, rotary_rad: np.ndarray) -> list[np.ndarray]:
    """The poses' indices in runs of one path label and one position of every axis the PLC
    positions (``rotary_rad``: (n, r) in ``machine.rotary_axes`` order): such an axis turns
    only with the nest up at the safe height, between runs."""
    plc = [k for k, a in enumerate(machine.rotary_axes) if a.m_function is not None]
    cut = (path[1:] != path[:-1]) | (rotary_rad[1:, plc] != rotary_rad[:-1, plc]).any(axis=1)
    return np.split(np.arange(len(path)), np.flatnonzero(cut) + 1)


def index_steps(machine: Machine, steps: list[dict], q: np.ndarray | None,
                axes: dict[str, float]) -> list[str]:
    """Each axis the PLC positions that ``axes`` (letter → deg) turns from ``q`` (NaN or
    None: not known) gets a step of its own before the move, the OEM's M-function with its
    target (U26): the NC never writes its word. Returns the letters taken out of the move."""
    out = []
    for a in machine.plc_axes:
        if a.name not in axes:
            continue
        now = None if q is None else np.degrees(q[machine.index(a.name)])
        if now is None or np.isnan(now) or abs(now - axes[a.name]) > SAME_DEG:
            steps.append({"kind": "index", "axis": a.name, "value": float(axes[a.name]), "m": a.m_function,
                          "param": PLC_TARGET[a.name], "note": f"the PLC turns {a.name}"})
        out.append(a.name)
    return out


def plc_lines(machine: Machine, ctl: Controller, tool: str) -> list[str]:
    """A program's header lines for the axes the PLC positions (``tool``: nest, stylus)."""
    return [f"{a.name} is positioned by the PLC: the OEM's M-function M{a.m_function} with its target "
            f"{ctl.plc_words(a)}, the {tool} up at the safe height; never a word of an NC move (U26)"
            for a in machine.plc_axes]


def check_plc(machine: Machine, ctl: Controller) -> None:
    """An axis the PLC positions is not interpolated: it turns only with TCP off (the control
    cannot hold the nest while it turns). A head's programs run under TCP throughout, and a
    control that has no way to have the PLC turn it (``Controller.plc_index``): refused."""
    if not machine.plc_axes:
        return
    names = " and ".join(a.name for a in machine.plc_axes)
    if machine.heads:
        raise CompgenError(f"{names} is positioned by the PLC (an M-function): a head's program runs under "
                           "TCP throughout, which does not hold the nest while the PLC turns an axis",
                           hint="position it by hand and measure each position as its own session")
    if not ctl.plc_index:
        raise CompgenError(f"{names} is positioned by the PLC (an M-function): on {ctl.words} the kinematics "
                           "move every axis of the machine themselves, and no position of an axis turned "
                           "outside them can be checked",
                           hint="configure the axis as one of the control's joints, or write the program "
                                "by hand")
