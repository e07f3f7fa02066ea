"""Walking simulation: it walks, the truth is consistent, the log follows the contract."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from grfguard.errors import ConfigError, SimulationError
from grfguard.io import schema
from grfguard.model.robot import JOINT_NAMES, SENSOR_NAMES, SIDES, SURALP
from grfguard.sim import GaitConfig, NoiseConfig, plan_walk, simulate
from grfguard.sim.pattern import default_com_height, preview_control
from grfguard.sim.simulate import EXTRA_TRUE_COLUMNS, SCENARIO, run_physics

WALKS = ["default_walk", "fast_gait_walk", "slow_gait_walk", "small_robot_walk"]
SETTLE = 0.3  # [s] settling transient after the start


def _foot_force(df: pd.DataFrame, side: str, prefix: str = "true_force_") -> np.ndarray:
    return df[[f"{prefix}{side}{k}" for k in range(1, 5)]].sum(axis=1).to_numpy()


def _touchdowns(df: pd.DataFrame, side: str, threshold: float = 20.0) -> int:
    """Number of steps of one foot: loads after an unloaded run longer than 30 % of the
    planned single support (true forces).

    The heel sometimes strikes, bounces off for a few ms (up to ~0.1 s after the last
    step of the fast gait) and lands again: that counts as one step.
    """
    gait = df.attrs["gait"]
    min_swing = int(0.3 * (1 - gait["double_support"]) * gait["step_period"] * 1000)
    loaded = _foot_force(df, side) > threshold
    edges = np.flatnonzero(np.diff(loaded.astype(int)))
    runs = np.split(loaded, edges + 1)
    count = 0
    for prev, nxt in zip(runs[:-1], runs[1:], strict=True):
        count += (not prev[0]) and len(prev) > min_swing and bool(nxt[0])
    return count


def _weight(df: pd.DataFrame) -> float:
    r = df.attrs["robot"]
    return r["mass"] * 9.806


def test_default_walk_makes_50_steps(default_walk):
    df = default_walk
    assert df["time"].iloc[-1] == pytest.approx(60.0 - 0.001)
    steps = _touchdowns(df, "r") + _touchdowns(df, "l")
    assert steps >= 50
    assert steps == df.attrs["n_steps"]
    # it goes forward: (n - 1) step lengths, within 10 cm
    x_end = df["true_com_x"].iloc[-1]
    assert x_end == pytest.approx((df.attrs["n_steps"] - 1) * 0.12, abs=0.1)


@pytest.mark.parametrize("walk", WALKS)
def test_walk_is_stable(walk, request):
    """No fall, CoM height within 5 cm of the plan, trunk tilt below 3 deg, all steps."""
    df = request.getfixturevalue(walk)
    zc = df.attrs["gait"]["com_height"]
    assert np.abs(df["true_com_z"] - zc).max() < 0.05
    assert df["true_trunk_tilt"].max() < 3.0
    assert _touchdowns(df, "r") + _touchdowns(df, "l") == df.attrs["n_steps"]


@pytest.mark.parametrize("walk", WALKS)
def test_mean_vertical_force_is_weight(walk, request):
    df = request.getfixturevalue(walk)
    after = df["time"] > SETTLE
    total = _foot_force(df, "r")[after] + _foot_force(df, "l")[after]
    assert total.mean() == pytest.approx(_weight(df), rel=0.005)


@pytest.mark.parametrize("walk", WALKS)
def test_planned_contact_matches_truth(walk, request):
    """In planned swing the foot is unloaded except at the edges (heel strike/toe-off).

    The heel lands ~70 ms before the planned touchdown and the toes leave ~40 ms after
    the planned lift-off (about 14 % of an 0.8 s swing), see the module report.
    """
    df = request.getfixturevalue(walk)
    for s in SIDES:
        swing = df[f"contact_ref_{s}"].to_numpy() == 0
        loaded = _foot_force(df, s) > 1.0
        assert swing.any()
        assert np.mean(loaded[swing]) < 0.2
        stance_single = (df[f"contact_ref_{s}"] == 1) & (
            df[f"contact_ref_{'l' if s == 'r' else 'r'}"] == 0
        )
        assert np.all(_foot_force(df, s)[stance_single.to_numpy()] > 0.2 * _weight(df))
        np.testing.assert_array_equal(df[f"true_contact_{s}"], _foot_force(df, s) > 0)


def test_true_zmp_follows_reference(default_walk):
    df = default_walk
    after = df["time"] > 1.0
    err = np.hypot(df["true_zmp_x"] - df["zmp_ref_x"], df["true_zmp_y"] - df["zmp_ref_y"])
    assert err[after].mean() < 0.025  # 1.3 cm measured (3.5 cm without feed-forward)
    # the truth ZMP is the CoP of all eight corners and lies between the feet
    assert df["true_zmp_y"].abs().max() < SURALP.hip_width / 2 + SURALP.foot_width / 2


def test_log_contract_columns(default_walk):
    df = default_walk
    expected = [
        schema.TIME, *schema.IMU_ACC, *schema.IMU_GYRO, *schema.IMU_QUAT,
        *schema.JOINT_COLUMNS, *schema.ZMP_REF, *schema.CONTACT_REF,
        *schema.FORCE_COLUMNS, *schema.TRUE_COLUMNS, *EXTRA_TRUE_COLUMNS,
    ]
    assert sorted(df.columns) == sorted(expected)
    assert len(set(df.columns)) == len(df.columns)
    assert all(c.startswith("true_") for c in EXTRA_TRUE_COLUMNS)
    assert np.all(np.diff(df["time"].to_numpy()) > 0)
    assert np.diff(df["time"].to_numpy()) == pytest.approx(0.001)
    assert set(np.unique(df[list(schema.CONTACT_REF)])) == {0, 1}
    quat = df[list(schema.IMU_QUAT)].to_numpy()
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, atol=1e-9)
    a = df.attrs
    assert a["sample_rate"] == 1000 and a["seed"] == 0 and a["scenario"] == SCENARIO
    assert a["robot"]["mass"] == SURALP.mass
    assert GaitConfig.from_dict(a["gait"]).com_height == pytest.approx(default_com_height(SURALP))
    assert NoiseConfig.from_dict(a["noise"]) == NoiseConfig()
    assert "grfguard_version" in a
    no_nan = [c for c in df.columns if not c.startswith(("true_zmp", "true_cop"))]
    assert np.isfinite(df[no_nan].to_numpy(dtype=float)).all()


def test_imu_at_rest_reads_gravity(clean_walk):
    rest = (clean_walk["time"] > 0.4) & (clean_walk["time"] < 0.6)
    acc = clean_walk.loc[rest, list(schema.IMU_ACC)].to_numpy()
    assert np.linalg.norm(acc, axis=1).mean() == pytest.approx(SURALP.gravity, abs=0.02)
    assert acc[:, 2].mean() > 0.99 * SURALP.gravity


def test_clean_noise_gives_truth(clean_walk):
    for s in SENSOR_NAMES:
        np.testing.assert_array_equal(clean_walk[f"force_{s}"], clean_walk[f"true_force_{s}"])
    quat = clean_walk[list(schema.IMU_QUAT)].to_numpy()
    base = clean_walk[[f"true_base_quat_{a}" for a in "wxyz"]].to_numpy()
    np.testing.assert_allclose(quat, base, atol=1e-12)  # the IMU sits on the trunk origin


def test_noise_levels(default_walk, clean_walk):
    n = len(clean_walk)
    err = default_walk["force_r1"].to_numpy()[:n] - default_walk["true_force_r1"].to_numpy()[:n]
    assert err.std() == pytest.approx(2.0, rel=0.05)
    res = 2 * np.pi / 2**17
    q = default_walk["q_r_knee"].to_numpy()
    np.testing.assert_allclose(q / res, np.round(q / res), atol=1e-6)


@pytest.fixture(scope="module")
def short_walks():
    gait = GaitConfig(duration=3.0)
    return (
        simulate(SURALP, gait, NoiseConfig(), seed=7),
        simulate(SURALP, gait, NoiseConfig(), seed=7),
        simulate(SURALP, gait, NoiseConfig(), seed=8),
    )


def test_same_seed_same_bytes(short_walks):
    a, b, c = short_walks
    assert a.to_numpy().tobytes() == b.to_numpy().tobytes()
    assert list(a.columns) == list(b.columns)
    assert not np.array_equal(a["force_r1"], c["force_r1"])
    assert not np.array_equal(a["imu_acc_x"], c["imu_acc_x"])
    np.testing.assert_array_equal(a["true_force_r1"], c["true_force_r1"])  # same physics


def test_progress_is_reported():
    seen: list[float] = []
    simulate(SURALP, GaitConfig(duration=2.5), NoiseConfig.none(), progress=seen.append)
    assert seen[0] == 0.0 and seen[-1] == 1.0
    assert np.all(np.diff(seen) >= 0) and len(seen) >= 4


def test_fall_raises_simulation_error():
    plan = plan_walk(SURALP, GaitConfig(duration=3.0))
    q = plan.q_ref.copy()
    ramp = np.clip((plan.time - 0.5) / 0.5, 0.0, 1.0)
    for s in SIDES:  # throw both hips sideways: the robot topples
        q[:, JOINT_NAMES.index(f"{s}_hip_roll")] += 0.9 * ramp
    bad = dataclasses.replace(plan, q_ref=q, qd_ref=np.gradient(q, 0.001, axis=0))
    with pytest.raises(SimulationError, match=r"fell at t = \d+\.\d+ s"):
        run_physics(SURALP, bad)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"step_length": -0.1}, "step_length"),
        ({"step_period": 0.0}, "step_period"),
        ({"double_support": 1.5}, "double_support"),
        ({"duration": 1.0, "start_time": 1.0, "stop_time": 1.0}, "duration"),
        ({"com_iterations": 2.5}, "com_iterations"),
        ({"preview_dt": 0.0055}, "preview_dt"),
    ],
)
def test_gait_validation(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        GaitConfig(**kwargs)


def test_config_round_trips_and_errors():
    g = GaitConfig(step_length=0.1, com_height=0.6)
    assert GaitConfig.from_dict(g.to_dict()) == g
    n = NoiseConfig(force_sigma=3.0)
    assert NoiseConfig.from_dict(n.to_dict()) == n
    assert NoiseConfig.none().is_clean and not NoiseConfig().is_clean
    with pytest.raises(ConfigError, match="unknown gait key"):
        GaitConfig.from_dict({"step_lenght": 0.1})
    with pytest.raises(ConfigError, match="encoder_counts_per_rev"):
        NoiseConfig(encoder_counts_per_rev=-1)
    with pytest.raises(ConfigError, match="force_sigma"):
        NoiseConfig(force_sigma=float("nan"))
    with pytest.raises(ConfigError, match="step_length"):
        plan_walk(SURALP, GaitConfig(step_length=0.5))
    with pytest.raises(ConfigError, match="seed"):
        simulate(SURALP, GaitConfig(duration=2.5), seed=1.5)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="GaitConfig"):
        simulate(SURALP, {"duration": 3})  # type: ignore[arg-type]


def test_preview_control_tracks_a_step():
    """The cart-table ZMP of the preview CoM tracks a ZMP step with small error."""
    dt, zc, g = 0.005, 0.66, 9.806
    t = np.arange(int(6 / dt)) * dt
    ref = np.where(t > 2.0, 0.1, 0.0)[:, None]
    states, _ = preview_control(ref, dt, zc, g, 1.6)
    zmp = states[:, 0, 0] - zc / g * states[:, 2, 0]
    assert abs(states[-1, 0, 0] - 0.1) < 1e-3
    assert np.abs(zmp - ref[:, 0])[(t < 1.9) | (t > 2.5)].max() < 0.01
    assert states[int(1.9 / dt), 0, 0] > 0.005  # the preview anticipates the step


def test_plan_is_consistent():
    plan = plan_walk(SURALP, GaitConfig(duration=8.0))
    assert plan.com_model_error < 1e-3
    assert plan.q_ref.shape == (8000, 12)
    # swing feet stay above ground, planned stance feet on it
    for i in range(2):
        assert plan.sole_pos[i, :, 2].min() >= 0.0
        assert np.all(plan.sole_pos[i, plan.contact_ref[:, i] == 1, 2] == 0.0)
    assert plan.sole_pos[:, :, 2].max() == pytest.approx(plan.gait.swing_height)


def test_planned_multibody_zmp_follows_reference():
    """Two-stage preview: the multibody ZMP of the plan (legs included) is on the reference."""
    from grfguard.sim.pattern import multibody_zmp

    plan = plan_walk(SURALP, GaitConfig(duration=8.0))
    zmp = multibody_zmp(SURALP, plan.time, plan.pelvis_pos, plan.q_ref)
    after = plan.time > 1.0
    err = np.hypot(*(zmp - plan.zmp_ref)[after].T)
    assert err.mean() < 0.003 and err.max() < 0.01
    # static posture: the ZMP is the CoM's ground projection
    n = 50
    still = multibody_zmp(
        SURALP, np.arange(n) * 0.005, np.tile(plan.pelvis_pos[0], (n, 1)),
        np.tile(plan.q_ref[0], (n, 1)),
    )
    np.testing.assert_allclose(still, np.tile(plan.com_ref[0, :2], (n, 1)), atol=1e-6)


def test_accelerometer_matches_the_motion(clean_walk):
    """Logged specific force = R_WI^T (second difference of the IMU position + g e_z).

    The IMU sits at the trunk origin (``true_base_*``). MuJoCo's own accelerometer
    sensor uses the explicit ``qacc`` and is off by ~0.3 m/s^2 with implicitfast.
    """
    from grfguard.model.kinematics import quat_to_rotation

    df = clean_walk
    p = df[["true_base_x", "true_base_y", "true_base_z"]].to_numpy()
    R = quat_to_rotation(df[[f"imu_quat_{a}" for a in "wxyz"]].to_numpy())
    a = (p[2:] - 2 * p[1:-1] + p[:-2]) / 1e-6
    a[:, 2] += SURALP.gravity
    expected = np.einsum("tji,tj->ti", R[1:-1], a)
    acc = df[list(schema.IMU_ACC)].to_numpy()[1:-1]
    np.testing.assert_allclose(acc, expected, atol=1e-6)
    assert acc.std(axis=0).min() > 0.05  # and it does move


@pytest.fixture(scope="module")
def clean_plan():
    """The plan behind ``clean_walk`` (same robot and gait)."""
    return plan_walk(SURALP, GaitConfig(duration=20.0))


def test_servos_track_the_plan(clean_walk, clean_plan):
    """With the inverse-dynamics feed-forward the open-loop servos track within mrad."""
    q = clean_walk[list(schema.JOINT_COLUMNS)].to_numpy()
    err = np.abs(q - clean_plan.q_ref)[500:]
    assert np.sqrt(np.mean(err**2)) < 1e-3
    assert err.max() < 5e-3
    assert clean_plan.tau_ff is not None and np.abs(clean_plan.tau_ff).max() > 50.0


def test_base_is_the_pelvis(clean_walk, clean_plan):
    plan = clean_plan
    base = clean_walk[["true_base_x", "true_base_y", "true_base_z"]].to_numpy()
    np.testing.assert_allclose(base[0], plan.pelvis_pos[0], atol=1e-12)
    assert np.abs(base - plan.pelvis_pos).max() < 0.02  # open loop, follows the plan


def test_vertical_momentum_balance(clean_walk):
    """m (c_z'' + g) equals the sum of the eight corner forces at every sample."""
    v = clean_walk["true_com_vel_z"].to_numpy()
    f = sum(clean_walk[f"true_force_{s}"].to_numpy() for s in SENSOR_NAMES)
    m_acc = SURALP.mass * ((v[1:] - v[:-1]) / 1e-3 + SURALP.gravity)
    assert np.abs(m_acc - f[:-1])[300:].max() < 0.5  # [N], out of ~1118 N
