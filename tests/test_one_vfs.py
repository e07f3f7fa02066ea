"""One virtual force sensor: ``VirtualForceSensor`` runs the compiled kernel itself, and on
the paper's scenario (the demo's SURALP walk, seed 0, the paper's four faults from 5 s;
here its first 15 s to keep the suite fast) its outputs and the monitor's equal the
Python stages (``tests/reference/vfs_stages.py``) to 1e-6 N; ``compiled=False`` is gone
from the sensor (the monitor keeps it for its pure-Python detector)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.demo import PAPER_FAULTS
from grfguard.detect import Monitor
from grfguard.errors import ConfigError
from grfguard.estimate.vfs import VFS_OUTPUT_COLUMNS, VFSConfig, VirtualForceSensor
from grfguard.faults import inject_faults, parse_fault_spec
from grfguard.kernels import CompiledVirtualForceSensor
from grfguard.model.robot import SURALP
from grfguard.sim import GaitConfig, NoiseConfig, simulate
from reference.vfs_stages import PythonVFS

#: Issue 11, must-show 3: optimised outputs equal the pure-Python ones to 1e-6 N.
TOL_N = 1e-6


@pytest.fixture(scope="module")
def paper_log() -> pd.DataFrame:
    walk = simulate(gait=GaitConfig(duration=15.0), noise=NoiseConfig(), seed=0)
    return inject_faults(walk, [parse_fault_spec(s) for s in PAPER_FAULTS], seed=0)


def _max_diff(a: pd.DataFrame, b: pd.DataFrame, cols: list[str]) -> float:
    x, y = a[cols].to_numpy(float), b[cols].to_numpy(float)
    np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
    return float(np.nanmax(np.abs(x - y)))


def test_one_class_two_engines() -> None:
    assert CompiledVirtualForceSensor is VirtualForceSensor
    assert VirtualForceSensor(SURALP).compiled
    with pytest.raises(ConfigError, match="tests/reference/vfs_stages.py"):
        VirtualForceSensor(compiled=False)
    # every setting runs compiled (kernels/vfs_paper.py: the paper's, the Kalman ZMP...)
    assert VirtualForceSensor(SURALP, VFSConfig.paper()).compiled
    assert VirtualForceSensor(SURALP, VFSConfig(zmp_filter="kalman")).compiled


def test_compiled_equals_python_stages_on_paper_scenario(paper_log) -> None:
    ref = PythonVFS.for_log(paper_log).run(paper_log)
    out = VirtualForceSensor.for_log(paper_log).run(paper_log)
    forces = [c for c in VFS_OUTPUT_COLUMNS if c.startswith(("vfs_r", "vfs_l", "vfs_total"))]
    assert _max_diff(ref, out, forces) <= TOL_N  # measured 0.0: one corner-QP solver
    assert _max_diff(ref, out, list(VFS_OUTPUT_COLUMNS)) <= TOL_N
    # the walk loads every corner, in single and double support
    assert (ref[forces[:8]].to_numpy() > 50.0).any(axis=0).all()
    assert (ref["contact_est_r"] * ref["contact_est_l"]).sum() > 300


def test_monitor_flags_identical_on_paper_scenario(paper_log) -> None:
    ref = Monitor.for_log(paper_log, compiled=False).run(paper_log)
    out = Monitor.for_log(paper_log).run(paper_log)
    flags = [c for c in ref.columns if c.startswith(("flag_", "kind_"))]
    pd.testing.assert_frame_equal(out[flags], ref[flags])
    assert ref[["flag_r1", "flag_r2", "flag_r3", "flag_r4"]].any().all()
    num = [c for c in ref.columns if c.startswith(("vfs_", "recovered_"))]
    assert _max_diff(ref, out, num) <= TOL_N
