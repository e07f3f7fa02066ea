"""CPU time per sample of the compiled virtual force sensor alone (``vfs_run``), SURALP,
default settings, on the 60 s paper-scenario walk (seed 0, the paper's four faults), for
comparing two source trees alternately on a shared machine (issue 11)::

    git archive <commit> src | tar -x -C /tmp/before
    for i in 1 2 3; do
        PYTHONPATH=/tmp/before/src taskset -c 1 .venv/bin/python benchmarks/bench_vfs_kernel.py
        taskset -c 1 .venv/bin/python benchmarks/bench_vfs_kernel.py
    done

Prints the minimum and median process CPU time per sample over ``--reps`` whole-log runs
of ``VFSKernel.run`` (reset + ``vfs_run``), the machine load, and with ``--save`` writes
the outputs (T, 22) to a ``.npy`` file for comparing two trees' outputs.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=9)
    ap.add_argument("--save", type=Path, default=None, help="write the outputs (.npy)")
    a = ap.parse_args()
    import grfguard
    from grfguard.estimate.vfs import VirtualForceSensor
    from grfguard.faults import inject_faults
    from grfguard.kernels.vfs import VFSKernel, log_to_array
    from grfguard.model.robot import SURALP
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    walk = simulate(SURALP, GaitConfig(duration=60.0), NoiseConfig(), seed=0)
    raw = inject_faults(walk, ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5",
                               "r4=offset:-100@5"], seed=0)
    X, has_gyro, has_ref = log_to_array(raw)
    k = VFSKernel(VirtualForceSensor.for_log(raw), has_gyro, has_ref)
    k.run(X[:100])  # compiled (or loaded from the cache)
    n = len(X)
    res = []
    for _ in range(a.reps):
        c = time.process_time()
        Y = k.run(X)
        res.append((time.process_time() - c) / n * 1e6)
    if a.save is not None:
        np.save(a.save, Y)
    print(f"{os.path.dirname(grfguard.__file__)}: vfs_run min {min(res):.3f} median "
          f"{np.median(res):.3f} µs/sample CPU ({1e6 / min(res):,.0f} samples/s), "
          f"{a.reps} runs of {n} samples; load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
