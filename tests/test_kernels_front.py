"""The virtual sensor's kinematics eight samples at a time (grfguard.kernels.front).

Against MuJoCo on random configurations and attitudes; a sample's poses from a block
equal, bit for bit, the poses computed for it alone; a row that is not the block's gets
its own poses; trees the block does not cover keep MuJoCo's order."""

from __future__ import annotations

import copy
import dataclasses

import mujoco
import numpy as np

from grfguard.estimate.config import VFSConfig
from grfguard.estimate.vfs import VirtualForceSensor
from grfguard.kernels.fk import TreeModel
from grfguard.kernels.front import (
    IW_SLOT,
    N_FRONT_ANGLES,
    N_FRONT_SITES,
    NPAIR,
    _quat_mat,
    front_constants,
    front_pose,
    front_trunk,
    front_ws_size,
)
from grfguard.kernels.lanes import LANES
from grfguard.kernels.vfs import _P_FRONT_CF, _P_FRONT_CI, N_SHARED, front_rows
from grfguard.model.robot import SURALP


def _kernel(cfg: VFSConfig | None = None):
    return VirtualForceSensor(SURALP, cfg).kernel()


def _unit(rng) -> np.ndarray:
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def _pose(k, x: np.ndarray, t: np.ndarray, slot: int = -1):
    nb = int(k.ci[0])
    xipos, ximat, sxp = np.zeros((nb, 3)), np.zeros((nb, 9)), np.zeros((N_FRONT_SITES, 3))
    k.iws[IW_SLOT] = slot
    front_pose(x, k.cf, k.ci, int(k.prm[_P_FRONT_CF]), int(k.prm[_P_FRONT_CI]), nb, k.ws,
               k.iws, N_SHARED, t[0], t[1], t[2], t[3], xipos, ximat, sxp)
    k.iws[IW_SLOT] = -1
    return xipos, ximat, sxp


def test_poses_match_mujoco_on_random_configurations():
    vfs = VirtualForceSensor(SURALP)
    k = vfs.kernel()
    assert k.prm[_P_FRONT_CF] > 0  # SURALP's tree is covered
    m = vfs.kin.model
    d = mujoco.MjData(m)
    sites = np.array([vfs.kin.imu_site, *vfs.kin.corner_sites, *vfs.kin.sole_sites])
    rng = np.random.default_rng(4)
    worst = 0.0
    for _ in range(200):
        x = rng.uniform(-1.5, 1.5, 12)
        t = _unit(rng)
        d.qpos[:] = m.qpos0
        d.qpos[vfs.kin.root_qadr:vfs.kin.root_qadr + 7] = [0, 0, 0, *t]
        d.qpos[vfs.kin.joint_qadr] = x
        mujoco.mj_kinematics(m, d)
        xipos, ximat, sxp = _pose(k, x, t)
        for ours, theirs in ((xipos[1:], d.xipos[1:]), (ximat[1:], d.ximat[1:]),
                             (sxp, d.site_xpos[sites])):
            worst = max(worst, float(np.abs(ours - theirs).max()))
    assert worst <= 1e-12  # measured 9e-16


def test_any_hinge_tree_matches_mujoco():
    # tilted joint axes, rotated bodies and inertial frames, anchors off the body origins:
    # every body takes the general rotation (the unit-axis shortcut and the own inertial
    # axes of SURALP's bodies are not used)
    vfs = VirtualForceSensor(SURALP)
    kin = vfs.kin
    m = copy.deepcopy(kin.model)
    rng = np.random.default_rng(12)
    for b in range(1, m.nbody):
        m.body_quat[b] = _unit(rng)
        m.body_iquat[b] = _unit(rng)
    for j in range(1, m.njnt):
        a = rng.normal(size=3)
        m.jnt_axis[j] = a / np.linalg.norm(a)
        m.jnt_pos[j] = rng.uniform(-0.05, 0.05, 3)
    # (MuJoCo's same-frame shortcuts were decided for the unchanged model: off)
    m.body_sameframe[:] = 0
    m.site_sameframe[:] = 0
    tm = TreeModel.from_mujoco(m)
    sites = np.array([kin.imu_site, *kin.corner_sites, *kin.sole_sites])
    floats, ints = front_constants(tm, kin.joint_qadr, 1, sites, kin.body_inertia)
    nb = int(m.nbody)
    assert (ints[2 * nb + N_FRONT_SITES:] <= 0).all()  # no shortcut applies
    ws = np.zeros(front_ws_size(nb) + N_SHARED)
    ws[:N_FRONT_ANGLES] = np.nan
    iws = np.full(64, -1, np.int64)
    d = mujoco.MjData(m)
    worst = 0.0
    for _ in range(100):
        x = rng.uniform(-1.5, 1.5, 12)
        t = _unit(rng)
        d.qpos[:] = m.qpos0
        d.qpos[kin.root_qadr:kin.root_qadr + 7] = [0, 0, 0, *t]
        d.qpos[kin.joint_qadr] = x
        mujoco.mj_kinematics(m, d)
        xipos, ximat, sxp = np.zeros((nb, 3)), np.zeros((nb, 9)), np.zeros((N_FRONT_SITES, 3))
        front_pose(x, floats, ints, 0, 0, nb, ws, iws, N_SHARED, *t, xipos, ximat, sxp)
        for ours, theirs in ((xipos[1:], d.xipos[1:]), (ximat[1:], d.ximat[1:]),
                             (sxp, d.site_xpos[sites])):
            worst = max(worst, float(np.abs(ours - theirs).max()))
    assert worst <= 1e-12  # measured 2e-15


def test_block_lanes_equal_single_samples_bit_for_bit():
    k = _kernel()
    rng = np.random.default_rng(9)
    X = rng.uniform(-1.5, 1.5, (11, 24))
    X[3, 5] = -0.0  # a signed zero is a different row from +0.0
    t = _unit(rng)
    alone = [_pose(k, X[i], t) for i in range(11)]
    for t0, nt in ((0, LANES), (LANES, 3)):
        front_rows(X, t0, nt, 0, k.cf, k.ci, k.ws, k.iws)
        for j in range(nt):
            got = _pose(k, X[t0 + j], t, slot=j)
            for a, b in zip(got, alone[t0 + j], strict=True):
                assert a.tobytes() == b.tobytes()
    # a row that is not the block's (changed after the fill) gets its own poses
    front_rows(X, 0, LANES, 0, k.cf, k.ci, k.ws, k.iws)
    y = X[2].copy()
    y[7] += 1e-3
    got = _pose(k, y, t, slot=2)
    ref = _pose(_kernel(), y, t)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(got, ref, strict=True))
    z = X[3].copy()
    z[5] = 0.0  # +0.0 against the block's -0.0
    got = _pose(k, z, t, slot=3)
    ref = _pose(_kernel(), z, t)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(got, ref, strict=True))


def test_trees_not_covered_keep_mujoco_order():
    # the paper's anchor attitude reads the sites' axes: no block
    assert _kernel(VFSConfig.paper()).prm[_P_FRONT_CF] == 0
    # a ball joint in the tree: no constants
    vfs = VirtualForceSensor(SURALP)
    tm = TreeModel.from_mujoco(vfs.kin.model)
    types = tm.jnt_type.copy()
    types[3] = 1  # mjJNT_BALL
    bad = dataclasses.replace(tm, jnt_type=types)
    sites = np.array([vfs.kin.imu_site, *vfs.kin.corner_sites, *vfs.kin.sole_sites])
    inertia = vfs.kin.body_inertia
    assert front_constants(bad, vfs.kin.joint_qadr, 1, sites, inertia) is None
    assert front_constants(tm, vfs.kin.joint_qadr, 1, sites, inertia) is not None
    assert front_constants(tm, vfs.kin.joint_qadr, 2, sites, inertia) is None  # trunk not 1


def _trunk(k, x: np.ndarray, qprev: np.ndarray | None, t: np.ndarray, slot: int = -1):
    """``front_trunk`` of the row ``x`` after a sample with the joint angles ``qprev``
    (None: no previous sample) at the attitude ``t``: the CoM, the trunk-frame sums and
    the sites, as bytes."""
    nb = int(k.ci[0])
    sxp = np.zeros((N_FRONT_SITES, 3))
    k.iws[IW_SLOT] = slot
    q = np.zeros(12) if qprev is None else np.ascontiguousarray(qprev[:12], dtype=float)
    c0, c1, c2, pst, pstep = front_trunk(
        x, q, qprev is not None, k.cf, k.ci, int(k.prm[_P_FRONT_CF]), int(k.prm[_P_FRONT_CI]),
        nb, k.ws, k.iws, N_SHARED, *_quat_mat(t).ravel(), sxp)
    k.iws[IW_SLOT] = -1
    sums = (np.array([k.ws[pst + i * pstep] for i in range(NPAIR)]) if pst >= 0
            else np.zeros(0))
    return np.array([c0, c1, c2]), sums, sxp


def _momentum(sums: np.ndarray, Q: np.ndarray, Qp: np.ndarray, dt: float) -> np.ndarray:
    """The angular momentum about the CoM from the trunk-frame sums (front._pairs)."""
    D = Q.T @ Qp
    N = sums[3:12].reshape(3, 3) @ D.T
    e = np.array([N[1, 2] - N[2, 1], N[2, 0] - N[0, 2], N[0, 1] - N[1, 0]])
    spin = np.einsum("acl,cl->a", sums[12:39].reshape(3, 3, 3), D)
    return Q @ (spin / (2 * dt) - e / dt)


def test_trunk_sums_give_the_world_frame_angular_momentum():
    # backward differences of the body poses in world axes (the reference's formula)
    # against the sums in the trunk's axes rotated by the two attitudes
    from reference.vfs_stages import angular_momentum_about_com

    vfs = VirtualForceSensor(SURALP)
    kin = vfs.kin
    k = vfs.kernel()
    m = kin.model
    d = mujoco.MjData(m)
    rng = np.random.default_rng(21)
    dt = 1e-3

    def world(x, t):
        d.qpos[:] = m.qpos0
        d.qpos[kin.root_qadr:kin.root_qadr + 7] = [0, 0, 0, *t]
        d.qpos[kin.joint_qadr] = x
        mujoco.mj_kinematics(m, d)
        return d.xipos[1:].copy(), d.ximat[1:].reshape(-1, 3, 3).copy()

    worst = 0.0
    for _ in range(50):
        x0 = rng.uniform(-1.5, 1.5, 24)
        x1 = x0 + rng.normal(0.0, 2e-3, 24)  # one millisecond of motion
        t0 = _unit(rng)
        t1 = t0 + rng.normal(0.0, 1e-3, 4)
        t1 /= np.linalg.norm(t1)
        c, sums, _ = _trunk(k, x1, x0, t1)
        p1, R1 = world(x1[:12], t1)
        p0, R0 = world(x0[:12], t0)
        ref = angular_momentum_about_com(p1, R1, p0, R0, m.body_mass[1:], kin.body_inertia, dt)
        ours = _momentum(sums, _quat_mat(t1), _quat_mat(t0), dt)
        worst = max(worst, float(np.abs(ours - ref).max() / np.abs(ref).max()))
        com = (p1 * m.body_mass[1:, None]).sum(0) / m.body_mass[1:].sum()
        assert np.abs(c - com).max() <= 1e-14  # (world axes)
    assert worst <= 1e-10  # measured 3e-13 of the largest component


def test_trunk_sums_from_the_block_equal_single_samples_bit_for_bit():
    k = _kernel()
    rng = np.random.default_rng(5)
    X = rng.uniform(-1.5, 1.5, (13, 24))
    t = _unit(rng)
    alone = [_trunk(_kernel(), X[i], X[i - 1] if i else None, t) for i in range(13)]
    for t0, nt in ((0, LANES), (LANES, 5)):  # lane 0 of the second block: the carry
        front_rows(X, t0, nt, 0, k.cf, k.ci, k.ws, k.iws)
        for j in range(nt):
            i = t0 + j
            got = _trunk(k, X[i], X[i - 1] if i else None, t, slot=j)
            for a, b in zip(got, alone[i], strict=True):
                assert a.tobytes() == b.tobytes()
    # a previous sample that is not the block's previous row (an invalid row between,
    # or a block of rows not following the last): computed for the row alone
    front_rows(X, 0, LANES, 0, k.cf, k.ci, k.ws, k.iws)
    for j, prev in ((3, X[1]), (0, X[11])):
        got = _trunk(k, X[j], prev, t, slot=j)
        ref = _trunk(_kernel(), X[j], prev, t)
        assert all(a.tobytes() == b.tobytes() for a, b in zip(got, ref, strict=True))
        assert got[1].size == NPAIR
    # streamed samples keep their poses for the next: the same bits as a fresh kernel's
    s = _kernel()
    for i in range(1, 4):
        got = _trunk(s, X[i], X[i - 1], t)
        assert all(a.tobytes() == b.tobytes() for a, b in zip(got, alone[i], strict=True))
