"""Validation shared by the frozen configs: one message format for an impossible value."""

from __future__ import annotations

import math
from typing import Any

from grfguard.errors import ConfigError

__all__ = ["check_number"]


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
