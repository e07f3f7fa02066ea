"""Issue 9: every stage of a monitor runs at the log's rate, not at an assumed 1 kHz.

A short simulated SURALP walk decimated to 100 Hz gives ``dt_s = 0.01`` in the monitor's
config, the standing layer, the guards, the system layer (common mode, swing zeros, gyro
bias, IMU tilt, vibration), the compiled step's parameters and the observer of the
paper's method; the sampling period of every stage that integrates in time is required.
Non-SURALP robots logged at 100 Hz (a heavier SURALP-shaped robot; Unitree G1's corner
cells; PAL Talos's ankle F/T sensors) go through every stage at the log's rate. A log
that names no robot is refused, never read as SURALP.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from grfguard.detect.config import MonitorConfig, config_for_log
from grfguard.detect.monitor import Monitor
from grfguard.detect.observer import ObserverConfig
from grfguard.detect.standing import StandingDetector, StandingStage
from grfguard.detect.system import (
    AccVibrationDetector,
    CommonModeMonitor,
    GyroBiasLearner,
    ImuTiltLearner,
    SwingZeroLearner,
)
from grfguard.errors import ConfigError, LogFormatError
from grfguard.estimate.vfs import VirtualForceSensor
from grfguard.model.robot import SURALP, RobotConfig
from grfguard.sim import simulate
from grfguard.sim.config import GaitConfig, NoiseConfig
from grfguard.sim.wholebody import decimate


@pytest.fixture(scope="module")
def log_100hz():
    walk = simulate(SURALP, GaitConfig(duration=2.0), NoiseConfig(), seed=3)
    return decimate(walk, 100)


def test_a_100hz_log_sets_every_stage_to_10ms(log_100hz) -> None:
    assert config_for_log(log_100hz).dt_s == pytest.approx(0.01, rel=1e-9)
    # default method: monitor config, guards, standing layer, compiled step
    m = Monitor.for_log(log_100hz, MonitorConfig())
    assert m.config.dt_s == pytest.approx(0.01, rel=1e-9)
    assert m.config.observer.dt_s == pytest.approx(0.01, rel=1e-9)
    assert m.time_guard.dt_s == pytest.approx(0.01, rel=1e-9)
    assert m.standing is not None
    assert m.standing.detector.dt_s == pytest.approx(0.01, rel=1e-9)
    k = m._kernel()
    if k is not None:  # the compiled step reads the same period
        from grfguard.kernels.detect import P_DT
        from grfguard.kernels.standing import _S_DT

        assert k.prm[P_DT] == pytest.approx(0.01, rel=1e-9)
        assert k.sp[_S_DT] == pytest.approx(0.01, rel=1e-9)
    _system_layer_at(m, 0.01)
    assert m.vfs is not None and m.vfs.config.dt == pytest.approx(0.01, rel=1e-9)
    # the paper's method: its observer (low-pass) runs at 10 ms too
    p = Monitor.for_log(log_100hz, MonitorConfig(method="paper"))
    assert p.config.observer.dt_s == pytest.approx(0.01, rel=1e-9)
    assert p.paper.config.observer.dt_s == pytest.approx(0.01, rel=1e-9)
    assert p.paper._obs.config.dt_s == pytest.approx(0.01, rel=1e-9)
    assert p.standing is not None and p.standing.detector.dt_s == pytest.approx(0.01)
    # a config given with another period is overridden by the log's rate
    q = Monitor.for_log(log_100hz, MonitorConfig(dt_s=0.005))
    assert q.config.dt_s == pytest.approx(0.01, rel=1e-9)
    assert q.config.observer.dt_s == pytest.approx(0.01, rel=1e-9)
    # and the monitor runs on the 100 Hz log without a false alarm
    out = m.run(log_100hz)
    flags = [c for c in out.columns if c.startswith("flag_")]
    assert flags and not out[flags].to_numpy(bool).any()


def test_observer_follows_the_monitor_rate() -> None:
    cfg = MonitorConfig(dt_s=0.005)
    assert cfg.observer.dt_s == 0.005
    cfg = MonitorConfig(dt_s=0.002, observer=ObserverConfig(dt_s=0.001, lowpass_hz=2.0))
    assert cfg.observer.dt_s == 0.002 and cfg.observer.lowpass_hz == 2.0
    assert cfg.replace(dt_s=0.01).observer.dt_s == 0.01
    assert MonitorConfig.from_toml_text(cfg.to_toml()).observer.dt_s == 0.002


def test_standing_detector_needs_the_sampling_period() -> None:
    with pytest.raises(TypeError):
        StandingDetector()  # type: ignore[call-arg]
    for bad in (0.0, -0.01, math.nan, "0.01", True):
        with pytest.raises(ConfigError, match="dt_s"):
            StandingDetector(bad, weight_n=SURALP.weight)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="dt_s"):
        StandingStage(0.0, weight_n=SURALP.weight)
    st = StandingStage(0.01, weight_n=SURALP.weight)
    assert st.detector.dt_s == 0.01
    # the 100 Hz filter constants are the continuous ones sampled at 10 ms
    c = st.detector.config
    assert st.detector._a == pytest.approx(1.0 - math.exp(-0.01 / c.filter_s))
    assert st._a_hold == pytest.approx(1.0 - math.exp(-0.01 / c.hold_filter_s))


def _system_layer_at(m: Monitor, dt: float) -> None:
    """Every stage of the monitor's system layer that exists runs at ``dt``."""
    stages = [m.common, m.zeros, m.gyro_bias, m.tilt, m.vibration]
    assert m.common is not None and m.zeros is not None and m.gyro_bias is not None
    for st in stages:
        if st is not None:
            assert st.dt_s == pytest.approx(dt, rel=1e-9), type(st).__name__


def test_system_stages_need_the_sampling_period() -> None:
    kin = VirtualForceSensor(SURALP).kin
    makers = {
        "CommonModeMonitor": lambda *a: CommonModeMonitor(SURALP, *a),
        "SwingZeroLearner": lambda *a: SwingZeroLearner(SURALP, *a),
        "AccVibrationDetector": lambda *a: AccVibrationDetector(*a),
        "GyroBiasLearner": lambda *a: GyroBiasLearner(*a),
        "ImuTiltLearner": lambda *a: ImuTiltLearner(kin, *a),
    }
    for name, make in makers.items():
        with pytest.raises(TypeError):
            make()  # no assumed 1 ms
        for bad in (0.0, -0.01, math.nan, "0.01", True, 2.0):
            with pytest.raises(ConfigError, match=f"{name}: dt_s"):
                make(bad)
        assert make(0.01).dt_s == 0.01
    # the time constants are in seconds: the same 10 s fit at 100 Hz and at 1 kHz
    lam_100 = CommonModeMonitor(SURALP, 0.01)
    assert lam_100.dt_s / lam_100.config.time_constant_s == pytest.approx(1e-3)
    # the vibration high-pass is the same continuous filter sampled at 10 ms
    v100, v1k = AccVibrationDetector(0.01), AccVibrationDetector(0.001)
    assert v100._lam == pytest.approx(math.exp(-0.01 / v100.config.time_constant_s))
    assert v100._b != v1k._b


def test_a_log_without_robot_is_refused(log_100hz) -> None:
    bare = log_100hz.copy()
    bare.attrs = {}
    with pytest.raises(LogFormatError, match=r"names no robot.*--robot"):
        VirtualForceSensor.for_log(bare)
    with pytest.raises(LogFormatError, match="names no robot"):
        Monitor.for_log(bare)


def test_a_heavier_robot_at_100hz_runs_every_stage_at_10ms() -> None:
    """A SURALP-shaped robot that is not SURALP (heavier, longer feet) logged at 100 Hz:
    its own description reaches the virtual sensor and the system layer."""
    other = RobotConfig(mass=SURALP.mass * 1.4, foot_length=SURALP.foot_length * 1.1)
    walk = simulate(other, GaitConfig(duration=3.0), NoiseConfig(), seed=5)
    log = decimate(walk, 100)
    m = Monitor.for_log(log, MonitorConfig())
    assert m.config.dt_s == pytest.approx(0.01, rel=1e-9)
    assert m.vfs is not None and m.vfs.config.dt == pytest.approx(0.01, rel=1e-9)
    assert m.robot.mass == pytest.approx(other.mass)
    assert m.vfs.robot.foot_length == pytest.approx(other.foot_length)
    assert m.standing is not None and m.standing.detector.dt_s == pytest.approx(0.01)
    _system_layer_at(m, 0.01)
    assert m.common is not None and m.common.robot.mass == pytest.approx(other.mass)
    out = m.run(log)
    flags = [c for c in out.columns if c.startswith("flag_")]
    assert flags and not out[flags].to_numpy(bool).any()
    # the virtual sensor weighs this robot, not SURALP (within 3 % in the mean)
    tot = out["vfs_total_r"].to_numpy(float) + out["vfs_total_l"].to_numpy(float)
    assert np.nanmean(tot) == pytest.approx(other.mass * other.gravity, rel=0.03)


@pytest.mark.parametrize("name", ["g1", "talos"])
def test_described_robots_at_100hz(name: str) -> None:
    """G1 (corner cells) and Talos (ankle F/T) simulated at 100 Hz: the monitor's stages
    (corner monitor or channel monitor) take the log's 10 ms, and the fault-free walk
    raises no alarm."""
    pytest.importorskip("mujoco")
    from grfguard.detect.channels import ChannelConfig, ChannelMonitor
    from grfguard.estimate.described import run_described, with_described_vfs
    from grfguard.model.description import load_description
    from grfguard.model.loader import load_model
    from grfguard.sim.wholebody import scaled_gait, simulate_robot

    rob = load_model(load_description(name))
    walk = simulate_robot(rob, scaled_gait(rob, duration=4.0), NoiseConfig(), seed=2,
                          sample_rate=100)
    assert np.median(np.diff(walk["time"].to_numpy(float))) == pytest.approx(0.01)
    log = with_described_vfs(walk, rob)
    if name == "g1":
        m = Monitor.for_log(log, MonitorConfig())
        assert m.config.dt_s == pytest.approx(0.01, rel=1e-9)
        assert m.time_guard.dt_s == pytest.approx(0.01, rel=1e-9)
        assert m.standing is not None and m.standing.detector.dt_s == pytest.approx(0.01)
        _system_layer_at(m, 0.01)
    else:
        from importlib import resources

        f = resources.files("grfguard") / "data" / "talos_channels.toml"
        cm = ChannelMonitor(ChannelConfig.from_toml_text(f.read_text(), str(f)))
        cm.run(log)
        assert cm.dt_s == pytest.approx(0.01, rel=1e-9)
    out = run_described(log, MonitorConfig(), rob)
    flags = [c for c in out.columns if c.startswith("flag_")]
    assert flags and not out[flags].to_numpy(bool).any()
