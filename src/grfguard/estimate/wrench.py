"""Virtual foot wrenches of any described robot from its log: IMU + every joint.

The ground must supply what the whole body's motion and weight need. With the base
at the origin (a free-floating body's dynamics does not depend on where it is), the
base attitude from the IMU, the joints from the encoders, and the base velocity from
the stance foot standing still (``v_B = -R_WB sum_i w_i (omega x p_i + d/dt p_i)``,
``p_i`` the sole of foot ``i`` in base axes, ``w_i`` the planned stance weights),
inverse dynamics gives
the generalized force ``f = M(q) qdd + c(q, qd)`` (``mj_rne``). Its six
free-joint rows are the ground's: a wrench ``w_i`` at sole ``i`` alone would need
``J_i,free^T w_i = f_free``. In single support the stance foot carries all of it; in
double support the load is shared as the centre of pressure of the total wrench lies
between the soles.

At an ankle F/T sensor the reading is not the ground wrench: the foot below the sensor
has weight and inertia. The ground wrench is applied to the foot body
(``xfrc_applied``) and ``mj_rnePostConstraint`` gives the internal wrench between the
foot body and its parent, read at the sensor frame as MuJoCo's force/torque sensors
do; the sign is that of the log (the foot's wrench on the leg, ``fz > 0`` loaded).

Corner load cells get the minimum-norm split of each foot's vertical force and
moments over its four cells (``f = A^+ (F_z, M_x, M_y)``).

The base's linear acceleration blends two sources (complementary, over ``blend``
seconds): the accelerometer (lever arm removed) for the fast part, the stance-foot
odometry for the slow part (the accelerometer's bias and the gravity leaking through an
attitude error are slow; the odometry's error, encoder quantization differentiated
twice, is fast). The attitude is the IMU's, leveled: its slow roll/pitch error is the
mean tilt between it and the stance sole lying flat over ``level_window`` seconds (an
attitude error of 0.1 deg moves the CoM of a 1 m tall robot 2 mm over its foot: 1 % of
the ankle torque of a 20 cm foot).

The base's angular velocity is the gyro's; derivatives and smoothing are Savitzky-Golay
(cubic) over ``window`` seconds, zero lag (offline, batch).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import pandas as pd
from scipy.ndimage import uniform_filter1d
from scipy.signal import savgol_filter

from grfguard.errors import LogFormatError
from grfguard.model.description import FT_AXES, SIDES
from grfguard.model.kinematics import quat_to_rotation, rotation_to_quat
from grfguard.model.loader import LoadedRobot

#: Window of the base angular acceleration as a multiple of ``window``.
ALPHA_FACTOR = 1.0

__all__ = ["WrenchEstimate", "estimate_wrenches", "evaluate_wrenches", "wrench_columns"]


@dataclass(frozen=True)
class WrenchEstimate:
    """Virtual foot wrenches of a log (T samples).

    Attributes:
        time: [s], (T,).
        ground: Ground wrench on each foot at its sole centre, world axes, (2, T, 6):
            force [N], torque [N m] (right, left).
        sensor: The log's force channels estimated: ``ft_<s>_<axis>`` (sensor frame,
            foot on leg) or ``force_<s><k>`` (corner cells, [N]) -> (T,) arrays.
        contact: (T, 2) bool, the feet taken as in stance (planned contact, or the
            lower sole), right then left.
    """

    time: np.ndarray
    ground: np.ndarray
    sensor: dict[str, np.ndarray]
    contact: np.ndarray | None = None


def wrench_columns(est: WrenchEstimate) -> pd.DataFrame:
    """``vfs_<channel>`` columns and per-foot ``vfs_total_<s>`` [N] as a DataFrame."""
    cols = {f"vfs_{k[3:] if k.startswith('ft_') else k[6:]}": v for k, v in est.sensor.items()}
    for i, s in enumerate(SIDES):
        cols[f"vfs_total_{s}"] = est.ground[i, :, 2]
    return pd.DataFrame(cols)


def _deriv(x: np.ndarray, win: int, order: int, dt: float) -> np.ndarray:
    """Savitzky-Golay (cubic) derivative of order ``order`` along axis 0
    (:func:`_derivs` with one order)."""
    return _derivs(x, win, (order,), dt)[0]


def _derivs(x: np.ndarray, win: int, orders: tuple[int, ...], dt: float) -> list[np.ndarray]:
    """Savitzky-Golay (cubic) derivatives of the orders ``orders`` along axis 0, as
    ``savgol_filter(x, win, 3, deriv=o, delta=dt, axis=0, mode="interp")``: a (T, k)
    array in one compiled pass for every order and column
    (:func:`grfguard.kernels.savgol.savgol_many`), the interior from sliding polynomial
    moments for windows of 33 samples and more (within some 10-50 rounding units of
    scipy's direct sum; shorter windows and non-finite inputs: scipy's bits). The edges
    are scipy's polynomial fit of all ``k`` columns at once, whose rounding depends on
    ``k``: keep the column groups (stacking arrays would change the edge samples' last
    bits)."""
    if x.ndim != 2:
        return [savgol_filter(x, win, 3, deriv=o, delta=dt, axis=0, mode="interp")
                for o in orders]
    from grfguard.kernels.savgol import savgol_many

    return savgol_many(x, win, orders, dt, sliding=True)


def _smooth_long(x: np.ndarray, win: int, dt: float) -> np.ndarray:
    """Savitzky-Golay (cubic) smoothing of the (T, k) ``x`` over a long window (the
    blend's, 1001 samples at 1 kHz): the interior by FFT convolution, equal to
    :func:`_deriv`'s direct sum to about 1e-15 of the signal and some ten times cheaper;
    the edges as scipy's (:func:`grfguard.kernels.savgol.savgol_many` with ``fft=True``)."""
    from grfguard.kernels.savgol import savgol_many

    return savgol_many(x, win, (0,), dt, fft=True)[0]


def _win(seconds: float, dt: float, n: int) -> int:
    """Odd Savitzky-Golay window of ``seconds`` (at least 5 samples, at most ``n``)."""
    win = max(5, int(round(seconds / dt)) | 1)
    if win > n:
        win = n if n % 2 else n - 1
    return win


@dataclass(frozen=True)
class _Signals:
    """The log's inputs, smoothed: time, joints and derivatives, IMU attitude and gyro."""

    t: np.ndarray
    dt: float
    win: int
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    R_WI: np.ndarray
    gyro_I: np.ndarray


def _signals(df: pd.DataFrame, robot: LoadedRobot, window: float) -> _Signals:
    """Stage 1: check the joint columns, smooth and differentiate the inputs."""
    missing = [f"q_{j}" for j in robot.joint_names if f"q_{j}" not in df.columns]
    if missing:
        raise LogFormatError(f"log misses joint column(s) {missing} of robot "
                             f"{robot.description.name!r}")
    t = df["time"].to_numpy(float)
    dt = float(np.median(np.diff(t)))
    win = _win(window, dt, t.size)
    q = np.ascontiguousarray(df[[f"q_{j}" for j in robot.joint_names]].to_numpy(float))
    # attitude and rates smoothed over the same window (white attitude noise would
    # otherwise be differentiated twice through the sole positions)
    quat_I = df[["imu_quat_w", "imu_quat_x", "imu_quat_y", "imu_quat_z"]].to_numpy(float)
    quat_I = quat_I * np.where(quat_I[:, :1] < 0, -1.0, 1.0)
    quat_I = _deriv(quat_I, win, 0, dt)
    gyro_I = _deriv(df[["imu_gyro_x", "imu_gyro_y", "imu_gyro_z"]].to_numpy(float), win, 0, dt)
    R_WI = quat_to_rotation(quat_I / np.linalg.norm(quat_I, axis=1, keepdims=True))
    qd, qdd = _derivs(q, win, (1, 2), dt)
    return _Signals(t, dt, win, q, qd, qdd, R_WI, gyro_I)


def _body_frames(robot: LoadedRobot, d: mujoco.MjData, sig: _Signals):
    """Stage 2 (pass 1): base attitude from the IMU, IMU and soles in base axes.

    Returns ``(R_WB, R_BI, p_rel, R_BS, p_imu)``: (T,3,3), (T,3,3), (2,T,3), (2,T,3,3),
    (T,3)."""
    m = robot.model
    n = sig.t.size
    jq = robot.qpos_adr(robot.joint_names)
    imu = m.site("imu").id
    sites = [m.site(f"{s}_sole").id for s in SIDES]
    qpos = m.qpos0.copy()
    qpos[:3] = 0.0
    R_WB = np.empty((n, 3, 3))
    R_BI = np.empty((n, 3, 3))
    p_rel = np.empty((2, n, 3))
    R_BS = np.empty((2, n, 3, 3))
    p_imu = np.empty((n, 3))
    for k in range(n):
        qpos[3:7] = (1.0, 0.0, 0.0, 0.0)
        qpos[jq] = sig.q[k]
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        R_BI[k] = d.site_xmat[imu].reshape(3, 3)  # IMU in base axes (base at identity)
        p_imu[k] = d.site_xpos[imu]
        R_WB[k] = sig.R_WI[k] @ R_BI[k].T
        for i, sid in enumerate(sites):
            p_rel[i, k] = d.site_xpos[sid]  # sole in base axes (encoders only)
            R_BS[i, k] = d.site_xmat[sid].reshape(3, 3)
    return R_WB, R_BI, p_rel, R_BS, p_imu


def _qpos_rows(robot: LoadedRobot, q: np.ndarray, quat: np.ndarray | None) -> np.ndarray:
    """(T, nq) configurations: base at the origin with attitude ``quat`` (identity when
    None), joints ``q``, every other coordinate at ``qpos0``."""
    m = robot.model
    Q = np.empty((q.shape[0], m.nq))
    Q[:] = np.asarray(m.qpos0, float)  # broadcast: no tiled copy
    Q[:, :3] = 0.0
    if quat is None:
        Q[:, 3:7] = (1.0, 0.0, 0.0, 0.0)
    else:
        Q[:, 3:7] = quat
    Q[:, _index(robot.qpos_adr(robot.joint_names))] = q
    return Q


def _index(adr) -> slice | np.ndarray:
    """``adr`` as a slice when it is a contiguous increasing range (a plain copy instead
    of numpy's gather/scatter), else as it is."""
    a = np.asarray(adr, np.int64)
    if a.size and np.array_equal(a, np.arange(a[0], a[0] + a.size)):
        return slice(int(a[0]), int(a[0]) + a.size)
    return a


def _body_frames_compiled(robot: LoadedRobot, rm, sig: _Signals):
    """:func:`_body_frames` by the compiled kinematics: for a tree of hinges
    :func:`grfguard.kernels.rne.hinge_frames_batch` (fixed bodies merged), else
    :func:`grfguard.kernels.rne.frames_batch` (MuJoCo's arithmetic); same outputs to a few
    units in the last place."""
    from grfguard.kernels.rne import frames_batch, hinge_frames_batch, site_paths

    m = robot.model
    n = sig.t.size
    sites = np.array([m.site("imu").id] + [m.site(f"{s}_sole").id for s in SIDES], np.int64)
    pos, mat = np.empty((n, 3, 3)), np.empty((n, 3, 9))
    feet = tuple(m.body(f.body).id for f in robot.description.feet)
    ht = _hinge_tree(robot, tuple(int(s) for s in sites), feet)
    if ht is not None:
        hinge_frames_batch(np.ascontiguousarray(sig.q, float), ht.arrays(), site_paths(ht),
                           pos, mat)
    else:
        frames_batch(_qpos_rows(robot, sig.q, None), rm.tree.arrays(), rm.site_arrays(),
                     sites, pos, mat)
    R_BI = mat[:, 0].reshape(n, 3, 3)
    R_WB = sig.R_WI @ np.swapaxes(R_BI, 1, 2)
    p_rel = np.ascontiguousarray(np.swapaxes(pos[:, 1:], 0, 1))
    R_BS = np.ascontiguousarray(np.swapaxes(mat[:, 1:], 0, 1)).reshape(2, n, 3, 3)
    return R_WB, np.ascontiguousarray(R_BI), p_rel, R_BS, np.ascontiguousarray(pos[:, 0])


def _frames_omega_compiled(robot: LoadedRobot, rm, sig: _Signals):
    """:func:`_body_frames_compiled` for a tree of hinges plus the base angular velocity
    ``omega_B = R_BI gyro`` (T, 3), its numpy products compiled
    (:func:`grfguard.kernels.rne.frames_post_batch`, the same bits); None when the
    robot's tree is not one of hinges."""
    from grfguard.kernels.rne import frames_post_batch, hinge_frames_batch, site_paths

    m = robot.model
    n = sig.t.size
    sites = (m.site("imu").id,) + tuple(m.site(f"{s}_sole").id for s in SIDES)
    feet = tuple(m.body(f.body).id for f in robot.description.feet)
    ht = _hinge_tree(robot, tuple(int(s) for s in sites), feet)
    if ht is None:
        return None
    pos, mat = np.empty((3, n, 3)), np.empty((3, n, 9))  # site-major: no copies after
    hinge_frames_batch(np.ascontiguousarray(sig.q, float), ht.arrays(), site_paths(ht),
                       np.swapaxes(pos, 0, 1), np.swapaxes(mat, 0, 1))
    R_WB, R_BI, omega_B = np.empty((n, 3, 3)), np.empty((n, 3, 3)), np.empty((n, 3))
    frames_post_batch(np.ascontiguousarray(sig.R_WI, float), mat[0],
                      np.ascontiguousarray(sig.gyro_I, float), R_WB, R_BI, omega_B)
    return (R_WB, R_BI, pos[1:], mat[1:].reshape(2, n, 3, 3), pos[0]), omega_B


def _inverse_dynamics_compiled(robot: LoadedRobot, rm, sig: _Signals, R_B: np.ndarray,
                               v_B: np.ndarray, omega_B: np.ndarray, a_B: np.ndarray,
                               alpha_B: np.ndarray, w: np.ndarray
                               ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_inverse_dynamics` by the compiled inverse dynamics: for a tree of hinges
    (Talos, G1) :func:`grfguard.kernels.rne.hinge_wrench_batch` (fixed bodies merged, one
    pass per stage over the moving bodies), else :func:`grfguard.kernels.rne
    .wrench_batch` (MuJoCo's arithmetic, the attitude ``R_B`` (T, 3, 3) as a quaternion);
    same outputs to about 1e-12 relative."""
    from grfguard.kernels.rne import hinge_wrench_batch, new_work, wrench_batch

    m = robot.model
    n = sig.t.size
    ft = robot.description.sensing == "ft"
    feet_b = [m.body(f.body).id for f in robot.description.feet]
    names = [f"{s}_sole" for s in SIDES] + ([f"{s}_ft" for s in SIDES] if ft else [])
    sites = np.array([m.site(nm).id for nm in names], np.int64)
    ground_f = np.zeros((2, n, 6))  # foot-major, as returned
    ft_f = np.zeros((2, n, 6))
    ground, ft_out = np.swapaxes(ground_f, 0, 1), np.swapaxes(ft_f, 0, 1)  # (n, 2, 6) views
    ht = _hinge_tree(robot, tuple(int(s) for s in sites), tuple(feet_b))
    if ht is not None:
        c = np.ascontiguousarray
        base = (c(R_B, float), c(v_B, float), c(omega_B, float), c(a_B, float),
                c(alpha_B, float))
        hinge_wrench_batch(c(sig.q, float), c(sig.qd, float), c(sig.qdd, float), base,
                           c(w, float), c(m.opt.gravity, float), ht.arrays(), ft, ground,
                           ft_out)
        return ground_f, ft_f
    else:
        jv = _index(robot.dof_adr(robot.joint_names))
        qvel = np.zeros((n, m.nv))
        qacc = np.zeros((n, m.nv))
        qvel[:, :3], qvel[:, 3:6], qvel[:, jv] = v_B, omega_B, sig.qd
        qacc[:, :3], qacc[:, 3:6], qacc[:, jv] = a_B, alpha_B, sig.qdd
        wrench_batch(_qpos_rows(robot, sig.q, rotation_to_quat(R_B)), qvel, qacc,
                     np.ascontiguousarray(w, float), rm.tree.arrays(), rm.site_arrays(),
                     rm.dyn_arrays(), sites, new_work(rm, sites.size), rm.root,
                     np.array(feet_b, np.int64), ft, ground, ft_out)
    return ground_f, ft_f


def _hinge_tree(robot: LoadedRobot, sites: tuple[int, ...], feet: tuple[int, ...]):
    """The robot's :class:`grfguard.kernels.rne.HingeTree` for these sites and feet
    (None when its tree is not one of hinges), built once per robot."""
    from grfguard.kernels.rne import HingeTree

    key = (sites, feet)
    cache = vars(robot).setdefault("_hinge_trees", {})  # 3 ms to build for Talos
    if key not in cache:
        cols = {int(a): c for c, a in enumerate(robot.qpos_adr(robot.joint_names))}
        cache[key] = HingeTree.from_mujoco(robot.model, cols, list(sites), list(feet))
    return cache[key]


def _stance_weights(df: pd.DataFrame, R_WB: np.ndarray, p_rel: np.ndarray) -> np.ndarray:
    """Stage 3: (T, 2) planned stance weights (``contact_ref_r/l``, else the lower sole)."""
    if {"contact_ref_r", "contact_ref_l"} <= set(df.columns):
        c = df[["contact_ref_r", "contact_ref_l"]].to_numpy(float)
    else:
        z = np.einsum("tj,itj->it", R_WB[:, 2, :], p_rel)  # sole heights below the base
        c = np.column_stack([z[0] <= z[1], z[1] < z[0]]).astype(float)
    return c / np.maximum(c.sum(axis=1, keepdims=True), 1.0)


def _attitude(attitude: str, R_WB: np.ndarray, R_BS: np.ndarray, w: np.ndarray,
              dt: float, level_window: float) -> np.ndarray:
    """Stage 4: the base attitude (T, 3, 3) the ``attitude`` option asks for."""
    n = w.shape[0]
    if attitude == "stance":
        # roll and pitch from the stance sole lying flat (encoders), yaw from the IMU:
        # an IMU attitude error of 0.1 deg would shift the CoM over a 1 m tall robot's
        # foot by 2 mm, 1 % of the ankle torque of a 20 cm foot
        st = np.argmax(w, axis=1)
        R_S = R_BS[st, np.arange(n)]  # stance sole in base axes
        R_WS = R_WB @ R_S
        yaw = np.arctan2(R_WS[:, 1, 0], R_WS[:, 0, 0])
        Rz = np.zeros((n, 3, 3))
        Rz[:, 0, 0], Rz[:, 0, 1] = np.cos(yaw), -np.sin(yaw)
        Rz[:, 1, 0], Rz[:, 1, 1] = np.sin(yaw), np.cos(yaw)
        Rz[:, 2, 2] = 1.0
        return Rz @ np.swapaxes(R_S, 1, 2)
    if attitude == "leveled":
        # the IMU's attitude with its slow roll/pitch error removed: the mean over
        # ``level_window`` of the tilt between it and the stance sole lying flat (the
        # sole's own rocking alternates from step to step and averages out); compiled
        # with numpy's operations (the same bits as D = R_WB R_S, R_S the stance sole in
        # base axes, tilt = 0.5 (D21 - D12, D02 - D20), then _small_rotations(-tilt) @ R_WB)
        from grfguard.kernels.rne import level_apply_batch, level_tilt_batch

        st = np.argmax(w, axis=1)
        R_WB = np.ascontiguousarray(R_WB, float)
        tilt = np.empty((n, 2))
        level_tilt_batch(R_WB, np.ascontiguousarray(R_BS, float), st, tilt)
        k_lv = max(1, int(round(level_window / dt)))
        tilt = uniform_filter1d(tilt, min(k_lv, n), axis=0, mode="nearest")
        corr = np.column_stack([-tilt, np.zeros(n)])
        out = np.empty((n, 3, 3))
        level_apply_batch(corr, R_WB, out)
        return out
    if attitude != "imu":
        raise ValueError(f"attitude must be 'imu', 'leveled' or 'stance', got {attitude!r}")
    return R_WB


def _base_motion(df: pd.DataFrame, robot: LoadedRobot, sig: _Signals, R_WB: np.ndarray,
                 p_rel: np.ndarray, p_imu: np.ndarray, w: np.ndarray, omega_B: np.ndarray,
                 alpha_B: np.ndarray, blend: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Stage 5: base velocity and acceleration (T, 3) each, world axes [m/s, m/s^2]."""
    from grfguard.kernels.rne import base_motion_batch, lever_removed_batch

    n, win, dt = sig.t.size, sig.win, sig.dt
    c = np.ascontiguousarray
    # stance sole still: v_B = -R (w x p + p'), a_B = -R (w x (w x p) + 2 w x p' + a x p + p'')
    # (base axes; attitude noise is never differentiated); compiled, numpy's operations
    # one array per foot: the edges' polynomial fit (scipy's lstsq over the columns at
    # once) rounds differently with more columns
    der = [_derivs(p_rel[i], win, (1, 2), dt) for i in range(2)]
    PD = np.stack([der[0][0], der[1][0]])
    PDD = np.stack([der[0][1], der[1][1]])
    v_B, a_B = np.empty((n, 3)), np.empty((n, 3))
    R_WB = c(R_WB, float)
    omega_B, alpha_B = c(omega_B, float), c(alpha_B, float)
    base_motion_batch(R_WB, c(p_rel, float), PD, PDD, c(w, float), omega_B, alpha_B, v_B, a_B)
    if blend is not None and {"imu_acc_x", "imu_acc_y", "imu_acc_z"} <= set(df.columns):
        # complementary blend: the accelerometer (lever arm of the IMU removed) with its
        # slow errors (bias, gravity leaking through an attitude error) replaced by the
        # odometry's, whose own error (encoder quantization differentiated twice) is fast
        f_I = df[["imu_acc_x", "imu_acc_y", "imu_acc_z"]].to_numpy(float)
        a_imu = np.einsum("tij,tj->ti", sig.R_WI, f_I)  # (its order depends on the layout)
        a_imu[:, 2] += float(robot.model.opt.gravity[2])
        a_rel = np.empty((n, 3))
        lever_removed_batch(c(a_imu), R_WB, omega_B, alpha_B, c(p_imu, float), a_rel)
        a_acc = _deriv(a_rel, win, 0, dt)
        a_B = a_acc + _smooth_long(a_B - a_acc, _win(blend, dt, n), dt)
    return v_B, a_B


def _cross(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float
           ) -> tuple[float, float, float]:
    """``np.cross`` of two 3-vectors on Python floats (the same three products and
    differences, so the same bits, without numpy's per-call overhead of ~20 us)."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


def _ft_ids(robot: LoadedRobot) -> tuple[list[int], list[int], list[int], list[int]]:
    """Foot bodies, sole sites, F/T sites and the feet's root bodies (model ids)."""
    m = robot.model
    feet_b = [m.body(f.body).id for f in robot.description.feet]
    return (feet_b, [m.site(f"{s}_sole").id for s in SIDES],
            [m.site(f"{s}_ft").id for s in SIDES], [int(m.body_rootid[b]) for b in feet_b])


def _ft_readings(robot: LoadedRobot, d: mujoco.MjData, ground_k: np.ndarray,
                 out_k: np.ndarray, ids: tuple | None = None) -> None:
    """Ankle F/T readings (2, 6) of one sample into ``out_k``: the ground wrench applied
    to each foot body, the internal wrench to its parent read at the sensor frame
    (``ids``: :func:`_ft_ids`, looked up when None)."""
    m = robot.model
    feet_b, sites, ft_sites, roots = ids if ids is not None else _ft_ids(robot)
    xfrc = d.xfrc_applied
    xfrc[:] = 0.0
    for i, b in enumerate(feet_b):
        F = ground_k[i, :3].tolist()
        tau = ground_k[i, 3:].tolist()
        ps = d.site_xpos[sites[i]].tolist()
        pb = d.xipos[b].tolist()
        c = _cross(ps[0] - pb[0], ps[1] - pb[1], ps[2] - pb[2], F[0], F[1], F[2])
        xfrc[b, :3] = F
        xfrc[b, 3:] = (tau[0] + c[0], tau[1] + c[1], tau[2] + c[2])
    mujoco.mj_rnePostConstraint(m, d)
    for i, b in enumerate(feet_b):
        tq = d.cfrc_int[b, :3].tolist()
        fo = d.cfrc_int[b, 3:].tolist()
        p_site = d.site_xpos[ft_sites[i]].tolist()
        sc = d.subtree_com[roots[i]].tolist()
        c = _cross(p_site[0] - sc[0], p_site[1] - sc[1], p_site[2] - sc[2], fo[0], fo[1], fo[2])
        tq_site = np.array([tq[0] - c[0], tq[1] - c[1], tq[2] - c[2]])
        R = d.site_xmat[ft_sites[i]].reshape(3, 3)
        out_k[i, :3] = -(R.T @ np.array(fo))
        out_k[i, 3:] = -(R.T @ tq_site)


def _inverse_dynamics(robot: LoadedRobot, d: mujoco.MjData, sig: _Signals,
                      quat_B: np.ndarray, v_B: np.ndarray, omega_B: np.ndarray,
                      a_B: np.ndarray, alpha_B: np.ndarray,
                      w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stage 6 (pass 2): ground wrench per foot at its sole (2, T, 6) and, for ankle F/T
    sensing, the sensor readings (2, T, 6) (zeros otherwise)."""
    m = robot.model
    n = sig.t.size
    jq = robot.qpos_adr(robot.joint_names)
    jv = robot.dof_adr(robot.joint_names)
    sites = [m.site(f"{s}_sole").id for s in SIDES]
    ft = robot.description.sensing == "ft"
    ground = np.zeros((2, n, 6))
    ft_out = np.zeros((2, n, 6))
    jac = np.zeros((6, m.nv))
    f_rne = np.zeros(m.nv)
    ids = _ft_ids(robot) if ft else None
    try:
        for k in range(n):
            d.qpos[:3] = 0.0
            d.qpos[3:7] = quat_B[k]
            d.qpos[jq] = sig.q[k]
            d.qvel[:3], d.qvel[3:6], d.qvel[jv] = v_B[k], omega_B[k], sig.qd[k]
            d.qacc[:3], d.qacc[3:6], d.qacc[jv] = a_B[k], alpha_B[k], sig.qdd[k]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            mujoco.mj_comVel(m, d)
            mujoco.mj_rne(m, d, 1, f_rne)  # M qdd + c (the free rows have no armature)
            f_free = f_rne[:6].copy()
            alone = np.empty((2, 6))
            for i, sid in enumerate(sites):
                mujoco.mj_jacSite(m, d, jac[:3], jac[3:], sid)
                alone[i] = np.linalg.solve(jac[:, :6].T, f_free)
            share = _share(w[k], alone, d.site_xpos[sites[0]], d.site_xpos[sites[1]])
            for i in range(2):
                ground[i, k] = share[i] * alone[i]
            if ft:
                _ft_readings(robot, d, ground[:, k], ft_out[:, k], ids)
    finally:
        d.xfrc_applied[:] = 0.0
    return ground, ft_out


def estimate_wrenches(df: pd.DataFrame, robot: LoadedRobot, window: float = 0.1,
                      attitude: str = "leveled", blend: float | None = 1.0,
                      level_window: float = 4.0, compiled: bool = True) -> WrenchEstimate:
    """Virtual foot wrenches of ``df`` (module docstring).

    Args:
        df: A log of ``robot`` (any rate from 100 Hz up); needs ``time``, ``imu_quat_*``,
            ``imu_gyro_*``, ``q_<joint>`` of every joint; ``contact_ref_r/l`` when
            present give the stance feet (otherwise the lower sole).
        robot: The loaded robot.
        window: Smoothing window of the derivatives [s].
        attitude: ``stance``: base roll and pitch from the stance sole lying flat, yaw
            from the IMU; ``imu``: the IMU's attitude; ``leveled``: the IMU's with its
            slow roll/pitch error taken out (mean tilt to the flat stance sole over
            ``level_window`` seconds).
        blend: Window [s] of the complementary blend of the base acceleration: the
            accelerometer's above about ``1 / blend`` Hz, the stance-foot odometry's
            below; None uses the odometry alone.
        level_window: Averaging window of the ``leveled`` attitude's tilt [s].
        compiled: True (default): kinematics and inverse dynamics compiled over the whole
            log (:mod:`grfguard.kernels.rne`); False: per-sample MuJoCo calls (the
            reference; same outputs to about 1e-12 relative, some 30-50 times slower).

    Returns:
        The :class:`WrenchEstimate`.

    Raises:
        LogFormatError: A joint column is missing.
    """
    from grfguard.io.logio import without_attrs

    df = without_attrs(df)  # read only: no deep copy of the metadata per column access
    sig = _signals(df, robot, window)
    fo = None
    if compiled:
        from grfguard.kernels.rne import RNEModel

        rm = RNEModel.from_mujoco(robot.model)
        fo = _frames_omega_compiled(robot, rm, sig)
        if fo is not None:
            (R_WB, R_BI, p_rel, R_BS, p_imu), omega_B = fo
        else:
            R_WB, R_BI, p_rel, R_BS, p_imu = _body_frames_compiled(robot, rm, sig)
    else:
        d = mujoco.MjData(robot.model)
        R_WB, R_BI, p_rel, R_BS, p_imu = _body_frames(robot, d, sig)
    if fo is None:  # base angular velocity, base axes
        omega_B = np.einsum("tij,tj->ti", R_BI, sig.gyro_I)
    # the base's angular acceleration is small and slow in walking; differentiating the
    # gyro's white noise needs a longer window than the joints
    alpha_B = _deriv(omega_B, _win(ALPHA_FACTOR * window, sig.dt, sig.t.size), 1, sig.dt)
    w = _stance_weights(df, R_WB, p_rel)
    R_WB = _attitude(attitude, R_WB, R_BS, w, sig.dt, level_window)
    v_B, a_B = _base_motion(df, robot, sig, R_WB, p_rel, p_imu, w, omega_B, alpha_B, blend)
    if compiled:
        ground, ft_out = _inverse_dynamics_compiled(robot, rm, sig, R_WB, v_B, omega_B, a_B,
                                                    alpha_B, w)
    else:
        ground, ft_out = _inverse_dynamics(robot, d, sig, rotation_to_quat(R_WB), v_B,
                                           omega_B, a_B, alpha_B, w)
    sensor: dict[str, np.ndarray] = {}
    if robot.description.sensing == "ft":
        for i, s in enumerate(SIDES):
            for a, ax in enumerate(FT_AXES):
                sensor[f"ft_{s}_{ax}"] = ft_out[i, :, a]
    else:
        for i, s in enumerate(SIDES):
            cells = _corner_split(robot, i, ground[i], R_WB, p_rel[i])
            for kk in range(4):
                sensor[f"force_{s}{kk + 1}"] = cells[:, kk]
    return WrenchEstimate(time=sig.t, ground=ground, sensor=sensor, contact=w > 0)


def _small_rotations(rv: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations of small rotation vectors (T, 3) [rad], first order made
    orthonormal: the polar factor of ``I + [rv]x`` in closed form, ``(I + K) / s + rv
    rv^T / (s (s + 1))`` with ``s = sqrt(1 + |rv|^2)`` (equal to the SVD's ``U V^T`` to
    about 1e-15, some ten times cheaper)."""
    n = rv.shape[0]
    s = np.sqrt(1.0 + np.einsum("ti,ti->t", rv, rv))
    a = 1.0 / s
    b = a / (s + 1.0)
    out = (b[:, None, None] * rv[:, :, None]) * rv[:, None, :]
    for k in range(3):
        out[:, k, k] += a
    k0, k1, k2 = rv[:, 0] * a, rv[:, 1] * a, rv[:, 2] * a
    out[:, 0, 1] -= k2
    out[:, 0, 2] += k1
    out[:, 1, 2] -= k0
    out[:, 1, 0] += k2
    out[:, 2, 0] -= k1
    out[:, 2, 1] += k0
    return out.reshape(n, 3, 3)


def _share(w: np.ndarray, alone: np.ndarray, p_r: np.ndarray, p_l: np.ndarray) -> np.ndarray:
    """Load shares of (right, left): the planned stance if one foot, else the CoP of the
    total wrench projected on the segment between the soles."""
    if w[0] == 0.0 or w[1] == 0.0:
        return w
    F, tau = alone[0, :3], alone[0, 3:]
    if F[2] < 1e-6:
        return w
    # CoP on the sole plane of the total wrench (given at the right sole centre)
    cop = p_r[:2] + np.array([-tau[1], tau[0]]) / F[2]
    dv = p_r[:2] - p_l[:2]
    a = float(np.clip(np.dot(cop - p_l[:2], dv) / np.dot(dv, dv), 0.0, 1.0))
    return np.array([a, 1.0 - a])


def _corner_split(robot: LoadedRobot, i: int, ground: np.ndarray, R_WB: np.ndarray,
                  p_rel: np.ndarray) -> np.ndarray:
    """(T, 4) corner forces [N]: minimum-norm split of (F_z, M_x, M_y) at the sole."""
    foot = robot.description.feet[i]
    xy = foot.corners_in_sole()
    # moments about the sole centre in world axes; the foot is flat in stance, the
    # sole yaw is neglected (straight walking)
    A = np.vstack([np.ones(4), xy[:, 1], -xy[:, 0]])
    pinv = np.linalg.pinv(A)
    rhs = np.column_stack([ground[:, 2], ground[:, 3], ground[:, 4]])
    return rhs @ pinv.T


def evaluate_wrenches(df: pd.DataFrame, est: WrenchEstimate, robot: LoadedRobot,
                      ss_margin_s: float = 0.05, t_start_s: float = 0.5,
                      phase: str = "ss") -> dict[str, float]:
    """Single-support accuracy of ``est`` against the truth of a simulated log.

    Single support (as :func:`grfguard.evaluate.vfs_metrics.support_windows`): one foot
    loaded (true normal force > 1 N), the other not, no contact change within
    ``ss_margin_s``; errors on the stance foot after ``t_start_s``. Returns RMSEs in %:
    ``foot_fz`` of the weight m g; ``corner`` (worst corner) of m g; ``ft_f<xyz>`` of
    m g and ``ft_t<xyz>`` of m g x foot length. ``phase="all"``: every sample after
    ``t_start_s`` on both feet (double support and swing included).
    """
    from grfguard.evaluate.vfs_metrics import _dilate

    t = df["time"].to_numpy(float)
    dt = float(np.median(np.diff(t)))
    loaded = np.column_stack([df[f"true_grf_{s}_z"].to_numpy(float) > 1.0 for s in SIDES])
    change = np.zeros(t.size, dtype=bool)
    change[1:] = np.any(loaded[1:] != loaded[:-1], axis=1)
    near = _dilate(change, int(round(ss_margin_s / dt)))
    ok = ~near & (t >= t_start_s)
    ss = [loaded[:, 0] & ~loaded[:, 1] & ok, loaded[:, 1] & ~loaded[:, 0] & ok]
    if phase == "all":  # every sample after t_start_s, on both feet (swing included)
        ss = [t >= t_start_s, t >= t_start_s]
    elif phase != "ss":
        raise ValueError(f"phase must be 'ss' or 'all', got {phase!r}")
    weight = robot.mass * float(-robot.model.opt.gravity[2])
    foot_len = robot.description.feet[0].length
    out: dict[str, float] = {"n_ss": float(ss[0].sum() + ss[1].sum())}

    def rmse(errs: list[np.ndarray]) -> float:
        e = np.concatenate(errs)
        return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")

    out["foot_fz"] = 100 * rmse([
        est.ground[i, ss[i], 2] - df[f"true_grf_{s}_z"].to_numpy(float)[ss[i]]
        for i, s in enumerate(SIDES)]) / weight
    if robot.description.sensing == "ft":
        for a, ax in enumerate(FT_AXES):
            scale = weight if a < 3 else weight * foot_len
            out[f"ft_{ax}"] = 100 * rmse([
                est.sensor[f"ft_{s}_{ax}"][ss[i]] - df[f"true_ft_{s}_{ax}"].to_numpy(float)[ss[i]]
                for i, s in enumerate(SIDES)]) / scale
    else:
        out["corner"] = np.nanmax([
            100 * rmse([est.sensor[f"force_{s}{k}"][ss[i]]
                        - df[f"true_force_{s}{k}"].to_numpy(float)[ss[i]]]) / weight
            for i, s in enumerate(SIDES) for k in range(1, 5)]).item()
    return out
