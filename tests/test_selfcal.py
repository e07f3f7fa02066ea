"""Model self-calibration (issue 10) on simulated walks of a robot that differs from its
model: corrections against the recorded truth, and no false alarm once applied."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.calib import ModelCorrections, apply_corrections, estimate_corrections
from grfguard.detect import Monitor
from grfguard.errors import LogFormatError
from grfguard.model.robot import SENSOR_NAMES, SURALP
from grfguard.sim import GaitConfig, simulate
from grfguard.sim.reality import RealityGap

GAP = RealityGap(
    mass_error=0.05,
    trunk_com_offset_m=(0.03, -0.03, 0.0),
    imu_mount_rpy_deg=(2.0, -2.0, 0.0),
    gyro_bias_rad_s=(0.03, 0.0, 0.0),
    acc_bias_m_s2=(0.3, 0.0, 0.0),
    load_cell_gain_error=0.05,
    load_cell_zero_n=10.0,
    seed=7,
)


@pytest.fixture(scope="module")
def gap_walk() -> pd.DataFrame:
    return simulate(gait=GaitConfig(duration=20.0), seed=1, reality=GAP)


@pytest.fixture(scope="module")
def corrections(gap_walk) -> ModelCorrections:
    return estimate_corrections(gap_walk)


def test_corrections_match_the_truth(gap_walk, corrections):
    truth = gap_walk.attrs["reality"]
    c = corrections
    assert np.allclose(c.imu_mount_rpy_deg[:2], truth["imu_mount_rpy_deg"][:2], atol=0.3)
    assert c.trunk_com_x_m == pytest.approx(0.03, abs=0.01)
    assert c.trunk_com_y_m == pytest.approx(-0.03, abs=0.01)
    assert np.allclose(c.gyro_bias_rad_s, truth["gyro_bias_rad_s"], atol=0.003)
    gt = np.array([truth["load_cell_gain"][s] for s in SENSOR_NAMES])
    ge = np.array([c.load_cell_gain[s] for s in SENSOR_NAMES])
    rel = ge / gt
    assert np.max(np.abs(rel / rel.mean() - 1)) < 0.01
    m_seen = SURALP.mass * 1.05 * gt.mean()
    assert c.mass_kg == pytest.approx(m_seen, rel=0.01)
    zt = np.array([truth["load_cell_zero_n"][s] for s in SENSOR_NAMES])
    ze = np.array([c.load_cell_zero_n[s] for s in SENSOR_NAMES])
    assert np.max(np.abs(ze - zt)) < 3.0
    assert all(v > 0 for v in c.sigma.values())


def test_measured_mass_fixes_the_common_scale(gap_walk):
    truth = gap_walk.attrs["reality"]
    m_true = SURALP.mass * 1.05
    c = estimate_corrections(gap_walk, measured_mass_kg=m_true)
    gt = np.array([truth["load_cell_gain"][s] for s in SENSOR_NAMES])
    ge = np.array([c.load_cell_gain[s] for s in SENSOR_NAMES])
    assert ge.mean() == pytest.approx(gt.mean(), rel=0.01)
    assert c.mass_kg == m_true and c.measured_mass


def test_corrections_remove_the_false_alarms(gap_walk, corrections):
    cols = [f"flag_{s}" for s in SENSOR_NAMES]
    before = Monitor.for_log(gap_walk, common_mode=False).run(gap_walk)
    assert before[cols].any().sum() >= 2  # the gap alone breaks the nominal model
    fixed = apply_corrections(gap_walk, corrections)
    assert fixed.attrs["robot"]["mass"] == pytest.approx(corrections.mass_kg)
    after = Monitor.for_log(fixed).run(fixed)
    assert not after[cols].any().any()


def test_toml_round_trip(tmp_path, corrections):
    p = tmp_path / "th.toml"
    p.write_text("[thresholds]\n" + corrections.to_toml())
    back = ModelCorrections.from_toml(p)
    assert back == corrections
    assert back.sigma == pytest.approx(corrections.sigma)
    q = tmp_path / "none.toml"
    q.write_text("[thresholds]\n")
    assert ModelCorrections.from_toml(q) is None
    assert apply_corrections(pd.DataFrame(), None).empty


def test_too_short_or_incomplete_log_is_refused(gap_walk):
    with pytest.raises(LogFormatError, match="at least 1000 samples"):
        estimate_corrections(gap_walk.iloc[:500])
    with pytest.raises(LogFormatError, match="imu_gyro_x"):
        estimate_corrections(gap_walk.drop(columns=["imu_gyro_x"]))


def test_cli_simulate_reality_calibrate_model_and_run(gap_walk, tmp_path):
    from typer.testing import CliRunner

    from grfguard.cli import app
    from grfguard.io.logio import load_log, write_log

    runner = CliRunner()
    sim = tmp_path / "g.parquet"
    res = runner.invoke(app, ["simulate", "-o", str(sim), "--duration", "2",
                              "--reality", "imu_pitch"])
    assert res.exit_code == 0, res.output
    assert load_log(sim).attrs["reality"]["imu_mount_rpy_deg"] == [0.0, 2.0, 0.0]
    log = tmp_path / "walk.parquet"
    write_log(gap_walk, log)
    th = tmp_path / "th.toml"
    res = runner.invoke(app, ["calibrate", str(log), "-o", str(th), "--model"])
    assert res.exit_code == 0, res.output
    text = th.read_text()
    assert "[thresholds]" in text and "[model_corrections]" in text
    out = tmp_path / "o.parquet"
    res = runner.invoke(app, ["run", str(log), "-o", str(out), "--thresholds", str(th)])
    assert res.exit_code == 0, res.output
    flags = load_log(out)[[f"flag_{s}" for s in SENSOR_NAMES]]
    assert not flags.any().any()


def test_cli_calibrate_model_records_the_twin_filter_and_run_uses_it(tmp_path, monkeypatch):
    """With a vibrating accelerometer `calibrate --model` chooses the accelerometer-free
    sensor's rate low-pass (two settings here, to keep the test short) at the
    command's false-alarm rate, writes it into
    the thresholds file, and `run` with that file monitors with it: the calibration walk
    itself is not flagged."""
    from typer.testing import CliRunner

    import grfguard.calib.twin_filter as tf
    from grfguard.cli import app
    from grfguard.cli_calib import corrected_log_and_config
    from grfguard.detect import MonitorConfig
    from grfguard.io.logio import load_log, write_log
    from grfguard.sim.reality import load_reality

    monkeypatch.setattr(tf, "TWIN_FILTER_GRID", ((10.0, None), (8.0, 0.5)))
    rates, choose = [], tf.choose_twin_filter

    def spy(*args, **kwargs):  # the filter is chosen at the CLI's false-alarm rate
        rates.append(kwargs.get("false_alarm_rate_per_hour"))
        return choose(*args, **kwargs)

    monkeypatch.setattr(tf, "choose_twin_filter", spy)
    gap = RealityGap(acc_vibration=load_reality("all").acc_vibration, seed=7)
    log = tmp_path / "vib.parquet"
    write_log(simulate(gait=GaitConfig(duration=16.0), seed=1, reality=gap), log)
    th = tmp_path / "th.toml"
    res = CliRunner().invoke(app, ["calibrate", str(log), "-o", str(th), "--model",
                                   "--false-alarm-rate", "0.05"])
    assert res.exit_code == 0, res.output
    assert rates == [0.05]
    assert "(chosen)" in res.output  # the settings tried, on the console
    corr = ModelCorrections.from_toml(th)
    assert not corr.use_accelerometer
    assert (corr.twin_filter_cutoff_hz, corr.twin_filter_damping) in ((10.0, None), (8.0, 0.5))
    assert f"twin_filter_cutoff_hz = {corr.twin_filter_cutoff_hz!r}" in th.read_text()
    _, cfg = corrected_log_and_config(load_log(log), th, MonitorConfig())
    assert (cfg.vfs.filter_cutoff, cfg.vfs.filter_damping) == (
        corr.twin_filter_cutoff_hz, corr.twin_filter_damping)
    out = tmp_path / "o.parquet"
    res = CliRunner().invoke(app, ["run", str(log), "-o", str(out), "--thresholds", str(th)])
    assert res.exit_code == 0, res.output
    assert not load_log(out)[[f"flag_{s}" for s in SENSOR_NAMES]].any().any()
