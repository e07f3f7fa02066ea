"""CPU time of the compiled monitor loop and of ``Monitor.run`` for two (or more) source
trees, interleaved in one process (the comparison least sensitive to a shared machine's
load).

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

More trees (scratch variants, each against the first): list them all, with as many
``--names``; ratios and bit-equality are then printed per tree against the first.
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
    ap.add_argument("trees", type=Path, nargs="+",
                    help="source trees (directories holding grfguard/), the first the reference")
    ap.add_argument("--names", nargs="+", default=None, help="package name per tree")
    ap.add_argument("--work", type=Path, default=Path("/tmp/grfguard_interleaved"))
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--runs", type=int, default=5, help="Monitor.run calls per tree")
    ap.add_argument("--order", choices=("C", "F"), default="C",
                    help="memory order of the loop's output (F: as Monitor.run's)")
    a = ap.parse_args()
    if len(a.trees) < 2:
        ap.error("give at least two source trees")
    if a.names is None:
        a.names = [f"gtree_{i}" for i in range(len(a.trees))]
    if len(a.names) != len(a.trees):
        ap.error(f"--names: {len(a.names)} names for {len(a.trees)} trees")
    a.work.mkdir(parents=True, exist_ok=True)
    for src, name in zip(a.trees, a.names, strict=True):
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
        Y, EX = np.empty((n, len(k.out_cols)), order=a.order), np.empty((n, km.N_EX))
        k.reset()
        km.monitor_run_packed(X, Y, EX, k.F, k.I)
        trees.append((mon, k, km, X, Y, EX))
    nt = len(trees)
    ref = trees[0][4]
    same = [np.array_equal(ref.view(np.int64), t[4].view(np.int64)) for t in trees]
    diff = [float(np.nanmax(np.abs(ref - t[4]), initial=0.0)) for t in trees]
    loop: list[list[float]] = [[] for _ in trees]
    for r in range(a.rounds):
        for i in _order(r, nt):
            mon, k, km, X, Y, EX = trees[i]
            k.reset()
            c = time.process_time()
            km.monitor_run_packed(X, Y, EX, k.F, k.I)
            loop[i].append((time.process_time() - c) / n * 1e6)
    run: list[list[float]] = [[] for _ in trees]
    for r in range(a.runs):
        for i in _order(r, nt):
            c = time.process_time()
            trees[i][0].run(raw)
            run[i].append((time.process_time() - c) / n * 1e6)
    la = np.array(loop[0])
    for i, name in enumerate(a.names):
        li = np.array(loop[i])
        print(f"{name}: loop min {li.min():.3f} median {np.median(li):.3f} µs/sample CPU; "
              f"Monitor.run min {min(run[i]):.3f} µs/sample CPU "
              f"({1e6 / min(run[i]) / 1e3:.0f} k samples/s)")
        if i:
            print(f"  {name}/{a.names[0]}: loop mins {li.min() / la.min():.3f}, median of "
                  f"round ratios {np.median(li / la):.3f}; Monitor.run mins "
                  f"{min(run[i]) / min(run[0]):.3f}; loop outputs equal bit for bit: "
                  f"{same[i]} (largest difference {diff[i]:.3g})")
    print(f"load {os.getloadavg()[0]:.1f}")


def _order(r: int, n: int) -> list[int]:
    """The trees' order in round ``r``: rotated each round, reversed every other one."""
    o = [(r + i) % n for i in range(n)]
    return o[::-1] if r % 2 else o


if __name__ == "__main__":
    main()
