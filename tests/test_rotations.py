"""grfguard.rotations.rotation_to_quat: accurate to the last bits for every rotation."""

from __future__ import annotations

import numpy as np

from grfguard.rotations import quat_to_matrix, rotation_to_quat


def test_round_trip_random_and_near_identity() -> None:
    """Random quaternions and ones with tiny components (near the identity, near a pure
    yaw: where a square root per component turned 1e-16 of rounding into 1e-8) come back
    to a few units in the last place."""
    rng = np.random.default_rng(2)
    q = rng.normal(size=(20000, 4))
    small = rng.normal(size=(2000, 4)) * np.array([1.0, 1e-9, 1e-12, 1e-7])
    yaw = rng.normal(size=(2000, 4)) * np.array([1.0, 1e-10, 1e-11, 1.0])
    q = np.concatenate([q, small, yaw])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    back = rotation_to_quat(quat_to_matrix(q))
    assert np.abs(back - q).max() < 2e-15
    assert (back[:, 0] >= 0).all()


def test_half_turns_and_shapes() -> None:
    """Rotations by pi (w = 0) give a valid quaternion of the same rotation; any leading
    shape is kept."""
    for axis in np.eye(3):
        R = 2 * np.outer(axis, axis) - np.eye(3)
        q = rotation_to_quat(R)
        np.testing.assert_allclose(quat_to_matrix(q), R, atol=1e-15)
        assert abs(np.linalg.norm(q) - 1.0) < 1e-15
    np.testing.assert_array_equal(rotation_to_quat(np.eye(3)), [1.0, 0.0, 0.0, 0.0])
    assert rotation_to_quat(np.broadcast_to(np.eye(3), (2, 5, 3, 3))).shape == (2, 5, 4)
