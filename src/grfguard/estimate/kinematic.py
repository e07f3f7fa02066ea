"""Sensor-free kinematics for the virtual force sensor: whole-body CoM, body poses, contact points.

Everything here reads only the joint encoders and the IMU attitude (never the force
sensors). The free-floating base is put at the origin with the IMU attitude, so every
position is expressed in a frame ``A`` with world orientation and origin at the trunk
(``p_A* = p_W* - p_WT``). The trunk position in world comes later from leg odometry
(:mod:`grfguard.estimate.com`).

Notation: ``p_AC`` CoM in frame A [m]; ``p_AK`` contact points (lowest point of each corner
sphere) in A [m]; ``R_WB`` body rotations (A and W share their orientation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from grfguard.errors import ConfigError
from grfguard.model.robot import JOINT_NAMES, SIDES, RobotConfig
from grfguard.rotations import quat_exp, quat_mul, quat_to_matrix

__all__ = [
    "rotate_frames",
    "AttitudeFilter",
    "KinematicModel", "KinematicFrames", "angular_momentum_about_com", "quat_to_matrix"]


@dataclass
class KinematicFrames:
    """Kinematic quantities for ``T`` samples (or one sample without the leading axis).

    Attributes:
        p_AC: (T, 3) whole-body CoM in frame A [m].
        p_AB: (T, nb, 3) body CoMs in A [m].
        R_WB: (T, nb, 3, 3) body inertia-frame rotations.
        p_AK: (T, 8, 3) lowest point of each corner sphere in A [m], order r1..r4, l1..l4.
        p_AS: (T, 2, 3) sole-centre sites in A [m], right then left.
        R_WS: (T, 2, 3, 3) sole frame rotations.
        p_AI: (T, 3) IMU site in A [m].
    """

    p_AC: np.ndarray
    p_AB: np.ndarray
    R_WB: np.ndarray
    p_AK: np.ndarray
    p_AS: np.ndarray
    R_WS: np.ndarray
    p_AI: np.ndarray


class KinematicModel:
    """MuJoCo kinematics of the robot, driven by encoders and the IMU attitude.

    Args:
        robot: Robot description; the model comes from ``grfguard.model.mjcf.build_model``.
        model: Optional prebuilt ``mujoco.MjModel`` following the naming contract.
    """

    def __init__(self, robot: RobotConfig, model: mujoco.MjModel | None = None) -> None:
        if model is None:
            from grfguard.model.mjcf import build_model

            model = build_model(robot)
        self.robot = robot
        self.model = model
        self.data = mujoco.MjData(model)
        m = model

        def _id(kind: mujoco.mjtObj, name: str) -> int:
            i = mujoco.mj_name2id(m, kind, name)
            if i < 0:
                raise ConfigError(
                    f"robot model has no {kind.name.lower()} named {name!r}; the MJCF must "
                    "follow the grfguard naming contract (grfguard.model.mjcf)"
                )
            return int(i)

        self.trunk_id = _id(mujoco.mjtObj.mjOBJ_BODY, "trunk")
        root = _id(mujoco.mjtObj.mjOBJ_JOINT, "root")
        self.root_qadr = int(m.jnt_qposadr[root])
        self.joint_qadr = np.array(
            [m.jnt_qposadr[_id(mujoco.mjtObj.mjOBJ_JOINT, j)] for j in JOINT_NAMES], dtype=int
        )
        imu = _id(mujoco.mjtObj.mjOBJ_SITE, "imu")
        self.imu_site = imu
        if int(m.site_bodyid[imu]) != self.trunk_id:
            raise ConfigError("the `imu` site must sit on the `trunk` body")
        #: Rotation of the IMU site in the trunk frame.
        self.R_TI = quat_to_matrix(np.array(m.site_quat[imu]))
        q_TI = np.array(m.site_quat[imu], float)
        #: Conjugate of the IMU site quaternion in the trunk: ``q_WT = q_WI (x) q_TI^-1``.
        self._q_IT = np.array([q_TI[0], -q_TI[1], -q_TI[2], -q_TI[3]]) / np.linalg.norm(q_TI)
        self.corner_sites = np.array(
            [_id(mujoco.mjtObj.mjOBJ_SITE, f"{s}{k}") for s in SIDES for k in range(1, 5)],
            dtype=int,
        )
        self.sole_sites = np.array([_id(mujoco.mjtObj.mjOBJ_SITE, f"{s}_sole") for s in SIDES])
        radius = []
        for s in SIDES:
            for k in range(1, 5):
                g = _id(mujoco.mjtObj.mjOBJ_GEOM, f"{s}{k}_contact")
                radius.append(float(m.geom_size[g][0]))
        self.corner_radius = np.array(radius)
        #: Robot bodies (every body below the world body).
        self.body_ids = np.arange(1, m.nbody, dtype=int)
        self.body_mass = np.array(m.body_mass[1:], float)
        self.body_inertia = np.array(m.body_inertia[1:], float)
        self.mass = float(self.body_mass.sum())

    # ------------------------------------------------------------------ one sample
    def forward(self, q_rad: np.ndarray, quat_imu_wxyz: np.ndarray) -> KinematicFrames:
        """Kinematics of one sample.

        Args:
            q_rad: (12,) joint angles in JOINT_NAMES order [rad].
            quat_imu_wxyz: (4,) IMU attitude in world.

        Returns:
            :class:`KinematicFrames` without the time axis.
        """
        m, d = self.model, self.data
        quat_t = np.empty(4)
        mujoco.mju_mulQuat(quat_t, np.asarray(quat_imu_wxyz, float), self._q_IT)
        mujoco.mju_normalize4(quat_t)
        a = self.root_qadr
        d.qpos[a : a + 3] = 0.0
        d.qpos[a + 3 : a + 7] = quat_t
        d.qpos[self.joint_qadr] = q_rad
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        p_AK = np.array(d.site_xpos[self.corner_sites])
        p_AK[:, 2] -= self.corner_radius
        return KinematicFrames(
            p_AC=np.array(d.subtree_com[self.trunk_id]),
            p_AB=np.array(d.xipos[1:]),
            R_WB=np.array(d.ximat[1:]).reshape(-1, 3, 3),
            p_AK=p_AK,
            p_AS=np.array(d.site_xpos[self.sole_sites]),
            R_WS=np.array(d.site_xmat[self.sole_sites]).reshape(-1, 3, 3),
            p_AI=np.array(d.site_xpos[self.imu_site]),
        )

    # ------------------------------------------------------------------ batch
    def forward_batch(self, q_rad: np.ndarray, quat_imu_wxyz: np.ndarray) -> KinematicFrames:
        """Kinematics of ``T`` samples (a loop over :meth:`forward`, 5-10 us per sample).

        Args:
            q_rad: (T, 12) joint angles [rad].
            quat_imu_wxyz: (T, 4) IMU attitudes.
        """
        n = q_rad.shape[0]
        nb = self.body_ids.size
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
            f = self.forward(q_rad[i], quat_imu_wxyz[i])
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
