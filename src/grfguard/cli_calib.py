"""Command-line glue of the model self-calibration (``grfguard calibrate --model``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["fit_model_corrections", "corrected_log"]


def fit_model_corrections(
    frames: list[Any], mass_kg: float | None, console: Any = None
) -> tuple[list[Any], str]:
    """Fit :class:`~grfguard.calib.ModelCorrections` on fault-free logs.

    Returns:
        The corrected logs (thresholds are calibrated on them) and the
        ``[model_corrections]`` TOML text to append to the thresholds file.
    """
    from grfguard.calib import apply_corrections, estimate_corrections

    corr = estimate_corrections(frames, measured_mass_kg=mass_kg)
    if console is not None:
        console.print(f"model corrections: {corr.summary()}")
    return [apply_corrections(f, corr) for f in frames], "\n" + corr.to_toml()


def corrected_log(log: Any, thresholds_path: str | Path) -> Any:
    """``log`` with the ``[model_corrections]`` of the thresholds file applied (unchanged
    when the file has none)."""
    from grfguard.calib import ModelCorrections, apply_corrections

    return apply_corrections(log, ModelCorrections.from_toml(thresholds_path))
