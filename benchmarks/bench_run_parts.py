"""Where ``Monitor.run``'s time goes outside the compiled loop (issue 11, must-show 2).

SURALP, the paper scenario on the 60 s walk (seed 0), default monitor (common-mode layer
on, VFS inside). Each round runs ``Monitor.run`` once and then a copy of
``compiled_monitor.run_frame`` with a timer between its parts (the kernel set-up, the
input columns, the buffers, the compiled loop into its reused output block, the blocks
split into the returned columns, the text columns, the frame assembly, ``attrs``), so
both see the same load; prints the minimum and median of each part in µs/sample of
process CPU time (the loop and the split of its blocks into the columns summed over the
blocks). Pin it to one core::

    taskset -c 0 .venv/bin/python benchmarks/bench_run_parts.py --rounds 9
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=9)
    a = ap.parse_args()
    from grfguard import compiled_monitor as M
    from grfguard.detect import Monitor
    from grfguard.faults import inject_faults
    from grfguard.model.robot import SURALP
    from grfguard.pipeline import _with_columns
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    walk = simulate(SURALP, GaitConfig(duration=60.0), NoiseConfig(), seed=0)
    raw = inject_faults(walk, ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5",
                               "r4=offset:-100@5"], seed=0)
    mon = Monitor.for_log(raw)
    mon.run(raw)  # compile or load, warm
    n = len(raw)
    acc: dict[str, list[float]] = {}

    def tick(name: str, t0: float) -> float:
        t = time.process_time()
        acc.setdefault(name, []).append((t - t0) / n * 1e6)
        return t

    def parts() -> None:
        t = time.process_time()
        k = mon._batch_kernel(raw)
        log = raw.copy(deep=False)
        log.attrs = {}
        t = tick("kernel set-up (reset, checks)", t)
        src = [(M._column(log, c) if c in log.columns else None) for c in k.in_cols]
        t = tick("input columns", t)
        bufs = M.chunk_buffers(k, min(M.RUN_BLOCK, n))
        rows = max(1, bufs[0].shape[1])
        block = np.empty((rows, len(k.out_cols)))
        cols = M._FrameColumns(k, n)
        EX = np.empty((n, M.N_EX))
        t = tick("buffers", t)
        loop = split = 0.0
        for s in range(0, n, rows):
            e = min(n, s + rows)
            c0 = time.process_time()
            M.run_rows(k, src, s, e, bufs, block[:e - s], EX[s:e])
            c1 = time.process_time()
            cols.take(block[:e - s], s, e)
            loop += c1 - c0
            split += time.process_time() - c1
        acc.setdefault("compiled loop (blocks of RUN_BLOCK rows)", []).append(loop / n * 1e6)
        acc.setdefault("blocks split into the columns (fresh memory)", []).append(
            split / n * 1e6)
        t = time.process_time()
        new = cols.columns(mon, log, src[0], EX)
        t = tick("output columns (kinds, texts)", t)
        out = _with_columns(log, new, copy=False)
        t = tick("frame assembly", t)
        out.attrs = {**raw.attrs, "monitor": mon.describe()}
        tick("attrs", t)

    for _ in range(a.rounds):
        t0 = time.process_time()
        mon.run(raw)
        tick("Monitor.run, whole", t0)
        t0 = time.process_time()
        parts()
        tick("the same in parts, whole", t0)
    print("| part | min [µs/sample] | median |\n|---|---|---|")
    for name, v in acc.items():
        print(f"| {name} | {min(v):.3f} | {np.median(v):.3f} |")


if __name__ == "__main__":
    main()
