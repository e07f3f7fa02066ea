"""A :class:`~grfguard.detect.Monitor` whose virtual force sensor is the compiled one.

Integration point until the monitor builds the compiled sensor itself: same settings and
outputs as ``Monitor.for_log(log, config)`` (forces within 1e-9 N, identical flags on the
tested walks), with the kernels warmed up before the first sample.
"""

from __future__ import annotations

from typing import Any

import pandas as pd

from grfguard.kernels.vfs import CompiledVirtualForceSensor, VFSKernel
from grfguard.kernels.warmup import warm_up

__all__ = ["compiled_monitor"]


def compiled_monitor(log: pd.DataFrame, config: Any = None, warm: bool = True) -> Any:
    """``Monitor.for_log(log, config)`` with :class:`CompiledVirtualForceSensor` inside.

    Args:
        log: A log of the contract (robot and sampling period are read from it).
        config: A :class:`~grfguard.detect.MonitorConfig` (default settings if None).
        warm: Compile or load the kernels now (:func:`warm_up`) instead of at the first
            sample.

    Returns:
        The monitor; its ``vfs`` is compiled when the log needs a virtual sensor and the
        settings are covered (:meth:`VFSKernel.supports`), else as ``Monitor.for_log``.
    """
    from grfguard.detect import Monitor

    mon = Monitor.for_log(log, config)
    v = mon.vfs
    if v is not None and VFSKernel.supports(v.config):
        mon.vfs = CompiledVirtualForceSensor(v.robot, v.config, v.kin)
        mon.reset()
        if warm:
            warm_up()
    return mon
