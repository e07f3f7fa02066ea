"""grfguard: guards the foot force sensors of walking robots.

A virtual force sensor built from the IMU, the joint encoders and the robot model is
compared with every real sole sensor to tell which one is lying, by how much and
since when, and to hand back a recovered signal.
"""

from __future__ import annotations

from grfguard.errors import ConfigError, GrfguardError, LogFormatError
from grfguard.model.robot import SURALP, RobotConfig

__version__ = "0.1.0"

__all__ = [
    "__version__",
    "GrfguardError",
    "ConfigError",
    "LogFormatError",
    "RobotConfig",
    "SURALP",
]
