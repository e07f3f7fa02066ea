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
    "axis_index",
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


def axis_index(axis: tuple[float, float, float]) -> int:
    """0, 1, 2 for the coordinate axis ``(1, 0, 0)``, ``(0, 1, 0)``, ``(0, 0, 1)``."""
    units = {(1.0, 0.0, 0.0): 0, (0.0, 1.0, 0.0): 1, (0.0, 0.0, 1.0): 2}
    if tuple(axis) not in units:
        raise ValueError(f"unsupported joint axis {axis}")
    return units[tuple(axis)]


def rot_axis(axis: tuple[float, float, float], angle: np.ndarray | float) -> np.ndarray:
    """Rotation about a coordinate axis ``(1, 0, 0)``, ``(0, 1, 0)`` or ``(0, 0, 1)``."""
    return (rot_x, rot_y, rot_z)[axis_index(axis)](angle)


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
    """Unit quaternions (..., 4) ``w, x, y, z`` with ``w >= 0`` from rotations (..., 3, 3).

    Shepperd's method: the largest of ``|w|, |x|, |y|, |z|`` from the diagonal (a square
    root of a number of at least 1), the three others from sums and differences of
    off-diagonal entries divided by it. Accurate to a few units in the last place for
    every rotation (a square root per component, as before, turned a rounding error of
    1e-16 in a near-zero component into about 1e-8)."""
    R = np.asarray(R, dtype=float)
    m00, m01, m02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    m10, m11, m12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    m20, m21, m22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    d = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22,
                  1 - m00 - m11 + m22], -1)
    k = np.argmax(d, axis=-1)
    big = 0.5 * np.sqrt(np.maximum(np.take_along_axis(d, k[..., None], -1)[..., 0], 1e-300))
    f = 0.25 / big
    # column i: 4 q_k q_i for the largest component k (rows: k = w, x, y, z)
    wx, wy, wz = m21 - m12, m02 - m20, m10 - m01
    xy, xz, yz = m01 + m10, m02 + m20, m12 + m21
    q = np.stack([
        np.choose(k, [big / f, wx, wy, wz]) * f,
        np.choose(k, [wx, big / f, xy, xz]) * f,
        np.choose(k, [wy, xy, big / f, yz]) * f,
        np.choose(k, [wz, xz, yz, big / f]) * f,
    ], -1)
    q = np.where(q[..., :1] < 0, -q, q)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)
