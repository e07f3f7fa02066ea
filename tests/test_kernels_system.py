"""The compiled system-level layer (``grfguard/kernels/system.py``) equals the Python one.

``Monitor(..., common_mode=True)`` runs the common-mode fit, the load-cell zero, gyro bias
and IMU tilt learners and the accelerometer vibration switch inside the compiled monitor
step; ``compiled=False`` runs the Python stages of ``grfguard/detect/system.py`` and
``grfguard/pipeline.py``. On simulated walks with reality gaps (``grfguard/data/reality``)
and the paper's faults on top: flags, kinds, onsets, ``model_mismatch`` and its reason
identical, forces equal to 1e-9 N (1e-5 N where the IMU tilt learner rotates the IMU
readings: it sums sole normals from MuJoCo's kinematics in Python and from the compiled
kinematics here, equal to about 1e-15, and the virtual sensor's finite differences of
the attitude steps amplify that). Streaming equals batch; a pickled monitor continues
where it was.
"""

from __future__ import annotations

import math
import pickle

import numpy as np
import pandas as pd
import pytest

from grfguard.detect import Monitor
from grfguard.faults import inject_faults
from grfguard.kernels.detect import KIND_NAMES
from grfguard.model.robot import SENSOR_NAMES
from grfguard.sim import GaitConfig, NoiseConfig, simulate
from grfguard.sim.reality import load_reality

PAPER = ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5", "r4=offset:-100@5"]
#: gap -> tolerance on the forces [N]
GAPS = {"exact": 1e-9, "mass_plus5": 1e-9, "imu_pitch": 1e-5, "vibration": 1e-9,
        "all": 1e-5}


def _walk(gap: str, seed: int = 0) -> pd.DataFrame:
    return simulate(gait=GaitConfig(duration=8.0), noise=NoiseConfig(), seed=seed,
                    reality=None if gap == "exact" else load_reality(gap))


def _compare(out: pd.DataFrame, ref: pd.DataFrame, tol: float) -> None:
    assert set(ref.columns) <= set(out.columns)
    for c in ref.columns:
        a, b = out[c].to_numpy(), ref[c].to_numpy()
        if b.dtype.kind == "f" or a.dtype.kind == "f":
            a, b = a.astype(float), b.astype(float)
            np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=c)
            np.testing.assert_allclose(a, b, rtol=0.0, atol=tol, equal_nan=True, err_msg=c)
        else:
            np.testing.assert_array_equal(a, b, err_msg=c)


@pytest.mark.parametrize(("gap", "faults"), [("exact", False), *((g, True) for g in GAPS)])
def test_compiled_system_layer_equals_python(gap: str, faults: bool) -> None:
    log = _walk(gap)
    if faults:
        log = inject_faults(log, PAPER, seed=0)
    mon = Monitor.for_log(log)  # the default monitor: the layer on, compiled
    assert mon.common is not None and mon.compiled_reason() == ""
    out = mon.run(log)
    ref = Monitor.for_log(log, common_mode=True, compiled=False).run(log)
    _compare(out, ref, GAPS[gap])
    mm = out["model_mismatch"].to_numpy(bool)
    if gap == "exact":
        assert not mm.any()
    else:  # every gap here is large enough to be blamed on the model
        assert mm[-1] and out["model_mismatch_reason"].iloc[-1]
    flagged = {s for s in SENSOR_NAMES if out[f"flag_{s}"].any()}
    if faults:
        assert flagged >= {"r1", "r2", "r3", "r4"}
    elif gap != "imu_pitch":  # (this 8 s walk's start flags two sensors in both paths)
        assert not flagged


def test_streaming_equals_batch_and_pickle_continues() -> None:
    log = inject_faults(_walk("all", seed=2), PAPER, seed=0)
    mon = Monitor.for_log(log, common_mode=True)
    out = mon.run(log)
    n = 4000
    X = np.column_stack([log[c].to_numpy(float) if c in log else np.full(len(log), np.nan)
                         for c in mon.input_columns])[:n]
    cols = mon.output_columns
    mon.reset()
    Y = np.array([mon.update_array(np.ascontiguousarray(x)) for x in X[:n // 2]])
    twin = pickle.loads(pickle.dumps(mon))  # mid-stream
    Y2 = np.array([twin.update_array(np.ascontiguousarray(x)) for x in X[n // 2:]])
    Y = np.vstack([Y, Y2])
    for j, c in enumerate(cols):
        if c.startswith("mm_"):
            continue
        b = out[c].to_numpy()[:n]
        if c.startswith("kind_"):
            np.testing.assert_array_equal(np.array(KIND_NAMES, object)[Y[:, j].astype(int)],
                                          b, err_msg=c)
        elif c != "system_state":
            np.testing.assert_array_equal(Y[:, j], b.astype(float), err_msg=c)
    # the dict call: the same values and the reason text
    mon.reset()
    rows = log.iloc[:n].to_dict("records")
    batch = out.iloc[:n]
    for k, r in enumerate(rows):
        o = mon.update(r)
        if k % 7:
            continue
        assert o["model_mismatch"] == batch["model_mismatch"].iloc[k]
        assert o["model_mismatch_reason"] == batch["model_mismatch_reason"].iloc[k]
        for s in SENSOR_NAMES:
            assert o[f"flag_{s}"] == batch[f"flag_{s}"].iloc[k]
            a, b = o[f"recovered_{s}"], batch[f"recovered_{s}"].iloc[k]
            assert a == b or (math.isnan(a) and math.isnan(b))
    assert out["model_mismatch"].iloc[n - 1]


def test_vibration_latching_while_the_estimator_inputs_are_missing() -> None:
    """The twin sensor takes the main sensor's kinematics and rates and computes its
    outputs only once the vibration switch is on (``kernels/vfs.py``
    ``vfs_step_shared``). When the switch latches while the joint angles are missing, the
    twin repeats its last output, computed then: every output is the same bits as with the
    twin computing everything itself on every sample (``Y_SHARE`` off), on this walk and
    on the walk with a time gap and missing accelerometer samples as well."""
    from grfguard.kernels.system import Y_SHARE

    log = inject_faults(_walk("vibration"), PAPER, seed=0)
    mon = Monitor.for_log(log)
    first = mon.run(log)
    on = first["model_mismatch_reason"].astype(str).str.contains("vibration").to_numpy()
    assert on.any()
    i = int(np.flatnonzero(on)[0])
    gap = log.copy()
    joints = [c for c in log.columns if c.startswith("q_")]
    gap.loc[gap.index[i - 30:i + 30], joints] = np.nan
    brk = log.copy()
    brk.loc[brk.index[i - 500:i - 400], [c for c in log.columns if c.startswith("imu_acc")]] = (
        np.nan)
    t = brk["time"].to_numpy().copy()
    t[i + 1000:] += 0.05
    brk["time"] = t
    for lg in (gap, brk):
        mon = Monitor.for_log(lg)
        k = mon._kernel(True, True)
        assert k.sysp[Y_SHARE] == 1.0
        out = mon.run(lg)
        if lg is gap:  # latched inside the gap: the switch does not read the joints
            on2 = out["model_mismatch_reason"].astype(str).str.contains("vibration")
            assert int(np.flatnonzero(on2.to_numpy())[0]) == i
            assert out["vfs_valid"].iloc[i] == 0.0
        k.sysp[Y_SHARE] = 0.0
        ref = mon.run(lg)
        assert list(out.columns) == list(ref.columns)
        for c in out.columns:
            a, b = out[c].to_numpy(), ref[c].to_numpy()
            if a.dtype.kind == "f":
                np.testing.assert_array_equal(a.view(np.int64), b.view(np.int64), err_msg=c)
            else:
                np.testing.assert_array_equal(a, b, err_msg=c)


def test_sort8_and_the_fit_median_match_numpy() -> None:
    """The branch-free sorting network sorts every 0/1 input (so every input, by the 0-1
    principle) and random values with ties; the common-mode fit's outlier median over
    the used residuals is ``np.median`` of them, for every use mask."""
    import itertools

    from grfguard.kernels.standing import sort8
    from grfguard.kernels.system import _median

    for bits in itertools.product((0.0, 1.0), repeat=8):
        a = np.array(bits)
        sort8(a)
        assert np.array_equal(a, np.sort(bits)), bits
    rng = np.random.default_rng(3)
    for _ in range(200):
        v = rng.choice([0.0, 0.5, 2.0, 1e-300, 7.25, math.inf], size=8) * rng.integers(1, 4, 8)
        a = v.copy()
        sort8(a)
        assert np.array_equal(a, np.sort(v))
    e = rng.exponential(size=8)
    tmp = np.empty(14)
    for mask in range(1, 256):
        use = np.array([(mask >> i) & 1 for i in range(8)], dtype=float)
        assert _median(e, use, tmp) == np.median(e[use != 0.0]), mask
