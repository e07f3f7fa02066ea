"""The monitor on the compiled virtual force sensor gives the pure-Python monitor's flags."""

from __future__ import annotations

import numpy as np
import pandas as pd

from grfguard.detect import Monitor
from grfguard.faults import inject_faults
from grfguard.kernels import CompiledVirtualForceSensor
from grfguard.model.robot import SURALP
from grfguard.sim import GaitConfig, NoiseConfig, simulate


def test_monitor_run_and_update_match_python_monitor():
    walk = simulate(SURALP, GaitConfig(duration=8.0), NoiseConfig(), seed=5)
    log = inject_faults(walk, "r2=offset:150@5")
    ref = Monitor.for_log(log, compiled=False).run(log)
    mon = Monitor.for_log(log)  # the compiled sensor and monitor, kernels warmed up
    assert isinstance(mon.vfs, CompiledVirtualForceSensor)
    out = mon.run(log)
    assert list(out.columns) == list(ref.columns)
    flags = [c for c in ref.columns if c.startswith(("flag_", "kind_"))]
    assert flags
    pd.testing.assert_frame_equal(out[flags], ref[flags])
    assert ref["flag_r2"].any()  # the injected fault is found by both
    num = [c for c in ref.columns if c.startswith(("vfs_", "recovered_", "eta_"))]
    a = ref[num].to_numpy(float)
    b = out[num].to_numpy(float)
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    assert np.nanmax(np.abs(a - b)) <= 1e-9
    # streaming through the same monitor: the batch outputs row by row
    mon.reset()
    rows = log.iloc[:400].to_dict("records")
    for k, r in enumerate(rows):
        o = mon.update(r)
        for c in ("vfs_r1", "vfs_l4", "flag_r2"):
            assert o[c] == out[c].iloc[k] or abs(o[c] - out[c].iloc[k]) <= 1e-12, (k, c)


def test_batch_loop_writes_any_memory_order_in_place():
    """``monitor_run_packed`` reads the input and writes the outputs in any memory order
    (row-major, column-major, a strided chunk of a larger array, read-only input) with
    the same bits as row-by-row ``MonitorKernel.step``, with a time gap and missing
    joints inside."""
    from grfguard.kernels.monitor import N_EX, monitor_run_packed

    walk = simulate(SURALP, GaitConfig(duration=3.0), NoiseConfig(), seed=7)
    log = inject_faults(walk, "r2=offset:150@1")
    log.loc[1200:1219, "q_r_knee"] = np.nan
    log.loc[2000:, "time"] += 0.05
    mon = Monitor.for_log(log)
    k = mon._kernel(True, True)
    n = len(log) - 5
    X = np.ascontiguousarray(np.column_stack([
        log[c].to_numpy(float) if c in log else np.full(len(log), np.nan) for c in k.in_cols
    ]))[:n]
    k.reset()
    ref = np.array([k.step(X[i].copy(), np.empty(len(k.out_cols))).copy() for i in range(n)])
    m = len(k.out_cols)
    ro = X.copy()
    ro.flags.writeable = False
    big = np.full((m + 3, n + 9), -7.0)
    for Xin, Y in ((X, np.empty((n, m))), (np.asfortranarray(X), np.empty((n, m), order="F")),
                   (ro, big[1:m + 1, 4:n + 4].T)):
        EX = np.empty((n, N_EX))
        k.reset()
        monitor_run_packed(Xin, Y, EX, k.F, k.I)
        assert np.array_equal(Y.view(np.int64), ref.view(np.int64))
    assert (big[0] == -7.0).all() and (big[m + 1:] == -7.0).all()  # nothing written outside
    assert (big[:, :4] == -7.0).all() and (big[:, n + 4:] == -7.0).all()
    assert (ref[:, k.out_cols.index("system_state")] != 0).any()  # the gap and NaNs seen


def test_two_pass_batch_loop_equals_steps_when_the_vibration_switch_latches():
    """The batch loop runs the sensor side of ``PASS_ROWS`` rows before their detector
    sides. On a walk whose accelerometer vibrates (the reality gap ``all``), the switch
    latches inside a pass (the twin's outputs replace the sensor's, the corner threshold
    widens, the fits settle): every output, the system layer's numbers included, has the
    bits of row-by-row ``MonitorKernel.step``, across missing joints and a time gap."""
    from grfguard.kernels.monitor import N_EX, PASS_ROWS, monitor_run_packed
    from grfguard.sim.reality import load_reality

    walk = simulate(SURALP, GaitConfig(duration=3.0), NoiseConfig(), seed=3,
                    reality=load_reality("all"))
    log = inject_faults(walk, "r1=frozen:0@1")
    log.loc[700:704, "q_l_knee"] = np.nan
    log.loc[1500:, "time"] += 0.2
    mon = Monitor.for_log(log)
    k = mon._kernel(True, True)
    X = np.ascontiguousarray(np.column_stack([
        log[c].to_numpy(float) if c in log else np.full(len(log), np.nan) for c in k.in_cols
    ]))
    k.reset()
    ref = np.array([k.step(x.copy(), np.empty(len(k.out_cols))).copy() for x in X])
    k.reset()
    Y, EX = np.empty_like(ref), np.empty((len(X), N_EX))
    monitor_run_packed(X, Y, EX, k.F, k.I)
    assert np.array_equal(Y.view(np.int64), ref.view(np.int64))
    on = np.flatnonzero(ref[:, k.out_cols.index("mm_vibration")] != 0.0)
    assert on.size and on[0] % PASS_ROWS not in (0, PASS_ROWS - 1)  # inside a pass
    assert (ref[:, k.out_cols.index("flag_r1")] != 0.0).any()
