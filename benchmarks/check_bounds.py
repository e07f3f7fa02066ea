"""Every compiled kernel once more with numba's bounds checks on (``make boundscheck``).

The kernels are compiled without bounds checks (an index past an array's end reads or
writes whatever memory is there). This run compiles them again with
``NUMBA_BOUNDSCHECK=1`` into a cache of its own (the project's cache is not touched) and
drives them through the paths whose arrays differ in size: the warm-up; the SURALP
monitor in batch and streaming (array and dict calls) with the virtual sensor inside,
with its columns precomputed (no sensor: one-float placeholders) and without the
common-mode layer (no twin sensor); the virtual sensor alone (batch, steps); the paper
method; Talos's described monitor (its inverse dynamics in vector lanes). An index
out of bounds raises ``IndexError`` (the run fails and names the call). Two such writes
were found this way on 2026-11-27 (BENCHMARKS.md, "SURALP virtual sensor: kinematics
eight samples at a time"). Part of ``make test`` since 2026-11-28
(``tests/test_boundscheck.py``): compiling everything again takes about three minutes of
CPU (1 min 49 s wall on two cores, 2026-11-28, session 38).

Usage: ``make boundscheck`` (or ``.venv/bin/python benchmarks/check_bounds.py``, which
sets the environment and runs itself in a child process).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time


def _run() -> None:
    import numba
    import numpy as np

    assert numba.config.BOUNDSCHECK, "run through main(): NUMBA_BOUNDSCHECK=1 is not set"
    from grfguard.detect import Monitor
    from grfguard.estimate.vfs import with_vfs_columns
    from grfguard.faults import inject_faults
    from grfguard.kernels import warm_up
    from grfguard.kernels.vfs import log_to_array
    from grfguard.model.robot import SURALP
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    def step(name, fn):
        t0 = time.process_time()
        fn()
        print(f"  {name}: in bounds ({time.process_time() - t0:.1f} s CPU)", flush=True)

    step("warm_up()", warm_up)
    walk = simulate(SURALP, GaitConfig(duration=4.0), NoiseConfig(), seed=0)
    log = inject_faults(walk, ["r1=frozen:0@2", "r3=drift:15@2"], seed=0)

    def monitor(lg, **kw):
        mon = Monitor.for_log(lg, **kw)
        mon.run(lg)
        mon.reset()
        for r in lg.iloc[:200].to_dict("records"):
            mon.update(r)
        X = np.column_stack([lg[c].to_numpy(float) if c in lg else np.full(len(lg), np.nan)
                             for c in mon.input_columns])
        mon.reset()
        for x in X[:200]:
            mon.update_array(x)

    step("monitor, virtual sensor inside", lambda: monitor(log))
    step("monitor, virtual-sensor columns precomputed", lambda: monitor(with_vfs_columns(log)))
    step("monitor without the common-mode layer", lambda: monitor(log, common_mode=False))

    def vfs_alone():
        k = Monitor.for_log(log)._kernel(True, True).vfs_kernel
        X = np.ascontiguousarray(log_to_array(log)[0])
        k.run(X)
        for x in X[:200]:
            k.step(x)

    step("virtual sensor alone", vfs_alone)
    from grfguard.detect.config import MonitorConfig

    step("paper method", lambda: Monitor.for_log(log, MonitorConfig(method="paper")).run(log))
    from grfguard.estimate.described import run_described
    from grfguard.model.description import load_description
    from grfguard.model.loader import load_model
    from grfguard.sim.wholebody import scaled_gait, simulate_robot

    def talos():
        r = load_model(load_description("talos"))
        w = simulate_robot(r, scaled_gait(r, duration=2.0), NoiseConfig(), seed=1)
        run_described(w, robot=r)

    step("Talos described monitor (inverse dynamics in vector lanes)", talos)


def main() -> None:
    if os.environ.get("NUMBA_BOUNDSCHECK") == "1":
        _run()
        print("no index out of bounds")
        return
    with tempfile.TemporaryDirectory(prefix="grfguard-boundscheck-") as cache:
        env = {**os.environ, "NUMBA_BOUNDSCHECK": "1", "NUMBA_CACHE_DIR": cache}
        sys.exit(subprocess.run([sys.executable, __file__], env=env).returncode)


if __name__ == "__main__":
    main()
