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
