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

import contextlib
import hashlib
import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from grfguard.errors import ConfigError
from grfguard.model.robot import JOINT_NAMES, SIDES, RobotConfig

if TYPE_CHECKING:
    import mujoco

    from grfguard.kernels.fk import TreeModel

__all__ = ["KinematicModel", "KinematicFrames"]

#: Bump when what :func:`_summary_of` stores changes (older cache files are then unused).
_CACHE_VERSION = "1"
#: The :class:`KinematicModel` attributes read from the MuJoCo model (and cached).
_KIN_FIELDS = ("trunk_id", "root_qadr", "joint_qadr", "imu_site", "_q_IT", "corner_sites",
               "sole_sites", "corner_radius", "body_ids", "body_mass", "body_inertia")
#: Files kept in the disk cache (about 16 kB each): storing one more removes the least
#: recently used beyond this (a campaign over many robot variants must not grow it
#: without bound).
_CACHE_FILES = 64
#: A temporary file of an interrupted store older than this is removed [s].
_STALE_TMP_S = 600.0
#: In-process memo of the cached summaries (key: the cache key).
_SUMMARIES: dict[str, dict[str, np.ndarray]] = {}


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

    What the compiled kernels read (body, joint and site indices, masses, inertias, the
    kinematic tree: :meth:`tree`) is taken from the MuJoCo model once and cached on disk
    (``__pycache__`` next to this module, keyed by the robot's MJCF, the MuJoCo install
    and this code), so that a batch run (``grfguard run``) need not import MuJoCo; the
    model itself (:attr:`model`, :attr:`data`, :meth:`forward`) is built on first use.

    Args:
        robot: Robot description; the model comes from ``grfguard.model.mjcf.build_model``.
        model: Optional prebuilt ``mujoco.MjModel`` following the naming contract (read
            directly, not cached).

    Raises:
        ConfigError: The model does not follow the naming contract (see
            :mod:`grfguard.model.mjcf`) or has mocap bodies.
    """

    def __init__(self, robot: RobotConfig, model: mujoco.MjModel | None = None) -> None:
        self.robot = robot
        self._model = model
        self._data: Any = None
        summary = _summary_of(model) if model is not None else _cached_summary(robot)
        self._summary = summary
        self.trunk_id = int(summary["trunk_id"])
        self.root_qadr = int(summary["root_qadr"])
        self.joint_qadr = summary["joint_qadr"].copy()
        self.imu_site = int(summary["imu_site"])
        #: Conjugate of the IMU site quaternion in the trunk: ``q_WT = q_WI (x) q_TI^-1``.
        self._q_IT = summary["_q_IT"].copy()
        self.corner_sites = summary["corner_sites"].copy()
        self.sole_sites = summary["sole_sites"].copy()
        self.corner_radius = summary["corner_radius"].copy()
        #: Robot bodies (every body below the world body).
        self.body_ids = summary["body_ids"].copy()
        self.body_mass = summary["body_mass"].copy()
        self.body_inertia = summary["body_inertia"].copy()
        self.mass = float(self.body_mass.sum())

    @property
    def model(self) -> mujoco.MjModel:
        """The compiled ``mujoco.MjModel`` (built on first use; shared: do not mutate)."""
        if self._model is None:
            from grfguard.model.mjcf import build_model

            self._model = build_model(self.robot)
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        """The ``mujoco.MjData`` of :meth:`forward` (made on first use)."""
        if self._data is None:
            import mujoco

            self._data = mujoco.MjData(self.model)
        return self._data

    def tree(self) -> TreeModel:
        """The model's kinematic tree as plain arrays (what
        ``grfguard.kernels.fk.TreeModel.from_mujoco(self.model)`` gives; without
        importing MuJoCo when the summary came from the cache)."""
        from grfguard.kernels.fk import TreeModel

        s = self._summary
        return TreeModel(**{f.name: s["tree_" + f.name] for f in fields(TreeModel)})

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
        import mujoco

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


def _summary_of(m: mujoco.MjModel) -> dict[str, np.ndarray]:
    """What :class:`KinematicModel` and the compiled kernels read from the model ``m``,
    as arrays: the names of :data:`_KIN_FIELDS`, and ``tree_<field>`` of the
    :class:`~grfguard.kernels.fk.TreeModel`.

    Raises:
        ConfigError: The model does not follow the naming contract, the IMU is not on
            the trunk, or the model has mocap bodies.
    """
    import mujoco

    from grfguard.kernels.fk import TreeModel

    def _id(kind: mujoco.mjtObj, name: str) -> int:
        i = mujoco.mj_name2id(m, kind, name)
        if i < 0:
            raise ConfigError(
                f"robot model has no {kind.name.lower()} named {name!r}; the MJCF must "
                "follow the grfguard naming contract (grfguard.model.mjcf)"
            )
        return int(i)

    trunk = _id(mujoco.mjtObj.mjOBJ_BODY, "trunk")
    root = _id(mujoco.mjtObj.mjOBJ_JOINT, "root")
    joint_qadr = np.array(
        [m.jnt_qposadr[_id(mujoco.mjtObj.mjOBJ_JOINT, j)] for j in JOINT_NAMES], dtype=int
    )
    imu = _id(mujoco.mjtObj.mjOBJ_SITE, "imu")
    if int(m.site_bodyid[imu]) != trunk:
        raise ConfigError("the `imu` site must sit on the `trunk` body")
    q_TI = np.array(m.site_quat[imu], float)
    radius = [float(m.geom_size[_id(mujoco.mjtObj.mjOBJ_GEOM, f"{s}{k}_contact")][0])
              for s in SIDES for k in range(1, 5)]
    out = {
        "trunk_id": np.array(trunk),
        "root_qadr": np.array(int(m.jnt_qposadr[root])),
        "joint_qadr": joint_qadr,
        "imu_site": np.array(imu),
        "_q_IT": np.array([q_TI[0], -q_TI[1], -q_TI[2], -q_TI[3]]) / np.linalg.norm(q_TI),
        "corner_sites": np.array(
            [_id(mujoco.mjtObj.mjOBJ_SITE, f"{s}{k}") for s in SIDES for k in range(1, 5)],
            dtype=int,
        ),
        "sole_sites": np.array([_id(mujoco.mjtObj.mjOBJ_SITE, f"{s}_sole") for s in SIDES]),
        "corner_radius": np.array(radius),
        "body_ids": np.arange(1, m.nbody, dtype=int),
        "body_mass": np.array(m.body_mass[1:], float),
        "body_inertia": np.array(m.body_inertia[1:], float),
    }
    tree = TreeModel.from_mujoco(m)
    out.update(("tree_" + f.name, getattr(tree, f.name)) for f in fields(TreeModel))
    return out


def _cached_summary(robot: RobotConfig) -> dict[str, np.ndarray]:
    """:func:`_summary_of` the model of ``robot``: from the disk cache when it is there
    (MuJoCo is then not imported), else from the model, then stored. An unreadable or
    unwritable cache costs only the model's build."""
    from grfguard.model.mjcf import build_mjcf, build_model

    key = _cache_key(build_mjcf(robot))
    if key in _SUMMARIES:
        return _SUMMARIES[key]
    path = Path(__file__).parent / "__pycache__" / f"kintree-{key}.npz"
    summary = _load_summary(path) if key else None
    if summary is None:
        summary = _summary_of(build_model(robot))
        if key:
            _store_summary(path, summary)
    if key:
        _SUMMARIES[key] = summary
    return summary


def _cache_key(xml: str) -> str:
    """Hex key of the cached summary of the model of ``xml``: the MJCF, the MuJoCo install
    (its ``__init__.py``: path, size, time stamp), this module and ``kernels/fk.py``
    (the code that reads the model). "" (no cache) when MuJoCo cannot be found."""
    import importlib.util

    try:
        spec = importlib.util.find_spec("mujoco")
        origin = spec.origin if spec is not None else None
        if origin is None:
            return ""
        st = os.stat(origin)
        here = Path(__file__)
        code = here.read_bytes() + (here.parent.parent / "kernels" / "fk.py").read_bytes()
    except (OSError, ImportError, ValueError):
        return ""
    h = hashlib.sha256()
    for part in (_CACHE_VERSION, origin, str(st.st_size), str(st.st_mtime_ns)):
        h.update(part.encode() + b"\0")
    h.update(code)
    h.update(xml.encode())
    return h.hexdigest()[:32]


def _load_summary(path: Path) -> dict[str, np.ndarray] | None:
    """The summary stored at ``path`` (None when absent, unreadable or incomplete)."""
    from grfguard.kernels.fk import TreeModel

    want = {*_KIN_FIELDS, *("tree_" + f.name for f in fields(TreeModel))}
    try:
        with np.load(path, allow_pickle=False) as z:
            out = {name: z[name] for name in z.files}
    except (OSError, ValueError, KeyError, EOFError):
        return None
    if set(out) != want:
        return None
    with contextlib.suppress(OSError):  # used now: the last to be evicted
        os.utime(path)
    return out


def _store_summary(path: Path, summary: dict[str, np.ndarray]) -> None:
    """Write ``summary`` to ``path`` atomically (nothing when it cannot be written)."""
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(exist_ok=True)
        with open(tmp, "wb") as fh:
            np.savez(fh, **summary)
        os.replace(tmp, path)
    except OSError:
        tmp.unlink(missing_ok=True)
        return
    _evict(path.parent, keep=path)


def _evict(directory: Path, keep: Path, limit: int = _CACHE_FILES) -> list[Path]:
    """Remove the least recently used ``kintree-*.npz`` files of ``directory`` beyond
    ``limit`` (never ``keep``) and temporary files of interrupted stores older than
    :data:`_STALE_TMP_S`; returns the files removed (best effort: a file another process
    removes or uses meanwhile is left to it)."""
    import time

    removed: list[Path] = []
    try:
        entries = []
        for p in directory.glob("kintree-*"):
            st = p.stat()
            entries.append((st.st_mtime_ns, p))
    except OSError:
        return removed
    now = time.time()
    done = [p for t, p in entries if p.name.endswith(".tmp") and now - t / 1e9 > _STALE_TMP_S]
    files = sorted((e for e in entries if e[1].suffix == ".npz" and e[1] != keep),
                   key=lambda e: e[0])
    done += [p for _, p in files[:max(0, len(files) + 1 - limit)]]
    for p in done:
        with contextlib.suppress(OSError):
            p.unlink()
            removed.append(p)
    return removed
