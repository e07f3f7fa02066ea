"""The grfguard command line: contract names, clear errors with exit code 2."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from grfguard.cli import app
from grfguard.io.logio import load_log
from grfguard.model.robot import SURALP, RobotConfig

runner = CliRunner()


def test_robot_show_prints_loadable_toml(tmp_path) -> None:
    res = runner.invoke(app, ["robot", "show"])
    assert res.exit_code == 0, res.output
    p = tmp_path / "r.toml"
    p.write_text(res.stdout)
    assert RobotConfig.from_toml(p) == SURALP


def test_bad_robot_file_is_one_clear_line(tmp_path) -> None:
    p = tmp_path / "r.toml"
    p.write_text(SURALP.to_toml().replace("mass = 114.0", "mass = -1.0"))
    res = runner.invoke(app, ["robot", "show", "--robot", str(p)])
    assert res.exit_code == 2
    assert "robot.mass" in res.output and "Traceback" not in res.output


def test_run_on_missing_file_fails_cleanly(tmp_path) -> None:
    res = runner.invoke(app, ["run", str(tmp_path / "none.parquet"), "-o", str(tmp_path / "o.parquet")])
    assert res.exit_code == 2
    assert "does not exist" in res.output


@pytest.mark.parametrize("noise", ["default", "none"])
def test_simulate_writes_a_valid_log(tmp_path, noise: str) -> None:
    p = tmp_path / "walk.parquet"
    res = runner.invoke(
        app, ["simulate", "--duration", "2", "--seed", "3", "--noise", noise, "-o", str(p)]
    )
    assert res.exit_code == 0, res.output
    log = load_log(p)
    assert abs(log["time"].iloc[-1] - 2.0) < 0.01
    assert log.attrs["seed"] == 3 and log.attrs["robot"]["mass"] == SURALP.mass
    same = (log["force_r1"] == log["true_force_r1"]).all()
    assert same == (noise == "none")


def test_simulate_rejects_unknown_noise(tmp_path) -> None:
    res = runner.invoke(app, ["simulate", "--noise", "loud", "-o", str(tmp_path / "x.parquet")])
    assert res.exit_code == 2 and "--noise" in res.output
