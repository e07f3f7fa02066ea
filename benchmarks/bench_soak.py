"""Soak benchmark (issue 12, must-show 9): a long stream through ``Monitor.update``.

A simulated 60 s walk (SURALP, default gait and noise, seed 0) is tiled with continuous
time to the requested duration (default one hour, 3.6 M samples) and streamed row by
row through one :class:`~grfguard.pipeline.Monitor` with the virtual sensor in the
loop. Every ``--every`` samples it records the process RSS [MB] (``/proc/self/statm``),
the Python heap traced by ``tracemalloc`` (``--tracemalloc``; slows the run) and the
mean time per sample of the last window [µs]. The streamed flags, kinds and recovered
forces are kept in preallocated arrays and compared with ``Monitor.run`` on the same
log (``--no-compare`` skips this; ``run`` holds the whole log in memory).

The tile boundaries join the end of a walk to the start of the next one: the robot's
pose jumps there (as after a real gap without a time gap), which the soak also covers.

Usage:
    taskset -c 1 .venv/bin/python benchmarks/bench_soak.py [--minutes 60] [--every 60000]
        [--no-compare] [--no-write] [--progress FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import update_section  # noqa: E402

from grfguard.detect import Monitor  # noqa: E402
from grfguard.model.robot import SENSOR_NAMES  # noqa: E402
from grfguard.sim import GaitConfig, NoiseConfig, simulate  # noqa: E402

_PAGE_MB = os.sysconf("SC_PAGE_SIZE") / 1e6


def rss_mb() -> float:
    """Resident set size of this process [MB]."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * _PAGE_MB


def tiled(tile: pd.DataFrame, n: int) -> pd.DataFrame:
    """``tile`` repeated to ``n`` rows with continuous time."""
    reps = -(-n // len(tile))
    period = float(tile["time"].iloc[-1] - tile["time"].iloc[0]) + float(
        np.median(np.diff(tile["time"].to_numpy()[:100])))
    parts = []
    for r in range(reps):
        p = tile.copy()
        p["time"] = p["time"].to_numpy() + r * period
        parts.append(p)
    out = pd.concat(parts, ignore_index=True).iloc[:n]
    out.attrs = dict(tile.attrs)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--every", type=int, default=60_000, help="samples per checkpoint")
    ap.add_argument("--tracemalloc", action="store_true")
    ap.add_argument("--no-compare", action="store_true")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--progress", default=None, help="JSON file updated at checkpoints")
    a = ap.parse_args()

    tile = simulate(gait=GaitConfig(duration=60.0), noise=NoiseConfig(), seed=0)
    keep = [c for c in tile.columns if not c.startswith(("true_", "fault_"))]
    tile = tile[keep]
    tile.attrs = dict(tile.attrs)
    n_tile = len(tile)
    n = int(round(a.minutes * 60_000))
    recs = tile.to_dict("records")
    period = n_tile * 0.001
    mon = Monitor.for_log(tile)
    kinds = {k: i for i, k in enumerate(
        ("none", "offset", "drift", "frozen", "stuck", "gain", "noise", "spikes",
         "dropout", "saturation", "unknown"))}
    # preallocated and touched now, so their pages do not show up as growth later
    flags = np.empty((n, 8), dtype=bool)
    kind = np.empty((n, 8), dtype=np.int8)
    rec = np.empty((n, 8))
    for arr in (flags, kind, rec):
        arr.fill(1)
    fcols = [f"flag_{s}" for s in SENSOR_NAMES]
    kcols = [f"kind_{s}" for s in SENSOR_NAMES]
    rcols = [f"recovered_{s}" for s in SENSOR_NAMES]
    if a.tracemalloc:
        tracemalloc.start()
    checkpoints = []
    t_win = time.perf_counter()
    t0 = t_win
    for k in range(n):
        r = dict(recs[k % n_tile])
        r["time"] = r["time"] + (k // n_tile) * period
        out = mon.update(r)
        for j in range(8):
            flags[k, j] = out[fcols[j]]
            kind[k, j] = kinds.get(out[kcols[j]], -1)
            rec[k, j] = out[rcols[j]]
        if (k + 1) % a.every == 0 or k + 1 == n:
            now = time.perf_counter()
            w = (k + 1) - (checkpoints[-1]["samples"] if checkpoints else 0)
            cp = {"samples": k + 1, "stream_min": (k + 1) / 60_000,
                  "rss_mb": round(rss_mb(), 2),
                  "us_per_sample": round(1e6 * (now - t_win) / w, 1),
                  "wall_s": round(now - t0, 1)}
            if a.tracemalloc:
                cur, peak = tracemalloc.get_traced_memory()
                cp["heap_mb"] = round(cur / 1e6, 3)
            checkpoints.append(cp)
            print(json.dumps(cp), flush=True)
            if a.progress:
                Path(a.progress).write_text(json.dumps(checkpoints, indent=1))
            t_win = time.perf_counter()
    if a.tracemalloc:
        tracemalloc.stop()
    equal = None
    if not a.no_compare:
        log = tiled(tile, n)
        t1 = time.perf_counter()
        batch = Monitor.for_log(log).run(log)
        t_run = time.perf_counter() - t1
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kB on Linux
        bk = np.stack([batch[c].map(kinds).to_numpy() for c in kcols], axis=1)
        equal = {
            "flags": bool((batch[fcols].to_numpy(dtype=bool) == flags).all()),
            "kinds": bool((bk == kind).all()),
            "recovered_max_abs_diff_n": float(np.nanmax(np.abs(batch[rcols].to_numpy() - rec))),
            "run_s": round(t_run, 1),
            "peak_rss_mb": round(peak, 1),
        }
        print(json.dumps(equal), flush=True)
    rss = [c["rss_mb"] for c in checkpoints]
    us = [c["us_per_sample"] for c in checkpoints]
    half = max(1, len(rss) // 2)
    summary = {
        "samples": n, "minutes": a.minutes,
        "rss_first_mb": rss[0], "rss_last_mb": rss[-1],
        "rss_growth_second_half_mb": round(rss[-1] - rss[half - 1], 2),
        "us_per_sample_first": us[0], "us_per_sample_last": us[-1],
        "flagged_samples": int(flags.any(axis=1).sum()),
        "equal_to_run": equal,
    }
    print(json.dumps(summary), flush=True)
    if a.progress:
        Path(a.progress).write_text(json.dumps({"checkpoints": checkpoints,
                                                "summary": summary}, indent=1))
    if not a.no_write:
        rows = "\n".join(
            f"| {c['stream_min']:.1f} | {c['rss_mb']:.1f} | {c['us_per_sample']:.0f} |"
            for c in checkpoints)
        eq = ("not compared" if equal is None else
              f"flags equal: {equal['flags']}, kinds equal: {equal['kinds']}, recovered "
              f"max |diff| {equal['recovered_max_abs_diff_n']:.3g} N (`run()` took "
              f"{equal['run_s']} s; the process's peak RSS after it, the tiled log and its "
              f"output frame in memory: {equal['peak_rss_mb'] / 1024:.1f} GB)")
        body = (
            f"Command: `taskset -c 1 .venv/bin/python benchmarks/bench_soak.py --minutes "
            f"{a.minutes:g} --every {a.every}` ({n:,} samples streamed through "
            "`Monitor.update`, the dict call, with the compiled virtual sensor inside "
            "(the `Monitor.for_log` default); "
            "a 60 s simulated walk tiled with continuous time; "
            f"{time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC, 2-core machine).\n\n"
            f"RSS {rss[0]:.1f} MB at the first checkpoint, {rss[-1]:.1f} MB at the last "
            f"(growth over the second half {summary['rss_growth_second_half_mb']:+.2f} MB; "
            "the output arrays are preallocated). Time per sample "
            f"{us[0]:.0f} µs in the first window, {us[-1]:.0f} µs in the last. "
            f"Streamed outputs vs `Monitor.run` on the same log: {eq}. Flagged samples: "
            f"{summary['flagged_samples']}.\n\n"
            "| streamed [min] | RSS [MB] | µs/sample (window) |\n|---|---|---|\n" + rows)
        update_section("## Soak", body)


if __name__ == "__main__":
    main()
