"""Fault-free walks: zero alarms with the shipped thresholds (calibrated on other seeds).

The full 10-minute check (3 gaits x 2 seeds x 100 s, about 1.5 min) runs here and in
benchmarks/bench_monitor.py; the other tests use the first 20 s of the session walks:
default, fast and slow gaits, and the 60 kg small robot to check that the per-phase
normalisation carries over.
"""

from __future__ import annotations

import pandas as pd
import pytest

from grfguard.detect.monitor import Monitor
from grfguard.estimate.vfs import with_vfs_columns
from grfguard.evaluate.detection import evaluate_detection
from grfguard.faults import inject_faults
from grfguard.model.robot import SENSOR_NAMES


@pytest.fixture(scope="module", params=["default", "fast", "slow", "small_robot"])
def free_walk(request) -> pd.DataFrame:
    name = {"default": "default_walk", "fast": "fast_gait_walk", "slow": "slow_gait_walk",
            "small_robot": "small_robot_walk"}[request.param]
    log = request.getfixturevalue(name)
    # 20 s of each (the VFS dominates the cost); 10 min in benchmarks/bench_monitor.py
    return with_vfs_columns(log.iloc[:20000])


def test_fault_free_walk_zero_alarms(free_walk: pd.DataFrame) -> None:
    res = Monitor.for_log(free_walk).run(free_walk)
    flags = res[[f"flag_{s}" for s in SENSOR_NAMES]].to_numpy()
    assert not flags.any(), (free_walk.attrs.get("gait"), flags.sum(axis=0))
    assert (res[[f"kind_{s}" for s in SENSOR_NAMES]].to_numpy() == "none").all()


def test_same_thresholds_detect_on_every_walk(free_walk: pd.DataFrame) -> None:
    """One threshold set across gaits and robot sizes: an offset and a frozen sensor."""
    log = inject_faults(free_walk, ["l2=offset:40@4", "r3=frozen@4"], seed=1)
    res = Monitor.for_log(log).run(log)
    tab = evaluate_detection(res)
    assert tab.loc["l2", "detected"] and tab.loc["l2", "kind_estimated"] == "offset"
    assert tab.loc["r3", "detected"] and tab.loc["r3", "kind_estimated"] == "frozen"
    assert tab.loc["l2", "delay_s"] < 2.0 and tab.loc["r3", "delay_s"] < 2.0
    assert tab["false_alarms"].sum() == 0


def test_ten_minutes_fault_free_zero_alarms() -> None:
    """3 gaits x seeds 1-2 x 100 s = 10 min, shipped thresholds (calibrated on 101-103)."""
    from grfguard.sim import GaitConfig, simulate

    for sl, sp in ((0.12, 1.0), (0.15, 0.8), (0.08, 1.2)):
        for seed in (1, 2):
            log = with_vfs_columns(simulate(gait=GaitConfig(step_length=sl, step_period=sp,
                                                    duration=100.0), seed=seed))
            res = Monitor.for_log(log).run(log)
            flags = res[[f"flag_{s}" for s in SENSOR_NAMES]].to_numpy()
            assert not flags.any(), (sl, sp, seed, flags.sum(axis=0))
