"""Detection metrics matched to truth windows, on a synthetic detector output."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.errors import LogFormatError
from grfguard.evaluate.detection import evaluate_detection, summarize_detection
from grfguard.faults import inject_faults
from grfguard.model.robot import SENSOR_NAMES


def test_evaluate_known_answers() -> None:
    t = np.arange(0, 10, 1e-3)
    d = {"time": t, "contact_ref_r": np.ones_like(t), "contact_ref_l": np.ones_like(t)}
    for s in SENSOR_NAMES:
        d[f"true_force_{s}"] = np.full_like(t, 100.0)
        d[f"force_{s}"] = np.full_like(t, 100.0)
    log = inject_faults(pd.DataFrame(d), ["r2=offset:50@5", "r1=frozen@3-6"], seed=0)
    out = pd.DataFrame({"time": t})
    for s in SENSOR_NAMES:
        out[f"flag_{s}"] = False
        out[f"kind_{s}"] = "none"
        out[f"eta_{s}"] = 0.0
        out[f"recovered_{s}"] = log[f"force_{s}"]
    out.loc[t >= 5.25, "flag_r2"] = True
    out.loc[t >= 5.25, "kind_r2"] = "offset"
    out.loc[t >= 5.25, "eta_r2"] = 48.0
    out.loc[t >= 5.25, "recovered_r2"] = log["force_r2"][t >= 5.25] - 48.0
    out.loc[(t >= 1) & (t < 1.5), "flag_l3"] = True  # a false alarm
    tab = evaluate_detection(log, out)
    assert tab.loc["r2", "detected"] and tab.loc["r2", "delay_s"] == pytest.approx(0.25)
    assert tab.loc["r2", "kind_correct"]
    assert tab.loc["r2", "recovery_rmse_n"] == pytest.approx(2.0)
    assert tab.loc["r2", "fault_size_error_n"] == pytest.approx(2.0)
    assert tab.loc["r1", "detected"] is False or not tab.loc["r1", "detected"]
    assert np.isnan(tab.loc["r1", "delay_s"])
    assert tab.loc["l3", "false_alarms"] == 1
    assert tab.loc["l3", "false_alarm_time_s"] == pytest.approx(0.5)
    assert np.isnan(tab.loc["l4", "delay_s"]) and not tab.loc["l4", "faulty"]
    s = summarize_detection(tab, duration_s=10.0)
    assert s["detection_rate"] == 0.5 and s["false_alarms_per_hour"] == pytest.approx(360)
    with pytest.raises(LogFormatError, match="flag_r1"):
        evaluate_detection(log, out.drop(columns=["flag_r1"]))
