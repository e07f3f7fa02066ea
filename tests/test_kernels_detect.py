"""The compiled detector, recovery and whole monitor equal the pure-Python stages.

These tests fail when the Python detector (``grfguard/detect/{detector,gating,
residual_tests,classify,sensor_state,tuning}.py``) or recovery (``grfguard/recover/``)
changes without the compiled mirror (``grfguard/kernels/detect.py``,
``grfguard/kernels/monitor.py``) following: flags, kinds, onsets and the sensor states
must be identical, the floats equal to 1e-9 N.
"""

from __future__ import annotations

import dataclasses
import math
import pickle

import numpy as np
import pandas as pd
import pytest

from grfguard.detect import Monitor, MonitorConfig
from grfguard.detect.detector import Detector, DetectorInputs
from grfguard.estimate.vfs import VirtualForceSensor, with_vfs_columns
from grfguard.faults import inject_faults
from grfguard.kernels.detect import KIND_NAMES, DetectKernel, detect_params
from grfguard.model.robot import SENSOR_NAMES, SURALP
from grfguard.recover.recovery import Recovery
from grfguard.sim import GaitConfig, NoiseConfig, simulate

#: The paper scenario and the nine fault kinds (two per log, one per foot).
SCENARIOS = {
    "paper": ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5", "r4=offset:-100@5"],
    "stuck+gain": ["r2=stuck@5.3", "l2=gain:1.6@5"],
    "noise+spikes": ["r3=noise:25@5", "l2=spikes:120@5"],
    "dropout+saturation": ["r4=dropout@5-6.5", "l2=saturation:200@5"],
    "offset20+drift": ["r1=offset:20@5", "l3=drift:15@5.5"],
    "frozen+offset": ["l1=frozen:0@5.2", "l4=offset:-100@5"],
    "fault-free": [],
    "quantised 0.5 N": ["l1=frozen:0@5.2"],
}


def sensor_states(ss: np.ndarray) -> list:
    """The per-sensor state ``ss`` as :class:`~grfguard.detect.sensor_state.SensorState`
    objects (what ``Detector.sensors`` would hold), to compare the compiled state with
    the Python one."""
    from grfguard.detect.sensor_state import SensorState
    from grfguard.kernels import detect as K

    out = []
    for row in ss:
        s = SensorState()
        s.last_reading_n = float(row[K.LAST])
        s.repeats = int(row[K.REP])
        s.pairs, s.chance_repeats = int(row[K.PAIRS]), int(row[K.CHANCE])
        s.run_pairs, s.run_repeats = int(row[K.RUNP]), int(row[K.RUNR])
        s.swing_pos, s.swing_neg = float(row[K.SWP]), float(row[K.SWN])
        s.corner_pos, s.corner_neg = float(row[K.CP]), float(row[K.CN])
        s.flag = bool(row[K.FLAG])
        s.source = K.SOURCE_NAMES[int(row[K.SRC])]
        s.kind = K.KIND_NAMES[int(row[K.KIND])]
        s.flag_time_s, s.last_alarm_s = float(row[K.FT]), float(row[K.LA])
        s.quiet_valid = int(row[K.QV])
        s.eta_n, s.gain, s.const_value_n = float(row[K.ETA]), float(row[K.GAIN]), float(row[K.CV])
        s.varied, s.const_returns = bool(row[K.VAR]), int(row[K.CR])
        w = s.swing
        w.n, w.outliers = int(row[K.FN]), int(row[K.FOUT])
        w.sum_t, w.sum_x, w.sum_tt = float(row[K.FST]), float(row[K.FSX]), float(row[K.FSTT])
        w.sum_tx, w.sum_xx = float(row[K.FSTX]), float(row[K.FSXX])
        st = s.stance
        st.n = int(row[K.SN])
        st.sum_load, st.sum_res = float(row[K.SL]), float(row[K.SR])
        st.sum_load2 = float(row[K.SLL])
        st.sum_load_res, st.sum_res2 = float(row[K.SLR]), float(row[K.SRR])
        st.eta_n = float(row[K.SETA])
        out.append(s)
    return out


@pytest.fixture(scope="module")
def walk() -> pd.DataFrame:
    """8 s SURALP walk with the default VFS columns."""
    return with_vfs_columns(simulate(SURALP, GaitConfig(duration=8.0), NoiseConfig(), seed=7))


def _python_stages(log: pd.DataFrame, cfg: MonitorConfig):
    inp = DetectorInputs.from_frames(log, log)
    det, rec = Detector(cfg), Recovery(cfg)
    n = len(log)
    flag = np.zeros((n, 8), bool)
    kind = np.empty((n, 8), object)
    eta = np.zeros((n, 8))
    out = np.zeros((n, 8))
    for k in range(n):
        t, x, v, tot, cref, cest = inp.sample(k)
        d = det.step(t, x, v, tot, cref, cest)
        o = rec.step(det.sensors, x, v, tot, d.columns)
        for i, s in enumerate(SENSOR_NAMES):
            flag[k, i] = o[f"flag_{s}"]
            kind[k, i] = o[f"kind_{s}"]
            eta[k, i] = o[f"eta_{s}"]
            out[k, i] = o[f"recovered_{s}"]
    return inp, det, flag, kind, eta, out


def _assert_close(a: np.ndarray, b: np.ndarray, tol: float = 1e-9) -> None:
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    np.testing.assert_allclose(a, b, rtol=0.0, atol=tol, equal_nan=True)


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_compiled_detector_equals_python(walk: pd.DataFrame, name: str) -> None:
    log = inject_faults(walk, SCENARIOS[name], seed=1) if SCENARIOS[name] else walk
    if name.startswith("quantised"):  # chance repeats of a coarse load cell
        log = log.copy()
        for s in SENSOR_NAMES:
            log[f"force_{s}"] = np.round(log[f"force_{s}"] / 0.5) * 0.5
    cfg = MonitorConfig()
    inp, det, flag, kind, eta, rec = _python_stages(log, cfg)
    k = DetectKernel(detect_params(cfg, det.tuning))
    n = len(log)
    arr = [np.array(c, float).T for c in (inp.x, inp.v, inp.tot, inp.cref, inp.cest)]
    f2, k2, e2, r2 = k.run(np.array(inp.t), *arr, np.zeros(n, bool))
    np.testing.assert_array_equal(f2, flag)  # flags and onsets
    np.testing.assert_array_equal(np.array(KIND_NAMES, object)[k2], kind)
    _assert_close(e2, eta)
    _assert_close(r2, rec)
    for a, b in zip(sensor_states(k.ss), det.sensors, strict=True):  # final states
        for slot in type(b).__slots__:
            va, vb = getattr(a, slot), getattr(b, slot)
            if slot in ("swing", "stance"):
                for sub in type(vb).__slots__:
                    x, y = getattr(va, sub), getattr(vb, sub)
                    assert x == y or (math.isnan(x) and math.isnan(y)), (slot, sub)
            else:
                assert va == vb or (math.isnan(va) and math.isnan(vb)), slot
    if name == "paper":
        assert {SENSOR_NAMES[i] for i in np.flatnonzero(flag.any(axis=0))} >= {
            "r1", "r2", "r3", "r4"}
    if name == "fault-free":
        assert not flag.any()


def _bad_raw(walk: pd.DataFrame) -> pd.DataFrame:
    """A raw log (no VFS columns) with every guard at work: NaN IMU, an inf and an
    absurd force, constant and backward stamps, a gap, a bad quaternion."""
    log = inject_faults(walk, SCENARIOS["paper"], seed=1)
    raw = log.drop(columns=[c for c in log.columns if c.startswith(
        ("vfs_", "com_est_", "contact_est_", "zmp_est"))]).copy()
    ix = raw.index
    raw.loc[ix[2000:2010], "imu_acc_z"] = np.nan
    raw.loc[ix[2500], "force_l3"] = 1e30
    raw.loc[ix[2600], "force_l1"] = -np.inf
    raw.loc[ix[3000], "time"] = raw["time"].iloc[2999]
    raw.loc[ix[3100], "time"] = raw["time"].iloc[3099] - 0.01
    raw.loc[ix[3200], "time"] = np.nan
    raw.loc[ix[3300], "imu_quat_x"] = 0.9
    raw.loc[ix[3400], "imu_gyro_y"] = 1e6
    return raw.drop(index=ix[5000:5100])


@pytest.mark.parametrize(("vfs_inside", "standing"), [(True, True), (False, True),
                                                      (True, False)])
def test_compiled_monitor_equals_python_monitor(walk: pd.DataFrame, vfs_inside: bool,
                                                standing: bool) -> None:
    raw = _bad_raw(walk)
    log = raw if vfs_inside else with_vfs_columns(raw)
    mon = Monitor.for_log(log, standing=standing)
    ref_mon = Monitor.for_log(log, compiled=False, standing=standing)
    assert mon.compiled_reason() == ""
    assert ref_mon.compiled_reason() != ""
    out = mon.run(log)
    ref = ref_mon.run(log)
    assert list(out.columns) == list(ref.columns)
    for c in ref.columns:
        a, b = out[c].to_numpy(), ref[c].to_numpy()
        if a.dtype.kind == "f":
            _assert_close(a, b.astype(float))
        else:
            np.testing.assert_array_equal(a, b, err_msg=c)
    states = set(out["system_state"])
    assert {"ok", "time_gap", "time_constant", "time_backwards", "time_missing",
            "settling"} <= states
    assert (out.loc[raw.index[2500], "kind_l3"] == "spikes") or not out.loc[
        raw.index[2500], "flag_l3"]
    # streaming through the compiled step equals the batch, dict and array calls alike
    mon.reset()
    rows = log.iloc[:3500].to_dict("records")
    cols = mon.output_columns
    X = np.column_stack([log[c].to_numpy(float) if c in log else np.full(len(log), np.nan)
                         for c in mon.input_columns])[:3500]
    twin = pickle.loads(pickle.dumps(mon))
    batch = out.iloc[:3500].to_dict("records")
    mon.reset()
    twin.reset()
    for k, r in enumerate(rows):
        o = mon.update(r)
        y = twin.update_array(np.ascontiguousarray(X[k]))
        b = batch[k]
        assert list(o) == [c for c in out.columns if c in o]  # the batch's column order
        for j, c in enumerate(cols):
            if c.startswith("mm_"):  # the numbers of model_mismatch_reason (array call)
                continue
            if c.startswith("kind_"):
                assert KIND_NAMES[int(y[j])] == o[c] == b[c]
            elif c == "system_state":
                assert o[c] == b[c]
            else:
                want = float(b[c])
                assert (y[j] == float(o[c]) == want) or (math.isnan(y[j]) and math.isnan(
                    want) and math.isnan(float(o[c]))), (k, c)
        assert o["system_reason"] == b["system_reason"], k


def test_for_log_builds_the_streaming_step_before_the_first_sample(walk: pd.DataFrame
                                                                      ) -> None:
    """``Monitor.for_log`` builds the compiled streaming step and finds its machine code
    before any sample (built at the first call, it took that sample 3-7 ms);
    ``warm=False`` leaves both to the first call. The state is untouched: both monitors
    give the same bits."""
    raw = walk.drop(columns=[c for c in walk.columns if c.startswith(
        ("vfs_", "com_est_", "contact_est_", "zmp_est"))]).iloc[:200]
    mon = Monitor.for_log(raw)
    k = mon._row_kernel
    assert k is not None and k._entry is not None
    lazy = Monitor.for_log(raw, warm=False)
    assert lazy._row_kernel is None
    X = np.column_stack([raw[c].to_numpy(float) if c in raw else np.full(len(raw), np.nan)
                         for c in mon.input_columns])
    got = np.array([mon.update_array(np.ascontiguousarray(x)) for x in X])
    want = np.array([lazy.update_array(np.ascontiguousarray(x)) for x in X])
    assert mon._row_kernel is k and lazy._row_kernel is not None
    np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))
    # the monitor of a log with its virtual sensor's columns precomputed too
    pre = Monitor.for_log(walk.iloc[:50])
    assert pre.vfs is None and pre._row_kernel is not None
    assert pre._row_kernel._entry is not None


def test_prepare_builds_the_streaming_step_of_a_monitor_built_directly(walk: pd.DataFrame
                                                                       ) -> None:
    """A monitor built directly (``Monitor(config, vfs)``) builds its streaming step at
    its first sample unless :meth:`Monitor.prepare` built it before; prepared or not,
    the same bits."""
    raw = walk.drop(columns=[c for c in walk.columns if c.startswith(
        ("vfs_", "com_est_", "contact_est_", "zmp_est"))]).iloc[:200]
    mons = [Monitor(MonitorConfig(), VirtualForceSensor(SURALP), robot=SURALP)
            for _ in range(2)]
    assert mons[0].prepare() is mons[0]
    k = mons[0]._row_kernel
    assert k is not None and k._entry is not None
    assert mons[1]._row_kernel is None
    X = np.column_stack([raw[c].to_numpy(float) if c in raw else np.full(len(raw), np.nan)
                         for c in mons[0].input_columns])
    got, want = (np.array([m.update_array(np.ascontiguousarray(x)) for x in X])
                 for m in mons)
    assert mons[0]._row_kernel is k
    np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))


def test_for_log_loads_the_dict_call_module(tmp_path) -> None:
    """The first dict ``update`` of a warm monitor imports nothing (the import of the dict
    call's module took that sample about 7 ms): ``Monitor.for_log`` loads it. In a fresh
    interpreter, where nothing has imported it yet."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from grfguard.detect import Monitor\n"
        "from grfguard.model.robot import SURALP\n"
        "from grfguard.sim import GaitConfig, NoiseConfig, simulate\n"
        "log = simulate(SURALP, GaitConfig(duration=3.0), NoiseConfig(), seed=1)\n"
        "log = log.drop(columns=[c for c in log.columns if c.startswith(('vfs_', "
        "'com_est_', 'contact_est_', 'zmp_est'))])\n"
        "assert 'grfguard.compiled_monitor' not in sys.modules\n"
        "Monitor.for_log(log, warm=False)\n"
        "assert 'grfguard.compiled_monitor' not in sys.modules\n"
        "Monitor.for_log(log)\n"
        "assert 'grfguard.compiled_monitor' in sys.modules\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_update_array_follows_a_replaced_virtual_sensor(walk: pd.DataFrame) -> None:
    """``update_array`` keeps its compiled step after the first call (the 1 kHz path);
    a virtual sensor replaced on the monitor drops it: the rows then go through the new
    sensor's step, as the dict call's do."""
    raw = walk.drop(columns=[c for c in walk.columns if c.startswith(
        ("vfs_", "com_est_", "contact_est_", "zmp_est"))]).iloc[:200]
    mon = Monitor.for_log(raw)
    ref = Monitor.for_log(raw)
    assert mon.vfs is not None
    X = np.column_stack([raw[c].to_numpy(float) if c in raw else np.full(len(raw), np.nan)
                         for c in mon.input_columns])
    rows = raw.to_dict("records")
    cols = mon.output_columns
    j = cols.index("vfs_r1")
    old = np.array([mon.update_array(np.ascontiguousarray(x)) for x in X])
    slower = dataclasses.replace(mon.vfs.config, filter_cutoff=4.0)
    for m in (mon, ref):
        m.vfs = VirtualForceSensor(m.vfs.robot, slower)
        m.reset()
    y = np.empty(len(cols))
    new = np.empty((200, 8))
    for k in range(200):
        got = mon.update_array(np.ascontiguousarray(X[k]), y)
        assert got is y
        want = ref.update(rows[k])
        for i, c in enumerate(cols[j:j + 8]):
            assert got[j + i] == float(want[c]) or (math.isnan(got[j + i]) and math.isnan(
                float(want[c]))), (k, c)
        new[k] = got[j:j + 8]
    # the new sensor's forces on the same rows, not the old one's
    assert np.nanmax(np.abs(new - old[:, j:j + 8])) > 1.0
    # a monitor pickled before the direct path existed (no such attribute) still streams
    was = pickle.loads(pickle.dumps(Monitor.for_log(raw)))
    was.__dict__.pop("_row_kernel", None)
    again = np.array([was.update_array(np.ascontiguousarray(x)) for x in X])
    np.testing.assert_array_equal(again[:, j:j + 8], old[:, j:j + 8])


def test_compiled_dict_call_equals_python_on_odd_values(walk: pd.DataFrame) -> None:
    """The compiled dict call takes what the pure-Python stages take, row by row: None,
    numeric text, other text, booleans, lists and missing keys give the same outputs,
    ``system_reason`` included (the same keys in the same order)."""
    raw = walk.drop(columns=[c for c in walk.columns if c.startswith(
        ("vfs_", "com_est_", "contact_est_", "zmp_est"))]).iloc[:300]
    mon = Monitor.for_log(raw)
    ref = Monitor.for_log(raw, compiled=False)
    assert mon.compiled_reason() == "" and ref.compiled_reason() != ""
    rows = raw.to_dict("records")
    odd = {40: ("force_r2", None), 60: ("imu_gyro_x", None), 80: ("force_l1", "12.5"),
           100: ("q_r_knee", "bent"), 120: ("contact_ref_r", True), 140: ("imu_acc_y", [1.0]),
           160: ("force_r4", float("inf")), 180: ("time", None), 200: ("imu_quat_w", "1")}
    for k, (c, v) in odd.items():
        assert c in rows[k]
        rows[k][c] = v
    for k in (220, 240):
        del rows[k]["force_l3"]
        del rows[k]["imu_gyro_z"]
    reasons = 0
    for k, r in enumerate(rows):
        o, w = mon.update(r), ref.update(r)
        assert list(o) == list(w), k
        for c, want in w.items():
            got = o[c]
            if isinstance(want, float):
                assert abs(got - want) <= 1e-9 or (math.isnan(got) and math.isnan(want)), (k, c)
            else:
                assert got == want, (k, c)
        reasons += w["system_reason"] != ""
    assert reasons >= len(odd)  # the odd rows were reported


def test_uncompiled_features_fall_back(walk: pd.DataFrame) -> None:
    """The paper method and diagnostics run the Python stages (the common-mode layer is
    compiled: tests/test_kernels_system.py); ``update_array`` still works through them."""
    assert not Monitor.for_log(walk, common_mode=True).compiled_reason()
    for mon in (Monitor.for_log(walk, MonitorConfig(method="paper")),
                Monitor.for_log(walk, MonitorConfig(diagnostics=True))):
        assert mon.compiled_reason()
        y = mon.update_array(np.full(len(mon.input_columns), np.nan))
        assert y.shape == (len(mon.output_columns),)
        j = mon.output_columns.index("recovered_r1")
        assert np.isfinite(y[j:j + 8]).all()  # recovered forces never NaN


@pytest.fixture(scope="module")
def stand() -> pd.DataFrame:
    """3 s of standing, then walking (8 s, VFS columns)."""
    return with_vfs_columns(simulate(SURALP, GaitConfig(duration=8.0, start_time=3.0),
                                     NoiseConfig(), seed=3))


@pytest.mark.parametrize("faults", [["r2=offset:40@1.6", "l3=drift:40@1.4"],
                                    ["r2=gain:1.3@1.6"]])
def test_compiled_standing_layer_equals_python(stand: pd.DataFrame, faults: list) -> None:
    """Faults that start during a stand (the standing layer flags them, holds them after
    the stand, weighs offset against gain) give the same outputs compiled and in Python."""
    log = inject_faults(stand, faults, seed=2)
    out = Monitor.for_log(log).run(log)
    ref = Monitor.for_log(log, compiled=False).run(log)
    for c in ref.columns:
        a, b = out[c].to_numpy(), ref[c].to_numpy()
        if a.dtype.kind == "f":
            _assert_close(a, b.astype(float))
        else:
            np.testing.assert_array_equal(a, b, err_msg=c)
    early = out["time"] < 3.0
    assert out.loc[early, "flag_r2"].any()  # flagged while standing


def _fsum_cases() -> list[np.ndarray]:
    """Vectors of 1-8 floats that exercise both paths of the compiled ``_fsum``: forces
    of one magnitude (the fast path), magnitudes 1e-20..1e20 and binary fractions near
    ties (its fallback), rounded values next to 2^53, zeros and tiny negatives."""
    rng = np.random.default_rng(11)
    out = []
    for trial in range(30):
        n = 1 + trial % 8
        kind = trial % 5
        if kind == 0:
            v = rng.normal(0, 300, (4000, n))
        elif kind == 1:
            v = rng.normal(0, 1, (4000, n)) * 10.0 ** rng.integers(-20, 20, (4000, n))
        elif kind == 2:
            v = (rng.integers(-2**20, 2**20, (4000, n)).astype(float)
                 * 2.0 ** rng.integers(-60, 0, (4000, n)))
        elif kind == 3:
            v = np.round(rng.normal(0, 300, (4000, n)), 2)
            v[:, 0] = 2.0 ** 53 * rng.choice([-1.0, 1.0], 4000)
        else:
            v = rng.normal(0, 300, (4000, n))
            v[rng.random((4000, n)) < 0.3] = 0.0
            v[rng.random((4000, n)) < 0.1] *= -1e-17
        out.append(np.ascontiguousarray(v))
    # every sign pattern of four zeros (a foot in the air: its corners' virtual forces)
    out.append(np.array([[-0.0 if (m >> j) & 1 else 0.0 for j in range(4)]
                         for m in range(16)]))
    return out


def test_compiled_fsum_equals_math_fsum() -> None:
    """``kernels.detect._fsum`` (TwoSum fast path, Shewchuk fallback) returns the value
    of ``math.fsum`` and the very bits of the Shewchuk kernel ``_fsum_exact`` (sign of
    zero included: for all-negative-zero input both give -0.0, where Python 3.11's
    ``math.fsum`` gives 0.0) on 120 000 vectors and every sign pattern of four zeros."""
    from numba import njit

    from grfguard.kernels.detect import _fsum, _fsum_exact

    @njit
    def both(v, out):
        part = np.zeros(16)
        for r in range(v.shape[0]):
            out[r, 0] = _fsum(v[r], v.shape[1], part)
            out[r, 1] = _fsum_exact(v[r], v.shape[1], part)

    for v in _fsum_cases():
        got = np.empty((len(v), 2))
        both(v, got)
        ref = np.array([math.fsum(row) for row in v])
        assert np.array_equal(got[:, 0], ref)
        assert np.array_equal(got[:, 1], ref)
        assert np.array_equal(got[:, 0].view(np.int64), got[:, 1].view(np.int64))
