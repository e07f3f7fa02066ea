"""Sensor-free kinematics for the virtual force sensor: whole-body CoM, body poses, contact points.

Everything here reads only the joint encoders and the IMU attitude (never the force
sensors). The free-floating base is put at the origin with the IMU attitude, so every
position is expressed in a frame ``A`` with world orientation and origin at the trunk
(``p_A* = p_W* - p_WT``). The trunk position in world comes later from leg odometry
(the compiled sensor, :mod:`grfguard.kernels.vfs`, which reads the kinematic tree, the
site and joint indices and the masses from :class:`KinematicModel`; :meth:`KinematicModel.forward`
is the one-sample MuJoCo kinematics, e.g. for the IMU mounting-tilt learner).

Notation: ``p_AC`` CoM in frame A [m]; ``p_AK`` contact points (lowest point of each corner
sphere) in A [m]; ``R_WB`` body rotations (A and W share their orientation).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from grfguard.errors import ConfigError
from grfguard.model.robot import JOINT_NAMES, SIDES, RobotConfig

__all__ = ["KinematicModel", "KinematicFrames"]


@dataclass
class KinematicFrames:
    """Kinematic quantities for ``T`` samples (or one sample without the leading axis).

    Attributes:
        p_AC: (T, 3) whole-body CoM in frame A [m].
        p_AB: (T, nb, 3) body CoMs in A [m].
        R_WB: (T, nb, 3, 3) body inertia-frame rotations.
        p_AK: (T, n_corner, 3) lowest point of each corner sphere in A [m], in the order of
            ``KinematicModel.corner_sites`` (``r1..r4, l1..l4`` for four cells per sole).
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
            q_rad: (n,) joint angles [rad], one per model joint in :data:`JOINT_NAMES`
                order, ``n = len(self.joint_qadr)`` (the joints the model's naming
                contract lists; no count is assumed here).
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
