"""Fault detection: the paper's observer, detector building blocks, thresholds, Monitor."""

from __future__ import annotations

from grfguard.detect.blocks import (
    Cusum,
    PersistentFlag,
    cusum,
    excursion_peaks,
    hysteresis,
    robust_scale,
    threshold_for_rate,
)
from grfguard.detect.monitor import (
    METHODS,
    Monitor,
    MonitorConfig,
    calibrate_monitor,
    calibrate_thresholds,
)
from grfguard.detect.observer import (
    FaultObserver,
    ObserverConfig,
    kalman_gain_sequence,
    paper_threshold,
    run_observer,
    steady_state_gain,
)
from grfguard.detect.thresholds import Thresholds, default_thresholds

__all__ = [
    "METHODS",
    "Cusum",
    "FaultObserver",
    "Monitor",
    "MonitorConfig",
    "ObserverConfig",
    "PersistentFlag",
    "Thresholds",
    "calibrate_monitor",
    "calibrate_thresholds",
    "cusum",
    "default_thresholds",
    "excursion_peaks",
    "hysteresis",
    "kalman_gain_sequence",
    "paper_threshold",
    "robust_scale",
    "run_observer",
    "steady_state_gain",
    "threshold_for_rate",
]
