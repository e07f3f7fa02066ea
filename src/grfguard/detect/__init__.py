"""Fault detection: the default detector's stages, the paper's observer, thresholds.

Stages (each a module): :mod:`~grfguard.detect.config` (``MonitorConfig``),
:mod:`~grfguard.detect.tuning` (``DetectTuning``), :mod:`~grfguard.detect.gating`,
:mod:`~grfguard.detect.residual_tests`, :mod:`~grfguard.detect.classify`,
:mod:`~grfguard.detect.detector` (``Detector``), :mod:`~grfguard.detect.paper`
(``PaperDetector``), :mod:`~grfguard.detect.calibrate`. ``Monitor`` (VFS → detector →
recovery) lives in :mod:`grfguard.pipeline` and is re-exported here lazily.
"""

from __future__ import annotations

from typing import Any

from grfguard.detect.blocks import (
    cusum,
    cusum_step,
    excursion_peaks,
    robust_scale,
    threshold_for_rate,
)
from grfguard.detect.calibrate import calibrate_thresholds
from grfguard.detect.config import METHODS, MonitorConfig
from grfguard.detect.detector import Detector
from grfguard.detect.observer import (
    FaultObserver,
    ObserverConfig,
    kalman_gain_sequence,
    paper_threshold,
    run_observer,
    steady_state_gain,
)
from grfguard.detect.paper import PaperDetector
from grfguard.detect.thresholds import Thresholds, default_thresholds
from grfguard.detect.tuning import DetectTuning

__all__ = [
    "METHODS",
    "DetectTuning",
    "Detector",
    "FaultObserver",
    "Monitor",
    "MonitorConfig",
    "ObserverConfig",
    "PaperDetector",
    "Thresholds",
    "calibrate_thresholds",
    "cusum",
    "cusum_step",
    "default_thresholds",
    "excursion_peaks",
    "kalman_gain_sequence",
    "paper_threshold",
    "robust_scale",
    "run_observer",
    "steady_state_gain",
    "threshold_for_rate",
]


def __getattr__(name: str) -> Any:
    if name == "Monitor":
        from grfguard.pipeline import Monitor

        return Monitor
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
