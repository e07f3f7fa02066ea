"""``grfguard run``'s fast command-line path (grfguard._fastargs): the same keyword
arguments as typer for plain command lines, typer for everything else."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

import grfguard.cli as cli
from grfguard._fastargs import parse

PLAIN = [
    ["walk.parquet", "-o", "out.parquet"],
    ["-o", "out.parquet", "walk.parquet"],
    ["walk.parquet", "--output", "out.parquet", "--no-unit-check", "--no-compiled"],
    ["walk.parquet", "--output=out.parquet", "--time-order=drop", "--unit-check"],
    ["walk.parquet", "-o", "o.parquet", "--config", "c.toml", "--thresholds", "t.toml",
     "--method", "paper", "--vfs", "default", "--robot", "g1", "--map", "m.toml"],
    ["-o", "o.parquet", "--", "-walk.parquet"],
    ["walk dir/log [1].parquet", "-o", "-"],
]
TYPER_ONLY = [
    [],
    ["--help"],
    ["walk.parquet"],  # -o missing: typer's message
    ["walk.parquet", "-o"],
    ["walk.parquet", "-o", ""],
    ["walk.parquet", "-o", "a", "-o", "b"],  # repeated
    ["walk.parquet", "-o", "a", "--unit-check=yes"],
    ["walk.parquet", "-o", "a", "--bogus"],
    ["a.parquet", "b.parquet", "-o", "c"],
    ["walk.parquet", "-oout.parquet"],
]


@pytest.fixture
def calls(monkeypatch):
    got: list[dict] = []

    def fake_run_log(log, output, **kw):
        got.append({"log": log, "output": output, **kw})
        return 0

    monkeypatch.setattr(cli, "run_log", fake_run_log)
    monkeypatch.setattr(cli, "_FAST_EXIT", False)
    return got


@pytest.mark.parametrize("argv", PLAIN)
def test_plain_command_lines_give_typers_arguments(argv, calls) -> None:
    res = CliRunner().invoke(cli.app, ["run", *argv])
    assert res.exit_code == 0, res.output
    assert cli._run_fast(["run", *argv]) is True
    assert len(calls) == 2
    assert calls[1] == calls[0]
    assert all(type(calls[1][k]) is type(calls[0][k]) for k in calls[0])


@pytest.mark.parametrize("argv", TYPER_ONLY)
def test_anything_else_is_left_to_typer(argv, calls) -> None:
    assert parse(cli.run, argv) is None
    assert cli._run_fast(["run", *argv]) is False
    assert calls == []


def test_other_commands_are_left_to_typer(calls) -> None:
    assert cli._run_fast(["simulate", "-o", "x.parquet"]) is False
    assert cli._run_fast([]) is False


def test_console_script_error_is_one_line_exit_2(tmp_path) -> None:
    """Through the fast path (a plain command line): the same one-line error and exit
    code 2 as through typer."""
    exe = Path(sys.executable).parent / "grfguard"
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "grfguard.cli"]
    res = subprocess.run([*cmd, "run", str(tmp_path / "missing.parquet"), "-o",
                          str(tmp_path / "out.parquet")], capture_output=True, text=True,
                         env={**os.environ, "COLUMNS": "200"}, timeout=120)
    assert res.returncode == 2, res.stderr
    assert "does not exist" in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "out.parquet").exists()
