"""Closed-form leg IK and vectorized FK against MuJoCo's forward kinematics."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from grfguard.errors import ConfigError
from grfguard.model import kinematics as K
from grfguard.model.mjcf import build_model
from grfguard.model.robot import SIDES, SURALP, RobotConfig

SMALL = RobotConfig(
    name="small", mass=60.0, foot_length=0.20, foot_width=0.12, upper_leg_length=0.22,
    lower_leg_length=0.21, sole_to_ankle=0.09, hip_width=0.16, ankle_offset_x=0.02,
)
N = 300


def _random_state(seed: int):
    """Random pelvis poses and joint angles within a walking robot's range (knee > 0)."""
    rng = np.random.default_rng(seed)
    q = np.column_stack(
        [
            rng.uniform(-0.5, 0.5, N),  # hip yaw
            rng.uniform(-0.4, 0.4, N),  # hip roll
            rng.uniform(-1.0, 0.6, N),  # hip pitch
            rng.uniform(0.05, 2.0, N),  # knee (bent forward)
            rng.uniform(-0.8, 0.8, N),  # ankle pitch
            rng.uniform(-0.4, 0.4, N),  # ankle roll
        ]
    )
    q12 = np.hstack([q, rng.permutation(q)])
    p_WB = rng.normal(0.0, 0.2, (N, 3)) + [0.0, 0.0, 0.6]
    e = rng.uniform(-0.4, 0.4, (N, 3))
    R_WB = K.rot_z(e[:, 0]) @ K.rot_y(e[:, 1]) @ K.rot_x(e[:, 2])
    return p_WB, R_WB, q12


def _mujoco_site_poses(robot, p_WB, R_WB, q12, site):
    m = build_model(robot)
    d = mujoco.MjData(m)
    quat = K.rotation_to_quat(R_WB)
    pos = np.empty((len(q12), 3))
    rot = np.empty((len(q12), 3, 3))
    for i in range(len(q12)):
        d.qpos[:3], d.qpos[3:7], d.qpos[7:] = p_WB[i], quat[i], q12[i]
        mujoco.mj_kinematics(m, d)
        pos[i] = d.site(site).xpos
        rot[i] = d.site(site).xmat.reshape(3, 3)
    return pos, rot


@pytest.mark.parametrize("robot", [SURALP, SMALL], ids=["suralp", "small"])
@pytest.mark.parametrize("side", SIDES)
def test_ik_round_trip_against_mujoco(robot, side):
    """MuJoCo sole pose -> IK -> MuJoCo sole pose again, within 1e-9 m."""
    p_WB, R_WB, q12 = _random_state(1 if side == "r" else 2)
    p_WS, R_WS = _mujoco_site_poses(robot, p_WB, R_WB, q12, f"{side}_sole")
    q_leg = K.leg_ik(robot, side, p_WB, R_WB, p_WS, R_WS)
    cols = slice(0, 6) if side == "r" else slice(6, 12)
    q12_ik = q12.copy()
    q12_ik[:, cols] = q_leg
    p2, R2 = _mujoco_site_poses(robot, p_WB, R_WB, q12_ik, f"{side}_sole")
    assert np.abs(p2 - p_WS).max() < 1e-9
    assert np.abs(R2 - R_WS).max() < 1e-9
    # the knee-forward solution within these ranges is unique: angles come back too
    assert np.abs(q_leg - q12[:, cols]).max() < 1e-8


@pytest.mark.parametrize("side", SIDES)
def test_leg_fk_matches_mujoco(side):
    p_WB, R_WB, q12 = _random_state(3)
    cols = slice(0, 6) if side == "r" else slice(6, 12)
    p, R = K.leg_fk(SMALL, side, p_WB, R_WB, q12[:, cols])
    p_mj, R_mj = _mujoco_site_poses(SMALL, p_WB, R_WB, q12, f"{side}_sole")
    assert np.abs(p - p_mj).max() < 1e-12
    assert np.abs(R - R_mj).max() < 1e-12


def test_center_of_mass_matches_mujoco():
    p_WB, R_WB, q12 = _random_state(4)
    com = K.center_of_mass(SMALL, p_WB, R_WB, q12)
    m = build_model(SMALL)
    d = mujoco.MjData(m)
    quat = K.rotation_to_quat(R_WB)
    for i in range(0, N, 10):
        d.qpos[:3], d.qpos[3:7], d.qpos[7:] = p_WB[i], quat[i], q12[i]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        np.testing.assert_allclose(com[i], d.subtree_com[m.body("trunk").id], atol=1e-12)


def test_rotation_helpers_round_trip():
    rng = np.random.default_rng(5)
    q = rng.normal(size=(100, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q *= np.sign(q[:, :1])
    R = K.quat_to_rotation(q)
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)
    np.testing.assert_allclose(K.rotation_to_quat(R), q, atol=1e-12)
    mj = np.empty(9)
    mujoco.mju_quat2Mat(mj, q[0])
    np.testing.assert_allclose(R[0].ravel(), mj, atol=1e-15)


def test_ik_unreachable_is_finite_and_straight():
    q = K.leg_ik(SURALP, "r", [0, 0, 1.5], np.eye(3), [0, -0.1, 0], np.eye(3))
    assert np.isfinite(q).all()
    assert q[0, 3] == pytest.approx(0.0)


def test_bad_side_and_shapes():
    with pytest.raises(ConfigError, match="side"):
        K.leg_ik(SURALP, "x", [0, 0, 0.6], np.eye(3), [0, 0, 0], np.eye(3))
    with pytest.raises(ConfigError, match="12 columns"):
        K.body_poses(SURALP, [0, 0, 0.6], np.eye(3), np.zeros(6))
