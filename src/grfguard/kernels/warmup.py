"""Compile (or load from the on-disk cache) every kernel before the first real sample.

The first call in a fresh environment compiles every kernel: about three minutes of CPU
(numba, one core; BENCHMARKS "Compiled kernels"). After that the machine code is cached
next to the modules and a new process loads all of it in about 0.3 s (2026-11-27).
:func:`warm_up` does it up front, e.g. before a live monitor starts, so no sample pays
for it.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

__all__ = ["warm_described", "warm_up"]

#: Seconds of walk :func:`warm_described` simulates (enough for every filter window of
#: the described-robot path: its Savitzky-Golay windows are 101 samples, the long blend
#: 1001).
WARM_DESCRIBED_S = 2.5


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


def warm_described(robot: Any) -> float:
    """Compile or load the kernels of a described robot's monitor (``run_described``:
    the virtual foot wrenches' filters, kinematics and inverse dynamics, then the
    channel or corner monitor), by running it on a short simulated walk of that robot.

    Compiled code depends on argument types, not on the robot, so one described robot
    warms the path for all of them; from an empty cache it takes about half a minute of
    CPU (BENCHMARKS "Described robots: compiled inverse dynamics"), later a few seconds
    (the simulation).

    Args:
        robot: A loaded robot (:func:`grfguard.model.loader.load_model`), a shipped name
            (``talos``, ``g1``) or a description file.

    Returns:
        Seconds it took.
    """
    t0 = time.perf_counter()
    from grfguard.estimate.described import run_described
    from grfguard.model.loader import LoadedRobot
    from grfguard.sim import NoiseConfig
    from grfguard.sim.wholebody import scaled_gait, simulate_robot

    if not isinstance(robot, LoadedRobot):
        from grfguard.model.description import load_description
        from grfguard.model.loader import load_model

        robot = load_model(load_description(str(robot)))
    log = simulate_robot(robot, scaled_gait(robot, duration=WARM_DESCRIBED_S), NoiseConfig(),
                         seed=0)
    run_described(log, robot=robot)
    return time.perf_counter() - t0
