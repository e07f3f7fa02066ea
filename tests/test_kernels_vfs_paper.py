"""The compiled stages of the virtual sensor's non-default settings
(:mod:`grfguard.kernels.vfs_paper`: the paper's LIPM CoM filter and split, the pendulum
Kalman ZMP, the anchor attitude, the rigid corner QP) against the pure-Python stages on a
real simulated 10 s walk: equal to 1e-9 N, streaming equals batch, pickling mid-walk."""

from __future__ import annotations

import pickle

import numpy as np
import pandas as pd
import pytest

from grfguard.estimate.vfs import VFS_OUTPUT_COLUMNS, VFSConfig, VirtualForceSensor
from grfguard.faults import inject_faults, parse_fault_spec
from grfguard.sim import GaitConfig, NoiseConfig, simulate
from reference.vfs_stages import PythonVFS

TOL_N = 1e-9  # forces [N]
TOL_M = 1e-9  # CoM, ZMP, CoP [m]

#: The settings the default kernel lacked, each on its own and the paper's method whole.
CONFIGS = {
    "paper_com": VFSConfig(com_method="paper"),
    "paper_split": VFSConfig(split_method="paper", qp_weight=0.01),
    "paper": VFSConfig.paper(),
    "kalman_zmp": VFSConfig(use_accelerometer=False, zmp_filter="kalman"),
    "anchor_attitude": VFSConfig(anchor_attitude_time_constant=1.0),
    "rigid_qp": VFSConfig(contact_stiffness_per_kg=0.0),
    "contact_twist": VFSConfig(use_accelerometer=False, contact_twist=0.42),
    "paper_anchor_no_dob": VFSConfig.paper(anchor_attitude_time_constant=0.5,
                                           paper_dob_gain=0.0, lipm_height=0.75),
}


def reference_run(log: pd.DataFrame, cfg: VFSConfig) -> pd.DataFrame:
    """The pure-Python stages (tests/reference/vfs_stages.py) over the whole log."""
    return PythonVFS.for_log(log, cfg).run(log)


@pytest.fixture(scope="module")
def walk() -> pd.DataFrame:
    """10 s SURALP walk, default noise, a 150 N offset on r1 from 4 s (the paper's CoM
    filter reads the force sensors, so a fault reaches its outputs)."""
    log = simulate(gait=GaitConfig(duration=10.0), noise=NoiseConfig(), seed=0)
    return inject_faults(log, [parse_fault_spec("r1=offset:150@4")], seed=0)


def _max_err(ref: pd.DataFrame, out: pd.DataFrame) -> tuple[float, float]:
    """Largest difference of the force columns [N] and of the others."""
    ef = eo = 0.0
    for c in VFS_OUTPUT_COLUMNS:
        a, b = ref[c].to_numpy(float), out[c].to_numpy(float)
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=c)
        ok = ~np.isnan(a)
        e = float(np.abs(a[ok] - b[ok]).max()) if ok.any() else 0.0
        if c.startswith(("vfs_r", "vfs_l", "vfs_total")):
            ef = max(ef, e)
        else:
            eo = max(eo, e)
    return ef, eo


@pytest.mark.parametrize("name", list(CONFIGS))
def test_compiled_equals_python_stages(walk, name):
    cfg = CONFIGS[name]
    vfs = VirtualForceSensor.for_log(walk, cfg)
    assert vfs.compiled
    out = vfs.run(walk)
    ref = reference_run(walk, cfg)
    ef, eo = _max_err(ref, out)
    assert ef <= TOL_N, f"{name}: forces differ by {ef:.2e} N"
    assert eo <= TOL_M, f"{name}: CoM/ZMP/CoP differ by {eo:.2e} m"
    # the walk loads both feet, in single and double support
    assert (ref["vfs_total_r"] > 100).any() and (ref["vfs_total_l"] > 100).any()
    assert (ref["contact_est_r"] * ref["contact_est_l"]).sum() > 500


def test_paper_com_reads_the_force_sensors(walk):
    # the offset on r1 moves the measured ZMP and so the paper's CoM (and not the default's)
    clean = simulate(gait=GaitConfig(duration=10.0), noise=NoiseConfig(), seed=0)
    for cfg, moves in ((VFSConfig.paper(), True), (VFSConfig(), False)):
        a = VirtualForceSensor.for_log(clean, cfg).run(clean)["com_est_x"].to_numpy()
        b = VirtualForceSensor.for_log(walk, cfg).run(walk)["com_est_x"].to_numpy()
        assert (np.abs(a - b)[8000:].max() > 1e-3) == moves


@pytest.mark.parametrize("name", ["paper", "anchor_attitude", "kalman_zmp"])
def test_streaming_equals_batch_and_pickles(walk, name):
    cfg = CONFIGS[name]
    log = walk.iloc[:1200]
    vfs = VirtualForceSensor.for_log(log, cfg)
    batch = vfs.run(log)
    vfs.reset()
    rows = log.to_dict("records")
    first = [vfs.update(r) for r in rows[:600]]
    twin = pickle.loads(pickle.dumps(vfs))
    rest = [vfs.update(r) for r in rows[600:]]
    rest_twin = [twin.update(r) for r in rows[600:]]
    stream = pd.DataFrame(first + rest, index=log.index)
    np.testing.assert_array_equal(stream.to_numpy(), batch.to_numpy())
    np.testing.assert_array_equal(pd.DataFrame(rest_twin).to_numpy(),
                                  batch.iloc[600:].to_numpy())


def test_paper_bad_samples_held_like_python_stages(walk):
    log = walk.iloc[:1500].copy()
    log.loc[log.index[200:205], "force_l3"] = np.nan  # the paper's filter reads them
    log.loc[log.index[400], "imu_acc_y"] = np.inf
    log.loc[log.index[600:700], ["zmp_ref_x", "zmp_ref_y"]] = np.nan  # optional: DOB paused
    cfg = VFSConfig.paper()
    out = VirtualForceSensor.for_log(log, cfg).run(log)
    ref = reference_run(log, cfg)
    ef, eo = _max_err(ref, out)
    assert ef <= TOL_N and eo <= TOL_M
    assert out["vfs_valid"].iloc[200:205].eq(0).all() and out["vfs_valid"].iloc[400] == 0
    assert out["vfs_valid"].iloc[600:700].eq(1).all()
    np.testing.assert_array_equal(out["vfs_r1"].iloc[200:205], out["vfs_r1"].iloc[199])


def test_contact_twist_twists_only_the_loaded_flat_soles(walk):
    """``VFSConfig.contact_twist``: where the planar split loads all four corners of a sole
    and the twisted one still does, the sole's load and centre of pressure (``P``, ``R``)
    stay and its twist becomes ``f1 - f2 - f3 + f4 = kappa P R / S``; a sole in the air
    does not move; no corner goes below 0."""
    base = VFSConfig(use_accelerometer=False)
    a = VirtualForceSensor.for_log(walk, base).run(walk)
    b = VirtualForceSensor.for_log(walk, base.replace(contact_twist=0.42)).run(walk)
    for side in "rl":
        fa = a[[f"vfs_{side}{k}" for k in range(1, 5)]].to_numpy(float)
        fb = b[[f"vfs_{side}{k}" for k in range(1, 5)]].to_numpy(float)
        both = np.all(fa > 0, axis=1) & np.all(fb > 0, axis=1)
        single = both & (b[f"contact_est_{'l' if side == 'r' else 'r'}"].to_numpy() == 0)
        for pat in ((1, 1, 1, 1), (1, 1, -1, -1), (1, -1, 1, -1)):
            np.testing.assert_allclose((fb @ np.array(pat))[single],
                                       (fa @ np.array(pat))[single], atol=1e-6)
        P, R, S = (fa[single] @ np.array(p) for p in ((1, 1, -1, -1), (1, -1, 1, -1),
                                                      (1, 1, 1, 1)))
        T = fb[single] @ np.array([1, -1, -1, 1])
        assert single.sum() > 1000
        np.testing.assert_allclose(T, 0.42 * P * R / S, rtol=1e-6, atol=1e-6)
        assert np.abs(T).max() > 5.0  # the twist is not negligible on this walk
        air = np.all(fa == 0, axis=1)
        np.testing.assert_array_equal(fb[air], 0.0)
        assert np.all(fb >= 0)


def test_contact_twist_out_of_range_is_refused():
    with pytest.raises(Exception, match="contact_twist"):
        VFSConfig(contact_twist=9.0)


def test_contact_twist_needs_the_front_left_first_sole_layout():
    from grfguard.errors import ConfigError
    from grfguard.kernels.vfs import _check_twist_layout
    from grfguard.model.robot import SURALP

    p = SURALP.sensor_positions_in_foot()
    _check_twist_layout(p)  # front-left, front-right, rear-left, rear-right
    with pytest.raises(ConfigError, match="front-left, front-right, rear-left, rear-right"):
        _check_twist_layout(p[[0, 2, 1, 3]])
