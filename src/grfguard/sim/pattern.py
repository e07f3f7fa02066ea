"""Walking pattern generation, vectorized over time.

Pipeline: footstep plan -> piecewise-linear ZMP reference -> Kajita preview control on
the cart-table model (CoM trajectory) -> swing-foot trajectories -> closed-form leg IK
-> a few pelvis corrections so the multibody CoM (not the pelvis) follows the planned
CoM -> joint references ``q_ref`` and rates ``qd_ref`` at 1 kHz.

Frames: world W (x forward, y left, z up); feet flat, walking straight along +x, the
pelvis upright. Positions in [m], times in [s], angles in [rad].

Preview control (Kajita et al., ICRA 2003; Katayama's integral form): per horizontal
axis the cart-table state ``x = (c, c', c'')`` with jerk input ``u`` and ZMP output
``p = c - (z_c / g) c''``; with the augmented state ``(sum e, x)`` and
``J = sum_k Q_e e_k^2 + R u_k^2`` the DARE gives
``u_k = -G_i sum_{i<=k} e_i - G_x x_k - sum_{j=1}^{N} G_d(j) p_ref(k + j)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.interpolate import CubicSpline

from grfguard.errors import ConfigError
from grfguard.model.kinematics import body_poses, center_of_mass, leg_ik
from grfguard.model.mjcf import body_layout
from grfguard.model.robot import SIDES, RobotConfig
from grfguard.sim.config import GaitConfig
from grfguard.sim.routine import ROUTINE_START_S, routine_duration, routine_soles, routine_zmp_knots

__all__ = [
    "SAMPLE_RATE",
    "WalkPlan",
    "default_com_height",
    "default_swing_height",
    "resolve_gait",
    "preview_gains",
    "preview_control",
    "plan_walk",
    "multibody_zmp",
    "feedforward_torques",
]

#: Sample rate of the plan, the simulation and the log in [Hz].
SAMPLE_RATE = 1000
_DT = 1.0 / SAMPLE_RATE
#: Hip-to-ankle distance as a fraction of thigh + shank in the nominal posture.
_NOMINAL_LEG_EXTENSION = 0.88


def default_com_height(robot: RobotConfig) -> float:
    """Default planned CoM height [m]: pelvis lowered until hip-ankle = 88 % of the leg.

    The feet stand flat under the hips; the CoM height of that posture (multibody
    model) is returned.
    """
    z_pelvis = robot.sole_to_ankle + _NOMINAL_LEG_EXTENSION * (
        robot.upper_leg_length + robot.lower_leg_length
    )
    p_WB = np.array([[robot.ankle_offset_x, 0.0, z_pelvis]])
    q = _ik_both(robot, p_WB, _feet_under_hips(robot, 1, x=0.0))
    return float(center_of_mass(robot, p_WB, np.eye(3), q)[0, 2])


def default_swing_height(robot: RobotConfig) -> float:
    """Default swing-foot height [m]: 6 % of the hip-to-sole length."""
    return 0.06 * robot.leg_length


def resolve_gait(robot: RobotConfig, gait: GaitConfig) -> GaitConfig:
    """``gait`` with robot-dependent defaults (``com_height``, ``swing_height``) filled in.

    Raises:
        ConfigError: If the step is too long for the legs or the CoM too high.
    """
    import dataclasses

    com_h = gait.com_height if gait.com_height is not None else default_com_height(robot)
    swing_h = gait.swing_height if gait.swing_height is not None else default_swing_height(robot)
    legs = robot.upper_leg_length + robot.lower_leg_length
    if gait.step_length > 0.6 * legs:
        raise ConfigError(
            f"gait.step_length = {gait.step_length} m is too long for legs of "
            f"{legs:.3f} m (thigh + shank); use at most {0.6 * legs:.3f} m"
        )
    if com_h > robot.leg_length + robot.trunk_com_height:
        raise ConfigError(
            f"gait.com_height = {com_h} m is above what straight legs reach "
            f"({robot.leg_length + robot.trunk_com_height:.3f} m); lower it"
        )
    out = dataclasses.replace(gait, com_height=float(com_h), swing_height=float(swing_h))
    if gait.calibration_poses:
        start = round(ROUTINE_START_S + routine_duration() + 0.5, 3)
        if gait.duration < start + gait.stop_time:
            raise ConfigError(
                f"gait.duration = {gait.duration} s is too short for the calibration poses "
                f"(routine until {start:g} s, then stop_time {gait.stop_time:g} s); "
                f"simulate at least {start + gait.stop_time + 10:g} s to walk after it"
            )
        out = dataclasses.replace(out, start_time=max(gait.start_time, start))
    return out


@dataclass(frozen=True)
class WalkPlan:
    """The planned walk sampled at 1 kHz (T samples).

    Attributes:
        gait: The resolved gait (robot defaults filled in).
        time: Sample times in [s], (T,).
        zmp_ref: Reference ZMP in world [m], (T, 2).
        contact_ref: Planned stance of (right, left) foot, 0/1 ints, (T, 2).
        com_ref: Planned CoM in world [m], (T, 3).
        com_vel_ref: Planned CoM velocity in world [m/s], (T, 3).
        sole_pos: Planned sole-centre positions in world [m], (2, T, 3) (right, left).
        pelvis_pos: Pelvis (trunk body) position in world [m], (T, 3); upright.
        q_ref: Joint references [rad], (T, 12), JOINT_NAMES order.
        qd_ref: Joint rate references [rad/s], (T, 12).
        footsteps: Footprint (x, y) of each foot after each step [m], (2, n + 1, 2).
        step_times: Start time of each step in [s], (n,).
        com_model_error: Max |model CoM - planned CoM| after the corrections in [m].
        tau_ff: Feed-forward joint torques [N m], (T, 12), from inverse dynamics of the
            planned motion (:func:`feedforward_torques`); None when disabled.
    """

    gait: GaitConfig
    time: np.ndarray
    zmp_ref: np.ndarray
    contact_ref: np.ndarray
    com_ref: np.ndarray
    com_vel_ref: np.ndarray
    sole_pos: np.ndarray
    pelvis_pos: np.ndarray
    q_ref: np.ndarray
    qd_ref: np.ndarray
    footsteps: np.ndarray
    step_times: np.ndarray
    com_model_error: float
    tau_ff: np.ndarray | None = None


def preview_gains(
    dt: float, com_height: float, gravity: float, horizon: float,
    q_e: float = 1.0, r_u: float = 1e-6,
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Gains of the cart-table preview controller.

    Args:
        dt: Controller period in [s].
        com_height: Cart-table height z_c in [m].
        gravity: g in [m/s^2].
        horizon: Preview horizon in [s].
        q_e: ZMP error weight.
        r_u: Jerk weight.

    Returns:
        ``(G_i, G_x (3,), G_d (N,), A (3, 3), B (3,))``.
    """
    A = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    B = np.array([dt**3 / 6, dt * dt / 2, dt])
    C = np.array([1.0, 0.0, -com_height / gravity])
    At = np.zeros((4, 4))
    At[0, 0] = 1.0
    At[0, 1:] = C @ A
    At[1:, 1:] = A
    Bt = np.concatenate([[C @ B], B])[:, None]
    Qt = np.zeros((4, 4))
    Qt[0, 0] = q_e
    Rm = np.array([[r_u]])
    P = scipy.linalg.solve_discrete_are(At, Bt, Qt, Rm)
    S = float(r_u + (Bt.T @ P @ Bt).item())
    K = (Bt.T @ P @ At / S).ravel()
    g_i, g_x = K[0], K[1:]
    Ac = At - Bt @ K[None, :]
    n = int(round(horizon / dt))
    g_d = np.empty(n)
    X = -Ac.T @ P @ np.array([1.0, 0.0, 0.0, 0.0])
    g_d[0] = -g_i
    for j in range(1, n):
        g_d[j] = float(Bt[:, 0] @ X) / S
        X = Ac.T @ X
    return float(g_i), g_x, g_d, A, B


def preview_control(
    zmp_ref: np.ndarray,
    dt: float,
    com_height: float,
    gravity: float,
    horizon: float,
    start: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """CoM trajectory tracking a ZMP reference with preview control.

    Args:
        zmp_ref: ZMP reference sampled every ``dt``, (K, d) [m] (d axes, e.g. x and y).
            The last value is held beyond the end for the preview.
        dt: Controller period in [s].
        com_height: Cart-table height in [m].
        gravity: g in [m/s^2].
        horizon: Preview horizon in [s].
        start: Initial CoM position (at rest) in [m]; None starts on ``zmp_ref[0]``.

    Returns:
        ``(states, jerk)``: CoM (position, velocity, acceleration) at each sample,
        (K, 3, d), and the jerk input held over each period, (K, d).
    """
    g_i, g_x, g_d, A, B = preview_gains(dt, com_height, gravity, horizon)
    p = np.asarray(zmp_ref, dtype=float)
    k_n, d = p.shape
    n = g_d.size
    pad = np.concatenate([p, np.repeat(p[-1:], n, axis=0)], axis=0)
    # f_k = sum_{j=1..n} G_d(j) p_ref(k + j), for every k at once
    win = np.lib.stride_tricks.sliding_window_view(pad[1:], n, axis=0)  # (K, d, n)
    f = win[:k_n] @ g_d  # (K, d)
    cz = com_height / gravity
    x = np.zeros((3, d))
    x[0] = p[0] if start is None else start
    states = np.empty((k_n, 3, d))
    jerk = np.empty((k_n, d))
    a = A.tolist()
    b = B.tolist()
    gx0, gx1, gx2 = (float(v) for v in g_x)
    a01, a02, a12 = a[0][1], a[0][2], a[1][2]
    b0, b1, b2 = b
    ng = -g_i
    for ax in range(d):
        c0, c1, c2 = float(x[0, ax]), float(x[1, ax]), float(x[2, ax])
        esum = 0.0
        out: list[float] = []  # c0, c1, c2 of each sample (Python floats: no item writes)
        uo: list[float] = []
        put, put_u = out.extend, uo.append
        for pk, fk in zip(p[:, ax].tolist(), f[:, ax].tolist(), strict=True):
            esum += c0 - cz * c2 - pk
            u = ng * esum - gx0 * c0 - gx1 * c1 - gx2 * c2 - fk
            put((c0, c1, c2))
            put_u(u)
            c0, c1, c2 = (
                c0 + a01 * c1 + a02 * c2 + b0 * u,
                c1 + a12 * c2 + b1 * u,
                c2 + b2 * u,
            )
        states[:, :, ax] = np.array(out).reshape(k_n, 3)
        jerk[:, ax] = uo
    return states, jerk


def _feet_under_hips(robot: RobotConfig, n: int, x: float) -> np.ndarray:
    """(2, n, 3) sole positions, flat on the ground under the hips."""
    feet = np.zeros((2, n, 3))
    for i, side in enumerate(SIDES):
        feet[i, :, 0] = x
        feet[i, :, 1] = robot.hip_width / 2 if side == "l" else -robot.hip_width / 2
    return feet


def _ik_both(robot: RobotConfig, p_WB: np.ndarray, sole_pos: np.ndarray,
             sole_rot: np.ndarray | None = None) -> np.ndarray:
    """Joints (T, 12) of both legs for an upright pelvis; soles flat unless ``sole_rot``
    (2, T, 3, 3) gives their orientations."""
    eye = np.eye(3)
    return np.hstack(
        [leg_ik(robot, side, p_WB, eye, sole_pos[i], eye if sole_rot is None else sole_rot[i])
         for i, side in enumerate(SIDES)]
    )


def _smooth(s: np.ndarray) -> np.ndarray:
    """Quintic 0 -> 1 with zero velocity and acceleration at both ends."""
    return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)


def plan_walk(robot: RobotConfig, gait: GaitConfig) -> WalkPlan:
    """Plan a straight walk and its joint references at 1 kHz (vectorized).

    Args:
        robot: The robot description.
        gait: The gait; robot defaults are filled in by :func:`resolve_gait`.

    Returns:
        The :class:`WalkPlan`.

    Raises:
        ConfigError: If the gait does not fit the robot (e.g. unreachable footholds).
    """
    gait = resolve_gait(robot, gait)
    zc = float(gait.com_height)
    n_t = int(round(gait.duration * SAMPLE_RATE))
    t = np.arange(n_t) * _DT
    n = gait.n_steps
    T, ts = gait.step_period, gait.start_time

    footsteps, swing = _footsteps(robot, gait)
    step_times = ts + np.arange(n) * T
    kt_a, kp_a = _zmp_knots(gait, footsteps, swing)
    if gait.calibration_poses:
        kt_a, kp_a = _with_routine_knots(kt_a, kp_a, footsteps)
    zmp = np.column_stack([np.interp(t, kt_a, kp_a[:, 0]), np.interp(t, kt_a, kp_a[:, 1])])

    # ---- feet at the 1 kHz samples and on the preview grid
    dtp = gait.preview_dt
    sub = int(round(dtp / _DT))
    n_p = (n_t + sub - 1) // sub + 1
    tp = np.arange(n_p) * dtp
    sole, contact = _feet(t, footsteps, swing, gait)
    sole_p, _ = _feet(tp, footsteps, swing, gait)
    rot = rot_p = None
    if gait.calibration_poses:
        sole, rot = _posed_soles(robot, t, sole)
        sole_p, rot_p = _posed_soles(robot, tp, sole_p)

    # ---- two-stage preview control on its grid, CoM resampled to 1 kHz
    zmp_p = np.column_stack([np.interp(tp, kt_a, kp_a[:, 0]), np.interp(tp, kt_a, kp_a[:, 1])])
    states, jerk, pelvis_p = _two_stage_preview(robot, gait, tp, zmp_p, sole_p, rot_p)
    com_ref, com_vel_ref = _resample_com(t, dtp, sub, states, jerk, zc)

    # ---- pelvis at 1 kHz: the smooth pelvis-minus-CoM offset of the grid, cubic spline
    eye = np.eye(3)
    offset = CubicSpline(tp, pelvis_p - np.column_stack([states[:, 0], np.full(n_p, zc)]))(t)
    pelvis = com_ref + offset
    q = _ik_both(robot, pelvis, sole, rot)
    check = np.arange(sub // 2, n_t, sub)
    com_err = float(
        np.abs(center_of_mass(robot, pelvis[check], eye, q[check]) - com_ref[check]).max()
    )
    _check_reach(robot, t, pelvis, sole)
    qd = np.gradient(q, _DT, axis=0)
    tau_ff = None
    if gait.torque_feedforward:
        alpha = _right_load_share(zmp, sole, contact)
        tau_ff = feedforward_torques(robot, t, pelvis, q, alpha, stride=sub)
    return WalkPlan(
        gait=gait,
        time=t,
        zmp_ref=zmp,
        contact_ref=contact,
        com_ref=com_ref,
        com_vel_ref=com_vel_ref,
        sole_pos=sole,
        pelvis_pos=pelvis,
        q_ref=q,
        qd_ref=qd,
        footsteps=footsteps,
        step_times=step_times,
        com_model_error=com_err,
        tau_ff=tau_ff,
    )


def _footsteps(robot: RobotConfig, gait: GaitConfig) -> tuple[np.ndarray, np.ndarray]:
    """Footprints ``footsteps[i, j]`` (2, n + 1, 2) [m] = foot i (0 right, 1 left) after
    step j, and the index of the swinging foot of each step (n,)."""
    n, L = gait.n_steps, gait.step_length
    half_w = robot.hip_width / 2
    footsteps = np.zeros((2, n + 1, 2))
    footsteps[0, :, 1] = -half_w
    footsteps[1, :, 1] = half_w
    swing = np.empty(n, dtype=int)  # index of the swinging foot in each step (1-based j)
    first = 0 if gait.first_swing == "r" else 1
    for j in range(1, n + 1):
        sw = first if j % 2 == 1 else 1 - first  # the feet alternate from first_swing
        swing[j - 1] = sw
        footsteps[:, j, 0] = footsteps[:, j - 1, 0]
        footsteps[sw, j, 0] = (j - 1) * L if j == n else j * L
    return footsteps, swing


def _zmp_knots(gait: GaitConfig, footsteps: np.ndarray,
               swing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Knot times [s] and positions (K, 2) [m] of the piecewise-linear ZMP reference."""
    n, T, Tds, ts = gait.n_steps, gait.step_period, gait.double_support_time, gait.start_time
    mid0 = footsteps[:, 0].mean(axis=0)
    kt = [0.0, ts]
    kp = [mid0, mid0]
    for j in range(1, n + 1):
        sup = 1 - swing[j - 1]
        kt += [ts + (j - 1) * T + Tds, ts + j * T]
        kp += [footsteps[sup, j - 1], footsteps[sup, j - 1]]
    t_end = ts + n * T
    mid_end = footsteps[:, n].mean(axis=0)
    kt += [t_end + Tds, gait.duration + gait.preview_horizon + 1.0]
    kp += [mid_end, mid_end]
    return np.asarray(kt), np.asarray(kp)


def _with_routine_knots(kt: np.ndarray, kp: np.ndarray,
                        footsteps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The walk's ZMP knots with the calibration routine's (:mod:`grfguard.sim.routine`)
    in place of the initial stand's first knot pair (ZMP between the feet)."""
    rt, rp = routine_zmp_knots(footsteps[:, 0])
    return np.concatenate([rt, kt[1:]]), np.concatenate([np.asarray(rp), kp[1:]])


def _posed_soles(robot: RobotConfig, t: np.ndarray,
                 sole: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sole positions (2, T, 3) [m] and orientations (2, T, 3, 3) with the calibration
    routine's corner poses (:func:`grfguard.sim.routine.routine_soles`)."""
    dp, rot = routine_soles(t, robot.sensor_positions_in_foot())
    return sole + dp, rot


def _two_stage_preview(
    robot: RobotConfig, gait: GaitConfig, tp: np.ndarray, zmp_p: np.ndarray, sole_p: np.ndarray,
    rot_p: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Preview control on its grid ``tp``: CoM states (N, 3, 2), jerks (N, 2) and the
    pelvis positions (N, 3) [m].

    Stage 1: cart-table model. Stage 2 (Kajita's two-stage scheme, ``gait.zmp_passes``
    times): the multibody ZMP of the planned motion (legs included) is computed, and the
    preview controller run on the ZMP error shifts the CoM plan so the multibody ZMP
    follows the reference.
    """
    g, zc, dtp = robot.gravity, float(gait.com_height), gait.preview_dt
    n_p = len(tp)
    states, jerk = preview_control(zmp_p, dtp, zc, g, gait.preview_horizon)
    pelvis_p = np.column_stack([states[:, 0], np.full(n_p, zc)])
    for pass_i in range(gait.zmp_passes + 1):
        com_p = np.column_stack([states[:, 0], np.full(n_p, zc)])
        pelvis_p, q_p = _pelvis_for_com(robot, com_p, sole_p, gait.com_iterations, pelvis_p,
                                        rot_p)
        if pass_i == gait.zmp_passes:
            break
        err = zmp_p - multibody_zmp(robot, tp, pelvis_p, q_p)
        d_states, d_jerk = preview_control(err, dtp, zc, g, gait.preview_horizon, start=0.0)
        states, jerk = states + d_states, jerk + d_jerk
    return states, jerk, pelvis_p


def _resample_com(t: np.ndarray, dtp: float, sub: int, states: np.ndarray, jerk: np.ndarray,
                  zc: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact (constant-jerk) resampling of the CoM to the samples ``t``: position (T, 3)
    [m] at height ``zc`` and velocity (T, 3) [m/s]."""
    n_t = len(t)
    k = np.arange(n_t) // sub
    tau = (t - k * dtp)[:, None]
    c0, c1, c2, u = states[k, 0], states[k, 1], states[k, 2], jerk[k]
    com_xy = c0 + c1 * tau + c2 * tau**2 / 2 + u * tau**3 / 6
    vel_xy = c1 + c2 * tau + u * tau**2 / 2
    com_ref = np.column_stack([com_xy, np.full(n_t, zc)])
    com_vel_ref = np.column_stack([vel_xy, np.zeros(n_t)])
    return com_ref, com_vel_ref


def _check_reach(robot: RobotConfig, t: np.ndarray, pelvis: np.ndarray,
                 sole: np.ndarray) -> None:
    """Raise :class:`ConfigError` if a foot is out of the legs' reach at some sample."""
    reach = _reach_margin(robot, pelvis, sole)
    if reach < 0.0:
        i_bad = int(np.argmin(_reach_all(robot, pelvis, sole)))
        raise ConfigError(
            f"gait does not fit the robot: at t = {t[i_bad]:.3f} s a foot is out of reach "
            f"by {-reach * 1000:.1f} mm; shorten step_length or lower com_height"
        )


def _feet(
    t: np.ndarray, footsteps: np.ndarray, swing: np.ndarray, gait: GaitConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Sole positions (2, T, 3) [m] and planned contact (T, 2) at times ``t`` [s].

    Step j (1..n) starts at ``start_time + (j - 1) * step_period``; its single-support
    phase ``s`` runs 0 -> 1 after the double support. The swing sole rises with
    ``64 s^3 (1 - s)^3`` (zero velocity and acceleration at lift-off and touchdown) and
    moves forward with a quintic over ``s`` in [0.1, 0.9].
    """
    n = swing.size
    T, Tds, ts = gait.step_period, gait.double_support_time, gait.start_time
    sole = np.zeros((2, t.size, 3))
    contact = np.ones((t.size, 2), dtype=np.int8)
    if n == 0:
        sole[:, :, :2] = footsteps[:, 0][:, None, :]
        return sole, contact
    j_idx = np.clip(np.floor((t - ts) / T).astype(int) + 1, 1, n)
    t_ss0 = ts + (j_idx - 1) * T + Tds
    s = np.clip((t - t_ss0) / (T - Tds), 0.0, 1.0)
    s = np.where(t < ts, 0.0, s)
    s_h = _smooth(np.clip((s - 0.1) / 0.8, 0.0, 1.0))
    bump = 64.0 * s**3 * (1.0 - s) ** 3
    in_ss = (s > 0.0) & (s < 1.0)
    for i in range(2):
        a = footsteps[i, j_idx - 1]
        b = footsteps[i, j_idx]
        sole[i, :, :2] = a + (b - a) * s_h[:, None]
        swinging = swing[j_idx - 1] == i
        sole[i, :, 2] = np.where(swinging, gait.swing_height * bump, 0.0)
        contact[:, i] = np.where(swinging & in_ss, 0, 1)
    return sole, contact


def _pelvis_for_com(
    robot: RobotConfig,
    com: np.ndarray,
    sole: np.ndarray,
    iterations: int,
    pelvis0: np.ndarray,
    sole_rot: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Pelvis positions (T, 3) [m] whose multibody CoM is ``com``, and the joints (T, 12).

    Fixed-point iteration ``pelvis += com - CoM(pelvis)`` starting from ``pelvis0``
    shifted by the CoM error of ``pelvis0``.
    """
    eye = np.eye(3)
    pelvis = pelvis0.copy()
    q = _ik_both(robot, pelvis, sole, sole_rot)
    for _ in range(iterations + 1):
        pelvis = pelvis + (com - center_of_mass(robot, pelvis, eye, q))
        q = _ik_both(robot, pelvis, sole, sole_rot)
    return pelvis, q


def multibody_zmp(
    robot: RobotConfig, t: np.ndarray, p_WB: np.ndarray, q: np.ndarray,
    R_WB: np.ndarray | None = None,
) -> np.ndarray:
    """ZMP on flat ground (z = 0) of a kinematic trajectory of the multibody model [m].

    ``p_x = (sum_i m_i ((z_i'' + g) x_i - x_i'' z_i) - sum_i Ldot_iy) / sum_i m_i (z_i'' + g)``
    and ``p_y`` with ``+ Ldot_ix``, where ``(x_i, y_i, z_i)`` is body i's CoM and
    ``Ldot_i`` the rate of its angular momentum about its CoM; derivatives by central
    differences over ``t``.

    Args:
        robot: The robot description.
        t: Sample times [s], (T,), increasing.
        p_WB: Trunk position in world [m], (T, 3).
        q: Joint angles [rad], (T, 12).
        R_WB: Trunk orientation (T, 3, 3); upright when None.

    Returns:
        (T, 2) ZMP (x, y) in world [m].
    """
    poses = body_poses(robot, p_WB, np.eye(3) if R_WB is None else R_WB, q)
    g = robot.gravity
    num = np.zeros((t.size, 2))
    den = np.zeros(t.size)
    for spec in body_layout(robot):
        p, R = poses[spec.name]
        c = p + R @ np.asarray(spec.com_in_body)
        a = np.gradient(np.gradient(c, t, axis=0), t, axis=0)
        W = np.gradient(R, t, axis=0) @ np.swapaxes(R, 1, 2)
        w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
        inertia = R @ np.diag(spec.inertia_diag) @ np.swapaxes(R, 1, 2)
        L_dot = np.gradient(np.einsum("tij,tj->ti", inertia, w), t, axis=0)
        fz = spec.mass * (a[:, 2] + g)
        den += fz
        num[:, 0] += fz * c[:, 0] - spec.mass * a[:, 0] * c[:, 2] - L_dot[:, 1]
        num[:, 1] += fz * c[:, 1] - spec.mass * a[:, 1] * c[:, 2] + L_dot[:, 0]
    return num / den[:, None]


def _right_load_share(zmp: np.ndarray, sole: np.ndarray, contact: np.ndarray) -> np.ndarray:
    """Planned share of the vertical load on the right foot, (T,) in [0, 1].

    The ZMP reference projected on the segment from the left to the right sole centre;
    1 / 0 when only the right / left foot is planned in contact.
    """
    d = sole[0, :, :2] - sole[1, :, :2]
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.einsum("ta,ta->t", zmp - sole[1, :, :2], d) / np.einsum("ta,ta->t", d, d)
    a = np.clip(np.nan_to_num(a, nan=0.5), 0.0, 1.0)
    a = np.where(contact[:, 1] == 0, 1.0, a)
    return np.where(contact[:, 0] == 0, 0.0, a)


def feedforward_torques(
    robot: RobotConfig,
    t: np.ndarray,
    p_WB: np.ndarray,
    q: np.ndarray,
    right_share: np.ndarray,
    stride: int = 5,
) -> np.ndarray:
    """Joint torques [N m] that realise the planned motion, (T, 12).

    Inverse dynamics of the floating multibody without contacts gives the generalized
    force ``f_inv = M qdd + c`` (``mj_inverse``, armature included). The six free-joint
    rows must come from the ground: a sole wrench ``w_s`` (at the ``{s}_sole`` site,
    world axes) alone would need ``J_s,free^T w_s = f_inv,free``; the load is shared as
    ``a w_r + (1 - a) w_l`` with ``a = right_share``, and the joint torques are
    ``tau = f_inv,joints - J_joints^T (a w_r + (1 - a) w_l)``. Computed every ``stride``
    samples and interpolated with a cubic spline. The pelvis is upright.

    Args:
        robot: The robot description.
        t: Sample times [s], (T,), 1 kHz.
        p_WB: Pelvis position in world [m], (T, 3).
        q: Joint angles [rad], (T, 12).
        right_share: Share of the load on the right foot, (T,).
        stride: Samples between inverse-dynamics evaluations.

    Returns:
        (T, 12) torques in JOINT_NAMES order.
    """
    import mujoco

    from grfguard.model.mjcf import build_mjcf

    model = mujoco.MjModel.from_xml_string(build_mjcf(robot))
    # no contacts; sensors and the (empty) constraint stage skipped: the same qfrc_inverse
    # and Jacobians, some 15 % less per call
    for flag in ("CONTACT", "SENSOR", "CONSTRAINT"):
        model.opt.disableflags |= int(getattr(mujoco.mjtDisableBit, f"mjDSBL_{flag}"))
    data = mujoco.MjData(model)
    dt = float(t[1] - t[0]) if t.size > 1 else _DT
    qd = np.gradient(q, dt, axis=0)
    qdd = np.gradient(qd, dt, axis=0)
    vb = np.gradient(p_WB, dt, axis=0)
    ab = np.gradient(vb, dt, axis=0)
    idx = np.unique(np.append(np.arange(0, t.size, stride), t.size - 1))
    sites = [model.site(f"{s}_sole").id for s in SIDES]
    n_i = idx.size
    f_inv = np.empty((n_i, model.nv))
    jacs = np.zeros((2, n_i, 6, model.nv))
    # the states of every evaluation, built at once (upright pelvis at rest in rotation)
    qpos = np.zeros((n_i, model.nq))
    qvel = np.zeros((n_i, model.nv))
    qacc = np.zeros((n_i, model.nv))
    qpos[:, :3], qpos[:, 3], qpos[:, 7:] = p_WB[idx], 1.0, q[idx]
    qvel[:, :3], qvel[:, 6:] = vb[idx], qd[idx]
    qacc[:, :3], qacc[:, 6:] = ab[idx], qdd[idx]
    d_qpos, d_qvel, d_qacc, d_frc = data.qpos, data.qvel, data.qacc, data.qfrc_inverse
    inverse, jac_site = mujoco.mj_inverse, mujoco.mj_jacSite
    (r_site, l_site), (r_jac, l_jac) = sites, jacs
    for n in range(n_i):
        d_qpos[:] = qpos[n]
        d_qvel[:] = qvel[n]
        d_qacc[:] = qacc[n]
        inverse(model, data)
        f_inv[n] = d_frc
        jr, jl = r_jac[n], l_jac[n]
        jac_site(model, data, jr[:3], jr[3:], r_site)
        jac_site(model, data, jl[:3], jl[3:], l_site)
    share = np.stack([right_share[idx], 1.0 - right_share[idx]])  # (2, n_i)
    ground = np.zeros((n_i, 12))
    for i in range(2):
        # the sole wrench that alone balances the free-joint rows, then its joint torques
        j_free_t = np.swapaxes(jacs[i, :, :, :6], 1, 2)  # (n_i, 6, 6)
        wrench = np.linalg.solve(j_free_t, f_inv[:, :6, None])[..., 0]
        ground += share[i][:, None] * np.einsum("nrj,nr->nj", jacs[i, :, :, 6:], wrench)
    tau = f_inv[:, 6:] - ground
    return CubicSpline(t[idx], tau)(t)


def _reach_all(robot: RobotConfig, pelvis: np.ndarray, sole: np.ndarray) -> np.ndarray:
    legs = robot.upper_leg_length + robot.lower_leg_length
    out = np.full(pelvis.shape[0], np.inf)
    for i, side in enumerate(SIDES):
        y = robot.hip_width / 2 if side == "l" else -robot.hip_width / 2
        hip = pelvis + np.array([0.0, y, 0.0])
        ankle = sole[i] + np.array([robot.ankle_offset_x, 0.0, robot.sole_to_ankle])
        out = np.minimum(out, legs - np.linalg.norm(hip - ankle, axis=1))
    return out


def _reach_margin(robot: RobotConfig, pelvis: np.ndarray, sole: np.ndarray) -> float:
    return float(_reach_all(robot, pelvis, sole).min())
