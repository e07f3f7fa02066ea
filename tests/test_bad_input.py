"""Issue 12's bad-input table, reproduced as a user would (CLI), one test per case.

Every case must end in one clear ``error:`` line naming the file/key/row and how to fix
it, exit code 2 and no traceback, or in a correct result; inputs stay byte-identical.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import resource
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from grfguard.cli import app
from grfguard.errors import GrfguardWarning, LogFormatError, OutputError
from grfguard.io.logio import load_log, read_log, write_log
from grfguard.io.safe import atomic_open, atomic_write_text, check_output
from grfguard.model.robot import SURALP, RobotConfig
from grfguard.sim import GaitConfig, simulate

runner = CliRunner()

SMALL = RobotConfig(
    name="small", mass=60.0, foot_length=0.20, foot_width=0.12, upper_leg_length=0.22,
    lower_leg_length=0.21, sole_to_ankle=0.09, hip_width=0.16,
)


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def _one_error_line(res) -> str:
    """The run failed as a user error: exit 2, an ``error:`` line, no traceback."""
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and res.exception is None or isinstance(
        res.exception, SystemExit
    ), res.output
    lines = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, res.output
    return lines[0]


@pytest.fixture(scope="module")
def walk(tmp_path_factory) -> Path:
    """A 3 s SURALP walk (Parquet, with metadata)."""
    p = tmp_path_factory.mktemp("bad") / "walk.parquet"
    write_log(simulate(SURALP, GaitConfig(duration=3.0), seed=1), p)
    return p


@pytest.fixture(scope="module")
def small_plain_csv(tmp_path_factory) -> tuple[Path, Path]:
    """A 60 kg robot's 3 s walk as a plain CSV (no grfguard metadata) and its robot TOML."""
    d = tmp_path_factory.mktemp("plain")
    df = simulate(SMALL, GaitConfig(duration=3.0), seed=2)
    csv = d / "small.csv"
    df.to_csv(csv, index=False)  # what a user's own tools write: no metadata line
    toml = d / "small.toml"
    toml.write_text(SMALL.to_toml())
    return csv, toml


# --------------------------------------------------------------------- row 1: overwrite
@pytest.mark.parametrize(
    "cmd",
    [
        ["calibrate", "{log}", "-o", "{log}"],
        ["report", "{log}", "-o", "{log}"],
        ["run", "{log}", "-o", "{log}"],
        ["inject", "{log}", "-o", "{log}", "--fault", "r1=offset:10@1"],
        ["run", "{log}", "-o", "{alias}"],  # same file through another spelling
        ["run", "{log}", "-o", "{link}"],  # same file through a symlink
    ],
)
def test_output_equal_to_an_input_is_refused(walk, tmp_path, cmd) -> None:
    log = tmp_path / "walk.parquet"
    log.write_bytes(walk.read_bytes())
    (tmp_path / "sub").mkdir()
    alias = tmp_path / "sub" / ".." / "walk.parquet"
    link = tmp_path / "link.parquet"
    link.symlink_to(log)
    before = _digest(log)
    args = [a.format(log=log, alias=alias, link=link) for a in cmd]
    line = _one_error_line(runner.invoke(app, args))
    assert "is also an input" in line and "never overwrites" in line
    assert _digest(log) == before


def test_failed_write_leaves_the_old_file_and_no_temp(tmp_path) -> None:
    out = tmp_path / "out.csv"
    out.write_text("old content\n")
    with pytest.raises(OutputError, match="disk is full"), atomic_open(out, "w") as fh:
        fh.write("half of the new ")
        raise OSError(errno.ENOSPC, "No space left on device")
    assert out.read_text() == "old content\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]
    with pytest.raises(RuntimeError), atomic_open(out, "w") as fh:  # any failure
        fh.write("x")
        raise RuntimeError("renderer crashed")
    assert out.read_text() == "old content\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]
    atomic_write_text(out, "new\n")
    assert out.read_text() == "new\n" and len(list(tmp_path.iterdir())) == 1


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_disk_full_keeps_old_output_and_leaves_no_partial_file(walk, tmp_path, suffix) -> None:
    """A real full disk: the file-size limit (``ulimit -f``) hit while writing the output."""
    log = tmp_path / "in.parquet"
    log.write_bytes(walk.read_bytes())
    out = tmp_path / f"out{suffix}"
    out.write_bytes(b"old output")
    limit = 64 * 1024  # the run's output is megabytes

    def limit_fsize() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    proc = subprocess.run(
        [sys.executable, "-m", "grfguard.cli", "run", str(log), "-o", str(out)],
        capture_output=True, text=True, preexec_fn=limit_fsize, timeout=120,
        env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1", "COLUMNS": "200"},
    )
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "file-size limit" in proc.stderr and "nothing was changed" in proc.stderr
    assert out.read_bytes() == b"old output"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.parquet", f"out{suffix}"]
    assert log.read_bytes() == walk.read_bytes()


# ------------------------------------------------------------- row 2: robot never guessed
def test_plain_csv_without_robot_is_refused_and_robot_option_works(
    small_plain_csv, tmp_path
) -> None:
    csv, toml = small_plain_csv
    before = _digest(csv)
    out = tmp_path / "o.parquet"
    line = _one_error_line(runner.invoke(app, ["run", str(csv), "-o", str(out)]))
    assert "no grfguard robot metadata" in line and "--robot ROBOT.toml" in line
    assert not out.exists()
    res = runner.invoke(app, ["run", str(csv), "-o", str(out), "--robot", str(toml)])
    assert res.exit_code == 0, res.output
    result = load_log(out)
    assert result.attrs["robot"]["mass"] == 60.0
    # the right robot matters: as SURALP the virtual sensor is off by about 500 N
    wrong = tmp_path / "wrong.parquet"
    res = runner.invoke(app, ["run", str(csv), "-o", str(wrong), "--robot", "suralp"])
    assert res.exit_code == 0, res.output
    sensors = [c[len("true_force_"):] for c in result.columns if c.startswith("true_force_")]

    def total_error(df: pd.DataFrame) -> float:
        vfs = df[[f"vfs_{s}" for s in sensors]].sum(axis=1)
        true = df[[f"true_force_{s}" for s in sensors]].sum(axis=1)
        return float((vfs - true).abs().iloc[500:].mean())

    assert total_error(result) < 0.05 * SMALL.weight
    assert total_error(load_log(wrong)) > 0.5 * SMALL.weight
    assert _digest(csv) == before


def test_calibrate_needs_a_robot_too(small_plain_csv, tmp_path) -> None:
    csv, _ = small_plain_csv
    line = _one_error_line(runner.invoke(app, ["calibrate", str(csv), "-o",
                                               str(tmp_path / "t.toml")]))
    assert "--robot" in line


def test_unknown_robot_name(walk, tmp_path) -> None:
    line = _one_error_line(runner.invoke(app, ["run", str(walk), "-o", str(tmp_path / "o.csv"),
                                               "--robot", "atlas"]))
    assert "'atlas'" in line and "suralp" in line


# ------------------------------------------------------------------- row 7: Rich markup
def test_paths_and_fault_specs_are_never_markup(walk, tmp_path) -> None:
    weird = tmp_path / "x[" / "][bold]y.parquet"  # a path containing "[/]" and "[bold]"
    res = runner.invoke(app, ["run", str(weird), "-o", str(tmp_path / "o.parquet")])
    line = _one_error_line(res)
    assert str(weird) in line
    res = runner.invoke(app, ["inject", str(walk), "-o", str(tmp_path / "f.parquet"),
                              "--fault", "[/]=offset:1@5"])
    line = _one_error_line(res)
    assert "[/]" in line
    # and in success messages
    (tmp_path / "a[").mkdir()
    out = tmp_path / "a[" / "][bold]out.parquet"
    res = runner.invoke(app, ["inject", str(walk), "-o", str(out), "--fault", "r1=offset:1@1"])
    assert res.exit_code == 0, res.output
    assert str(out) in res.output.replace("\n", "")


def test_error_messages_keep_their_brackets(walk, tmp_path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text("[vfs]\nbogus = 1\n")
    line = _one_error_line(runner.invoke(app, ["run", str(walk), "-o", str(tmp_path / "o.csv"),
                                               "--config", str(cfg)]))
    assert "in [vfs]" in line and "'bogus'" in line and str(cfg) in line


# ---------------------------------------------------------------- row 8: truncated input
def test_truncated_csv_is_refused(walk, tmp_path) -> None:
    df = read_log(walk)
    full = tmp_path / "full.csv"
    write_log(df, full)
    data = full.read_bytes()
    cut = tmp_path / "cut.csv"
    cut.write_bytes(data[: len(data) - 300])  # cut inside the last row
    line = _one_error_line(runner.invoke(app, ["run", str(cut), "-o", str(tmp_path / "o.csv")]))
    assert "truncated" in line and str(cut) in line
    assert cut.read_bytes() == data[: len(data) - 300]
    # cut exactly at a line end: the metadata's row count notices
    at_line = data[: data.rfind(b"\n", 0, len(data) - 300) + 1]
    cut.write_bytes(at_line)
    with pytest.raises(LogFormatError, match="metadata says"):
        read_log(cut)
    # a foreign CSV (no metadata) cut inside a row: the short last row is refused
    plain = tmp_path / "plain.csv"
    df.iloc[:50].to_csv(plain, index=False)
    text = plain.read_bytes()
    plain.write_bytes(text[: len(text) - 200])
    with pytest.raises(LogFormatError, match=r"last row \(row 49\) has \d+ of \d+ fields"):
        read_log(plain)
    # a row damaged in the middle (one field lost) is not padded with NaN either
    lines = text.decode().splitlines(keepends=True)
    lines[11] = lines[11].replace(",", "", 1)
    plain.write_text("".join(lines))
    with pytest.raises(LogFormatError, match=r"row 10 \(line 12\) has \d+ of \d+ fields"):
        read_log(plain)


# --------------------------------------------------------------- row 9: one clear line
def test_unwritable_output_is_found_before_the_work(tmp_path) -> None:
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    # a 60 s simulation would take seconds: the check must come first
    for out, needle in [
        (blocker / "walk.parquet", "is a file, not a directory"),
        (tmp_path, "is a directory"),
        (Path("/proc/walk.parquet"), "cannot write"),
    ]:
        line = _one_error_line(runner.invoke(app, ["simulate", "--duration", "60", "-o",
                                                   str(out)]))
        assert needle in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt"]


def test_report_png_dir_that_is_a_file(walk, tmp_path) -> None:
    f = tmp_path / "f"
    f.write_text("x")
    line = _one_error_line(runner.invoke(app, ["report", str(walk), "--png", str(f)]))
    assert "not a directory" in line


@pytest.mark.parametrize("cmd", [["simulate", "-o", "{d}/x.parquet"],
                                 ["inject", "{log}", "-o", "{d}/x.parquet", "--fault",
                                  "r1=noise:1@1"]])
def test_negative_seed(walk, tmp_path, cmd) -> None:
    args = [a.format(d=tmp_path, log=walk) for a in cmd] + ["--seed", "-1"]
    line = _one_error_line(runner.invoke(app, args))
    assert "--seed = -1" in line and "from 0" in line


def _toml_cases(tmp_path: Path) -> list[tuple[str, Path, str]]:
    d = tmp_path / "adir"
    d.mkdir()
    binary = tmp_path / "bin.toml"
    binary.write_bytes(bytes(range(256)) * 4)
    cases = []
    for option in ("--config", "--thresholds", "--robot"):
        cases.append((option, d, "is a directory"))
        cases.append((option, binary, "not a text file"))
    for text, needle in [
        ("thresholds = 5\n", "key 'thresholds' must be a table"),
        ("monitor = 5\n", "key 'monitor' must be a table"),
        ("[vfs]\nbogus = 1\n", "unknown key(s) ['bogus'] in [vfs]"),
        ("[monitor]\nclear_s = 'soon'\n", "clear_s"),
        ("[observer]\nq = 'x'\n", "--config"),
        ("[extra]\nx = 1\n", "unknown top-level key(s) ['extra']"),
    ]:
        p = tmp_path / f"c{len(cases)}.toml"
        p.write_text(text)
        cases.append(("--config", p, needle))
    for text, needle in [("thresholds = 5\n", "key 'thresholds' must be a table"),
                         ("[thresholds]\nbogus = 1\n", "'bogus'")]:
        p = tmp_path / f"t{len(cases)}.toml"
        p.write_text(text)
        cases.append(("--thresholds", p, needle))
    for text, needle in [("robot = 5\n", "key 'robot' must be a [robot] table"),
                         ("[robot]\nbogus = 1\n", "unknown robot key(s) ['bogus']"),
                         ("[robot]\nmass = 'heavy'\n", "robot.mass must be a number")]:
        p = tmp_path / f"r{len(cases)}.toml"
        p.write_text(text)
        cases.append(("--robot", p, needle))
    return cases


def test_bad_toml_files_are_one_clear_line(walk, tmp_path) -> None:
    before = _digest(walk)
    for option, path, needle in _toml_cases(tmp_path):
        res = runner.invoke(app, ["run", str(walk), "-o", str(tmp_path / "o.parquet"),
                                  option, str(path)])
        line = _one_error_line(res)
        assert needle in line and str(path) in line, (option, path.name, line)
    assert not (tmp_path / "o.parquet").exists()
    assert _digest(walk) == before


def test_bad_faults_file(walk, tmp_path) -> None:
    f = tmp_path / "faults.toml"
    f.write_bytes(b"\x00\x01\xff")
    line = _one_error_line(runner.invoke(app, ["inject", str(walk), "-o", str(tmp_path / "x.csv"),
                                               "--faults", str(f)]))
    assert str(f) in line and "not a text file" in line


@pytest.mark.parametrize(
    ("meta", "needle"),
    [
        ("[1, 2]", "must be a JSON object"),
        ("5", "must be a JSON object"),
        ('{"robot": 5}', "metadata key 'robot' must be a JSON object"),
        ('{"robot": {"mass": -3}}', "metadata key 'robot' is not a valid robot"),
        ("{not json", "not valid JSON"),
    ],
)
def test_bad_metadata_is_one_clear_line(walk, tmp_path, meta, needle) -> None:
    df = read_log(walk).iloc[:200]
    p = tmp_path / "m.csv"
    p.write_text(f"# grfguard: {meta}\n" + df.to_csv(index=False))
    before = _digest(p)
    line = _one_error_line(runner.invoke(app, ["run", str(p), "-o", str(tmp_path / "o.csv")]))
    assert needle in line and str(p) in line
    assert _digest(p) == before


def test_parquet_metadata_not_an_object(walk, tmp_path) -> None:
    import pyarrow.parquet as pq

    table = pq.read_table(walk)
    table = table.replace_schema_metadata({b"grfguard": b"[1]"})
    p = tmp_path / "m.parquet"
    pq.write_table(table, p)
    with pytest.raises(LogFormatError, match="must be a JSON object"):
        read_log(p)


# ----------------------------------------------------------------------- row 5: time
def test_time_gap_is_reported_with_its_row(walk, tmp_path) -> None:
    df = read_log(walk)
    gap = df.drop(index=range(1000, 2000)).reset_index(drop=True)  # 1 s of rows removed
    p = tmp_path / "gap.parquet"
    write_log(gap, p)
    with pytest.warns(GrfguardWarning, match=r"time gap.* at row 1000 \(t = "):
        got = read_log(p)
    assert got.attrs["time_gaps"][0][0] == 1000
    assert got.attrs["time_gaps"][0][2] - got.attrs["time_gaps"][0][1] == pytest.approx(1.001)
    res = runner.invoke(app, ["run", str(p), "-o", str(tmp_path / "o.parquet")])
    assert res.exit_code == 0, res.output
    assert "warning:" in res.output and "row 1000" in res.output


def test_backwards_and_constant_time(walk, tmp_path) -> None:
    df = read_log(walk)
    t = df["time"].to_numpy().copy()
    back = df.copy()
    back["time"] = np.concatenate([t[:1500], t[1200:1500] - 0.0, t[1800:]])[: len(t)]
    pb = tmp_path / "back.csv"
    write_log(back, pb)
    before = _digest(pb)
    line = _one_error_line(runner.invoke(app, ["run", str(pb), "-o", str(tmp_path / "o.csv")]))
    assert "time goes backwards at row 1500" in line and "--time-order" in line
    res = runner.invoke(app, ["run", str(pb), "-o", str(tmp_path / "o.parquet"),
                              "--time-order", "split"])
    assert res.exit_code == 0, res.output
    with pytest.warns(GrfguardWarning, match="time gap"):  # the 0.3 s cut inside segment 1
        out = load_log(tmp_path / "o.parquet")  # the output reads back: time rises per segment
    assert out["segment"].max() == 1 and len(out) == len(back)
    const = df.copy()
    const.loc[2000:2299, "time"] = const.loc[2000, "time"]
    pc = tmp_path / "const.parquet"
    write_log(const, pc)
    with pytest.raises(LogFormatError, match="does not advance .* at row 2001 for 299 rows"):
        read_log(pc)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        dropped = read_log(pc, time_order="drop")
    assert len(dropped) == len(const) - 299 and dropped["time"].is_monotonic_increasing
    assert any("dropped 299 row(s)" in str(x.message) for x in w)
    assert _digest(pb) == before


def test_check_output_names_the_problem(tmp_path) -> None:
    with pytest.raises(OutputError, match="is also an input"):
        check_output(tmp_path / "a.csv", inputs=[tmp_path / "." / "a.csv"])
    assert check_output(tmp_path / "new" / "deep" / "a.csv") == tmp_path / "new" / "deep" / "a.csv"


def test_json_dump_of_warning_free_read(walk) -> None:
    """A healthy log reads without any grfguard warning (no false alarms on load)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", GrfguardWarning)
        df = read_log(walk)
    assert "time_gaps" not in df.attrs
    json.dumps(df.attrs)  # metadata stays JSON


# ---------------------------------------------------------- row 6/11: units on load
@pytest.mark.parametrize(
    ("change", "needle"),
    [
        ("kgf", "they look like kgf: multiply by 9.80665"),
        ("degrees", "degrees? convert the joint angles to rad"),
        ("g", "the acceleration looks like g"),
    ],
)
def test_unit_mistakes_are_refused_with_the_fix(walk, tmp_path, change, needle) -> None:
    df = read_log(walk)
    if change == "kgf":
        cols = [c for c in df.columns if c.startswith("force_")]
        df[cols] = df[cols] / 9.80665
    elif change == "degrees":
        cols = [c for c in df.columns if c.startswith("q_")]
        df[cols] = np.degrees(df[cols])
    else:
        cols = ["imu_acc_x", "imu_acc_y", "imu_acc_z"]
        df[cols] = df[cols] / 9.80665
    p = tmp_path / "units.csv"
    write_log(df, p)
    before = _digest(p)
    out = tmp_path / "o.parquet"
    line = _one_error_line(runner.invoke(app, ["run", str(p), "-o", str(out)]))
    assert needle in line and str(p) in line and "--no-unit-check" in line
    assert not out.exists() and _digest(p) == before
    res = runner.invoke(app, ["run", str(p), "-o", str(out), "--no-unit-check"])
    assert res.exit_code == 0, res.output


# ------------------------------------------------- row 10: no misleading exit 0 (CLI part)
def test_commands_that_need_truth_or_a_run_say_so(walk, tmp_path) -> None:
    line = _one_error_line(runner.invoke(app, ["report", str(walk), "-o",
                                               str(tmp_path / "r.html")]))
    assert "never run" in line and "grfguard run" in line
    assert not (tmp_path / "r.html").exists()
    df = read_log(walk)
    df = df.drop(columns=[c for c in df.columns if c.startswith("true_")])
    no_truth = write_log(df, tmp_path / "no_truth.parquet")
    out = tmp_path / "o.parquet"
    assert runner.invoke(app, ["run", str(no_truth), "-o", str(out)]).exit_code == 0
    line = _one_error_line(runner.invoke(app, ["evaluate", str(out)]))
    assert "no truth" in line


def test_fault_outside_the_log_is_refused(walk, tmp_path) -> None:
    out = tmp_path / "f.parquet"
    line = _one_error_line(runner.invoke(app, ["inject", str(walk), "-o", str(out),
                                               "--fault", "r1=offset:10@50"]))
    assert "outside the log" in line and "nothing would be injected" in line
    assert not out.exists()


def test_png_figures_move_in_atomically(tmp_path) -> None:
    from grfguard.cli import _write_pngs_atomically

    figs = tmp_path / "figs"
    figs.mkdir()
    (figs / "a.png").write_bytes(b"old a")

    def good(df, out):
        paths = [out / "a.png", out / "b.png"]
        for p in paths:
            p.write_bytes(b"new " + p.name.encode())
        return paths

    def dies_half_way(df, out):
        (out / "a.png").write_bytes(b"partial")
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OutputError, match="previous figures"):
        _write_pngs_atomically(None, figs, dies_half_way)
    assert (figs / "a.png").read_bytes() == b"old a"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figs"]  # no temporary directory
    assert _write_pngs_atomically(None, figs, good) == [figs / "a.png", figs / "b.png"]
    assert (figs / "a.png").read_bytes() == b"new a.png"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figs"]


@pytest.mark.parametrize(("duration", "needle"), [("1e9", "GB of memory"),
                                                   ("nan", "positive number")])
def test_simulate_duration_is_checked_against_memory(tmp_path, duration, needle) -> None:
    out = tmp_path / "w.parquet"
    line = _one_error_line(runner.invoke(app, ["simulate", "--duration", duration, "-o",
                                               str(out)]))
    assert needle in line and not out.exists()


def test_calibrate_on_a_few_samples_is_refused(walk, tmp_path) -> None:
    short = write_log(read_log(walk).iloc[:5], tmp_path / "five.parquet")
    out = tmp_path / "th.toml"
    line = _one_error_line(runner.invoke(app, ["calibrate", str(short), "-o", str(out)]))
    assert "at least 5 s" in line and not out.exists()


def test_infinite_threshold_is_never_silent(walk, tmp_path) -> None:
    th = tmp_path / "th.toml"
    th.write_text("[thresholds]\nswing_h = inf\n")
    res = runner.invoke(app, ["run", str(walk), "-o", str(tmp_path / "o.parquet"),
                              "--thresholds", str(th)])
    assert res.exit_code == 0, res.output
    assert "warning:" in res.output and "['swing_h'] = inf switch those tests off" in res.output
