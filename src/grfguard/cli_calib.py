"""Command-line glue of the model self-calibration (``grfguard calibrate --model``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["fit_model_corrections", "corrected_log_and_config"]


def fit_model_corrections(
    frames: list[Any], mass_kg: float | None, console: Any = None, config: Any = None,
    false_alarm_rate_per_hour: float = 0.1,
) -> tuple[list[Any], str, Any]:
    """Fit :class:`~grfguard.calib.ModelCorrections` on fault-free logs.

    Args:
        frames: Fault-free logs.
        mass_kg: Weighed mass [kg] or None.
        console: Where the summary goes (None: nowhere).
        config: Monitor config (``MonitorConfig``, a TOML path or None).
        false_alarm_rate_per_hour: The rate the thresholds will be calibrated at
            (``grfguard calibrate --false-alarm-rate``): the filter is chosen at it too.

    Returns:
        The corrected logs (thresholds are calibrated on them), the
        ``[model_corrections]`` TOML text to append to the thresholds file, and the
        monitor config to calibrate the thresholds with (the accelerometer left out of
        the virtual sensor when it vibrates, with the rate low-pass chosen on these logs
        by :func:`grfguard.calib.twin_filter.choose_twin_filter` at
        ``false_alarm_rate_per_hour``).
    """
    from grfguard.calib import apply_corrections, corrected_config, estimate_corrections
    from grfguard.calib.twin_filter import choose_twin_filter
    from grfguard.detect import MonitorConfig

    corr = estimate_corrections(frames, measured_mass_kg=mass_kg)
    if isinstance(config, (str, Path)):
        config = MonitorConfig.from_toml(config)
    fixed = [apply_corrections(f, corr) for f in frames]
    corr, rows = choose_twin_filter(fixed, corr, config,  # accelerometer left out only
                                    false_alarm_rate_per_hour=false_alarm_rate_per_hour)
    if rows:
        fixed = [apply_corrections(f, corr) for f in frames]  # records the chosen filter
    if console is not None:
        console.print(f"model corrections: {corr.summary()}")
        if rows:
            console.print("accelerometer-free sensor's rate low-pass (per-corner / "
                          "foot-total threshold on the calibration data): " + "; ".join(
                              f"{r['cutoff_hz']:g} Hz "
                              + ("Butterworth" if r["damping"] is None
                                 else f"damping {r['damping']:g}")
                              + f" {r['corner']:.3f} / {r['total']:.3f}"
                              + (" (chosen)" if r["chosen"] else "") for r in rows))
    return fixed, "\n" + corr.to_toml(), corrected_config(config, corr)


def corrected_log_and_config(log: Any, thresholds_path: str | Path, config: Any) -> Any:
    """``(log, config)`` with the ``[model_corrections]`` of the thresholds file applied:
    the corrected log and the monitor config the corrections call for (the accelerometer
    left out of the virtual sensor when it vibrated during calibration)."""
    from grfguard.calib import ModelCorrections, apply_corrections, corrected_config

    corr = ModelCorrections.from_toml(thresholds_path)
    return apply_corrections(log, corr), corrected_config(config, corr)
