"""``vfs_run`` of two source trees in one process, alternating 2,000-sample slices of the
60 s SURALP paper walk (seed 0, the paper's four faults, default settings): the
comparison least sensitive to the load of a shared machine (issue 11).

The other tree (a directory holding ``grfguard/``) is copied once under ``--work`` as the
package ``grfguard_before``, every import renamed (``_common.renamed_copy``)::

    git archive <commit> src | tar -x -C /tmp/before
    taskset -c 1 .venv/bin/python benchmarks/bench_vfs_kernel_ab.py --before /tmp/before/src

Prints the largest output difference of the two trees, the minimum and median process
CPU time per sample of each and the median of the per-slice ratios (this tree / before).
With ``--monitor`` the whole compiled monitor loop (``MonitorKernel.run``, default monitor,
VFS and twin inside) instead of the sensor alone.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import renamed_copy  # noqa: E402

SLICE = 2_000


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, required=True,
                    help="the other source tree (a directory holding grfguard/)")
    ap.add_argument("--work", type=Path, default=Path("/tmp/grfguard_vfs_ab"))
    ap.add_argument("--reps", type=int, default=150)
    ap.add_argument("--monitor", action="store_true", help="the whole monitor loop")
    a = ap.parse_args()
    a.work.mkdir(parents=True, exist_ok=True)
    renamed_copy(a.before, "grfguard_before", a.work)
    sys.path.insert(0, str(a.work))
    from grfguard_before.estimate.vfs import VirtualForceSensor as OldVFS
    from grfguard_before.kernels.vfs import VFSKernel as OldKernel

    from grfguard.estimate.vfs import VirtualForceSensor
    from grfguard.faults import inject_faults
    from grfguard.kernels.vfs import VFSKernel, log_to_array
    from grfguard.model.robot import SURALP
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    walk = simulate(SURALP, GaitConfig(duration=60.0), NoiseConfig(), seed=0)
    raw = inject_faults(walk, ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5",
                               "r4=offset:-100@5"], seed=0)
    X, has_gyro, has_ref = log_to_array(raw)
    new = VFSKernel(VirtualForceSensor.for_log(raw), has_gyro, has_ref)
    old = OldKernel(OldVFS.for_log(raw), has_gyro, has_ref)
    if a.monitor:
        new, old, X = _monitor_kernels(raw)
    yn, yo = _out(new, X), _out(old, X)
    diff = np.abs(yn - yo)
    print(f"largest |this - before|: corner forces {np.nanmax(diff[:, :8]):.2e} N, "
          f"all outputs {np.nanmax(diff):.2e}")
    n = len(X)
    tn, to, ratio = [], [], []
    for r in range(a.reps):
        m = slice((r * 7919) % (n - SLICE), (r * 7919) % (n - SLICE) + SLICE)
        for order in ((new, old), (old, new)):
            t = {}
            for k in order:
                if a.monitor:
                    k.reset()  # (VFSKernel.run resets by itself)
                c = time.process_time()
                k.run(X[m])
                t[id(k)] = (time.process_time() - c) / SLICE * 1e6
            tn.append(t[id(new)])
            to.append(t[id(old)])
            ratio.append(t[id(new)] / t[id(old)])
    print(f"this tree: min {min(tn):.3f} median {np.median(tn):.3f} µs/sample CPU; before: "
          f"min {min(to):.3f} median {np.median(to):.3f}; this / before: median of "
          f"{len(ratio)} slice ratios {np.median(ratio):.3f} (quartiles "
          f"{np.percentile(ratio, 25):.3f}-{np.percentile(ratio, 75):.3f}); load "
          f"{os.getloadavg()[0]:.1f}")


def _out(k, X):
    """Outputs of a whole run from reset (the monitor's first array: its output row)."""
    k.reset()
    y = k.run(X)
    return y[0] if isinstance(y, tuple) else y


def _monitor_kernels(raw):
    """The two trees' compiled monitors of ``raw`` and their input array (same layout)."""
    from grfguard_before.detect import Monitor as OldMonitor

    from grfguard.detect import Monitor

    new = Monitor.for_log(raw)._kernel(True, True)
    old = OldMonitor.for_log(raw)._kernel(True, True)
    assert list(new.in_cols) == list(old.in_cols)
    n = len(raw)
    X = np.ascontiguousarray(np.column_stack([
        raw[c].to_numpy(float) if c in raw else np.full(n, np.nan) for c in new.in_cols]))
    return new, old, X


if __name__ == "__main__":
    main()
