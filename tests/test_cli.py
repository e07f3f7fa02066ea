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
    missing, out = str(tmp_path / "none.parquet"), str(tmp_path / "o.parquet")
    res = runner.invoke(app, ["run", missing, "-o", out])
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


@pytest.fixture(scope="module")
def short_walk(tmp_path_factory):
    """An 8 s default walk written as Parquet by the CLI."""
    p = tmp_path_factory.mktemp("cli") / "walk.parquet"
    res = runner.invoke(app, ["simulate", "--duration", "8", "--seed", "5", "-o", str(p)])
    assert res.exit_code == 0, res.output
    return p


def test_inject_run_evaluate_report(short_walk, tmp_path) -> None:
    faulty = tmp_path / "faulty.csv"  # CSV in and out of the pipeline as well
    res = runner.invoke(app, ["inject", str(short_walk), "-o", str(faulty),
                              "--fault", "l2=offset:100@4", "--seed", "1"])
    assert res.exit_code == 0, res.output
    out = tmp_path / "out.parquet"
    res = runner.invoke(app, ["run", str(faulty), "-o", str(out)])
    assert res.exit_code == 0, res.output
    meta = load_log(out).attrs  # the run says what produced it
    assert meta["faults"] == ["l2=offset:100@4"] and meta["monitor"]["method"] == "default"
    assert meta["monitor"]["thresholds"]["swing_h"] > 0
    res = runner.invoke(app, ["evaluate", str(out), "--json"])
    assert res.exit_code == 0, res.output
    import json

    metrics = json.loads(res.stdout)
    l2 = metrics["detection"]["sensors"]["l2"]
    assert l2["detected"] and l2["kind_estimated"] == "offset" and l2["delay_s"] < 1.0
    assert all(m["false_alarms"] == 0 for m in metrics["detection"]["sensors"].values())
    assert metrics["vfs"]["ss"]["foot_rmse"] < 10.0
    html = tmp_path / "report.html"
    res = runner.invoke(app, ["report", str(out), "-o", str(html)])
    assert res.exit_code == 0, res.output
    text = html.read_text()
    assert html.stat().st_size > 1e6 and "l2" in text
    assert "swing_h" in text and "l2=offset:100@4" in text  # method, thresholds, faults


def test_paper_method_uses_the_papers_virtual_sensor(short_walk, tmp_path) -> None:
    from grfguard.config import monitor_config
    from grfguard.estimate.config import VFSConfig

    assert monitor_config(method="paper").vfs == VFSConfig.paper()
    assert monitor_config(method="paper", vfs="default").vfs == VFSConfig()
    assert monitor_config().method == "default"
    out = tmp_path / "paper.parquet"
    res = runner.invoke(app, ["run", str(short_walk), "-o", str(out), "--method", "paper"])
    assert res.exit_code == 0, res.output
    assert {"flag_r1", "eta_r1", "vfs_r1"} <= set(load_log(out).columns)


def test_calibrate_then_run_with_the_thresholds(short_walk, tmp_path) -> None:
    th = tmp_path / "th.toml"
    res = runner.invoke(app, ["calibrate", str(short_walk), "-o", str(th),
                              "--false-alarm-rate", "1"])
    assert res.exit_code == 0, res.output
    assert "[thresholds]" in th.read_text()
    out = tmp_path / "o.parquet"
    res = runner.invoke(app, ["run", str(short_walk), "-o", str(out), "--thresholds", str(th)])
    assert res.exit_code == 0, res.output


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--fault", "r9=offset:1@1"], "r9"),
        (["--fault", "r1=wobble@1"], "wobble"),
        (["--fault", "r1=offset:abc@1"], "abc"),
        ([], "no fault"),
    ],
)
def test_inject_bad_specs_are_one_line(short_walk, tmp_path, args, needle) -> None:
    res = runner.invoke(app, ["inject", str(short_walk), "-o", str(tmp_path / "x.parquet"),
                              *args])
    assert res.exit_code == 2, res.output
    assert needle in res.output and "Traceback" not in res.output


def test_run_on_log_without_encoders_names_them(short_walk, tmp_path) -> None:
    import pandas as pd

    from grfguard.io.logio import write_log

    df = pd.read_parquet(short_walk).drop(columns=["q_r_knee"])
    bad = write_log(df, tmp_path / "bad.parquet")
    res = runner.invoke(app, ["run", str(bad), "-o", str(tmp_path / "o.parquet")])
    assert res.exit_code == 2 and "q_r_knee" in res.output


def test_evaluate_on_input_log_says_run_first(short_walk) -> None:
    res = runner.invoke(app, ["evaluate", str(short_walk)])
    assert res.exit_code == 2 and "grfguard run" in res.output
