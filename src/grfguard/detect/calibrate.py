"""Threshold calibration from fault-free logs (``grfguard calibrate``).

Noise scales are robust (MAD) estimates of each test's residual over its valid phase;
CUSUM thresholds come from the exponential tail of the fault-free excursion peaks
(:func:`~grfguard.detect.blocks.threshold_for_rate`); the paper's eq. 33 thresholds are a
safety factor times the largest fault-free ``|η_f|``. The detector runs with infinite
thresholds and ``diagnostics=True`` (it never flags, so recovery plays no part).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from grfguard._lazy import lazy_module
from grfguard.detect.blocks import cusum as cusum_batch
from grfguard.detect.blocks import excursion_peaks, robust_scale, threshold_for_rate
from grfguard.detect.config import MonitorConfig, config_for_log
from grfguard.detect.detector import Detector, DetectorInputs
from grfguard.detect.paper import PaperDetector
from grfguard.detect.thresholds import Thresholds
from grfguard.errors import ConfigError
from grfguard.io.schema import TIME, vfs_col
from grfguard.model.robot import SENSOR_NAMES, SIDES

pd = lazy_module("pandas")  # (imported on first use: `grfguard run` never does)

__all__ = ["calibrate_thresholds"]

_N = len(SENSOR_NAMES)


def _fault_free_statistics(
    log: pd.DataFrame, config: MonitorConfig
) -> tuple[pd.DataFrame, DetectorInputs]:
    """The default detector's diagnostics over ``log`` (VFS columns reused or computed)
    and the inputs it read."""
    cfg = config_for_log(log, config)
    vfs_cols = [vfs_col(s) for s in SENSOR_NAMES] + [f"vfs_total_{s}" for s in SIDES]
    if all(c in log.columns for c in vfs_cols):
        src = log
    else:
        from grfguard.estimate.vfs import VirtualForceSensor

        src = VirtualForceSensor.for_log(log, cfg.vfs).run(log)
    inputs = DetectorInputs.from_frames(log, src)
    det = Detector(cfg)
    rows = [det.step(*inputs.sample(k)).diagnostics for k in range(len(log))]
    return pd.DataFrame(rows, index=log.index), inputs


def _scale(runs: Sequence[pd.DataFrame], prefix: str, names: Sequence[str],
           fallback: float) -> float:
    """Robust scale of the residual columns ``<prefix><name>`` over all runs (``fallback``
    when no sample was valid)."""
    r = np.concatenate([run[[f"{prefix}{s}" for s in names]].to_numpy(float).ravel()
                        for run in runs])
    return float(robust_scale(r[np.isfinite(r)])) if np.isfinite(r).any() else fallback


def _peaks(runs: Sequence[pd.DataFrame], prefix: str, names: Sequence[str], sigma: float,
           kappa: float) -> np.ndarray:
    """Excursion peaks of the un-reset CUSUM of every normalised residual column."""
    out = []
    for r in runs:
        for nm in names:
            res = r[f"{prefix}{nm}"].to_numpy(float)
            m = np.isfinite(res)
            if not m.any():
                continue
            g = cusum_batch(res[m] / sigma, kappa, 1e300, reset=False)
            out.append(excursion_peaks(np.maximum(g.g_pos, g.g_neg)))
    return np.concatenate(out) if out else np.zeros(0)


def _check_fault_free(log: pd.DataFrame) -> None:
    if any(c in log.columns and (log[c].astype(str) != "none").any()
           for c in (f"fault_kind_{s}" for s in SENSOR_NAMES)):
        raise ConfigError("calibrate_thresholds needs fault-free logs; this one has "
                          "injected faults (fault_kind_* != 'none')")


def calibrate_thresholds(
    logs: Sequence[pd.DataFrame],
    false_alarm_rate_per_hour: float = 0.1,
    config: MonitorConfig | str | Path | None = None,
    safety: float = 1.5,
    min_h: float = 30.0,
) -> Thresholds:
    """Calibrate every threshold from fault-free logs for a stated false-alarm rate.

    Noise scales are robust (MAD) estimates over the valid phase of each test; CUSUM
    thresholds come from the exponential tail of the fault-free excursion peaks
    (:func:`~grfguard.detect.blocks.threshold_for_rate`), with the target rate split
    evenly over the 8 swing, 8 corner and 2 foot-total tests, and never below ``safety``
    times the largest peak seen. The paper's eq. 33 thresholds are ``safety`` times the
    largest fault-free ``|η_f|`` per sensor (its own tuning rule: the fault-free run).

    Args:
        logs: Fault-free logs (with or without VFS columns).
        false_alarm_rate_per_hour: Target rate of the whole detector [1/h].
        config: Monitor config (or a TOML path); its gates and CUSUM allowances are used.
        safety: Factor on the largest fault-free statistic.
        min_h: Lower bound of every CUSUM threshold [σ·samples] (a margin for walks
            unlike the calibration ones).

    Returns:
        New :class:`Thresholds`.
    """
    if isinstance(config, (str, Path)):
        config = MonitorConfig.from_toml(config)
    cfg = config if config is not None else MonitorConfig()
    if not logs:
        raise ConfigError("calibrate_thresholds needs at least one fault-free log")
    if not (false_alarm_rate_per_hour > 0):
        raise ConfigError(
            f"false_alarm_rate_per_hour = {false_alarm_rate_per_hour!r} must be > 0"
        )
    base = cfg.thresholds
    inf_th = base.replace(swing_h=1e300, total_h=1e300, corner_h=1e300,
                          paper_eta_n=(1e300,) * 8)
    runs = []
    paper_max = np.zeros(_N)
    hours = 0.0
    for log in logs:
        _check_fault_free(log)
        diag, inputs = _fault_free_statistics(
            log, replace(cfg, method="default", thresholds=inf_th, diagnostics=True))
        runs.append(diag)
        t = log[TIME].to_numpy(float)
        hours += (t[-1] - t[0]) / 3600.0
        paper = PaperDetector(replace(cfg, method="paper", thresholds=inf_th, diagnostics=True))
        pout = paper.run(np.array(inputs.t), np.array(inputs.x).T, np.array(inputs.v).T)
        etaf = np.column_stack([pout[f"eta_filtered_{s}"] for s in SENSOR_NAMES])
        paper_max = np.maximum(paper_max, np.nanmax(np.abs(etaf), axis=0))
    rate = false_alarm_rate_per_hour / 18.0
    sigma_sw = _scale(runs, "res_swing_", SENSOR_NAMES, base.sigma_swing_n)
    sigma_t = _scale(runs, "res_total_", SIDES, base.total_sigma)
    sigma_c = _scale(runs, "res_corner_", SENSOR_NAMES, base.corner_sigma)
    p_sw = _peaks(runs, "res_swing_", SENSOR_NAMES, sigma_sw, base.swing_kappa)
    p_t = _peaks(runs, "res_total_", SIDES, sigma_t, base.total_kappa)
    p_c = _peaks(runs, "res_corner_", SENSOR_NAMES, sigma_c, base.corner_kappa)
    h_sw = threshold_for_rate(p_sw, hours * 8, rate, safety, floor=min_h)
    h_t = threshold_for_rate(p_t, hours * 2, rate, safety, floor=min_h)
    h_c = threshold_for_rate(p_c, hours * 8, rate, safety, floor=min_h)
    paper_tr = tuple(float(max(safety * m, 1.0)) for m in paper_max)
    return base.replace(
        sigma_swing_n=sigma_sw,
        swing_h=h_sw,
        total_sigma=sigma_t,
        total_h=h_t,
        corner_sigma=sigma_c,
        corner_h=h_c,
        paper_eta_n=paper_tr,
        false_alarm_rate_per_hour=float(false_alarm_rate_per_hour),
        source=f"calibrated on {len(logs)} fault-free log(s), {hours * 60:.1f} min",
    )
