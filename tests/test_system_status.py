"""System-level status (issue 10): a residual common to all sensors is blamed on the
model (``model_mismatch``), a single sensor's is not; the wiring keeps stream = batch."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.detect.system import CommonModeConfig, CommonModeMonitor, SystemAwareMonitor
from grfguard.errors import ConfigError
from grfguard.estimate.vfs import VirtualForceSensor
from grfguard.model.robot import SENSOR_NAMES, SURALP
from grfguard.sim import GaitConfig, simulate
from grfguard.sim.reality import RealityGap

GAIT = GaitConfig(duration=6.0)


def _vfs(df: pd.DataFrame) -> pd.DataFrame:
    return VirtualForceSensor.for_log(df).run(df)


def _status(df: pd.DataFrame, v: pd.DataFrame, offset: dict[str, float] | None = None):
    cm = CommonModeMonitor(SURALP, 0.001)
    x = df[[f"force_{s}" for s in SENSOR_NAMES]].to_numpy(float).copy()
    for s, val in (offset or {}).items():
        x[:, SENSOR_NAMES.index(s)] += val
    vv = v[[f"vfs_{s}" for s in SENSOR_NAMES]].to_numpy(float)
    c = df[["contact_ref_r", "contact_ref_l"]].to_numpy() > 0.5
    raised, last = 0, None
    for k in range(len(df)):
        last = cm.update(x[k], vv[k], c[k])
        raised += last.model_mismatch
    return raised / len(df), last


@pytest.fixture(scope="module")
def exact():
    df = simulate(gait=GAIT, seed=4)
    return df, _vfs(df)


def test_mass_error_raises_model_mismatch_with_the_ratio():
    df = simulate(gait=GAIT, seed=4, reality=RealityGap(mass_error=0.05))
    share, last = _status(df, _vfs(df))
    assert share > 0.35  # from 2 s of single support on (first at 1.2 s)
    assert last.model_mismatch and "total force off by +" in last.reason
    assert last.ratio == pytest.approx(0.05, abs=0.02)
    # the correction explains the common residual: corrected VFS total ~ measured total
    assert np.sum(last.correction_n) > 0


def test_exact_model_does_not_blame_the_model(exact):
    df, v = exact
    share, last = _status(df, v)
    assert share == 0.0 and last.reason == "" and not np.any(last.correction_n)


def test_bad_samples_and_config():
    cm = CommonModeMonitor(SURALP, 0.001)
    r = cm.update([np.nan] * 8, [np.nan] * 8, (True, True))
    assert not r.model_mismatch and np.all(np.isfinite(r.correction_n))
    with pytest.raises(ConfigError, match="time_constant_s"):
        CommonModeConfig(time_constant_s=0.0)


def test_wired_monitor_stream_equals_batch_and_has_the_status_column(exact):
    df = exact[0].iloc[:800].copy()
    df.attrs = dict(exact[0].attrs)
    mon = SystemAwareMonitor.for_log(df)
    batch = mon.run(df)
    assert {"model_mismatch", "model_mismatch_reason", "standing_flag_r1"} <= set(batch)
    mon.reset()
    rows = [mon.update(r) for r in df.to_dict("records")]
    stream = pd.DataFrame(rows, index=df.index)
    for c in ("model_mismatch", *(f"flag_{s}" for s in SENSOR_NAMES)):
        assert (stream[c].to_numpy() == batch[c].to_numpy()).all(), c
    assert np.allclose(stream["vfs_r1"], batch["vfs_r1"], equal_nan=True, atol=1e-6)
    assert not batch[[f"flag_{s}" for s in SENSOR_NAMES]].any().any()


def test_single_sensor_offset_is_not_blamed_on_the_model(exact):
    df, v = exact
    share, last = _status(df, v, {"r2": 100.0})
    assert share < 0.05, last.reason


def test_system_limits_are_fractions_of_the_weight() -> None:
    """The swing-zero limit and deadband and the common-mode outlier bound are fractions
    of the robot's weight: 20 N, 3 N and 20 N on SURALP (as tuned), scaled on others."""
    from grfguard.detect.system import SwingZeroLearner
    from grfguard.model.robot import RobotConfig

    z, cm = SwingZeroLearner(SURALP, 0.001), CommonModeMonitor(SURALP, 0.001)
    assert z.limit_n == 20.0 and cm.outlier_n == 20.0
    assert z.deadband_n == pytest.approx(3.0, abs=1e-12)
    light = RobotConfig(mass=SURALP.mass / 4)
    assert SwingZeroLearner(light, 0.001).limit_n == pytest.approx(5.0)
    assert CommonModeMonitor(light, 0.001).outlier_n == pytest.approx(5.0)


def test_swing_zeros_are_learned_only_while_the_foot_is_in_the_air() -> None:
    """A planned swing whose foot lands early (its heel cells read load in the last part
    of the swing, as G1's do) teaches no zero: only samples whose readings, less the zeros
    learned so far, sum within ``air_fraction`` of the weight count."""
    from grfguard.detect.system import SwingZeroLearner

    z = SwingZeroLearner(SURALP, 0.001)
    zero = [4.0, -3.5, 5.0, 6.0]  # load-cell zero errors of the right sole
    swing, stance = [False, True], [0.0, 600.0]
    for k in range(1200):  # 1.2 s of planned swing; the heel lands at 0.7 s
        heel = 0.0 if k < 700 else 300.0
        x = [zero[0], zero[1], zero[2] + heel, zero[3] + heel] + [150.0] * 4
        z.update(x, stance, swing, [False] * 8)
    assert z._n[0] == pytest.approx(600.0, abs=1.0)  # 0.7 s less the 0.1 s settling
    assert z.zeros_n[:4] == pytest.approx(zero)  # the heel's load was not learned
    assert z.air_n == pytest.approx(0.05 * SURALP.weight)
