"""The ``grfguard`` command line.

Every command reads and writes logs of the contract (:mod:`grfguard.io.schema`). Errors
on bad input are reported in one line saying what to fix, with exit code 2.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from grfguard._cliutil import ROBOT_HELP
from grfguard._term import cli_friendly as _friendly
from grfguard._term import cli_say as _say
from grfguard._term import console, out  # noqa: F401  (re-exported for cli_* modules)
from grfguard._term import progress as _progress
from grfguard.cli_campaign import campaign_app

app = typer.Typer(
    name="grfguard",
    help="Virtual force sensor, fault detection and recovery for walking-robot foot sensors.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
app.add_typer(campaign_app, name="campaign")

# -------------------------------------------------------------------------- simulate
@app.command()
@_friendly
def simulate(
    output: Annotated[Path, typer.Option("-o", "--output", help="Log to write (.parquet/.csv).")],
    duration: Annotated[float, typer.Option(help="Walk duration [s].")] = 60.0,
    step_length: Annotated[float | None, typer.Option(help="Step length [m].")] = None,
    step_period: Annotated[float | None, typer.Option(help="Step period [s].")] = None,
    double_support: Annotated[
        float | None, typer.Option(help="Double-support fraction of a step (0-1).")
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the sensor noise.")] = 0,
    robot: Annotated[
        str | None, typer.Option(help=ROBOT_HELP + " Also talos, g1. Default SURALP.")
    ] = None,
    noise: Annotated[str, typer.Option(help="Sensor noise: default or none.")] = "default",
    rate: Annotated[float, typer.Option(help="Log sample rate [Hz] (divides 1000).")] = 1000.0,
    reality: Annotated[
        str | None, typer.Option(help="Reality gap TOML or shipped name (grfguard.sim.reality).")
    ] = None,
    controller: Annotated[
        str | None, typer.Option(
            help="With --reality: the simulated walking controller, open_loop (plan on "
            "the description) or balanced (plan on the true body); default: the gap "
            "file's `controller` (open_loop when absent).")
    ] = None,
    calibration_poses: Annotated[
        bool, typer.Option(
            "--calibration-poses",
            help="Start with the calibration routine (each sole tilted onto each corner "
            "in turn, about 30 s of standing), then walk: data for `calibrate --model`.")
    ] = False,
) -> None:
    """Simulate a MuJoCo walk and write its log (with ground truth)."""
    from grfguard._cliutil import check_seed, resolve_robot
    from grfguard.cli_robot import is_described_robot, simulate_described
    from grfguard.io.logio import write_log
    from grfguard.io.safe import check_output
    from grfguard.model.robot import SURALP
    from grfguard.sim import GaitConfig, NoiseConfig
    from grfguard.sim import simulate as _simulate
    from grfguard.sim.reality import load_reality

    check_seed(seed)
    gap = _reality_with_controller(load_reality(reality), controller)
    if robot is not None and str(robot) == "suralp":
        robot = None  # SURALP keeps its dedicated simulation
    _check_memory_for(duration)
    if is_described_robot(robot):
        _suralp_type_only(robot, {"--calibration-poses": calibration_poses,
                                  "--reality": gap is not None})
        check_output(output, inputs=[robot], what="log")
        simulate_described(robot, output, duration, step_length, step_period,
                           double_support, seed, noise, rate)
        return
    rob = resolve_robot(robot) or SURALP
    check_output(output, inputs=[robot], what="log")
    gait_kw: dict[str, Any] = {"duration": duration, "calibration_poses": calibration_poses}
    if step_length is not None:
        gait_kw["step_length"] = step_length
    if step_period is not None:
        gait_kw["step_period"] = step_period
    if double_support is not None:
        gait_kw["double_support"] = double_support
    gait = GaitConfig(**gait_kw)
    noise_cfg = _noise_config(noise, NoiseConfig)
    with _progress("simulate") as prog:
        task = prog.add_task("simulate", total=1.0)
        df = _simulate(
            robot=rob,
            gait=gait,
            noise=noise_cfg,
            seed=seed,
            progress=lambda f: prog.update(task, completed=f),
            reality=gap,
        )
    if rate != 1000.0:
        from grfguard.sim.wholebody import decimate

        df = decimate(df, rate)
    write_log(df, output)
    _say(f"wrote {output}: {len(df)} samples, {df['time'].iloc[-1]:.2f} s, robot {rob.name}")


def _suralp_type_only(robot: str, given: dict[str, bool]) -> None:
    """Refuse the options (``{flag: given}``) that only SURALP-type robots support."""
    from grfguard.errors import ConfigError

    for flag, on in given.items():
        if on:
            raise ConfigError(
                f"{flag} is implemented for SURALP-type robots only, not for {robot}; "
                "simulate it without the option")


def _reality_with_controller(gap: Any, controller: str | None) -> Any:
    """``gap`` with its walking controller replaced by ``controller`` (when given)."""
    if controller is None:
        return gap
    import dataclasses

    from grfguard.errors import ConfigError

    if gap is None:
        raise ConfigError(
            f"--controller {controller} needs a reality gap (--reality NAME or FILE): "
            "without one the robot is its description and is always planned on it")
    return dataclasses.replace(gap, controller=controller)


#: Peak memory of a simulation per simulated second [bytes] (measured: 132 MB for a 40 s
#: SURALP walk at 1 kHz, 73 columns; described robots have more columns, hence the margin).
_SIM_BYTES_PER_S = 5_000_000


def _check_memory_for(duration: float) -> None:
    """Refuse a ``--duration`` whose simulation cannot fit in the available memory."""
    from grfguard._memory import available_memory
    from grfguard.errors import ConfigError

    if not isinstance(duration, (int, float)) or not duration > 0 or duration != duration:
        raise ConfigError(f"--duration = {duration!r} s must be a positive number of seconds")
    avail = available_memory()
    need = duration * _SIM_BYTES_PER_S
    if avail is not None and need > 0.8 * avail:
        max_s = 0.8 * avail / _SIM_BYTES_PER_S
        raise ConfigError(
            f"--duration {duration:g} s needs about {need / 1e9:.1f} GB of memory, more than "
            f"the {avail / 1e9:.1f} GB available; simulate at most about {max_s:.0f} s at a "
            "time (and concatenate, or stream with the Python API)"
        )


def _noise_config(name: str, cls: Any) -> Any:
    from grfguard.errors import ConfigError

    if name == "default":
        return cls()
    if name == "none":
        return cls.none()
    raise ConfigError(f"--noise must be 'default' or 'none', got {name!r}")


# ---------------------------------------------------------------------------- inject
@app.command()
@_friendly
def inject(
    log: Annotated[Path, typer.Argument(help="Input log.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Faulty log to write.")],
    fault: Annotated[
        list[str] | None,
        typer.Option(
            "--fault",
            help="SENSOR=KIND[:VALUE]@START[-END], e.g. r2=offset:100@5 (repeatable).",
        ),
    ] = None,
    faults_file: Annotated[
        Path | None, typer.Option("--faults", help="TOML file with [[fault]] tables.")
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of random fault kinds (noise, spikes).")] = 0,
) -> None:
    """Inject sensor faults into a log (writes fault_<s> / fault_kind_<s> truth columns)."""
    from grfguard._cliutil import check_faults_toml, check_seed
    from grfguard.errors import FaultSpecError
    from grfguard.faults import inject_faults, parse_fault_spec
    from grfguard.io.logio import read_log, write_log
    from grfguard.io.safe import check_output

    check_seed(seed)
    specs = [parse_fault_spec(s) for s in (fault or [])]
    if faults_file is not None:
        specs.extend(check_faults_toml(faults_file))
    if not specs:
        raise FaultSpecError("no fault given: use --fault r2=offset:100@5 or --faults FILE.toml")
    check_output(output, inputs=[log, faults_file], what="faulty log")
    df = read_log(log)
    t0, t1 = float(df["time"].iloc[0]), float(df["time"].iloc[-1])
    for spec in specs:
        if spec.start > t1 or spec.end <= t0:
            raise FaultSpecError(
                f"fault {spec.sensor}={spec.kind}@{spec.start:g}: it lies outside the log "
                f"{log} (time {t0:g} s to {t1:g} s), so nothing would be injected; give a "
                "start time inside the log"
            )
    faulty = inject_faults(df, specs, seed=seed)
    write_log(faulty, output)
    _say(f"wrote {output} with {len(specs)} fault(s)")


# ------------------------------------------------------------------------------- run
@app.command()
@_friendly
def run(
    log: Annotated[Path, typer.Argument(help="Input log (Parquet or CSV) or ROS bag.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Output log to write.")],
    config: Annotated[Path | None, typer.Option(help="Monitor/VFS config TOML.")] = None,
    thresholds: Annotated[Path | None, typer.Option(help="Thresholds TOML (calibrate).")] = None,
    method: Annotated[
        str | None,
        typer.Option(help="Detection method: default, or paper (eq. 24-33 as published)."),
    ] = None,
    vfs: Annotated[
        str | None,
        typer.Option(
            help="Virtual sensor: default or paper (eq. 1-23). Default: the paper's with "
            "--method paper, ours otherwise."
        ),
    ] = None,
    robot: Annotated[
        str | None,
        typer.Option(help=ROBOT_HELP + " Required when the log has no grfguard metadata."),
    ] = None,
    time_order: Annotated[
        str,
        typer.Option(
            "--time-order",
            help="Rows whose time does not advance: strict (error), drop (drop them) or "
            "split (run each increasing segment on its own).",
        ),
    ] = "strict",
    unit_check: Annotated[
        bool,
        typer.Option(
            "--unit-check/--no-unit-check",
            help="Refuse forces in kN/kgf, acceleration in g, angles in degrees, a sensor "
            "on the wrong foot.",
        ),
    ] = True,
    topics_map: Annotated[
        Path | None, typer.Option("--map", help="Topics map TOML for a ROS bag input.")
    ] = None,
    compiled: Annotated[
        bool,
        typer.Option("--compiled/--no-compiled",
                     help="Compiled virtual force sensor (numba) or the pure-Python one."),
    ] = True,
) -> None:
    """Run the virtual force sensor, fault detection and recovery over a log."""
    n = run_log(log, output, config=config, thresholds=thresholds, method=method, vfs=vfs,
                robot=robot, time_order=time_order, unit_check=unit_check,
                topics_map=topics_map, compiled=compiled)
    _say(f"wrote {output}: {n} samples")
    global _FAST_EXIT
    _FAST_EXIT = True


def run_log(
    log: Path,
    output: Path,
    *,
    config: Path | None = None,
    thresholds: Path | None = None,
    method: str | None = None,
    vfs: str | None = None,
    robot: str | None = None,
    time_order: str = "strict",
    unit_check: bool = True,
    topics_map: Path | None = None,
    compiled: bool = True,
    phase: Any = None,
) -> int:
    """``grfguard run`` without the command line: read ``log``, run the monitor, write
    ``output``; returns the number of samples written. ``phase(name)`` (optional) is
    called at the end of each step (``read``, ``checks``, ``monitor_setup``, then
    ``kernel_setup`` and ``run_write`` when the compiled monitor writes a Parquet output
    block by block, otherwise ``monitor_run`` and ``write``:
    ``benchmarks/bench_run_cli.py`` times them)."""
    from grfguard._cliutil import check_log_plausible, robot_for_log
    from grfguard.io.anyread import is_bag, read_any
    from grfguard.io.logio import write_log
    from grfguard.io.runwriter import copy_only_columns
    from grfguard.io.safe import check_output

    mark = phase if phase is not None else (lambda name: None)
    rob = _check_run_inputs(config, thresholds, robot)
    check_output(output, inputs=[log, config, thresholds, robot, topics_map], what="output log")
    if rob is not None and hasattr(rob, "sensing"):  # a described robot: its columns
        from grfguard.io.robot_schema import load_robot_log

        df = load_robot_log(log, robot)
        df.attrs.setdefault("robot_name", robot)
        df.attrs.setdefault("sensing", rob.sensing)
        source, skip = None, []
    else:
        # a Parquet log read as it is: its columns may be copied into the output unchanged,
        # its ground truth without being read (io/runwriter.py)
        plain = time_order == "strict" and log.suffix.lower() != ".csv" and not is_bag(log)
        source = log if plain else None
        skip = (copy_only_columns(log) if plain and thresholds is None and compiled
                and output.suffix.lower() != ".csv" else [])
        names = _parquet_names(log) if skip else []
        # the block writer's input as numpy columns (no pandas: io/columns.py)
        lite = plain and compiled and thresholds is None and output.suffix.lower() != ".csv"
        df = read_any(log, topics_map, time_order=time_order, copy=False,  # read-only columns
                      columns=[c for c in names if c not in skip] if skip else None,
                      frame=not lite)
    mark("read")
    robot_for_log(df, rob, str(log))
    if unit_check:
        check_log_plausible(df, rob, str(log))
    mark("checks")
    # (the kernels load from numba's cache without its linear algebra, hence without
    # scipy.linalg: grfguard.kernels._jit._lean_cache_class)
    result = _run_segments(df, config=config, thresholds=thresholds, method=method,
                           vfs=vfs, compiled=compiled, mark=mark, output=output,
                           source=source, skipped=skip)
    if isinstance(result, int):  # written block by block (io/runwriter.py)
        mark("run_write")
        return result
    mark("monitor_run")
    del df
    write_log(result, output)
    mark("write")
    return len(result)


def _check_run_inputs(config: Path | None, thresholds: Path | None, robot: str | None) -> Any:
    """Validate the config, thresholds and robot files before any work (errors name the
    file and key); returns the ``--robot`` robot or None."""
    from grfguard._cliutil import check_monitor_toml, check_thresholds_toml, resolve_robot

    if config is not None:
        check_monitor_toml(config)
    if thresholds is not None:
        check_thresholds_toml(thresholds)
    return resolve_robot(robot)


def _parquet_names(path: Path) -> list[str]:
    import pyarrow.parquet as pq

    return list(pq.read_schema(path).names)


def _run_segments(df: Any, **kw: Any) -> Any:
    """Run the monitor; a log read with ``time_order="split"`` runs segment by segment."""
    from grfguard.io.logio import SEGMENT

    if SEGMENT not in df.columns:
        return _run_monitor(df, **kw)
    import pandas as pd

    kw["output"] = kw["source"] = None  # (a split log: read whole, nothing skipped)
    from grfguard.io.columns import as_frame

    df = as_frame(df)
    parts = []
    for k, part in df.groupby(SEGMENT, sort=False):
        seg = part.drop(columns=[SEGMENT]).reset_index(drop=True)
        seg.attrs = dict(df.attrs)
        res = _run_monitor(seg, **kw)
        res[SEGMENT] = k
        parts.append(res)
    out = pd.concat(parts, ignore_index=True)
    out.attrs = dict(parts[0].attrs)
    return out


def _run_monitor(
    df: Any,
    config: Path | None,
    thresholds: Path | None,
    method: str | None,
    vfs: str | None = None,
    compiled: bool = True,
    mark: Any = None,
    output: Path | None = None,
    source: Path | None = None,
    skipped: list[str] | None = None,
) -> Any:
    """The monitor's output frame of ``df``; with ``output`` (a Parquet path) the compiled
    monitor writes it there block by block and the number of rows is returned instead
    (:func:`grfguard.io.runwriter.write_run`; the frame when it runs the Python stages).
    ``source``: the Parquet file ``df`` was read from as it is (its unchanged columns are
    then copied into ``output``), or None; ``skipped``: columns of ``source`` that
    ``df`` was read without (copied by the writer, else read now)."""
    from grfguard.config import monitor_config
    from grfguard.detect.monitor import Monitor
    from grfguard.estimate.described import is_described, run_described
    from grfguard.io.columns import as_frame
    from grfguard.io.runwriter import restore_columns

    batch = output is not None and output.suffix.lower() != ".csv"
    if not batch or thresholds is not None or is_described(df):
        df = as_frame(df)  # (only the block writer reads numpy columns)
    if skipped and (is_described(df) or thresholds is not None or not batch):
        df = restore_columns(df, source, skipped)  # (only the block writer copies them)
    if is_described(df) and df.attrs.get("sensing") == "ft":  # channel thresholds (issue 9)
        return run_described(df, channels=thresholds)
    cfg = monitor_config(config, thresholds, method, vfs)
    if not compiled:
        cfg = cfg.replace(compiled=False)
    if is_described(df):  # Talos, G1, a robot TOML: the batch wrench estimator (issue 9)
        return run_described(df, cfg)
    if thresholds is not None:  # model corrections of `calibrate --model` (issue 10)
        from grfguard.cli_calib import corrected_log_and_config

        df, cfg = corrected_log_and_config(df, thresholds, cfg)
        source = None  # (corrected sensor columns)
    mon = Monitor.for_log(df, config=cfg, warm=not batch)  # batch: loads only its loop
    if mark is not None:
        mark("monitor_setup")
    if batch:
        from grfguard.io.runwriter import write_run

        n = write_run(mon, df, output, phase=mark, source=source, partial=bool(skipped))
        if n is not None:
            return n
        df = as_frame(df)
    if skipped:  # the frame path writes every column
        df = restore_columns(df, source, skipped)
    return mon.run(df)


# -------------------------------------------------------------------------- evaluate
@app.command()
@_friendly
def evaluate(
    log: Annotated[Path, typer.Argument(help="Output of `grfguard run`.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    robot: Annotated[
        str | None, typer.Option(help=ROBOT_HELP + " Overrides the log's metadata.")
    ] = None,
) -> None:
    """Accuracy of the virtual sensor and of detection against the truth columns."""
    from grfguard._cliutil import resolve_robot
    from grfguard.errors import LogFormatError
    from grfguard.evaluate.frame import evaluate_frame
    from grfguard.io.logio import read_log

    rob = resolve_robot(robot)
    df = read_log(log)
    if rob is not None:
        df.attrs["robot"] = rob.to_dict()
    result = evaluate_frame(df)
    if "vfs" not in result and "detection" not in result:
        raise LogFormatError(
            f"{log} has no truth to evaluate against (no true_force_* or fault_* columns): "
            "evaluate needs a simulated log (`grfguard simulate`, `grfguard inject`) run "
            "through `grfguard run`"
        )
    if as_json:
        from grfguard.io.logio import to_jsonable

        out.print_json(json.dumps(to_jsonable(result)))
    else:
        _print_evaluation(result)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def _print_evaluation(result: dict[str, Any]) -> None:
    for section, data in result.items():
        if not isinstance(data, dict):
            continue
        from rich.table import Table  # lazy: only `evaluate` prints tables

        table = Table(title=section)
        table.add_column("metric")
        table.add_column("value")
        for key, value in _flatten(data).items():
            table.add_row(key, _fmt(value))
        out.print(table)


def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            flat.update(_flatten(v, key + "."))
        else:
            flat[key] = v
    return flat


# ------------------------------------------------------------------------- calibrate
@app.command()
@_friendly
def calibrate(
    logs: Annotated[list[Path], typer.Argument(help="Fault-free logs.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Thresholds TOML to write.")],
    false_alarm_rate: Annotated[
        float, typer.Option("--false-alarm-rate", help="Target false alarms per hour.")
    ] = 0.1,
    config: Annotated[Path | None, typer.Option(help="Monitor config TOML.")] = None,
    robot: Annotated[
        str | None,
        typer.Option(help=ROBOT_HELP + " Required when a log has no grfguard metadata."),
    ] = None,
    model: Annotated[
        bool, typer.Option("--model", help="Also fit model corrections (grfguard.calib).")
    ] = False,
    mass: Annotated[float | None, typer.Option(help="Measured robot mass [kg].")] = None,
) -> None:
    """Calibrate detection thresholds from fault-free logs for a false-alarm rate."""
    from grfguard._cliutil import robot_for_log
    from grfguard.detect.calibrate import calibrate_thresholds
    from grfguard.io.logio import load_log
    from grfguard.io.safe import atomic_write_text, check_output

    rob = _check_run_inputs(config, None, robot)
    check_output(output, inputs=[*logs, config, robot], what="thresholds TOML")
    frames = [load_log(p) for p in logs]
    for p, f in zip(logs, frames, strict=True):
        robot_for_log(f, rob, str(p))
    from grfguard.estimate.described import calibration_frames, ft_channel_calibration

    ft_toml = ft_channel_calibration(frames, false_alarm_rate)  # ankle F/T robot (issue 9)
    if ft_toml is not None:
        atomic_write_text(output, ft_toml, what="channel thresholds TOML")
        _say(f"wrote channel thresholds {output} from {len(frames)} log(s)")
        return
    frames = calibration_frames(frames)  # described robots: their virtual sensor (issue 9)
    total_s = sum(float(f["time"].iloc[-1] - f["time"].iloc[0]) for f in frames)
    if total_s < _MIN_CALIBRATION_S:
        from grfguard.errors import LogFormatError

        raise LogFormatError(
            f"calibration needs at least {_MIN_CALIBRATION_S:g} s of fault-free walking, the "
            f"{len(frames)} log(s) hold {total_s:.3g} s; give longer logs (minutes give "
            "thresholds that hold)"
        )
    corr_toml = ""
    if model:  # model corrections first, thresholds on the corrected data (issue 10)
        from grfguard.cli_calib import fit_model_corrections

        frames, corr_toml, config = fit_model_corrections(frames, mass, console, config,
                                                          false_alarm_rate)
    summary: dict = {}
    th = calibrate_thresholds(frames, false_alarm_rate_per_hour=false_alarm_rate, config=config,
                              summary=summary)
    atomic_write_text(output, th.to_toml() + corr_toml, what="thresholds TOML")
    _say(f"wrote {output} from {len(frames)} log(s)")
    if not model:
        _tilt_hint(frames[0], rob, summary)


def _tilt_hint(log: Any, rob: Any, summary: dict) -> None:
    """Say so when the per-corner residuals carry a steady centre-of-pressure shift
    (:func:`grfguard.detect.calibrate.tilt_hint`: common to the logs, ``calibrate
    --model`` fits it; changing from log to log, it does not)."""
    from grfguard._cliutil import _robot_of_log
    from grfguard.detect.calibrate import tilt_hint

    robot = rob if rob is not None else _robot_of_log(log)
    if "corner_median" not in summary or not hasattr(robot, "sensor_positions_in_foot"):
        return
    text = tilt_hint(summary, robot.sensor_positions_in_foot())
    if text is not None:
        _say(f"hint: {text}")


#: Least fault-free walking `grfguard calibrate` accepts [s] (a few steps).
_MIN_CALIBRATION_S = 5.0


# ---------------------------------------------------------------------------- report
@app.command()
@_friendly
def report(
    log: Annotated[Path, typer.Argument(help="Output of `grfguard run`.")],
    output: Annotated[
        Path | None, typer.Option("-o", "--output", help="HTML report to write.")
    ] = None,
    png: Annotated[Path | None, typer.Option("--png", help="Directory for PNG figures.")] = None,
    robot: Annotated[
        str | None, typer.Option(help=ROBOT_HELP + " Overrides the log's metadata.")
    ] = None,
) -> None:
    """Write a standalone HTML report and/or PNG figures of a run."""
    from grfguard._cliutil import resolve_robot
    from grfguard.errors import ConfigError, LogFormatError
    from grfguard.io.logio import read_log
    from grfguard.io.safe import check_output, check_output_dir

    if output is None and png is None:
        raise ConfigError("nothing to write: give -o REPORT.html and/or --png DIR")
    rob = resolve_robot(robot)
    if output is not None:
        check_output(output, inputs=[log], what="HTML report")
    if png is not None:
        check_output_dir(png, inputs=[log], what="figure directory", option="--png")
    df = read_log(log)  # the report computes the metrics of `grfguard evaluate` itself
    if rob is not None:
        df.attrs["robot"] = rob.to_dict()
    if not any(str(c).startswith("flag_") for c in df.columns):
        raise LogFormatError(
            f"{log} has no flag_* columns: it was never run; report the output of "
            f"`grfguard run {log} -o OUT.parquet`"
        )
    if output is not None:
        from grfguard.report.html import write_html_report

        write_html_report(df, output)  # atomic (io.safe)
        _say(f"wrote {output}")
    if png is not None:
        from grfguard.report.figures import write_png_figures

        paths = _write_pngs_atomically(df, png, write_png_figures)
        _say(f"wrote {len(paths)} figure(s) to {png}")


def _write_pngs_atomically(df: Any, png: Path, writer: Any) -> list[Path]:
    """Render every figure in a temporary directory next to ``png``, then move each one
    in with an atomic rename: a failure leaves no partial PNG and the old figures intact."""
    import os
    import tempfile

    from grfguard.errors import OutputError

    png.mkdir(parents=True, exist_ok=True)
    try:
        with tempfile.TemporaryDirectory(dir=png.parent, prefix=f".{png.name}.") as tmp:
            rendered = writer(df, Path(tmp))
            done = []
            for p in rendered:
                os.replace(p, png / Path(p).name)
                done.append(png / Path(p).name)
            return done
    except OSError as exc:
        raise OutputError(
            f"--png {png}: could not write the figures ({exc.strerror or exc}); the "
            "previous figures, if any, are unchanged"
        ) from None


# ------------------------------------------------------------------------------ demo
@app.command()
@_friendly
def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Output directory.")] = Path("out"),
    duration: Annotated[float, typer.Option(help="Walk duration [s].")] = 60.0,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
) -> None:
    """The paper's scenario end to end: simulate, inject, run both methods, evaluate, report."""
    from grfguard._cliutil import check_seed
    from grfguard.demo import run_demo
    from grfguard.io.safe import check_output_dir

    check_seed(seed)
    check_output_dir(out_dir)
    run_demo(out_dir, duration=duration, seed=seed, console=console, out=out)


# --------------------------------------------------------------------------- warm-up
@app.command("warm-up")
@_friendly
def warm_up_cmd(
    robot: Annotated[
        str | None, typer.Option(
            help="Also a described robot's monitor (talos, g1, or a description file): "
            "one warms them all.")
    ] = None,
) -> None:
    """Compile (or load from the on-disk cache) the compiled kernels now, so that no log
    and no live sample pays for it (run it once after installing; 3-5 minutes from an
    empty cache, half a minute more with --robot)."""
    from grfguard.kernels import warm_described, warm_up

    _say(f"monitor kernels ready in {warm_up():.1f} s")
    if robot is not None:
        _say(f"described-robot kernels ready in {warm_described(robot):.1f} s ({robot})")


from grfguard.cli_robot import decimate_cmd, robot_app  # noqa: E402

app.add_typer(robot_app, name="robot")
app.command("decimate")(decimate_cmd)

from grfguard.cli_ros import register as _register_ros  # noqa: E402

_register_ros(app, _friendly)


def main() -> None:
    """Console-script entry point."""
    import os

    # no command renders with MuJoCo: skip its OpenGL bindings (glfw, about 60 ms of
    # start-up); an explicit MUJOCO_GL is kept
    os.environ.setdefault("MUJOCO_GL", "disable")
    if sys.argv[1:2] == ["run"]:  # a batch over a whole log
        from grfguard._memory import batch_process

        batch_process()
    try:
        if not _run_fast(sys.argv[1:]):
            app()
    except SystemExit as exc:
        if not (_FAST_EXIT and exc.code in (0, None)):
            raise
    if _FAST_EXIT:  # `run` wrote its output (renamed into place): nothing left to do
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)  # skips the interpreter's teardown (about 0.3 s after a long log)


def _run_fast(argv: list[str]) -> bool:
    """``grfguard run`` on a plain command line (:func:`grfguard._fastargs.parse`: the
    same keyword arguments as typer gives, without typer's per-option pydantic
    validators, about 0.1 s of the command); False (nothing done) for any other command
    line, which typer then parses and reports as always."""
    if not argv or argv[0] != "run":
        return False
    from grfguard._fastargs import parse

    kw = parse(run, argv[1:])
    if kw is None:
        return False
    try:
        run(**kw)  # errors: one line and typer.Exit(2), as under typer
    except typer.Exit as exc:
        raise SystemExit(exc.exit_code) from None
    return True


#: Set by a command whose work is complete (outputs closed and renamed): :func:`main` then
#: ends the process without the interpreter's teardown (freeing every module and
#: array; nothing left to flush). Only :func:`main` (the console script) acts on it;
#: commands called in-process (tests, ``CliRunner``) are not affected.
_FAST_EXIT = False


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
