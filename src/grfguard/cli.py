"""The ``grfguard`` command line.

Every command reads and writes logs of the contract (:mod:`grfguard.io.schema`). Errors
on bad input are reported in one line saying what to fix, with exit code 2.
"""

from __future__ import annotations

import functools
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from grfguard.errors import GrfguardError

app = typer.Typer(
    name="grfguard",
    help="Virtual force sensor, fault detection and recovery for walking-robot foot sensors.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

console = Console(stderr=True)
out = Console()


def _friendly(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn grfguard errors into one red line and exit code 2."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except GrfguardError as exc:
            console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
            raise typer.Exit(2) from None

    return wrapper


def _progress(description: str) -> Progress:
    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>5.1f}%"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=False,
        disable=not console.is_terminal,
    )


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
        Path | None, typer.Option(help="suralp (default), talos, g1, or a robot TOML.")
    ] = None,
    noise: Annotated[str, typer.Option(help="Sensor noise: default or none.")] = "default",
    rate: Annotated[float, typer.Option(help="Log sample rate [Hz] (divides 1000).")] = 1000.0,
) -> None:
    """Simulate a MuJoCo walk and write its log (with ground truth)."""
    from grfguard.cli_robot import is_described_robot, simulate_described

    if robot is not None and str(robot) == "suralp":
        robot = None  # SURALP keeps its dedicated simulation
    if is_described_robot(robot):
        simulate_described(robot, output, duration, step_length, step_period,
                           double_support, seed, noise, rate)
        return
    from grfguard.io.logio import write_log
    from grfguard.model.robot import load_robot
    from grfguard.sim import GaitConfig, NoiseConfig
    from grfguard.sim import simulate as _simulate

    rob = load_robot(robot)
    gait_kw: dict[str, Any] = {"duration": duration}
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
        )
    if rate != 1000.0:
        from grfguard.sim.wholebody import decimate

        df = decimate(df, rate)
    write_log(df, output)
    console.print(
        f"wrote {output}: {len(df)} samples, {df['time'].iloc[-1]:.2f} s, robot {rob.name}"
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
    from grfguard.errors import FaultSpecError
    from grfguard.faults import inject_faults, load_faults, parse_fault_spec
    from grfguard.io.logio import read_log, write_log

    specs = [parse_fault_spec(s) for s in (fault or [])]
    if faults_file is not None:
        specs.extend(load_faults(faults_file))
    if not specs:
        raise FaultSpecError("no fault given: use --fault r2=offset:100@5 or --faults FILE.toml")
    df = read_log(log)
    faulty = inject_faults(df, specs, seed=seed)
    write_log(faulty, output)
    console.print(f"wrote {output} with {len(specs)} fault(s)")


# ------------------------------------------------------------------------------- run
@app.command()
@_friendly
def run(
    log: Annotated[Path, typer.Argument(help="Input log (Parquet or CSV).")],
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
) -> None:
    """Run the virtual force sensor, fault detection and recovery over a log."""
    from grfguard.io.logio import load_log, write_log

    df = load_log(log)
    result = _run_monitor(df, config=config, thresholds=thresholds, method=method, vfs=vfs)
    write_log(result, output)
    console.print(f"wrote {output}: {len(result)} samples")


def monitor_config(
    config: Path | None = None,
    thresholds: Path | None = None,
    method: str | None = None,
    vfs: str | None = None,
) -> Any:
    """The monitor configuration the command-line options describe.

    ``method="paper"`` means the paper as published: its observer and, unless ``vfs``
    or the config file says otherwise, its virtual sensor too.
    """
    from grfguard.detect.monitor import MonitorConfig
    from grfguard.detect.thresholds import default_thresholds, paper_vfs_thresholds
    from grfguard.errors import ConfigError
    from grfguard.estimate.config import VFSConfig

    cfg = MonitorConfig.from_toml(config) if config is not None else MonitorConfig()
    if method is not None:
        cfg = cfg.with_method(method)
    if vfs is None and method == "paper" and cfg.vfs is None:
        vfs = "paper"
    if vfs == "paper":
        cfg = cfg.replace(vfs=VFSConfig.paper())
        if thresholds is None and cfg.thresholds == default_thresholds():
            # the paper's eq. 33 thresholds come from fault-free runs of its own pipeline
            cfg = cfg.with_thresholds(paper_vfs_thresholds())
    elif vfs == "default":
        cfg = cfg.replace(vfs=VFSConfig())
    elif vfs is not None:
        raise ConfigError(f"--vfs must be 'default' or 'paper', got {vfs!r}")
    if thresholds is not None:
        cfg = cfg.with_thresholds(thresholds)
    return cfg


def _run_monitor(
    df: Any,
    config: Path | None,
    thresholds: Path | None,
    method: str | None,
    vfs: str | None = None,
) -> Any:
    from grfguard.detect.monitor import Monitor

    cfg = monitor_config(config, thresholds, method, vfs)
    return Monitor.for_log(df, config=cfg).run(df)


# -------------------------------------------------------------------------- evaluate
@app.command()
@_friendly
def evaluate(
    log: Annotated[Path, typer.Argument(help="Output of `grfguard run`.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Accuracy of the virtual sensor and of detection against the truth columns."""
    from grfguard.io.logio import read_log

    df = read_log(log)
    result = evaluate_frame(df)
    if as_json:
        from grfguard.io.logio import to_jsonable

        out.print_json(json.dumps(to_jsonable(result)))
    else:
        _print_evaluation(result)


def evaluate_frame(df: Any) -> dict[str, Any]:
    """All metrics the truth in ``df`` allows (VFS accuracy, detection)."""
    from grfguard.errors import LogFormatError

    result: dict[str, Any] = {"source": df.attrs.get("source")}
    if "vfs_r1" not in df.columns:
        raise LogFormatError(
            "the log has no vfs_* columns: evaluate the output of `grfguard run`, not its input"
        )
    if "true_force_r1" in df.columns:
        from grfguard.evaluate.vfs_metrics import evaluate_vfs

        result["vfs"] = evaluate_vfs(df)
    if "flag_r1" in df.columns and "fault_r1" in df.columns:
        result["detection"] = detection_metrics(df)
    return result


def detection_metrics(df: Any) -> dict[str, Any]:
    """Per-sensor detection metrics and their summary, as plain JSON-able dicts."""
    import math

    from grfguard.evaluate.detection import evaluate_detection, summarize_detection

    table = evaluate_detection(df)
    duration = float(df["time"].iloc[-1] - df["time"].iloc[0])

    def clean(v: Any) -> Any:
        if hasattr(v, "item"):
            v = v.item()
        if isinstance(v, float) and math.isnan(v):
            return None
        return v

    sensors = {
        str(s): {k: clean(v) for k, v in row.items()} for s, row in table.iterrows()
    }
    summary = {k: clean(v) for k, v in summarize_detection(table, duration).items()}
    return {"sensors": sensors, "summary": summary}


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def _print_evaluation(result: dict[str, Any]) -> None:
    for section, data in result.items():
        if not isinstance(data, dict):
            continue
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
) -> None:
    """Calibrate detection thresholds from fault-free logs for a false-alarm rate."""
    from grfguard.detect.monitor import calibrate_monitor
    from grfguard.io.logio import load_log

    frames = [load_log(p) for p in logs]
    th = calibrate_monitor(frames, false_alarm_rate_per_hour=false_alarm_rate, config=config)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(th.to_toml())
    console.print(f"wrote {output} from {len(frames)} log(s)")


# ---------------------------------------------------------------------------- report
@app.command()
@_friendly
def report(
    log: Annotated[Path, typer.Argument(help="Output of `grfguard run`.")],
    output: Annotated[
        Path | None, typer.Option("-o", "--output", help="HTML report to write.")
    ] = None,
    png: Annotated[Path | None, typer.Option("--png", help="Directory for PNG figures.")] = None,
) -> None:
    """Write a standalone HTML report and/or PNG figures of a run."""
    from grfguard.errors import ConfigError
    from grfguard.io.logio import read_log

    if output is None and png is None:
        raise ConfigError("nothing to write: give -o REPORT.html and/or --png DIR")
    df = read_log(log)
    metrics = _detection_metrics_or_none(df)
    if output is not None:
        from grfguard.report.html import write_html_report

        write_html_report(df, output, metrics=metrics)
        console.print(f"wrote {output}")
    if png is not None:
        from grfguard.report.figures import write_png_figures

        paths = write_png_figures(df, png, metrics=metrics)
        console.print(f"wrote {len(paths)} figure(s) to {png}")


def _detection_metrics_or_none(df: Any) -> Any:
    if "flag_r1" in df.columns and "fault_r1" in df.columns:
        return detection_metrics(df)["sensors"]
    return None


# ------------------------------------------------------------------------------ demo
@app.command()
@_friendly
def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Output directory.")] = Path("out"),
    duration: Annotated[float, typer.Option(help="Walk duration [s].")] = 60.0,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
) -> None:
    """The paper's scenario end to end: simulate, inject, run both methods, evaluate, report."""
    from grfguard.demo import run_demo

    run_demo(out_dir, duration=duration, seed=seed, console=console, out=out)


from grfguard.cli_robot import decimate_cmd, robot_app  # noqa: E402

app.add_typer(robot_app, name="robot")
app.command("decimate")(decimate_cmd)


def main() -> None:
    """Console-script entry point."""
    app()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
