"""The virtual force sensor (VFS): corner forces from IMU, encoders and the robot model.

Pipeline per sample (DESIGN.md, "Pipeline"):

1. attitude (:class:`grfguard.estimate.kinematic.AttitudeFilter`): gyro integration pulled
   toward the logged IMU quaternion (its 1 mrad jitter would become fake accelerations);
2. kinematics (:mod:`grfguard.estimate.kinematic`): whole-body CoM, body poses, corner
   points relative to the trunk, from the encoders and that attitude;
3. leg odometry (:class:`grfguard.estimate.com.LegOdometry`): trunk position in world,
   anchored on a flat stance foot;
4. momentum (:mod:`grfguard.estimate.com`): ``multibody`` (default, sensor-free): CoM
   acceleration = accelerometer (above 1 Hz) + odometry (below) + kinematic CoM motion
   relative to the IMU (15 Hz Butterworth), centroidal angular-momentum rate by finite
   differences (15 Hz), ZMP by Newton-Euler; or the paper's LIPM Kalman filter (``paper``,
   reads the force sensors through the measured ZMP);
5. split (:mod:`grfguard.estimate.legs`, :mod:`grfguard.estimate.compliance`): contact per
   corner from the kinematic heights, one QP over all corners in contact with the total
   force, the ZMP and a sole-compliance prior (``qp``, default), or the paper's alpha rule
   and eq. 10-12 (``paper``).

:class:`VirtualForceSensor` streams (``update``) and batches (``run``); both give the same
numbers. A sample with a non-finite input is skipped (the state does not move), the last
output is held and ``vfs_valid`` is 0.

Outputs: ``vfs_<s>`` for r1..r4, l1..l4 [N], ``com_est_x/y/z`` [m], ``vfs_total_r/l`` [N],
``vfs_cop_r_x/y``, ``vfs_cop_l_x/y`` [m, world; NaN when the foot carries < 1 N],
``contact_est_r/l`` (0/1), ``zmp_est_x/y`` [m], ``vfs_valid`` (0/1).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import LogFormatError
from grfguard.estimate.com import (
    CausalLowPass,
    LegOdometry,
    PaperCoMFilter,
    ZMPKalmanFilter,
    zmp_from_momentum,
)
from grfguard.estimate.compliance import (
    compliance_prior,
    solve_with_prior,
    split_with_prior,
)
from grfguard.estimate.config import VFSConfig
from grfguard.estimate.kinematic import (
    AttitudeFilter,
    KinematicFrames,
    KinematicModel,
    angular_momentum_about_com,
    rotate_frames,
)
from grfguard.estimate.legs import (
    corner_contact,
    paper_alpha,
    paper_cop_literal,
    paper_leg_forces,
    split_paper_feet,
    split_qp,
    world_to_foot_xy,
)
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

__all__ = ["VFSConfig", "VirtualForceSensor", "VFS_OUTPUT_COLUMNS", "with_vfs_columns"]

_CORNER_COLS = tuple(vfs_col(s) for s in SENSOR_NAMES)
#: Every column :meth:`VirtualForceSensor.run` returns, in order.
VFS_OUTPUT_COLUMNS: tuple[str, ...] = (
    *_CORNER_COLS,
    *COM_EST_COLUMNS,
    "vfs_total_r",
    "vfs_total_l",
    "vfs_cop_r_x",
    "vfs_cop_r_y",
    "vfs_cop_l_x",
    "vfs_cop_l_y",
    "contact_est_r",
    "contact_est_l",
    "zmp_est_x",
    "zmp_est_y",
    "vfs_valid",
)
_MIN_FOOT_FORCE_N = 1.0


def _robot_from_attrs(attrs: Mapping[str, Any]) -> RobotConfig:
    r = attrs.get("robot") if attrs else None
    if r is None:
        return RobotConfig()
    if isinstance(r, RobotConfig):
        return r
    if isinstance(r, str):
        import json

        try:
            r = json.loads(r)
        except ValueError as exc:
            raise LogFormatError(
                f"log.attrs['robot'] is not a JSON robot description: {exc}"
            ) from exc
    return RobotConfig.from_dict(dict(r))


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


class VirtualForceSensor:
    """Virtual foot force sensor, streaming (``update``) and batch (``run``).

    Args:
        robot: Robot description.
        config: Settings (default :class:`VFSConfig`).
        kinematics: Optional prebuilt :class:`KinematicModel` (shares the MuJoCo model).

    Example:
        >>> vfs = VirtualForceSensor.for_log(log)
        >>> out = vfs.run(log)          # DataFrame with vfs_r1 ... vfs_l4
        >>> vfs.reset(); row_out = vfs.update(log.iloc[0].to_dict())
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
        cls, log: pd.DataFrame, config: VFSConfig | None = None
    ) -> VirtualForceSensor:
        """A sensor for ``log``: robot from ``log.attrs["robot"]`` (SURALP if absent), the
        sampling period from the ``time`` column."""
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
        self._lp = CausalLowPass(c.filter_cutoff, c.dt, c.filter_order, 9)
        self._lp_fuse = CausalLowPass(c.fusion_cutoff, c.dt, c.filter_order, 3)
        self._lp_acc = CausalLowPass(c.acc_cutoff, c.dt, c.filter_order, 3)
        self._hist_I: list[np.ndarray] = []
        self._hist_C: list[np.ndarray] = []
        self._prev_frames: KinematicFrames | None = None
        self._prev_L: np.ndarray | None = None
        self._paper: PaperCoMFilter | None = None
        self._zkf = ZMPKalmanFilter(c.dt, c.zmp_rate_psd, c.com_acc_psd, c.com_sigma)
        self._p_act_prev: np.ndarray | None = None
        self._last: dict[str, float] | None = None

    # ------------------------------------------------------------------ input helpers
    def _check_columns(self, cols: Any) -> None:
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

    def _stance_fallback(self, p_AK: np.ndarray) -> np.ndarray:
        """Planned stance when the log has no contact_ref: feet within 1 cm of the lowest."""
        z = p_AK[..., 2].reshape(p_AK.shape[:-2] + (2, 4)).min(axis=-1)
        return z - z.min(axis=-1, keepdims=True) < 0.01

    # ------------------------------------------------------------------ streaming
    def update(self, row: Mapping[str, float]) -> dict[str, float]:
        """Process one sample.

        Args:
            row: Mapping with the log-contract columns of one sample.

        Returns:
            Dict of :data:`VFS_OUTPUT_COLUMNS` (floats). A sample with a missing or
            non-finite input is skipped: the last output is returned with
            ``vfs_valid = 0`` (NaN before the first valid sample).
        """
        c = self.config
        try:
            q = np.array([float(row[k]) for k in JOINT_COLUMNS])
            quat = np.array([float(row[k]) for k in IMU_QUAT])
            extra = {}
            if c.com_method == "paper" or c.use_accelerometer:
                extra["acc"] = np.array([float(row[k]) for k in IMU_ACC])
            if c.com_method == "paper":
                extra["forces"] = np.array([float(row[k]) for k in FORCE_COLUMNS])
                zr = [row.get(k, np.nan) for k in ZMP_REF]
                extra["zmp_ref"] = np.array([float(v) for v in zr])
            gyro = (
                np.array([float(row[k]) for k in IMU_GYRO])
                if all(k in row for k in IMU_GYRO)
                else None
            )
            if all(k in row for k in CONTACT_REF):
                stance = np.array([float(row[k]) for k in CONTACT_REF])
            else:
                stance = None
        except (KeyError, TypeError, ValueError):
            return self._hold()
        vals = [q, quat] + [v for k, v in extra.items() if k != "zmp_ref"]
        if stance is not None:
            vals.append(stance)
        if gyro is not None:
            vals.append(gyro)
        if not all(np.all(np.isfinite(v)) for v in vals) or np.linalg.norm(quat) < 1e-6:
            return self._hold()
        quat = self._att.update(quat, gyro)
        fr = self.kin.forward(q, quat)
        st = (stance > 0.5) if stance is not None else self._stance_fallback(fr.p_AK)
        R_corr, p_WT, ground, _ = self._odo.update(fr.p_AK, fr.p_AS, fr.R_WS, st)
        fr = rotate_frames(fr, R_corr)
        com_W = p_WT + fr.p_AC
        p_WK = p_WT[None, :] + fr.p_AK
        if c.com_method == "multibody":
            raw = self._raw_rates(p_WT + fr.p_AI, fr.p_AC - fr.p_AI, fr)
            acc_W = None
            if c.use_accelerometer:
                acc_W = quat_to_matrix(quat) @ extra["acc"] - np.array([0.0, 0.0, self.g])
            c_dd, ld = self._filter_rates(
                raw[None], None if acc_W is None else acc_W[None], stream=True
            )
            force = self.mass * (c_dd[0] + np.array([0.0, 0.0, self.g]))
            zmp = self._zmp(com_W[None], force[None], ld, np.array([ground]))[0]
            com_out = com_W
        else:
            com_out, force, zmp = self._paper_step(
                fr, p_WT, p_WK, com_W, ground, quat, extra["acc"], extra["forces"],
                extra["zmp_ref"],
            )
        forces, contact = self._split_one(fr, p_WT, p_WK, com_out, ground, force, zmp, st)
        out = _outputs(forces, p_WK[:, :2], com_out, contact, zmp)
        res = {k: float(v) for k, v in out.items()}
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

    def _raw_rates(self, p_WI: np.ndarray, p_IC: np.ndarray, fr: KinematicFrames) -> np.ndarray:
        """Raw (unfiltered) rates of one sample: (9,) = [d2 p_IC, L_dot, d2 p_WI]."""
        dt = self.config.dt
        hI, hC = self._hist_I, self._hist_C
        hI.append(p_WI)
        hC.append(p_IC)
        if len(hI) > 3:
            del hI[0], hC[0]
        raw = np.zeros(9)
        if len(hI) == 3:
            for off, h in ((0, hC), (6, hI)):
                v1 = (h[2] - h[1]) / dt
                v0 = (h[1] - h[0]) / dt
                raw[off : off + 3] = (v1 - v0) / dt
        L = None
        if self._prev_frames is not None:
            L = angular_momentum_about_com(
                fr.p_AB[None], fr.R_WB[None], self._prev_frames.p_AB[None],
                self._prev_frames.R_WB[None], self.kin.body_mass, self.kin.body_inertia, dt,
            )[0]
            if self._prev_L is not None:
                raw[3:6] = (L - self._prev_L) / dt
        self._prev_frames, self._prev_L = fr, L
        return raw

    def _filter_rates(
        self, raw: np.ndarray, acc_W: np.ndarray | None, stream: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """CoM acceleration (T, 3) and angular momentum rate (T, 3) from raw rates (T, 9)."""
        c = self.config
        run = (lambda f, x: f.update(x[0])[None]) if stream else (lambda f, x: f.run(x))
        main = run(self._lp, raw)
        if acc_W is not None:
            c_dd = run(self._lp_acc, acc_W) + run(self._lp_fuse, raw[:, 6:9] - acc_W)
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

    def _paper_step(
        self, fr, p_WT, p_WK, com_W, ground, quat, acc, forces, zmp_ref
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

    def _split_one(self, fr, p_WT, p_WK, com, ground, force, zmp, st):
        c = self.config
        if c.split_method == "qp":
            h = p_WK[:, 2] - ground
            contact = corner_contact(h, st, c.contact_height, c.kinematic_contact)
            if self.contact_stiffness > 0:
                fz = float(force[2])
                prior = compliance_prior(p_WK[:, 2], contact, fz, self.contact_stiffness)
                forces = solve_with_prior(p_WK[:, :2] - zmp, prior, fz, c.qp_weight, contact)
            else:
                forces = split_qp(
                    p_WK[None, :, :2], contact[None], zmp[None], force[2:3], c.qp_weight
                )[0]
            feet = contact.reshape(2, 4).any(axis=1)
            return forces, feet
        forces = self._split_paper(
            fr.p_AS[None] + p_WT[None, None, :], fr.R_WS[None], com[None], force[None],
            st[None],
        )[0]
        return forces, np.asarray(st, bool)

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

    # ------------------------------------------------------------------ batch
    def run(self, log: pd.DataFrame) -> pd.DataFrame:
        """Reset, then process the whole log (vectorized where it pays).

        Args:
            log: Log-contract DataFrame.

        Returns:
            DataFrame with :data:`VFS_OUTPUT_COLUMNS`, same index as ``log``.
        """
        self.reset()
        self._check_columns(log.columns)
        c = self.config
        n = len(log)
        q_all = log[list(JOINT_COLUMNS)].to_numpy(float)
        quat_all = log[list(IMU_QUAT)].to_numpy(float)
        has_ref = all(k in log.columns for k in CONTACT_REF)
        parts = [q_all, quat_all]
        has_gyro = all(k in log.columns for k in IMU_GYRO)
        if has_gyro:
            gyro_all = log[list(IMU_GYRO)].to_numpy(float)
            parts.append(gyro_all)
        if has_ref:
            st_all = log[list(CONTACT_REF)].to_numpy(float)
            parts.append(st_all)
        if c.com_method == "multibody" and c.use_accelerometer:
            parts.append(log[list(IMU_ACC)].to_numpy(float))
        if c.com_method == "paper":
            acc_all = log[list(IMU_ACC)].to_numpy(float)
            f_all = log[list(FORCE_COLUMNS)].to_numpy(float)
            parts += [acc_all, f_all]
            if all(k in log.columns for k in ZMP_REF):
                zr_all = log[list(ZMP_REF)].to_numpy(float)
            else:
                zr_all = np.full((n, 2), np.nan)
        valid = np.all(np.concatenate([np.isfinite(p) for p in parts], axis=1), axis=1)
        valid &= np.linalg.norm(np.nan_to_num(quat_all), axis=1) >= 1e-6
        idx = np.flatnonzero(valid)
        m = idx.size
        result = {k: np.full(n, np.nan) for k in VFS_OUTPUT_COLUMNS}
        result["vfs_valid"] = valid.astype(float)
        if m == 0:
            return pd.DataFrame(result, index=log.index)
        quat_f = np.empty((m, 4))
        att = self._att
        for i, j in enumerate(idx):
            quat_f[i] = att.update(quat_all[j], gyro_all[j] if has_gyro else None)
        fr = self.kin.forward_batch(q_all[idx], quat_f)
        if has_ref:
            st = st_all[idx] > 0.5
        else:
            st = self._stance_fallback(fr.p_AK)
        p_WT = np.empty((m, 3))
        ground = np.empty(m)
        R_corr = np.empty((m, 3, 3))
        odo = self._odo
        for i in range(m):
            R_corr[i], p_WT[i], ground[i], _ = odo.update(
                fr.p_AK[i], fr.p_AS[i], fr.R_WS[i], st[i]
            )
        fr = rotate_frames(fr, R_corr)
        com_W = p_WT + fr.p_AC
        p_WK = p_WT[:, None, :] + fr.p_AK
        dt = c.dt
        if c.com_method == "multibody":
            raw = np.zeros((m, 9))
            for off, x in ((0, fr.p_AC - fr.p_AI), (6, p_WT + fr.p_AI)):
                v = np.zeros((m, 3))
                v[1:] = (x[1:] - x[:-1]) / dt
                raw[2:, off : off + 3] = (v[2:] - v[1:-1]) / dt
            L = np.zeros((m, 3))
            if m > 1:
                L[1:] = angular_momentum_about_com(
                    fr.p_AB[1:], fr.R_WB[1:], fr.p_AB[:-1], fr.R_WB[:-1],
                    self.kin.body_mass, self.kin.body_inertia, dt,
                )
            raw[2:, 3:6] = (L[2:] - L[1:-1]) / dt
            acc_W = None
            if c.use_accelerometer:
                acc_all = log[list(IMU_ACC)].to_numpy(float)[idx]
                acc_W = np.einsum("tij,tj->ti", quat_to_matrix(quat_f), acc_all)
                acc_W = acc_W - np.array([0.0, 0.0, self.g])
            c_dd, ld = self._filter_rates(raw, acc_W, stream=False)
            force = self.mass * (c_dd + np.array([0.0, 0.0, self.g]))
            zmp = self._zmp(com_W, force, ld, ground)
            com_out = com_W
        else:
            com_out = np.empty((m, 3))
            force = np.empty((m, 3))
            zmp = np.empty((m, 2))
            quat_v, acc_v, f_v, zr_v = quat_f, acc_all[idx], f_all[idx], zr_all[idx]
            for i in range(m):
                co, fo, zm = self._paper_step(
                    None, p_WT[i], p_WK[i], com_W[i], ground[i], quat_v[i], acc_v[i], f_v[i],
                    zr_v[i],
                )
                com_out[i], force[i], zmp[i] = co, fo, zm
        if c.split_method == "qp":
            h = p_WK[:, :, 2] - ground[:, None]
            contact = corner_contact(h, st, c.contact_height, c.kinematic_contact)
            if self.contact_stiffness > 0:
                forces = split_with_prior(
                    p_WK, contact, zmp, force[:, 2], c.qp_weight, self.contact_stiffness
                )
            else:
                forces = split_qp(p_WK[:, :, :2], contact, zmp, force[:, 2], c.qp_weight)
            feet = contact.reshape(m, 2, 4).any(axis=2)
        else:
            forces = self._split_paper(
                fr.p_AS + p_WT[:, None, :], fr.R_WS, com_out, force, st
            )
            feet = st
        out = _outputs(forces, p_WK[:, :, :2], com_out, feet, zmp)
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


def with_vfs_columns(log: pd.DataFrame, config: VFSConfig | None = None) -> pd.DataFrame:
    """``log`` plus the virtual sensor's output columns (metadata kept).

    A :class:`~grfguard.detect.monitor.Monitor` given such a log reuses the columns
    instead of running the virtual sensor again (handy when several fault scenarios are
    injected into one walk: the default virtual sensor does not read the force sensors).

    Args:
        log: A log of the contract.
        config: Virtual sensor settings (default :class:`VFSConfig`).

    Returns:
        A new DataFrame; existing columns of the same name are replaced.
    """
    out = log.copy()
    out.attrs = dict(log.attrs)
    vfs = VirtualForceSensor.for_log(log, config).run(log)
    for c in vfs.columns:
        out[c] = vfs[c].to_numpy()
    return out
