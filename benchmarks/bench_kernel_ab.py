"""CPU time per sample of the compiled monitor loop and of ``Monitor.run`` (SURALP, the
paper scenario on a 60 s walk, default monitor: common-mode layer on, VFS inside), for
comparing two source trees alternately on a shared machine::

    git archive <commit> src | tar -x -C /tmp/before
    for i in 1 2 3; do
        PYTHONPATH=/tmp/before/src .venv/bin/python benchmarks/bench_kernel_ab.py
        .venv/bin/python benchmarks/bench_kernel_ab.py
    done

Prints the minimum and median process CPU time per sample of ``MonitorKernel.run`` over
``--reps`` whole-log runs, and the minimum of three ``Monitor.run`` calls.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=5)
    a = ap.parse_args()
    import grfguard
    from grfguard.detect import Monitor
    from grfguard.faults import inject_faults
    from grfguard.kernels import warm_up
    from grfguard.model.robot import SURALP
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    warm_up()
    walk = simulate(SURALP, GaitConfig(duration=60.0), NoiseConfig(), seed=0)
    raw = inject_faults(walk, ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5",
                               "r4=offset:-100@5"], seed=0)
    n = len(raw)
    mon = Monitor.for_log(raw)
    k = mon._kernel(True, True)
    X = np.ascontiguousarray(np.column_stack([
        raw[c].to_numpy(float) if c in raw else np.full(n, np.nan) for c in k.in_cols]))
    k.reset()
    k.run(X[:100])
    res = []
    for _ in range(a.reps):
        k.reset()
        c = time.process_time()
        k.run(X)
        res.append((time.process_time() - c) / n * 1e6)
    mr = []
    for _ in range(3):
        c = time.process_time()
        mon.run(raw)
        mr.append((time.process_time() - c) / n * 1e6)
    print(f"{os.path.dirname(grfguard.__file__)}: kernel loop min {min(res):.2f} median "
          f"{np.median(res):.2f} µs/sample CPU; Monitor.run min {min(mr):.2f} µs/sample CPU; "
          f"load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
