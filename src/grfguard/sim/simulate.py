"""Open-loop MuJoCo walking simulation that writes a log following the log contract.

The planned joint references (:func:`grfguard.sim.pattern.plan_walk`) drive position
servos, ``ctrl = q_ref + (kv / kp) qd_ref + tau_ff / kp`` (MuJoCo's position ``kv``
damps toward zero velocity, so the velocity term gives velocity tracking; ``tau_ff``
are the inverse-dynamics torques of the plan, see ``GaitConfig.torque_feedforward``).
The physics runs with ``mujoco.rollout`` in one-second chunks; every log row is read
from ``sensordata`` of the same ``mj_forward`` (time ``k`` ms, before the step to
``k + 1`` ms).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np
import pandas as pd
from mujoco import rollout as mj_rollout

from grfguard.errors import ConfigError, SimulationError
from grfguard.model.kinematics import quat_to_rotation, rotation_to_quat
from grfguard.model.mjcf import KV_OVER_KP, actuator_gains, build_model
from grfguard.model.robot import JOINT_NAMES, SENSOR_NAMES, SIDES, SURALP, RobotConfig
from grfguard.sim.config import GaitConfig, NoiseConfig
from grfguard.sim.pattern import SAMPLE_RATE, WalkPlan, plan_walk, resolve_gait

__all__ = [
    "SCENARIO",
    "FALL_TILT_DEG",
    "FALL_COM_FRACTION",
    "EXTRA_TRUE_COLUMNS",
    "simulate",
    "run_physics",
    "PhysicsResult",
]

#: Versioned scenario id written to ``df.attrs["scenario"]`` (``<robot name>-walk-v1``
#: for other robots).
SCENARIO = "suralp-walk-v1"
#: Trunk tilt from vertical that counts as a fall in [deg].
FALL_TILT_DEG = 30.0
#: The robot has fallen when the CoM drops below this fraction of the planned height.
FALL_COM_FRACTION = 0.6
#: Truth columns beyond the log contract's ``TRUE_COLUMNS``.
EXTRA_TRUE_COLUMNS = (
    "true_com_vel_x",
    "true_com_vel_y",
    "true_com_vel_z",
    *(f"true_cop_{s}_{a}" for s in SIDES for a in "xy"),
    *(f"true_sole_{s}_{a}" for s in SIDES for a in "xyz"),
    *(f"true_sole_{s}_yaw" for s in SIDES),
    *(f"true_contact_{s}" for s in SIDES),
    "true_trunk_tilt",
)
_CHUNK = 1000  # physics steps per rollout call (1 s)


class PhysicsResult:
    """Raw sensordata of an open-loop run and a name -> column-slice index.

    Attributes:
        sensordata: (T, nsensordata) values, row k at time k ms.
        index: Sensor name -> slice of columns.
    """

    def __init__(self, sensordata: np.ndarray, index: dict[str, slice]) -> None:
        self.sensordata = sensordata
        self.index = index

    def __getitem__(self, name: str) -> np.ndarray:
        return self.sensordata[:, self.index[name]]


def _sensor_index(model: mujoco.MjModel) -> dict[str, slice]:
    out = {}
    for i in range(model.nsensor):
        adr, dim = int(model.sensor_adr[i]), int(model.sensor_dim[i])
        out[mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SENSOR, i)] = slice(adr, adr + dim)
    return out


def _tilt_deg(quat_wxyz: np.ndarray) -> np.ndarray:
    """Angle between the body z axis and world z in [deg]."""
    x, y = quat_wxyz[:, 1], quat_wxyz[:, 2]
    n2 = np.sum(quat_wxyz**2, axis=1)
    cos_t = np.clip(1.0 - 2.0 * (x * x + y * y) / n2, -1.0, 1.0)
    return np.degrees(np.arccos(cos_t))


def run_physics(
    robot: RobotConfig,
    plan: WalkPlan,
    progress: Callable[[float], Any] | None = None,
    progress_offset: float = 0.0,
    progress_scale: float = 1.0,
    perturb: Callable[[mujoco.MjModel], Any] | None = None,
) -> PhysicsResult:
    """Roll the plan out open loop in MuJoCo and return the sensordata.

    Args:
        robot: The robot description.
        plan: The walk plan (joint references at 1 kHz).
        progress: Optional ``callable(fraction_done)``.
        progress_offset: Fraction reported before the physics starts.
        progress_scale: Fraction of the total the physics accounts for.
        perturb: Optional ``callable(model)`` that edits the built ``MjModel`` in place
            before the run (reality gap: sensor position errors).

    Returns:
        The :class:`PhysicsResult`.

    Raises:
        SimulationError: If the robot falls (trunk tilt > 30 deg or CoM below 60 % of
            the planned height); the message gives the time and the reason.
    """
    model = build_model(robot)
    if perturb is not None:  # edit a copy: build_model is cached per robot
        model = copy.copy(model)
        perturb(model)
    data = mujoco.MjData(model)
    index = _sensor_index(model)
    ctrl = _controls(robot, plan, model)
    _start_at_rest(model, data, plan, ctrl[0])
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    n_t = plan.time.size
    out = np.empty((n_t, model.nsensordata))
    state = np.empty(mujoco.mj_stateSize(model, spec))
    warm = np.zeros(model.nv)
    tilt_sl, com_sl = index["truth_base_quat"], index["truth_com_pos"]
    com_min = FALL_COM_FRACTION * float(plan.gait.com_height)
    for k0 in range(0, n_t, _CHUNK):
        k1 = min(n_t, k0 + _CHUNK)
        mujoco.mj_getState(model, data, state, spec)
        _, sens = mj_rollout.rollout(
            model,
            data,
            initial_state=state[None],
            control=ctrl[None, k0:k1],
            initial_warmstart=warm[None],
        )
        out[k0:k1] = sens[0]
        warm = data.qacc_warmstart.copy()
        _check_fall(robot, plan, k0, out[k0:k1, tilt_sl], out[k0:k1, com_sl], com_min)
        if progress is not None:
            progress(progress_offset + progress_scale * k1 / n_t)
    return PhysicsResult(out, index)


def _controls(robot: RobotConfig, plan: WalkPlan, model: mujoco.MjModel) -> np.ndarray:
    """Position-servo controls (T, nu) in the model's actuator order: ``q_ref`` plus the
    velocity feed-forward and the torque feed-forward divided by the servo gain."""
    # actuator order = joint order of the model; map to JOINT_NAMES
    act_cols = [JOINT_NAMES.index(model.actuator(i).name) for i in range(model.nu)]
    ctrl = plan.q_ref + KV_OVER_KP * plan.qd_ref
    if plan.tau_ff is not None:
        kp = np.array([actuator_gains(robot)[j][0] for j in JOINT_NAMES])
        ctrl = ctrl + plan.tau_ff / kp
    return ctrl[:, act_cols]


def _start_at_rest(model: mujoco.MjModel, data: mujoco.MjData, plan: WalkPlan,
                   ctrl0: np.ndarray) -> None:
    """Initial state: the planned pose at rest, upright, first controls applied."""
    data.qpos[:3] = plan.pelvis_pos[0]
    data.qpos[3:7] = (1.0, 0.0, 0.0, 0.0)
    for i, name in enumerate(JOINT_NAMES):
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = plan.q_ref[0, i]
    data.qvel[:] = 0.0
    data.ctrl[:] = ctrl0
    mujoco.mj_forward(model, data)


def _check_fall(robot: RobotConfig, plan: WalkPlan, k0: int, base_quat: np.ndarray,
                com_pos: np.ndarray, com_min: float) -> None:
    """Raise :class:`SimulationError` at the first sample of a chunk (starting at sample
    ``k0``) whose trunk tilt exceeds FALL_TILT_DEG or whose CoM is below ``com_min`` [m]."""
    tilt = _tilt_deg(base_quat)
    low = com_pos[:, 2] < com_min
    bad = (tilt > FALL_TILT_DEG) | low
    if bad.any():
        i = int(np.argmax(bad))
        t = plan.time[k0 + i]
        reason = (
            f"trunk tilt {tilt[i]:.1f} deg > {FALL_TILT_DEG} deg"
            if tilt[i] > FALL_TILT_DEG
            else f"CoM height {com_pos[i][2]:.3f} m < {com_min:.3f} m"
        )
        raise SimulationError(
            f"robot {robot.name!r} fell at t = {t:.3f} s ({reason}) with gait "
            f"{plan.gait.to_dict()}; try shorter or slower steps"
        )


def _small_rotation(rotvec: np.ndarray) -> np.ndarray:
    """Rotation matrices (T, 3, 3) of rotation vectors (T, 3) [rad] (Rodrigues)."""
    theta = np.linalg.norm(rotvec, axis=1)
    safe = np.where(theta > 0, theta, 1.0)
    k = rotvec / safe[:, None]
    K = np.zeros((rotvec.shape[0], 3, 3))
    K[:, 0, 1], K[:, 0, 2] = -k[:, 2], k[:, 1]
    K[:, 1, 0], K[:, 1, 2] = k[:, 2], -k[:, 0]
    K[:, 2, 0], K[:, 2, 1] = -k[:, 1], k[:, 0]
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def _imu_specific_force(phys: PhysicsResult, gravity: float) -> np.ndarray:
    """Accelerometer reading (specific force in the IMU frame) [m/s^2], (T, 3).

    MuJoCo's ``accelerometer`` sensor uses the explicit ``qacc`` of ``mj_forward``;
    with the ``implicitfast`` integrator and stiff servo damping the velocity actually
    changes by a different amount (the implicit damping correction), so that sensor
    disagrees with the simulated motion by ~0.3 m/s^2 RMS. The log uses the motion
    itself instead: ``R_WI^T ((v_{k+1} - v_k) / dt + g e_z)`` from the IMU site's
    world velocity, which equals the second difference of its position.
    """
    v = phys["truth_imu_linvel"]
    a = np.empty_like(v)
    a[:-1] = (v[1:] - v[:-1]) * SAMPLE_RATE
    a[-1] = a[-2] if len(a) > 1 else 0.0
    a[:, 2] += gravity
    R_WI = quat_to_rotation(phys["imu_quat"])
    return np.einsum("tji,tj->ti", R_WI, a)


def _yaw(quat_wxyz: np.ndarray) -> np.ndarray:
    w, x, y, z = (quat_wxyz[:, i] for i in range(4))
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def simulate(
    robot: RobotConfig = SURALP,
    gait: GaitConfig | None = None,
    noise: NoiseConfig | None = None,
    seed: int = 0,
    progress: Callable[[float], Any] | None = None,
    reality: Any = None,
) -> pd.DataFrame:
    """Simulate an open-loop walk in MuJoCo and return a log-contract DataFrame.

    Args:
        robot: The robot description (default SURALP).
        gait: The gait (default :class:`GaitConfig()`: 0.12 m steps, 1.0 s period,
            20 % double support, 60 s).
        noise: Sensor noise (default :class:`NoiseConfig()`; ``NoiseConfig.none()``
            for clean data).
        seed: Seed of ``numpy.random.default_rng`` for every noise draw.
        progress: Optional ``callable(fraction_done)`` called with values in [0, 1].
        reality: Optional :class:`grfguard.sim.reality.RealityGap`: the physics and the
            sensors follow the true robot, ``attrs["robot"]`` keeps ``robot`` and
            ``attrs["reality"]`` records the resolved gap (truth only); its
            ``controller`` plans the walk on ``robot`` (``"open_loop"``) or on the true
            body (``"balanced"``).

    Returns:
        One row per 1 ms sample. Columns: ``time``, ``imu_acc_*`` (specific force, IMU
        frame, +g up at rest) [m/s^2], ``imu_gyro_*`` [rad/s], ``imu_quat_w/x/y/z``,
        ``q_<joint>`` [rad], ``zmp_ref_x/y`` [m], ``contact_ref_r/l`` (0/1),
        ``force_<s>`` (noisy) [N], and truth ``true_force_<s>`` [N],
        ``true_com_x/y/z`` [m], ``true_zmp_x/y`` [m] (CoP of all corner forces),
        ``true_base_x/y/z`` [m], ``true_base_quat_w/x/y/z``, plus
        :data:`EXTRA_TRUE_COLUMNS` (CoM velocity [m/s], per-foot CoP [m, NaN when the
        foot carries < 1 N], sole positions [m] and yaw [rad], actual contact of each
        foot (0/1, any corner force > 0), trunk tilt [deg]).
        ``df.attrs`` holds ``robot``, ``gait`` (resolved), ``noise``, ``seed``,
        ``sample_rate``, ``grfguard_version``, ``scenario``, ``n_steps``,
        ``step_times``.

    Raises:
        SimulationError: If the robot falls (time and reason in the message).
        ConfigError: If an argument has the wrong type or the gait does not fit.
    """
    from grfguard import __version__

    gait = GaitConfig() if gait is None else gait
    noise = NoiseConfig() if noise is None else noise
    _check_arguments(robot, gait, noise, seed)
    if progress is not None:
        progress(0.0)
    plan = _plan(robot, gait, reality)
    if progress is not None:
        progress(0.1)
    true_robot = robot if reality is None else reality.true_robot(robot)
    perturb = None if reality is None else reality.perturb_model
    phys = run_physics(
        true_robot, plan, progress, progress_offset=0.1, progress_scale=0.85, perturb=perturb
    )
    cols = _log_columns(robot, plan, phys, noise, int(seed))
    if reality is not None:
        cols = reality.apply_to_columns(cols, plan.contact_ref, SAMPLE_RATE)
    df = pd.DataFrame(cols)
    df.attrs.update(
        {
            "robot": robot.to_dict(),
            "gait": plan.gait.to_dict(),
            "noise": noise.to_dict(),
            "seed": int(seed),
            "sample_rate": SAMPLE_RATE,
            "grfguard_version": __version__,
            "scenario": SCENARIO if robot.name == "suralp" else f"{robot.name}-walk-v1",
            "n_steps": int(plan.gait.n_steps),
            "step_times": [float(v) for v in plan.step_times],
        }
    )
    if reality is not None:
        df.attrs["reality"] = reality.resolve()
    if progress is not None:
        progress(1.0)
    return df


def _plan(robot: RobotConfig, gait: GaitConfig, reality: Any) -> WalkPlan:
    """The walk plan: on the description, or on the body ``reality.controller`` names;
    the gait's robot defaults (CoM height) always come from the description."""
    if reality is None:
        return plan_walk(robot, gait)
    return plan_walk(reality.planned_robot(robot), resolve_gait(robot, gait))


def _check_arguments(robot: Any, gait: Any, noise: Any, seed: Any) -> None:
    """Raise :class:`ConfigError` if an argument of :func:`simulate` has the wrong type."""
    for name, val, typ in (
        ("robot", robot, RobotConfig),
        ("gait", gait, GaitConfig),
        ("noise", noise, NoiseConfig),
    ):
        if not isinstance(val, typ):
            raise ConfigError(
                f"simulate({name}=...) needs a {typ.__name__}, got {type(val).__name__}"
            )
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool):
        raise ConfigError(f"simulate(seed=...) needs an integer, got {seed!r}")


def _log_columns(
    robot: RobotConfig, plan: WalkPlan, phys: PhysicsResult, noise: NoiseConfig, seed: int
) -> dict[str, np.ndarray]:
    """Every log column: measured IMU, encoders, plan, load cells, then the truth.

    One ``numpy.random.default_rng(seed)`` draws in a fixed order: IMU biases and noise
    (:func:`_imu_columns`), then load-cell noise (:func:`_force_columns`).
    """
    rng = np.random.default_rng(seed)
    cols: dict[str, np.ndarray] = {"time": np.round(plan.time, 9)}
    _imu_columns(cols, robot, phys, noise, rng)
    _encoder_and_plan_columns(cols, plan, phys, noise)
    f_all = _force_columns(cols, phys, noise, rng)
    _truth_columns(cols, phys, f_all)
    return cols


def _imu_columns(cols: dict[str, np.ndarray], robot: RobotConfig, phys: PhysicsResult,
                 noise: NoiseConfig, rng: np.random.Generator) -> None:
    """IMU: accelerometer and gyro with constant bias + white noise, attitude error."""
    n_t = len(cols["time"])
    acc_bias = rng.normal(0.0, noise.acc_bias_sigma, 3) if noise.acc_bias_sigma > 0 else np.zeros(3)
    gyro_bias = (
        rng.normal(0.0, noise.gyro_bias_sigma, 3) if noise.gyro_bias_sigma > 0 else np.zeros(3)
    )
    att_bias = (
        rng.normal(0.0, noise.attitude_bias_sigma, 3)
        if noise.attitude_bias_sigma > 0
        else np.zeros(3)
    )
    acc = _imu_specific_force(phys, robot.gravity) + acc_bias
    if noise.acc_sigma > 0:
        acc = acc + rng.normal(0.0, noise.acc_sigma, (n_t, 3))
    gyro = phys["imu_gyro"] + gyro_bias
    if noise.gyro_sigma > 0:
        gyro = gyro + rng.normal(0.0, noise.gyro_sigma, (n_t, 3))
    quat = phys["imu_quat"].copy()
    if noise.attitude_sigma > 0 or noise.attitude_bias_sigma > 0:
        rv = np.broadcast_to(att_bias, (n_t, 3)).copy()
        if noise.attitude_sigma > 0:
            rv = rv + rng.normal(0.0, noise.attitude_sigma, (n_t, 3))
        quat = rotation_to_quat(quat_to_rotation(quat) @ _small_rotation(rv))
    quat = quat * np.where(quat[:, :1] < 0, -1.0, 1.0)
    for i, a in enumerate("xyz"):
        cols[f"imu_acc_{a}"] = acc[:, i]
    for i, a in enumerate("xyz"):
        cols[f"imu_gyro_{a}"] = gyro[:, i]
    for i, a in enumerate("wxyz"):
        cols[f"imu_quat_{a}"] = quat[:, i]


def _encoder_and_plan_columns(cols: dict[str, np.ndarray], plan: WalkPlan,
                              phys: PhysicsResult, noise: NoiseConfig) -> None:
    """Quantized encoders ``q_<joint>`` [rad], the plan's ZMP [m] and contact (0/1)."""
    res = 2 * np.pi / noise.encoder_counts_per_rev if noise.encoder_counts_per_rev else 0.0
    for j in JOINT_NAMES:
        q = phys[f"jointpos_{j}"][:, 0]
        cols[f"q_{j}"] = np.round(q / res) * res if res else q.copy()

    cols["zmp_ref_x"] = plan.zmp_ref[:, 0].copy()
    cols["zmp_ref_y"] = plan.zmp_ref[:, 1].copy()
    for i, s in enumerate(SIDES):
        cols[f"contact_ref_{s}"] = plan.contact_ref[:, i].astype(np.int64)


def _force_columns(cols: dict[str, np.ndarray], phys: PhysicsResult, noise: NoiseConfig,
                   rng: np.random.Generator) -> np.ndarray:
    """Noisy ``force_<s>`` and ``true_force_<s>`` [N]; returns the true forces (T, 8)."""
    n_t = len(cols["time"])
    true_force = {s: phys[f"touch_{s}"][:, 0] for s in SENSOR_NAMES}
    force_noise = (
        rng.normal(0.0, noise.force_sigma, (n_t, len(SENSOR_NAMES)))
        if noise.force_sigma > 0
        else np.zeros((n_t, len(SENSOR_NAMES)))
    )
    for k, s in enumerate(SENSOR_NAMES):
        cols[f"force_{s}"] = true_force[s] + force_noise[:, k]
    for s in SENSOR_NAMES:
        cols[f"true_force_{s}"] = true_force[s].copy()
    return np.column_stack([true_force[s] for s in SENSOR_NAMES])


def _truth_columns(cols: dict[str, np.ndarray], phys: PhysicsResult, f_all: np.ndarray) -> None:
    """Truth: CoM, ZMP, base pose, CoM velocity, per-foot CoP, soles, contact, tilt."""
    com = phys["truth_com_pos"]
    for i, a in enumerate("xyz"):
        cols[f"true_com_{a}"] = com[:, i].copy()
    # ZMP on flat ground = CoP of the corner normal forces (contacts lie below the
    # sphere centres, so the centres' xy are the contact points' xy)
    p_all = np.stack([phys[f"truth_corner_{s}_pos"] for s in SENSOR_NAMES], axis=1)
    zmp = _cop(f_all, p_all[:, :, :2])
    cols["true_zmp_x"], cols["true_zmp_y"] = zmp[:, 0], zmp[:, 1]
    base = phys["truth_base_pos"]
    for i, a in enumerate("xyz"):
        cols[f"true_base_{a}"] = base[:, i].copy()
    bq = phys["truth_base_quat"]
    bq = bq * np.where(bq[:, :1] < 0, -1.0, 1.0)
    for i, a in enumerate("wxyz"):
        cols[f"true_base_quat_{a}"] = bq[:, i].copy()

    vel = phys["truth_com_vel"]
    for i, a in enumerate("xyz"):
        cols[f"true_com_vel_{a}"] = vel[:, i].copy()
    for si, s in enumerate(SIDES):
        cop = _cop(f_all[:, 4 * si : 4 * si + 4], p_all[:, 4 * si : 4 * si + 4, :2])
        cols[f"true_cop_{s}_x"], cols[f"true_cop_{s}_y"] = cop[:, 0], cop[:, 1]
    for s in SIDES:
        sp = phys[f"truth_sole_{s}_pos"]
        for i, a in enumerate("xyz"):
            cols[f"true_sole_{s}_{a}"] = sp[:, i].copy()
    for s in SIDES:
        cols[f"true_sole_{s}_yaw"] = _yaw(phys[f"truth_sole_{s}_quat"])
    for si, s in enumerate(SIDES):
        cols[f"true_contact_{s}"] = (f_all[:, 4 * si : 4 * si + 4].sum(axis=1) > 0.0).astype(
            np.int64
        )
    cols["true_trunk_tilt"] = _tilt_deg(bq)


def _cop(f: np.ndarray, p_xy: np.ndarray) -> np.ndarray:
    """Centre of pressure (T, 2) [m] of forces ``f`` (T, K) [N] at points ``p_xy``
    (T, K, 2) [m]; NaN where the total is below 1 N."""
    tot = f.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cop = np.einsum("tk,tka->ta", f, p_xy) / tot[:, None]
    cop[tot < 1.0] = np.nan
    return cop
