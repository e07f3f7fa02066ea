"""``Monitor.for_log`` runs the compiled virtual force sensor by default; across breaks
(a time gap, samples without IMU) it resyncs like the pure-Python sensor, in streaming
and in batch."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from grfguard.cli import app
from grfguard.detect import Monitor, MonitorConfig
from grfguard.estimate.config import VFSConfig
from grfguard.estimate.vfs import VirtualForceSensor
from grfguard.faults import inject_faults
from grfguard.io.logio import load_log, write_log
from grfguard.kernels import CompiledVirtualForceSensor
from grfguard.model.robot import SURALP
from grfguard.sim import GaitConfig, NoiseConfig, simulate
from reference.vfs_stages import PythonVFS


@pytest.fixture(scope="module")
def broken_log() -> pd.DataFrame:
    """8 s faulty walk with a 50 ms time gap at 3 s and 100 ms without IMU at 5 s."""
    walk = simulate(SURALP, GaitConfig(duration=8.0), NoiseConfig(), seed=7)
    log = inject_faults(walk, "l3=offset:120@4")
    t = log["time"].to_numpy()
    log = log.loc[~((t >= 3.0) & (t < 3.05))].reset_index(drop=True)
    t = log["time"].to_numpy()
    imu = [c for c in log.columns if c.startswith("imu_")]
    log.loc[(t >= 5.0) & (t < 5.1), imu] = np.nan
    log.attrs = dict(walk.attrs)
    return log


def _compare(ref: pd.DataFrame, out: pd.DataFrame) -> None:
    flags = [c for c in ref.columns if c.startswith(("flag_", "kind_", "system_state"))]
    pd.testing.assert_frame_equal(out[flags], ref[flags])
    num = [c for c in ref.columns if c.startswith(("vfs_", "recovered_", "eta_", "com_est"))]
    a, b = ref[num].to_numpy(float), out[num].to_numpy(float)
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    assert np.nanmax(np.abs(a - b)) <= 1e-9


def _python_monitor(log: pd.DataFrame, monkeypatch) -> Monitor:
    """The pure-Python reference: Python detector around the numpy VFS stages."""
    import grfguard.estimate.vfs as vfs_mod

    with monkeypatch.context() as m:
        m.setattr(vfs_mod, "VirtualForceSensor", PythonVFS)
        mon = Monitor.for_log(log, compiled=False)
    assert type(mon.vfs) is PythonVFS
    return mon


def test_for_log_default_is_compiled_and_opt_out_is_python(broken_log) -> None:
    assert isinstance(Monitor.for_log(broken_log).vfs, CompiledVirtualForceSensor)
    assert Monitor.for_log(broken_log).vfs.compiled
    for mon in (Monitor.for_log(broken_log, compiled=False),
                Monitor.for_log(broken_log, MonitorConfig(compiled=False))):
        # the Python detector around the (always compiled) virtual sensor
        assert type(mon.vfs) is VirtualForceSensor and mon.vfs.compiled
        assert mon.compiled_reason() == "compiled=False"
    # the paper's sensor runs compiled; the monitor around it (which does not pass the
    # force sensors to the sensor's step) runs the Python stages
    paper = Monitor.for_log(broken_log, MonitorConfig(vfs=VFSConfig.paper()))
    assert type(paper.vfs) is VirtualForceSensor and paper.vfs.compiled
    assert "paper" in paper.compiled_reason()
    assert MonitorConfig.from_toml_text(MonitorConfig(compiled=False).to_toml()).compiled is False


def test_compiled_default_equals_python_across_breaks(broken_log, monkeypatch) -> None:
    ref = _python_monitor(broken_log, monkeypatch).run(broken_log)
    states = set(ref["system_state"])
    assert {"time_gap", "input_invalid", "settling"} <= states
    assert ref["flag_l3"].any() and not ref[["flag_r1", "flag_r2", "flag_l1"]].any().any()
    mon = Monitor.for_log(broken_log)
    out = mon.run(broken_log)
    _compare(ref, out)
    # streaming (resync at each break) equals the batch run
    mon.reset()
    rows = [mon.update(r) for r in broken_log.to_dict("records")]
    stream = pd.DataFrame(rows, index=broken_log.index)
    stream["time"] = broken_log["time"].to_numpy()
    _compare(out, stream)


def test_cli_no_compiled_gives_the_same_output(broken_log, tmp_path) -> None:
    src = tmp_path / "in.parquet"
    write_log(broken_log.iloc[:3000], src)
    runner = CliRunner()
    outs = []
    for extra in ([], ["--no-compiled"]):
        dst = tmp_path / f"out{len(extra)}.parquet"
        res = runner.invoke(app, ["run", str(src), "-o", str(dst), *extra])
        assert res.exit_code == 0, res.output
        outs.append(load_log(dst))
    _compare(outs[1], outs[0])
