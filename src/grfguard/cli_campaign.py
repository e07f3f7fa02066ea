"""``grfguard campaign run|report``: detection campaigns on Dask (see :mod:`grfguard.campaign`)."""

from __future__ import annotations

import functools
import json
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console

from grfguard.errors import GrfguardError

__all__ = ["campaign_app"]

campaign_app = typer.Typer(
    help="Detection campaigns: many simulated runs on Dask, then rates, delays, false alarms.",
    no_args_is_help=True,
)
_console = Console(stderr=True)


def _friendly(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn grfguard errors into one red line and exit code 2."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except GrfguardError as exc:
            _console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
            raise typer.Exit(2) from None

    return wrapper


@campaign_app.command("run")
@_friendly
def campaign_run(
    spec: Annotated[Path, typer.Argument(help="Campaign TOML (see campaigns/).")],
    out_dir: Annotated[Path, typer.Option("-o", "--out", help="Results folder.")],
    scheduler: Annotated[
        str | None,
        typer.Option(help="tcp://HOST:PORT of a running Dask scheduler (default: a local "
                          "cluster on 127.0.0.1)."),
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="Worker processes of the local cluster (default: CPUs).")
    ] = None,
    progress: Annotated[bool, typer.Option(help="Show the progress bar.")] = True,
) -> None:
    """Run every cell of SPEC not yet in the results folder; results stream to Parquet."""
    from grfguard.campaign import load_spec
    from grfguard.campaign.runner import run_campaign

    s = load_spec(spec)
    cells = s.cells()
    _console.print(f"campaign {s.name}: {len(cells)} cells on {len(s.walks())} walks -> {out_dir}")
    r = run_campaign(s, out_dir, scheduler=scheduler, n_workers=workers, progress=progress)
    line = {
        "cells": r.n_cells, "skipped": r.n_skipped, "computed": r.n_computed,
        "failed": r.n_failed, "walks_simulated": r.n_walks, "elapsed_s": round(r.elapsed_s, 2),
        "cells_per_min": None if r.n_computed == 0 else round(r.cells_per_min, 1),
        "scheduler": r.scheduler,
    }
    typer.echo(json.dumps(line))
    if r.n_failed:
        _console.print(f"[red]{r.n_failed} cells failed[/] (errors in {out_dir}/failed/); "
                       "run the same command again to retry them")
        raise typer.Exit(1)


@campaign_app.command("report")
@_friendly
def campaign_report(
    results: Annotated[Path, typer.Argument(help="Results folder of `campaign run`.")],
    out_dir: Annotated[Path, typer.Option("-o", "--out", help="Report folder.")],
    level: Annotated[float, typer.Option(help="Detection rate that counts as detectable.")] = 0.95,
) -> None:
    """Analyse a campaign: rates, delays, false alarms/h, curves; figures + index.html."""
    from grfguard.campaign.report import CampaignReport

    rep = CampaignReport(results, level)
    path = rep.write(out_dir)
    _console.print(f"report: {path}")
    side = rep.side_by_side
    if not side.empty:
        typer.echo(side.to_string())
