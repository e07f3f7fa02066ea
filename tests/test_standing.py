"""Standing still is covered (issue 10): additive faults that start during an 8 s stand
in double support are detected there, and 60 s of fault-free standing raise nothing."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.detect.standing import StandingConfig, StandingDetector
from grfguard.errors import ConfigError
from grfguard.estimate.vfs import VirtualForceSensor
from grfguard.faults.inject import inject_faults
from grfguard.model.robot import SENSOR_NAMES
from grfguard.sim import GaitConfig, simulate

FORCES = [f"force_{s}" for s in SENSOR_NAMES]


@pytest.fixture(scope="module")
def stand() -> tuple[pd.DataFrame, np.ndarray]:
    df = simulate(gait=GaitConfig(duration=8.0, start_time=7.0, stop_time=1.0), seed=3)
    v = VirtualForceSensor.for_log(df).run(df)[[f"vfs_{s}" for s in SENSOR_NAMES]]
    return df, v.to_numpy(float)


def _first_flags(df: pd.DataFrame, v: np.ndarray) -> dict[str, tuple[float, str]]:
    det = StandingDetector(0.001)
    x = df[FORCES].to_numpy(float)
    ds = (df[["contact_ref_r", "contact_ref_l"]].to_numpy() > 0.5).all(axis=1)
    t = df["time"].to_numpy()
    out: dict[str, tuple[float, str]] = {}
    for k in range(len(t)):
        flags, kinds = det.update(x[k], v[k], bool(ds[k]))
        for i, s in enumerate(SENSOR_NAMES):
            if flags[i] and s not in out:
                out[s] = (float(t[k]), kinds[i])
    return out


@pytest.mark.parametrize(
    "spec, sensor, within_s, kind",
    [
        ("r2=offset:100@3", "r2", 1.0, "offset"),
        ("l1=offset:-100@3", "l1", 1.0, "offset"),
        ("l3=drift:15@3", "l3", 2.0, "drift"),
        ("r4=gain:1.5@3", "r4", 1.0, "offset"),
    ],
)
def test_fault_during_a_stand_is_detected_there(stand, spec, sensor, within_s, kind):
    df, v = stand
    faulty = inject_faults(df, [spec], seed=0)
    flags = _first_flags(faulty, v)
    assert set(flags) == {sensor}, flags
    t, k = flags[sensor]
    assert 3.0 < t <= 3.0 + within_s
    assert k == kind


def test_no_false_alarm_over_60_s_of_standing(stand):
    df, v = stand
    # 60 s = the fault-free stand with 8 noise seeds (the physics is the same)
    for seed in range(8):
        noisy = df.copy()
        rng = np.random.default_rng(seed)
        noisy[FORCES] = df[[f"true_force_{s}" for s in SENSOR_NAMES]].to_numpy() + rng.normal(
            0.0, 2.0, (len(df), 8))
        assert _first_flags(noisy, v) == {}


def test_standing_detector_resets_when_a_foot_lifts():
    det = StandingDetector(0.001, StandingConfig(settle_s=0.01, baseline_s=0.01))
    for _ in range(30):
        det.update([100.0] * 8, [100.0] * 8, True)
    assert det.standing
    det.update([100.0] * 8, [100.0] * 8, False)
    assert not det.standing and not det.flags.any()
    flags, _ = det.update([np.nan] * 8, [100.0] * 8, True)  # bad sample: no exception
    assert not flags.any()
    with pytest.raises(ConfigError, match="threshold_n"):
        StandingConfig(threshold_n=-1.0)
