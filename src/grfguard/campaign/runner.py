"""Run a campaign on ``dask.distributed``: a local cluster by default, or any scheduler.

One task per fault-free walk (simulated once, kept in the cluster's memory while cells
need it) and one task per cell depending on its walk. The client writes each cell's
result as it finishes (:class:`~grfguard.campaign.store.ResultStore`, atomic and
idempotent by cell id); cells already on disk are not submitted again. A worker that
dies is replaced (the local cluster's nanny restarts it) and the scheduler reruns what
it held: its running cells and any walk it kept; the client still receives exactly one
result per cell (``distributed.scheduler.allowed-failures`` bounds the reruns).
"""

from __future__ import annotations

import math
import os
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from grfguard.campaign.spec import CampaignSpec, Cell
from grfguard.campaign.store import ResultStore
from grfguard.errors import ConfigError, GrfguardError

__all__ = ["RunSummary", "run_campaign", "local_cluster", "cells_table"]


@dataclass(frozen=True)
class RunSummary:
    """What a campaign run did.

    Attributes:
        n_cells: Cells in the spec.
        n_skipped: Cells already done before this run (not recomputed).
        n_computed: Cells computed and written by this run.
        n_failed: Cells that failed in this run (see ``RESULTS/failed/``).
        n_walks: Walks simulated by this run.
        elapsed_s: Wall time of the run [s] (cluster start included).
        compute_s: Wall time from the first submission to the last result [s].
        scheduler: Address of the scheduler used ("" when nothing was computed).
    """

    n_cells: int
    n_skipped: int
    n_computed: int
    n_failed: int
    n_walks: int
    elapsed_s: float
    compute_s: float
    scheduler: str

    @property
    def cells_per_min(self) -> float:
        """Computed cells per minute of compute wall time."""
        return 60.0 * self.n_computed / self.compute_s if self.compute_s > 0 else math.nan


def cells_table(cells: list[Cell]) -> pd.DataFrame:
    """One row per cell: id, walk, method, kind, size, sensor, onset, scale, group."""
    return pd.DataFrame(
        {
            "cell_id": [c.cell_id for c in cells],
            "walk_id": [c.walk.walk_id for c in cells],
            "group": [c.group for c in cells],
            "method": [c.method for c in cells],
            "kind": [c.kind for c in cells],
            "size": [float(c.size) for c in cells],
            "sensor": [c.sensor for c in cells],
            "onset_s": [float(c.onset_s) for c in cells],
            "end_s": [float(c.end_s) for c in cells],
            "threshold_scale": [float(c.threshold_scale) for c in cells],
            "seed": [int(c.walk.seed) for c in cells],
        }
    )


def local_cluster(n_workers: int | None = None) -> Any:
    """A ``LocalCluster`` of single-threaded worker processes that listens on 127.0.0.1 only
    (scheduler, its HTTP server, workers and nannies, on free ports)."""
    from distributed import LocalCluster

    n = n_workers if n_workers is not None else max(1, os.cpu_count() or 1)
    if n < 1:
        raise ConfigError(f"campaign: workers = {n} must be >= 1")
    return LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address="127.0.0.1:0",  # the scheduler's HTTP server: localhost too
        silence_logs=40,
    )


def _progress_bar(enabled: bool) -> Any:
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("done  [red]{task.fields[failed]} failed"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        disable=not enabled,
    )


def run_campaign(
    spec: CampaignSpec,
    out_dir: str | Path,
    scheduler: str | None = None,
    n_workers: int | None = None,
    client: Any = None,
    progress: bool = True,
    retries: int = 1,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> RunSummary:
    """Run every cell of ``spec`` not yet in ``out_dir``; results stream to disk.

    Args:
        spec: The parsed campaign.
        out_dir: Results folder (see :mod:`grfguard.campaign.store`).
        scheduler: ``tcp://HOST:PORT`` of a running Dask scheduler; None starts a local
            cluster on this machine (``n_workers`` processes, 127.0.0.1 only).
        n_workers: Worker processes of the local cluster (default: the CPU count).
        client: An existing ``distributed.Client`` (overrides ``scheduler``).
        progress: Show a progress bar (cells done, failed, ETA) on stderr.
        retries: Extra attempts of a cell whose code raised (worker deaths are
            retried by the scheduler regardless).
        on_result: Called with every result row after it is written.

    Returns:
        A :class:`RunSummary`.
    """
    t0 = time.perf_counter()
    cells = spec.cells()
    store = ResultStore(out_dir)
    store.prepare(spec.text, cells_table(cells))
    done = store.done_ids()
    todo = [c for c in cells if c.cell_id not in done]
    if not todo:
        return RunSummary(len(cells), len(cells), 0, 0, 0, time.perf_counter() - t0, 0.0, "")

    # compile (or load) the kernels once here, before the workers run cells: local workers
    # would otherwise all compile them at the same time on a fresh install (~35 s each)
    from grfguard.kernels import warm_up

    warm_up()
    client, own_cluster = _connect(client, scheduler, n_workers)
    try:
        address = str(client.scheduler.address)
        t1 = time.perf_counter()
        sub = _submit(client, todo, retries)
        with _progress_bar(progress) as bar:
            task = bar.add_task(spec.name, total=len(todo), failed=0)
            n_ok, n_failed = _collect(
                sub, store, on_result, lambda nf: bar.update(task, advance=1, failed=nf))
        t2 = time.perf_counter()
        n_workers_seen = len(client.scheduler_info().get("workers", {}))
        summary = RunSummary(len(cells), len(cells) - len(todo), n_ok, n_failed,
                             len(sub.walk_order), t2 - t0, t2 - t1, address)
        store.log_run({**asdict(summary), "cells_per_min": summary.cells_per_min,
                       "workers": n_workers_seen, "campaign": spec.name,
                       "load_avg_1min": os.getloadavg()[0],
                       "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())})
        return summary
    finally:
        if own_cluster is not None:
            client.close()
            own_cluster.close()
        elif scheduler is not None:
            client.close()


def _connect(client: Any, scheduler: str | None, n_workers: int | None) -> tuple[Any, Any]:
    """The Dask client to use and the local cluster started for it (None if not ours)."""
    from distributed import Client

    own_cluster = None
    if client is None:
        if scheduler is not None:
            try:
                client = Client(scheduler, timeout="20s")
            except OSError as exc:
                raise GrfguardError(
                    f"campaign: cannot reach the Dask scheduler {scheduler!r} ({exc}); start "
                    "one with `dask scheduler` and `dask worker ADDRESS`, or leave out "
                    "--scheduler for a local cluster"
                ) from None
        else:
            own_cluster = local_cluster(n_workers)
            client = Client(own_cluster)
    return client, own_cluster


@dataclass
class _Submitted:
    """Futures of one run: a walk future per walk, a cell future per cell."""

    walk_futs: dict[str, Any]
    walk_order: list[str]
    futs: dict[str, Any]
    by_key: dict[str, Cell]
    remaining: dict[str, int]


def _submit(client: Any, todo: list[Cell], retries: int) -> _Submitted:
    """Submit each walk once (in first-use order, earlier walks first) and every cell."""
    from grfguard.campaign.work import run_cell, simulate_walk

    walks: dict[str, Any] = {}
    order: list[str] = []
    for c in todo:
        if c.walk.walk_id not in walks:
            walks[c.walk.walk_id] = c.walk
            order.append(c.walk.walk_id)
    rank = {wid: i for i, wid in enumerate(order)}
    remaining = {wid: 0 for wid in order}
    walk_futs = {
        wid: client.submit(simulate_walk, walks[wid], key=f"walk-{wid}",
                           priority=-rank[wid], retries=retries, pure=False)
        for wid in order
    }
    futs = {}
    by_key = {}
    for c in todo:
        wid = c.walk.walk_id
        f = client.submit(run_cell, c, walk_futs[wid], key=f"cell-{c.cell_id}",
                          priority=-rank[wid], retries=retries, pure=False)
        futs[f.key] = f
        by_key[f.key] = c
        remaining[wid] += 1
    return _Submitted(walk_futs, order, futs, by_key, remaining)


def _collect(sub: _Submitted, store: ResultStore,
             on_result: Callable[[dict[str, Any]], None] | None,
             advance: Callable[[int], Any]) -> tuple[int, int]:
    """Write every cell's result (or failure) as it completes, release finished walks;
    returns (cells ok, cells failed)."""
    from distributed import as_completed

    n_ok = n_failed = 0
    for fut in as_completed(list(sub.futs.values())):
        c = sub.by_key[fut.key]
        if fut.status == "finished":
            row = fut.result()
            store.write(row)
            n_ok += 1
            if on_result is not None:
                on_result(row)
        else:
            exc = fut.exception()
            tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
            store.write_failure(c.cell_id, tb)
            n_failed += 1
        del sub.futs[fut.key]
        fut.release()
        wid = c.walk.walk_id
        sub.remaining[wid] -= 1
        if sub.remaining[wid] == 0:
            sub.walk_futs.pop(wid).release()
        advance(n_failed)
    return n_ok, n_failed
