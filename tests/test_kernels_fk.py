"""Compiled forward kinematics against MuJoCo (mj_kinematics + mj_comPos)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from grfguard.errors import ConfigError
from grfguard.kernels.fk import N_WORK, TreeModel, fk_batch, fk_sites, fk_tree
from grfguard.model.mjcf import build_model
from grfguard.model.robot import SURALP
from kernels_reference import random_tree_xml


def _compare(model: mujoco.MjModel, n: int, seed: int) -> float:
    d = mujoco.MjData(model)
    tm = TreeModel.from_mujoco(model)
    frames = tm.new_frames()
    work_q = np.zeros(model.nq)
    work_m = np.zeros(model.nbody)
    sites = np.arange(model.nsite, dtype=np.int64)
    sxp = np.zeros((model.nsite, 3))
    sxm = np.zeros((model.nsite, 9))
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(n):
        q = model.qpos0.copy()
        for j in range(model.njnt):
            a = model.jnt_qposadr[j]
            t = model.jnt_type[j]
            if t == mujoco.mjtJoint.mjJNT_FREE:
                q[a : a + 3] = rng.normal(size=3)
                q[a + 3 : a + 7] = rng.normal(size=4)  # not normalised: both normalise
            elif t == mujoco.mjtJoint.mjJNT_BALL:
                q[a : a + 4] = rng.normal(size=4)
            else:
                q[a] += rng.uniform(-2.0, 2.0)
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        fk_tree(q, *tm.arrays(), work_q, *frames, work_m, np.zeros(N_WORK))
        xpos, xquat, xmat, xipos, ximat, stc = frames
        fk_sites(sites, tm.site_body, tm.site_sameframe, tm.site_pos, tm.site_quat, xpos, xquat,
                 xmat, xipos, ximat, sxp, sxm, np.zeros(8))
        for ours, theirs in (
            (xpos, d.xpos), (xquat, d.xquat), (xmat, d.xmat), (xipos, d.xipos),
            (ximat, d.ximat), (stc, d.subtree_com), (sxp, d.site_xpos), (sxm, d.site_xmat),
        ):
            worst = max(worst, float(np.abs(ours - np.asarray(theirs)).max()))
    return worst


def test_fk_suralp_matches_mujoco_on_random_configurations():
    worst = _compare(build_model(SURALP), 300, seed=1)
    assert worst <= 1e-12  # measured: 0 (same operation order as MuJoCo)


@pytest.mark.parametrize("seed", [0, 1])
def test_fk_random_30_joint_tree_matches_mujoco(seed):
    model = mujoco.MjModel.from_xml_string(random_tree_xml(30, seed))
    assert model.njnt == 31
    assert {int(t) for t in model.jnt_type} == {0, 1, 2, 3}  # free, ball, slide, hinge
    worst = _compare(model, 100, seed=seed + 10)
    assert worst <= 1e-12


def test_fk_rejects_mocap_bodies():
    xml = ('<mujoco><worldbody><body name="m" mocap="true"><geom size="0.1"/></body>'
           '</worldbody></mujoco>')
    with pytest.raises(ConfigError, match="mocap"):
        TreeModel.from_mujoco(mujoco.MjModel.from_xml_string(xml))


def test_fk_batch_equals_one_sample_calls():
    model = mujoco.MjModel.from_xml_string(random_tree_xml(30, 3))
    tm = TreeModel.from_mujoco(model)
    rng = np.random.default_rng(4)
    Q = np.tile(model.qpos0, (5, 1))
    Q[:, 7:] += rng.uniform(-1.0, 1.0, (5, model.nq - 7))
    com = np.zeros((5, 3))
    xi = np.zeros((5, model.nbody, 3))
    fk_batch(Q, *tm.arrays(), com, xi)
    d = mujoco.MjData(model)
    for t in range(5):
        d.qpos[:] = Q[t]
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        # a few units in the last place on general trees (bit-equal on SURALP)
        np.testing.assert_allclose(com[t], d.subtree_com[1], rtol=0, atol=1e-12)
        np.testing.assert_allclose(xi[t], d.xipos, rtol=0, atol=1e-12)


def test_quaternion_norm_band_leaves_the_quaternion_as_mujoco_does():
    # fk's fast normalisation skips sqrt and division when |q.q - 1| < NQ_BAND; MuJoCo's
    # mju_normalize4 leaves q unchanged when |sqrt(q.q) - 1| <= 1e-15: every double in the
    # band must satisfy the latter (checked one by one; there are a few dozen)
    from grfguard.kernels.fk import NQ_BAND

    s = 1.0
    checked = 0
    for direction in (-np.inf, np.inf):
        s = 1.0
        while abs(s - 1.0) < NQ_BAND:
            assert abs(float(np.sqrt(s)) - 1.0) <= 1e-15, s
            s = float(np.nextafter(s, direction))
            checked += 1
    assert checked > 10


def test_fast_kinematics_of_the_virtual_sensor_equal_fk_tree_bit_for_bit():
    # the sensor's kinematics (bodies, the trunk's subtree CoM, site positions only) give
    # the same bits as fk_tree + fk_sites on random configurations
    from grfguard.kernels.fk import fk_bodies, fk_site_pos, subtree_com_of

    model = build_model(SURALP)
    tm = TreeModel.from_mujoco(model)
    ref, fast = tm.new_frames(), tm.new_frames()
    sites = np.arange(model.nsite, dtype=np.int64)
    sxp, sxp2, sxm = (np.zeros((model.nsite, 3)), np.zeros((model.nsite, 3)),
                      np.zeros((model.nsite, 9)))
    rng = np.random.default_rng(3)
    (parent, jntadr, jntnum, sameframe, pos, quat, ipos, iquat, mass, jtype, qadr, axis, jpos,
     qpos0, order) = tm.arrays()
    for _ in range(300):
        q = qpos0.copy()
        q[3:7] = rng.normal(size=4)
        q[7:] += rng.uniform(-2.0, 2.0, size=q.size - 7)
        fk_tree(q, *tm.arrays(), np.zeros(model.nq), *ref, np.zeros(model.nbody),
                np.zeros(N_WORK))
        fk_sites(sites, tm.site_body, tm.site_sameframe, tm.site_pos, tm.site_quat, ref[0],
                 ref[1], ref[2], ref[3], ref[4], sxp, sxm, np.zeros(8))
        fk_bodies(q, parent, jntadr, jntnum, sameframe, pos, quat, ipos, iquat, jtype, qadr,
                  axis, jpos, qpos0, order, np.zeros(model.nq), *fast[:5])
        com = subtree_com_of(1, parent, mass, fast[3], fast[5], np.zeros(model.nbody))
        fk_site_pos(sites, tm.site_body, tm.site_sameframe, tm.site_pos, fast[0], fast[2],
                    fast[3], sxp2)
        for a, b in zip(ref[:5], fast[:5], strict=True):
            assert np.array_equal(a, b)
        assert np.array_equal(np.array(com), ref[5][1])
        assert np.array_equal(sxp, sxp2)


@pytest.mark.parametrize("robot", ["suralp", "random"])
def test_unit_hinge_kinematics_equal_the_generic_ones(robot):
    # fk_bodies_kind (unit hinges at the body origin without the products with zeros)
    # gives the values of fk_bodies (MuJoCo's operations) on random configurations
    from grfguard.kernels.fk import GENERIC, fk_bodies, fk_bodies_kind

    model = (build_model(SURALP) if robot == "suralp"
             else mujoco.MjModel.from_xml_string(random_tree_xml(30, 5)))
    tm = TreeModel.from_mujoco(model)
    kinds = tm.body_kinds()
    if robot == "suralp":  # every leg body is a unit hinge; the trunk (free) is not
        assert kinds[0] == GENERIC and kinds[1] == GENERIC
        assert (kinds[2:] >= 0).all() and set(kinds[2:].tolist()) == {0, 1, 2}
    ref, fast = tm.new_frames(), tm.new_frames()
    (parent, jntadr, jntnum, sameframe, pos, quat, ipos, iquat, mass, jtype, qadr, axis, jpos,
     qpos0, order) = tm.arrays()
    rng = np.random.default_rng(7)
    for t in range(300):
        q = qpos0.copy()
        q[3:7] = rng.normal(size=4)
        q[7:] += rng.uniform(-2.0, 2.0, size=q.size - 7) * (t % 10 != 0)  # zero angles too
        fk_bodies(q, parent, jntadr, jntnum, sameframe, pos, quat, ipos, iquat, jtype, qadr,
                  axis, jpos, qpos0, order, np.zeros(model.nq), *ref[:5])
        fk_bodies_kind(q, kinds, parent, jntadr, jntnum, sameframe, pos, quat, ipos, iquat,
                       jtype, qadr, axis, jpos, qpos0, order, np.zeros(model.nq), *fast[:5])
        for a, b in zip(ref[:5], fast[:5], strict=True):
            assert np.array_equal(a, b)
