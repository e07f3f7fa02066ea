"""Inverse dynamics of a free-floating MuJoCo tree, compiled: the ground wrench a walking
robot needs and the ankle F/T readings it causes, sample by sample or over a whole log.

What :mod:`grfguard.estimate.wrench` used to get from per-sample MuJoCo calls:

* the free-base rows of ``mj_rne(m, d, 1, f)`` (``M qacc + c``; rigid-body dynamics: the
  free rows carry no armature, so none is added here), i.e. the total spatial force
  ``sum_i I_i a_i + v_i x* I_i v_i`` of the bodies about the robot's CoM, and the wrench at
  a sole site that balances it (``J_free^T w = f_free`` of ``mj_jacSite``, solved in
  closed form: ``F``, ``tau_c + (c - p) x F``);
* the internal wrench ``cfrc_int`` of ``mj_rnePostConstraint`` of a foot body with the
  ground wrench applied to it, read at the F/T site as MuJoCo's force/torque sensors do.

The arithmetic is MuJoCo's (``mj_comPos``: ``cinert``, ``cdof``; ``mj_comVel``: ``cvel``,
``cdof_dot``; ``mj_rne``: ``cacc``, ``cfrc_body``; spatial vectors ``[angular; linear]`` in
world axes about the subtree CoM of the root body); the kinematics are
:func:`grfguard.kernels.fk.fk_bodies` (MuJoCo's bits). Results agree with MuJoCo to about
1e-12 relative (``tests/test_kernels_rne.py``).

Supported: one free joint (the base) and hinge, slide or ball joints, at most one joint per
body (what URDF trees give: Talos, G1).

For a tree of hinges (Talos, G1) :class:`HingeTree` and :func:`hinge_wrench_batch` do the
same physics faster: fixed bodies merged into their moving parents, each hinge and offset
one branch-free rotation, base axes about the base origin, one pass per stage over the
bodies (agrees with MuJoCo to about 1e-12 relative, ``tests/test_kernels_rne.py``);
:func:`hinge_frames_batch` is its first kinematics pass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grfguard.errors import ConfigError
from grfguard.kernels._jit import fma, njit, njit_nort
from grfguard.kernels.fk import (
    BALL,
    FREE,
    HINGE,
    SLIDE,
    TreeModel,
    _mm,
    _mv,
    fk_bodies,
    fk_sites,
    subtree_com_of,
)
from grfguard.kernels.lanes import LANES, lane, lanes2d, lanes_size, splat, vload
from grfguard.kernels.sincos import SINCOS_MAX, sincos_flat  # noqa: F401 (re-exported)

__all__ = ["RNEModel", "rne_sample", "sample_wrenches", "wrench_batch", "frames_batch", "new_work",
           "HingeTree", "hinge_wrench_batch", "hinge_frames_batch", "site_paths"]

@dataclass(frozen=True)
class RNEModel:
    """The tree (:class:`TreeModel`) plus what the dynamics need (``nb`` bodies, ``nj``
    joints)."""

    tree: TreeModel
    body_inertia: np.ndarray  # (nb, 3) principal inertia [kg m^2]
    jnt_dofadr: np.ndarray  # (nj,) int64
    gravity: np.ndarray  # (3,) [m/s^2]
    root: int  # the body of the free joint
    nv: int

    @classmethod
    def from_mujoco(cls, model) -> RNEModel:
        """Copy a ``mujoco.MjModel``.

        Raises:
            ConfigError: The model is not one free-floating tree with at most one joint per
                body, or gravity is disabled.
        """
        m = model
        free = [j for j in range(m.njnt) if int(m.jnt_type[j]) == FREE]
        if len(free) != 1 or int(m.jnt_bodyid[free[0]]) != 1:
            raise ConfigError(
                "the compiled inverse dynamics need exactly one free joint, on the first body "
                f"(the base); the model has {len(free)} free joint(s)")
        many = [m.body(i).name for i in range(m.nbody) if int(m.body_jntnum[i]) > 1]
        if many:
            raise ConfigError(
                f"the compiled inverse dynamics support one joint per body; bodies {many} have "
                "more (split them into chained bodies in the model file)")
        if int(m.opt.disableflags) & 64:  # mjDSBL_GRAVITY
            raise ConfigError("the compiled inverse dynamics need gravity enabled in the model")
        return cls(
            tree=TreeModel.from_mujoco(m),
            body_inertia=np.ascontiguousarray(np.asarray(m.body_inertia, float).reshape(-1, 3)),
            jnt_dofadr=np.ascontiguousarray(np.asarray(m.jnt_dofadr), dtype=np.int64),
            gravity=np.ascontiguousarray(np.asarray(m.opt.gravity, float)),
            root=1,
            nv=int(m.nv),
        )

    def site_arrays(self) -> tuple:
        """``(site_body, site_sameframe, site_pos, site_quat)`` of the tree."""
        t = self.tree
        return t.site_body, t.site_sameframe, t.site_pos, t.site_quat

    def dyn_arrays(self) -> tuple:
        """``(body_inertia, jnt_dofadr, gravity)`` in the argument order of the kernels."""
        return self.body_inertia, self.jnt_dofadr, self.gravity


# ------------------------------------------------------------------ spatial algebra (MuJoCo)
@njit_nort(inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit_nort(inline="always")
def _add_motion(a, v, i, S, r, qv, qa):
    """``a[i] += cdof_dot qv + S[r] qa`` with ``cdof_dot = v[i] x S[r]``
    (mju_crossMotion); rows are ``[angular; linear]``."""
    d0, d1, d2 = _cross(v[i, 0], v[i, 1], v[i, 2], S[r, 0], S[r, 1], S[r, 2])
    e0, e1, e2 = _cross(v[i, 0], v[i, 1], v[i, 2], S[r, 3], S[r, 4], S[r, 5])
    f0, f1, f2 = _cross(v[i, 3], v[i, 4], v[i, 5], S[r, 0], S[r, 1], S[r, 2])
    a[i, 0] += d0 * qv + S[r, 0] * qa
    a[i, 1] += d1 * qv + S[r, 1] * qa
    a[i, 2] += d2 * qv + S[r, 2] * qa
    a[i, 3] += (e0 + f0) * qv + S[r, 3] * qa
    a[i, 4] += (e1 + f1) * qv + S[r, 4] * qa
    a[i, 5] += (e2 + f2) * qv + S[r, 5] * qa


@njit_nort(inline="always")
def _cdofs(i, j, t, jnt_axis, jnt_pos, xpos, xmat, c, S):
    """mj_comPos's ``cdof`` of the rotational/sliding dofs of joint ``j`` of body ``i`` into
    ``S[0..]`` (ball and free: the body's axes; offsets from the CoM ``c``)."""
    if t == FREE:
        o0, o1, o2 = c[0] - xpos[i, 0], c[1] - xpos[i, 1], c[2] - xpos[i, 2]
    else:
        p0, p1, p2 = jnt_pos[j, 0], jnt_pos[j, 1], jnt_pos[j, 2]
        o0 = c[0] - (xpos[i, 0] + (xmat[i, 0] * p0 + xmat[i, 1] * p1 + xmat[i, 2] * p2))
        o1 = c[1] - (xpos[i, 1] + (xmat[i, 3] * p0 + xmat[i, 4] * p1 + xmat[i, 5] * p2))
        o2 = c[2] - (xpos[i, 2] + (xmat[i, 6] * p0 + xmat[i, 7] * p1 + xmat[i, 8] * p2))
    nrot = 3 if (t == FREE or t == BALL) else 1
    for r in range(nrot):
        if t == FREE or t == BALL:
            ax0, ax1, ax2 = xmat[i, r], xmat[i, 3 + r], xmat[i, 6 + r]
        else:
            q0, q1, q2 = jnt_axis[j, 0], jnt_axis[j, 1], jnt_axis[j, 2]
            ax0 = xmat[i, 0] * q0 + xmat[i, 1] * q1 + xmat[i, 2] * q2
            ax1 = xmat[i, 3] * q0 + xmat[i, 4] * q1 + xmat[i, 5] * q2
            ax2 = xmat[i, 6] * q0 + xmat[i, 7] * q1 + xmat[i, 8] * q2
        if t == SLIDE:
            S[r, 0], S[r, 1], S[r, 2] = 0.0, 0.0, 0.0
            S[r, 3], S[r, 4], S[r, 5] = ax0, ax1, ax2
        else:
            l0, l1, l2 = _cross(ax0, ax1, ax2, o0, o1, o2)
            S[r, 0], S[r, 1], S[r, 2] = ax0, ax1, ax2
            S[r, 3], S[r, 4], S[r, 5] = l0, l1, l2
    return nrot


@njit_nort(inline="always")
def _joint_motion(i, j, t, qvel, qacc, jnt_dofadr, jnt_axis, jnt_pos, xpos, xmat, c, S,
                  cvel, cacc):
    """Add joint ``j`` (type ``t``) of body ``i`` to ``cvel[i]``, ``cacc[i]`` (mj_comVel,
    mj_rne: ``cdof_dot`` from the velocity before the joint's rotations; the free joint's
    translations have none and come first)."""
    da = jnt_dofadr[j]
    if t == FREE:
        for r in range(3):
            cvel[i, 3 + r] += qvel[da + r]
            cacc[i, 3 + r] += qacc[da + r]
        da += 3
    nrot = _cdofs(i, j, t, jnt_axis, jnt_pos, xpos, xmat, c, S)
    for r in range(nrot):
        _add_motion(cacc, cvel, i, S, r, qvel[da + r], qacc[da + r])
    for r in range(nrot):
        for k in range(6):
            cvel[i, k] += S[r, k] * qvel[da + r]


@njit_nort(inline="always")
def _mul_inert(I00, I11, I22, I01, I02, I12, h0, h1, h2, m, x0, x1, x2, x3, x4, x5):
    """mju_mulInertVec: the spatial inertia (rotational ``I``, first moment ``h``, mass
    ``m``) times the motion vector ``x`` (angular first)."""
    return (I00 * x0 + I01 * x1 + I02 * x2 - h2 * x4 + h1 * x5,
            I01 * x0 + I11 * x1 + I12 * x2 + h2 * x3 - h0 * x5,
            I02 * x0 + I12 * x1 + I22 * x2 - h1 * x3 + h0 * x4,
            h2 * x1 - h1 * x2 + m * x3,
            h0 * x2 - h2 * x0 + m * x4,
            h1 * x0 - h0 * x1 + m * x5)


@njit_nort(inline="always")
def _body_force(i, m, body_inertia, xipos, ximat, c, cvel, cacc, cfrc):
    """``cfrc[i] = I a + v x* (I v)`` (mj_rne's ``cfrc_body``; ``I`` mju_inertCom's inertia
    about the CoM ``c``)."""
    d0, d1, d2 = xipos[i, 0] - c[0], xipos[i, 1] - c[1], xipos[i, 2] - c[2]
    J0, J1, J2 = body_inertia[i, 0], body_inertia[i, 1], body_inertia[i, 2]
    R = ximat
    I00 = R[i, 0] * J0 * R[i, 0] + R[i, 1] * J1 * R[i, 1] + R[i, 2] * J2 * R[i, 2]
    I11 = R[i, 3] * J0 * R[i, 3] + R[i, 4] * J1 * R[i, 4] + R[i, 5] * J2 * R[i, 5]
    I22 = R[i, 6] * J0 * R[i, 6] + R[i, 7] * J1 * R[i, 7] + R[i, 8] * J2 * R[i, 8]
    I01 = R[i, 0] * J0 * R[i, 3] + R[i, 1] * J1 * R[i, 4] + R[i, 2] * J2 * R[i, 5]
    I02 = R[i, 0] * J0 * R[i, 6] + R[i, 1] * J1 * R[i, 7] + R[i, 2] * J2 * R[i, 8]
    I12 = R[i, 3] * J0 * R[i, 6] + R[i, 4] * J1 * R[i, 7] + R[i, 5] * J2 * R[i, 8]
    I00 += m * (d1 * d1 + d2 * d2)
    I11 += m * (d0 * d0 + d2 * d2)
    I22 += m * (d0 * d0 + d1 * d1)
    I01 -= m * d0 * d1
    I02 -= m * d0 * d2
    I12 -= m * d1 * d2
    h0, h1, h2 = m * d0, m * d1, m * d2
    a0, a1, a2, a3, a4, a5 = cacc[i, 0], cacc[i, 1], cacc[i, 2], cacc[i, 3], cacc[i, 4], cacc[i, 5]
    v0, v1, v2, v3, v4, v5 = cvel[i, 0], cvel[i, 1], cvel[i, 2], cvel[i, 3], cvel[i, 4], cvel[i, 5]
    # mju_mulInertVec of the acceleration and of the velocity
    f0, f1, f2, f3, f4, f5 = _mul_inert(I00, I11, I22, I01, I02, I12, h0, h1, h2, m,
                                        a0, a1, a2, a3, a4, a5)
    g0, g1, g2, g3, g4, g5 = _mul_inert(I00, I11, I22, I01, I02, I12, h0, h1, h2, m,
                                        v0, v1, v2, v3, v4, v5)
    # mju_crossForce: [w x g_ang + v_lin x g_lin; w x g_lin]
    t0, t1, t2 = _cross(v0, v1, v2, g0, g1, g2)
    u0, u1, u2 = _cross(v3, v4, v5, g3, g4, g5)
    w0, w1, w2 = _cross(v0, v1, v2, g3, g4, g5)
    cfrc[i, 0] = f0 + t0 + u0
    cfrc[i, 1] = f1 + t1 + u1
    cfrc[i, 2] = f2 + t2 + u2
    cfrc[i, 3] = f3 + w0
    cfrc[i, 4] = f4 + w1
    cfrc[i, 5] = f5 + w2


@njit_nort(inline="always")
def _dynamics(qvel, qacc, gravity, body_parent, body_jntadr, body_jntnum, body_mass,
              jnt_type, jnt_dofadr, jnt_axis, jnt_pos, body_inertia, xpos, xmat, xipos, ximat,
              c, S, cvel, cacc, cfrc):
    """Forward pass (velocities, accelerations from the world's ``-gravity``, body forces)
    then the backward sum: ``cfrc[i]`` becomes the total of body ``i``'s subtree."""
    nb = body_parent.shape[0]
    for k in range(3):
        cvel[0, k] = 0.0
        cvel[0, 3 + k] = 0.0
        cacc[0, k] = 0.0
        cacc[0, 3 + k] = -gravity[k]
        for kk in range(2):
            cfrc[0, 3 * kk + k] = 0.0
    for i in range(1, nb):
        p = body_parent[i]
        for k in range(6):
            cvel[i, k] = cvel[p, k]
            cacc[i, k] = cacc[p, k]
        if body_jntnum[i] == 1:
            j = body_jntadr[i]
            _joint_motion(i, j, jnt_type[j], qvel, qacc, jnt_dofadr, jnt_axis, jnt_pos, xpos,
                          xmat, c, S, cvel, cacc)
        _body_force(i, body_mass[i], body_inertia, xipos, ximat, c, cvel, cacc, cfrc)
    for i in range(nb - 1, 0, -1):
        p = body_parent[i]
        for k in range(6):
            cfrc[p, k] += cfrc[i, k]


@njit_nort(inline="always")
def rne_sample(qpos_in, qvel, qacc, tree, site, dyn, sites, work):
    """Kinematics and inverse dynamics of one sample (no allocation).

    ``tree``: :meth:`TreeModel.arrays`; ``site``: ``(site_body, site_sameframe, site_pos,
    site_quat)``; ``dyn``: :meth:`RNEModel.dyn_arrays`; ``sites``: site ids whose poses go
    to ``work``'s ``site_xpos`` (k, 3), ``site_xmat`` (k, 9); ``work``: :func:`new_work`.
    Leaves in ``work``'s ``cfrc`` (nb, 6) the total spatial force ``[torque; force]`` of
    each body's subtree about the CoM (``work``'s ``com`` (3,)), ``I a + v x* I v`` with
    the world accelerating at ``-gravity``: row ``root`` is ``mj_rne``'s free-base
    generalized force before projection."""
    (body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos, body_quat, body_ipos,
     body_iquat, body_mass, jnt_type, jnt_qposadr, jnt_axis, jnt_pos, qpos0, body_order) = tree
    site_body, site_sameframe, site_pos, site_quat = site
    body_inertia, jnt_dofadr, gravity = dyn
    (qpos, xpos, xquat, xmat, xipos, ximat, stc, ms, com, S, cvel, cacc, cfrc, site_xpos,
     site_xmat) = work
    fk_bodies(qpos_in, body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos,
              body_quat, body_ipos, body_iquat, jnt_type, jnt_qposadr, jnt_axis, jnt_pos,
              qpos0, body_order, qpos, xpos, xquat, xmat, xipos, ximat)
    c0, c1, c2 = subtree_com_of(1, body_parent, body_mass, xipos, stc, ms)
    com[0], com[1], com[2] = c0, c1, c2
    fk_sites(sites, site_body, site_sameframe, site_pos, site_quat, xpos, xquat, xmat, xipos,
             ximat, site_xpos, site_xmat, com)
    _dynamics(qvel, qacc, gravity, body_parent, body_jntadr, body_jntnum, body_mass, jnt_type,
              jnt_dofadr, jnt_axis, jnt_pos, body_inertia, xpos, xmat, xipos, ximat, com, S,
              cvel, cacc, cfrc)


def new_work(model: RNEModel, n_sites: int) -> tuple:
    """Scratch arrays of :func:`rne_sample` (see there for the order)."""
    nb = model.tree.nbody
    frames = model.tree.new_frames()  # xpos, xquat, xmat, xipos, ximat, subtree_com
    return (np.zeros(model.tree.nq), *frames, np.zeros(nb), np.zeros(3), np.zeros((3, 6)),
            np.zeros((nb, 6)), np.zeros((nb, 6)), np.zeros((nb, 6)), np.zeros((n_sites, 3)),
            np.zeros((n_sites, 9)))


@njit_nort(inline="always")
def _share(w0, w1, F2, tau0, tau1, pr0, pr1, pl0, pl1):
    """Right foot's load share: the planned stance if one foot, else the CoP of the total
    wrench (given at the right sole) projected on the segment between the soles."""
    if w0 == 0.0 or w1 == 0.0 or F2 < 1e-6:
        return w0, w1
    cx = pr0 + (-tau1) / F2
    cy = pr1 + tau0 / F2
    dx, dy = pr0 - pl0, pr1 - pl1
    a = ((cx - pl0) * dx + (cy - pl1) * dy) / (dx * dx + dy * dy)
    a = min(max(a, 0.0), 1.0)
    return a, 1.0 - a


@njit_nort(inline="always")
def sample_wrenches(w0, w1, root, feet, ft, work, ground, ft_out):
    """Ground wrench ``[force; torque]`` at each sole (``ground`` (2, 6), world axes) and,
    when ``ft``, the F/T readings of the foot bodies ``feet`` (2,) (``ft_out`` (2, 6),
    sensor axes, foot on leg), from :func:`rne_sample`'s ``work`` with sites (sole r,
    sole l, F/T r, F/T l)."""
    com, cfrc, site_xpos, site_xmat = work[8], work[12], work[13], work[14]
    F0, F1, F2 = cfrc[root, 3], cfrc[root, 4], cfrc[root, 5]
    for i in range(2):  # the wrench at sole i alone: tau_c + (c - p_i) x F
        m0, m1, m2 = _cross(com[0] - site_xpos[i, 0], com[1] - site_xpos[i, 1],
                            com[2] - site_xpos[i, 2], F0, F1, F2)
        ground[i, 0], ground[i, 1], ground[i, 2] = F0, F1, F2
        ground[i, 3] = cfrc[root, 0] + m0
        ground[i, 4] = cfrc[root, 1] + m1
        ground[i, 5] = cfrc[root, 2] + m2
    s0, s1 = _share(w0, w1, F2, ground[0, 3], ground[0, 4], site_xpos[0, 0],
                    site_xpos[0, 1], site_xpos[1, 0], site_xpos[1, 1])
    for k in range(6):
        ground[0, k] *= s0
        ground[1, k] *= s1
    if not ft:
        return
    for i in range(2):
        b = feet[i]
        g0, g1, g2 = ground[i, 0], ground[i, 1], ground[i, 2]
        e0, e1, e2 = _cross(site_xpos[i, 0] - com[0], site_xpos[i, 1] - com[1],
                            site_xpos[i, 2] - com[2], g0, g1, g2)
        # cfrc_int of the foot body (mj_rnePostConstraint with the ground wrench applied)
        fo0, fo1, fo2 = cfrc[b, 3] - g0, cfrc[b, 4] - g1, cfrc[b, 5] - g2
        tq0 = cfrc[b, 0] - (ground[i, 3] + e0)
        tq1 = cfrc[b, 1] - (ground[i, 4] + e1)
        tq2 = cfrc[b, 2] - (ground[i, 5] + e2)
        s = 2 + i
        r0, r1, r2 = _cross(site_xpos[s, 0] - com[0], site_xpos[s, 1] - com[1],
                            site_xpos[s, 2] - com[2], fo0, fo1, fo2)
        tq0, tq1, tq2 = tq0 - r0, tq1 - r1, tq2 - r2
        R = site_xmat
        for a in range(3):  # -(R^T f), -(R^T tau)
            ft_out[i, a] = -(R[s, a] * fo0 + R[s, 3 + a] * fo1 + R[s, 6 + a] * fo2)
            ft_out[i, 3 + a] = -(R[s, a] * tq0 + R[s, 3 + a] * tq1 + R[s, 6 + a] * tq2)


@njit
def wrench_batch(Qpos, Qvel, Qacc, W, tree, site, dyn, sites, work, root, feet, ft, ground,
                 ft_out):
    """:func:`rne_sample` and :func:`sample_wrenches` over a log: ``Qpos`` (T, nq), ``Qvel``,
    ``Qacc`` (T, nv), stance weights ``W`` (T, 2) -> ``ground``, ``ft_out`` (T, 2, 6)."""
    for t in range(Qpos.shape[0]):
        rne_sample(Qpos[t], Qvel[t], Qacc[t], tree, site, dyn, sites, work)
        sample_wrenches(W[t, 0], W[t, 1], root, feet, ft, work, ground[t], ft_out[t])


@njit
def frames_batch(Q, tree, site, sites, out_pos, out_mat):
    """World poses of ``sites`` (k,) for every row of ``Q`` (T, nq): ``out_pos`` (T, k, 3),
    ``out_mat`` (T, k, 9) (row-major rotation)."""
    (body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos, body_quat, body_ipos,
     body_iquat, body_mass, jnt_type, jnt_qposadr, jnt_axis, jnt_pos, qpos0, body_order) = tree
    site_body, site_sameframe, site_pos, site_quat = site
    nb = body_parent.shape[0]
    qpos = np.empty(qpos0.shape[0])
    xpos, xquat, xmat = np.empty((nb, 3)), np.empty((nb, 4)), np.empty((nb, 9))
    xipos, ximat = np.empty((nb, 3)), np.empty((nb, 9))
    for t in range(Q.shape[0]):
        fk_bodies(Q[t], body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos,
                  body_quat, body_ipos, body_iquat, jnt_type, jnt_qposadr, jnt_axis, jnt_pos,
                  qpos0, body_order, qpos, xpos, xquat, xmat, xipos, ximat)
        fk_sites(sites, site_body, site_sameframe, site_pos, site_quat, xpos, xquat, xmat,
                 xipos, ximat, out_pos[t], out_mat[t], qpos)


# ------------------------------------------------- hinge trees: fixed bodies merged, fused
def _qmat(q) -> np.ndarray:
    """3x3 rotation of a MuJoCo quaternion (normalised)."""
    import mujoco

    r = np.zeros(9)
    mujoco.mju_quat2Mat(r, np.asarray(q, float) / np.linalg.norm(q))
    return r.reshape(3, 3)


@dataclass(frozen=True)
class HingeTree:
    """A free-floating tree of hinge joints with every fixed body (no joint) merged into
    its nearest moving ancestor, for :func:`hinge_wrench_batch`. URDF trees (Talos: 60
    bodies, 33 moving; G1: 39, 30) are of this kind.

    Moving body ``i`` (index 0 the base; by depth, parents first) has its frame at
    ``R_i = R_p L_i``, ``x_i = x_p + R_p (u0 + c u1 + s u2)`` from its parent ``p``'s and
    the joint angle's cosine ``c`` and sine ``s``: ``L_i = B0 + c B1 + s B2`` is the
    fixed offset rotation ``O`` times Rodrigues' ``Rot(a, angle) = a a^T + c (I - a a^T)
    + s [a]x`` (``B0 = O a a^T``, ``B1 = O - B0``, ``B2 = O [a]x``); ``u0 + c u1 + s u2``
    the offset of the body origin, moved by the rotation about the anchor ``j``
    (``u0 = o + O j - B0 j``, ``u1 = -B1 j``, ``u2 = -B2 j``). The joint's axis is
    ``R_p O a`` through ``x_p + R_p (o + O j)``. No branch per body: any axis, anchor
    and offset take the same arithmetic.

    Array shapes: ``n`` moving bodies, ``k`` sites."""

    parent: np.ndarray  # (n,) int64, -1 for the base
    B: np.ndarray  # (n, 3, 9) B0, B1, B2 row-major
    u: np.ndarray  # (n, 3, 3) u0, u1, u2
    axis: np.ndarray  # (n, 3) O a
    anchor: np.ndarray  # (n, 3) o + O j
    qcol: np.ndarray  # (n,) int64: column of the joint in q, qd, qdd (-1: still at qpos0)
    q0: np.ndarray  # (n,) the joint's qpos0 (its zero angle)
    mass: np.ndarray  # (n,)
    com: np.ndarray  # (n, 3) body frame
    inertia: np.ndarray  # (n, 6) xx, yy, zz, xy, xz, yz about the CoM, body axes
    foot_bodies: np.ndarray  # (m,) int64: the bodies of foot 0's subtree, then foot 1's
    foot_ptr: np.ndarray  # (3,) int64: foot f's are foot_bodies[foot_ptr[f]:foot_ptr[f+1]]
    site_body: np.ndarray  # (k,) int64 moving body of each chosen site
    site_pos: np.ndarray  # (k, 3)
    site_rot: np.ndarray  # (k, 9)

    @classmethod
    def from_mujoco(cls, model, qpos_cols, sites, feet) -> HingeTree | None:
        """The merged tree of ``model`` (None when it is not a free base with hinges
        only, one joint per body, every body below the base). ``qpos_cols``: qpos
        address -> column of the joint's angle in the caller's ``q`` (joints not listed
        stay at ``qpos0``); ``sites``, ``feet``: site and body ids (a foot must have a
        joint)."""
        m = model
        nb = int(m.nbody)
        if (int(m.body_jntnum[1]) != 1 or int(m.jnt_type[m.body_jntadr[1]]) != FREE
                or any(int(m.body_rootid[b]) != 1 for b in range(1, nb))
                or any(int(m.body_jntnum[b]) > 1 for b in range(nb))
                or any(int(t) != HINGE for t in np.asarray(m.jnt_type)[1:])
                or any(int(m.body_jntnum[f]) != 1 for f in feet)):
            return None
        anc, P, Rm = [0] * nb, [np.zeros(3)] * nb, [np.eye(3)] * nb
        moving = [1]
        rows: list[tuple] = [(-1, np.zeros(3), np.eye(3), -1)]
        for b in range(2, nb):
            pb = int(m.body_parentid[b])
            pos = P[pb] + Rm[pb] @ m.body_pos[b]
            rot = Rm[pb] @ _qmat(m.body_quat[b])
            if int(m.body_jntnum[b]) == 1:
                anc[b] = len(moving)
                moving.append(b)
                rows.append((anc[pb], pos, rot, int(m.body_jntadr[b])))
            else:
                anc[b], P[b], Rm[b] = anc[pb], pos, rot
        return cls._build(m, moving, anc, P, Rm, rows, qpos_cols, sites, feet)

    @staticmethod
    def _inertias(m, n, anc, P, Rm) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Merged mass, CoM (moving body's frame) and inertia about it, per moving body."""
        mass, first, second = np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3, 3))
        for b in range(1, int(m.nbody)):
            a, mb = anc[b], float(m.body_mass[b])
            c = P[b] + Rm[b] @ m.body_ipos[b]
            Ri = Rm[b] @ _qmat(m.body_iquat[b])
            mass[a] += mb
            first[a] += mb * c
            second[a] += Ri @ np.diag(m.body_inertia[b]) @ Ri.T + mb * (
                (c @ c) * np.eye(3) - np.outer(c, c))
        com = first / np.maximum(mass, 1e-300)[:, None]
        inert = np.zeros((n, 6))
        for a in range(n):
            c = com[a]
            Ic = second[a] - mass[a] * ((c @ c) * np.eye(3) - np.outer(c, c))
            inert[a] = Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2]
        return mass, com, inert

    @staticmethod
    def _joint(m, row, qpos_cols) -> tuple:
        """``B`` (3, 9), ``u`` (3, 3), axis, anchor, column and zero angle of a body's
        hinge (class docstring)."""
        _, o, O, j = row
        if j < 0:  # the base
            return (np.stack([np.zeros(9), np.eye(3).ravel(), np.zeros(9)]), np.zeros((3, 3)),
                    np.zeros(3), np.zeros(3), -1, 0.0)
        a = np.asarray(m.jnt_axis[j], float)
        jp = np.asarray(m.jnt_pos[j], float)
        K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
        B0 = O @ np.outer(a, a)
        B1, B2 = O - B0, O @ K
        u = np.stack([o + O @ jp - B0 @ jp, -B1 @ jp, -B2 @ jp])
        adr = int(m.jnt_qposadr[j])
        return (np.stack([B0.ravel(), B1.ravel(), B2.ravel()]), u, O @ a, o + O @ jp,
                qpos_cols.get(adr, -1), float(m.qpos0[adr]))

    @classmethod
    def _build(cls, m, moving, anc, P, Rm, rows, qpos_cols, sites, feet) -> HingeTree:
        n = len(moving)
        mass, com, inert = cls._inertias(m, n, anc, P, Rm)
        B, u, axis, anchor, qcol, q0 = (np.array(x) for x in zip(
            *(cls._joint(m, r, qpos_cols) for r in rows), strict=True))
        # by depth, the branches of one depth next to each other (the CPU overlaps them)
        par = np.array([r[0] for r in rows], np.int64)
        depth = np.zeros(n, np.int64)
        for a in range(1, n):
            depth[a] = depth[par[a]] + 1
        o = np.argsort(depth, kind="stable")
        inv = np.empty(n, np.int64)
        inv[o] = np.arange(n)
        par = np.where(par[o] < 0, -1, inv[np.maximum(par[o], 0)])
        under = []
        for fb in feet:  # moving bodies in each foot's subtree (new indices)
            sub = [a for a, b in enumerate(moving) if _descends(m, b, fb)]
            under.append(sorted(int(inv[a]) for a in sub))
        sb = [int(m.site_bodyid[s]) for s in sites]

        def c(x, dt=float):
            return np.ascontiguousarray(x, dtype=dt)

        return cls(parent=c(par, np.int64), B=c(B[o]), u=c(u[o]), axis=c(axis[o]),
                   anchor=c(anchor[o]), qcol=c(qcol[o], np.int64), q0=c(q0[o]),
                   mass=c(mass[o]), com=c(com[o]), inertia=c(inert[o]),
                   foot_bodies=c([a for f in under for a in f], np.int64),
                   foot_ptr=c(np.cumsum([0] + [len(f) for f in under]), np.int64),
                   site_body=c([inv[anc[b]] for b in sb], np.int64),
                   site_pos=c([P[b] + Rm[b] @ m.site_pos[s] for b, s in zip(sb, sites,
                                                                             strict=True)]),
                   site_rot=c([(Rm[b] @ _qmat(m.site_quat[s])).ravel()
                               for b, s in zip(sb, sites, strict=True)]))

    def arrays(self) -> tuple:
        """The arrays in the argument order of the kernels."""
        return (self.parent, self.B, self.u, self.axis, self.anchor, self.qcol, self.q0,
                self.mass, self.com, self.inertia, self.foot_bodies, self.foot_ptr,
                self.site_body, self.site_pos, self.site_rot)


def _descends(m, b: int, top: int) -> bool:
    """Body ``b`` is ``top`` or below it."""
    while b > 0 and b != top:
        b = int(m.body_parentid[b])
    return b == top


#: Samples whose joint angles :func:`_block_sincos` takes at once.
SC_BLOCK = 64
assert SC_BLOCK % LANES == 0  # whole groups of lanes (the last one padded)


@njit_nort(inline="always")
def _block_sincos(t0, nt, q, qcol, q0, bodies, TH, SN, CS):
    """Sines and cosines of the joint angles of bodies ``bodies`` (k of them) for the
    samples ``t0 .. t0 + nt - 1``, lane-major for :func:`~grfguard.kernels.lanes.vload`:
    sample ``t0 + g LANES + j``'s at entry ``(g k + b) LANES + j`` of ``SN``, ``CS`` (the
    angle 0 for a body whose joint is not in ``q``; lanes past ``nt`` repeat the last
    sample)."""
    k = bodies.shape[0]
    ng = (nt + LANES - 1) // LANES
    for g in range(ng):
        for b in range(k):
            i = bodies[b]
            c = qcol[i]
            for j in range(LANES):
                t = t0 + min(g * LANES + j, nt - 1)
                TH[(g * k + b) * LANES + j] = q[t, max(c, 0)] - q0[i] if c >= 0 else 0.0
    sincos_flat(TH, ng * k * LANES, SN, CS)


@njit_nort(inline="always")
def _ht_pose(i, p, c, s, B, u, axis, anchor, R, X, S):
    """Body ``i``'s rotation ``R[i]`` and origin ``X[i]`` from its parent ``p``'s and its
    joint's ``cos``, ``sin`` (:class:`HingeTree`); its joint's motion ``S[i] = [s; x x
    s]`` (axis ``s`` through the anchor ``x``; spatial vectors ``[angular; linear]``
    about the origin). Computed into locals, stored once, no branch."""
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = (R[p, 0], R[p, 1], R[p, 2], R[p, 3], R[p, 4],
                                          R[p, 5], R[p, 6], R[p, 7], R[p, 8])
    L = (B[i, 0, 0] + c * B[i, 1, 0] + s * B[i, 2, 0], B[i, 0, 1] + c * B[i, 1, 1] + s * B[i, 2, 1],
         B[i, 0, 2] + c * B[i, 1, 2] + s * B[i, 2, 2], B[i, 0, 3] + c * B[i, 1, 3] + s * B[i, 2, 3],
         B[i, 0, 4] + c * B[i, 1, 4] + s * B[i, 2, 4], B[i, 0, 5] + c * B[i, 1, 5] + s * B[i, 2, 5],
         B[i, 0, 6] + c * B[i, 1, 6] + s * B[i, 2, 6], B[i, 0, 7] + c * B[i, 1, 7] + s * B[i, 2, 7],
         B[i, 0, 8] + c * B[i, 1, 8] + s * B[i, 2, 8])
    n0, n1, n2, n3, n4, n5, n6, n7, n8 = _mm(r0, r1, r2, r3, r4, r5, r6, r7, r8, L[0], L[1],
                                             L[2], L[3], L[4], L[5], L[6], L[7], L[8])
    R[i, 0], R[i, 1], R[i, 2], R[i, 3], R[i, 4] = n0, n1, n2, n3, n4
    R[i, 5], R[i, 6], R[i, 7], R[i, 8] = n5, n6, n7, n8
    d0, d1, d2 = _mv(r0, r1, r2, r3, r4, r5, r6, r7, r8, u[i, 0, 0] + c * u[i, 1, 0] + s
                     * u[i, 2, 0], u[i, 0, 1] + c * u[i, 1, 1] + s * u[i, 2, 1],
                     u[i, 0, 2] + c * u[i, 1, 2] + s * u[i, 2, 2])
    X[i, 0], X[i, 1], X[i, 2] = X[p, 0] + d0, X[p, 1] + d1, X[p, 2] + d2
    s0, s1, s2 = _mv(r0, r1, r2, r3, r4, r5, r6, r7, r8, axis[i, 0], axis[i, 1], axis[i, 2])
    a0, a1, a2 = _mv(r0, r1, r2, r3, r4, r5, r6, r7, r8, anchor[i, 0], anchor[i, 1],
                     anchor[i, 2])
    l0, l1, l2 = _cross(X[p, 0] + a0, X[p, 1] + a1, X[p, 2] + a2, s0, s1, s2)
    S[i, 0], S[i, 1], S[i, 2], S[i, 3], S[i, 4], S[i, 5] = s0, s1, s2, l0, l1, l2


@njit_nort(inline="always")
def _ht_motion(i, p, qd, qdd, S, V, A):
    """``V[i] = V[p] + S[i] qd``, ``A[i] = A[p] + (V[p] x S[i]) qd + S[i] qdd``."""
    s0, s1, s2, l0, l1, l2 = S[i, 0], S[i, 1], S[i, 2], S[i, 3], S[i, 4], S[i, 5]
    w0, w1, w2 = V[p, 0], V[p, 1], V[p, 2]
    d0, d1, d2 = _cross(w0, w1, w2, s0, s1, s2)
    e0, e1, e2 = _cross(w0, w1, w2, l0, l1, l2)
    f0, f1, f2 = _cross(V[p, 3], V[p, 4], V[p, 5], s0, s1, s2)
    A[i, 0] = A[p, 0] + d0 * qd + s0 * qdd
    A[i, 1] = A[p, 1] + d1 * qd + s1 * qdd
    A[i, 2] = A[p, 2] + d2 * qd + s2 * qdd
    A[i, 3] = A[p, 3] + (e0 + f0) * qd + l0 * qdd
    A[i, 4] = A[p, 4] + (e1 + f1) * qd + l1 * qdd
    A[i, 5] = A[p, 5] + (e2 + f2) * qd + l2 * qdd
    V[i, 0], V[i, 1], V[i, 2] = w0 + s0 * qd, w1 + s1 * qd, w2 + s2 * qd
    V[i, 3], V[i, 4], V[i, 5] = V[p, 3] + l0 * qd, V[p, 4] + l1 * qd, V[p, 5] + l2 * qd


@njit_nort(inline="always")
def _ht_force(i, mass, com, inertia, R, X, V, A, Fb):
    """Body ``i``'s ``I a + v x* I v`` (Newton-Euler at its CoM, moved to the origin:
    ``[torque; force]``) into ``Fb[i]``."""
    m = mass[i]
    c0, c1, c2 = _mv(R[i, 0], R[i, 1], R[i, 2], R[i, 3], R[i, 4], R[i, 5], R[i, 6],
                     R[i, 7], R[i, 8], com[i, 0], com[i, 1], com[i, 2])
    c0, c1, c2 = c0 + X[i, 0], c1 + X[i, 1], c2 + X[i, 2]
    w0, w1, w2 = V[i, 0], V[i, 1], V[i, 2]
    u0, u1, u2 = _cross(w0, w1, w2, c0, c1, c2)
    v0, v1, v2 = V[i, 3] + u0, V[i, 4] + u1, V[i, 5] + u2  # the CoM's velocity
    b0, b1, b2 = _cross(A[i, 0], A[i, 1], A[i, 2], c0, c1, c2)
    e0, e1, e2 = _cross(w0, w1, w2, v0, v1, v2)
    F0, F1, F2 = m * (A[i, 3] + b0 + e0), m * (A[i, 4] + b1 + e1), m * (A[i, 5] + b2 + e2)
    # rotational part in body axes: J alpha + w x J w
    o0 = R[i, 0] * w0 + R[i, 3] * w1 + R[i, 6] * w2
    o1 = R[i, 1] * w0 + R[i, 4] * w1 + R[i, 7] * w2
    o2 = R[i, 2] * w0 + R[i, 5] * w1 + R[i, 8] * w2
    al0 = R[i, 0] * A[i, 0] + R[i, 3] * A[i, 1] + R[i, 6] * A[i, 2]
    al1 = R[i, 1] * A[i, 0] + R[i, 4] * A[i, 1] + R[i, 7] * A[i, 2]
    al2 = R[i, 2] * A[i, 0] + R[i, 5] * A[i, 1] + R[i, 8] * A[i, 2]
    Jxx, Jyy, Jzz, Jxy, Jxz, Jyz = (inertia[i, 0], inertia[i, 1], inertia[i, 2],
                                     inertia[i, 3], inertia[i, 4], inertia[i, 5])
    L0 = Jxx * o0 + Jxy * o1 + Jxz * o2
    L1 = Jxy * o0 + Jyy * o1 + Jyz * o2
    L2 = Jxz * o0 + Jyz * o1 + Jzz * o2
    g0, g1, g2 = _cross(o0, o1, o2, L0, L1, L2)
    t0 = Jxx * al0 + Jxy * al1 + Jxz * al2 + g0
    t1 = Jxy * al0 + Jyy * al1 + Jyz * al2 + g1
    t2 = Jxz * al0 + Jyz * al1 + Jzz * al2 + g2
    T0, T1, T2 = _mv(R[i, 0], R[i, 1], R[i, 2], R[i, 3], R[i, 4], R[i, 5], R[i, 6],
                     R[i, 7], R[i, 8], t0, t1, t2)
    h0, h1, h2 = _cross(c0, c1, c2, F0, F1, F2)
    Fb[i, 0], Fb[i, 1], Fb[i, 2] = T0 + h0, T1 + h1, T2 + h2
    Fb[i, 3], Fb[i, 4], Fb[i, 5] = F0, F1, F2


@njit_nort(inline="always")
def _ht_base(t, base, g, R, X, V, A):
    """The base (body 0): identity pose, velocity ``[omega; R_WB^T v_B]``, spatial
    acceleration ``[alpha; R_WB^T (a_B - g) - omega x v]`` (base axes)."""
    Rw, vB, wB, aB, alB = base[0][t], base[1][t], base[2][t], base[3][t], base[4][t]
    for k in range(9):
        R[0, k] = 0.0
    R[0, 0], R[0, 4], R[0, 8] = 1.0, 1.0, 1.0
    X[0, 0], X[0, 1], X[0, 2] = 0.0, 0.0, 0.0
    for r in range(3):
        v = Rw[0, r] * vB[0] + Rw[1, r] * vB[1] + Rw[2, r] * vB[2]
        a = (Rw[0, r] * (aB[0] - g[0]) + Rw[1, r] * (aB[1] - g[1])
             + Rw[2, r] * (aB[2] - g[2]))
        V[0, r], V[0, 3 + r], A[0, r], A[0, 3 + r] = wB[r], v, alB[r], a
    c0, c1, c2 = _cross(wB[0], wB[1], wB[2], V[0, 3], V[0, 4], V[0, 5])
    A[0, 3], A[0, 4], A[0, 5] = A[0, 3] - c0, A[0, 4] - c1, A[0, 5] - c2


@njit_nort(inline="always")
def _site_pose(k, site_body, site_pos, site_rot, R, X, pos, rot):
    """Site ``k``'s origin into ``pos`` (3,) and, when ``rot`` has 9 entries, its
    rotation (row-major)."""
    b = site_body[k]
    p0, p1, p2 = _mv(R[b, 0], R[b, 1], R[b, 2], R[b, 3], R[b, 4], R[b, 5], R[b, 6],
                     R[b, 7], R[b, 8], site_pos[k, 0], site_pos[k, 1], site_pos[k, 2])
    pos[0], pos[1], pos[2] = p0 + X[b, 0], p1 + X[b, 1], p2 + X[b, 2]
    if rot.shape[0] == 9:
        for r in range(3):
            for c in range(3):
                rot[3 * r + c] = (R[b, 3 * r] * site_rot[k, c] + R[b, 3 * r + 1]
                                  * site_rot[k, 3 + c] + R[b, 3 * r + 2] * site_rot[k, 6 + c])


@njit_nort(inline="always")
def _ht_wrenches(t, w0, w1, Rw, ft, ht, R, X, tot, P, rot, gb, ground, ft_out):
    """Sample ``t``'s ground wrench at each sole (world axes) and, when ``ft``, the F/T
    readings, from the subtree forces ``tot`` of :func:`_ht_lanes` (sites: sole r, sole l,
    F/T r, F/T l). ``P`` (4, 3), ``rot`` (9,), ``gb`` (2, 6): scratch."""
    site_body, site_pos, site_rot = ht[12], ht[13], ht[14]
    F0, F1, F2 = tot[0, 3], tot[0, 4], tot[0, 5]
    for i in range(2):  # the wrench at sole i alone: tau_o - p_i x F (base axes), in world
        _site_pose(i, site_body, site_pos, site_rot, R, X, P[i], rot[:0])
        m0, m1, m2 = _cross(P[i, 0], P[i, 1], P[i, 2], F0, F1, F2)
        gb[i, 0], gb[i, 1], gb[i, 2] = F0, F1, F2
        gb[i, 3], gb[i, 4], gb[i, 5] = tot[0, 0] - m0, tot[0, 1] - m1, tot[0, 2] - m2
        for r in range(3):
            ground[t, i, r] = Rw[r, 0] * F0 + Rw[r, 1] * F1 + Rw[r, 2] * F2
            ground[t, i, 3 + r] = Rw[r, 0] * gb[i, 3] + Rw[r, 1] * gb[i, 4] + Rw[r, 2] * gb[i, 5]
    pr0 = Rw[0, 0] * P[0, 0] + Rw[0, 1] * P[0, 1] + Rw[0, 2] * P[0, 2]
    pr1 = Rw[1, 0] * P[0, 0] + Rw[1, 1] * P[0, 1] + Rw[1, 2] * P[0, 2]
    pl0 = Rw[0, 0] * P[1, 0] + Rw[0, 1] * P[1, 1] + Rw[0, 2] * P[1, 2]
    pl1 = Rw[1, 0] * P[1, 0] + Rw[1, 1] * P[1, 1] + Rw[1, 2] * P[1, 2]
    s0, s1 = _share(w0, w1, ground[t, 0, 2], ground[t, 0, 3], ground[t, 0, 4], pr0, pr1,
                    pl0, pl1)
    for k in range(6):
        ground[t, 0, k] *= s0
        ground[t, 1, k] *= s1
        gb[0, k] *= s0
        gb[1, k] *= s1
    if not ft:
        return
    for i in range(2):  # the foot's subtree force minus the ground's: the force on the leg
        fo0, fo1, fo2 = tot[1 + i, 3] - gb[i, 0], tot[1 + i, 4] - gb[i, 1], tot[1 + i, 5] - gb[i, 2]
        e0, e1, e2 = _cross(P[i, 0], P[i, 1], P[i, 2], gb[i, 0], gb[i, 1], gb[i, 2])
        tq0 = tot[1 + i, 0] - (gb[i, 3] + e0)
        tq1 = tot[1 + i, 1] - (gb[i, 4] + e1)
        tq2 = tot[1 + i, 2] - (gb[i, 5] + e2)
        _site_pose(2 + i, site_body, site_pos, site_rot, R, X, P[2 + i], rot)
        r0, r1, r2 = _cross(P[2 + i, 0], P[2 + i, 1], P[2 + i, 2], fo0, fo1, fo2)
        tq0, tq1, tq2 = tq0 - r0, tq1 - r1, tq2 - r2
        for a in range(3):  # -(R^T f), -(R^T tau): sensor axes
            ft_out[t, i, a] = -(rot[a] * fo0 + rot[3 + a] * fo1 + rot[6 + a] * fo2)
            ft_out[t, i, 3 + a] = -(rot[a] * tq0 + rot[3 + a] * tq1 + rot[6 + a] * tq2)


@njit_nort(inline="always")
def _ht_lanes(t, lt, nreal, n, qd, qdd, base, g, ht, SN, CS, L, vw, sw, W, ft, ground, ft_out):
    """Samples ``t .. t + nreal - 1`` (``nreal`` <= :data:`~grfguard.kernels.lanes.LANES`)
    in vector lanes: kinematics and the subtree forces (the whole tree's, foot 0's, foot
    1's; ``[torque; force]`` about the base origin, base axes) with one pass per stage
    over the bodies (poses, motions, forces: each body's work is short, so the CPU
    overlaps the bodies of different branches), then each sample's :func:`_ht_wrenches`
    alone. Lanes past ``nreal`` repeat the last sample and are not written.

    ``lt``: the samples' first row in the block of ``SN``, ``CS`` (a multiple of LANES;
    the sines and cosines of the bodies' joint angles, :func:`_block_sincos`). ``base``:
    ``(R_WB, v_B, omega_B, a_B, alpha_B)``, the base's attitude, world linear velocity and
    acceleration of its origin, body-axes angular velocity and acceleration (MuJoCo's
    free-joint ``qvel``, ``qacc``); the world accelerates at ``-g``. ``L`` ((2 n + 12)
    LANES): lane-major scratch (rates, base motion); ``vw``: the vector arrays ``(R, X,
    S, V, A, F, tot)``; ``sw``: one sample's scalar rows ``(R, X, V, A, tot)`` and
    :func:`_ht_wrenches`' scratch ``(P, rot, gb)``."""
    (parent, B, u, axis, anchor, qcol, q0, mass, com, inertia, foot_bodies,
     foot_ptr) = ht[:12]
    site_body = ht[12]
    Rv, Xv, Sv, Vv, Av, Fv, totv = vw
    Rs, Xs, Vs, As, tots, P, rot, gb = sw
    for j in range(LANES):  # lane-major copies of the rates and the base motion
        jj = min(j, nreal - 1)
        _ht_base(t + jj, base, g, Rs, Xs, Vs, As)
        for k in range(6):
            L[(2 * n + k) * LANES + j] = Vs[0, k]
            L[(2 * n + 6 + k) * LANES + j] = As[0, k]
        for i in range(1, n):
            c = qcol[i]
            L[i * LANES + j] = qd[t + jj, c] if c >= 0 else 0.0
            L[(n + i) * LANES + j] = qdd[t + jj, c] if c >= 0 else 0.0
    for k in range(6):  # the base: its pose (identity) is set once by the caller
        Vv[0, k] = vload(L, (2 * n + k) * LANES)
        Av[0, k] = vload(L, (2 * n + 6 + k) * LANES)
    g0 = lt // LANES * n
    for i in range(1, n):
        _ht_pose(i, parent[i], vload(CS, (g0 + i) * LANES), vload(SN, (g0 + i) * LANES), B, u,
                 axis, anchor, Rv, Xv, Sv)
    for i in range(1, n):
        _ht_motion(i, parent[i], vload(L, i * LANES), vload(L, (n + i) * LANES), Sv, Vv, Av)
    for i in range(n):
        _ht_force(i, mass, com, inertia, Rv, Xv, Vv, Av, Fv)
    for r in range(3):
        for k in range(6):
            totv[r, k] = splat(0.0)
    for i in range(n):
        for k in range(6):
            totv[0, k] += Fv[i, k]
    for f in range(foot_ptr.shape[0] - 1):
        for m in range(foot_ptr[f], foot_ptr[f + 1]):
            i = foot_bodies[m]
            for k in range(6):
                totv[1 + f, k] += Fv[i, k]
    for j in range(nreal):
        _lane_rows(j, site_body, Rv, Xv, Rs, Xs)
        for r in range(3):
            for k in range(6):
                tots[r, k] = lane(totv[r, k], j)
        _ht_wrenches(t + j, W[t + j, 0], W[t + j, 1], base[0][t + j], ft, ht, Rs, Xs, tots,
                     P, rot, gb, ground, ft_out)


@njit_nort(inline="always")
def _lane_rows(j, bodies, Rv, Xv, R, X):
    """Lane ``j`` of the vector rows ``Rv``, ``Xv`` of ``bodies`` into ``R``, ``X``."""
    for s in range(bodies.shape[0]):
        b = bodies[s]
        for k in range(9):
            R[b, k] = lane(Rv[b, k], j)
        for k in range(3):
            X[b, k] = lane(Xv[b, k], j)


@njit
def hinge_wrench_batch(q, qd, qdd, base, W, g, ht, ft, ground, ft_out):
    """Ground wrenches ``ground`` (T, 2, 6) (``[force; torque]`` at the soles, world
    axes, shared by the stance weights ``W`` (T, 2) as :func:`sample_wrenches` does) and,
    when ``ft``, the F/T readings ``ft_out`` (T, 2, 6) of a :class:`HingeTree` (``ht``:
    its :meth:`HingeTree.arrays`, sites sole r, sole l[, F/T r, F/T l]) over a log:
    joint angles ``q``, rates ``qd``, ``qdd`` (T, nj) in the tree's ``qcol`` columns;
    ``base``: ``(R_WB (T, 3, 3), v_B, omega_B, a_B, alpha_B (T, 3))`` (see
    :func:`_ht_lanes`); ``g`` (3,) gravity. Base at the origin; the arithmetic is in
    base axes about the base origin (one kinematics and dynamics pass over the moving
    bodies), the same physics as :func:`rne_sample` and :func:`sample_wrenches`.
    Samples go :data:`~grfguard.kernels.lanes.LANES` at a time through vector lanes
    (:func:`_ht_lanes`; each lane computes the bits of scalar code)."""
    n = ht[0].shape[0]
    R, X, V, A = np.empty((n, 9)), np.empty((n, 3)), np.empty((n, 6)), np.empty((n, 6))
    tot, P, rot, gb = np.empty((3, 6)), np.empty((4, 3)), np.empty(9), np.empty((2, 6))
    # the vector arrays borrow these buffers (kept alive by the last statement)
    bR, bX, bS = np.empty(lanes_size(n, 9)), np.empty(lanes_size(n, 3)), np.empty(lanes_size(n, 6))
    bV, bA, bF = np.empty(lanes_size(n, 6)), np.empty(lanes_size(n, 6)), np.empty(lanes_size(n, 6))
    btot = np.empty(lanes_size(3, 6))
    Rv, Xv, Sv = lanes2d(bR, n, 9), lanes2d(bX, n, 3), lanes2d(bS, n, 6)
    Vv, Av, Fv = lanes2d(bV, n, 6), lanes2d(bA, n, 6), lanes2d(bF, n, 6)
    totv = lanes2d(btot, 3, 6)
    for k in range(9):
        Rv[0, k] = splat(1.0 if k % 4 == 0 else 0.0)
    for k in range(3):
        Xv[0, k] = splat(0.0)
    vw, sw = (Rv, Xv, Sv, Vv, Av, Fv, totv), (R, X, V, A, tot, P, rot, gb)
    L = np.empty((2 * n + 12) * LANES)
    every = np.arange(n)
    TH, SN, CS = np.empty(SC_BLOCK * n), np.empty(SC_BLOCK * n), np.empty(SC_BLOCK * n)
    T = q.shape[0]
    for t0 in range(0, T, SC_BLOCK):
        nt = min(SC_BLOCK, T - t0)
        _block_sincos(t0, nt, q, ht[5], ht[6], every, TH, SN, CS)
        for lt in range(0, nt, LANES):
            _ht_lanes(t0 + lt, lt, min(LANES, nt - lt), n, qd, qdd, base, g, ht, SN, CS, L, vw,
                      sw, W, ft, ground, ft_out)
    bR[0] = bX[0] = bS[0] = bV[0] = bA[0] = bF[0] = btot[0] = 0.0


def site_paths(ht: HingeTree) -> np.ndarray:
    """The moving bodies from the base to the tree's sites (parents first, base left out):
    all :func:`hinge_frames_batch` needs."""
    need: set[int] = set()
    for b in ht.site_body:
        b = int(b)
        while b > 0:
            need.add(b)
            b = int(ht.parent[b])
    return np.array(sorted(need), np.int64)


@njit
def hinge_frames_batch(q, ht, bodies, out_pos, out_mat):
    """Poses of the :class:`HingeTree`'s sites in base axes (base at the origin, identity
    attitude) for every row of the joint angles ``q`` (T, nj): ``out_pos`` (T, k, 3),
    ``out_mat`` (T, k, 9) (row-major rotations). ``bodies``: :func:`site_paths` (only
    these are posed). Samples go :data:`~grfguard.kernels.lanes.LANES` at a time through
    vector lanes (each lane computes the bits of scalar code)."""
    parent, B, u, axis, anchor, qcol, q0 = ht[:7]
    site_body, site_pos, site_rot = ht[12], ht[13], ht[14]
    n = parent.shape[0]
    R, X = np.zeros((n, 9)), np.zeros((n, 3))
    R[0, 0], R[0, 4], R[0, 8] = 1.0, 1.0, 1.0
    # the vector arrays borrow these buffers (kept alive by the last statement)
    bR, bX, bS = np.empty(lanes_size(n, 9)), np.empty(lanes_size(n, 3)), np.empty(lanes_size(n, 6))
    Rv, Xv, Sv = lanes2d(bR, n, 9), lanes2d(bX, n, 3), lanes2d(bS, n, 6)
    for c in range(9):
        Rv[0, c] = splat(1.0 if c % 4 == 0 else 0.0)
    for c in range(3):
        Xv[0, c] = splat(0.0)
    k = bodies.shape[0]
    TH, SN, CS = np.empty(SC_BLOCK * k), np.empty(SC_BLOCK * k), np.empty(SC_BLOCK * k)
    T = q.shape[0]
    for t0 in range(0, T, SC_BLOCK):
        nt = min(SC_BLOCK, T - t0)
        _block_sincos(t0, nt, q, qcol, q0, bodies, TH, SN, CS)
        for lt in range(0, nt, LANES):
            nreal = min(LANES, nt - lt)
            g0 = lt // LANES * k
            for b in range(k):
                i = bodies[b]
                _ht_pose(i, parent[i], vload(CS, (g0 + b) * LANES), vload(SN, (g0 + b) * LANES),
                         B, u, axis, anchor, Rv, Xv, Sv)
            for j in range(nreal):
                _lane_rows(j, site_body, Rv, Xv, R, X)
                for s in range(site_body.shape[0]):
                    _site_pose(s, site_body, site_pos, site_rot, R, X, out_pos[t0 + lt + j, s],
                               out_mat[t0 + lt + j, s])
    bR[0] = bX[0] = bS[0] = 0.0


# ------------------------------------------ described robots: base motion from the soles
@njit_nort(inline="always")
def _ein3(a0, a1, a2, b0, b1, b2):
    """``numpy.einsum("tij,tj->ti")``'s sum of three products, in its order."""
    return (a0 * b0 + a2 * b2) + a1 * b1


@njit
def base_motion_batch(R_WB, P, PD, PDD, W, omega, alpha, v_B, a_B):
    """The stance-sole odometry of :func:`grfguard.estimate.wrench._base_motion` over a log,
    the same operations as its numpy form (``np.cross``, ``einsum``), so the same bits:
    ``v_B = -R_WB sum_i w_i (omega x p_i + p_i')`` and ``a_B = -R_WB sum_i w_i (omega x
    (omega x p_i) + 2 omega x p_i' + alpha x p_i + p_i'')``. ``P``, ``PD``, ``PDD`` (2, T,
    3): the soles in base axes and their derivatives; ``W`` (T, 2); ``omega``, ``alpha``
    (T, 3) base axes; outputs ``v_B``, ``a_B`` (T, 3) world axes."""
    for t in range(W.shape[0]):
        o0, o1, o2 = omega[t, 0], omega[t, 1], omega[t, 2]
        l0, l1, l2 = alpha[t, 0], alpha[t, 1], alpha[t, 2]
        v0 = v1 = v2 = a0 = a1 = a2 = 0.0
        for i in range(2):
            p0, p1, p2 = P[i, t, 0], P[i, t, 1], P[i, t, 2]
            d0, d1, d2 = PD[i, t, 0], PD[i, t, 1], PD[i, t, 2]
            w = W[t, i]
            c0, c1, c2 = _cross(o0, o1, o2, p0, p1, p2)
            v0 += w * (c0 + d0)
            v1 += w * (c1 + d1)
            v2 += w * (c2 + d2)
            e0, e1, e2 = _cross(o0, o1, o2, c0, c1, c2)
            f0, f1, f2 = _cross(o0, o1, o2, d0, d1, d2)
            g0, g1, g2 = _cross(l0, l1, l2, p0, p1, p2)
            a0 += w * (((e0 + 2 * f0) + g0) + PDD[i, t, 0])
            a1 += w * (((e1 + 2 * f1) + g1) + PDD[i, t, 1])
            a2 += w * (((e2 + 2 * f2) + g2) + PDD[i, t, 2])
        for r in range(3):
            v_B[t, r] = -_ein3(R_WB[t, r, 0], R_WB[t, r, 1], R_WB[t, r, 2], v0, v1, v2)
            a_B[t, r] = -_ein3(R_WB[t, r, 0], R_WB[t, r, 1], R_WB[t, r, 2], a0, a1, a2)


@njit
def lever_removed_batch(a_imu, R_WB, omega, alpha, r_B, out):
    """``a_imu - R_WB (alpha x r + omega x (omega x r))`` (T, 3) into ``out``: the IMU's
    lever arm ``r`` (base axes) taken out of its world acceleration, as
    :func:`grfguard.estimate.wrench._base_motion`'s numpy form computes it (same bits)."""
    for t in range(a_imu.shape[0]):
        r0, r1, r2 = r_B[t, 0], r_B[t, 1], r_B[t, 2]
        o0, o1, o2 = omega[t, 0], omega[t, 1], omega[t, 2]
        b0, b1, b2 = _cross(alpha[t, 0], alpha[t, 1], alpha[t, 2], r0, r1, r2)
        c0, c1, c2 = _cross(o0, o1, o2, r0, r1, r2)
        d0, d1, d2 = _cross(o0, o1, o2, c0, c1, c2)
        l0, l1, l2 = b0 + d0, b1 + d1, b2 + d2
        for r in range(3):
            out[t, r] = a_imu[t, r] - _ein3(R_WB[t, r, 0], R_WB[t, r, 1], R_WB[t, r, 2], l0,
                                            l1, l2)


@njit_nort(inline="always")
def _mm_entry(a0, a1, a2, b0, b1, b2):
    """One entry of numpy's (BLAS) 3x3 ``matmul``, in its order: fused multiply-adds."""
    return fma(a2, b2, fma(a1, b1, a0 * b0))


@njit
def frames_post_batch(R_WI, mat, gyro, R_WB, R_BI, omega):
    """After the first kinematics pass, the same bits as :func:`grfguard.estimate.wrench
    ._body_frames_compiled` and ``estimate_wrenches``' numpy: ``R_BI`` (T, 3, 3) the IMU
    in base axes (``mat[:, 0]``, (T, 9) row-major), ``R_WB = R_WI R_BI^T`` (numpy's
    ``matmul``), ``omega = R_BI gyro`` (numpy's ``einsum``)."""
    for t in range(R_WI.shape[0]):
        for i in range(3):
            for j in range(3):
                R_BI[t, i, j] = mat[t, 3 * i + j]
        for i in range(3):
            for j in range(3):
                R_WB[t, i, j] = _mm_entry(R_WI[t, i, 0], R_WI[t, i, 1], R_WI[t, i, 2],
                                          mat[t, 3 * j], mat[t, 3 * j + 1], mat[t, 3 * j + 2])
            omega[t, i] = _ein3(mat[t, 3 * i], mat[t, 3 * i + 1], mat[t, 3 * i + 2],
                                gyro[t, 0], gyro[t, 1], gyro[t, 2])


@njit
def level_tilt_batch(R_WB, R_BS, st, tilt):
    """The leveled attitude's tilt (T, 2) before averaging, as :func:`grfguard.estimate
    .wrench._attitude` computes it (same bits): ``D = R_WB R_S`` (``R_S`` the stance sole
    ``st[t]`` in base axes, numpy's ``matmul``), ``tilt = 0.5 (D21 - D12, D02 - D20)``."""
    d = np.empty(9)
    for t in range(R_WB.shape[0]):
        S = R_BS[st[t], t]
        for i in range(3):
            for j in range(3):
                d[3 * i + j] = _mm_entry(R_WB[t, i, 0], R_WB[t, i, 1], R_WB[t, i, 2],
                                         S[0, j], S[1, j], S[2, j])
        tilt[t, 0] = 0.5 * (d[7] - d[5])
        tilt[t, 1] = 0.5 * (d[2] - d[6])


@njit
def level_apply_batch(rv, R_WB, out):
    """``out = Q(rv) R_WB`` (T, 3, 3): :func:`grfguard.estimate.wrench._small_rotations`'s
    closed-form polar factor ``Q`` of each small rotation vector ``rv`` (T, 3) times the
    attitude (numpy's ``matmul``), the same operations and bits as the numpy form."""
    q = np.empty(9)
    for t in range(rv.shape[0]):
        r0, r1, r2 = rv[t, 0], rv[t, 1], rv[t, 2]
        s = math.sqrt(1.0 + ((r0 * r0 + r2 * r2) + r1 * r1))  # einsum("ti,ti->t")
        a = 1.0 / s
        b = a / (s + 1.0)
        for i in range(3):
            bi = b * rv[t, i]
            for j in range(3):
                q[3 * i + j] = bi * rv[t, j]
        q[0] += a
        q[4] += a
        q[8] += a
        k0, k1, k2 = r0 * a, r1 * a, r2 * a
        q[1] -= k2
        q[2] += k1
        q[5] -= k0
        q[3] += k2
        q[6] -= k1
        q[7] += k0
        for i in range(3):
            for j in range(3):
                out[t, i, j] = _mm_entry(q[3 * i], q[3 * i + 1], q[3 * i + 2], R_WB[t, 0, j],
                                         R_WB[t, 1, j], R_WB[t, 2, j])
