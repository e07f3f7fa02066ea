"""Compiled virtual force sensor against the pure-Python stages (tests/reference) on a real
simulated walk; streaming equals batch; the compliance QP against exact rationals."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.errors import LogFormatError
from grfguard.estimate.config import VFSConfig
from grfguard.estimate.vfs import VFS_OUTPUT_COLUMNS
from grfguard.io.schema import CONTACT_REF, IMU_GYRO, JOINT_COLUMNS
from grfguard.kernels import CompiledVirtualForceSensor, vfs_batch
from grfguard.kernels.nnls import new_scratch, prior_qp
from grfguard.model.robot import SURALP
from grfguard.sim import GaitConfig, NoiseConfig, simulate
from kernels_reference import exact_prior_qp
from reference.nnls_split import nnls_prior_qp
from reference.vfs_stages import PythonVFS

FORCE_COLS = [c for c in VFS_OUTPUT_COLUMNS if c.startswith("vfs_") and c != "vfs_valid"]
#: Corner forces, totals [N]. Rounding differences: the QP (nnls vs. ours) and the
#: kinematics (the kernel poses the bodies in base axes, eight samples at a time
#: (grfguard.kernels.front), the reference in MuJoCo's order: positions within about
#: 1e-15 m, which the rates' second differences multiply by 1 / dt^2 = 1e6), and the
#: angular momentum (the kernel's from trunk-frame sums, the reference's from world-axes
#: poses). Measured up to 3e-9 N over this module's walks and settings.
TOL_N = 1e-8
#: ZMP [m]: the same rates (measured up to 7e-13 m, 2e-10 m without the gyro).
TOL_ZMP = 1e-9


@pytest.fixture(scope="module")
def walk() -> pd.DataFrame:
    """6 s SURALP walk with default sensor noise (3 steps, single and double support)."""
    return simulate(SURALP, GaitConfig(duration=6.0), NoiseConfig(), seed=3)


def _assert_same(ref: pd.DataFrame, out: pd.DataFrame, tol_n: float = TOL_N) -> None:
    assert list(out.columns) == list(ref.columns)
    for c in ref.columns:
        a = ref[c].to_numpy(float)
        b = out[c].to_numpy(float)
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=c)
        ok = ~np.isnan(a)
        if c.startswith(("vfs_r", "vfs_l", "vfs_total")):
            tol = tol_n
        elif c.startswith("vfs_cop"):
            tol = 1e-9  # [m]
        elif c.startswith("zmp_"):
            tol = TOL_ZMP
        else:
            tol = 1e-12  # CoM [m] (measured 8e-15), contact and valid flags
        err = float(np.abs(a[ok] - b[ok]).max()) if ok.any() else 0.0
        assert err <= tol, f"{c}: {err:.3e} > {tol:.0e}"


def test_batch_matches_python_sensor_on_walk(walk):
    ref = PythonVFS.for_log(walk).run(walk)
    out = vfs_batch(walk)
    _assert_same(ref, out)
    # the walk exercises single and double support and every corner
    assert (ref["contact_est_r"] * ref["contact_est_l"]).sum() > 100
    assert (ref[FORCE_COLS[:8]].to_numpy() > 1.0).any(axis=0).all()


def test_streaming_equals_batch_bit_for_bit(walk):
    vfs = CompiledVirtualForceSensor.for_log(walk)
    batch = vfs.run(walk)
    vfs.reset()
    rows = walk.iloc[:1500]
    stream = pd.DataFrame([vfs.update(r) for r in rows.to_dict("records")], index=rows.index)
    np.testing.assert_array_equal(stream.to_numpy(), batch.iloc[:1500].to_numpy())


def test_bad_samples_hold_like_python_sensor(walk):
    log = walk.iloc[:800].copy()
    log.iloc[0, log.columns.get_loc("q_r_knee") if "q_r_knee" in log else 20] = np.nan
    log.loc[log.index[100:105], "imu_quat_w"] = np.nan
    log.loc[log.index[300], ["imu_quat_w", "imu_quat_x", "imu_quat_y", "imu_quat_z"]] = 0.0
    log.loc[log.index[500], "imu_gyro_x"] = np.inf
    ref = PythonVFS.for_log(log).run(log)
    out = vfs_batch(log)
    _assert_same(ref, out)
    assert ref["vfs_valid"].sum() < len(log)
    # streaming (dict call) holds the same way as the Python sensor's update
    py = PythonVFS.for_log(log)
    cv = CompiledVirtualForceSensor.for_log(log)
    for r in log.iloc[95:110].to_dict("records"):
        a, b = py.update(r), cv.update(r)
        for k in VFS_OUTPUT_COLUMNS:
            assert (np.isnan(a[k]) and np.isnan(b[k])) or abs(a[k] - b[k]) <= TOL_N, k


def test_streaming_equals_batch_around_invalid_rows(walk):
    # the momentum's sums come from the block only when the previous valid sample is the
    # row before; invalid rows at a block's first and last lanes, runs of them across a
    # block boundary and a repeated row make the samples after them compute alone
    from grfguard.kernels.vfs import log_to_array

    log = walk.iloc[:400].copy()
    q = log.columns.get_loc(JOINT_COLUMNS[3])
    for r in (8, 15, 16, 17, 23, 24, 39, 40, 41, 42, 43, 44, 45, 46, 47, 48, 121):
        log.iloc[r, q] = np.nan
    log.iloc[200] = log.iloc[199]  # the same joint angles twice
    log.loc[log.index[300], "imu_quat_w"] = np.nan  # valid angles, invalid sample
    vfs = CompiledVirtualForceSensor.for_log(log)
    batch = vfs.run(log).to_numpy()
    X, _, _ = log_to_array(log)
    vfs.reset()
    stream = np.array([vfs.update_array(x) for x in X])
    assert stream.tobytes() == batch.tobytes()
    assert (batch[:, -1] == 0.0).sum() == 18  # the invalid rows
    ref = PythonVFS.for_log(log).run(log)
    _assert_same(ref, vfs.run(log))


@pytest.mark.parametrize(("drop", "tol_n"), [(IMU_GYRO, 1e-5), (CONTACT_REF, TOL_N)])
def test_missing_optional_columns(walk, drop, tol_n):
    # Without the gyro the logged attitude jitter reaches the ZMP and some corner QPs get
    # ill-conditioned: scipy's nnls is then off the exact minimiser by up to 2e-6 N
    # (measured against exact rationals), ours by 1e-8 N; hence the looser tolerance.
    log = walk.iloc[:1500].drop(columns=list(drop))
    ref = PythonVFS.for_log(log).run(log)
    _assert_same(ref, vfs_batch(log), tol_n)


def test_settings_variants_match(walk):
    log = walk.iloc[:1500]
    for cfg in (
        VFSConfig(use_accelerometer=False, use_angular_momentum=False),
        VFSConfig(accelerometer_vertical=True, kinematic_contact=False, filter_order=3),
        VFSConfig(use_accelerometer=False, filter_cutoff=8.0, filter_damping=0.4),
        VFSConfig(use_accelerometer=False, filter_lead=0.005),
        VFSConfig(use_accelerometer=False, filter_cutoff=8.0, filter_damping=0.45,
                  filter_lead=0.003),
    ):
        ref = PythonVFS.for_log(log, cfg).run(log)
        out = CompiledVirtualForceSensor.for_log(log, cfg).run(log)
        _assert_same(ref, out)


def test_every_setting_is_compiled(walk):
    cfg = VFSConfig.paper()
    log = walk.iloc[:300]
    cv = CompiledVirtualForceSensor.for_log(log, cfg)
    assert cv.compiled and cv.kernel().n_in == 34  # + force sensors and planned ZMP
    ref = PythonVFS.for_log(log, cfg).run(log)
    _assert_same(ref, cv.run(log))


def test_compliance_qp_against_exact_rationals():
    rng = np.random.default_rng(7)
    scratch = new_scratch()
    worst_ours = worst_scipy = 0.0
    for _ in range(150):
        n = int(rng.integers(1, 9))
        rel = rng.uniform(-0.15, 0.15, (n, 2))
        total = float(rng.uniform(50.0, 1500.0))
        prior = total / n + 4.8e5 * rng.normal(0.0, 2e-3, n)
        x = scratch[0]
        prior_qp(rel, prior, total, 1e-3, n, *scratch)
        ours = x[:n] * (total / x[:n].sum())
        ref = nnls_prior_qp(rel, prior, total, 1e-3)
        exact = exact_prior_qp(rel, prior, total, 1e-3, ours > 0)
        worst_ours = max(worst_ours, float(np.abs(ours - exact).max()))
        worst_scipy = max(worst_scipy, float(np.abs(ref - exact).max()))
        assert np.all(ours >= 0.0)
    # both solve the same problem; ours is at least as close to the exact minimiser
    assert worst_ours <= 1e-10  # measured 2e-12 N
    assert worst_scipy <= 1e-7  # measured 2e-9 N


def test_warm_started_qp_is_exact_and_independent_of_the_guess():
    # prior_qp_warm (the split inside the sensor, started from the last sample's positive
    # corners) gives the exact minimiser, the same bits for every starting guess, and
    # prior_qp's bits when every corner is positive
    from grfguard.kernels.nnls import prior_qp_warm

    rng = np.random.default_rng(11)
    scratch, scratch2 = new_scratch(), new_scratch()
    worst = 0.0
    n_partial = 0
    for _ in range(120):
        n = int(rng.integers(2, 9))
        rel = rng.uniform(-0.15, 0.15, (n, 2))
        total = float(rng.uniform(50.0, 1500.0))
        prior = total / n + 4.8e5 * rng.normal(0.0, 2e-3, n)
        prior_qp(rel, prior, total, 1e-3, n, *scratch2)
        cold = scratch2[0][:n].copy()
        answers = set()
        for guess in {0, (1 << n) - 1, *(int(g) for g in rng.integers(0, 1 << n, 6))}:
            mask = prior_qp_warm(rel, prior, total, 1e-3, n, *scratch, guess)
            x = scratch[0][:n].copy()
            assert mask == sum(1 << j for j in range(n) if x[j] > 0.0)
            answers.add(x.tobytes())
        assert len(answers) == 1  # the same bits whatever the guess
        if mask == (1 << n) - 1:
            assert np.array_equal(x, cold)
        else:
            n_partial += 1
        ours = x * (total / x.sum())
        exact = exact_prior_qp(rel, prior, total, 1e-3, ours > 0)
        worst = max(worst, float(np.abs(ours - exact).max()))
    assert n_partial > 20  # the active set matters in many of the problems
    assert worst <= 1e-10


def test_array_call_rejects_wrong_shapes_and_survives_garbage(walk):
    vfs = CompiledVirtualForceSensor.for_log(walk)
    with pytest.raises(LogFormatError, match="IN_COLUMNS"):
        vfs.update_array(np.zeros(23))
    with pytest.raises(LogFormatError, match=r"\(T, 24\)"):
        vfs.kernel().run(np.zeros((5, 20)))
    # garbage rows never raise: NaN output (nothing valid yet) with vfs_valid = 0
    y = vfs.update_array(np.full(24, np.inf))
    assert np.isnan(y[:-1]).all() and y[-1] == 0.0
    y = vfs.update(dict.fromkeys(["q_r_hip_yaw", "imu_quat_w"], "junk"))
    assert y["vfs_valid"] == 0.0
    # an integer too large for a float is a bad value too, not a crash of the live sensor
    row = walk.iloc[0].to_dict()
    row["q_r_knee"] = 10**400
    assert vfs.update(row)["vfs_valid"] == 0.0
    row["q_r_knee"] = float(walk["q_r_knee"].iloc[0])
    assert vfs.update(row)["vfs_valid"] == 1.0


def test_for_log_builds_the_streaming_step_before_the_first_sample(walk):
    """``for_log`` builds the sensor's streaming step and finds its machine code before
    any sample (built at the first call, it took that sample 1.4-2.8 ms); ``warm=False``
    leaves both to the first call. The state is untouched: both give the same bits."""
    vfs = CompiledVirtualForceSensor.for_log(walk)
    k = vfs._kern.get((True, True))
    assert k is not None and k._entry is not None
    lazy = CompiledVirtualForceSensor.for_log(walk, warm=False)
    assert lazy._kern == {}
    rows = walk.iloc[:200].to_dict("records")
    got = np.array([list(vfs.update(r).values()) for r in rows])
    want = np.array([list(lazy.update(r).values()) for r in rows])
    assert vfs.kernel() is k
    np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))


def test_prepare_builds_the_streaming_step_of_a_sensor_built_directly(walk):
    """A sensor built directly (no log) has no streaming step until :meth:`prepare`,
    which builds it without a sample; the outputs are those of an unprepared sensor."""
    direct = CompiledVirtualForceSensor(SURALP)
    assert direct._kern == {}
    assert direct.prepare() is direct
    k = direct._kern.get((True, True))
    assert k is not None and k._entry is not None
    lazy = CompiledVirtualForceSensor(SURALP)
    rows = walk.iloc[:100].to_dict("records")
    got = np.array([list(direct.update(r).values()) for r in rows])
    want = np.array([list(lazy.update(r).values()) for r in rows])
    assert direct.kernel() is k
    np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))
