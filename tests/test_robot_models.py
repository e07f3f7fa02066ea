"""Described robots (Talos, G1): model loading, TOML errors, whole-body walks, logs,
virtual foot wrenches. Real URDFs from example-robot-data, real MuJoCo physics."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("mujoco")

from grfguard.errors import ConfigError, LogFormatError  # noqa: E402
from grfguard.estimate.wrench import estimate_wrenches, evaluate_wrenches  # noqa: E402
from grfguard.io.logio import load_log, write_log  # noqa: E402
from grfguard.model.description import load_description, shipped_robots  # noqa: E402
from grfguard.model.loader import load_model  # noqa: E402
from grfguard.sim.config import NoiseConfig  # noqa: E402
from grfguard.sim.wholebody import decimate, scaled_gait, simulate_robot  # noqa: E402


@pytest.fixture(scope="module")
def talos_walk(talos):
    return simulate_robot(talos, scaled_gait(talos, duration=4.0), NoiseConfig.none(), seed=1)


@pytest.fixture(scope="module")
def g1_walk(g1):
    return simulate_robot(g1, scaled_gait(g1, duration=4.0), NoiseConfig.none(), seed=1)


def test_shipped_robots_load(talos, g1) -> None:
    assert {"talos", "g1"} <= set(shipped_robots())
    assert len(talos.joint_names) == 32 and abs(talos.mass - 90.27) < 0.01
    assert len(g1.joint_names) == 29 and abs(g1.mass - 33.34) < 0.01
    for r in (talos, g1):
        assert all(len(leg) == 6 for leg in r.leg_joints)
        assert r.model.jnt_type[0] == 0  # free base added


@pytest.mark.parametrize("fixture", ["talos_walk", "g1_walk"])
def test_walk_carries_the_weight(request, fixture) -> None:
    df = request.getfixturevalue(fixture)
    robot = request.getfixturevalue(fixture.split("_")[0])
    fz = df["true_grf_r_z"] + df["true_grf_l_z"]
    assert abs(fz.mean() / (robot.mass * 9.81) - 1.0) < 0.005
    assert df["true_trunk_tilt"].max() < 5.0
    assert (df["true_contact_r"] == 0).sum() > 200  # a real step: the right foot lifted
    assert all(f"q_{j}" in df.columns for j in robot.joint_names)


def test_talos_log_has_ft_channels(talos_walk) -> None:
    for s in "rl":
        for a in ("fx", "fy", "fz", "tx", "ty", "tz"):
            assert f"ft_{s}_{a}" in talos_walk.columns
    # standing: each ankle carries about half the weight minus the foot below it
    stand = talos_walk["time"].between(0.5, 0.9)
    assert 300 < talos_walk.loc[stand, "ft_r_fz"].mean() < 450


@pytest.mark.parametrize("rate", [1000, 100])
def test_talos_virtual_ft_accuracy(talos, talos_walk, rate) -> None:
    df = talos_walk if rate == 1000 else decimate(talos_walk, rate)
    acc = evaluate_wrenches(df, estimate_wrenches(df, talos), talos)
    assert acc["n_ss"] > 50
    assert acc["foot_fz"] <= 0.5
    assert acc["ft_fz"] <= 1.0
    assert acc["ft_tx"] <= 1.0 and acc["ft_ty"] <= 1.0


def test_g1_virtual_corner_accuracy(g1, g1_walk) -> None:
    df = decimate(g1_walk, 200)
    acc = evaluate_wrenches(df, estimate_wrenches(df, g1), g1)
    assert acc["foot_fz"] <= 0.5
    assert acc["corner"] <= 3.0


def test_noisy_g1_log_roundtrip_at_100_hz(tmp_path, g1) -> None:
    df = simulate_robot(g1, scaled_gait(g1, duration=2.5), NoiseConfig(), seed=2,
                        sample_rate=100)
    assert df.attrs["sample_rate"] == 100 and np.allclose(np.diff(df["time"]), 0.01)
    path = write_log(df, tmp_path / "g1.parquet")
    back = load_log(path)  # columns checked against the G1 model, not SURALP's
    assert list(back.columns) == list(df.columns)
    bad = back.drop(columns=["q_left_knee_joint"])
    write_log(bad, tmp_path / "bad.parquet")
    with pytest.raises(LogFormatError, match="left_knee_joint"):
        load_log(tmp_path / "bad.parquet")


def _write(tmp_path, text: str):
    p = tmp_path / "robot.toml"
    p.write_text(text)
    return p


def test_wrong_body_name_is_named(tmp_path) -> None:
    d = load_description("g1")
    bad = dataclasses.replace(d, feet=(dataclasses.replace(d.feet[0], body="right_foot"),
                                       d.feet[1]))
    with pytest.raises(ConfigError, match=r"feet.r.body.*'right_foot'.*not a body"):
        load_model(bad)


def test_sole_above_ankle_is_named(tmp_path) -> None:
    d = load_description("talos")
    foot = d.feet[1]
    up = dataclasses.replace(foot, sole=dataclasses.replace(foot.sole, pos=(0.0, 0.0, 0.05)))
    with pytest.raises(ConfigError, match=r"feet.l.sole.pos.*above the ankle"):
        load_model(dataclasses.replace(d, feet=(d.feet[0], up)))


def test_bad_toml_keys_name_file_and_key(tmp_path) -> None:
    p = _write(tmp_path, 'name = "x"\nmodel = "missing.urdf"\nsensing = "ft"\n')
    with pytest.raises(ConfigError, match=r"robot.toml.*'model'.*does not exist"):
        load_description(p)
    p = _write(tmp_path, 'name = "x"\nmodel = "a.urdf"\nsensing = "strain"\n')
    with pytest.raises(ConfigError, match=r"'sensing' must be one of"):
        load_description(p)


def test_cli_robot_list_show_simulate_decimate(tmp_path) -> None:
    from typer.testing import CliRunner

    from grfguard.cli import app

    runner = CliRunner()
    res = runner.invoke(app, ["robot", "list"])
    assert res.exit_code == 0 and "talos" in res.stdout and "g1" in res.stdout
    res = runner.invoke(app, ["robot", "show", "talos"])
    assert res.exit_code == 0, res.output
    assert "joints      32" in res.stdout and "ft_r_tz" in res.stdout
    out = tmp_path / "g1.parquet"
    res = runner.invoke(app, ["simulate", "--robot", "g1", "--duration", "2", "--noise",
                              "none", "-o", str(out)])
    assert res.exit_code == 0, res.output
    log = load_log(out)
    assert log.attrs["robot_name"] == "g1" and "force_l4" in log.columns
    res = runner.invoke(app, ["decimate", str(out), "--rate", "200", "-o",
                              str(tmp_path / "g1_200.parquet")])
    assert res.exit_code == 0, res.output
    assert len(load_log(tmp_path / "g1_200.parquet")) == 400
    res = runner.invoke(app, ["decimate", str(out), "--rate", "300", "-o",
                              str(tmp_path / "x.parquet")])
    assert res.exit_code == 2 and "must divide" in res.output


def test_talos_virtual_ft_accuracy_on_noisy_log(talos) -> None:
    """Default sensor noise (IMU noise and bias, attitude error, 2^17-count encoders)."""
    df = simulate_robot(talos, scaled_gait(talos, duration=6.0), NoiseConfig(), seed=3)
    acc = evaluate_wrenches(df, estimate_wrenches(df, talos), talos)
    assert acc["foot_fz"] <= 0.5 and acc["ft_fz"] <= 1.0
    assert acc["ft_tx"] <= 1.0 and acc["ft_ty"] <= 1.0


def test_mjcf_model_suralp_described(default_walk) -> None:
    """The MJCF path: SURALP's own MJCF (its actuators, sensors and contacts replaced),
    a whole-body walk of it, and the virtual corner forces on the dedicated SURALP log."""
    r = load_model(load_description("suralp"))
    assert len(r.joint_names) == 12 and r.mass == pytest.approx(114.0)
    df = simulate_robot(r, scaled_gait(r, duration=3.0), NoiseConfig.none())
    fz = df["true_grf_r_z"] + df["true_grf_l_z"]
    assert abs(fz.mean() / (r.mass * 9.81) - 1.0) < 0.005
    log = default_walk.iloc[:6000]
    est = estimate_wrenches(log, r)
    t = log["time"].to_numpy()
    ss = ((log["contact_ref_r"] == 1) & (log["contact_ref_l"] == 0) & (t > 2.0)).to_numpy()
    err = est.ground[0, ss, 2] - log.loc[ss, [f"true_force_r{k}" for k in range(1, 5)]].sum(
        axis=1).to_numpy()
    assert np.sqrt(np.mean(err**2)) < 0.01 * 114.0 * 9.81
