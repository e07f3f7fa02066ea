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
from grfguard.kernels._jit import borrow, njit, njit_nort, view1d, view2d

__all__ = ["TreeModel", "fk_tree", "fk_bodies", "fk_sites", "fk_site_pos", "subtree_com_of",
           "fk_batch", "fk_bodies_kind", "N_WORK", "FREE", "BALL", "SLIDE", "HINGE",
           "GENERIC"]

FREE, BALL, SLIDE, HINGE = 0, 1, 2, 3
#: Body kind of :meth:`TreeModel.body_kinds`: any joints, offsets and rotations.
GENERIC = -1
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
    #: Bodies 1..nb-1 by depth in the tree (parents first; the branches of one depth next
    #: to each other, so the CPU overlaps the legs' dependency chains).
    body_order: np.ndarray  # (nb - 1,) int64

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

        parent = i64(m.body_parentid)
        depth = np.zeros(parent.shape[0], np.int64)
        for i in range(1, parent.shape[0]):
            depth[i] = depth[parent[i]] + 1
        order = np.argsort(depth[1:], kind="stable").astype(np.int64) + 1
        return cls(
            body_parent=parent,
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
            body_order=np.ascontiguousarray(order),
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
            self.body_order,
        )

    def body_kinds(self) -> np.ndarray:
        """Per body (nb,) int64: :data:`GENERIC` (-1), or the axis index 0/1/2 of a body
        with one hinge about the unit axis x/y/z, no rotation relative to its parent
        (``body_quat`` = 1) and its anchor at the body origin (``jnt_pos`` = 0): for
        those :func:`fk_bodies_kind` leaves out the products with the zeros (same values
        as :func:`fk_bodies` up to the sign of zeros)."""
        kinds = np.full(self.nbody, GENERIC, np.int64)
        for i in range(1, self.nbody):
            j = int(self.body_jntadr[i])
            if (self.body_jntnum[i] != 1 or self.jnt_type[j] != HINGE
                    or not np.array_equal(self.body_quat[i], [1.0, 0.0, 0.0, 0.0])
                    or np.any(self.jnt_pos[j] != 0.0)):
                continue
            for k in range(3):
                if np.array_equal(self.jnt_axis[j], np.eye(3)[k]):
                    kinds[i] = k
        return kinds

    def new_frames(self) -> tuple[np.ndarray, ...]:
        """Output arrays ``(xpos, xquat, xmat, xipos, ximat, subtree_com)`` for one sample."""
        nb = self.nbody
        return (
            np.zeros((nb, 3)), np.zeros((nb, 4)), np.zeros((nb, 9)),
            np.zeros((nb, 3)), np.zeros((nb, 9)), np.zeros((nb, 3)),
        )


# ----------------------------------------------------------------------------- MuJoCo maths
# Scalar helpers (no array views: nothing to reference-count, everything stays in
# registers); the operation order is MuJoCo's, so results are bit-equal where MuJoCo's
# build does not fuse differently.
@njit_nort(inline="always")
def _nq(q0, q1, q2, q3):
    """mju_normalize4: unit quaternion (identity below 1e-15; unchanged within 1e-15)."""
    n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    if n < _MINVAL:
        return 1.0, 0.0, 0.0, 0.0
    if abs(n - 1.0) > _MINVAL:
        inv = 1.0 / n
        return q0 * inv, q1 * inv, q2 * inv, q3 * inv
    return q0, q1, q2, q3


#: ``|q.q - 1|`` below this: ``|sqrt(q.q) - 1| <= 1e-15`` for sure (every double in the
#: band is checked in ``tests/test_kernels_fk.py``), so :func:`_nq` returns ``q`` as it is.
NQ_BAND = 1.5e-15


@njit_nort
def _nq_slow(q0, q1, q2, q3):
    return _nq(q0, q1, q2, q3)


@njit_nort(inline="always")
def _nqf(q0, q1, q2, q3):
    """:func:`_nq` with the usual case (a product of unit quaternions, norm within a few
    units in the last place of 1) decided without the square root and the division,
    which kept the chain of body orientations waiting; same result bit for bit."""
    s = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
    if abs(s - 1.0) < NQ_BAND:
        return q0, q1, q2, q3
    return _nq_slow(q0, q1, q2, q3)


@njit_nort(inline="always")
def _mq(a0, a1, a2, a3, b0, b1, b2, b3):
    """mju_mulQuat."""
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


@njit_nort(inline="always")
def _rv(v0, v1, v2, q0, q1, q2, q3):
    """mju_rotVecQuat."""
    if v0 == 0 and v1 == 0 and v2 == 0:
        return 0.0, 0.0, 0.0
    if q0 == 1 and q1 == 0 and q2 == 0 and q3 == 0:
        return v0, v1, v2
    t0 = q0 * v0 + q2 * v2 - q3 * v1
    t1 = q0 * v1 + q3 * v0 - q1 * v2
    t2 = q0 * v2 + q1 * v1 - q2 * v0
    return (v0 + 2 * (q2 * t2 - q3 * t1), v1 + 2 * (q3 * t0 - q1 * t2),
            v2 + 2 * (q1 * t1 - q2 * t0))


@njit_nort(inline="always")
def _q2m(q0, q1, q2, q3):
    """mju_quat2Mat (row-major 9-tuple)."""
    if q0 == 1 and q1 == 0 and q2 == 0 and q3 == 0:
        return 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    q00 = q0 * q0
    q01 = q0 * q1
    q02 = q0 * q2
    q03 = q0 * q3
    q11 = q1 * q1
    q12 = q1 * q2
    q13 = q1 * q3
    q22 = q2 * q2
    q23 = q2 * q3
    q33 = q3 * q3
    # the association order MuJoCo's build uses (measured bit-equal on mujoco 4.0.0)
    return ((q00 - q22) + (q11 - q33), 2 * (q12 - q03), 2 * (q13 + q02),
            2 * (q12 + q03), (q00 + q22) - (q11 + q33), 2 * (q23 - q01),
            2 * (q13 - q02), 2 * (q23 + q01), (q00 - q22) - (q11 - q33))


@njit_nort(inline="always")
def _mv(m0, m1, m2, m3, m4, m5, m6, m7, m8, v0, v1, v2):
    """mju_mulMatVec3 (row-major matrix entries)."""
    return (m0 * v0 + m1 * v1 + m2 * v2,
            m3 * v0 + m4 * v1 + m5 * v2,
            m6 * v0 + m7 * v1 + m8 * v2)


@njit_nort(inline="always")
def _mm(a0, a1, a2, a3, a4, a5, a6, a7, a8, b0, b1, b2, b3, b4, b5, b6, b7, b8):
    """3x3 product of row-major entries."""
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7,
            a0 * b2 + a1 * b5 + a2 * b8, a3 * b0 + a4 * b3 + a5 * b6,
            a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
            a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7,
            a6 * b2 + a7 * b5 + a8 * b8)


# mj_local2Global (sameframe: 0 none, 1 body, 2 inertia, 3 body rotation, 4 inertia
# rotation) is written out in _inertial_frames and fk_sites: a call per body with a
# dozen array arguments costs more than the arithmetic.
@njit_nort(inline="always")
def _inertial_frames(body_sameframe, body_ipos, body_iquat, xpos, xquat, xmat, xipos, ximat):
    """``xipos``/``ximat`` of bodies 1.. from their inertial frames (sameframe 2 / 4, the
    inertial frame relative to itself, leaves them as they are)."""
    for i in range(1, body_sameframe.shape[0]):
        sf = body_sameframe[i]
        if sf == 0 or sf == 3 or sf == 4:
            v0, v1, v2 = _mv(xmat[i, 0], xmat[i, 1], xmat[i, 2], xmat[i, 3], xmat[i, 4],
                             xmat[i, 5], xmat[i, 6], xmat[i, 7], xmat[i, 8],
                             body_ipos[i, 0], body_ipos[i, 1], body_ipos[i, 2])
            xipos[i, 0] = v0 + xpos[i, 0]
            xipos[i, 1] = v1 + xpos[i, 1]
            xipos[i, 2] = v2 + xpos[i, 2]
        elif sf == 1:
            for k in range(3):
                xipos[i, k] = xpos[i, k]
        if sf == 0:
            q0, q1, q2, q3 = _mq(xquat[i, 0], xquat[i, 1], xquat[i, 2], xquat[i, 3],
                                 body_iquat[i, 0], body_iquat[i, 1], body_iquat[i, 2],
                                 body_iquat[i, 3])
            r = _q2m(q0, q1, q2, q3)
            for k in range(9):
                ximat[i, k] = r[k]
        elif sf == 1 or sf == 3:
            for k in range(9):
                ximat[i, k] = xmat[i, k]


@njit_nort(inline="always")
def fk_tree(qpos_in, body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos,
            body_quat, body_ipos, body_iquat, body_mass, jnt_type, jnt_qposadr, jnt_axis,
            jnt_pos, qpos0, body_order, qpos, xpos, xquat, xmat, xipos, ximat, subtree_com,
            mass_subtree, work):
    """``mj_kinematics`` (bodies, inertial frames) and ``mj_comPos``'s subtree CoM into
    ``xpos``, ``xquat``, ``xmat``, ``xipos``, ``ximat``, ``subtree_com`` [m] (``qpos``: work
    copy of ``qpos_in``; ``work`` unused). Bodies in ``body_order`` (parents first; each
    body's arithmetic is MuJoCo's, so the order changes no bit). No allocation."""
    fk_bodies(qpos_in, body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos,
              body_quat, body_ipos, body_iquat, jnt_type, jnt_qposadr, jnt_axis, jnt_pos,
              qpos0, body_order, qpos, xpos, xquat, xmat, xipos, ximat)
    _subtree_coms(body_parent, body_mass, xipos, subtree_com, mass_subtree)


@njit_nort(inline="always")
def fk_bodies(qpos_in, body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos,
              body_quat, body_ipos, body_iquat, jnt_type, jnt_qposadr, jnt_axis, jnt_pos,
              qpos0, body_order, qpos, xpos, xquat, xmat, xipos, ximat):
    """:func:`fk_tree` without the subtree CoMs (see :func:`subtree_com_of`)."""
    nb = body_parent.shape[0]
    _normalized_qpos(qpos_in, qpos, jnt_type, jnt_qposadr)
    _world_frame(xpos, xquat, xmat, xipos, ximat)
    for n in range(nb - 1):
        _generic_body(body_order[n], qpos, body_parent, body_jntadr, body_jntnum, body_pos,
                      body_quat, jnt_type, jnt_qposadr, jnt_axis, jnt_pos, qpos0, xpos, xquat,
                      xmat)
    _inertial_frames(body_sameframe, body_ipos, body_iquat, xpos, xquat, xmat, xipos, ximat)


@njit_nort(inline="always")
def _generic_body(i, qpos, body_parent, body_jntadr, body_jntnum, body_pos, body_quat,
                  jnt_type, jnt_qposadr, jnt_axis, jnt_pos, qpos0, xpos, xquat, xmat):
    """mj_kinematics of body ``i`` (its parent done): any joints, offsets, rotations."""
    ja = body_jntadr[i]
    if body_jntnum[i] == 1 and jnt_type[ja] == FREE:
        a = jnt_qposadr[ja]
        p0, p1, p2 = qpos[a], qpos[a + 1], qpos[a + 2]
        q0, q1, q2, q3 = qpos[a + 3], qpos[a + 4], qpos[a + 5], qpos[a + 6]
    else:
        p = body_parent[i]
        v0, v1, v2 = _mv(xmat[p, 0], xmat[p, 1], xmat[p, 2], xmat[p, 3], xmat[p, 4],
                         xmat[p, 5], xmat[p, 6], xmat[p, 7], xmat[p, 8],
                         body_pos[i, 0], body_pos[i, 1], body_pos[i, 2])
        p0 = xpos[p, 0] + v0
        p1 = xpos[p, 1] + v1
        p2 = xpos[p, 2] + v2
        q0, q1, q2, q3 = _mq(xquat[p, 0], xquat[p, 1], xquat[p, 2], xquat[p, 3],
                             body_quat[i, 0], body_quat[i, 1], body_quat[i, 2],
                             body_quat[i, 3])
        for jj in range(body_jntnum[i]):
            j = ja + jj
            a = jnt_qposadr[j]
            t = jnt_type[j]
            j0, j1, j2 = jnt_pos[j, 0], jnt_pos[j, 1], jnt_pos[j, 2]
            a0, a1, a2 = _rv(j0, j1, j2, q0, q1, q2, q3)
            a0 = a0 + p0
            a1 = a1 + p1
            a2 = a2 + p2
            if t == SLIDE:
                v0, v1, v2 = _rv(jnt_axis[j, 0], jnt_axis[j, 1], jnt_axis[j, 2], q0, q1,
                                 q2, q3)
                sl = qpos[a] - qpos0[a]
                p0 = p0 + v0 * sl
                p1 = p1 + v1 * sl
                p2 = p2 + v2 * sl
            else:
                if t == BALL:
                    l0, l1, l2, l3 = qpos[a], qpos[a + 1], qpos[a + 2], qpos[a + 3]
                else:
                    ang = qpos[a] - qpos0[a]
                    if ang == 0:
                        l0, l1, l2, l3 = 1.0, 0.0, 0.0, 0.0
                    else:
                        sn = math.sin(ang * 0.5)
                        l0 = math.cos(ang * 0.5)
                        l1 = jnt_axis[j, 0] * sn
                        l2 = jnt_axis[j, 1] * sn
                        l3 = jnt_axis[j, 2] * sn
                q0, q1, q2, q3 = _mq(q0, q1, q2, q3, l0, l1, l2, l3)
                v0 = a0 - p0
                v1 = a1 - p1
                v2 = a2 - p2
                w0, w1, w2 = _rv(j0, j1, j2, q0, q1, q2, q3)
                p0 += v0 - w0
                p1 += v1 - w1
                p2 += v2 - w2
    _store_body(i, p0, p1, p2, q0, q1, q2, q3, xpos, xquat, xmat)


@njit_nort(inline="always")
def _unit_hinge(k, q0, q1, q2, q3, sn, cs):
    """mju_mulQuat(q, (cs, sn e_k)) for the unit axis ``e_k`` without the products with
    its zeros (each component is MuJoCo's sum with the zero terms left out: the same
    value, up to the sign of a zero)."""
    if k == 0:
        return q0 * cs - q1 * sn, q0 * sn + q1 * cs, q2 * cs + q3 * sn, q3 * cs - q2 * sn
    if k == 1:
        return q0 * cs - q2 * sn, q1 * cs - q3 * sn, q0 * sn + q2 * cs, q1 * sn + q3 * cs
    return q0 * cs - q3 * sn, q1 * cs + q2 * sn, q2 * cs - q1 * sn, q0 * sn + q3 * cs


@njit_nort(inline="always")
def fk_bodies_kind(qpos_in, body_kind, body_parent, body_jntadr, body_jntnum, body_sameframe,
                   body_pos, body_quat, body_ipos, body_iquat, jnt_type, jnt_qposadr,
                   jnt_axis, jnt_pos, qpos0, body_order, qpos, xpos, xquat, xmat, xipos,
                   ximat):
    """:func:`fk_bodies` with the bodies of :meth:`TreeModel.body_kinds` >= 0 (a unit
    hinge at the body origin, no body rotation) done without the products with zeros;
    the same values (tests: ``tests/test_kernels_fk.py``)."""
    nb = body_parent.shape[0]
    _normalized_qpos(qpos_in, qpos, jnt_type, jnt_qposadr)
    _world_frame(xpos, xquat, xmat, xipos, ximat)
    for n in range(nb - 1):
        i = body_order[n]
        k = body_kind[i]
        if k < 0:
            _generic_body(i, qpos, body_parent, body_jntadr, body_jntnum, body_pos, body_quat,
                          jnt_type, jnt_qposadr, jnt_axis, jnt_pos, qpos0, xpos, xquat, xmat)
            continue
        p = body_parent[i]
        v0, v1, v2 = _mv(xmat[p, 0], xmat[p, 1], xmat[p, 2], xmat[p, 3], xmat[p, 4],
                         xmat[p, 5], xmat[p, 6], xmat[p, 7], xmat[p, 8],
                         body_pos[i, 0], body_pos[i, 1], body_pos[i, 2])
        q0, q1, q2, q3 = xquat[p, 0], xquat[p, 1], xquat[p, 2], xquat[p, 3]
        a = jnt_qposadr[body_jntadr[i]]
        ang = qpos[a] - qpos0[a]
        if ang != 0:
            q0, q1, q2, q3 = _unit_hinge(k, q0, q1, q2, q3, math.sin(ang * 0.5),
                                         math.cos(ang * 0.5))
        _store_body(i, xpos[p, 0] + v0, xpos[p, 1] + v1, xpos[p, 2] + v2, q0, q1, q2, q3,
                    xpos, xquat, xmat)
    _inertial_frames(body_sameframe, body_ipos, body_iquat, xpos, xquat, xmat, xipos, ximat)


@njit_nort(inline="always")
def _store_body(i, p0, p1, p2, q0, q1, q2, q3, xpos, xquat, xmat):
    """Normalise the orientation (mju_normalize4) and store the body's frame."""
    q0, q1, q2, q3 = _nqf(q0, q1, q2, q3)
    xquat[i, 0] = q0
    xquat[i, 1] = q1
    xquat[i, 2] = q2
    xquat[i, 3] = q3
    xpos[i, 0] = p0
    xpos[i, 1] = p1
    xpos[i, 2] = p2
    r = _q2m(q0, q1, q2, q3)
    for k in range(9):
        xmat[i, k] = r[k]


@njit_nort(inline="always")
def _normalized_qpos(qpos_in, qpos, jnt_type, jnt_qposadr):
    """Copy ``qpos_in`` into ``qpos`` and normalise its free/ball quaternions."""
    for k in range(qpos.shape[0]):
        qpos[k] = qpos_in[k]
    for j in range(jnt_type.shape[0]):
        t = jnt_type[j]
        if t == FREE or t == BALL:
            a = jnt_qposadr[j] + (3 if t == FREE else 0)
            q0, q1, q2, q3 = _nq(qpos[a], qpos[a + 1], qpos[a + 2], qpos[a + 3])
            qpos[a] = q0
            qpos[a + 1] = q1
            qpos[a + 2] = q2
            qpos[a + 3] = q3


@njit_nort(inline="always")
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
    xmat[0, 0] = 1.0
    xmat[0, 4] = 1.0
    xmat[0, 8] = 1.0
    ximat[0, 0] = 1.0
    ximat[0, 4] = 1.0
    ximat[0, 8] = 1.0


@njit_nort(inline="always")
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


@njit_nort(inline="always")
def subtree_com_of(b, body_parent, body_mass, xipos, subtree_com, mass_subtree):
    """The subtree CoM of body ``b`` alone (3 floats) [m]: :func:`_subtree_coms`'s backward
    pass in the same order (same bits), without normalising the other bodies."""
    nb = body_parent.shape[0]
    for i in range(nb):
        for k in range(3):
            subtree_com[i, k] = xipos[i, k] * body_mass[i]
        mass_subtree[i] = body_mass[i]
    for i in range(nb - 1, b, -1):
        p = body_parent[i]
        for k in range(3):
            subtree_com[p, k] += subtree_com[i, k]
        mass_subtree[p] += mass_subtree[i]
    if mass_subtree[b] < _MINVAL:
        return xipos[b, 0], xipos[b, 1], xipos[b, 2]
    inv = 1.0 / max(_MINVAL, mass_subtree[b])
    return subtree_com[b, 0] * inv, subtree_com[b, 1] * inv, subtree_com[b, 2] * inv


@njit_nort(inline="always")
def fk_site_pos(sites, site_body, site_sameframe, site_pos, xpos, xmat, xipos, site_xpos):
    """:func:`fk_sites` without the sites' orientations: positions only."""
    for n in range(sites.shape[0]):
        s = sites[n]
        b = site_body[s]
        sf = site_sameframe[s]
        if sf == 0 or sf == 3 or sf == 4:
            v0, v1, v2 = _mv(xmat[b, 0], xmat[b, 1], xmat[b, 2], xmat[b, 3], xmat[b, 4],
                             xmat[b, 5], xmat[b, 6], xmat[b, 7], xmat[b, 8],
                             site_pos[s, 0], site_pos[s, 1], site_pos[s, 2])
            site_xpos[n, 0] = v0 + xpos[b, 0]
            site_xpos[n, 1] = v1 + xpos[b, 1]
            site_xpos[n, 2] = v2 + xpos[b, 2]
        elif sf == 1:
            for k in range(3):
                site_xpos[n, k] = xpos[b, k]
        else:
            for k in range(3):
                site_xpos[n, k] = xipos[b, k]


@njit_nort(inline="always")
def fk_sites(sites, site_body, site_sameframe, site_pos, site_quat, xpos, xquat, xmat, xipos,
             ximat, site_xpos, site_xmat, work):
    """World pose of the chosen ``sites`` (k,) into ``site_xpos (k, 3)``, ``site_xmat (k, 9)``
    (``work`` is unused, kept for the signature)."""
    for n in range(sites.shape[0]):
        s = sites[n]
        b = site_body[s]
        sf = site_sameframe[s]
        if sf == 0 or sf == 3 or sf == 4:
            v0, v1, v2 = _mv(xmat[b, 0], xmat[b, 1], xmat[b, 2], xmat[b, 3], xmat[b, 4],
                             xmat[b, 5], xmat[b, 6], xmat[b, 7], xmat[b, 8],
                             site_pos[s, 0], site_pos[s, 1], site_pos[s, 2])
            site_xpos[n, 0] = v0 + xpos[b, 0]
            site_xpos[n, 1] = v1 + xpos[b, 1]
            site_xpos[n, 2] = v2 + xpos[b, 2]
        elif sf == 1:
            for k in range(3):
                site_xpos[n, k] = xpos[b, k]
        else:
            for k in range(3):
                site_xpos[n, k] = xipos[b, k]
        if sf == 0:
            q0, q1, q2, q3 = _mq(xquat[b, 0], xquat[b, 1], xquat[b, 2], xquat[b, 3],
                                 site_quat[s, 0], site_quat[s, 1], site_quat[s, 2],
                                 site_quat[s, 3])
            r = _q2m(q0, q1, q2, q3)
            for k in range(9):
                site_xmat[n, k] = r[k]
        elif sf == 1 or sf == 3:
            for k in range(9):
                site_xmat[n, k] = xmat[b, k]
        else:
            for k in range(9):
                site_xmat[n, k] = ximat[b, k]


@njit
def fk_batch(Q, body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos, body_quat,
             body_ipos, body_iquat, body_mass, jnt_type, jnt_qposadr, jnt_axis, jnt_pos, qpos0,
             body_order, out_com, out_xipos):
    """Kinematics of every row of ``Q`` (T, nq): whole-robot CoM ``out_com`` (T, 3) (subtree
    of body 1) and body CoMs ``out_xipos`` (T, nb, 3) [m] (throughput benchmark and batch
    use)."""
    nb = body_parent.shape[0]
    nq = qpos0.shape[0]
    # borrowed (no reference counting on every call of fk_tree)
    (body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos, body_quat, body_ipos,
     body_iquat, body_mass, jnt_type, jnt_qposadr, jnt_axis, jnt_pos, qpos0, body_order) = (
        borrow(body_parent), borrow(body_jntadr), borrow(body_jntnum), borrow(body_sameframe),
        borrow(body_pos), borrow(body_quat), borrow(body_ipos), borrow(body_iquat),
        borrow(body_mass), borrow(jnt_type), borrow(jnt_qposadr), borrow(jnt_axis),
        borrow(jnt_pos), borrow(qpos0), borrow(body_order))
    # one buffer, borrowed views of it (kept alive by its use after the loop)
    buf = np.empty(2 * nq + 32 * nb + N_WORK)
    o = 0
    qpos = view1d(buf, o, nq)
    o += nq
    xpos = view2d(buf, o, nb, 3)
    o += 3 * nb
    xquat = view2d(buf, o, nb, 4)
    o += 4 * nb
    xmat = view2d(buf, o, nb, 9)
    o += 9 * nb
    xipos = view2d(buf, o, nb, 3)
    o += 3 * nb
    ximat = view2d(buf, o, nb, 9)
    o += 9 * nb
    stc = view2d(buf, o, nb, 3)
    o += 3 * nb
    ms = view1d(buf, o, nb)
    o += nb
    work = view1d(buf, o, N_WORK)
    for t in range(Q.shape[0]):
        fk_tree(Q[t], body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos,
                body_quat, body_ipos, body_iquat, body_mass, jnt_type, jnt_qposadr, jnt_axis,
                jnt_pos, qpos0, body_order, qpos, xpos, xquat, xmat, xipos, ximat, stc, ms,
                work)
        for k in range(3):
            out_com[t, k] = stc[1, k]
        for i in range(nb):
            for k in range(3):
                out_xipos[t, i, k] = xipos[i, k]
    buf[0] = 0.0
