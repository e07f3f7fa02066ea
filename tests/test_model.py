"""MJCF model: naming contract, masses, contacts, scaled gains, touch sensor truth."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from grfguard.errors import ConfigError
from grfguard.model.mjcf import (
    KV_OVER_KP,
    actuator_gains,
    body_layout,
    build_mjcf,
    build_model,
    joint_armature,
)
from grfguard.model.robot import JOINT_NAMES, SENSOR_NAMES, SIDES, SURALP, RobotConfig

SMALL = RobotConfig(
    name="small", mass=60.0, foot_length=0.20, foot_width=0.12, upper_leg_length=0.22,
    lower_leg_length=0.21, sole_to_ankle=0.09, hip_width=0.16,
)
AXES = {
    "hip_yaw": (0, 0, 1), "hip_roll": (1, 0, 0), "hip_pitch": (0, 1, 0),
    "knee": (0, 1, 0), "ankle_pitch": (0, 1, 0), "ankle_roll": (1, 0, 0),
}


@pytest.fixture(scope="module", params=[SURALP, SMALL], ids=["suralp", "small"])
def robot_model(request):
    return request.param, build_model(request.param)


def test_naming_contract(robot_model):
    robot, m = robot_model
    assert m.body("trunk").id == 1
    assert m.joint("root").type == mujoco.mjtJoint.mjJNT_FREE
    for s in SIDES:
        for b in ("hip_yaw_link", "hip_roll_link", "thigh", "shank", "ankle_pitch_link", "foot"):
            m.body(f"{s}_{b}")
        m.site(f"{s}_sole")
        for k in range(1, 5):
            m.site(f"{s}{k}")
            m.geom(f"{s}{k}_contact")
            m.sensor(f"touch_{s}{k}")
    hinges = [m.joint(i) for i in range(m.njnt) if m.jnt_type[i] == mujoco.mjtJoint.mjJNT_HINGE]
    assert [j.name for j in hinges] == list(JOINT_NAMES)
    for j in hinges:
        np.testing.assert_array_equal(j.axis, AXES[j.name[2:]])
        m.sensor(f"jointpos_{j.name}")
        assert m.actuator(j.name).trntype == mujoco.mjtTrn.mjTRN_JOINT
    for name in ("imu_acc", "imu_gyro", "imu_quat"):
        m.sensor(name)
    m.site("imu")
    assert m.nu == 12
    assert m.opt.timestep == pytest.approx(0.001)
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST


def test_masses_and_layout(robot_model):
    robot, m = robot_model
    assert m.body_mass.sum() == pytest.approx(robot.mass, rel=1e-12)
    assert sum(b.mass for b in body_layout(robot)) == pytest.approx(robot.mass, rel=1e-12)
    legs = [m.body_mass[m.body(f"r_{b}").id] for b in
            ("hip_yaw_link", "hip_roll_link", "thigh", "shank", "ankle_pitch_link", "foot")]
    frac = robot.thigh_mass_fraction + robot.shank_mass_fraction + robot.foot_mass_fraction
    assert sum(legs) == pytest.approx(frac * robot.mass)


def test_only_corner_spheres_collide(robot_model):
    robot, m = robot_model
    colliding = [
        mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g)
        for g in range(m.ngeom)
        if (m.geom_contype[g] or m.geom_conaffinity[g]) and m.geom_bodyid[g] != 0
    ]
    assert sorted(colliding) == sorted(f"{s}_contact" for s in SENSOR_NAMES)
    for s in SENSOR_NAMES:
        g = m.geom(f"{s}_contact")
        assert g.type == mujoco.mjtGeom.mjGEOM_SPHERE
        assert g.size[0] == pytest.approx(robot.contact_radius)


def test_standing_geometry(robot_model):
    """Zero angles: soles flat on z = 0, sphere centres at the sensor positions."""
    robot, m = robot_model
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    corners = robot.sensor_positions_in_foot()
    for s in SIDES:
        sole = d.site(f"{s}_sole")
        y = robot.hip_width / 2 * (1 if s == "l" else -1)
        np.testing.assert_allclose(sole.xpos, [0.0, y, 0.0], atol=1e-12)
        np.testing.assert_allclose(sole.xmat.reshape(3, 3), np.eye(3), atol=1e-12)
        for k in range(4):
            p = d.site(f"{s}{k + 1}").xpos
            np.testing.assert_allclose(
                p, [corners[k, 0], y + corners[k, 1], robot.contact_radius], atol=1e-12
            )
            np.testing.assert_allclose(d.geom(f"{s}{k + 1}_contact").xpos, p, atol=1e-12)


def test_gains_and_armature_scale():
    g_big, g_small = actuator_gains(SURALP), actuator_gains(SMALL)
    assert g_big["r_knee"][0] == pytest.approx(3.0e4)
    assert g_big["l_ankle_roll"][0] == pytest.approx(1.0e4)
    assert g_big["r_hip_pitch"][1] == pytest.approx(KV_OVER_KP * 3.0e4)
    assert joint_armature(SURALP) == pytest.approx(0.3)
    ratio = (SMALL.mass * SMALL.leg_length) / (SURALP.mass * SURALP.leg_length)
    assert g_small["r_knee"][0] == pytest.approx(3.0e4 * ratio)
    inertia_ratio = (SMALL.mass * SMALL.leg_length**2) / (SURALP.mass * SURALP.leg_length**2)
    assert joint_armature(SMALL) == pytest.approx(0.3 * inertia_ratio)
    m = build_model(SMALL)
    assert m.actuator_gainprm[m.actuator("r_knee").id, 0] == pytest.approx(g_small["r_knee"][0])
    assert m.dof_armature[m.joint("r_knee").dofadr[0]] == pytest.approx(joint_armature(SMALL))


def test_build_model_is_cached_and_checks_input():
    assert build_model(SURALP) is build_model(RobotConfig())
    assert "<mujoco" in build_mjcf(SURALP)
    with pytest.raises(ConfigError, match="RobotConfig"):
        build_mjcf({"mass": 114.0})  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def standing_run():
    """SURALP standing with servos holding a bent-knee pose for 0.6 s (mj_step loop)."""
    from grfguard.model.kinematics import leg_ik

    m = build_model(SURALP)
    d = mujoco.MjData(m)
    pelvis = np.array([0.0, 0.0, 0.60])
    q = []
    for s in SIDES:
        y = SURALP.hip_width / 2 * (1 if s == "l" else -1)
        q.append(leg_ik(SURALP, s, pelvis, np.eye(3), np.array([0.03, y, 0.0]), np.eye(3))[0])
    q = np.concatenate(q)
    d.qpos[:3] = pelvis
    d.qpos[7:] = q
    d.ctrl[:] = q
    rows = []
    for _ in range(600):
        mujoco.mj_step(m, d)
        touch = {s: d.sensor(f"touch_{s}").data[0] for s in SENSOR_NAMES}
        contact = {s: 0.0 for s in SENSOR_NAMES}
        f6 = np.zeros(6)
        for i in range(d.ncon):
            c = d.contact[i]
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, c.geom[1])
            if name is None or not name.endswith("_contact"):
                name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, c.geom[0])
            mujoco.mj_contactForce(m, d, i, f6)
            contact[name[:2]] += f6[0]
        rows.append((touch, contact, d.sensor("imu_acc").data.copy(), d.ncon))
    return rows


def test_touch_equals_contact_force(standing_run):
    loaded = 0
    for touch, contact, _, _ in standing_run:
        for s in SENSOR_NAMES:
            assert touch[s] == pytest.approx(contact[s], abs=1e-9, rel=1e-12)
            loaded += contact[s] > 1.0
    assert loaded > 0.9 * 8 * len(standing_run)  # all corners carry load while standing
    assert all(n == 8 for *_, n in standing_run[300:])  # one contact per corner


def test_standing_statics(standing_run):
    """At rest: total force = m g, accelerometer reads +g up."""
    touch, _, acc, _ = standing_run[-1]
    assert sum(touch.values()) == pytest.approx(SURALP.weight, rel=2e-3)
    # specific force of a body at rest: g up, seen in the (slightly tilted) IMU frame
    assert np.linalg.norm(acc) == pytest.approx(SURALP.gravity, abs=0.01)
    assert acc[2] > 0.999 * SURALP.gravity
