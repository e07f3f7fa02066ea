"""Issue 9: every stage of a monitor runs at the log's rate, not at an assumed 1 kHz.

A short simulated SURALP walk decimated to 100 Hz gives ``dt_s = 0.01`` in the monitor's
config, the standing layer, the guards, the compiled step's parameters and the observer
of the paper's method; the sampling period of a bare standing detector is required.
"""

from __future__ import annotations

import math

import pytest

from grfguard.detect.config import MonitorConfig, config_for_log
from grfguard.detect.monitor import Monitor
from grfguard.detect.observer import ObserverConfig
from grfguard.detect.standing import StandingDetector, StandingStage
from grfguard.errors import ConfigError
from grfguard.model.robot import SURALP
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
    if m.common is not None:
        assert m.common.dt_s == pytest.approx(0.01, rel=1e-9)
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
            StandingDetector(bad)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="dt_s"):
        StandingStage(0.0)
    st = StandingStage(0.01)
    assert st.detector.dt_s == 0.01
    # the 100 Hz filter constants are the continuous ones sampled at 10 ms
    c = st.detector.config
    assert st.detector._a == pytest.approx(1.0 - math.exp(-0.01 / c.filter_s))
    assert st._a_hold == pytest.approx(1.0 - math.exp(-0.01 / c.hold_filter_s))
