"""No silent SURALP: a log or a monitor given no robot is refused with a message that says
how to give one; a log's metadata gives its own robot (one resolver,
``grfguard.estimate.described.log_robot``, for ``Monitor.for_log`` and
``grfguard.calib.robot_of``); SURALP stays usable when asked for explicitly."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from grfguard.calib import estimate_corrections, robot_of
from grfguard.detect import MonitorConfig
from grfguard.errors import ConfigError, LogFormatError
from grfguard.estimate.vfs import VirtualForceSensor
from grfguard.model.robot import SURALP, RobotConfig
from grfguard.pipeline import Monitor
from grfguard.sim import GaitConfig, NoiseConfig, simulate


@pytest.fixture(scope="module")
def walk() -> pd.DataFrame:
    """2 s SURALP walk (its metadata names the robot)."""
    return simulate(SURALP, GaitConfig(duration=2.0), NoiseConfig(), seed=3)


def _bare(df: pd.DataFrame) -> pd.DataFrame:
    out = df.copy()
    out.attrs = {}
    return out


def test_robot_of_refuses_a_log_without_robot_metadata(walk) -> None:
    with pytest.raises(LogFormatError, match=r"robot_of: the log names no robot.*robot="):
        robot_of(_bare(walk))
    assert robot_of(_bare(walk), SURALP) is SURALP  # SURALP when asked for
    assert robot_of(walk) == SURALP  # the metadata grfguard writes


def test_robot_of_reads_the_logs_own_robot() -> None:
    heavy = RobotConfig(mass=150.0, foot_length=0.3)
    log = pd.DataFrame({"time": [0.0, 0.001]})
    log.attrs["robot"] = heavy.to_dict()
    assert robot_of(log) == heavy
    log.attrs["robot"] = json.dumps(RobotConfig(mass=60.0).to_dict())  # as JSON text
    assert robot_of(log).mass == 60.0


def test_robot_of_a_g1_log_is_g1(g1) -> None:
    """A G1 log (metadata as the whole-body simulation writes it, ``robot`` holding the
    name): G1's own mass and sole, not SURALP's."""
    log = pd.DataFrame({"time": [0.0, 0.001]})
    log.attrs.update({"robot": "g1", "robot_name": "g1", "sensing": "corners"})
    rob = robot_of(log)  # no attrs["mass"]: the mass of the loaded model
    assert rob.mass == pytest.approx(g1.mass)
    assert abs(rob.mass - SURALP.mass) > 50.0
    assert rob.foot_length == pytest.approx(g1.description.feet[0].length)
    log.attrs["mass"] = 33.5  # the simulation's attrs["mass"] saves loading the model
    assert robot_of(log).mass == 33.5
    only_name = pd.DataFrame({"time": [0.0, 0.001]})
    only_name.attrs["robot"] = "g1"
    assert robot_of(only_name).mass == pytest.approx(g1.mass)


def test_robot_of_a_described_robot_dict_takes_its_sole_and_mass(g1) -> None:
    log = pd.DataFrame({"time": [0.0, 0.001]})
    log.attrs["robot"] = {**g1.description.to_dict(), "mass": 34.0}
    rob = robot_of(log)
    foot = g1.description.feet[0]
    assert (rob.mass, rob.foot_length, rob.foot_width, rob.sensor_inset) == pytest.approx(
        (34.0, foot.length, foot.width, foot.corner_inset))


def test_robot_of_a_described_robot_dict_refuses_two_different_soles(g1) -> None:
    d = g1.description.to_dict()
    d["feet"] = {**d["feet"], "l": {**d["feet"]["l"], "width": d["feet"]["l"]["width"] + 0.01}}
    log = pd.DataFrame({"time": [0.0, 0.001]})
    log.attrs["robot"] = {**d, "mass": 34.0}
    with pytest.raises(LogFormatError, match=r"one sole for both feet.*feet.r and feet.l"):
        robot_of(log)


def test_estimate_corrections_refuses_a_log_without_robot(walk) -> None:
    with pytest.raises(LogFormatError, match="names no robot"):
        estimate_corrections(_bare(walk))


def test_estimate_corrections_refuses_a_described_robot(walk) -> None:
    g1_like = walk.copy()
    g1_like.attrs = {"robot": "g1", "robot_name": "g1", "sensing": "corners", "mass": 33.0}
    with pytest.raises(LogFormatError, match=r"'g1' is described by its model file.*--model"):
        estimate_corrections(g1_like)


def test_monitor_without_robot_is_refused(walk) -> None:
    with pytest.raises(ConfigError, match=r"Monitor: no robot.*Monitor.for_log"):
        Monitor(MonitorConfig())
    assert Monitor(MonitorConfig(), robot=SURALP).robot is SURALP
    light = RobotConfig(mass=60.0)
    vfs = VirtualForceSensor(light)
    assert Monitor(MonitorConfig(), vfs).robot is light  # the virtual sensor's robot
    assert Monitor.for_log(walk).robot == SURALP
    with pytest.raises(LogFormatError, match="names no robot"):
        Monitor.for_log(_bare(walk))


def test_virtual_sensor_without_robot_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"VirtualForceSensor: no robot.*for_log"):
        VirtualForceSensor()


def test_cli_csv_without_metadata_needs_robot(walk, tmp_path) -> None:
    """A plain CSV cannot carry grfguard's metadata line: ``run`` and ``calibrate`` refuse
    it with a message naming ``--robot``, and take it with ``--robot suralp``."""
    from typer.testing import CliRunner

    from grfguard.cli import app

    csv = tmp_path / "plain.csv"
    walk.to_csv(csv, index=False)  # no '# grfguard:' line
    runner = CliRunner()
    for args in (["run", str(csv), "-o", str(tmp_path / "o.parquet")],
                 ["calibrate", str(csv), "-o", str(tmp_path / "th.toml")]):
        res = runner.invoke(app, args)
        assert res.exit_code != 0
        text = " ".join(res.output.split())
        assert "no grfguard robot metadata" in text and "--robot" in text, res.output
    out = tmp_path / "o.parquet"
    res = runner.invoke(app, ["run", str(csv), "-o", str(out), "--robot", "suralp"])
    assert res.exit_code == 0, res.output
    assert out.exists()
    res = runner.invoke(app, ["calibrate", str(csv), "-o", str(tmp_path / "th.toml"),
                              "--robot", "suralp"])
    assert "at least 5 s" in " ".join(res.output.split())  # past the robot: 2 s is short
