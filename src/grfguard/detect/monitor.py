"""Old import path of the monitor (kept for compatibility).

The monitor is now split into stages: settings in :mod:`grfguard.detect.config`, the
default detector in :mod:`grfguard.detect.detector` (gates, tests, kinds in
:mod:`~grfguard.detect.gating`, :mod:`~grfguard.detect.residual_tests`,
:mod:`~grfguard.detect.classify`), the paper's method in :mod:`grfguard.detect.paper`,
recovery in :mod:`grfguard.recover.recovery`, calibration in
:mod:`grfguard.detect.calibrate`, and :class:`~grfguard.pipeline.Monitor` wiring them.
``Monitor`` is resolved lazily here (``grfguard.pipeline`` sits above ``detect``).
"""

from __future__ import annotations

from typing import Any

from grfguard.detect.calibrate import calibrate_thresholds
from grfguard.detect.config import METHODS, MonitorConfig

__all__ = [
    "METHODS",
    "Monitor",  # noqa: F822 - resolved by __getattr__
    "MonitorConfig",
    "calibrate_thresholds",
]


def __getattr__(name: str) -> Any:
    if name == "Monitor":
        from grfguard.pipeline import Monitor

        return Monitor
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
