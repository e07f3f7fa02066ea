"""CPU time of the compiled monitor loop and of ``Monitor.run`` for two source trees,
interleaved in one process (the comparison least sensitive to a shared machine's load).

SURALP, the paper scenario on the 60 s walk (seed 0), default monitor (common-mode layer
on, VFS inside). Each tree's ``grfguard`` package is copied once under ``--work`` with
the package renamed (``<name>.…`` imports), so both load side by side; each keeps its
own numba cache there (the first run compiles both). Rounds alternate the order; prints
the minimum and median µs/sample of ``monitor_run_packed`` over the whole log for each
tree, the median of the per-round ratios, whether the outputs are equal bit for bit, and
the best of ``--runs`` ``Monitor.run`` calls per tree (also alternated)::

    git archive <commit> src | tar -x -C /tmp/before
    taskset -c 0 .venv/bin/python benchmarks/bench_kernel_interleaved.py \\
        /tmp/before/src src --names gbefore gafter --work /tmp/interleaved
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import renamed_copy  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", type=Path, help="source tree A (a directory holding grfguard/)")
    ap.add_argument("b", type=Path, help="source tree B")
    ap.add_argument("--names", nargs=2, default=("gtree_a", "gtree_b"))
    ap.add_argument("--work", type=Path, default=Path("/tmp/grfguard_interleaved"))
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--runs", type=int, default=5, help="Monitor.run calls per tree")
    a = ap.parse_args()
    a.work.mkdir(parents=True, exist_ok=True)
    for src, name in zip((a.a, a.b), a.names, strict=True):
        renamed_copy(src, name, a.work)
    sys.path.insert(0, str(a.work))
    sim = importlib.import_module(a.names[0] + ".sim")  # tree A's simulator and faults
    robot = importlib.import_module(a.names[0] + ".model.robot").SURALP
    faults = importlib.import_module(a.names[0] + ".faults")
    walk = sim.simulate(robot, sim.GaitConfig(duration=60.0), sim.NoiseConfig(), seed=0)
    raw = faults.inject_faults(walk, ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5",
                                      "r4=offset:-100@5"], seed=0)
    n = len(raw)
    trees = []
    for name in a.names:
        mon = importlib.import_module(name + ".detect").Monitor.for_log(raw)
        km = importlib.import_module(name + ".kernels.monitor")
        k = mon._kernel(True, True)
        X = np.ascontiguousarray(np.column_stack([
            raw[c].to_numpy(float) if c in raw else np.full(n, np.nan) for c in k.in_cols]))
        Y, EX = np.empty((n, len(k.out_cols))), np.empty((n, km.N_EX))
        k.reset()
        km.monitor_run_packed(X, Y, EX, k.F, k.I)
        trees.append((mon, k, km, X, Y, EX))
    same = np.array_equal(trees[0][4].view(np.int64), trees[1][4].view(np.int64))
    loop: list[list[float]] = [[], []]
    for r in range(a.rounds):
        for i in ((0, 1) if r % 2 == 0 else (1, 0)):
            mon, k, km, X, Y, EX = trees[i]
            k.reset()
            c = time.process_time()
            km.monitor_run_packed(X, Y, EX, k.F, k.I)
            loop[i].append((time.process_time() - c) / n * 1e6)
    run: list[list[float]] = [[], []]
    for r in range(a.runs):
        for i in ((0, 1) if r % 2 == 0 else (1, 0)):
            c = time.process_time()
            trees[i][0].run(raw)
            run[i].append((time.process_time() - c) / n * 1e6)
    la, lb = np.array(loop[0]), np.array(loop[1])
    print(f"outputs of the loop equal bit for bit: {same}")
    for i, name in enumerate(a.names):
        li = np.array(loop[i])
        print(f"{name}: loop min {li.min():.3f} median {np.median(li):.3f} µs/sample CPU; "
              f"Monitor.run min {min(run[i]):.3f} µs/sample CPU "
              f"({1e6 / min(run[i]) / 1e3:.0f} k samples/s)")
    print(f"B/A: loop mins {lb.min() / la.min():.3f}, median of round ratios "
          f"{np.median(lb / la):.3f}; Monitor.run mins {min(run[1]) / min(run[0]):.3f}; "
          f"load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
