"""Standing still is covered (issue 10): additive faults that start during an 8 s stand
in double support are detected there by the default monitor, the faulty sensor isolated
and recovered while standing, the flag held across the return to walking; 60 s of
fault-free standing raise nothing. Real simulated stands (MuJoCo), default Monitor."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.detect import Monitor
from grfguard.detect.standing import StandingConfig, StandingDetector, StandingStage
from grfguard.errors import ConfigError
from grfguard.estimate.vfs import with_vfs_columns
from grfguard.evaluate.detection import evaluate_detection
from grfguard.faults.inject import inject_faults
from grfguard.model.robot import SENSOR_NAMES, SURALP
from grfguard.sim import GaitConfig, simulate

FLAGS = [f"flag_{s}" for s in SENSOR_NAMES]
ONSET_S = 3.0
STAND_END_S = 8.0


@pytest.fixture(scope="module")
def stand() -> pd.DataFrame:
    """8 s of standing in double support, then 4 s of walking (seed 3), VFS columns."""
    return with_vfs_columns(simulate(gait=GaitConfig(duration=12.0, start_time=8.0,
                                                     stop_time=1.0), seed=3))


@pytest.mark.parametrize(
    "spec, sensor, within_s, kind",
    [
        ("r1=offset:100@3", "r1", 1.0, "offset"),   # right foot, front
        ("l4=offset:-100@3", "l4", 1.0, "offset"),  # left foot, rear
        ("l2=drift:15@3", "l2", 2.0, "drift"),      # left foot, front
        ("r3=gain:1.5@3", "r3", 1.0, "offset"),     # right foot, rear: a still load
    ],
)
def test_fault_during_a_stand_is_detected_there(stand, spec, sensor, within_s, kind):
    faulty = inject_faults(stand, [spec], seed=0)
    out = Monitor.for_log(faulty).run(faulty)
    tab = evaluate_detection(out)
    assert tab.loc[sensor, "detected"]
    assert 0.0 < tab.loc[sensor, "delay_s"] <= within_s, tab.loc[sensor, "delay_s"]
    assert tab["false_alarms"].sum() == 0, tab["false_alarms"]
    t = out["time"].to_numpy()
    others = [f"flag_{s}" for s in SENSOR_NAMES if s != sensor]
    assert not out[others].to_numpy().any()
    standing = (t > ONSET_S + within_s) & (t < STAND_END_S)
    assert (out.loc[standing, f"kind_{sensor}"] == kind).all()
    # held without a gap across the return to walking, until the end of the log
    assert out[f"flag_{sensor}"].to_numpy()[t >= ONSET_S + within_s].all()
    # recovered while standing: the reading minus the deviation from the baseline
    err = (out[f"recovered_{sensor}"] - out[f"true_force_{sensor}"]).to_numpy()[standing]
    raw = (out[f"force_{sensor}"] - out[f"true_force_{sensor}"]).to_numpy()[standing]
    assert np.sqrt(np.mean(err ** 2)) < 10.0 < np.sqrt(np.mean(raw ** 2))


def test_without_the_standing_layer_the_fault_waits_for_walking(stand):
    """The layer is what detects it: switched off, the +100 N offset is only seen after
    walking resumes (the per-sensor tests need a swing or single support)."""
    faulty = inject_faults(stand, ["r1=offset:100@3"], seed=0)
    out = Monitor.for_log(faulty, standing=False).run(faulty)
    d = evaluate_detection(out).loc["r1", "delay_s"]
    # after walking resumes (the system layer arms the stance tests after 2 s of single
    # support: with 2 steps after the stand, not within this log at all)
    assert not d <= STAND_END_S - ONSET_S, d


def test_streaming_equals_batch_during_a_stand(stand):
    part = stand[stand["time"] < 4.0]
    part.attrs = stand.attrs
    faulty = inject_faults(part, ["l3=offset:100@3"], seed=0)
    mon = Monitor.for_log(faulty)
    batch = mon.run(faulty)
    mon.reset()
    rows = [mon.update(r) for r in faulty.to_dict("records")]
    cols = FLAGS + ["kind_l3", "eta_l3", "recovered_l3"]
    stream = pd.DataFrame(rows, index=faulty.index)[cols]
    assert batch["flag_l3"].any()
    pd.testing.assert_frame_equal(stream, batch[cols], check_dtype=False)


def test_no_false_alarm_over_60_s_of_standing():
    log = with_vfs_columns(simulate(gait=GaitConfig(duration=60.0, start_time=30.0,
                                                    stop_time=30.0), seed=4))
    out = Monitor.for_log(log).run(log)
    assert not out[FLAGS].to_numpy().any(), out[FLAGS].sum()


def test_standing_detector_resets_when_a_foot_lifts_or_the_weight_shifts():
    det = StandingDetector(0.001, StandingConfig(settle_s=0.01, baseline_s=0.01),
                           weight_n=SURALP.weight)
    for _ in range(30):
        det.update([100.0] * 8, [100.0] * 8, True, [400.0, 400.0])
    assert det.standing
    det.update([100.0] * 8, [100.0] * 8, False)
    assert not det.standing and not det.flags.any()
    flags, _ = det.update([np.nan] * 8, [100.0] * 8, True)  # bad sample: no exception
    assert not flags.any()
    for _ in range(30):
        det.update([100.0] * 8, [100.0] * 8, True, [400.0, 400.0])
    assert det.standing
    det.update([100.0] * 8, [100.0] * 8, True, [350.0, 450.0])  # 50 N > 3 % of 800 N
    assert not det.standing
    with pytest.raises(ConfigError, match="threshold_fraction"):
        StandingConfig(threshold_fraction=-1.0)
    with pytest.raises(ConfigError, match="weight_n"):
        StandingDetector(0.001, weight_n=0.0)


def test_standing_threshold_is_a_fraction_of_the_weight(g1) -> None:
    """15 N on SURALP exactly (its outputs unchanged), the same fraction of G1's weight;
    the monitor gives the layer its robot's weight."""
    assert StandingDetector(0.001, weight_n=SURALP.weight).threshold_n == 15.0
    light = StandingStage(0.001, weight_n=g1.mass * 9.81).detector.threshold_n
    assert light == pytest.approx(15.0 * g1.mass * 9.81 / SURALP.weight)
    assert 4.0 < light < 5.0


def test_stage_holds_the_flag_until_both_feet_have_swung():
    """After the stand, the flag is held until the sensor's foot and then the other foot
    have completed a swing (the per-sensor tests had their chance), unless the detector
    flags the sensor first."""
    stage = StandingStage(0.001, StandingConfig(settle_s=0.01, baseline_s=0.01),
                          weight_n=SURALP.weight)
    x, v = [100.0] * 8, [100.0] * 8
    both, right_up, left_up = [1.0, 1.0], [0.0, 1.0], [1.0, 0.0]

    def step(xx, c):
        out = {f: False for f in FLAGS}
        stage.step(xx, v, [400.0, 400.0], c, [np.nan, np.nan], out)
        return out

    for _ in range(40):
        step(x, both)
    faulty = [150.0] + x[1:]  # r1 +50 N
    for _ in range(100):
        out = step(faulty, both)
    assert out["flag_r1"] and out["kind_r1"] == "offset"
    assert out["eta_r1"] == pytest.approx(50.0, abs=1.0)
    assert out["recovered_r1"] == pytest.approx(100.0, abs=1.0)
    for phase in (left_up, both, right_up, both, left_up):
        # the left foot swings first (no release: the right foot has not swung yet),
        # then the right foot, then the left foot lifts again
        assert step(faulty, phase)["flag_r1"]
    out = step(faulty, both)  # the left foot's swing after the right foot's ends
    assert not out["flag_r1"] and "kind_r1" not in out  # the detector's row is left as is


def test_held_flag_tells_a_gain_from_an_offset_once_the_load_changes():
    """Standing, a gain of 1.5 on a 100 N load reads like a +50 N offset; when the foot
    lifts, a gain reads zero (an offset would read 50 N): the held flag becomes a gain and
    the recovered force follows the load."""
    stage = StandingStage(0.001, StandingConfig(settle_s=0.01, baseline_s=0.01),
                          weight_n=SURALP.weight)
    v = [100.0] * 8

    def step(xx, vv, c):
        out = {f: False for f in FLAGS}
        stage.step(xx, vv, [400.0, 400.0], c, [np.nan, np.nan], out)
        return out

    for _ in range(40):
        step([100.0] * 8, v, [1.0, 1.0])
    for _ in range(100):
        out = step([150.0] + [100.0] * 7, v, [1.0, 1.0])
    assert out["kind_r1"] == "offset" and out["eta_r1"] == pytest.approx(50.0, abs=1.0)
    swing = [0.0] * 4 + [200.0] * 4
    for _ in range(200):  # the right foot swings: true load 0, the reading 1.5 x 0
        out = step(swing, swing, [0.0, 1.0])
    assert out["kind_r1"] == "gain" and out["recovered_r1"] == pytest.approx(0.0, abs=1.0)
    for _ in range(50):  # back on the ground with 120 N: the gain is removed
        out = step([180.0] + [100.0] * 7, [120.0] + [100.0] * 7, [1.0, 1.0])
    assert out["recovered_r1"] == pytest.approx(120.0, abs=1.0)
