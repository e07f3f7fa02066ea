"""Compiled inverse dynamics (grfguard.kernels.rne) against MuJoCo on random states of the
shipped described robots (Talos: ankle F/T, G1: corner cells) and of a small model with
ball and slide joints; the compiled virtual foot wrenches against the per-sample MuJoCo
path on simulated walks."""

from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from grfguard.errors import ConfigError  # noqa: E402
from grfguard.estimate.wrench import _share  # noqa: E402
from grfguard.kernels.rne import RNEModel, new_work, rne_sample, sample_wrenches  # noqa: E402
from grfguard.model.description import SIDES  # noqa: E402

BALL_SLIDE_XML = """
<mujoco>
  <option gravity="0.3 -0.2 -9.81"/>
  <worldbody>
    <body name="base" pos="0 0 1">
      <freejoint/>
      <geom type="box" size="0.1 0.2 0.05" mass="5"/>
      <body name="arm" pos="0.1 0.2 0" quat="0.9 0.1 0.3 0.2">
        <joint name="ball" type="ball" pos="0.01 0.02 0.03" armature="0.1"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1.3"/>
        <body name="slider" pos="0.3 0 0">
          <joint name="slide" type="slide" axis="0.2 0.5 0.8" armature="0.2" damping="3"/>
          <geom type="sphere" size="0.04" pos="0.02 0.01 0" mass="0.7"/>
          <site name="tip" pos="0.05 0 0.01" quat="0.7 0.7 0 0"/>
        </body>
      </body>
      <body name="leg" pos="0 -0.1 -0.1">
        <joint name="hinge" type="hinge" axis="0.3 1 0.1" pos="0 0 0.02" armature="0.05"/>
        <geom type="box" size="0.03 0.04 0.2" pos="0.01 0 -0.2" mass="2"/>
        <site name="foot" pos="0 0 -0.4"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""




def _random_state(m, rng):
    qpos = m.qpos0.copy()
    for j in range(m.njnt):
        a, t = m.jnt_qposadr[j], m.jnt_type[j]
        if t == mujoco.mjtJoint.mjJNT_FREE:
            qpos[a:a + 3] = rng.normal(0, 0.3, 3)
            q = rng.normal(size=4)
            qpos[a + 3:a + 7] = q / np.linalg.norm(q)
        elif t == mujoco.mjtJoint.mjJNT_BALL:
            q = rng.normal(size=4)
            qpos[a:a + 4] = q / np.linalg.norm(q)
        else:
            qpos[a] = rng.uniform(-1.0, 1.0)
    return qpos, rng.normal(0, 1.0, m.nv), rng.normal(0, 5.0, m.nv)


def _mujoco_reference(m, d, qpos, qvel, qacc, site_ids, feet, ground=None, ft_sites=None):
    """f_free (mj_rne), the sole wrenches alone (J_free^T w = f_free) and, with ``ground``,
    the F/T readings (mj_rnePostConstraint), as grfguard.estimate.wrench computes them."""
    d.qpos[:], d.qvel[:], d.qacc[:] = qpos, qvel, qacc
    d.xfrc_applied[:] = 0.0
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    mujoco.mj_comVel(m, d)
    f = np.zeros(m.nv)
    mujoco.mj_rne(m, d, 1, f)
    jac = np.zeros((6, m.nv))
    alone = []
    for sid in site_ids:
        mujoco.mj_jacSite(m, d, jac[:3], jac[3:], sid)
        alone.append(np.linalg.solve(jac[:, :6].T, f[:6]))
    if ground is None:
        return f[:6], np.array(alone), None
    from grfguard.estimate.wrench import _ft_readings

    class _R:  # the minimal LoadedRobot _ft_readings reads
        model = m

    out = np.zeros((2, 6))
    ids = (list(feet), list(site_ids), list(ft_sites), [1, 1])
    _ft_readings(_R, d, ground, out, ids)
    return f[:6], np.array(alone), out


def _kernel(rm, qpos, qvel, qacc, sites, feet, w, ft):
    work = new_work(rm, len(sites))
    rne_sample(qpos, qvel, qacc, rm.tree.arrays(), rm.site_arrays(), rm.dyn_arrays(),
               np.asarray(sites, np.int64), work)
    ground, ft_out = np.zeros((2, 6)), np.zeros((2, 6))
    sample_wrenches(w[0], w[1], rm.root, np.asarray(feet, np.int64), ft, work, ground, ft_out)
    return work, ground, ft_out


def _free_rows(m, work):
    """The free-base generalized force from the kernel's subtree force (cdof^T cfrc)."""
    d = mujoco.MjData(m)
    d.qpos[:] = work[0]
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    return d.cdof[:6] @ work[12][1]


@pytest.mark.parametrize("name", ["talos", "g1"])
def test_inverse_dynamics_matches_mujoco(name, request) -> None:
    robot = request.getfixturevalue(name)
    m = robot.model
    d = mujoco.MjData(m)
    rm = RNEModel.from_mujoco(m)
    soles = [m.site(f"{s}_sole").id for s in SIDES]
    feet = [m.body(f.body).id for f in robot.description.feet]
    ft = robot.description.sensing == "ft"
    fts = [m.site(f"{s}_ft").id for s in SIDES] if ft else []
    rng = np.random.default_rng(5)
    for trial in range(20):
        qpos, qvel, qacc = _random_state(m, rng)
        w = (1.0, 0.0) if trial % 3 == 0 else ((0.0, 1.0) if trial % 3 == 1 else (0.5, 0.5))
        work, ground, ft_out = _kernel(rm, qpos, qvel, qacc, soles + fts, feet, w, ft)
        f_ref, alone, _ = _mujoco_reference(m, d, qpos, qvel, qacc, soles, feet)
        scale = max(1.0, np.abs(f_ref).max())
        assert np.abs(_free_rows(m, work) - f_ref).max() < 1e-9 * scale
        np.testing.assert_allclose(work[13][:2], d.site_xpos[soles], rtol=0, atol=1e-12)
        _assert_ground_and_ft(m, d, (qpos, qvel, qacc), soles, feet, fts if ft else None, w,
                              alone, ground, ft_out, scale)


def _assert_ground_and_ft(m, d, state, soles, feet, fts, w, alone, ground, ft_out,
                          scale) -> None:
    """The kernel's sole wrenches split as grfguard.estimate.wrench._share takes them (CoP
    in double support), and its F/T wrenches (``fts`` not None) equal MuJoCo's."""
    share = _share(np.array(w), alone, d.site_xpos[soles[0]], d.site_xpos[soles[1]])
    assert np.abs(ground - share[:, None] * alone).max() < 1e-9 * scale
    if fts is not None:
        _, _, ft_ref = _mujoco_reference(m, d, *state, soles, feet, ground, fts)
        assert np.abs(ft_out - ft_ref).max() < 1e-9 * scale


def test_ball_slide_model_matches_mujoco() -> None:
    m = mujoco.MjModel.from_xml_string(BALL_SLIDE_XML)
    d = mujoco.MjData(m)
    rm = RNEModel.from_mujoco(m)
    soles = [m.site("tip").id, m.site("foot").id]
    feet = [m.body("slider").id, m.body("leg").id]
    rng = np.random.default_rng(11)
    for _ in range(20):
        qpos, qvel, qacc = _random_state(m, rng)
        ground = rng.normal(0, 20.0, (2, 6))
        work, g, ft_out = _kernel(rm, qpos, qvel, qacc, soles + soles, feet, (1.0, 0.0), True)
        f_ref, alone, _ = _mujoco_reference(m, d, qpos, qvel, qacc, soles, feet)
        assert np.abs(_free_rows(m, work) - f_ref).max() < 1e-9 * max(1, np.abs(f_ref).max())
        assert np.abs(g[0] - alone[0]).max() < 1e-9 * max(1.0, np.abs(alone).max())
        # F/T of both "feet" under the kernel's own ground wrench (tip, foot: its site)
        _, _, ft_ref = _mujoco_reference(m, d, qpos, qvel, qacc, soles, feet, g, soles)
        assert np.abs(ft_out - ft_ref).max() < 1e-9 * max(1.0, np.abs(ft_ref).max())
        assert ground.shape == (2, 6)


def test_unsupported_models_are_named() -> None:
    fixed = BALL_SLIDE_XML.replace("<freejoint/>", "")
    with pytest.raises(ConfigError, match="free joint"):
        RNEModel.from_mujoco(mujoco.MjModel.from_xml_string(fixed))
    two = BALL_SLIDE_XML.replace(
        '<joint name="hinge" type="hinge" axis="0.3 1 0.1" pos="0 0 0.02" armature="0.05"/>',
        '<joint name="hinge" type="hinge" axis="0.3 1 0.1"/><joint name="h2" axis="1 0 0"/>')
    with pytest.raises(ConfigError, match="one joint per body"):
        RNEModel.from_mujoco(mujoco.MjModel.from_xml_string(two))


@pytest.mark.parametrize("name", ["talos", "g1"])
def test_estimate_wrenches_compiled_equals_mujoco_path(name, request) -> None:
    """The compiled batch path gives today's (per-sample MuJoCo) virtual wrenches to 1e-9 N
    on a noisy simulated walk (double support, swing and the ``leveled`` attitude in)."""
    from grfguard.estimate.wrench import estimate_wrenches
    from grfguard.sim.config import NoiseConfig
    from grfguard.sim.wholebody import scaled_gait, simulate_robot

    robot = request.getfixturevalue(name)
    df = simulate_robot(robot, scaled_gait(robot, duration=2.5), NoiseConfig(), seed=4)
    new = estimate_wrenches(df, robot)
    old = estimate_wrenches(df, robot, compiled=False)
    assert np.abs(new.ground[:, :, 2]).max() > 0.5 * robot.mass * 9.81  # carries the weight
    assert np.abs(new.ground - old.ground).max() < 1e-9
    assert new.sensor.keys() == old.sensor.keys()
    for k in new.sensor:
        assert np.abs(new.sensor[k] - old.sensor[k]).max() < 1e-9, k
    np.testing.assert_array_equal(new.contact, old.contact)


HINGE_XML = """
<mujoco>
  <option gravity="0.4 -0.3 -9.81"/>
  <worldbody>
    <body name="base" pos="0 0 1">
      <freejoint/>
      <geom type="box" size="0.1 0.2 0.05" mass="5"/>
      <body name="plate" pos="0.02 0 0.1" quat="0.9 0.2 0.1 0.3">
        <geom type="box" size="0.05 0.05 0.01" pos="0.01 0.02 0" mass="0.4"/>
        <body name="arm" pos="0.1 0.2 0" quat="0.8 0.1 0.3 0.2">
          <joint name="a1" axis="0.3 0.5 0.8" pos="0.01 0.02 0.03"/>
          <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1.3"/>
          <body name="hand" pos="0.3 0 0">
            <joint name="a2" axis="0 -1 0"/>
            <geom type="sphere" size="0.02" pos="0.01 0.01 0" mass="0.02"/>
            <site name="tip" pos="0.05 0 0.01" quat="0.7 0.7 0 0"/>
          </body>
        </body>
      </body>
      <body name="leg_r" pos="0 -0.1 -0.1">
        <joint name="hr" axis="1 0 0" pos="0 0 0.02"/>
        <geom type="box" size="0.03 0.04 0.2" pos="0.01 0 -0.2" mass="2"/>
        <body name="foot_r" pos="0 0 -0.4" quat="0.99 0 0.1 0">
          <joint name="ar" axis="0 1 0"/>
          <geom type="box" size="0.1 0.05 0.02" pos="0.03 0 -0.03" mass="0.8"/>
          <body name="sole_r" pos="0.02 0 -0.05">
            <geom type="sphere" size="0.01" mass="0.05"/>
            <site name="sole_r" pos="0.01 0 -0.01"/>
          </body>
          <site name="ft_r" pos="0 0 0.01" quat="0.9 0 0 0.3"/>
        </body>
      </body>
      <body name="leg_l" pos="0 0.1 -0.1">
        <joint name="hl" axis="0 0 1"/>
        <geom type="box" size="0.03 0.04 0.2" pos="0.01 0 -0.2" mass="2"/>
        <body name="foot_l" pos="0 0 -0.4">
          <joint name="al" axis="0.2 1 0"/>
          <geom type="box" size="0.1 0.05 0.02" pos="0.03 0 -0.03" mass="0.8"/>
          <site name="sole_l" pos="0.03 0 -0.05"/>
          <site name="ft_l" pos="0 0 0.01"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def _hinge_kernel(m, qpos, qvel, qacc, sites, feet, w, ft, skip=()):
    """:func:`hinge_wrench_batch` on one state (joints in model order; the joints in
    ``skip`` are left out of the columns: at qpos0, still)."""
    from grfguard.kernels.rne import HingeTree, hinge_wrench_batch
    from grfguard.rotations import quat_to_matrix

    hinges = [j for j in range(1, m.njnt) if j not in skip]
    cols = {int(m.jnt_qposadr[j]): c for c, j in enumerate(hinges)}
    ht = HingeTree.from_mujoco(m, cols, list(sites), list(feet))
    q = qpos[[m.jnt_qposadr[j] for j in hinges]][None]
    qd = qvel[[m.jnt_dofadr[j] for j in hinges]][None]
    qdd = qacc[[m.jnt_dofadr[j] for j in hinges]][None]
    base = (quat_to_matrix(qpos[3:7])[None], qvel[None, :3], qvel[None, 3:6], qacc[None, :3],
            qacc[None, 3:6])
    ground, ft_out = np.zeros((1, 2, 6)), np.zeros((1, 2, 6))
    hinge_wrench_batch(np.ascontiguousarray(q), np.ascontiguousarray(qd),
                       np.ascontiguousarray(qdd), tuple(np.ascontiguousarray(b) for b in base),
                       np.array([w], float), np.asarray(m.opt.gravity, float), ht.arrays(), ft,
                       ground, ft_out)
    return ht, ground[0], ft_out[0]


@pytest.mark.parametrize("name", ["talos", "g1", "hinge_xml"])
def test_hinge_tree_matches_mujoco(name, request) -> None:
    """The merged hinge tree (fixed bodies folded into their moving parents, general axes,
    anchors and offsets) gives MuJoCo's ground wrenches and F/T
    readings on random states."""
    if name == "hinge_xml":
        m = mujoco.MjModel.from_xml_string(HINGE_XML)
        soles, feet = [m.site("sole_r").id, m.site("sole_l").id], [m.body("foot_r").id,
                                                                   m.body("foot_l").id]
        fts, ft = [m.site("ft_r").id, m.site("ft_l").id], True
    else:
        robot = request.getfixturevalue(name)
        m = robot.model
        soles = [m.site(f"{s}_sole").id for s in SIDES]
        feet = [m.body(f.body).id for f in robot.description.feet]
        ft = robot.description.sensing == "ft"
        fts = [m.site(f"{s}_ft").id for s in SIDES] if ft else []
    d = mujoco.MjData(m)
    rng = np.random.default_rng(7)
    for trial in range(12):
        qpos, qvel, qacc = _random_state(m, rng)
        qpos[:3] = 0.0  # the kernel puts the base at the origin (the wrenches do not care)
        w = (1.0, 0.0) if trial % 3 == 0 else ((0.0, 1.0) if trial % 3 == 1 else (0.5, 0.5))
        ht, ground, ft_out = _hinge_kernel(m, qpos, qvel, qacc, soles + fts, feet, w, ft)
        assert ht.parent.size == 1 + sum(int(m.body_jntnum[b]) for b in range(2, m.nbody))
        f_ref, alone, _ = _mujoco_reference(m, d, qpos, qvel, qacc, soles, feet)
        scale = max(1.0, np.abs(f_ref).max())
        _assert_ground_and_ft(m, d, (qpos, qvel, qacc), soles, feet, fts if ft else None, w,
                              alone, ground, ft_out, scale)


def test_hinge_tree_joint_left_out_stays_at_qpos0() -> None:
    """A hinge missing from the caller's columns is taken at qpos0, not moving."""
    m = mujoco.MjModel.from_xml_string(HINGE_XML)
    d = mujoco.MjData(m)
    soles, feet = [m.site("sole_r").id, m.site("sole_l").id], [m.body("foot_r").id,
                                                               m.body("foot_l").id]
    qpos, qvel, qacc = _random_state(m, np.random.default_rng(3))
    qpos[:3] = 0.0
    a2 = m.joint("a2").id
    qpos[m.jnt_qposadr[a2]], qvel[m.jnt_dofadr[a2]], qacc[m.jnt_dofadr[a2]] = 0.0, 0.0, 0.0
    _, ground, _ = _hinge_kernel(m, qpos, qvel, qacc, soles, feet, (1.0, 0.0), False, (a2,))
    _, alone, _ = _mujoco_reference(m, d, qpos, qvel, qacc, soles, feet)
    assert np.abs(ground[0] - alone[0]).max() < 1e-9 * max(1.0, np.abs(alone).max())


def test_hinge_tree_declines_other_joints() -> None:
    """Ball and slide joints are not a hinge tree: the caller keeps MuJoCo's arithmetic."""
    from grfguard.kernels.rne import HingeTree

    m = mujoco.MjModel.from_xml_string(BALL_SLIDE_XML)
    assert HingeTree.from_mujoco(m, {}, [m.site("tip").id], [m.body("leg").id]) is None


def test_sincos_within_an_ulp_of_libm() -> None:
    """The vectorisable sine and cosine of the hinge kernels
    (:func:`grfguard.kernels.rne.sincos_flat`): within one ulp of numpy's (libm's) for
    joint angles, two ulps up to :data:`SINCOS_MAX`, libm's beyond; NaN and infinities
    give NaN; exact at 0 and pi/2 where libm is."""
    from grfguard.kernels.rne import SINCOS_MAX, sincos_flat

    rng = np.random.default_rng(3)
    for span, ulps in ((1.0, 1), (10.0, 1), (SINCOS_MAX, 2)):
        x = rng.uniform(-span, span, 200_000)
        sn, cs = np.empty_like(x), np.empty_like(x)
        sincos_flat(x, x.size, sn, cs)
        for got, ref in ((sn, np.sin(x)), (cs, np.cos(x))):
            err = np.abs(got - ref) / np.spacing(np.abs(ref))
            assert err.max() <= ulps, (span, err.max())
    x = np.array([0.0, np.pi / 2, 3e5, -1e12, np.nan, np.inf, -np.inf])
    sn, cs = np.empty_like(x), np.empty_like(x)
    sincos_flat(x, x.size, sn, cs)
    with np.errstate(invalid="ignore"):
        np.testing.assert_array_equal(sn, np.sin(x))
        np.testing.assert_array_equal(cs, np.cos(x))


def _hinge_case(name, request):
    """(model, sole and F/T sites, feet, has F/T) of a shipped robot or the small
    hinge model."""
    if name == "hinge_xml":
        m = mujoco.MjModel.from_xml_string(HINGE_XML)
        sites = [m.site(s).id for s in ("sole_r", "sole_l", "ft_r", "ft_l")]
        return m, sites, [m.body("foot_r").id, m.body("foot_l").id], True
    robot = request.getfixturevalue(name)
    m = robot.model
    ft = robot.description.sensing == "ft"
    sites = [m.site(f"{s}_sole").id for s in SIDES] + (
        [m.site(f"{s}_ft").id for s in SIDES] if ft else [])
    return m, sites, [m.body(f.body).id for f in robot.description.feet], ft


@pytest.mark.parametrize("name", ["talos", "g1", "hinge_xml"])
def test_hinge_kernels_lanes_equal_one_sample_at_a_time(name, request) -> None:
    """:func:`hinge_wrench_batch` and :func:`hinge_frames_batch` run groups of
    :data:`~grfguard.kernels.lanes.LANES` samples through vector lanes (a block's last,
    partial group padded with copies of its last sample): a log of random states
    (several blocks, a partial group, the small model's tree shorter than the lane
    scratch's header) gives, bit for bit, what each state gives alone in lane 0, which the
    MuJoCo tests above check; no sample's lane leaks into another's."""
    from grfguard.kernels.lanes import LANES
    from grfguard.kernels.rne import (
        SC_BLOCK,
        HingeTree,
        hinge_frames_batch,
        hinge_wrench_batch,
        site_paths,
    )
    from grfguard.rotations import quat_to_matrix

    m, sites, feet, ft = _hinge_case(name, request)
    hinges = list(range(1, m.njnt))
    ht = HingeTree.from_mujoco(m, {int(m.jnt_qposadr[j]): c for c, j in enumerate(hinges)},
                               sites, feet)
    rng = np.random.default_rng(11)
    T = SC_BLOCK + 3 * LANES + 5
    states = [_random_state(m, rng) for _ in range(T)]
    q = np.array([[s[0][m.jnt_qposadr[j]] for j in hinges] for s in states])
    qd = np.array([[s[1][m.jnt_dofadr[j]] for j in hinges] for s in states])
    qdd = np.array([[s[2][m.jnt_dofadr[j]] for j in hinges] for s in states])
    base = (np.array([quat_to_matrix(s[0][3:7]) for s in states]),
            np.array([s[1][:3] for s in states]), np.array([s[1][3:6] for s in states]),
            np.array([s[2][:3] for s in states]), np.array([s[2][3:6] for s in states]))
    W = rng.uniform(0.0, 1.0, (T, 2))
    g = np.asarray(m.opt.gravity, float)
    ground, ft_out = np.zeros((T, 2, 6)), np.zeros((T, 2, 6))
    hinge_wrench_batch(q, qd, qdd, base, W, g, ht.arrays(), ft, ground, ft_out)
    paths = site_paths(ht)
    pos, mat = np.zeros((T, len(sites), 3)), np.zeros((T, len(sites), 9))
    hinge_frames_batch(q, ht.arrays(), paths, pos, mat)
    for t in range(T):
        one = slice(t, t + 1)
        g1_, f1_ = np.zeros((1, 2, 6)), np.zeros((1, 2, 6))
        hinge_wrench_batch(q[one], qd[one], qdd[one], tuple(np.ascontiguousarray(b[one])
                                                            for b in base),
                           W[one], g, ht.arrays(), ft, g1_, f1_)
        p1, r1 = np.zeros((1, len(sites), 3)), np.zeros((1, len(sites), 9))
        hinge_frames_batch(q[one], ht.arrays(), paths, p1, r1)
        assert np.array_equal(ground[t], g1_[0]), t
        assert np.array_equal(ft_out[t], f1_[0]), t
        assert np.array_equal(pos[t], p1[0]) and np.array_equal(mat[t], r1[0]), t
    assert np.isfinite(ground).all() and np.abs(ground).max() > 1.0
