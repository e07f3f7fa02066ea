"""Physical plausibility of log values (issue 12, rows 3-4): the issue's absurd finite
values are caught, a healthy simulated walk has none, per-sample and batch checks agree,
and clamp_recovered keeps any input within the physical range."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grfguard.errors import ConfigError
from grfguard.io.plausibility import (
    PlausibilityChecker,
    PlausibleRanges,
    check_log,
    clamp_recovered,
    force_range,
    ranges_for,
)
from grfguard.model.robot import SURALP, RobotConfig
from grfguard.sim import GaitConfig, simulate

SMALL = RobotConfig(
    name="small", mass=60.0, foot_length=0.20, foot_width=0.12, upper_leg_length=0.22,
    lower_leg_length=0.21, sole_to_ankle=0.09, hip_width=0.16,
)


@pytest.fixture(scope="module")
def walks() -> dict[str, pd.DataFrame]:
    """6 s walks of SURALP (114 kg) and of a 60 kg robot, default noise."""
    return {
        "suralp": simulate(SURALP, GaitConfig(duration=6.0), seed=4),
        "small": simulate(SMALL, GaitConfig(duration=6.0), seed=4),
    }


def _glitched(df: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, list[int]]]:
    """The issue's reproduction: force_r2 = 1e30 for 11 ms in swing, 1e6 for one sample in
    stance, imu_acc_z = 1e30 for 11 ms, imu_gyro_x = 1e3 rad/s for 11 ms."""
    out = df.copy()
    swing = np.flatnonzero(out["contact_ref_r"].to_numpy() < 0.5)
    stance = np.flatnonzero(out["contact_ref_r"].to_numpy() > 0.5)
    s0 = int(swing[len(swing) // 2])
    st0 = int(stance[len(stance) // 2])
    rows = {
        "force_r2": [*range(s0, s0 + 11), st0],
        "imu_acc_z": list(range(2000, 2011)),
        "imu_gyro_x": list(range(2500, 2511)),
    }
    out.loc[s0:s0 + 10, "force_r2"] = 1e30
    out.loc[st0, "force_r2"] = 1e6
    out.loc[2000:2010, "imu_acc_z"] = 1e30
    out.loc[2500:2510, "imu_gyro_x"] = 1e3
    return out, rows


@pytest.mark.parametrize("robot_name", ["suralp", "small"])
def test_issue_values_are_caught_and_nothing_else(walks, robot_name) -> None:
    robot = SURALP if robot_name == "suralp" else SMALL
    df = walks[robot_name]
    checker = PlausibilityChecker(robot)
    clean_mask, clean_reasons = checker.check_frame(df)
    assert not clean_mask.to_numpy().any(), clean_reasons  # a healthy walk is plausible
    bad, rows = _glitched(df)
    mask, reasons = checker.check_frame(bad)
    for col in mask.columns:
        assert sorted(np.flatnonzero(mask[col].to_numpy())) == sorted(rows.get(col, [])), col
    first = min(rows["force_r2"])
    value = "1e+30" if bad.loc[first, "force_r2"] > 1e29 else "1e+06"
    assert reasons["force_r2"].startswith(f"force_r2 = {value} N is above the physical range")
    assert f"at row {first} (12 row(s) in all)" in reasons["force_r2"]
    assert "imu_gyro_x = 1000 rad/s" in reasons["imu_gyro_x"]
    # per sample (streaming) gives the same answer as the batch check
    for i in [rows["force_r2"][0], rows["force_r2"][-1], 2000, 2505, 100, 3000]:
        sample = bad.iloc[i].to_dict()
        assert set(checker.check_sample(sample)) == set(mask.columns[mask.iloc[i].to_numpy()])


def test_force_range_scales_with_the_robot() -> None:
    lo_s, hi_s = force_range(SURALP)
    lo_m, hi_m = force_range(SMALL)
    assert hi_s == pytest.approx(3 * SURALP.weight) and lo_s == pytest.approx(-0.25 * SURALP.weight)
    assert hi_m < 2500.0 < hi_s
    assert PlausibilityChecker(SURALP).check_value("force_l1", 2500.0) is None
    assert "above" in PlausibilityChecker(SMALL).check_value("force_l1", 2500.0)


def test_virtual_corners_have_a_wider_lower_bound() -> None:
    """A virtual corner force may be negative (a corner split of a CoP near the sole's
    edge), a load cell's reading may not: -0.5 m g is plausible for ``vfs_<s>`` only."""
    chk = PlausibilityChecker(SURALP)
    W = SURALP.weight
    assert chk.ranges.vfs_force_lo == pytest.approx(-3 * W)
    assert chk.check_value("vfs_r1", -0.5 * W) is None
    assert "below" in chk.check_value("force_r1", -0.5 * W)
    assert "below" in chk.check_value("recovered_r1", -0.5 * W)
    assert "below" in chk.check_value("vfs_l4", -3.5 * W)
    assert chk.check_value("vfs_total_r", -0.5 * W) is None  # not a corner: no range here


def test_units_mistakes_are_implausible(walks) -> None:
    """Joint angles in degrees; a quaternion that is not a unit quaternion."""
    df = walks["suralp"]
    checker = PlausibilityChecker(SURALP)
    deg = df.copy()
    deg["q_r_knee"] = np.degrees(deg["q_r_knee"])
    mask, reasons = checker.check_frame(deg)
    assert mask["q_r_knee"].mean() > 0.5 and "rad" in reasons["q_r_knee"]
    quat = df.copy()
    quat["imu_quat_w"] *= 0.5  # every component in [-1, 1], but not a unit quaternion
    mask, reasons = checker.check_frame(quat)
    assert mask["imu_quat_w"].all() and "norm" in reasons["imu_quat_w"]


def test_joint_limits_from_the_model_are_used() -> None:
    r = ranges_for(SURALP, joint_limits={"r_knee": (0.0, 2.5)})
    c = PlausibilityChecker(r)
    assert c.check_value("q_r_knee", -0.1) is not None
    assert c.check_value("q_l_knee", -0.1) is None  # default [-pi, pi]


@given(st.one_of(st.none(), st.text(max_size=5), st.complex_numbers(), st.booleans(),
                 st.floats(allow_nan=True, allow_infinity=True), st.integers(),
                 st.lists(st.floats(), max_size=2)))
@settings(max_examples=100, deadline=None, derandomize=True)
def test_check_value_never_raises(value) -> None:
    c = PlausibilityChecker(SURALP)
    for col in ("force_r1", "imu_acc_x", "imu_gyro_z", "q_r_knee", "imu_quat_w", "time"):
        r = c.check_value(col, value)
        assert r is None or col in r


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=1, max_size=50))
@settings(max_examples=300, deadline=None, derandomize=True)
def test_clamp_recovered_is_always_in_range(values) -> None:
    lo, hi = force_range(SURALP)
    arr = np.array(values, dtype=float)
    out = clamp_recovered(arr, SURALP)
    finite = ~np.isnan(out)
    assert np.array_equal(finite, ~np.isnan(arr))  # NaN (no estimate) stays NaN
    assert np.all((out[finite] >= lo) & (out[finite] <= hi))
    inside = np.isfinite(arr) & (arr >= lo) & (arr <= hi)
    assert np.array_equal(out[inside], arr[inside])  # plausible values untouched
    filled = clamp_recovered(arr, SURALP, nan=0.0)
    assert np.isfinite(filled).all()
    series = clamp_recovered(pd.Series(arr), SURALP)
    assert np.array_equal(series.to_numpy(), out, equal_nan=True)
    for v in values[:3]:
        sv = clamp_recovered(v, SURALP)
        assert math.isnan(sv) if math.isnan(v) else lo <= sv <= hi


def test_bad_ranges_are_config_errors() -> None:
    with pytest.raises(ConfigError, match="plausibility.gyro_max"):
        PlausibleRanges(weight_n=1000.0, gyro_max=-1.0)


@pytest.mark.parametrize("robot_name", ["suralp", "small"])
def test_whole_log_checks_find_unit_and_wiring_mistakes(walks, robot_name) -> None:
    robot = SURALP if robot_name == "suralp" else SMALL
    df = walks[robot_name]
    assert check_log(df, robot) == []  # a healthy walk raises nothing
    forces = [c for c in df.columns if c.startswith("force_")]

    def findings(d: pd.DataFrame) -> list[tuple[str, str, str]]:
        return [(i.severity, i.column, i.message) for i in check_log(d, robot)]

    for factor, unit in [(1 / 9.80665, "kgf"), (1e-3, "kN"), (0.224809, "lbf")]:
        d = df.copy()
        d[forces] *= factor
        [(sev, col, msg)] = findings(d)
        assert sev == "error" and col == "force_*" and f"look like {unit}" in msg
    d = df.copy()
    d[["imu_acc_x", "imu_acc_y", "imu_acc_z"]] /= 9.80665
    assert findings(d)[0][:2] == ("error", "imu_acc_*") and "like g" in findings(d)[0][2]
    d = df.copy()
    d["q_r_hip_pitch"] = np.degrees(d["q_r_hip_pitch"])
    assert [f[1] for f in findings(d)] == ["q_r_hip_pitch"] and "degrees" in findings(d)[0][2]
    d = df.copy()
    d[["force_r3", "force_l2"]] = d[["force_l2", "force_r3"]].to_numpy()
    assert sorted(f[1] for f in findings(d)) == ["force_l2", "force_r3"]
    assert "looks like a sensor of foot 'l'" in dict((f[1], f[2]) for f in findings(d))["force_r3"]
    d = df.copy()
    d["force_r2"] += 0.25 * robot.weight  # a large offset fault is a fault, not wiring
    assert findings(d) == []
    d = df.copy()
    q = d[["imu_quat_w", "imu_quat_x", "imu_quat_y", "imu_quat_z"]].to_numpy()
    d[["imu_quat_w", "imu_quat_x", "imu_quat_y", "imu_quat_z"]] = q[:, [1, 2, 3, 0]]
    assert findings(d)[0][:2] == ("warning", "imu_quat_*")
