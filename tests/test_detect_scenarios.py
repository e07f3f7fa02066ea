"""The must-show list of the detector on real simulated walks (shipped thresholds).

Timeline of the default walk (right foot supports first, 1.0 s steps, 20 % double
support): the right foot touches down at 5.0 s and swings 6.2-7.0 s; the left foot
lifts off at 5.2 s and lands at 6.0 s. So the paper's scenario on the right foot has
its faults start at a touchdown (the faulty foot only swings 1.2 s later), and the
mirror scenario on the left foot has the timing of the paper (the faulty foot lifts
0.2 s after the onset).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.detect.monitor import Monitor, MonitorConfig
from grfguard.estimate.vfs import with_vfs_columns
from grfguard.evaluate.detection import evaluate_detection
from grfguard.faults import inject_faults
from grfguard.model.robot import SENSOR_NAMES

ONSET = 5.0




def paper_faults(side: str) -> list[str]:
    return [f"{side}1=frozen:0@5", f"{side}2=offset:100@5", f"{side}3=drift:15@5",
            f"{side}4=offset:-100@5"]


@pytest.fixture(scope="module")
def walk(default_walk: pd.DataFrame) -> pd.DataFrame:
    """The first 20 s of the 60 s default walk with its VFS (the full 60 s run is in
    benchmarks/bench_monitor.py); the faults are permanent from 5 s to the end."""
    return with_vfs_columns(default_walk.iloc[:20000])


@pytest.fixture(scope="module")
def runs(walk: pd.DataFrame) -> dict[str, tuple[pd.DataFrame, pd.DataFrame]]:
    out = {}
    for side in ("r", "l"):
        log = inject_faults(walk, paper_faults(side), seed=0)
        for method in ("default", "paper"):
            res = Monitor.for_log(log, MonitorConfig(method=method)).run(log)
            out[f"{side}_{method}"] = (res, evaluate_detection(res))
    return out


def _vfs_rmse(res: pd.DataFrame, s: str, t_from: float) -> float:
    t = res["time"].to_numpy()
    m = (t >= t_from) & (res[f"contact_ref_{s[0]}"].to_numpy() > 0.5)
    e = res[f"vfs_{s}"].to_numpy()[m] - res[f"true_force_{s}"].to_numpy()[m]
    return float(np.sqrt(np.mean(e**2)))


def _common_checks(side: str, res: pd.DataFrame, tab: pd.DataFrame) -> None:
    other = "l" if side == "r" else "r"
    t = res["time"].to_numpy()
    flags = res[[f"flag_{s}" for s in SENSOR_NAMES]].to_numpy()
    assert not flags[t < ONSET].any(), "no flag before the onset"
    assert not res[[f"flag_{other}{k}" for k in range(1, 5)]].to_numpy().any(), \
        "no flag on the healthy foot, ever"
    assert tab["detected"][[f"{side}{k}" for k in range(1, 5)]].all()
    kinds = tab["kind_estimated"]
    assert kinds[f"{side}1"] == "frozen"
    assert kinds[f"{side}2"] == "offset"
    assert kinds[f"{side}3"] == "drift"
    assert kinds[f"{side}4"] == "offset"
    rm = tab["recovery_rmse_n"]
    assert rm[f"{side}2"] <= 5.0 and rm[f"{side}4"] <= 5.0
    assert rm[f"{side}3"] <= 10.0
    d1 = tab.loc[f"{side}1", "delay_s"]
    assert rm[f"{side}1"] <= _vfs_rmse(res, f"{side}1", ONSET + d1)
    # eta sizes the additive faults
    assert tab["fault_size_error_n"][[f"{side}2", f"{side}3", f"{side}4"]].max() < 5.0
    assert tab["false_alarms"].sum() == 0


def _next_loaded(res: pd.DataFrame, sensor: str, t0: float) -> float:
    """First time >= t0 at which ``sensor``'s corner carries load (truth) [s]."""
    t = res["time"].to_numpy()
    idx = np.flatnonzero((t >= t0) & (res[f"true_force_{sensor}"].to_numpy() > 1.0))
    return float(t[idx[0]])


def test_paper_scenario_right_foot(runs) -> None:
    """The issue's bounds; the right foot has the prototype's timing (swing 5.2-6.0 s)."""
    res, tab = runs["r_default"]
    _common_checks("r", res, tab)
    d = tab["delay_s"]
    assert d["r2"] <= 0.5 and d["r4"] <= 0.5
    assert d["r3"] <= 1.0
    # frozen at 0: within 0.2 s of the foot being (next) loaded
    assert ONSET + d["r1"] - _next_loaded(res, "r1", ONSET) <= 0.2


def test_mirror_scenario_left_foot(runs) -> None:
    """The left foot lands at the onset: the unfavourable phase for the drift."""
    res, tab = runs["l_default"]
    _common_checks("l", res, tab)
    d = tab["delay_s"]
    assert d["l2"] <= 0.5 and d["l4"] <= 0.5
    assert ONSET + d["l1"] - _next_loaded(res, "l1", ONSET) <= 0.2
    # The drift (15 N/s) stays below the per-corner VFS error in this single support
    # and the foot-total test is blind while l1 carries no information: it is caught
    # at the start of the next swing window (benchmarks/bench_onset_phase.py).
    assert d["l3"] <= 1.5


def test_paper_method_same_runs_reported(runs) -> None:
    """The paper's method runs on the same input; its numbers go to BENCHMARKS.md."""
    for side in ("r", "l"):
        res, tab = runs[f"{side}_paper"]
        assert set(tab.index) == set(SENSOR_NAMES)
        rec = res[[f"recovered_{s}" for s in SENSOR_NAMES]].to_numpy(float)
        assert np.isfinite(rec).all()
        assert (tab["kind_estimated"][tab["detected"].fillna(False).astype(bool)]
                == "unknown").all()


SINGLE = {
    "stuck": "l2=stuck@5.3",
    "gain": "l2=gain:1.6@5",
    "noise": "l2=noise:25@5",
    "spikes": "l2=spikes:120@5",
    "dropout": "l2=dropout@5-6.5",
    "saturation": "l2=saturation:200@5",
    "offset_small": "l2=offset:20@5",
}


@pytest.mark.parametrize("name", list(SINGLE))
def test_single_fault_detected_and_classified(walk: pd.DataFrame, name: str) -> None:
    log = inject_faults(walk.iloc[:16000], [SINGLE[name]], seed=5)
    res = Monitor.for_log(log).run(log)
    tab = evaluate_detection(res)
    assert tab.loc["l2", "detected"], tab.loc["l2"]
    kind = name.split("_")[0]
    assert tab.loc["l2", "kind_estimated"] == kind, tab.loc["l2"]
    others = [s for s in SENSOR_NAMES if s != "l2"]
    assert not res[[f"flag_{s}" for s in others]].to_numpy().any()
    # a gain only shows in stance, through the foot-total balance (coarse VFS total)
    assert tab.loc["l2", "delay_s"] < (5.0 if kind == "gain" else 2.0)
    assert np.isfinite(res["recovered_l2"].to_numpy()).all()
