"""Reference (tests and benchmarks only; formerly the Python stages of
``grfguard.estimate.vfs.VirtualForceSensor(compiled=False)``): the virtual force sensor as
stage methods over ``(T, ...)`` arrays in numpy, the implementation the compiled kernel
(:mod:`grfguard.kernels.vfs`, :mod:`grfguard.kernels.vfs_paper`) is tested against.

Pipeline (DESIGN.md, "Pipeline"):

1. attitude (:class:`AttitudeFilter`): gyro integration pulled toward the logged IMU
   quaternion (its 1 mrad jitter would become fake accelerations);
2. kinematics (:func:`forward_batch` over :class:`grfguard.estimate.kinematic.KinematicModel`):
   whole-body CoM, body poses, corner points relative to the trunk, from the encoders and
   that attitude;
3. leg odometry (:class:`reference.vfs_com.LegOdometry`): trunk position in world,
   anchored on a flat stance foot;
4. momentum (:mod:`reference.vfs_com`): ``multibody``: CoM acceleration = accelerometer
   (above 1 Hz) + odometry (below) + kinematic CoM motion relative to the IMU (15 Hz
   Butterworth), centroidal angular-momentum rate by finite differences (15 Hz), ZMP by
   Newton-Euler (or the pendulum Kalman filter); or the paper's LIPM Kalman filter
   (``paper``, reads the force sensors through the measured ZMP);
5. split (:mod:`reference.vfs_legs`): contact per corner from the kinematic heights, one
   QP over all corners in contact with the total force, the ZMP and a sole-compliance
   prior (``qp``), or the paper's alpha rule and eq. 10-12 (``paper``).

``run`` batches the stages (T = the whole log), ``update`` streams them (T = 1); stateful
stages carry their state between calls. A sample with a non-finite input is skipped (the
state does not move), the last output is held and ``vfs_valid`` is 0.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import LogFormatError
from grfguard.estimate.config import VFSConfig
from grfguard.estimate.kinematic import KinematicFrames, KinematicModel
from grfguard.estimate.vfs import VFS_OUTPUT_COLUMNS, _robot_from_attrs
from grfguard.io.schema import (
    COM_EST_COLUMNS,
    CONTACT_REF,
    FORCE_COLUMNS,
    IMU_ACC,
    IMU_GYRO,
    IMU_QUAT,
    JOINT_COLUMNS,
    TIME,
    ZMP_REF,
    vfs_col,
)
from grfguard.model.robot import SENSOR_NAMES, SIDES, RobotConfig
from grfguard.rotations import quat_to_matrix
from reference.vfs_com import (
    CausalLowPass,
    LegOdometry,
    PaperCoMFilter,
    ZMPKalmanFilter,
    zmp_from_momentum,
)
from reference.vfs_legs import (
    corner_contact,
    paper_alpha,
    paper_cop_literal,
    paper_leg_forces,
    split_paper_feet,
    split_qp,
    split_with_prior,
    world_to_foot_xy,
)

Quat = tuple[float, float, float, float]


def quat_mul(a: Quat | tuple[float, ...], b: Quat | tuple[float, ...]) -> Quat:
    """Hamilton product ``a ⊗ b`` of two scalar quaternions."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_exp(x: float, y: float, z: float) -> Quat:
    """Unit quaternion of the rotation vector ``(x, y, z)`` [rad]."""
    th = math.sqrt(x * x + y * y + z * z)
    if th < 1e-12:
        return (1.0, 0.5 * x, 0.5 * y, 0.5 * z)
    s = math.sin(0.5 * th) / th
    return (math.cos(0.5 * th), s * x, s * y, s * z)


__all__ = ["PythonVFS", "AttitudeFilter", "angular_momentum_about_com", "forward_batch",
           "rotate_frames"]

_MIN_FOOT_FORCE_N = 1.0


def forward_batch(kin: KinematicModel, q_rad: np.ndarray, quat_imu_wxyz: np.ndarray
                  ) -> KinematicFrames:
    """Kinematics of ``T`` samples (a loop over ``kin.forward``, 5-10 us per sample).

    Args:
        q_rad: (T, 12) joint angles [rad].
        quat_imu_wxyz: (T, 4) IMU attitudes.
    """
    n = q_rad.shape[0]
    nb = kin.body_ids.size
    out = KinematicFrames(
        p_AC=np.empty((n, 3)),
        p_AB=np.empty((n, nb, 3)),
        R_WB=np.empty((n, nb, 3, 3)),
        p_AK=np.empty((n, 8, 3)),
        p_AS=np.empty((n, 2, 3)),
        R_WS=np.empty((n, 2, 3, 3)),
        p_AI=np.empty((n, 3)),
    )
    for i in range(n):
        f = kin.forward(q_rad[i], quat_imu_wxyz[i])
        out.p_AC[i] = f.p_AC
        out.p_AB[i] = f.p_AB
        out.R_WB[i] = f.R_WB
        out.p_AK[i] = f.p_AK
        out.p_AS[i] = f.p_AS
        out.R_WS[i] = f.R_WS
        out.p_AI[i] = f.p_AI
    return out


def angular_momentum_about_com(
    p_AB: np.ndarray,
    R_WB: np.ndarray,
    p_AB_prev: np.ndarray,
    R_WB_prev: np.ndarray,
    body_mass_kg: np.ndarray,
    body_inertia: np.ndarray,
    dt_s: float,
) -> np.ndarray:
    """Centroidal angular momentum from two consecutive body poses (backward differences).

    ``L = sum_i m_i (p_i - c) x v_i + R_i I_i R_i^T w_i`` with ``v_i = (p_i - p_i') / dt`` and
    ``w_i = vee(R_i R_i'^T - R_i' R_i^T) / (2 dt)``. A common translation of every body (the
    unknown trunk position) cancels, so positions in frame A suffice.

    Args:
        p_AB: (..., nb, 3) body CoM positions now [m].
        R_WB: (..., nb, 3, 3) body rotations now.
        p_AB_prev: same one sample earlier.
        R_WB_prev: same one sample earlier.
        body_mass_kg: (nb,) masses [kg].
        body_inertia: (nb, 3) principal inertias [kg m^2].
        dt_s: Sampling period [s].

    Returns:
        (..., 3) angular momentum about the CoM in world axes [kg m^2/s].
    """
    m = body_mass_kg[:, None]
    c = (p_AB * m).sum(axis=-2, keepdims=True) / body_mass_kg.sum()
    v = (p_AB - p_AB_prev) / dt_s
    lin = (np.cross(p_AB - c, v) * m).sum(axis=-2)
    dR = R_WB @ np.swapaxes(R_WB_prev, -1, -2)
    w = np.stack(
        [
            dR[..., 2, 1] - dR[..., 1, 2],
            dR[..., 0, 2] - dR[..., 2, 0],
            dR[..., 1, 0] - dR[..., 0, 1],
        ],
        axis=-1,
    ) / (2.0 * dt_s)
    # I_W w = R diag(I) R^T w
    w_B = np.einsum("...ji,...j->...i", R_WB, w)
    rot = np.einsum("...ij,...j->...i", R_WB, w_B * body_inertia).sum(axis=-2)
    return lin + rot


class AttitudeFilter:
    """Complementary attitude filter: gyro integration pulled slowly toward the IMU quaternion.

    The attitude estimator's quaternion in the log carries white jitter (about 1 mrad) that
    finite differences turn into large fake accelerations; the gyro is smooth. Per sample::

        q <- q (x) Exp(w dt)                        (gyro, IMU frame)
        q <- q (x) Exp(k Log(q^-1 (x) q_meas)),     k = dt / (tau + dt)

    so the result follows the gyro above ``1 / (2 pi tau)`` and the logged attitude (and
    its gyro-bias-free drift correction) below.

    Args:
        dt_s: Sampling period [s].
        time_constant_s: ``tau`` [s]; 0 returns the logged quaternion unchanged.
    """

    def __init__(self, dt_s: float, time_constant_s: float) -> None:
        self.dt = dt_s
        self.k = dt_s / (time_constant_s + dt_s) if time_constant_s > 0 else 1.0
        self.q: tuple[float, float, float, float] | None = None

    def reset(self) -> None:
        """Forget the state."""
        self.q = None

    def update(self, quat_meas_wxyz: np.ndarray, gyro_rad_s: np.ndarray | None) -> np.ndarray:
        """One sample: filtered attitude (4,) ``w, x, y, z``."""
        w, x, y, z = (float(v) for v in quat_meas_wxyz)
        nm = math.sqrt(w * w + x * x + y * y + z * z)
        qm = (w / nm, x / nm, y / nm, z / nm)
        if self.q is None or self.k >= 1.0 or gyro_rad_s is None:
            self.q = qm
            return np.array(qm)
        dt = self.dt
        gx, gy, gz = (float(v) * dt for v in gyro_rad_s)
        q = quat_mul(self.q, quat_exp(gx, gy, gz))
        e = quat_mul((q[0], -q[1], -q[2], -q[3]), qm)
        sgn = 2.0 * self.k if e[0] >= 0 else -2.0 * self.k
        q = quat_mul(q, quat_exp(sgn * e[1], sgn * e[2], sgn * e[3]))
        n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        self.q = (q[0] / n, q[1] / n, q[2] / n, q[3] / n)
        return np.array(self.q)


def rotate_frames(fr: KinematicFrames, R: np.ndarray) -> KinematicFrames:
    """Rotate every vector and orientation of ``fr`` by ``R`` ((3, 3) or (T, 3, 3))."""
    R = np.asarray(R, float)
    if R.ndim == 2:

        def vec(x: np.ndarray) -> np.ndarray:
            return x @ R.T

        def rot(x: np.ndarray) -> np.ndarray:
            return R @ x

    else:

        def vec(x: np.ndarray) -> np.ndarray:
            if x.ndim == 2:
                return np.einsum("tij,tj->ti", R, x)
            return np.einsum("tij,tkj->tki", R, x)

        def rot(x: np.ndarray) -> np.ndarray:
            return np.einsum("tij,tkjl->tkil", R, x)

    return KinematicFrames(
        p_AC=vec(fr.p_AC),
        p_AB=vec(fr.p_AB),
        R_WB=rot(fr.R_WB),
        p_AK=vec(fr.p_AK),
        p_AS=vec(fr.p_AS),
        R_WS=rot(fr.R_WS),
        p_AI=vec(fr.p_AI),
    )


def _outputs(
    forces: np.ndarray,
    p_WK_xy: np.ndarray,
    com: np.ndarray,
    contact_feet: np.ndarray,
    zmp: np.ndarray,
) -> dict[str, np.ndarray]:
    """Derived per-foot outputs (vectorized over a leading axis)."""
    out: dict[str, np.ndarray] = {}
    for j, s in enumerate(SENSOR_NAMES):
        out[vfs_col(s)] = forces[..., j]
    for j, c in enumerate(COM_EST_COLUMNS):
        out[c] = com[..., j]
    for i, side in enumerate(SIDES):
        f = forces[..., 4 * i : 4 * i + 4]
        tot = f.sum(axis=-1)
        out[f"vfs_total_{side}"] = tot
        pts = p_WK_xy[..., 4 * i : 4 * i + 4, :]
        ok = tot >= _MIN_FOOT_FORCE_N
        safe = np.where(ok, tot, 1.0)
        for a, ax in enumerate("xy"):
            cop = (f * pts[..., a]).sum(axis=-1) / safe
            out[f"vfs_cop_{side}_{ax}"] = np.where(ok, cop, np.nan)
    out["contact_est_r"] = contact_feet[..., 0].astype(float)
    out["contact_est_l"] = contact_feet[..., 1].astype(float)
    out["zmp_est_x"] = zmp[..., 0]
    out["zmp_est_y"] = zmp[..., 1]
    return out


@dataclass
class _Inputs:
    """The inputs of T samples, (T, k) arrays; optional ones None when absent."""

    q: np.ndarray  # joint angles [rad]
    quat: np.ndarray  # IMU attitude (w, x, y, z)
    gyro: np.ndarray | None  # [rad/s]
    stance: np.ndarray | None  # planned contact (right, left), 0/1
    acc: np.ndarray | None  # IMU specific force [m/s^2]
    forces: np.ndarray | None  # corner force sensors [N] (the paper's CoM filter only)
    zmp_ref: np.ndarray | None  # planned ZMP [m] (the paper's CoM filter only)

    def valid(self) -> np.ndarray:
        """(T,) samples whose inputs are all finite with a non-zero quaternion.

        The planned ZMP is optional (non-finite: not used) and does not count.
        """
        parts = [self.q, self.quat] + [
            p for p in (self.gyro, self.stance, self.acc, self.forces) if p is not None
        ]
        ok = np.all(np.concatenate([np.isfinite(p) for p in parts], axis=1), axis=1)
        return ok & (np.linalg.norm(np.nan_to_num(self.quat), axis=1) >= 1e-6)

    def take(self, idx: np.ndarray) -> _Inputs:
        """The samples ``idx``."""
        vals = (getattr(self, f.name) for f in fields(self))
        return _Inputs(*(None if v is None else v[idx] for v in vals))


def twist_prior(forces: np.ndarray, contact: np.ndarray, kappa: float) -> np.ndarray:
    """(T, 8) prior change [N] putting the contact twist ``f1 - f2 - f3 + f4 = kappa P R
    / S`` (``VFSConfig.contact_twist``) of the split ``forces`` on each sole whose four
    corners are in contact."""
    out = np.zeros_like(forces)
    for o in (0, 4):
        f1, f2, f3, f4 = (forces[:, o + k] for k in range(4))
        S = f1 + f2 + f3 + f4
        ok = np.all(contact[:, o:o + 4], axis=1) & (S > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            q = 0.25 * (kappa * (f1 + f2 - f3 - f4) * (f1 - f2 + f3 - f4) / S)
        q = np.where(ok, q, 0.0)
        out[:, o:o + 4] = q[:, None] * np.array([1.0, -1.0, -1.0, 1.0])
    return out


class PythonVFS:
    """The virtual force sensor's stages in numpy, streaming (``update``) and batch
    (``run``): the reference of :class:`grfguard.estimate.vfs.VirtualForceSensor`.

    Args:
        robot: Robot description.
        config: Settings (default :class:`VFSConfig`).
        kinematics: Optional prebuilt :class:`KinematicModel` (shares the MuJoCo model).
    """

    def __init__(
        self,
        robot: RobotConfig | None = None,
        config: VFSConfig | None = None,
        kinematics: KinematicModel | None = None,
    ) -> None:
        self.robot = robot if robot is not None else RobotConfig()
        self.config = config if config is not None else VFSConfig()
        self.kin = kinematics if kinematics is not None else KinematicModel(self.robot)
        self.mass = self.kin.mass
        self.g = self.robot.gravity
        self.points_F = self.robot.sensor_positions_in_foot()
        #: Corner contact stiffness of the compliance prior [N/m] (0: rigid QP).
        self.contact_stiffness = self.config.contact_stiffness_per_kg * self.mass
        self.reset()

    # ------------------------------------------------------------------ construction
    @classmethod
    def for_log(
        cls, log: pd.DataFrame, config: VFSConfig | None = None, warm: bool = True
    ) -> PythonVFS:
        """A sensor for ``log``: robot from ``log.attrs["robot"]`` (SURALP if absent), the
        sampling period from the ``time`` column (``warm``: as the compiled sensor's
        signature; nothing to build here)."""
        robot = _robot_from_attrs(getattr(log, "attrs", {}) or {})
        cfg = config if config is not None else VFSConfig()
        if TIME in log.columns and len(log) > 1:
            dt = float(np.median(np.diff(log[TIME].to_numpy(float))))
            if np.isfinite(dt) and dt > 0 and abs(dt - cfg.dt) > 1e-9 * cfg.dt:
                cfg = cfg.replace(dt=dt)
        return cls(robot, cfg)

    def reset(self) -> None:
        """Forget all state (odometry anchor, filters, previous samples)."""
        c = self.config
        self._odo = LegOdometry(c.contact_height, c.dt, c.anchor_attitude_time_constant)
        self._att = AttitudeFilter(c.dt, c.attitude_time_constant)
        self._lp = CausalLowPass(c.filter_cutoff, c.dt, c.filter_order, 9, c.filter_damping,
                                 c.filter_lead)
        self._lp_fuse = CausalLowPass(c.fusion_cutoff, c.dt, c.filter_order, 3)
        self._lp_acc = CausalLowPass(c.acc_cutoff, c.dt, c.filter_order, 3)
        self._hist: dict[str, np.ndarray] = {"C": np.zeros((0, 3)), "I": np.zeros((0, 3))}
        self._prev_frames: KinematicFrames | None = None
        self._prev_L: np.ndarray | None = None
        self._paper: PaperCoMFilter | None = None
        self._zkf = ZMPKalmanFilter(c.dt, c.zmp_rate_psd, c.com_acc_psd, c.com_sigma)
        self._p_act_prev: np.ndarray | None = None
        self._last: dict[str, float] | None = None

    # ------------------------------------------------------------------ inputs
    def check_columns(self, cols: Any) -> None:
        """Raise :class:`LogFormatError` if a column this sensor reads is missing."""
        need = [*IMU_QUAT, *JOINT_COLUMNS]
        if self.config.com_method == "paper":
            need += [*IMU_ACC, *FORCE_COLUMNS]
        elif self.config.use_accelerometer:
            need += [*IMU_ACC]
        missing = [c for c in need if c not in cols]
        if missing:
            raise LogFormatError(
                f"the virtual force sensor needs column(s) {missing}; see the log contract "
                "in grfguard.io.schema (com_method='paper' also needs imu_acc_* and force_*)"
            )

    def _inputs(self, src: pd.DataFrame | Mapping[str, float]) -> _Inputs:
        """Parse a log (T rows) or one sample (a mapping, T = 1) into (T, k) arrays.

        Raises:
            KeyError, TypeError, ValueError: A mapping misses a needed key or has a
                non-numeric value (``update`` then holds its last output).
        """
        c = self.config
        frame = isinstance(src, pd.DataFrame)
        has = (lambda cols: all(k in src.columns for k in cols)) if frame else (
            lambda cols: all(k in src for k in cols)
        )

        def take(cols: tuple[str, ...]) -> np.ndarray:
            if frame:
                return src[list(cols)].to_numpy(float)
            return np.array([[float(src[k]) for k in cols]])

        paper = c.com_method == "paper"
        inp = _Inputs(
            q=take(JOINT_COLUMNS),
            quat=take(IMU_QUAT),
            gyro=take(IMU_GYRO) if has(IMU_GYRO) else None,
            stance=take(CONTACT_REF) if has(CONTACT_REF) else None,
            acc=take(IMU_ACC) if paper or c.use_accelerometer else None,
            forces=take(FORCE_COLUMNS) if paper else None,
            zmp_ref=None,
        )
        if paper:
            n = inp.q.shape[0]
            inp.zmp_ref = take(ZMP_REF) if has(ZMP_REF) else np.full((n, 2), np.nan)
        return inp

    def _stance_fallback(self, p_AK: np.ndarray) -> np.ndarray:
        """Planned stance when the log has no contact_ref: feet within 1 cm of the lowest."""
        z = p_AK[..., 2].reshape(p_AK.shape[:-2] + (2, 4)).min(axis=-1)
        return z - z.min(axis=-1, keepdims=True) < 0.01

    # ------------------------------------------------------------------ streaming
    def update(self, row: Mapping[str, float]) -> dict[str, float]:
        """Process one sample: the stages of :meth:`run` with T = 1.

        Args:
            row: Mapping with the log-contract columns of one sample.

        Returns:
            Dict of :data:`VFS_OUTPUT_COLUMNS` (floats). A sample with a missing or
            non-finite input is skipped: the last output is returned with
            ``vfs_valid = 0`` (NaN before the first valid sample).
        """
        try:
            inp = self._inputs(row)
        except (KeyError, TypeError, ValueError):
            return self._hold()
        if not inp.valid()[0]:
            return self._hold()
        out = self._process(inp)
        res = {k: float(v[0]) for k, v in out.items()}
        res["vfs_valid"] = 1.0
        self._last = res
        return dict(res)

    def _hold(self) -> dict[str, float]:
        if self._last is None:
            res = {k: float("nan") for k in VFS_OUTPUT_COLUMNS}
        else:
            res = dict(self._last)
        res["vfs_valid"] = 0.0
        return res

    # ------------------------------------------------------------------ batch
    def run(self, log: pd.DataFrame) -> pd.DataFrame:
        """Reset, then process the whole log (vectorized where it pays).

        Args:
            log: Log-contract DataFrame.

        Returns:
            DataFrame with :data:`VFS_OUTPUT_COLUMNS`, same index as ``log``.
        """
        self.reset()
        self.check_columns(log.columns)
        n = len(log)
        inp = self._inputs(log)
        valid = inp.valid()
        idx = np.flatnonzero(valid)
        result = {k: np.full(n, np.nan) for k in VFS_OUTPUT_COLUMNS}
        result["vfs_valid"] = valid.astype(float)
        if idx.size == 0:
            return pd.DataFrame(result, index=log.index)
        out = self._process(inp.take(idx))
        # skipped samples hold the output of the last valid one
        pos = np.maximum.accumulate(np.where(valid, np.cumsum(valid) - 1, -1))
        has = pos >= 0
        for k, v in out.items():
            col = np.full(n, np.nan)
            col[has] = np.asarray(v, float)[pos[has]]
            result[k] = col
        self._last = {k: float(result[k][idx[-1]]) for k in VFS_OUTPUT_COLUMNS}
        self._last["vfs_valid"] = 1.0
        return pd.DataFrame(result, index=log.index)

    def input_valid(self, log: pd.DataFrame) -> np.ndarray:
        """(T,) bool: rows whose inputs the sensor can use (finite quaternion, joints...)."""
        return self._inputs(log).valid()

    def resync(self) -> None:
        """Forget the finite-difference history only (a continuity break): the next two
        samples have no rate; filters, attitude and odometry keep their state."""
        self._hist = {"C": np.zeros((0, 3)), "I": np.zeros((0, 3))}
        self._prev_frames = None
        self._prev_L = None

    def run_resynced(self, log: pd.DataFrame, resync: np.ndarray) -> pd.DataFrame:
        """:meth:`run` with :meth:`resync` before every row where ``resync`` is True (the
        batch twin of a streaming monitor resyncing at breaks); the sensor is reset after.
        """
        self.reset()
        self.check_columns(log.columns)
        n = len(log)
        inp = self._inputs(log)
        valid = inp.valid()
        result = {k: np.full(n, np.nan) for k in VFS_OUTPUT_COLUMNS}
        result["vfs_valid"] = valid.astype(float)
        starts = sorted({0, *np.flatnonzero(resync).tolist(), n})
        outs: dict[str, list[np.ndarray]] = {}
        for a, b in zip(starts[:-1], starts[1:], strict=True):
            idx = a + np.flatnonzero(valid[a:b])
            if a > 0 and resync[a]:
                self.resync()
            if idx.size:
                for k, val in self._process(inp.take(idx)).items():
                    outs.setdefault(k, []).append(np.asarray(val, float))
        if outs:
            pos = np.maximum.accumulate(np.where(valid, np.cumsum(valid) - 1, -1))
            has = pos >= 0
            for k, parts in outs.items():
                v = np.concatenate(parts)
                col = np.full(n, np.nan)
                col[has] = v[pos[has]]
                result[k] = col
        self.reset()
        return pd.DataFrame(result, index=log.index)

    # ------------------------------------------------------------------ stages
    def _process(self, inp: _Inputs) -> dict[str, np.ndarray]:
        """All stages over T valid samples (T = 1 when streaming): (T,) output columns."""
        quat = self._attitude(inp.quat, inp.gyro)
        fr = forward_batch(self.kin, inp.q, quat)
        st = inp.stance > 0.5 if inp.stance is not None else self._stance_fallback(fr.p_AK)
        fr, p_WT, ground = self._odometry(fr, st)
        com_W = p_WT + fr.p_AC
        p_WK = p_WT[:, None, :] + fr.p_AK
        if self.config.com_method == "multibody":
            com_out = com_W
            force, zmp = self._momentum(fr, p_WT, com_W, ground, quat, inp.acc)
        else:
            com_out, force, zmp = self._paper_momentum(p_WK, com_W, ground, quat, inp)
        forces, feet = self._split(fr, p_WT, p_WK, com_out, ground, force, zmp, st)
        return _outputs(forces, p_WK[:, :, :2], com_out, feet, zmp)

    def _attitude(self, quat: np.ndarray, gyro: np.ndarray | None) -> np.ndarray:
        """Filtered IMU attitude (T, 4) (stateful: one filter step per sample)."""
        out = np.empty_like(quat)
        for i in range(quat.shape[0]):
            out[i] = self._att.update(quat[i], None if gyro is None else gyro[i])
        return out

    def _odometry(
        self, fr: KinematicFrames, st: np.ndarray
    ) -> tuple[KinematicFrames, np.ndarray, np.ndarray]:
        """Leg odometry: frames rotated by the anchor correction, trunk position (T, 3) [m]
        and ground height (T,) [m] (stateful)."""
        m = st.shape[0]
        p_WT, ground, R_corr = np.empty((m, 3)), np.empty(m), np.empty((m, 3, 3))
        for i in range(m):
            R_corr[i], p_WT[i], ground[i], _ = self._odo.update(
                fr.p_AK[i], fr.p_AS[i], fr.R_WS[i], st[i]
            )
        return rotate_frames(fr, R_corr), p_WT, ground

    def _momentum(
        self, fr: KinematicFrames, p_WT: np.ndarray, com_W: np.ndarray, ground: np.ndarray,
        quat: np.ndarray, acc: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Multibody momentum: total ground force (T, 3) [N] and ZMP (T, 2) [m]."""
        raw = self._raw_rates(p_WT + fr.p_AI, fr.p_AC - fr.p_AI, fr)
        acc_W = None
        if self.config.use_accelerometer:
            acc_W = np.einsum("tij,tj->ti", quat_to_matrix(quat), acc)
            acc_W = acc_W - np.array([0.0, 0.0, self.g])
        c_dd, ld = self._filter_rates(raw, acc_W)
        force = self.mass * (c_dd + np.array([0.0, 0.0, self.g]))
        return force, self._zmp(com_W, force, ld, ground)

    def _raw_rates(self, p_WI: np.ndarray, p_IC: np.ndarray, fr: KinematicFrames) -> np.ndarray:
        """Raw (unfiltered) rates (T, 9) = [d2 p_IC, L_dot, d2 p_WI] by finite differences.

        The last two positions, the last frame and the last angular momentum carry over
        between calls, so T samples at once and T calls with one sample give the same
        numbers; the first two samples after a reset have no rate (zero).
        """
        dt, T = self.config.dt, p_WI.shape[0]
        raw = np.zeros((T, 9))
        for off, key, x in ((0, "C", p_IC), (6, "I", p_WI)):
            h = self._hist[key].shape[0]
            xs = np.concatenate([self._hist[key], x])
            v = (xs[1:] - xs[:-1]) / dt
            r0 = max(0, 2 - h)
            raw[r0:, off : off + 3] = ((v[1:] - v[:-1]) / dt)[h + r0 - 2 :]
            self._hist[key] = xs[-2:]
        prev = self._prev_frames
        hf = 0 if prev is None else 1
        pB = fr.p_AB if prev is None else np.concatenate([prev.p_AB[-1:], fr.p_AB])
        RB = fr.R_WB if prev is None else np.concatenate([prev.R_WB[-1:], fr.R_WB])
        L_new = angular_momentum_about_com(
            pB[1:], RB[1:], pB[:-1], RB[:-1], self.kin.body_mass, self.kin.body_inertia, dt
        )
        hl = 0 if self._prev_L is None else 1
        Ls = L_new if self._prev_L is None else np.concatenate([self._prev_L, L_new])
        raw[2 - hl - hf :, 3:6] = (Ls[1:] - Ls[:-1]) / dt
        self._prev_frames = fr
        self._prev_L = Ls[-1:] if Ls.shape[0] else None
        return raw

    def _filter_rates(
        self, raw: np.ndarray, acc_W: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """CoM acceleration (T, 3) and angular momentum rate (T, 3) from raw rates (T, 9)."""
        c = self.config
        main = self._lp.run(raw)
        if acc_W is not None:
            c_dd = self._lp_acc.run(acc_W) + self._lp_fuse.run(raw[:, 6:9] - acc_W)
            c_dd = c_dd + main[:, 0:3]
            if not c.accelerometer_vertical:
                c_dd[:, 2] = main[:, 2] + main[:, 8]
        else:
            c_dd = main[:, 0:3] + main[:, 6:9]
        ld = main[:, 3:6] if c.use_angular_momentum else np.zeros_like(main[:, 3:6])
        return c_dd, ld

    def _zmp(
        self, com_W: np.ndarray, force: np.ndarray, ld: np.ndarray, ground: np.ndarray
    ) -> np.ndarray:
        """ZMP (T, 2) from CoM, total force and angular momentum rate (T, 3) each."""
        if self.config.zmp_filter == "direct":
            return zmp_from_momentum(com_W, force, ld, ground)
        h = np.maximum(com_W[:, 2] - ground, 1e-3)
        fz = np.maximum(force[:, 2], 1.0)
        w2 = fz / (self.mass * h)
        u = np.stack([-ld[:, 1], ld[:, 0]], axis=1) / (self.mass * h)[:, None]
        out = np.empty((com_W.shape[0], 2))
        kf = self._zkf
        for i in range(com_W.shape[0]):
            out[i] = kf.update(com_W[i, :2], float(w2[i]), u[i])[0]
        return out

    def _paper_filter(self, com_z_rel: float) -> PaperCoMFilter:
        c = self.config
        if self._paper is None:
            zc = c.lipm_height if c.lipm_height > 0 else com_z_rel
            self._paper = PaperCoMFilter(
                c.dt, zc, self.g, c.paper_process_noise, c.paper_measurement_noise,
                dob_time_constant_s=c.paper_dob_time_constant,
                dob_gain=c.paper_dob_gain,
            )
        return self._paper

    def _paper_momentum(
        self, p_WK: np.ndarray, com_W: np.ndarray, ground: np.ndarray, quat: np.ndarray,
        inp: _Inputs,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The paper's LIPM filter: CoM (T, 3) [m], ground force (T, 3) [N], ZMP (T, 2) [m]."""
        m = com_W.shape[0]
        com_out, force, zmp = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 2))
        for i in range(m):
            com_out[i], force[i], zmp[i] = self._paper_step(
                p_WK[i], com_W[i], float(ground[i]), quat[i], inp.acc[i], inp.forces[i],
                inp.zmp_ref[i],
            )
        return com_out, force, zmp

    def _paper_step(
        self, p_WK: np.ndarray, com_W: np.ndarray, ground: float, quat: np.ndarray,
        acc: np.ndarray, forces: np.ndarray, zmp_ref: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        kf = self._paper_filter(float(com_W[2] - ground))
        fsum = forces.sum()
        if fsum > _MIN_FOOT_FORCE_N:
            p_act = (forces[:, None] * p_WK[:, :2]).sum(axis=0) / fsum
        elif self._p_act_prev is not None:
            p_act = self._p_act_prev
        else:
            p_act = com_W[:2]
        self._p_act_prev = p_act
        acc_W = quat_to_matrix(quat) @ acc - np.array([0.0, 0.0, self.g])
        ref = zmp_ref if np.all(np.isfinite(zmp_ref)) else None
        c_hat, c_dd = kf.update(p_act, acc_W[:2], ref)
        zc = kf.z_c
        com_out = np.array([c_hat[0], c_hat[1], ground + zc])
        force = self.mass * np.array([c_dd[0], c_dd[1], self.g])
        zmp = c_hat - zc * c_dd / self.g
        return com_out, force, zmp

    def _split(
        self, fr: KinematicFrames, p_WT: np.ndarray, p_WK: np.ndarray, com: np.ndarray,
        ground: np.ndarray, force: np.ndarray, zmp: np.ndarray, st: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Corner forces (T, 8) [N] and feet in contact (T, 2)."""
        c = self.config
        if c.split_method == "paper":
            return self._split_paper(fr.p_AS + p_WT[:, None, :], fr.R_WS, com, force, st), st
        h = p_WK[:, :, 2] - ground[:, None]
        contact = corner_contact(h, st, c.contact_height, c.kinematic_contact)
        if self.contact_stiffness > 0:
            forces = split_with_prior(
                p_WK, contact, zmp, force[:, 2], c.qp_weight, self.contact_stiffness
            )
            if c.contact_twist != 0.0:  # second solve, the twist of the first in the prior
                forces = split_with_prior(
                    p_WK, contact, zmp, force[:, 2], c.qp_weight, self.contact_stiffness,
                    twist_prior(forces, contact, c.contact_twist))
        else:
            forces = split_qp(p_WK[:, :, :2], contact, zmp, force[:, 2], c.qp_weight)
        return forces, contact.reshape(-1, 2, 4).any(axis=2)

    def _split_paper(self, p_WS, R_WS, com, force, st) -> np.ndarray:
        """Paper split for (T, ...) arrays."""
        c = self.config
        mid = p_WS.mean(axis=1)  # (T, 3)
        x_axis = R_WS[:, :, :, 0].mean(axis=1)
        heading = np.arctan2(x_axis[:, 1], x_axis[:, 0])
        y_axis = np.stack([-np.sin(heading), np.cos(heading)], axis=-1)
        cy_rel = ((com[:, :2] - mid[:, :2]) * y_axis).sum(axis=-1)
        if c.paper_cy_max > 0:
            cy_max: np.ndarray | float = c.paper_cy_max
        else:
            cy_max = 0.5 * np.abs(((p_WS[:, 1, :2] - p_WS[:, 0, :2]) * y_axis).sum(axis=-1))
        alpha = paper_alpha(cy_rel, cy_max)
        legs = paper_leg_forces(force, alpha, st)
        f = p_WS - com[:, None, :]
        cop_W = paper_cop_literal(f, legs)
        cop_F = world_to_foot_xy(cop_W, R_WS)
        return split_paper_feet(cop_F, legs[..., 2], self.points_F, c.qp_weight)
