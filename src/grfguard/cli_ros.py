"""ROS commands of the ``grfguard`` command line: ``import`` (bag -> log), ``export``
(results -> MCAP) and ``bag`` (log -> a realistic ROS 2 bag)."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console

__all__ = ["register"]

console = Console(stderr=True)


def _show_bag_warnings() -> None:
    """Print bag-import warnings as one yellow line each (not Python's warning format)."""
    import sys

    previous = warnings.showwarning

    def show(message: Any, category: Any, filename: str, lineno: int, file: Any = None,
             line: Any = None) -> None:
        rosbag = sys.modules.get("grfguard.io.rosbag")  # not imported: not a bag warning
        if (rosbag is not None and isinstance(category, type)
                and issubclass(category, rosbag.BagImportWarning)):
            console.print(f"[bold yellow]warning:[/] {message}", highlight=False,
                          soft_wrap=True)
        else:
            previous(message, category, filename, lineno, file, line)

    if getattr(previous, "_grfguard", False):
        return
    show._grfguard = True  # type: ignore[attr-defined]
    warnings.showwarning = show


def import_bag(
    bag: Annotated[Path, typer.Argument(help="ROS bag: rosbag2 dir, .mcap, .db3 or .bag.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Log to write (.parquet/.csv).")],
    topics_map: Annotated[
        Path | None, typer.Option("--map", help="Topics map TOML (default: the example map).")
    ] = None,
    per_message: Annotated[
        bool, typer.Option("--per-message", help="Decode message by message with rosbags "
                           "(the slow reference).")
    ] = False,
) -> None:
    """Import a ROS bag into a grfguard log (topics aligned on one time grid)."""
    from grfguard.io.logio import write_log
    from grfguard.io.rosbag import read_bag

    _show_bag_warnings()
    df = read_bag(bag, topics_map, vectorised=not per_message)
    write_log(df, output)
    info = df.attrs["ros_import"]
    console.print(
        f"wrote {output}: {len(df)} samples at {info['rate_hz']:g} Hz, "
        f"{len(info['gaps'])} gap(s); stamps: "
        + ", ".join(f"{t} {k}" for t, k in info["stamps"].items()),
        highlight=False, soft_wrap=True,
    )


def export(
    log: Annotated[Path, typer.Argument(help="Output of `grfguard run` (.parquet/.csv).")],
    output: Annotated[Path, typer.Option("-o", "--output", help="MCAP file to write.")],
    layout: Annotated[
        Path | None, typer.Option("--layout", help="Also write a Foxglove layout JSON.")
    ] = None,
    status_rate: Annotated[
        float, typer.Option("--status-rate", help="Rate of /grfguard/status [Hz].")
    ] = 10.0,
) -> None:
    """Export results as ROS 2 messages in MCAP (Foxglove, PlotJuggler)."""
    from grfguard.errors import ConfigError
    from grfguard.io.logio import read_log
    from grfguard.io.mcap_export import export_mcap

    if not (0 < status_rate <= 1000):
        raise ConfigError(f"--status-rate must be in (0, 1000] Hz, got {status_rate}")
    df = read_log(log)
    counts = export_mcap(df, output, status_rate_hz=status_rate, layout=layout)
    console.print(f"wrote {output}: {len(counts)} topics, {sum(counts.values())} messages"
                  + (f"; layout {layout}" if layout else ""))


def bag(
    log: Annotated[Path, typer.Argument(help="Log to convert (.parquet/.csv, 1 kHz).")],
    output: Annotated[
        Path, typer.Option("-o", "--output",
                           help="Bag: file.mcap, file.db3, or a directory (rosbag2).")
    ],
    storage: Annotated[
        str | None, typer.Option(help="mcap or sqlite3 (default from the suffix, else mcap).")
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the stamp jitter and latency.")] = 0,
) -> None:
    """Write a log as a realistic ROS 2 bag (IMU 1 kHz, joints 500 Hz, load cells 1 kHz)."""
    from grfguard.io.bagwrite import write_bag
    from grfguard.io.logio import load_log

    df = load_log(log)
    write_bag(df, output, storage, seed=seed)
    console.print(f"wrote {output}")


def register(app: typer.Typer, friendly: Callable[..., Any]) -> None:
    """Add the ROS commands to ``app`` (each wrapped by ``friendly`` error reporting)."""
    _show_bag_warnings()
    app.command("import")(friendly(import_bag))
    app.command("export")(friendly(export))
    app.command("bag")(friendly(bag))
