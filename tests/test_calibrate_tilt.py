"""A steady centre-of-pressure shift in the per-corner residuals (an IMU attitude error or a
trunk CoM offset on a model otherwise exact) is measured by ``calibrate_thresholds`` and
pointed out by ``grfguard calibrate``: ``calibrate --model`` would fit it."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from grfguard.cli import app
from grfguard.detect.calibrate import corner_tilt, tilt_hint
from grfguard.io.logio import write_log
from grfguard.model.robot import SURALP
from grfguard.sim import GaitConfig, simulate

runner = CliRunner()


def test_corner_tilt_recovers_a_cop_shift() -> None:
    """Medians made by a known CoP shift (plus a twist, which no shift explains) give it
    back; none give none."""
    p = SURALP.sensor_positions_in_foot()
    c = p - p.mean(axis=0)
    d = np.array([0.002, -0.003])
    pattern = c @ np.linalg.solve(c.T @ c, d)
    twist = np.array([1.0, -1.0, -1.0, 1.0]) * 0.004
    med = np.concatenate([pattern + twist, pattern - twist])
    t = corner_tilt(med, 0.01, p)
    assert np.allclose(t.cop_shift_m, d, atol=1e-12)
    assert t.share == pytest.approx(np.sqrt(np.mean(pattern ** 2)) / 0.01)
    none = corner_tilt(np.zeros(8), 0.01, p)
    assert none.share == 0.0
    # the hint: one log (cannot tell), logs that agree (fit it), logs that differ (don't)
    a, b = np.concatenate([pattern, pattern]), -0.5 * np.concatenate([pattern, pattern])
    one = tilt_hint({"corner_sigma": 0.003, "corner_median": a, "corner_median_per_log": [a]}, p)
    assert one.startswith("the load cells put each stance sole's centre of pressure 2.0 mm "
                          "forward and 3.0 mm to the right") and "several runs" in one
    same = tilt_hint({"corner_sigma": 0.003, "corner_median": a,
                      "corner_median_per_log": [a, 0.9 * a, 1.1 * a]}, p)
    assert "It is common to the 3 logs" in same and "--model` fits it" in same
    diff = tilt_hint({"corner_sigma": 0.003, "corner_median": 0.25 * a,
                      "corner_median_per_log": [a, b]}, p)
    assert "changes from log to log" in diff and "would not remove" in diff
    assert "log 2: 1.0 mm back and 1.5 mm to the left" in diff
    assert tilt_hint({"corner_sigma": 0.1, "corner_median": a,
                      "corner_median_per_log": [a]}, p) is None


@pytest.mark.parametrize(("seed", "hint"), [(3, True), (4, False)])
def test_calibrate_points_out_the_imu_attitude_error(tmp_path, seed, hint) -> None:
    """The exact model's simulated IMU carries a constant attitude error drawn per seed
    (seed 3: -4.0 mrad of roll; seed 4: -1.3 / +0.3 mrad): a roll error moves the CoM
    estimate sideways (CoM height x error, about 2.9 mm) and every stance sole's centre
    of pressure with it. ``calibrate`` says so on seed 3 and not on seed 4, never with
    ``--model`` (which fits it). One log cannot tell a constant error from a run's own;
    with seed 6's log beside it the shift is seen to change from log to log."""
    log = tmp_path / "walk.parquet"
    write_log(simulate(SURALP, GaitConfig(duration=20.0), seed=seed), log)
    res = runner.invoke(app, ["calibrate", str(log), "-o", str(tmp_path / "th.toml")])
    assert res.exit_code == 0, res.output
    out = " ".join(res.output.split())
    assert ("hint:" in out) is hint, out
    if hint:
        assert "mm to the right of where the model does" in out
        assert "Calibrate on logs of several runs to tell them apart" in out
        other = tmp_path / "other.parquet"  # seed 6: +1.3 mrad roll, +3.0 pitch
        write_log(simulate(SURALP, GaitConfig(duration=20.0), seed=6), other)
        res = runner.invoke(app, ["calibrate", str(log), str(other), "-o",
                                  str(tmp_path / "two.toml")])
        out = " ".join(res.output.split())
        assert res.exit_code == 0 and "changes from log to log" in out, out
        res = runner.invoke(app, ["calibrate", str(log), "-o", str(tmp_path / "m.toml"),
                                  "--model"])
        assert res.exit_code == 0, res.output
        assert "hint:" not in res.output
