"""What ``Monitor.run`` spends around the compiled SURALP loop: the memory layout of its
input chunk and output, and the output frame's conversions.

SURALP, the paper scenario on the 60 s walk (seed 0), default monitor (VFS inside), one
process, process CPU time per sample, minimum of ``--repeat`` calls per variant, the
variants alternated over ``--rounds`` rounds (the median of the rounds' minima is
printed too):

* the compiled loop over the whole log already in one row-major array, output row-major
  (``monitor_run_packed``: no chunk, the lower bound of the loop);
* :func:`grfguard.compiled_monitor.run_rows` over the whole log (input columns copied
  chunk by chunk into a column-major buffer of 4,096 rows), with the input buffer's rows
  padded to an odd number of cache lines (``chunk_buffers``) or not (4,096 floats: every
  column's value of a sample 32 kB from the next, one L1 set), into a column-major
  output (``Monitor.run``'s until session 31) or a row-major one;
* ``Monitor.run``'s blocks since session 31: chunks of ``RUN_BLOCK`` rows into one reused
  row-major block, each split into the returned columns (``_FrameColumns``);
* ``Monitor.run`` whole;
* two parts of the output frame: the input columns taken from the log and the text
  columns (``kind_<s>``, ``system_state``: :func:`grfguard.io.codes.codes_to_str`).

Pin it to one core; nothing is written to BENCHMARKS.md::

    taskset -c 1 .venv/bin/python benchmarks/bench_run_layouts.py [--rounds 3]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from grfguard import compiled_monitor as km
from grfguard.detect import Monitor
from grfguard.faults import inject_faults
from grfguard.io.codes import codes_to_str
from grfguard.kernels.detect import KIND_NAMES
from grfguard.model.robot import SURALP
from grfguard.sim import GaitConfig, NoiseConfig, simulate

PAPER = ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5", "r4=offset:-100@5"]


def _buffers(k: km.MonitorKernel, rows: int, padded: bool) -> tuple:
    if padded:
        return km.chunk_buffers(k, rows)
    return (np.empty((len(k.in_cols), rows)), np.empty((rows, len(k.out_cols))),
            np.empty((rows, km.N_EX)))


def _variants(mon: Monitor, log) -> dict:
    n = len(log)
    k = mon._batch_kernel(log)
    shallow = log.copy(deep=False)
    shallow.attrs = {}  # as run_frame: column access would deep-copy the metadata
    src = [(km._column(shallow, c) if c in shallow.columns else None) for c in k.in_cols]
    X = np.ascontiguousarray(np.column_stack(
        [s if s is not None else np.full(n, math.nan) for s in src]))
    m = len(k.out_cols)
    YC, YF, EX = np.empty((n, m)), np.empty((n, m), order="F"), np.empty((n, km.N_EX))

    def loop(Y, padded):
        bufs = _buffers(k, min(4096, n), padded)

        def f():
            k.reset()
            km.run_rows(k, src, 0, n, bufs, Y, EX)
        return f

    def packed():
        k.reset()
        km.monitor_run_packed(X, YC, EX, k.F, k.I)

    def texts():
        for _, typ, j in km.output_rows(k):
            if typ in ("kind", "state"):
                codes_to_str(YF[:, j].astype(np.int64), KIND_NAMES if typ == "kind"
                             else km.SYSTEM_STATES)

    def blocks():
        k.reset()
        km.run_blocks(k, src, n)

    loop(YF, True)()
    return {
        "loop, whole log row-major in and out (monitor_run_packed)": packed,
        "blocks of RUN_BLOCK rows, reused row-major block, split (Monitor.run's)": blocks,
        "run_rows, padded input chunk, column-major output (Monitor.run's before)":
            loop(YF, True),
        "run_rows, unpadded input chunk (4,096 floats), column-major output": loop(YF, False),
        "run_rows, padded input chunk, row-major output": loop(YC, True),
        "run_rows, unpadded input chunk, row-major output": loop(YC, False),
        "Monitor.run, whole": lambda: mon.run(log),
        "frame: input columns taken from the log": lambda: [
            km._column(shallow, c) for c in k.in_cols if c in shallow.columns],
        "frame: text columns from codes (kind_<s>, system_state)": texts,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    walk = simulate(SURALP, GaitConfig(duration=60.0), NoiseConfig(), seed=0)
    log = inject_faults(walk, PAPER, seed=0)
    mon = Monitor.for_log(log)
    mon.run(log)
    variants = _variants(mon, log)
    best: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(a.rounds):
        for name, f in variants.items():
            b = math.inf
            for _ in range(a.repeat):
                c = time.process_time()
                f()
                b = min(b, time.process_time() - c)
            best[name].append(b / len(log) * 1e6)
    print("| variant | min / median of the rounds' minima [µs/sample, CPU] |")
    print("|---|---|")
    for name, v in best.items():
        print(f"| {name} | {min(v):.3f} / {float(np.median(v)):.3f} |")


if __name__ == "__main__":
    main()
