"""CoM / momentum estimators: filters, ZMP formula, odometry, angular momentum, paper KF."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from grfguard.estimate.kinematic import KinematicModel
from grfguard.model.robot import SURALP
from grfguard.rotations import quat_to_matrix
from reference.vfs_com import (
    CausalLowPass,
    LegOdometry,
    PaperCoMFilter,
    zmp_from_momentum,
)
from reference.vfs_stages import AttitudeFilter, angular_momentum_about_com


@pytest.fixture(scope="module")
def kin() -> KinematicModel:
    return KinematicModel(SURALP)


def test_lowpass_streaming_equals_batch() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(500, 3)) + 5.0
    a = CausalLowPass(15.0, 1e-3, 2, 3)
    b = CausalLowPass(15.0, 1e-3, 2, 3)
    yb = a.run(x)
    ys = np.array([b.update(v) for v in x])
    np.testing.assert_allclose(ys, yb, atol=1e-12)
    # steady-state start: a constant input passes unchanged from the first sample
    c = CausalLowPass(15.0, 1e-3, 2, 1).run(np.full((50, 1), 3.0))
    np.testing.assert_allclose(c, 3.0, atol=1e-12)


def test_zmp_formula_signs() -> None:
    m, g, h = 100.0, 9.806, 0.7
    com = np.array([0.1, -0.2, h])
    # static: ZMP under the CoM
    np.testing.assert_allclose(
        zmp_from_momentum(com, np.array([0, 0, m * g]), np.zeros(3), 0.0), [0.1, -0.2]
    )
    # accelerating forward (+x) and left (+y): the ZMP lies behind and to the right
    acc = np.array([1.0, 0.5, 0.0])
    p = zmp_from_momentum(com, m * (acc + [0, 0, g]), np.zeros(3), 0.0)
    np.testing.assert_allclose(p, com[:2] - h * acc[:2] / g)
    # L_dot = (p - c) x F must hold for the returned p (ground at z = 0.05)
    F = np.array([30.0, -20.0, 1100.0])
    Ld = np.array([4.0, -7.0, 0.0])
    p = zmp_from_momentum(com, F, Ld, 0.05)
    r = np.array([p[0], p[1], 0.05]) - com
    np.testing.assert_allclose(np.cross(r, F)[:2], Ld[:2], atol=1e-9)


def test_attitude_filter_follows_gyro_and_quaternion() -> None:
    dt = 1e-3
    f = AttitudeFilter(dt, 0.5)
    w = np.array([0.0, 0.0, 0.5])
    q_true = np.array([1.0, 0, 0, 0])
    rng = np.random.default_rng(1)
    for k in range(2000):
        th = 0.5 * dt * (k + 1)
        q_true = np.array([np.cos(th / 2), 0, 0, np.sin(th / 2)])
        jitter = rng.normal(0, 1e-3, 3)
        q_meas = q_true + 0.5 * np.concatenate([[0.0], jitter])
        q = f.update(q_meas, w if k > 0 else None)
    R_err = quat_to_matrix(q) @ quat_to_matrix(q_true).T
    assert np.arccos(min(1.0, (np.trace(R_err) - 1) / 2)) < 2e-4  # far below the 1 mrad jitter


def test_angular_momentum_matches_mujoco(kin: KinematicModel) -> None:
    """Finite differences of body poses vs MuJoCo's subtree angular momentum."""
    m, d = kin.model, mujoco.MjData(kin.model)
    rng = np.random.default_rng(2)
    d.qpos[:] = m.qpos0
    d.qpos[7:] = rng.uniform(-0.3, 0.3, m.nq - 7)
    d.qvel[:] = rng.normal(0, 0.5, m.nv)
    dt = 1e-6
    mujoco.mj_forward(m, d)
    mujoco.mj_subtreeVel(m, d)
    L_ref = d.subtree_angmom[kin.trunk_id].copy()
    p0, R0 = d.xipos[1:].copy(), d.ximat[1:].reshape(-1, 3, 3).copy()
    q1 = d.qpos.copy()
    mujoco.mj_integratePos(m, q1, d.qvel, dt)
    d.qpos[:] = q1
    mujoco.mj_kinematics(m, d)
    p1, R1 = d.xipos[1:].copy(), d.ximat[1:].reshape(-1, 3, 3).copy()
    L = angular_momentum_about_com(p1, R1, p0, R0, kin.body_mass, kin.body_inertia, dt)
    np.testing.assert_allclose(L, L_ref, rtol=1e-4, atol=1e-4)


def test_leg_odometry_anchor_switch_is_continuous() -> None:
    odo = LegOdometry(0.003)
    p_AS = np.array([[0.0, -0.1, -0.7], [0.0, 0.1, -0.7]])
    corners = np.array([[0.1, 0.05], [0.1, -0.05], [-0.1, 0.05], [-0.1, -0.05]])

    def pak(p_AS: np.ndarray) -> np.ndarray:
        out = np.zeros((8, 3))
        for i in range(2):
            out[4 * i : 4 * i + 4, :2] = p_AS[i, :2] + corners
            out[4 * i : 4 * i + 4, 2] = p_AS[i, 2]
        return out

    R = np.stack([np.eye(3)] * 2)
    _, p0, g0, a0 = odo.update(pak(p_AS), p_AS, R, (True, False))
    # the right (only planned) foot is put at x = y = 0
    assert a0 == 0 and g0 == pytest.approx(0.0) and p0[:2] == pytest.approx([0.0, 0.1])
    # trunk moves forward 5 cm over the right foot, the left foot lands 0.2 m ahead
    p_AS2 = np.array([[-0.05, -0.1, -0.7], [0.15, 0.1, -0.7]])
    _, p1, _, _ = odo.update(pak(p_AS2), p_AS2, R, (True, True))
    assert p1[0] == pytest.approx(0.05)
    assert odo.anchor == 1  # the flat, planned left foot takes over
    p_AS3 = p_AS2 + [-0.01, 0, 0]
    _, p2, _, a2 = odo.update(pak(p_AS3), p_AS3, R, (False, True))
    assert a2 == 1 and p2[0] == pytest.approx(0.06)


def test_paper_filter_tracks_lipm() -> None:
    """On an exact LIPM trajectory the paper's filter recovers c and c_dd."""
    dt, zc, g = 1e-3, 0.7, 9.806
    t = np.arange(0, 4, dt)
    c = 0.05 * np.sin(2 * np.pi * 0.5 * t)
    cdd = -((2 * np.pi * 0.5) ** 2) * c
    p = c - zc / g * cdd
    f = PaperCoMFilter(dt, zc, g, 1e2, 0.05**2, dob_gain=0.0)
    est = np.array([f.update(np.array([p[k], 0.0]), np.array([cdd[k], 0.0]), None)[0] for k in
                    range(t.size)])
    assert np.max(np.abs(est[1000:, 0] - c[1000:])) < 2e-3
