"""Compiled core (numba): forward kinematics of any MuJoCo tree and the virtual force sensor
as one step function over plain arrays, streamed sample by sample or looped over a log.

* :class:`VFSKernel`: the constants, state and scratch of the compiled virtual force
  sensor; :class:`grfguard.estimate.vfs.VirtualForceSensor` runs it (``update``, ``run``,
  ``update_array``) whenever it covers the settings. ``CompiledVirtualForceSensor`` is
  an old name of that class.
* :func:`vfs_batch`: compiled ``VirtualForceSensor.for_log(log).run(log)``.
* :func:`warm_up`: compile or load the cache before the first sample;
  :func:`warm_described` the same for a described robot's monitor (Talos, G1).

Array layouts: :data:`IN_COLUMNS`, :data:`OUT_COLUMNS` (:mod:`grfguard.kernels.vfs`).
"""

from __future__ import annotations

from grfguard.kernels.fk import TreeModel, fk_sites, fk_tree
from grfguard.kernels.vfs import (
    IN_COLUMNS,
    OUT_COLUMNS,
    CompiledVirtualForceSensor,
    VFSKernel,
    vfs_batch,
    vfs_run,
    vfs_step,
)
from grfguard.kernels.warmup import warm_described, warm_up

__all__ = [
    "TreeModel", "fk_tree", "fk_sites", "IN_COLUMNS", "OUT_COLUMNS",
    "CompiledVirtualForceSensor", "VFSKernel", "vfs_batch", "vfs_run", "vfs_step",
    "warm_described", "warm_up",
]
