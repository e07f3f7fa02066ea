"""The pattern generator's faster paths give the values of the plain numpy ones, bit for bit.

Every figure of BENCHMARKS.md comes from simulated walks, so the planner's speed-ups
(compiled body chain, identity products left out of the leg IK, the preview loop over
Python floats, the inverse dynamics' states built at once) must not move a bit: each is
compared here with the straightforward code it replaced.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from grfguard.model import kinematics as K
from grfguard.model.mjcf import build_mjcf
from grfguard.model.robot import SIDES, SURALP, RobotConfig
from grfguard.rotations import rot_x, rot_y, rot_z
from grfguard.sim import pattern as P

SMALL = RobotConfig(
    name="small", mass=60.0, foot_length=0.20, foot_width=0.12, upper_leg_length=0.22,
    lower_leg_length=0.21, sole_to_ankle=0.09, hip_width=0.16,
)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal values and equal signs of zero."""
    a, b = np.asarray(a), np.asarray(b)
    return bool(np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b)))


@pytest.fixture()
def numpy_path(monkeypatch):
    """Run the kinematics on numpy's path only."""

    def run(fn, *args):
        with monkeypatch.context() as m:
            m.setattr(K, "_COMPILED_MIN_SAMPLES", 10**12)
            return fn(*args)

    return run


@pytest.mark.parametrize("robot", [SURALP, SMALL], ids=["suralp", "small"])
@pytest.mark.parametrize("n", [256, 999, 12001])
def test_compiled_chain_equals_numpy(robot, n, numpy_path):
    rng = np.random.default_rng(n)
    q = rng.normal(0.0, 0.5, (n, 12))
    q[:, 0] = -0.0  # hip yaw: the planner's IK gives -0.0
    q[::7, 5] = 0.0
    p = rng.normal(0.0, 0.3, (n, 3))
    for R_WB in (np.eye(3), rot_z(0.3) @ rot_x(-0.2)):
        for p_WB in (p, p[0]):
            fast = K.body_poses(robot, p_WB, R_WB, q)
            ref = numpy_path(K.body_poses, robot, p_WB, R_WB, q)
            assert fast.keys() == ref.keys()
            for name in ref:
                assert _same(fast[name][0], ref[name][0]), name
                assert _same(fast[name][1], ref[name][1]), name
            assert _same(K.center_of_mass(robot, p_WB, R_WB, q),
                         numpy_path(K.center_of_mass, robot, p_WB, R_WB, q))


def test_compiled_chain_is_used_where_exact_and_not_elsewhere(monkeypatch):
    n = K._COMPILED_MIN_SAMPLES
    q = np.random.default_rng(4).normal(0.0, 0.5, (n, 12))
    p = np.zeros((n, 3))
    # the probe's verdict is what comparing the two paths gives on this machine
    fast = K._compiled_poses(SURALP, *K._as_traj(p, np.eye(3), n), q)[0]
    slow = K._numpy_poses(SURALP, *K._as_traj(p, np.eye(3), n), q)
    same = all(_same(fast[k][i], slow[k][i]) for k in slow for i in (0, 1))
    assert K._probe_same_bits() == same
    # the compiled path returns views of one (nb, T, 3) block, numpy's separate arrays
    poses = K.body_poses(SURALP, np.zeros(3), np.eye(3), q)
    assert (poses["r_foot"][0].base is not None) == K._use_compiled(n)
    assert K.body_poses(SURALP, np.zeros(3), np.eye(3), q[:-1])["r_foot"][0].base is None
    monkeypatch.setattr(K, "_COMPILED_SAME_BITS", False)  # a machine that multiplies otherwise
    assert K.body_poses(SURALP, np.zeros(3), np.eye(3), q)["r_foot"][0].base is None
    assert _same(K.center_of_mass(SURALP, p, np.eye(3), q), K._numpy_com(SURALP, slow))


def test_one_compiled_signature_whatever_the_layout():
    from grfguard.kernels import chain

    n = K._COMPILED_MIN_SAMPLES
    q = np.zeros((n, 12))
    K._compiled_poses(SURALP, *K._as_traj(np.zeros(3), np.eye(3), n), q)
    K._compiled_poses(SURALP, *K._as_traj(np.zeros((n, 3))[:, ::-1], rot_z(0.1), n), q)
    _, p0, R0, P, R = K._compiled_poses(SURALP, *K._as_traj(np.zeros((n, 3)), np.eye(3), n), q)
    K._compiled_com(SURALP, p0, R0, P, R)
    chain.warm()
    assert len(chain.chain_poses.signatures) == 1
    assert len(chain.chain_com.signatures) == 1


def test_hip_entries_equal_the_matrix_product():
    rng = np.random.default_rng(1)
    a = np.concatenate([rng.uniform(-np.pi / 2, np.pi / 2, 20000),
                        [0.0, -0.0, np.pi / 2, -np.pi / 2, 1e-300, -5e-324, 0.0]])
    b = np.concatenate([rng.uniform(-1.5, 1.5, 20000),
                        [0.0, -0.0, 1e-300, -0.0, 0.0, -5e-324, -1e-300]])
    R = rot_x(a) @ rot_y(b)
    for (i, j), v in zip([(0, 1), (1, 1), (2, 0), (2, 1), (2, 2)], K._hip_entries(a, b),
                            strict=True):
        assert _same(v, R[:, i, j]), (i, j)


@pytest.mark.parametrize("side", SIDES)
def test_leg_ik_without_identity_products_equals_the_general_path(side):
    """An upright pelvis and flat sole given as (3, 3) take the short path; given as
    stacks of identities, the general products: same bits."""
    rng = np.random.default_rng(2)
    n = 5000
    y = SURALP.hip_width / 2 * (1 if side == "l" else -1)
    p_WB = np.column_stack([rng.normal(0, 0.05, n), y + rng.normal(0, 0.05, n),
                            np.full(n, 0.85 * SURALP.leg_length)])
    p_WS = np.column_stack([rng.normal(0, 0.1, n), np.full(n, y), rng.uniform(0, 0.05, n)])
    p_WS[::11, 1] = p_WB[::11, 1] + y  # hip over ankle: ankle roll exactly 0
    eye = np.eye(3)
    stack = np.broadcast_to(eye, (n, 3, 3)).copy()
    fast = K.leg_ik(SURALP, side, p_WB, eye, p_WS, eye)
    general = K.leg_ik(SURALP, side, p_WB, stack, p_WS, stack)
    assert np.isfinite(fast).all() and (fast[::11, 5] == 0.0).all()
    assert _same(fast, general)


def _preview_reference(zmp_ref, dt, com_height, gravity, horizon, start=None):
    """The preview loop as first written (numpy item writes)."""
    g_i, g_x, g_d, A, B = P.preview_gains(dt, com_height, gravity, horizon)
    p = np.asarray(zmp_ref, dtype=float)
    k_n, d = p.shape
    n = g_d.size
    pad = np.concatenate([p, np.repeat(p[-1:], n, axis=0)], axis=0)
    f = np.lib.stride_tricks.sliding_window_view(pad[1:], n, axis=0)[:k_n] @ g_d
    cz = com_height / gravity
    states, jerk = np.empty((k_n, 3, d)), np.empty((k_n, d))
    a, b = A.tolist(), B.tolist()
    gx0, gx1, gx2 = (float(v) for v in g_x)
    for ax in range(d):
        c0 = float(p[0, ax]) if start is None else float(start)
        c1 = c2 = esum = 0.0
        for k in range(k_n):
            esum += c0 - cz * c2 - p[k, ax]
            u = -g_i * esum - gx0 * c0 - gx1 * c1 - gx2 * c2 - f[k, ax]
            states[k, :, ax] = c0, c1, c2
            jerk[k, ax] = u
            c0, c1, c2 = (c0 + a[0][1] * c1 + a[0][2] * c2 + b[0] * u,
                          c1 + a[1][2] * c2 + b[1] * u, c2 + b[2] * u)
    return states, jerk


@pytest.mark.parametrize("start", [None, 0.0])
def test_preview_loop_equals_the_first_version(start):
    rng = np.random.default_rng(3)
    zmp = np.cumsum(rng.normal(0, 1e-3, (3000, 2)), axis=0)
    got = P.preview_control(zmp, 0.005, 0.8, 9.81, 1.6, start=start)
    ref = _preview_reference(zmp, 0.005, 0.8, 9.81, 1.6, start=start)
    assert _same(got[0], ref[0]) and _same(got[1], ref[1])


def test_feedforward_torques_equal_per_sample_states():
    """The inverse dynamics' states built at once give the torques of states set up
    sample by sample."""
    from scipy.interpolate import CubicSpline

    from grfguard.sim.config import GaitConfig

    plan = P.plan_walk(SURALP, GaitConfig(duration=4.0, torque_feedforward=False))
    t, pel, q = plan.time, plan.pelvis_pos, plan.q_ref
    share = np.linspace(0.0, 1.0, t.size)
    got = P.feedforward_torques(SURALP, t, pel, q, share, stride=5)

    model = mujoco.MjModel.from_xml_string(build_mjcf(SURALP))
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    data = mujoco.MjData(model)
    dt = float(t[1] - t[0])
    qd = np.gradient(q, dt, axis=0)
    qdd = np.gradient(qd, dt, axis=0)
    vb = np.gradient(pel, dt, axis=0)
    ab = np.gradient(vb, dt, axis=0)
    idx = np.unique(np.append(np.arange(0, t.size, 5), t.size - 1))
    sites = [model.site(f"{s}_sole").id for s in SIDES]
    f_inv = np.empty((idx.size, model.nv))
    jacs = np.zeros((2, idx.size, 6, model.nv))
    for n, k in enumerate(idx):
        data.qpos[:3], data.qpos[3:7], data.qpos[7:] = pel[k], (1.0, 0.0, 0.0, 0.0), q[k]
        data.qvel[:] = 0.0
        data.qvel[:3], data.qvel[6:] = vb[k], qd[k]
        data.qacc[:] = 0.0
        data.qacc[:3], data.qacc[6:] = ab[k], qdd[k]
        mujoco.mj_inverse(model, data)
        f_inv[n] = data.qfrc_inverse
        for i, site in enumerate(sites):
            mujoco.mj_jacSite(model, data, jacs[i, n, :3], jacs[i, n, 3:], site)
    sh = np.stack([share[idx], 1.0 - share[idx]])
    ground = np.zeros((idx.size, 12))
    for i in range(2):
        w = np.linalg.solve(np.swapaxes(jacs[i, :, :, :6], 1, 2), f_inv[:, :6, None])[..., 0]
        ground += sh[i][:, None] * np.einsum("nrj,nr->nj", jacs[i, :, :, 6:], w)
    ref = CubicSpline(t[idx], f_inv[:, 6:] - ground)(t)
    assert _same(got, ref)
