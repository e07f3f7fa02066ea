"""Self-calibration of the robot model and its sensors from fault-free data."""

from __future__ import annotations

from grfguard.calib.selfcal import (
    ModelCorrections,
    accelerometer_vibration_rms,
    apply_corrections,
    corrected_config,
    estimate_corrections,
    robot_of,
)
from grfguard.calib.twin_filter import choose_twin_filter

__all__ = [
    "ModelCorrections",
    "accelerometer_vibration_rms",
    "apply_corrections",
    "choose_twin_filter",
    "corrected_config",
    "estimate_corrections",
    "robot_of",
]
