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
    N_FRONT_SITES,
    front_constants,
    front_pose,
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
    floats, ints = front_constants(tm, kin.joint_qadr, 1, sites)
    nb = int(m.nbody)
    assert (ints[2 * nb + N_FRONT_SITES:] <= 0).all()  # no shortcut applies
    ws = np.zeros(front_ws_size(nb) + N_SHARED)
    ws[:LANES * 12] = np.nan
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
    assert front_constants(bad, vfs.kin.joint_qadr, 1, sites) is None
    assert front_constants(tm, vfs.kin.joint_qadr, 1, sites) is not None
    assert front_constants(tm, vfs.kin.joint_qadr, 2, sites) is None  # trunk not body 1
