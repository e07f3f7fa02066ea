"""Speed of the compiled whole monitor (issue 11): streaming array and dict calls, batch run.

Every figure is given next to the pure-Python path (``compiled=False``: Python guards,
detector, recovery and standing layer; Python VFS when the VFS runs inside) timed in the
same run, and as a ratio, so it holds on a loaded machine. Pin it to one core::

    taskset -c 1 .venv/bin/python benchmarks/bench_compiled_monitor.py [--write] [--n 100000]

Streaming: ``Monitor.update_array`` (one compiled call per sample) and ``Monitor.update``
(dict in, dict out) over ``--n`` samples of the paper scenario (SURALP, 60 s walk repeated,
VFS inside or precomputed); the Python reference over fewer samples (it is 30-100x
slower). Batch: ``Monitor.run`` over the 60 s log. Wall-clock per call, and the process
CPU time per sample for the batch (less sensitive to other processes).
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
import pandas as pd

from grfguard.detect import Monitor
from grfguard.estimate.vfs import with_vfs_columns
from grfguard.faults import inject_faults
from grfguard.kernels import warm_up
from grfguard.model.robot import SURALP
from grfguard.sim import GaitConfig, NoiseConfig, simulate

SECTION = "## Compiled monitor (whole monitor in one compiled step)"
PAPER = ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5", "r4=offset:-100@5"]


def _array_rows(mon: Monitor, log: pd.DataFrame) -> np.ndarray:
    cols = [log[c].to_numpy(float) if c in log else np.full(len(log), np.nan)
            for c in mon.input_columns]
    return np.ascontiguousarray(np.column_stack(cols))


def _stats(dts: np.ndarray) -> str:
    us = dts * 1e6
    return f"{np.median(us):.1f} / {np.percentile(us, 99):.1f} / {us.max():,.0f}"


def _stream_array(mon: Monitor, X: np.ndarray, n: int) -> np.ndarray:
    y = np.empty(len(mon.output_columns))
    mon.reset()
    pc = time.perf_counter
    dts = np.empty(n)
    m = len(X)
    for k in range(n):
        x = X[k % m]
        t0 = pc()
        mon.update_array(x, y)
        dts[k] = pc() - t0
    return dts


def _stream_dict(mon: Monitor, rows: list[dict], n: int) -> np.ndarray:
    mon.reset()
    pc = time.perf_counter
    dts = np.empty(n)
    m = len(rows)
    for k in range(n):
        r = rows[k % m]
        t0 = pc()
        mon.update(r)
        dts[k] = pc() - t0
    return dts


def _first_calls(log: pd.DataFrame, n: int = 5) -> list[tuple[float, float]]:
    """Wall time [µs] of the first ``update_array`` and the first ``update`` (dict) of
    ``n`` new monitors (``Monitor.for_log``, which builds the streaming step; kernels
    loaded), each on the log's first row."""
    x = None
    out = []
    for _ in range(n):
        arr = Monitor.for_log(log)
        x = _array_rows(arr, log.iloc[:1])[0] if x is None else x
        y = np.empty(len(arr.output_columns))
        t0 = time.perf_counter()
        arr.update_array(x, y)
        t1 = time.perf_counter()
        dic = Monitor.for_log(log)
        row = log.iloc[0].to_dict()
        t2 = time.perf_counter()
        dic.update(row)
        out.append(((t1 - t0) * 1e6, (time.perf_counter() - t2) * 1e6))
    return out


def _batch(mon: Monitor, log: pd.DataFrame) -> tuple[float, float]:
    """(samples/s wall, CPU µs/sample) of ``mon.run(log)`` (best of two)."""
    best = (0.0, float("inf"))
    for _ in range(2):
        t0, c0 = time.perf_counter(), time.process_time()
        mon.run(log)
        w, c = time.perf_counter() - t0, time.process_time() - c0
        if len(log) / w > best[0]:
            best = (len(log) / w, c / len(log) * 1e6)
    return best


_FIRST = """
import sys, time
from grfguard.detect import Monitor
from grfguard.io.logio import read_log
log = read_log(sys.argv[1])
mon = Monitor.for_log(log)
mon.run(log.iloc[:100])  # kernels loaded from the cache, columns checked
c = time.process_time()
mon.run(log)
print((time.process_time() - c) / len(log) * 1e6)
"""


def _first_runs(log: pd.DataFrame, n: int = 3) -> list[float]:
    """CPU µs/sample of the first full ``Monitor.run`` in ``n`` fresh processes (what a
    script that loads a log and runs it once sees: the outputs' memory is touched for the
    first time in the process)."""
    import subprocess
    import sys
    import tempfile

    from grfguard.io.logio import write_log

    with tempfile.TemporaryDirectory() as d:
        path = f"{d}/log.parquet"
        write_log(log, path)
        return [float(subprocess.run([sys.executable, "-c", _FIRST, path], check=True,
                                     capture_output=True, text=True).stdout.split()[-1])
                for _ in range(n)]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=100_000, help="streamed samples (compiled)")
    ap.add_argument("--n-ref", type=int, default=3_000, help="streamed samples (Python)")
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--write", action="store_true", help="update BENCHMARKS.md")
    a = ap.parse_args()
    t_warm = warm_up()
    walk = simulate(SURALP, GaitConfig(duration=a.duration), NoiseConfig(), seed=0)
    raw = inject_faults(walk, PAPER, seed=0)
    pre = with_vfs_columns(raw)
    load0 = os.getloadavg()[0]
    lines = [
        "| input | call | compiled: median / p99 / max [µs/sample] | pure Python "
        "(`compiled=False`) | ratio (median) |",
        "|---|---|---|---|---|",
    ]
    batch = [
        "| input | compiled `Monitor.run` [samples/s] (CPU µs/sample) | pure Python "
        "[samples/s] | ratio |",
        "|---|---|---|---|",
    ]
    for label, log in (("VFS inside (raw log)", raw), ("VFS columns precomputed", pre)):
        mon = Monitor.for_log(log)
        ref = Monitor.for_log(log, compiled=False)
        assert mon.compiled_reason() == "", mon.compiled_reason()
        X = _array_rows(mon, log)
        rows = log.to_dict("records")
        d_arr = _stream_array(mon, X, a.n)
        d_dict = _stream_dict(mon, rows, a.n)
        d_ref = _stream_dict(ref, rows, a.n_ref)
        r_ref = float(np.median(d_ref))
        lines.append(f"| {label} | `update_array` | {_stats(d_arr)} (over {a.n:,}) | "
                     f"{r_ref * 1e6:.0f} (dict, over {a.n_ref:,}) | "
                     f"{r_ref / np.median(d_arr):.0f}x |")
        lines.append(f"| {label} | `update` (dict) | {_stats(d_dict)} (over {a.n:,}) | "
                     f"{r_ref * 1e6:.0f} | {r_ref / np.median(d_dict):.0f}x |")
        sps, cpu = _batch(mon, log)
        ref_log = log if label.startswith("VFS columns") else log.iloc[:10_000]
        rsps, _ = _batch(ref, ref_log)
        batch.append(f"| {label} | {sps:,.0f} ({cpu:.1f}) | {rsps:,.0f} | {sps / rsps:.0f}x |")
    from _common import cpu_name, fresh_touch_ms, reference_us
    from bench_batch_stages import suralp_stages, talos_stages
    from bench_batch_stages import table as stage_table

    ref_us = reference_us()
    touch = fresh_touch_ms(48)  # (the child inherits this process's core)
    first = _first_runs(raw)
    calls = _first_calls(raw)
    stages = stage_table(suralp_stages(raw), talos_stages(), ref_us)
    load1 = os.getloadavg()[0]
    body = "\n".join([
        f"Command: `taskset -c 1 .venv/bin/python benchmarks/bench_compiled_monitor.py "
        f"--n {a.n}` ({platform.machine()} {cpu_name()}, {os.cpu_count()} cores "
        f"shared with other jobs; load average {load0:.1f} at the start, {load1:.1f} at the "
        f"end; {time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC). Paper scenario on a "
        f"{a.duration:.0f} s SURALP walk (seed 0), default "
        "settings (standing layer on). Kernels warmed up first "
        f"(`warm_up()`: {t_warm:.1f} s in this process). The first touch of 48 MB of "
        f"fresh memory in a fresh process took {touch:.0f} ms in this run "
        "(`_common.fresh_touch_ms`, numpy's huge-page hint on; `Monitor.run` writes the "
        "columns it returns, 25 MB per minute of log, into fresh memory without that hint, "
        "`grfguard._memory.small_pages`). The first full `Monitor.run` of the raw log in "
        "a fresh process (kernels loaded, nothing else run): "
        + ", ".join(f"{v:.2f}" for v in first) + " µs/sample of CPU in three processes. "
        "The first sample of a new monitor (raw log; `Monitor.for_log` builds the "
        "streaming step, so the first call does not; five monitors): `update_array` "
        + ", ".join(f"{a_:.0f}" for a_, _ in calls) + " µs, `update` (dict) "
        + ", ".join(f"{d:.0f}" for _, d in calls) + " µs.",
        "",
        "Streaming, one sample per call (wall clock per call):",
        "",
        *lines,
        "",
        "Batch `Monitor.run` (best of two; the Python reference with the VFS inside runs "
        "10,000 samples):",
        "",
        *batch,
        "",
        "Batch throughput stage by stage (`benchmarks/bench_batch_stages.py`; SURALP: "
        "best process CPU time of five whole-log runs of each, alternated, the compiled "
        "stages into reused output arrays; Talos: best of two whole runs; "
        f"reference: `numpy.sort` of 10^6 floats, {ref_us / 1e3:.0f} ms in this run). "
        "Issue 11 targets: >= 1 M samples/s on SURALP, >= 300 k samples/s on a 30-joint "
        "robot, kinematics included:",
        "",
        *stages,
    ])
    print(body)
    if a.write:
        from _common import update_section

        update_section(SECTION, body)


if __name__ == "__main__":
    main()
