"""grfguard: guards the foot force sensors of walking robots.

A virtual force sensor built from the IMU, the joint encoders and the robot model is
compared with every real sole sensor to tell which one is lying, by how much and
since when, and to hand back a recovered signal.
"""

from __future__ import annotations

from typing import Any

from grfguard.errors import (
    ConfigError,
    FaultSpecError,
    GrfguardError,
    LogFormatError,
    SimulationError,
)
from grfguard.io.logio import load_log, read_log, write_log
from grfguard.model.robot import SURALP, RobotConfig

__version__ = "0.1.0"

__all__ = [
    "__version__",
    "GrfguardError",
    "ConfigError",
    "LogFormatError",
    "FaultSpecError",
    "SimulationError",
    "RobotConfig",
    "SURALP",
    "load_log",
    "read_log",
    "write_log",
    "VirtualForceSensor",
    "Monitor",
    "simulate",
]

# Heavier parts (MuJoCo, scipy) load on first use.
_LAZY = {
    "VirtualForceSensor": ("grfguard.estimate.vfs", "VirtualForceSensor"),
    "Monitor": ("grfguard.pipeline", "Monitor"),
    "simulate": ("grfguard.sim", "simulate"),
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        value = getattr(importlib.import_module(module), attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'grfguard' has no attribute {name!r}")
