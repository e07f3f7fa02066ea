"""``compiled_monitor``: the old name of ``Monitor.for_log`` with the kernels warmed up."""

from __future__ import annotations

from typing import Any

import pandas as pd

from grfguard.kernels.warmup import warm_up

__all__ = ["compiled_monitor"]


def compiled_monitor(log: pd.DataFrame, config: Any = None, warm: bool = True) -> Any:
    """``Monitor.for_log(log, config)`` (whose virtual force sensor is the compiled one
    whenever the kernel covers the settings), kept for its old callers.

    Args:
        log: A log of the contract (robot and sampling period are read from it).
        config: A :class:`~grfguard.detect.MonitorConfig` (default settings if None).
        warm: Compile or load the kernels now (:func:`warm_up`) instead of at the first
            sample.
    """
    from grfguard.detect import Monitor

    mon = Monitor.for_log(log, config)
    if warm and getattr(mon.vfs, "compiled", False):
        warm_up()
    return mon
