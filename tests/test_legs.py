"""Leg split, CoP and contact-point forces (qp default and the paper's eq. 6-12)."""

from __future__ import annotations

import numpy as np
import pytest

from grfguard.model.robot import SURALP
from reference.vfs_legs import (
    corner_contact,
    paper_alpha,
    paper_cop_literal,
    paper_leg_forces,
    split_paper_feet,
    split_qp,
    world_to_foot_xy,
)

PTS_F = SURALP.sensor_positions_in_foot()  # (4, 2)


def _two_feet(y_r: float = -0.1, y_l: float = 0.1, x_l: float = 0.0) -> np.ndarray:
    return np.concatenate([PTS_F + [0.0, y_r], PTS_F + [x_l, y_l]])


def test_corner_contact_heights_and_plan() -> None:
    h = np.zeros(8)
    h[4:6] = 0.02  # left toes lifted (heel-first landing)
    c = corner_contact(h, np.array([True, True]), 0.003)
    assert c.tolist() == [True] * 4 + [False, False, True, True]
    # kinematics wins over the plan: a foot on the ground touches even if planned in swing
    # (early touchdown, late lift-off); without kinematics the plan decides
    c = corner_contact(np.zeros(8), np.array([True, False]), 0.003)
    assert c.all()
    c = corner_contact(np.zeros(8), np.array([True, False]), 0.003, kinematic=False)
    assert c.tolist() == [True] * 4 + [False] * 4
    # a planned foot with every corner high keeps its lowest corner
    h = np.full(8, 0.01)
    h[2] = 0.005
    c = corner_contact(h, np.array([True, False]), 0.003)
    assert c.tolist() == [False, False, True, False] + [False] * 4
    assert corner_contact(h, np.array([True, False]), 0.003, kinematic=False)[:4].all()


def test_single_support_reproduces_zmp_inside_and_clips_outside() -> None:
    pts = _two_feet()[None]
    contact = np.array([[True] * 4 + [False] * 4])
    fz = np.array([1000.0])
    zmp = np.array([[0.03, -0.12]])
    f = split_qp(pts, contact, zmp, fz, 1e-6)[0]
    assert f[4:] == pytest.approx(0.0, abs=1e-9)
    assert f.sum() == pytest.approx(1000.0)
    cop = (f[:4, None] * pts[0, :4]).sum(axis=0) / f.sum()
    np.testing.assert_allclose(cop, zmp[0], atol=2e-4)
    # ZMP outside the sole (between the feet): clipped to the inner edge (y = -0.035)
    f = split_qp(pts, contact, np.array([[0.0, 0.0]]), fz, 1e-6)[0]
    assert f[[0, 2]] == pytest.approx([500.0, 500.0], abs=0.5)
    assert f[[1, 3]] == pytest.approx([0.0, 0.0], abs=0.5)


def test_double_support_equal_springs() -> None:
    """With all 8 corners loaded, the min-norm solution is the rigid body on equal springs:
    forces affine in position, total force and moment reproduced."""
    pts = _two_feet(x_l=0.06)
    zmp = np.array([0.02, 0.03])
    f = split_qp(pts[None], np.ones((1, 8), bool), zmp[None], np.array([1118.0]), 1e-9)[0]
    A = np.vstack([np.ones(8), pts.T])
    b = np.array([1118.0, 1118.0 * zmp[0], 1118.0 * zmp[1]])
    expected = A.T @ np.linalg.solve(A @ A.T, b)
    assert np.all(expected > 0)
    np.testing.assert_allclose(f, expected, atol=1e-3)


def test_paper_alpha_and_leg_forces() -> None:
    assert paper_alpha(np.array([0.05, 0.5, -0.5]), 0.1).tolist() == [0.5, 1.0, -1.0]
    F = np.array([[10.0, 0.0, 1000.0]] * 3)
    alpha = np.array([0.5, 0.5, 0.5])
    st = np.array([[True, True], [True, False], [False, True]])
    legs = paper_leg_forces(F, alpha, st)
    assert legs[0, :, 2].tolist() == [250.0, 750.0]  # F_R = (1-a)/2, F_L = (1+a)/2
    assert legs[1, :, 2].tolist() == [1000.0, 0.0]
    assert legs[2, :, 2].tolist() == [0.0, 1000.0]
    np.testing.assert_allclose(legs.sum(axis=1), F)


def test_paper_cop_literal_drops_com_offset() -> None:
    """Eq. 10-12 literally: CoP = h F_xy / F_z, whatever the CoM-to-foot offset."""
    F = np.array([50.0, -20.0, 1000.0])
    for offset in ([0.0, 0.0], [0.05, -0.1], [-0.2, 0.3]):
        f = np.array([offset[0], offset[1], -0.7])  # foot origin from the CoM
        cop = paper_cop_literal(f, F)
        np.testing.assert_allclose(cop, 0.7 * F[:2] / F[2])
    assert paper_cop_literal(f, np.zeros(3)) == pytest.approx([0.0, 0.0])


def test_world_to_foot_rotation() -> None:
    th = np.pi / 2
    R = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    np.testing.assert_allclose(world_to_foot_xy(np.array([0.0, 1.0]), R), [1.0, 0.0], atol=1e-12)


def test_paper_weight_pulls_cop_to_centre() -> None:
    cop = np.array([[[0.08, 0.04], [0.0, 0.0]]])
    fz = np.array([[1000.0, 0.0]])
    small = split_paper_feet(cop, fz, PTS_F, 1e-6)[0, :4]
    paper = split_paper_feet(cop, fz, PTS_F, 0.01)[0, :4]
    c_small = (small[:, None] * PTS_F).sum(axis=0) / small.sum()
    c_paper = (paper[:, None] * PTS_F).sum(axis=0) / paper.sum()
    np.testing.assert_allclose(c_small, cop[0, 0], atol=1e-3)
    assert np.linalg.norm(c_paper) < np.linalg.norm(c_small) - 0.005
    assert split_paper_feet(cop, fz, PTS_F, 0.01)[0, 4:] == pytest.approx(0.0)
