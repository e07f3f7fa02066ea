"""Validation shared by the frozen configs: one message format for an impossible value."""

from __future__ import annotations

import math
from typing import Any

from grfguard.errors import ConfigError

__all__ = ["check_number", "check_period"]


def check_number(
    owner: str, name: str, value: Any, lo: float, hi: float, unit: str, fix: str = ""
) -> None:
    """Raise :class:`ConfigError` unless ``value`` is a finite number in ``[lo, hi]``.

    Args:
        owner: Config table name (``robot``, ``gait``, ``vfs``, ...).
        name: Field name.
        value: The value to check.
        lo: Smallest allowed value.
        hi: Largest allowed value.
        unit: Unit shown in the message (``m``, ``kg``, ``s`` or empty).
        fix: Optional hint appended to the message (how to fix it).
    """
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        raise ConfigError(f"{owner}.{name} must be a number, got {value!r}")
    if not math.isfinite(value) or not (lo <= value <= hi):
        msg = f"{owner}.{name} = {value!r} {unit} is outside the allowed range [{lo}, {hi}] {unit}"
        raise ConfigError(f"{msg}; {fix}" if fix else msg)


def check_period(owner: str, dt_s: Any) -> float:
    """The sampling period ``dt_s`` as a float [s]; :class:`ConfigError` naming ``owner``
    unless it is a number in (0, 1) s.

    Real robots log at 100 Hz to 1 kHz: a stage that integrates or filters in time takes
    the log's period (``MonitorConfig.dt_s`` set by ``config_for_log`` / ``for_log``), never
    an assumed 1 ms.
    """
    if isinstance(dt_s, bool) or not isinstance(dt_s, (int, float)) or not (
            0.0 < float(dt_s) < 1.0):
        raise ConfigError(f"{owner}: dt_s = {dt_s!r} must be the log's sampling period, "
                          "a number in (0, 1) s (e.g. 0.01 for a 100 Hz log; the monitor "
                          "passes its config.dt_s, set from the log's time column)")
    return float(dt_s)
