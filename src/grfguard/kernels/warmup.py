"""Compile (or load from the on-disk cache) every kernel before the first real sample.

The first call in a fresh environment compiles every kernel: 278-323 s on one core,
197-210 s with the monitor's loop and the rest compiled in two processes (2026-11-28,
BENCHMARKS "Issue 11 status (2026-11-28, session 33)"). After that the machine code is
cached next to the modules and a new process loads all of it in about 0.3 s
(2026-11-27).
:func:`warm_up` does it up front, e.g. before a live monitor starts, so no sample pays
for it.
"""

from __future__ import annotations

import contextlib
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["warm_described", "warm_up"]

#: Seconds of walk :func:`warm_described` simulates (enough for every filter window of
#: the described-robot path: its Savitzky-Golay windows are 101 samples, the long blend
#: 1001).
WARM_DESCRIBED_S = 2.5
#: Seconds :func:`warm_up` waits for its child after compiling the monitor's loop (which
#: takes longer than the child's part) before it stops the child and compiles the rest
#: itself.
CHILD_WAIT_S = 600.0
#: Bytes of free memory :func:`warm_up` wants before it compiles in two processes: the
#: monitor's loop peaks at about 1.0 GB since grfguard's functions are inlined without
#: numba's deep copies (:func:`grfguard.kernels._jit.inline_without_copies`; 2.0 GB
#: before), the child at 0.7 GB at most (2026-11-28).
TWO_PROCESS_BYTES = 2.5e9


def warm_up(jobs: int | None = None) -> float:
    """Compile or load every kernel by running each once on a tiny input.

    From an empty cache with ``jobs`` of 2 or more (default: 2 when this process may run
    on two cores), the monitor's loop, the longest compilation, is compiled here while a
    child process compiles the virtual sensor's own entry points and the described
    robots' kernels (:func:`_warm_rest`): the wall time is then about the loop's alone
    (BENCHMARKS "Issue 11 status (2026-11-28, session 33)"), if the machine has the
    memory for both (:data:`TWO_PROCESS_BYTES`). With a warm cache, or if the child
    fails, everything loads (or compiles) here, one kernel after the other.

    Returns:
        Seconds it took (compilation on the first run, cache loading afterwards).
    """
    t0 = time.perf_counter()
    two = _jobs(jobs) > 1 and _cold() and _free_memory() >= TWO_PROCESS_BYTES
    child = _start_rest() if two else None
    try:
        from grfguard.kernels.monitor import warm_monitor

        warm_monitor()
    except BaseException:  # an error or an interrupt here: the child is not needed
        if child is not None:
            child.kill()
            child.wait()
        raise
    if child is not None:
        try:
            child.wait(timeout=CHILD_WAIT_S)
        except subprocess.TimeoutExpired:  # a stuck child: compile what it left here
            child.kill()
            child.wait()
    _warm_rest()
    return time.perf_counter() - t0


def _warm_rest() -> None:
    """The kernels :func:`warm_up` compiles besides the monitor's loop: the virtual
    sensor's own entry points (``VFSKernel.run`` / ``step``), the described robots'
    channels and filters."""
    from grfguard.estimate.vfs import VirtualForceSensor
    from grfguard.kernels.vfs import N_IN, VFSKernel
    from grfguard.model.robot import RobotConfig

    # the reference robot: the kernels compile for argument types, not for a robot
    k = VFSKernel(VirtualForceSensor(RobotConfig()))
    X = np.full((2, N_IN), np.nan)
    k.run(X)
    k.step(X[0])
    from grfguard.kernels import channels, savgol  # described robots: channels, filters

    channels.warm()
    savgol.warm()


def _jobs(jobs: int | None) -> int:
    """Processes :func:`warm_up` may use: ``jobs``, or 2 when this process may run on two
    cores or more."""
    if jobs is not None:
        return jobs
    try:
        return min(2, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return min(2, os.cpu_count() or 1)


def _free_memory() -> float:
    """Bytes this process could still allocate: the system's available memory
    (:func:`grfguard._memory.available_memory`), less where a cgroup (v2) limit leaves
    less; infinite where neither can be read."""
    from grfguard._memory import available_memory

    avail = available_memory()
    free = math.inf if avail is None else float(avail)
    with contextlib.suppress(OSError, ValueError):
        cg = Path("/sys/fs/cgroup")
        limit = (cg / "memory.max").read_text().strip()
        if limit != "max":
            free = min(free, float(limit) - float((cg / "memory.current").read_text()))
    return free


def _cold() -> bool:
    """The monitor's loop is not in numba's on-disk cache (a fresh install, or its
    sources changed: :mod:`grfguard.kernels._jit` drops stale entries at import)."""
    from grfguard.kernels.monitor import _run_flat

    cache = getattr(_run_flat, "_cache", None)
    index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    return index is not None and not os.path.exists(index)


def _start_rest() -> subprocess.Popen | None:
    """A child process running :func:`_warm_rest` (its output discarded; None if it
    cannot start). It imports this package from where this process did: that directory
    goes first on its path only when its own path lacks it, and the working directory
    is not on it (``-P``)."""
    import grfguard

    root = str(Path(grfguard.__file__).resolve().parents[1])
    code = (f"import sys; r = {root!r}; r in sys.path or sys.path.insert(0, r); "
            "from grfguard.kernels.warmup import _warm_rest; _warm_rest()")
    try:
        return subprocess.Popen([sys.executable, "-P", "-c", code],
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
    except OSError:
        return None


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
