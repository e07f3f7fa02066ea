"""Compile (or load from the on-disk cache) every kernel before the first real sample.

The first call in a fresh environment compiles every kernel: about three minutes of CPU
(numba, one core; BENCHMARKS "Compiled kernels"). After that the machine code is cached
next to the modules and a new process loads all of it in about 0.3 s (2026-11-27).
:func:`warm_up` does it up front, e.g. before a live monitor starts, so no sample pays
for it.
"""

from __future__ import annotations

import time

import numpy as np

__all__ = ["warm_up"]


def warm_up() -> float:
    """Compile or load every kernel by running each once on a tiny input.

    Returns:
        Seconds it took (compilation on the first run, cache loading afterwards).
    """
    t0 = time.perf_counter()
    from grfguard.estimate.vfs import VirtualForceSensor
    from grfguard.kernels.vfs import N_IN, VFSKernel
    from grfguard.model.robot import RobotConfig

    # the reference robot: the kernels compile for argument types, not for a robot
    k = VFSKernel(VirtualForceSensor(RobotConfig()))
    X = np.full((2, N_IN), np.nan)
    k.run(X)
    k.step(X[0])
    from grfguard.kernels.monitor import warm_monitor

    warm_monitor()
    from grfguard.kernels import channels, savgol  # described robots: channels, filters

    channels.warm()
    savgol.warm()
    return time.perf_counter() - t0
