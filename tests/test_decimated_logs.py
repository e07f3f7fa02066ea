"""The paper's scenario on SURALP logged at 200 Hz and 100 Hz (every 5th / 10th sample
of the 1 kHz walk): detected, with no false alarm on the fault-free walk; also with the
load cells quantised to 0.5 N at 100 Hz (a healthy reading then repeats by chance, the
frozen test must not take that for a frozen sensor)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.detect.monitor import Monitor, MonitorConfig
from grfguard.evaluate.detection import evaluate_detection
from grfguard.faults import inject_faults
from grfguard.sim.wholebody import decimate

FAULTS = ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5", "r4=offset:-100@5"]


@pytest.fixture(scope="module", params=[(200, 0.0), (100, 0.0), (100, 0.5)],
                ids=["200Hz", "100Hz", "100Hz-0.5N"])
def decimated(request, default_walk: pd.DataFrame):
    rate, lsb_n = request.param
    walk = decimate(default_walk.iloc[:12000], rate)
    if lsb_n:
        cols = [c for c in walk.columns if c.startswith("force_")]
        walk[cols] = np.round(walk[cols].to_numpy() / lsb_n) * lsb_n
    faulty = inject_faults(walk, FAULTS, seed=0)
    res = Monitor.for_log(faulty, MonitorConfig()).run(faulty)
    clean = Monitor.for_log(walk, MonitorConfig()).run(walk)
    return rate, walk, evaluate_detection(res), clean


def test_rate_is_the_decimated_one(decimated) -> None:
    rate, walk, _, _ = decimated
    assert walk.attrs["sample_rate"] == rate
    assert abs(walk["time"].diff().median() - 1.0 / rate) < 1e-9


def test_offsets_and_drift_detected_in_bounds(decimated) -> None:
    _, _, tab, _ = decimated
    assert tab.loc[["r1", "r2", "r3", "r4"], "detected"].all()
    assert tab.loc["r2", "delay_s"] <= 0.5 and tab.loc["r4", "delay_s"] <= 0.5
    assert tab.loc["r3", "delay_s"] <= 1.0
    assert (tab.loc[["r1", "r2", "r3", "r4"], "kind_estimated"]
            == ["frozen", "offset", "drift", "offset"]).all()


def test_no_false_alarm_on_the_fault_free_walk(decimated) -> None:
    _, _, _, clean = decimated
    for s in ("r1", "r2", "r3", "r4", "l1", "l2", "l3", "l4"):
        assert not clean[f"flag_{s}"].any(), s


def test_frozen_detected_within_0_2_s_of_the_load(decimated) -> None:
    """The right foot is loaded from 5.0 s, the onset."""
    _, _, tab, _ = decimated
    assert tab.loc["r1", "delay_s"] <= 0.2


def test_constant_run_must_beat_the_sensors_chance_repeats() -> None:
    """A sensor that repeated half of its readings by chance needs a longer identical run
    than one that never repeated, for the same chance limit."""
    from grfguard.detect.residual_tests import constant_test
    from grfguard.detect.sensor_state import SensorState

    def run_length(history: list[float]) -> int:
        """Identical readings of 500 N until the alarm, after ``history``."""
        s = SensorState()
        for x in history:
            constant_test(s, x, True, 3, 1e-6)
        return next(n for n in range(1, 200) if constant_test(s, 500.0, True, 3, 1e-6))

    smooth = [float(k) for k in range(400)]  # never repeats
    coarse = [float(k // 2) for k in range(400)]  # every value twice
    assert run_length(smooth) == 4  # p = 1/401: (1/401)^3 <= 1e-6 < (1/401)^2
    assert run_length(coarse) == 22  # p = 201/401: 21 repeats (p^20 = 1.001e-6 > 1e-6)


def test_zeros_of_an_unloaded_cell_are_not_chance_repeats() -> None:
    """A cell clipped at 0 N in swing repeats 0 for long stretches; only loaded readings
    teach the chance of a repeat, so a frozen loaded reading is still found in 4."""
    from grfguard.detect.residual_tests import constant_test
    from grfguard.detect.sensor_state import SensorState

    s = SensorState()
    for cycle in range(4):
        for _ in range(300):
            constant_test(s, 0.0, False, 3, 1e-6)  # swing: clipped at zero
        for k in range(100):
            constant_test(s, 200.0 + k + cycle / 10, True, 3, 1e-6)  # stance: varies
    hits = [constant_test(s, 250.0, True, 3, 1e-6) for _ in range(4)]
    assert hits == [False, False, False, True]


def test_frozen_time_is_in_seconds_and_legacy_counts_are_read_at_1_khz() -> None:
    from grfguard.detect.config import MonitorConfig
    from grfguard.detect.detector import Detector
    from grfguard.detect.thresholds import Thresholds
    from grfguard.errors import ConfigError

    th = Thresholds.from_toml_text("[thresholds]\nconst_samples = 30\n")
    assert th.const_s == pytest.approx(0.030)
    with pytest.raises(ConfigError, match="const_s"):
        Thresholds.from_toml_text("[thresholds]\nconst_samples = 30\nconst_s = 0.03\n")
    n = {dt: Detector(MonitorConfig(dt_s=dt)).const_samples for dt in (1e-3, 5e-3, 1e-2)}
    assert n == {1e-3: 25, 5e-3: 5, 1e-2: 3}
