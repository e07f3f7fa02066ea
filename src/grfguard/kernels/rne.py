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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grfguard.errors import ConfigError
from grfguard.kernels._jit import njit, njit_nort
from grfguard.kernels.fk import (
    BALL,
    FREE,
    SLIDE,
    TreeModel,
    fk_bodies,
    fk_sites,
    subtree_com_of,
)

__all__ = ["RNEModel", "rne_sample", "sample_wrenches", "wrench_batch", "frames_batch", "new_work"]

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
