"""Monitor contract: reset/stream/batch/pickle, bad samples, configs, both methods."""

from __future__ import annotations

import pickle

import numpy as np
import pandas as pd
import pytest

from grfguard.detect.monitor import METHODS, Monitor, MonitorConfig
from grfguard.detect.thresholds import Thresholds, default_thresholds
from grfguard.errors import ConfigError, LogFormatError
from grfguard.faults import inject_faults
from grfguard.model.robot import SENSOR_NAMES, SURALP

OUT_COLS = [f"{p}_{s}" for s in SENSOR_NAMES for p in ("flag", "kind", "eta", "recovered")]


@pytest.fixture(scope="module")
def short_log(default_walk: pd.DataFrame) -> pd.DataFrame:
    """First 12 s of the default walk with the VFS columns and a few faults."""
    from grfguard.estimate.vfs import VirtualForceSensor

    log = default_walk.iloc[:12000].copy()
    log.attrs = dict(default_walk.attrs)
    vfs = VirtualForceSensor.for_log(log).run(log)
    for c in vfs.columns:
        log[c] = vfs[c].to_numpy()
    return inject_faults(
        log, ["l2=offset:60@5.5", "l3=frozen@5", "r4=dropout@8-8.5", "r1=spikes:80@7"], seed=3
    )


@pytest.mark.parametrize("method", METHODS)
def test_batch_equals_streaming(short_log: pd.DataFrame, method: str) -> None:
    log = short_log.iloc[:9000]
    mon = Monitor.for_log(log, MonitorConfig(method=method))
    assert mon.vfs is None  # reuses the log's vfs_* columns
    batch = mon.run(log)
    mon.reset()
    rows = [mon.update(r) for r in log.to_dict("records")]
    stream = pd.DataFrame(rows)
    for c in OUT_COLS:
        a = batch[c].to_numpy()
        b = stream[c].to_numpy()
        if c.startswith(("eta", "recovered")):
            np.testing.assert_allclose(b.astype(float), a.astype(float), rtol=0, atol=1e-9,
                                       err_msg=c)
        else:
            assert np.array_equal(a.astype(str), b.astype(str)), c
    rec = batch[[f"recovered_{s}" for s in SENSOR_NAMES]].to_numpy(float)
    assert np.all(np.isfinite(rec))


def test_streaming_with_vfs_in_the_loop(short_log: pd.DataFrame) -> None:
    raw = short_log.drop(columns=[c for c in short_log.columns if c.startswith("vfs_")])
    raw = raw.iloc[:400]
    mon = Monitor.for_log(raw)
    assert mon.vfs is not None
    batch = mon.run(raw)
    assert "vfs_r1" in batch.columns and "flag_r1" in batch.columns
    mon.reset()
    rows = pd.DataFrame([mon.update(r) for r in raw.to_dict("records")])
    np.testing.assert_allclose(rows["vfs_r1"], batch["vfs_r1"], atol=1e-9)
    np.testing.assert_allclose(rows["recovered_l2"], batch["recovered_l2"], atol=1e-9)


def test_detects_and_classifies_the_injected_faults(short_log: pd.DataFrame) -> None:
    out = Monitor.for_log(short_log).run(short_log)
    t = out["time"].to_numpy()
    assert not out.loc[t < 5, [f"flag_{s}" for s in SENSOR_NAMES]].to_numpy().any()
    drop = (t >= 8.0) & (t < 8.5)
    assert out["flag_r4"].to_numpy()[drop].all()
    assert set(out["kind_r4"].to_numpy()[drop]) == {"dropout"}
    assert np.isfinite(out["recovered_r4"].to_numpy()[drop]).all()
    assert not out["flag_r4"].to_numpy()[t > 9.5].any()  # cleared after the dropout
    assert out["kind_l3"].iloc[-1] == "frozen"
    assert out["kind_l2"].iloc[-1] == "offset"
    assert abs(out["eta_l2"].iloc[-1] - 60) < 3
    assert out["kind_r1"].iloc[-1] == "spikes"
    for s in ("r2", "r3"):
        assert not out[f"flag_{s}"].any()


def test_update_never_raises_on_bad_samples(short_log: pd.DataFrame) -> None:
    mon = Monitor.for_log(short_log)
    row = short_log.iloc[100].to_dict()
    for bad in (
        {},
        {"time": "x"},
        {k: v for k, v in row.items() if k != "force_r2"},
        {**row, "force_l1": float("nan"), "time": float("nan")},
        {**row, "vfs_r1": None},
    ):
        out = mon.update(bad)
        assert all(np.isfinite(out[f"recovered_{s}"]) for s in SENSOR_NAMES)
    assert mon.update({**row, "force_l1": float("nan")})["kind_l1"] == "dropout"
    mon.reset()
    assert mon.update(row)["flag_l1"] is False


def test_pickle_and_reset(short_log: pd.DataFrame) -> None:
    mon = Monitor.for_log(short_log)
    rows = short_log.iloc[:3000].to_dict("records")
    for r in rows[:1500]:
        mon.update(r)
    clone = pickle.loads(pickle.dumps(mon))
    a = [mon.update(r) for r in rows[1500:]]
    b = [clone.update(r) for r in rows[1500:]]
    assert a == b


def test_config_round_trip_and_errors(tmp_path) -> None:
    cfg = MonitorConfig(method="paper", gate_touchdown_s=0.2)
    text = cfg.to_toml()
    back = MonitorConfig.from_toml_text(text)
    assert back.method == "paper" and back.gate_touchdown_s == 0.2
    assert back.thresholds == cfg.thresholds and back.observer == cfg.observer
    assert cfg.with_method("default").method == "default"
    p = tmp_path / "th.toml"
    th = Thresholds(swing_h=42.0, paper_eta_n=(5.0,) * 8)
    p.write_text(th.to_toml())
    assert Thresholds.from_toml(p) == th
    assert cfg.with_thresholds(p).thresholds.swing_h == 42.0
    with pytest.raises(ConfigError, match="method"):
        MonitorConfig(method="magic")
    with pytest.raises(ConfigError, match="gate_liftoff_s"):
        MonitorConfig(gate_liftoff_s=-1.0)
    with pytest.raises(ConfigError, match="unknown threshold keys"):
        Thresholds.from_toml_text("[thresholds]\nfoo = 1\n")
    with pytest.raises(ConfigError, match="paper_eta_n"):
        Thresholds(paper_eta_n=(1.0, 2.0))
    with pytest.raises(ConfigError, match="does not exist"):
        Thresholds.from_toml(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match="monitor"):
        MonitorConfig.from_toml_text("[monitor]\nbogus = 3\n")
    assert default_thresholds().source != "builtin"  # the shipped, calibrated file


def test_run_needs_forces() -> None:
    with pytest.raises(LogFormatError, match="force_r1"):
        Monitor(MonitorConfig(), None, robot=SURALP).run(pd.DataFrame({"time": [0.0, 0.001]}))


def test_calibrate_thresholds_from_fault_free_logs(short_log: pd.DataFrame) -> None:
    from grfguard.detect.monitor import calibrate_thresholds

    clean = short_log.iloc[:4900].drop(
        columns=[c for c in short_log.columns if c.startswith(("fault_", "fault_kind_"))]
    )
    th = calibrate_thresholds([clean], false_alarm_rate_per_hour=0.5)
    assert 1.5 < th.sigma_swing_n < 2.5  # the simulated sensor noise is 2 N
    assert th.swing_h >= 30.0 and th.total_h >= 30.0 and th.corner_h >= 30.0
    assert all(x > 0 for x in th.paper_eta_n)
    assert th.false_alarm_rate_per_hour == 0.5 and "1 fault-free log" in th.source
    assert Thresholds.from_toml_text(th.to_toml()) == th
    # the calibrated monitor raises no alarm on its own calibration data
    out = Monitor.for_log(clean, MonitorConfig(thresholds=th)).run(clean)
    assert not out[[f"flag_{s}" for s in SENSOR_NAMES]].to_numpy().any()
    with pytest.raises(ConfigError, match="fault-free"):
        calibrate_thresholds([short_log], 0.1)
    with pytest.raises(ConfigError, match="at least one"):
        calibrate_thresholds([], 0.1)
