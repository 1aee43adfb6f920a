"""Pure array functions on stacks of homogeneous transforms, shape (..., 4, 4).

Angles in rad, lengths in mm. Nothing here knows about machines or errors.
"""

from __future__ import annotations

import numpy as np

UNIT = {"x": np.array([1.0, 0.0, 0.0]), "y": np.array([0.0, 1.0, 0.0]),
        "z": np.array([0.0, 0.0, 1.0])}


def trans(v: np.ndarray) -> np.ndarray:
    """Translation by ``v`` (..., 3) mm → (..., 4, 4)."""
    v = np.asarray(v, dtype=float)
    T = np.zeros(v.shape[:-1] + (4, 4))
    T[..., 0, 0] = T[..., 1, 1] = T[..., 2, 2] = T[..., 3, 3] = 1.0
    T[..., :3, 3] = v
    return T


def rot_exact(w: np.ndarray) -> np.ndarray:
    """Rotation by the rotation vector ``w`` (..., 3) rad, built exactly (Rodrigues), as
    a transform (..., 4, 4).

    Small location errors are rotation vectors, not first-order matrices: the contract's
    reference simulator builds them this way, and it stays valid at 30× realistic errors.
    """
    w = np.asarray(w, dtype=float)
    T = np.zeros(w.shape[:-1] + (4, 4))
    T[..., :3, :3] = rodrigues(w)
    T[..., 3, 3] = 1.0
    return T


def rodrigues(w: np.ndarray) -> np.ndarray:
    """The rotation matrix (..., 3, 3) of the rotation vector ``w`` (..., 3) rad."""
    w = np.asarray(w, dtype=float)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    K = np.zeros(w.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -w[..., 2], w[..., 1]
    K[..., 1, 0], K[..., 1, 2] = w[..., 2], -w[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -w[..., 1], w[..., 0]
    # sin θ/θ and (1 − cos θ)/θ² = ½(sin(θ/2)/(θ/2))², without branches or cancellation
    a = np.sinc(theta / np.pi)
    b = 0.5 * np.sinc(theta / (2 * np.pi)) ** 2
    return np.eye(3) + a * K + b * (K @ K)


def rot_axis(direction: str, angle: np.ndarray) -> np.ndarray:
    """Right-handed rotation about the unit axis ``direction`` ('x', 'y' or 'z') by ``angle`` rad."""
    angle = np.asarray(angle, dtype=float)
    c, s = np.cos(angle), np.sin(angle)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[direction]
    T = np.zeros(angle.shape + (4, 4))
    T[..., 0, 0] = T[..., 1, 1] = T[..., 2, 2] = T[..., 3, 3] = 1.0
    T[..., i, i] = T[..., j, j] = c
    T[..., j, i], T[..., i, j] = s, -s
    return T


def apply(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Transform points ``p`` (..., 3) by ``T`` (..., 4, 4)."""
    return np.einsum("...ij,...j->...i", T[..., :3, :3], p) + T[..., :3, 3]
