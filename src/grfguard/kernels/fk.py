"""Forward kinematics of any MuJoCo kinematic tree, compiled.

:class:`TreeModel` copies what ``mj_kinematics`` and ``mj_comPos`` need from an
``mujoco.MjModel`` (parents, body offsets and rotations, joint types, axes and anchors,
inertial frames, masses, sites) into plain arrays; :func:`fk_tree` runs the same
arithmetic as MuJoCo (quaternion products, off-centre hinge correction, normalisation,
the backward subtree-CoM pass) in the same order, so the positions agree with MuJoCo to
a few units in the last place (tests: ``tests/test_kernels_fk.py``).

Supported joints: free, ball, hinge, slide (the four MuJoCo joint types). Mocap bodies
are not supported (a robot model has none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grfguard.errors import ConfigError
from grfguard.kernels._jit import njit

__all__ = ["TreeModel", "fk_tree", "fk_sites", "fk_batch", "N_WORK", "FREE", "BALL", "SLIDE",
           "HINGE"]

FREE, BALL, SLIDE, HINGE = 0, 1, 2, 3
_MINVAL = 1e-15
#: Scratch floats :func:`fk_tree` needs.
N_WORK = 27


@dataclass(frozen=True)
class TreeModel:
    """Plain-array copy of a MuJoCo model's kinematic tree (shapes: ``nb`` bodies incl. world,
    ``nj`` joints, ``ns`` sites)."""

    body_parent: np.ndarray  # (nb,) int64
    body_jntadr: np.ndarray  # (nb,) int64
    body_jntnum: np.ndarray  # (nb,) int64
    body_sameframe: np.ndarray  # (nb,) int64
    body_pos: np.ndarray  # (nb, 3)
    body_quat: np.ndarray  # (nb, 4)
    body_ipos: np.ndarray  # (nb, 3)
    body_iquat: np.ndarray  # (nb, 4)
    body_mass: np.ndarray  # (nb,)
    jnt_type: np.ndarray  # (nj,) int64
    jnt_qposadr: np.ndarray  # (nj,) int64
    jnt_axis: np.ndarray  # (nj, 3)
    jnt_pos: np.ndarray  # (nj, 3)
    qpos0: np.ndarray  # (nq,)
    site_body: np.ndarray  # (ns,) int64
    site_sameframe: np.ndarray  # (ns,) int64
    site_pos: np.ndarray  # (ns, 3)
    site_quat: np.ndarray  # (ns, 4)

    @classmethod
    def from_mujoco(cls, model) -> TreeModel:
        """Copy the tree of a ``mujoco.MjModel``.

        Raises:
            ConfigError: The model has mocap bodies (not a robot tree).
        """
        m = model
        if int(m.nmocap) > 0:
            raise ConfigError(
                "the compiled kinematics do not support mocap bodies; remove them from the "
                "robot model or use grfguard.estimate.kinematic.KinematicModel"
            )

        def i64(x):
            return np.ascontiguousarray(np.asarray(x), dtype=np.int64).reshape(-1)

        def f64(x, k):
            return np.ascontiguousarray(np.asarray(x, dtype=np.float64)).reshape(-1, k)

        return cls(
            body_parent=i64(m.body_parentid),
            body_jntadr=i64(m.body_jntadr),
            body_jntnum=i64(m.body_jntnum),
            body_sameframe=i64(m.body_sameframe),
            body_pos=f64(m.body_pos, 3),
            body_quat=f64(m.body_quat, 4),
            body_ipos=f64(m.body_ipos, 3),
            body_iquat=f64(m.body_iquat, 4),
            body_mass=np.ascontiguousarray(np.asarray(m.body_mass, dtype=np.float64)),
            jnt_type=i64(m.jnt_type),
            jnt_qposadr=i64(m.jnt_qposadr),
            jnt_axis=f64(m.jnt_axis, 3),
            jnt_pos=f64(m.jnt_pos, 3),
            qpos0=np.ascontiguousarray(np.asarray(m.qpos0, dtype=np.float64)),
            site_body=i64(m.site_bodyid),
            site_sameframe=i64(m.site_sameframe),
            site_pos=f64(m.site_pos, 3),
            site_quat=f64(m.site_quat, 4),
        )

    @property
    def nbody(self) -> int:
        return int(self.body_parent.shape[0])

    @property
    def nq(self) -> int:
        return int(self.qpos0.shape[0])

    def arrays(self) -> tuple:
        """The arrays in the argument order of :func:`fk_tree`."""
        return (
            self.body_parent, self.body_jntadr, self.body_jntnum, self.body_sameframe,
            self.body_pos, self.body_quat, self.body_ipos, self.body_iquat, self.body_mass,
            self.jnt_type, self.jnt_qposadr, self.jnt_axis, self.jnt_pos, self.qpos0,
        )

    def new_frames(self) -> tuple[np.ndarray, ...]:
        """Output arrays ``(xpos, xquat, xmat, xipos, ximat, subtree_com)`` for one sample."""
        nb = self.nbody
        return (
            np.zeros((nb, 3)), np.zeros((nb, 4)), np.zeros((nb, 9)),
            np.zeros((nb, 3)), np.zeros((nb, 9)), np.zeros((nb, 3)),
        )


# ----------------------------------------------------------------------------- MuJoCo maths
@njit(inline="always")
def _normalize4(v):
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + v[3] * v[3])
    if n < _MINVAL:
        v[0] = 1.0
        v[1] = 0.0
        v[2] = 0.0
        v[3] = 0.0
    elif abs(n - 1.0) > _MINVAL:
        inv = 1.0 / n
        v[0] *= inv
        v[1] *= inv
        v[2] *= inv
        v[3] *= inv
    return n


@njit(inline="always")
def _mulquat(res, qa, qb):
    t0 = qa[0] * qb[0] - qa[1] * qb[1] - qa[2] * qb[2] - qa[3] * qb[3]
    t1 = qa[0] * qb[1] + qa[1] * qb[0] + qa[2] * qb[3] - qa[3] * qb[2]
    t2 = qa[0] * qb[2] - qa[1] * qb[3] + qa[2] * qb[0] + qa[3] * qb[1]
    t3 = qa[0] * qb[3] + qa[1] * qb[2] - qa[2] * qb[1] + qa[3] * qb[0]
    res[0] = t0
    res[1] = t1
    res[2] = t2
    res[3] = t3


@njit(inline="always")
def _rotvecquat(res, vec, quat):
    if vec[0] == 0 and vec[1] == 0 and vec[2] == 0:
        res[0] = 0.0
        res[1] = 0.0
        res[2] = 0.0
    elif quat[0] == 1 and quat[1] == 0 and quat[2] == 0 and quat[3] == 0:
        res[0] = vec[0]
        res[1] = vec[1]
        res[2] = vec[2]
    else:
        t0 = quat[0] * vec[0] + quat[2] * vec[2] - quat[3] * vec[1]
        t1 = quat[0] * vec[1] + quat[3] * vec[0] - quat[1] * vec[2]
        t2 = quat[0] * vec[2] + quat[1] * vec[1] - quat[2] * vec[0]
        r0 = vec[0] + 2 * (quat[2] * t2 - quat[3] * t1)
        r1 = vec[1] + 2 * (quat[3] * t0 - quat[1] * t2)
        r2 = vec[2] + 2 * (quat[1] * t1 - quat[2] * t0)
        res[0] = r0
        res[1] = r1
        res[2] = r2


@njit(inline="always")
def _quat2mat(res, q):
    if q[0] == 1 and q[1] == 0 and q[2] == 0 and q[3] == 0:
        for k in range(9):
            res[k] = 0.0
        res[0] = 1.0
        res[4] = 1.0
        res[8] = 1.0
        return
    q00 = q[0] * q[0]
    q01 = q[0] * q[1]
    q02 = q[0] * q[2]
    q03 = q[0] * q[3]
    q11 = q[1] * q[1]
    q12 = q[1] * q[2]
    q13 = q[1] * q[3]
    q22 = q[2] * q[2]
    q23 = q[2] * q[3]
    q33 = q[3] * q[3]
    # the association order MuJoCo's build uses (measured bit-equal on mujoco 4.0.0)
    res[0] = (q00 - q22) + (q11 - q33)
    res[4] = (q00 + q22) - (q11 + q33)
    res[8] = (q00 - q22) - (q11 - q33)
    res[1] = 2 * (q12 - q03)
    res[2] = 2 * (q13 + q02)
    res[3] = 2 * (q12 + q03)
    res[5] = 2 * (q23 - q01)
    res[6] = 2 * (q13 - q02)
    res[7] = 2 * (q23 + q01)


@njit(inline="always")
def _matvec3(res, mat, vec):
    r0 = mat[0] * vec[0] + mat[1] * vec[1] + mat[2] * vec[2]
    r1 = mat[3] * vec[0] + mat[4] * vec[1] + mat[5] * vec[2]
    r2 = mat[6] * vec[0] + mat[7] * vec[1] + mat[8] * vec[2]
    res[0] = r0
    res[1] = r1
    res[2] = r2


@njit(inline="always")
def _local2global(xpos_out, xmat_out, pos, quat, body, sameframe, xpos, xquat, xmat, xipos,
                  ximat, tmp4, tmp3):
    # sameframe: 0 none, 1 body, 2 inertia, 3 body rotation, 4 inertia rotation
    if sameframe == 0 or sameframe == 3 or sameframe == 4:
        _matvec3(tmp3, xmat[body], pos)
        xpos_out[0] = tmp3[0] + xpos[body, 0]
        xpos_out[1] = tmp3[1] + xpos[body, 1]
        xpos_out[2] = tmp3[2] + xpos[body, 2]
    elif sameframe == 1:
        for k in range(3):
            xpos_out[k] = xpos[body, k]
    else:
        for k in range(3):
            xpos_out[k] = xipos[body, k]
    if sameframe == 0:
        _mulquat(tmp4, xquat[body], quat)
        _quat2mat(xmat_out, tmp4)
    elif sameframe == 1 or sameframe == 3:
        for k in range(9):
            xmat_out[k] = xmat[body, k]
    else:
        for k in range(9):
            xmat_out[k] = ximat[body, k]


@njit
def fk_tree(qpos_in, body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos,
            body_quat, body_ipos, body_iquat, body_mass, jnt_type, jnt_qposadr, jnt_axis,
            jnt_pos, qpos0, qpos, xpos, xquat, xmat, xipos, ximat, subtree_com, mass_subtree,
            work):
    """``mj_kinematics`` (bodies and inertial frames) and the subtree CoM of ``mj_comPos``.

    ``qpos`` is a work copy of ``qpos_in`` (its free/ball quaternions get normalised);
    outputs ``xpos (nb, 3)``, ``xquat (nb, 4)``, ``xmat (nb, 9)``, ``xipos (nb, 3)``,
    ``ximat (nb, 9)``, ``subtree_com (nb, 3)`` [m], work ``mass_subtree (nb,)``.
    """
    nb = body_parent.shape[0]
    _normalized_qpos(qpos_in, qpos, jnt_type, jnt_qposadr)
    _world_frame(xpos, xquat, xmat, xipos, ximat)
    pos = work[0:3]
    quat = work[3:7]
    vec = work[7:10]
    vec1 = work[10:13]
    xanchor = work[13:16]
    qloc = work[16:20]
    tmp4 = work[20:24]
    tmp3 = work[24:27]
    for i in range(1, nb):
        ja = body_jntadr[i]
        if body_jntnum[i] == 1 and jnt_type[ja] == FREE:
            a = jnt_qposadr[ja]
            for k in range(3):
                pos[k] = qpos[a + k]
            for k in range(4):
                quat[k] = qpos[a + 3 + k]
        else:
            p = body_parent[i]
            _matvec3(vec, xmat[p], body_pos[i])
            for k in range(3):
                pos[k] = xpos[p, k] + vec[k]
            _mulquat(quat, xquat[p], body_quat[i])
            for jj in range(body_jntnum[i]):
                j = ja + jj
                a = jnt_qposadr[j]
                t = jnt_type[j]
                _rotvecquat(xanchor, jnt_pos[j], quat)
                for k in range(3):
                    xanchor[k] = xanchor[k] + pos[k]
                if t == SLIDE:
                    _rotvecquat(vec, jnt_axis[j], quat)
                    s = qpos[a] - qpos0[a]
                    for k in range(3):
                        pos[k] = pos[k] + vec[k] * s
                else:
                    _joint_rotation(qloc, t, qpos, a, qpos0[a], jnt_axis[j])
                    _mulquat(quat, quat, qloc)
                    for k in range(3):
                        vec[k] = xanchor[k] - pos[k]
                    _rotvecquat(vec1, jnt_pos[j], quat)
                    for k in range(3):
                        pos[k] += vec[k] - vec1[k]
        _normalize4(quat)
        for k in range(4):
            xquat[i, k] = quat[k]
        for k in range(3):
            xpos[i, k] = pos[k]
        _quat2mat(xmat[i], quat)
    for i in range(1, nb):
        _local2global(xipos[i], ximat[i], body_ipos[i], body_iquat[i], i, body_sameframe[i],
                      xpos, xquat, xmat, xipos, ximat, tmp4, tmp3)
    _subtree_coms(body_parent, body_mass, xipos, subtree_com, mass_subtree)


@njit
def _normalized_qpos(qpos_in, qpos, jnt_type, jnt_qposadr):
    """Copy ``qpos_in`` into ``qpos`` and normalise its free/ball quaternions."""
    for k in range(qpos.shape[0]):
        qpos[k] = qpos_in[k]
    for j in range(jnt_type.shape[0]):
        t = jnt_type[j]
        if t == FREE:
            _normalize4(qpos[jnt_qposadr[j] + 3 : jnt_qposadr[j] + 7])
        elif t == BALL:
            _normalize4(qpos[jnt_qposadr[j] : jnt_qposadr[j] + 4])


@njit
def _world_frame(xpos, xquat, xmat, xipos, ximat):
    """Body 0 (the world): zero position, identity orientation."""
    for k in range(3):
        xpos[0, k] = 0.0
        xipos[0, k] = 0.0
    for k in range(4):
        xquat[0, k] = 0.0
    xquat[0, 0] = 1.0
    for k in range(9):
        xmat[0, k] = 0.0
        ximat[0, k] = 0.0
    for k in (0, 4, 8):
        xmat[0, k] = 1.0
        ximat[0, k] = 1.0


@njit
def _joint_rotation(qloc, t, qpos, a, qpos0_a, axis):
    """Local rotation ``qloc`` (wxyz) of a ball joint (its quaternion) or a hinge (angle
    ``qpos[a] - qpos0_a`` [rad] about ``axis``)."""
    if t == BALL:
        for k in range(4):
            qloc[k] = qpos[a + k]
    else:
        ang = qpos[a] - qpos0_a
        if ang == 0:
            qloc[0] = 1.0
            qloc[1] = 0.0
            qloc[2] = 0.0
            qloc[3] = 0.0
        else:
            s = math.sin(ang * 0.5)
            qloc[0] = math.cos(ang * 0.5)
            qloc[1] = axis[0] * s
            qloc[2] = axis[1] * s
            qloc[3] = axis[2] * s


@njit
def _subtree_coms(body_parent, body_mass, xipos, subtree_com, mass_subtree):
    """mj_comPos: backward pass for the subtree CoMs [m] (MuJoCo 4 puts every body's own
    m x_i in first, then adds the children: same order here)."""
    nb = body_parent.shape[0]
    for i in range(nb):
        for k in range(3):
            subtree_com[i, k] = xipos[i, k] * body_mass[i]
        mass_subtree[i] = body_mass[i]
    for i in range(nb - 1, -1, -1):
        if i > 0:
            p = body_parent[i]
            for k in range(3):
                subtree_com[p, k] += subtree_com[i, k]
            mass_subtree[p] += mass_subtree[i]
        if mass_subtree[i] < _MINVAL:
            for k in range(3):
                subtree_com[i, k] = xipos[i, k]
        else:
            inv = 1.0 / max(_MINVAL, mass_subtree[i])
            for k in range(3):
                subtree_com[i, k] = subtree_com[i, k] * inv


@njit
def fk_sites(sites, site_body, site_sameframe, site_pos, site_quat, xpos, xquat, xmat, xipos,
             ximat, site_xpos, site_xmat, work):
    """World pose of the chosen ``sites`` (k,) into ``site_xpos (k, 3)``, ``site_xmat (k, 9)``
    (``work``: at least 7 floats)."""
    tmp4 = work[0:4]
    tmp3 = work[4:7]
    for n in range(sites.shape[0]):
        s = sites[n]
        _local2global(site_xpos[n], site_xmat[n], site_pos[s], site_quat[s], site_body[s],
                      site_sameframe[s], xpos, xquat, xmat, xipos, ximat, tmp4, tmp3)


@njit
def fk_batch(Q, body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos, body_quat,
             body_ipos, body_iquat, body_mass, jnt_type, jnt_qposadr, jnt_axis, jnt_pos, qpos0,
             out_com, out_xipos):
    """Kinematics of every row of ``Q`` (T, nq): whole-robot CoM ``out_com`` (T, 3) (subtree
    of body 1) and body CoMs ``out_xipos`` (T, nb, 3) [m] (throughput benchmark and batch
    use)."""
    nb = body_parent.shape[0]
    nq = qpos0.shape[0]
    qpos = np.empty(nq)
    xpos = np.empty((nb, 3))
    xquat = np.empty((nb, 4))
    xmat = np.empty((nb, 9))
    xipos = np.empty((nb, 3))
    ximat = np.empty((nb, 9))
    stc = np.empty((nb, 3))
    ms = np.empty(nb)
    work = np.empty(N_WORK)
    for t in range(Q.shape[0]):
        fk_tree(Q[t], body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos,
                body_quat, body_ipos, body_iquat, body_mass, jnt_type, jnt_qposadr, jnt_axis,
                jnt_pos, qpos0, qpos, xpos, xquat, xmat, xipos, ximat, stc, ms, work)
        for k in range(3):
            out_com[t, k] = stc[1, k]
        for i in range(nb):
            for k in range(3):
                out_xipos[t, i, k] = xipos[i, k]
