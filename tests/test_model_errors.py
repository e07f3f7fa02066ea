"""Issue 10: model errors that ``common_mode=True`` explains instead of flagging healthy
sensors (gyro bias learned at rest, load-cell zeros learned in swing)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.detect.system import GyroBiasLearner, SwingZeroLearner
from grfguard.model.robot import SENSOR_NAMES, SURALP
from grfguard.pipeline import Monitor
from grfguard.sim import GaitConfig, NoiseConfig, simulate
from grfguard.sim.reality import load_reality

FLAGS = [f"flag_{s}" for s in SENSOR_NAMES]


@pytest.fixture(scope="module")
def gyro_walk() -> pd.DataFrame:
    return simulate(gait=GaitConfig(duration=8.0), noise=NoiseConfig(), seed=0,
                    reality=load_reality("gyro_bias"))


def test_gyro_bias_is_learned_at_rest_and_blamed_on_the_model(gyro_walk) -> None:
    plain = Monitor.for_log(gyro_walk, common_mode=False).run(gyro_walk)
    assert plain[FLAGS].any().sum() >= 4  # without the option: healthy sensors flagged
    out = Monitor.for_log(gyro_walk, common_mode=True).run(gyro_walk)
    assert not out[FLAGS].any().any()
    assert out["model_mismatch"].iloc[-1]
    assert "gyro bias (+0.03" in out["model_mismatch_reason"].iloc[-1]
    assert not out["model_mismatch"].iloc[:100].any()  # nothing known at the start


def test_gyro_bias_streaming_equals_run(gyro_walk) -> None:
    log = gyro_walk.iloc[:3000].copy()
    log.attrs = dict(gyro_walk.attrs)
    mon = Monitor.for_log(log, common_mode=True)
    batch = mon.run(log)
    mon.reset()
    stream = pd.DataFrame([mon.update(r) for r in log.to_dict("records")], index=log.index)
    for c in [*FLAGS, "model_mismatch", "model_mismatch_reason"]:
        assert (batch[c].to_numpy() == stream[c].to_numpy()).all(), c
    np.testing.assert_allclose(batch["vfs_r1"], stream["vfs_r1"], atol=1e-6, rtol=0)


def test_swing_zeros_clear_both_feet() -> None:
    log = simulate(gait=GaitConfig(duration=6.0), noise=NoiseConfig(), seed=0,
                   reality=load_reality("zeros"))
    plain = Monitor.for_log(log, common_mode=False).run(log)
    assert plain[["flag_r1", "flag_r2", "flag_l1"]].any().all()
    out = Monitor.for_log(log, common_mode=True).run(log)
    # the swing tests of a foot wait for its zeros (the left foot's first swing at 2.2 s
    # starts before its zeros can be learned: l1 was flagged there before the arming)
    assert not out[FLAGS].any().any()
    reason = out["model_mismatch_reason"].iloc[-1]
    assert "load-cell zeros removed (r1 -10 N, r2 +" in reason and "l1 +" in reason


def test_learners_ignore_motion_and_faults() -> None:
    g = GyroBiasLearner(0.001)
    for _ in range(2000):  # moving: no learning
        b = g.update([0.5, 0.0, 0.0], [1.0, 1.0], [0.0, 0.0])
    assert b == (0.0, 0.0, 0.0)
    for _ in range(2000):  # still, below the deadband
        b = g.update([0.005, 0.0, 0.0], [1.0, 1.0], [0.0, 0.0])
    assert b == (0.0, 0.0, 0.0)
    z = SwingZeroLearner(SURALP, dt_s=0.001)
    for _ in range(2000):  # a 30 N offset in swing is a fault (beyond 20 N), not a zero
        zs = z.update([30.0, 8.0, 0.0, 0.0, 0, 0, 0, 0], [0.0, 500.0], [False, True],
                      [False] * 8)
    assert zs[0] == 0.0 and zs[1] == pytest.approx(8.0) and zs[4] == 0.0
    # 100 N: flagged at once by the swing test, left out of the in-the-air sum
    z = SwingZeroLearner(SURALP, dt_s=0.001)
    for _ in range(2000):
        zs = z.update([100.0, 8.0, 0.0, 0.0, 0, 0, 0, 0], [0.0, 500.0], [False, True],
                      [True] + [False] * 7)
    assert zs[0] == 0.0 and zs[1] == pytest.approx(8.0) and zs[4] == 0.0
    # unflagged, 108 N on the sole: the readings say the foot is not in the air
    z = SwingZeroLearner(SURALP, dt_s=0.001)
    for _ in range(2000):
        zs = z.update([100.0, 8.0, 0.0, 0.0, 0, 0, 0, 0], [0.0, 500.0], [False, True],
                      [False] * 8)
    assert not zs.any() and z.armed(0)


def test_imu_mounting_tilt_is_learned_from_the_flat_soles() -> None:
    log = simulate(gait=GaitConfig(duration=6.0), noise=NoiseConfig(), seed=0,
                   reality=load_reality("imu_pitch"))  # 2 deg in pitch
    plain = Monitor.for_log(log, common_mode=False).run(log)
    assert plain[FLAGS].any().all()  # without the option: every sensor flagged
    out = Monitor.for_log(log, common_mode=True).run(log)
    assert not out[FLAGS].any().any()
    reason = out["model_mismatch_reason"].iloc[-1]
    pitch = float(reason.split("pitch ")[1].split(")")[0])
    assert abs(pitch - 2.0) < 0.3, reason
    # the same numbers streamed (the tilt is applied row by row there)
    head = log.iloc[:1500].copy()
    head.attrs = dict(log.attrs)
    mon = Monitor.for_log(head, common_mode=True)
    batch = mon.run(head)
    mon.reset()
    stream = pd.DataFrame([mon.update(r) for r in head.to_dict("records")], index=head.index)
    assert (batch["model_mismatch_reason"] == stream["model_mismatch_reason"]).all()
    np.testing.assert_allclose(batch["vfs_r1"], stream["vfs_r1"], atol=1e-4, rtol=0)
