"""Rotations and unit quaternions ``(w, x, y, z)``: the one implementation every module uses.

Vectorized functions take (..., 4) quaternions or (...) angles [rad] and return
(..., 3, 3) matrices (``R_AB`` maps B coordinates to A).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "rot_x",
    "rot_y",
    "rot_z",
    "rot_axis",
    "quat_to_matrix",
    "rotation_to_quat",
]

def _rot(angle: np.ndarray | float, i: int, j: int) -> np.ndarray:
    """Rotation by ``angle`` [rad] in the plane of axes ``i -> j`` (about the third axis)."""
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    r = np.zeros(a.shape + (3, 3))
    k = 3 - i - j
    r[..., k, k] = 1.0
    r[..., i, i] = c
    r[..., j, j] = c
    r[..., i, j] = -s
    r[..., j, i] = s
    return r


def rot_x(angle: np.ndarray | float) -> np.ndarray:
    """Rotation matrices about x, shape ``angle.shape + (3, 3)``; angle in [rad]."""
    return _rot(angle, 1, 2)


def rot_y(angle: np.ndarray | float) -> np.ndarray:
    """Rotation matrices about y, shape ``angle.shape + (3, 3)``; angle in [rad]."""
    return _rot(angle, 2, 0)


def rot_z(angle: np.ndarray | float) -> np.ndarray:
    """Rotation matrices about z, shape ``angle.shape + (3, 3)``; angle in [rad]."""
    return _rot(angle, 0, 1)


def rot_axis(axis: tuple[float, float, float], angle: np.ndarray | float) -> np.ndarray:
    """Rotation about a coordinate axis ``(1, 0, 0)``, ``(0, 1, 0)`` or ``(0, 0, 1)``."""
    fns = {(1.0, 0.0, 0.0): rot_x, (0.0, 1.0, 0.0): rot_y, (0.0, 0.0, 1.0): rot_z}
    if tuple(axis) not in fns:
        raise ValueError(f"unsupported joint axis {axis}")
    return fns[tuple(axis)](angle)


def quat_to_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from quaternions (..., 4) ``w, x, y, z`` (normalized here)."""
    q = np.asarray(quat_wxyz, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def rotation_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) ``w, x, y, z`` with ``w >= 0`` from rotations (..., 3, 3)."""
    R = np.asarray(R, dtype=float)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    w = 0.5 * np.sqrt(np.maximum(0.0, 1 + m00 + m11 + m22))
    x = 0.5 * np.sqrt(np.maximum(0.0, 1 + m00 - m11 - m22))
    y = 0.5 * np.sqrt(np.maximum(0.0, 1 - m00 + m11 - m22))
    z = 0.5 * np.sqrt(np.maximum(0.0, 1 - m00 - m11 + m22))
    x = np.copysign(x, R[..., 2, 1] - R[..., 1, 2])
    y = np.copysign(y, R[..., 0, 2] - R[..., 2, 0])
    z = np.copysign(z, R[..., 1, 0] - R[..., 0, 1])
    q = np.stack([w, x, y, z], -1)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)
