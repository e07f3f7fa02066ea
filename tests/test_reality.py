"""Reality gap simulation (issue 10): the physics and sensors follow the true robot, the
log keeps the nominal description, the truth is recorded."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from grfguard.errors import ConfigError
from grfguard.model.kinematics import quat_to_rotation
from grfguard.model.robot import SENSOR_NAMES, SURALP
from grfguard.sim import GaitConfig, simulate
from grfguard.sim.reality import REALITY_FILES, RealityGap, load_reality, vibration

STAND = GaitConfig(duration=3.0, start_time=2.0, stop_time=1.0)


def test_shipped_gap_files_load_and_round_trip():
    for name in REALITY_FILES:
        gap = load_reality(name)
        assert RealityGap.from_dict(gap.to_dict()) == gap
        assert not gap.is_exact
    assert load_reality(None) is None


@pytest.mark.parametrize(
    "kwargs, word",
    [
        ({"mass_error": 0.9}, "mass_error"),
        ({"imu_mount_rpy_deg": [20.0, 0.0, 0.0]}, "imu_mount_rpy_deg"),
        ({"imu_mount_rpy_deg": [1.0, 0.0]}, "imu_mount_rpy_deg"),
        ({"load_cell_gain_error": -0.1}, "load_cell_gain_error"),
        ({"seed": 1.5}, "seed"),
        ({"controller": "stabilised"}, "controller"),
    ],
)
def test_bad_gap_values_name_the_field(kwargs, word):
    with pytest.raises(ConfigError, match=word):
        RealityGap(**kwargs)
    with pytest.raises(ConfigError, match="unknown reality key"):
        RealityGap.from_dict({"mass_err": 0.1})


def test_resolve_is_deterministic_and_bounded():
    gap = load_reality("all")
    a, b = gap.resolve(), gap.resolve()
    assert a == b
    g = np.array(list(a["load_cell_gain"].values()))
    assert np.all(np.abs(g - 1) <= 0.05) and np.ptp(g) > 0.02
    z = np.array(list(a["load_cell_zero_n"].values()))
    assert np.all(np.abs(z) <= 10.0)
    assert RealityGap(load_cell_zero_n=10.0, seed=8).resolve() != RealityGap(
        load_cell_zero_n=10.0, seed=9).resolve()


def test_gap_reaches_physics_and_sensors_but_not_the_description():
    gap = RealityGap(mass_error=0.05, imu_mount_rpy_deg=(0.0, 2.0, 0.0),
                     load_cell_gain_error=0.05, load_cell_zero_n=10.0, seed=4)
    df = simulate(gait=STAND, seed=0, reality=gap)
    ref = simulate(gait=STAND, seed=0)
    assert df.attrs["robot"]["mass"] == SURALP.mass  # the estimator sees the model
    truth = df.attrs["reality"]
    assert truth["mass_error"] == 0.05
    stand = (df.time > 1.0) & (df.time < 1.9)
    true_total = df.loc[stand, [f"true_force_{s}" for s in SENSOR_NAMES]].sum(axis=1).mean()
    assert true_total == pytest.approx(1.05 * SURALP.weight, rel=0.005)
    # load cells read gain * f + zero
    for s in SENSOR_NAMES:
        pred = truth["load_cell_gain"][s] * df[f"true_force_{s}"] + truth["load_cell_zero_n"][s]
        assert np.std(df[f"force_{s}"] - pred) < 3.0
    # the IMU frame is rotated by 2 deg in pitch relative to the exact sensor
    q = df[[f"imu_quat_{a}" for a in "wxyz"]].to_numpy()
    q0 = ref[[f"imu_quat_{a}" for a in "wxyz"]].to_numpy()
    R = np.einsum("tji,tjk->tik", quat_to_rotation(q0), quat_to_rotation(q))
    pitch = np.degrees(np.arcsin(R[:, 0, 2]))
    assert np.median(pitch) == pytest.approx(2.0, abs=0.05)


def test_vibration_band_rms_follows_the_icub_table():
    n = 20000
    cref = np.ones((n, 2))
    cref[::1000, 0] = 0
    v = vibration(n, cref, 1000.0, seed=1)
    assert np.sqrt(np.mean(v[:, 2] ** 2)) == pytest.approx(
        np.sqrt(0.16**2 + 0.27**2 + 0.51**2 + 1.22**2 + 0.67**2), rel=0.1)
    assert np.allclose(v, vibration(n, cref, 1000.0, seed=1))


def _single_support_cop_x(df, side: str) -> float:
    """Mean x of a stance sole's true centre of pressure from the sole centre [m], over
    planned single support."""
    other = "l" if side == "r" else "r"
    ss = (df[f"contact_ref_{side}"] > 0.5) & (df[f"contact_ref_{other}"] < 0.5)
    return float((df[f"true_cop_{side}_x"] - df[f"true_sole_{side}_x"])[ss].mean())


def test_balanced_controller_walks_the_true_body_over_the_soles():
    """A trunk CoM 3 cm forward: planned on the description (open loop) the soles' centres
    of pressure sit centimetres forward; planned on the true body they stay near the
    soles' centres. The log's description and the resolved gap say which it was."""
    gait = GaitConfig(duration=6.0)
    com = (0.03, 0.0, 0.0)
    open_loop = simulate(gait=gait, seed=0, reality=RealityGap(trunk_com_offset_m=com))
    balanced = simulate(gait=gait, seed=0,
                        reality=RealityGap(trunk_com_offset_m=com, controller="balanced"))
    for side in "rl":
        assert _single_support_cop_x(open_loop, side) > 0.015
        assert abs(_single_support_cop_x(balanced, side)) < 0.005
    assert balanced.attrs["reality"]["controller"] == "balanced"
    assert balanced.attrs["robot"] == open_loop.attrs["robot"]
    assert balanced.attrs["gait"] == open_loop.attrs["gait"]
    assert not np.array_equal(balanced["q_r_hip_pitch"], open_loop["q_r_hip_pitch"])


def test_balanced_controller_changes_nothing_without_a_body_gap():
    """Sensor gaps alone leave the true body equal to the description: both controllers
    give the same log, bit for bit."""
    gap = RealityGap(load_cell_gain_error=0.05, imu_mount_rpy_deg=(1.0, 0.0, 0.0), seed=3)
    a = simulate(gait=STAND, seed=0, reality=gap)
    b = simulate(gait=STAND, seed=0, reality=dataclasses.replace(gap, controller="balanced"))
    assert a.equals(b)
    assert RealityGap(controller="balanced").is_exact


def test_cli_simulate_controller_option(tmp_path):
    """``grfguard simulate --reality GAP --controller balanced`` records the controller;
    ``--controller`` without a gap, a bad value and ``--reality`` on a described robot are
    refused with a message that says what to do."""
    from typer.testing import CliRunner

    from grfguard.cli import app
    from grfguard.io.logio import read_log

    out = tmp_path / "bal.parquet"
    run = CliRunner().invoke
    res = run(app, ["simulate", "-o", str(out), "--duration", "3", "--reality", "com_x",
                    "--controller", "balanced"])
    assert res.exit_code == 0, res.output
    assert read_log(out).attrs["reality"]["controller"] == "balanced"
    for args, words in (
        (["--controller", "balanced"], "needs a reality gap"),
        (["--reality", "com_x", "--controller", "closed"], "reality.controller"),
        (["--robot", "g1", "--reality", "com_x"], "SURALP-type robots only"),
    ):
        res = run(app, ["simulate", "-o", str(tmp_path / "x.parquet"), "--duration", "3",
                        *args])
        assert res.exit_code != 0 and words in res.output, res.output
        assert not (tmp_path / "x.parquet").exists()
