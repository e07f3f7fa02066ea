"""The compiled virtual force sensor as ``Monitor.for_log``'s default: first call, streaming.

Prints (markdown) for the default monitor (compiled VFS) and ``compiled=False``
(pure-Python VFS), SURALP, default settings, a simulated walk with sensor noise:

1. ``Monitor.for_log`` in a fresh process (kernels loaded from the on-disk cache) [s];
2. streaming ``Monitor.update`` (dict call, VFS inside) [µs/sample]: median, p99, max;
3. optionally ``grfguard run`` end to end on a log file (``--run-log``), wall and CPU.

Usage:
    .venv/bin/python benchmarks/bench_compiled_default.py [--samples 20000]
        [--run-log walk600.parquet]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from grfguard.detect import Monitor
from grfguard.model.robot import SURALP
from grfguard.sim import GaitConfig, NoiseConfig, simulate

FIRST_CALL = """
import time, sys
from grfguard.io.logio import load_log
log = load_log(sys.argv[1])
from grfguard.detect import Monitor
t0 = time.perf_counter()
Monitor.for_log(log, compiled=sys.argv[2] == "1")
print(time.perf_counter() - t0)
"""


def first_call(path: Path, compiled: bool) -> float:
    out = subprocess.run([sys.executable, "-c", FIRST_CALL, str(path), "1" if compiled else "0"],
                         check=True, capture_output=True, text=True)
    return float(out.stdout.strip().splitlines()[-1])


def streaming(log, compiled: bool, n: int) -> tuple[float, float, float, int]:
    mon = Monitor.for_log(log, compiled=compiled)
    rows = log.iloc[2000:2000 + n].to_dict("records")
    mon.reset()
    for r in log.iloc[:2000].to_dict("records"):  # past the start-up
        mon.update(r)
    dts = np.empty(len(rows))
    for k, r in enumerate(rows):
        t0 = time.perf_counter()
        mon.update(r)
        dts[k] = time.perf_counter() - t0
    return (statistics.median(dts) * 1e6, float(np.percentile(dts, 99)) * 1e6,
            float(dts.max()) * 1e6, len(rows))


def cli_run(path: Path, compiled: bool) -> tuple[float, float]:
    exe = Path(sys.executable).with_name("grfguard")
    with tempfile.TemporaryDirectory() as d:
        cmd = [str(exe), "run", str(path), "-o", str(Path(d) / "out.parquet")]
        if not compiled:
            cmd.append("--no-compiled")
        r0 = os.times()
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        wall = time.perf_counter() - t0
        r1 = os.times()
    return wall, (r1.children_user - r0.children_user) + (r1.children_system - r0.children_system)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=20000, help="streamed samples per mode")
    ap.add_argument("--python-samples", type=int, default=3000,
                    help="streamed samples with the pure-Python VFS")
    ap.add_argument("--run-log", type=Path, default=None,
                    help="also time `grfguard run` on this log")
    args = ap.parse_args()
    dur = max(30.0, (args.samples + 2000) / 1000.0 + 1.0)
    log = simulate(SURALP, GaitConfig(duration=dur), NoiseConfig(), seed=0)
    print(f"Machine: {platform.machine()}, {os.cpu_count()} logical cores, Python "
          f"{platform.python_version()}; load average {os.getloadavg()[0]:.1f}.")
    print()
    print("| what | compiled (default) | `compiled=False` (Python detector) | ratio |")
    print("| --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "walk.parquet"
        from grfguard.io.logio import write_log

        write_log(log, p)
        fc = first_call(p, True)
        fp = first_call(p, False)
    print(f"| `Monitor.for_log` in a fresh process, cache on disk [s] | {fc:.2f} | {fp:.2f} | |")
    c = streaming(log, True, args.samples)
    py = streaming(log, False, args.python_samples)
    print(f"| streaming `Monitor.update`, VFS inside [µs/sample] median / p99 / max "
          f"| {c[0]:.0f} / {c[1]:.0f} / {c[2]:.0f} (over {c[3]:,}) "
          f"| {py[0]:.0f} / {py[1]:.0f} / {py[2]:.0f} (over {py[3]:,}) "
          f"| {py[0] / c[0]:.0f}x (median) |")
    if args.run_log is not None:
        n = len(__import__("grfguard.io.logio", fromlist=["load_log"]).load_log(args.run_log))
        wc, cc = cli_run(args.run_log, True)
        wp, cp = cli_run(args.run_log, False)
        print(f"| `grfguard run` end to end, {n:,} samples [s] wall (CPU) | {wc:.1f} ({cc:.1f}) "
              f"| {wp:.1f} ({cp:.1f}) | {wp / wc:.1f}x |")


if __name__ == "__main__":
    main()
