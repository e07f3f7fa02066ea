"""Self-calibration of the robot model and its sensors from fault-free data."""

from __future__ import annotations

from grfguard.calib.selfcal import (
    ModelCorrections,
    apply_corrections,
    estimate_corrections,
    robot_of,
)

__all__ = ["ModelCorrections", "apply_corrections", "estimate_corrections", "robot_of"]
