"""One exception tree for grfguard.

Every error raised for bad user input derives from :class:`GrfguardError`, and its
message says what is wrong, where, and how to fix it.
"""

from __future__ import annotations

__all__ = [
    "GrfguardError",
    "ConfigError",
    "LogFormatError",
    "FaultSpecError",
    "SimulationError",
    "OutputError",
    "GrfguardWarning",
]


class GrfguardError(Exception):
    """Base class of every error grfguard raises on purpose."""


class ConfigError(GrfguardError, ValueError):
    """A configuration value is impossible (name, value and allowed range in the message)."""


class LogFormatError(GrfguardError, ValueError):
    """A log file or DataFrame does not follow the log contract."""


class FaultSpecError(GrfguardError, ValueError):
    """A fault specification (``SENSOR=KIND[:VALUE]@START[-END]``) cannot be parsed."""


class SimulationError(GrfguardError, RuntimeError):
    """The walking simulation failed (for example the robot fell)."""


class OutputError(GrfguardError, OSError):
    """An output cannot be written: the path is an input, a directory, not writable, or the
    disk filled up while writing (the previous file, if any, is left untouched)."""

    def __str__(self) -> str:  # OSError would format (errno, strerror); keep the message
        return str(self.args[0]) if self.args else ""


class GrfguardWarning(UserWarning):
    """Something in the input looks wrong but grfguard can go on (a time gap, a value
    outside its physical range, a robot TOML relying on defaults, ...)."""
