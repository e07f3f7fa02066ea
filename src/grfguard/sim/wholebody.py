"""Whole-body walking simulation of any humanoid described by a model file + TOML.

Pipeline (as :mod:`grfguard.sim.pattern` for SURALP, without its closed-form IK):
footstep plan -> piecewise-linear ZMP reference -> cart-table preview control (CoM
x, y at a constant height) -> swing-foot trajectories -> whole-body IK -> joint
references, and inverse-dynamics feed-forward torques -> position servos in MuJoCo.

IK (every ``ik_dt``, then cubic splines to 1 kHz): the unknowns are the base position
and the leg joints (base upright, upper body at the nominal posture); the tasks are
the multibody CoM and the pose of each sole (6 + 6 + 3 equations). Damped least
squares on MuJoCo Jacobians, ``dx = J^T (J J^T + lambda^2 I)^-1 e``, warm-started
from the previous sample.

Feed-forward: ``f = M qdd + c`` (``mj_inverse`` without contacts); the six free-joint
rows come from the soles, shared as the ZMP reference is between the feet (as in
:func:`grfguard.sim.pattern.feedforward_torques`); ``tau = f_joints - J^T w``.

The log has ``q_<joint>`` for every joint of the model, the IMU of the TOML, and the
force channels of the TOML: ``force_<r|l><1..4>`` [N] (corner load cells) or
``ft_<r|l>_<fx,fy,fz>`` [N] and ``ft_<r|l>_<tx,ty,tz>`` [N m] (six-axis sensor, sensor
frame, the wrench the foot below the sensor exerts on the leg above: ``fz > 0`` when
the foot is loaded), with ``true_`` columns of each, and truth of the CoM, base,
soles and contact.
"""

from __future__ import annotations

import dataclasses
import math
import time as _time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
import pandas as pd
from mujoco import rollout as mj_rollout
from scipy.interpolate import CubicSpline

from grfguard.errors import ConfigError, SimulationError
from grfguard.model.description import FT_AXES, SIDES
from grfguard.model.kinematics import quat_to_rotation, rotation_to_quat
from grfguard.model.loader import KV_OVER_KP, LoadedRobot
from grfguard.sim.config import GaitConfig, NoiseConfig
from grfguard.sim.pattern import _feet, _right_load_share, preview_control
from grfguard.sim.simulate import _small_rotation

__all__ = ["WholeBodyPlan", "scaled_gait", "plan_wholebody", "simulate_robot",
           "SAMPLE_RATE", "decimate"]

#: Physics and plan rate [Hz].
SAMPLE_RATE = 1000
_DT = 1.0 / SAMPLE_RATE
#: SURALP's hip-to-sole length [m]: the default gait (0.12 m, 1 s) is scaled from it.
_REF_LEG = 0.674
_FALL_TILT_DEG = 30.0
_CHUNK = 1000


def scaled_gait(robot: LoadedRobot, **overrides: Any) -> GaitConfig:
    """The default gait scaled to the robot: step length ``0.12 m * L / L_SURALP``,
    period ``1 s * sqrt(L / L_SURALP)`` (same Froude number), swing height 6 % of L
    (L = hip-to-sole length); ``overrides`` replace any field."""
    s = robot.leg_length / _REF_LEG
    kw: dict[str, Any] = {
        "step_length": round(0.12 * s, 4),
        "step_period": round(math.sqrt(s), 3),
        "swing_height": round(0.06 * robot.leg_length, 4),
    }
    kw.update({k: v for k, v in overrides.items() if v is not None})
    return GaitConfig(**kw)


@dataclass(frozen=True)
class WholeBodyPlan:
    """A planned walk at 1 kHz (T samples, n joints in ``robot.joint_names`` order).

    Attributes:
        gait: The resolved gait.
        time: [s], (T,).
        zmp_ref: [m], (T, 2).
        contact_ref: Planned stance of (right, left), (T, 2) 0/1.
        com_ref: Planned CoM [m], (T, 3).
        base_pos: Base position [m], (T, 3) (base upright).
        q_ref: Joint references [rad], (T, n).
        qd_ref: Joint rates [rad/s], (T, n).
        tau_ff: Feed-forward torques [N m], (T, n).
        step_times: Step start times [s].
        ik_error: Largest IK residual over the plan [m].
    """

    gait: GaitConfig
    time: np.ndarray
    zmp_ref: np.ndarray
    contact_ref: np.ndarray
    com_ref: np.ndarray
    base_pos: np.ndarray
    q_ref: np.ndarray
    qd_ref: np.ndarray
    tau_ff: np.ndarray
    step_times: np.ndarray
    ik_error: float


class _IK:
    """Damped-least-squares IK on the CoM and both sole poses (module docstring)."""

    def __init__(self, robot: LoadedRobot, damping: float = 1e-4) -> None:
        m = robot.model
        self.m = m
        self.d = mujoco.MjData(m)
        self.base = m.body(robot.base_body).id
        self.sites = [m.site(f"{s}_sole").id for s in SIDES]
        legs = [j for leg in robot.leg_joints for j in leg]
        self.leg_q = robot.qpos_adr(legs)
        self.cols = np.concatenate([[0, 1, 2], robot.dof_adr(legs)])
        self.lam2 = damping**2
        self.jc = np.zeros((3, m.nv))
        self.jp = np.zeros((3, m.nv))
        self.jr = np.zeros((3, m.nv))

    def solve(self, qpos: np.ndarray, com: np.ndarray, soles: np.ndarray, iters: int) -> float:
        m, d = self.m, self.d
        err = np.inf
        for _ in range(iters + 1):
            d.qpos[:] = qpos
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            e = [com - d.subtree_com[self.base]]
            rows = []
            mujoco.mj_jacSubtreeCom(m, d, self.jc, self.base)
            rows.append(self.jc[:, self.cols].copy())
            for i, sid in enumerate(self.sites):
                R = d.site_xmat[sid].reshape(3, 3)
                e.append(soles[i] - d.site_xpos[sid])
                # rotation error to the flat, forward-pointing target: -log(R) (small)
                e.append(-0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0],
                                          R[1, 0] - R[0, 1]]))
                mujoco.mj_jacSite(m, d, self.jp, self.jr, sid)
                rows.append(self.jp[:, self.cols].copy())
                rows.append(self.jr[:, self.cols].copy())
            ev = np.concatenate(e)
            err = float(np.abs(ev).max())
            if _ == iters or err < 1e-7:
                break
            J = np.vstack(rows)
            dx = J.T @ np.linalg.solve(J @ J.T + self.lam2 * np.eye(J.shape[0]), ev)
            qpos[:3] += dx[:3]
            qpos[self.leg_q] += dx[3:]
        return err


def _nominal_qpos(robot: LoadedRobot) -> np.ndarray:
    m = robot.model
    qpos = m.qpos0.copy()
    qpos[:3] = 0.0
    qpos[3:7] = (1.0, 0.0, 0.0, 0.0)
    for j, v in robot.description.nominal.items():
        qpos[m.jnt_qposadr[m.joint(j).id]] = v
    return qpos


def _footsteps(gait: GaitConfig, half_w: float, x0: float) -> tuple[np.ndarray, np.ndarray]:
    n = gait.n_steps
    footsteps = np.zeros((2, n + 1, 2))
    footsteps[:, :, 0] = x0
    footsteps[0, :, 1] = -half_w
    footsteps[1, :, 1] = half_w
    swing = np.empty(n, dtype=int)
    first = 0 if gait.first_swing == "r" else 1
    for j in range(1, n + 1):
        sw = first if j % 2 == 1 else 1 - first
        swing[j - 1] = sw
        footsteps[:, j, 0] = footsteps[:, j - 1, 0]
        footsteps[sw, j, 0] = x0 + ((j - 1) * gait.step_length if j == n else j * gait.step_length)
    return footsteps, swing


def _zmp_knots(gait: GaitConfig, footsteps: np.ndarray, swing: np.ndarray):
    n, T, Tds, ts = gait.n_steps, gait.step_period, gait.double_support_time, gait.start_time
    mid0 = footsteps[:, 0].mean(axis=0)
    kt, kp = [0.0, ts], [mid0, mid0]
    for j in range(1, n + 1):
        sup = 1 - swing[j - 1]
        kt += [ts + (j - 1) * T + Tds, ts + j * T]
        kp += [footsteps[sup, j - 1], footsteps[sup, j - 1]]
    mid_end = footsteps[:, n].mean(axis=0)
    kt += [ts + n * T + Tds, gait.duration + gait.preview_horizon + 1.0]
    kp += [mid_end, mid_end]
    return np.asarray(kt), np.asarray(kp)


def plan_wholebody(robot: LoadedRobot, gait: GaitConfig, ik_dt: float = 0.01,
                   gravity: float = 9.81) -> WholeBodyPlan:
    """Plan a straight walk of ``robot`` (module docstring).

    Raises:
        ConfigError: If the IK cannot reach the planned feet (gait too long or CoM too
            high for the legs).
    """
    ik = _IK(robot)
    qpos, half_w, gait = _stand_and_resolve(robot, ik, gait)
    com_h = gait.com_height

    n_t = int(round(gait.duration * SAMPLE_RATE))
    t = np.arange(n_t) * _DT
    footsteps, swing = _footsteps(gait, half_w, 0.0)
    kt, kp = _zmp_knots(gait, footsteps, swing)
    zmp = np.column_stack([np.interp(t, kt, kp[:, 0]), np.interp(t, kt, kp[:, 1])])
    sole, contact = _feet(t, footsteps, swing, gait)
    dtp = gait.preview_dt
    n_p = int(math.ceil(gait.duration / dtp)) + 1
    tp = np.arange(n_p) * dtp
    zmp_p = np.column_stack([np.interp(tp, kt, kp[:, 0]), np.interp(tp, kt, kp[:, 1])])
    states, _ = preview_control(zmp_p, dtp, com_h, gravity, gait.preview_horizon)
    # IK grid
    n_i = int(math.ceil(gait.duration / ik_dt)) + 1
    ti = np.arange(n_i) * ik_dt
    com_i = np.column_stack([np.interp(ti, tp, states[:, 0, 0]),
                             np.interp(ti, tp, states[:, 0, 1]), np.full(n_i, com_h)])
    sole_i, _ = _feet(ti, footsteps, swing, gait)
    legs_adr = ik.leg_q
    _bend_knees(robot, qpos)
    base_i, q_i, worst = _solve_ik_grid(robot, ik, qpos, com_i, sole_i)
    base_sp = CubicSpline(ti, base_i)
    q_sp = CubicSpline(ti, q_i)
    base = base_sp(t)
    qpos_all = np.tile(qpos, (n_t, 1))
    qpos_all[:, :3] = base
    qpos_all[:, legs_adr] = q_sp(t)
    joint_adr = robot.qpos_adr(robot.joint_names)
    q_ref = qpos_all[:, joint_adr]
    dof_legs = {a: i for i, a in enumerate(legs_adr)}
    qd_ref = np.zeros_like(q_ref)
    qd_legs = q_sp(t, 1)
    for n, a in enumerate(joint_adr):
        if a in dof_legs:
            qd_ref[:, n] = qd_legs[:, dof_legs[a]]
    alpha = _right_load_share(zmp, sole, contact)
    tau = _feedforward(robot, ti, base_sp, q_sp, legs_adr, qpos, np.interp(ti, t, alpha))
    tau_ff = CubicSpline(ti, tau)(t)
    com_ref = np.column_stack([np.interp(t, tp, states[:, 0, 0]),
                               np.interp(t, tp, states[:, 0, 1]), np.full(n_t, com_h)])
    return WholeBodyPlan(
        gait=gait, time=t, zmp_ref=zmp, contact_ref=contact, com_ref=com_ref, base_pos=base,
        q_ref=q_ref, qd_ref=qd_ref, tau_ff=tau_ff,
        step_times=gait.start_time + np.arange(gait.n_steps) * gait.step_period,
        ik_error=worst,
    )


def _stand_and_resolve(robot: LoadedRobot, ik: _IK,
                       gait: GaitConfig) -> tuple[np.ndarray, float, GaitConfig]:
    """Nominal pose standing on the ground (sole centres at x = 0, feet centred on y = 0),
    half the distance between the soles [m], and the gait with the robot's CoM height
    (10 % of the leg below straight legs) and swing height (6 % of the leg) filled in.

    Raises:
        ConfigError: If the step is longer than 40 % of the leg.
    """
    m = robot.model
    qpos = _nominal_qpos(robot)
    d = ik.d
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    soles0 = np.array([d.site_xpos[s].copy() for s in ik.sites])
    com0 = d.subtree_com[ik.base].copy()
    z_sole = soles0[:, 2].mean()
    half_w = 0.5 * (soles0[1, 1] - soles0[0, 1])
    # stand on the ground, sole centres at x = 0, feet centred on y = 0
    shift = np.array([-soles0[:, 0].mean(), -soles0[:, 1].mean(), -z_sole])
    qpos[:3] += shift
    com_straight = com0[2] - z_sole
    com_h = gait.com_height if gait.com_height is not None else (
        com_straight - 0.10 * robot.leg_length)
    swing_h = gait.swing_height if gait.swing_height is not None else 0.06 * robot.leg_length
    gait = dataclasses.replace(gait, com_height=float(com_h), swing_height=float(swing_h))
    if gait.step_length > 0.4 * robot.leg_length:
        raise ConfigError(
            f"gait.step_length = {gait.step_length} m is too long for {robot.description.name}"
            f" (hip-to-sole {robot.leg_length:.3f} m); use at most "
            f"{0.4 * robot.leg_length:.3f} m")
    return qpos, half_w, gait


def _bend_knees(robot: LoadedRobot, qpos: np.ndarray) -> None:
    """Bend the knees a little (in place) so the IK starts away from the straight-leg
    singularity, and lower the base by 2 % of the leg."""
    m = robot.model
    for leg in robot.leg_joints:
        for j, sgn in ((leg[3], 1.0), (leg[2], -0.5), (leg[4], -0.5)):
            lo, hi = m.jnt_range[m.joint(j).id]
            bend = 0.3 * sgn if (lo <= 0.3 * sgn <= hi or lo == hi) else -0.3 * sgn
            qpos[m.jnt_qposadr[m.joint(j).id]] = bend
    qpos[2] -= 0.02 * robot.leg_length


def _solve_ik_grid(robot: LoadedRobot, ik: _IK, qpos: np.ndarray, com_i: np.ndarray,
                   sole_i: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Whole-body IK at every grid point (warm-started from the previous one, ``qpos``
    updated in place): base positions (N, 3) [m], leg joints (N, n_legs) [rad] and the
    worst residual [m].

    Raises:
        ConfigError: If the worst residual exceeds 1 mm.
    """
    n_i, legs_adr = len(com_i), ik.leg_q
    base_i = np.empty((n_i, 3))
    q_i = np.empty((n_i, legs_adr.size))
    worst = 0.0
    for k in range(n_i):
        err = ik.solve(qpos, com_i[k], sole_i[:, k], 60 if k == 0 else 3)
        worst = max(worst, err)
        base_i[k] = qpos[:3]
        q_i[k] = qpos[legs_adr]
    if worst > 1e-3:
        raise ConfigError(
            f"gait does not fit {robot.description.name}: whole-body IK residual "
            f"{1000 * worst:.1f} mm; shorten step_length or lower com_height")
    return base_i, q_i, worst


def _feedforward(robot, ti, base_sp, q_sp, legs_adr, qpos_nominal, right_share) -> np.ndarray:
    """Joint torques [N m] (len(ti), n joints) of the planned motion (module docstring)."""
    m = robot.model
    d = mujoco.MjData(m)
    saved = m.opt.disableflags
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    sites = [m.site(f"{s}_sole").id for s in SIDES]
    leg_dof = robot.dof_adr([j for leg in robot.leg_joints for j in leg])
    joint_dof = robot.dof_adr(robot.joint_names)
    b, bd, bdd = base_sp(ti), base_sp(ti, 1), base_sp(ti, 2)
    q, qd, qdd = q_sp(ti), q_sp(ti, 1), q_sp(ti, 2)
    out = np.empty((ti.size, joint_dof.size))
    jac = np.zeros((6, m.nv))
    try:
        for k in range(ti.size):
            d.qpos[:] = qpos_nominal
            d.qpos[:3] = b[k]
            d.qpos[legs_adr] = q[k]
            d.qvel[:] = 0.0
            d.qacc[:] = 0.0
            d.qvel[:3], d.qacc[:3] = bd[k], bdd[k]
            d.qvel[leg_dof], d.qacc[leg_dof] = qd[k], qdd[k]
            mujoco.mj_inverse(m, d)
            f = d.qfrc_inverse.copy()
            ground = np.zeros(m.nv)
            for i, sid in enumerate(sites):
                mujoco.mj_jacSite(m, d, jac[:3], jac[3:], sid)
                w = np.linalg.solve(jac[:, :6].T, f[:6])
                share = right_share[k] if i == 0 else 1.0 - right_share[k]
                ground += share * (jac.T @ w)
            out[k] = (f - ground)[joint_dof]
    finally:
        m.opt.disableflags = saved
    return out


def _tilt_deg(quat: np.ndarray) -> np.ndarray:
    x, y = quat[:, 1], quat[:, 2]
    n2 = np.sum(quat**2, axis=1)
    return np.degrees(np.arccos(np.clip(1.0 - 2.0 * (x * x + y * y) / n2, -1.0, 1.0)))


def _run(robot: LoadedRobot, plan: WholeBodyPlan, progress) -> tuple[np.ndarray, dict]:
    m = robot.model
    d = mujoco.MjData(m)
    index = {}
    for i in range(m.nsensor):
        a, n = int(m.sensor_adr[i]), int(m.sensor_dim[i])
        index[m.sensor(i).name] = slice(a, a + n)
    act = [robot.joint_names.index(m.actuator(i).name) for i in range(m.nu)]
    ctrl = (plan.q_ref + KV_OVER_KP * plan.qd_ref + plan.tau_ff / robot.kp)[:, act]
    d.qpos[:] = _nominal_qpos(robot)
    d.qpos[:3] = plan.base_pos[0]
    d.qpos[robot.qpos_adr(robot.joint_names)] = plan.q_ref[0]
    d.ctrl[:] = ctrl[0]
    mujoco.mj_forward(m, d)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    n_t = plan.time.size
    out = np.empty((n_t, m.nsensordata))
    state = np.empty(mujoco.mj_stateSize(m, spec))
    warm = np.zeros(m.nv)
    com_min = 0.6 * float(plan.gait.com_height)
    for k0 in range(0, n_t, _CHUNK):
        k1 = min(n_t, k0 + _CHUNK)
        mujoco.mj_getState(m, d, state, spec)
        _, sens = mj_rollout.rollout(m, d, initial_state=state[None],
                                     control=ctrl[None, k0:k1], initial_warmstart=warm[None])
        out[k0:k1] = sens[0]
        warm = d.qacc_warmstart.copy()
        tilt = _tilt_deg(out[k0:k1, index["truth_base_quat"]])
        low = out[k0:k1, index["truth_com_pos"]][:, 2] < com_min
        bad = (tilt > _FALL_TILT_DEG) | low
        if bad.any():
            i = int(np.argmax(bad))
            raise SimulationError(
                f"robot {robot.description.name!r} fell at t = {plan.time[k0 + i]:.3f} s "
                f"(trunk tilt {tilt[i]:.1f} deg, CoM height "
                f"{out[k0 + i, index['truth_com_pos']][2]:.3f} m) with gait "
                f"{plan.gait.to_dict()}; try shorter or slower steps")
        if progress is not None:
            progress(0.3 + 0.65 * k1 / n_t)
    return out, index


def decimate(df: pd.DataFrame, rate: float) -> pd.DataFrame:
    """Every k-th row of a 1 kHz log so it is sampled at ``rate`` [Hz] (1000 / rate must
    be an integer); ``attrs["sample_rate"]`` is updated.

    Raises:
        ConfigError: If ``rate`` does not divide the log's rate.
    """
    src = float(df.attrs.get("sample_rate", SAMPLE_RATE))
    k = src / float(rate)
    if rate <= 0 or abs(k - round(k)) > 1e-9 or round(k) < 1:
        raise ConfigError(
            f"sample rate {rate} Hz must divide the log's {src:g} Hz (e.g. 500, 200, 100)")
    out = df.iloc[:: int(round(k))].reset_index(drop=True)
    out.attrs = dict(df.attrs)
    out.attrs["sample_rate"] = float(rate)
    return out


def simulate_robot(
    robot: LoadedRobot,
    gait: GaitConfig | None = None,
    noise: NoiseConfig | None = None,
    seed: int = 0,
    sample_rate: float = SAMPLE_RATE,
    progress: Callable[[float], Any] | None = None,
) -> pd.DataFrame:
    """Walk ``robot`` in MuJoCo and return its log (module docstring for the columns).

    Args:
        robot: From :func:`grfguard.model.loader.load_model`.
        gait: Default: :func:`scaled_gait` (60 s).
        noise: Default ``NoiseConfig()``; F/T torques get ``force_sigma`` x 1 cm [N m].
        seed: Seed of every noise draw.
        sample_rate: Log rate [Hz] (the physics runs at 1 kHz; rows are decimated).
        progress: Optional ``callable(fraction_done)``.

    Raises:
        SimulationError: If the robot falls.
        ConfigError: If the gait does not fit the robot.
    """
    from grfguard import __version__

    gait = scaled_gait(robot) if gait is None else gait
    if gait.calibration_poses:
        raise ConfigError(
            "gait.calibration_poses is implemented for RobotConfig robots (SURALP, "
            f"grfguard robot show) only, not for the described robot {robot.name!r}; "
            "simulate without it")
    noise = NoiseConfig() if noise is None else noise
    t0 = _time.perf_counter()
    plan = plan_wholebody(robot, gait)
    if progress is not None:
        progress(0.3)
    t1 = _time.perf_counter()
    phys, index = _run(robot, plan, progress)
    t2 = _time.perf_counter()
    df = pd.DataFrame(_columns(robot, plan, phys, index, noise, int(seed)))
    df.attrs.update({
        # "robot" holds a name here: a dict there is read as SURALP-shaped parameters
        "robot": robot.description.name,
        "robot_name": robot.description.name,
        "robot_description": robot.description.to_dict(),
        "sensing": robot.description.sensing,
        "mass": robot.mass,
        "joint_names": list(robot.joint_names),
        "gait": plan.gait.to_dict(),
        "noise": noise.to_dict(),
        "seed": int(seed),
        "sample_rate": SAMPLE_RATE,
        "grfguard_version": __version__,
        "scenario": f"{robot.description.name}-walk-v1",
        "n_steps": int(plan.gait.n_steps),
        "step_times": [float(v) for v in plan.step_times],
        "timing_s": {"plan": t1 - t0, "physics": t2 - t1},
    })
    if sample_rate != SAMPLE_RATE:
        df = decimate(df, sample_rate)
    if progress is not None:
        progress(1.0)
    return df


def _columns(robot, plan, phys, index, noise: NoiseConfig, seed: int) -> dict[str, np.ndarray]:
    def P(name):
        return phys[:, index[name]]

    n_t = plan.time.size
    rng = np.random.default_rng(seed)
    cols: dict[str, np.ndarray] = {"time": np.round(plan.time, 9)}

    def draw(sigma, shape):
        return rng.normal(0.0, sigma, shape) if sigma > 0 else np.zeros(shape)

    acc_bias = draw(noise.acc_bias_sigma, 3)
    gyro_bias = draw(noise.gyro_bias_sigma, 3)
    att_bias = draw(noise.attitude_bias_sigma, 3)
    v = P("truth_imu_linvel")
    a = np.empty_like(v)
    a[:-1] = (v[1:] - v[:-1]) * SAMPLE_RATE
    a[-1] = a[-2]
    a[:, 2] += -robot.model.opt.gravity[2]
    R_WI = quat_to_rotation(P("imu_quat"))
    acc = np.einsum("tji,tj->ti", R_WI, a) + acc_bias + draw(noise.acc_sigma, (n_t, 3))
    gyro = P("imu_gyro") + gyro_bias + draw(noise.gyro_sigma, (n_t, 3))
    quat = P("imu_quat").copy()
    if noise.attitude_sigma > 0 or noise.attitude_bias_sigma > 0:
        rv = att_bias + draw(noise.attitude_sigma, (n_t, 3))
        quat = rotation_to_quat(quat_to_rotation(quat) @ _small_rotation(rv))
    quat = quat * np.where(quat[:, :1] < 0, -1.0, 1.0)
    for i, ax in enumerate("xyz"):
        cols[f"imu_acc_{ax}"] = acc[:, i]
    for i, ax in enumerate("xyz"):
        cols[f"imu_gyro_{ax}"] = gyro[:, i]
    for i, ax in enumerate("wxyz"):
        cols[f"imu_quat_{ax}"] = quat[:, i]
    res = 2 * np.pi / noise.encoder_counts_per_rev if noise.encoder_counts_per_rev else 0.0
    for j in robot.joint_names:
        q = P(f"jointpos_{j}")[:, 0]
        cols[f"q_{j}"] = np.round(q / res) * res if res else q.copy()
    cols["zmp_ref_x"], cols["zmp_ref_y"] = plan.zmp_ref[:, 0].copy(), plan.zmp_ref[:, 1].copy()
    for i, s in enumerate(SIDES):
        cols[f"contact_ref_{s}"] = plan.contact_ref[:, i].astype(np.int64)
    truth: dict[str, np.ndarray] = {}
    if robot.description.sensing == "corners":
        for s in SIDES:
            for k in range(1, 5):
                f = P(f"touch_{s}{k}")[:, 0]
                cols[f"force_{s}{k}"] = f + draw(noise.force_sigma, n_t)
                truth[f"true_force_{s}{k}"] = f.copy()
    else:
        for s in SIDES:
            # MuJoCo gives the force of the parent (leg) on the child (foot); the log
            # has the foot's wrench on the leg (fz > 0 when loaded)
            w = -np.hstack([P(f"force_{s}"), P(f"torque_{s}")])
            for i, ax in enumerate(FT_AXES):
                sigma = noise.force_sigma * (1.0 if i < 3 else 0.01)
                cols[f"ft_{s}_{ax}"] = w[:, i] + draw(sigma, n_t)
                truth[f"true_ft_{s}_{ax}"] = w[:, i].copy()
    cols.update(truth)
    for i, ax in enumerate("xyz"):
        cols[f"true_com_{ax}"] = P("truth_com_pos")[:, i].copy()
    for i, ax in enumerate("xyz"):
        cols[f"true_com_vel_{ax}"] = P("truth_com_vel")[:, i].copy()
    for i, ax in enumerate("xyz"):
        cols[f"true_base_{ax}"] = P("truth_base_pos")[:, i].copy()
    bq = P("truth_base_quat")
    bq = bq * np.where(bq[:, :1] < 0, -1.0, 1.0)
    for i, ax in enumerate("wxyz"):
        cols[f"true_base_quat_{ax}"] = bq[:, i].copy()
    for s in SIDES:
        for i, ax in enumerate("xyz"):
            cols[f"true_sole_{s}_{ax}"] = P(f"truth_sole_{s}_pos")[:, i].copy()
    for s in SIDES:
        fz = P(f"touch_sole_{s}")[:, 0]
        cols[f"true_grf_{s}_z"] = fz.copy()
        cols[f"true_contact_{s}"] = (fz > 0.0).astype(np.int64)
    cols["true_trunk_tilt"] = _tilt_deg(bq)
    return cols
