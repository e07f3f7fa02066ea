"""Choice of the accelerometer-free virtual sensor's rate low-pass on the calibration data.

When the accelerometer vibrates, the corrected monitor runs the virtual sensor without it
(:func:`grfguard.calib.corrected_config`), and the horizontal CoM acceleration then comes
from the leg odometry's finite differences through the rate low-pass
(``VFSConfig.filter_cutoff``). Its lag (22.5 ms for the 10 Hz Butterworth) is most of the
per-corner error left after calibration (BENCHMARKS.md "Model self-calibration: per-corner
noise of the accelerometer-free sensor"); a second-order low-pass damped less than the
Butterworth lags less but rings at the walk's transients, by an amount that depends on the
robot. So :func:`choose_twin_filter` tries a small grid of (cut-off, damping) on the
corrected calibration data itself and keeps the one with the lowest calibrated per-corner
threshold ``sigma * h`` (a ringing filter raises ``h``: the fault-free CUSUM peaks grow),
if it beats the default quiet twin by a margin and does not raise the foot-total
threshold. Only the calibration logs are read (never a simulation's truth). The grid
stops at damping 0.45: how much a filter rings on gaits unlike the calibration walk is
invisible in the calibration data, and below that it rang on other walks of the
all-gaps robot (:data:`TWIN_FILTER_GRID`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

__all__ = ["TWIN_FILTER_GRID", "TWIN_FILTER_MIN_GAIN", "choose_twin_filter"]

#: (cut-off [Hz], damping ratio or None for the Butterworth) tried by
#: :func:`choose_twin_filter`; the first is the default quiet twin
#: (:func:`grfguard.detect.system.quiet_vfs_config`). Damping 0.45 or more only: the
#: calibration data cannot see how much a filter rings on other gaits (a ringing filter
#: raises ``h`` on them, not on it). Measured on the all-gaps robot (calibration poses +
#: walk, seed 1; 10 min of other walks, five gaits, seeds 11-20; healthy-sensor alarm
#: episodes): 10 Hz Butterworth 0, 10 Hz 0.5 0, 9 Hz 0.5 0, 8 Hz 0.5 0, 8 Hz 0.45 0,
#: 8 Hz 0.42 1, 8 Hz 0.4 4, 7 Hz 0.4 5, 7 Hz 0.35 7, 7 Hz 0.3 20, while the calibrated
#: per-corner threshold kept falling (0.715, 0.646, 0.632, 0.639, 0.611, 0.597, 0.590,
#: 0.594, 0.569, 0.563); 8.5 Hz 0.45 (0.610) and 7.5 Hz 0.45 (0.619): 0 episodes.
TWIN_FILTER_GRID: tuple[tuple[float, float | None], ...] = (
    (10.0, None), (10.0, 0.5), (9.0, 0.5), (8.0, 0.5), (8.0, 0.45),
)
#: Fraction of the default twin's per-corner threshold a damped setting must gain to be
#: chosen (a margin against fitting the calibration data's own noise).
TWIN_FILTER_MIN_GAIN = 0.03
#: Largest rise of the foot-total threshold a chosen setting may cause (fraction).
TWIN_FILTER_MAX_TOTAL_RISE = 0.10


def choose_twin_filter(
    logs: Sequence[Any], corr: Any, config: Any = None,
    false_alarm_rate_per_hour: float = 0.1,
    grid: Sequence[tuple[float, float | None]] | None = None,
) -> tuple[Any, list[dict[str, Any]]]:
    """The corrections with the accelerometer-free sensor's rate low-pass chosen.

    Args:
        logs: The calibration logs, corrected (:func:`~grfguard.calib.apply_corrections`
            with ``corr``).
        corr: The :class:`~grfguard.calib.ModelCorrections` fitted on them.
        config: Monitor config (``MonitorConfig`` or None for the default).
        false_alarm_rate_per_hour: As :func:`~grfguard.detect.calibrate_thresholds`.
        grid: Settings tried (None: :data:`TWIN_FILTER_GRID`), the first being the
            reference (kept unless another gains
            ``TWIN_FILTER_MIN_GAIN`` of its per-corner threshold without raising the
            foot-total one by more than ``TWIN_FILTER_MAX_TOTAL_RISE``).

    Returns:
        ``(corr', rows)``: ``corr`` with ``twin_filter_cutoff_hz`` and
        ``twin_filter_damping`` set (unchanged when the accelerometer is used or the
        monitor's sensor is not the multibody one), and one row per setting tried
        (``cutoff_hz``, ``damping``, ``corner``, ``total``: thresholds ``sigma * h``).
    """
    from grfguard.calib.selfcal import corrected_config
    from grfguard.detect import calibrate_thresholds

    grid = list(TWIN_FILTER_GRID if grid is None else grid)
    base = dataclasses.replace(corr, twin_filter_cutoff_hz=None, twin_filter_damping=None)
    cfg0 = corrected_config(config, base)
    if corr.use_accelerometer or cfg0.vfs is None or cfg0.vfs.use_accelerometer:
        return corr, []
    if cfg0.vfs.filter_order != 2:  # the damping shapes a second-order low-pass only
        grid = [g for g in grid if g[1] is None]
    rows: list[dict[str, Any]] = []
    for cut, zeta in grid:
        cfg = cfg0.replace(vfs=cfg0.vfs.replace(filter_cutoff=float(cut), filter_damping=zeta))
        th = calibrate_thresholds(list(logs), false_alarm_rate_per_hour, config=cfg)
        rows.append({"cutoff_hz": float(cut), "damping": zeta,
                     "corner": th.corner_sigma * th.corner_h,
                     "total": th.total_sigma * th.total_h})
    ref = rows[0]
    ok = [r for r in rows[1:] if r["corner"] <= (1 - TWIN_FILTER_MIN_GAIN) * ref["corner"]
          and r["total"] <= (1 + TWIN_FILTER_MAX_TOTAL_RISE) * ref["total"]]
    best = min(ok, key=lambda r: r["corner"]) if ok else ref
    for r in rows:
        r["chosen"] = r is best
    return dataclasses.replace(corr, twin_filter_cutoff_hz=best["cutoff_hz"],
                               twin_filter_damping=best["damping"]), rows
