"""Threshold calibration from fault-free logs (``grfguard calibrate``).

Noise scales are robust (MAD) estimates of each test's residual over its valid phase;
CUSUM thresholds come from the exponential tail of the fault-free excursion peaks
(:func:`~grfguard.detect.blocks.threshold_for_rate`); the paper's eq. 33 thresholds are a
safety factor times the largest fault-free ``|η_f|``. The detector runs with infinite
thresholds and ``diagnostics=True`` (it never flags, so recovery plays no part).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
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

__all__ = ["calibrate_thresholds", "CornerTilt", "corner_tilt", "tilt_hint"]

_N = len(SENSOR_NAMES)


def _unreachable(th: Thresholds) -> Thresholds:
    """``th`` with every test's threshold out of reach: a detector that never flags, so
    its residuals stay those of a fault-free run."""
    return th.replace(swing_h=1e300, total_h=1e300, corner_h=1e300,
                      paper_eta_n=(1e300,) * 8)


def _fault_free_statistics(
    log: pd.DataFrame, config: MonitorConfig
) -> tuple[pd.DataFrame, DetectorInputs]:
    """The default detector's diagnostics over ``log`` (VFS columns reused or computed)
    with ``config``'s settings and no threshold in reach (nothing flagged), and the
    inputs it read."""
    cfg = config_for_log(log, replace(config, method="default", diagnostics=True,
                                      thresholds=_unreachable(config.thresholds)))
    vfs_cols = [vfs_col(s) for s in SENSOR_NAMES] + [f"vfs_total_{s}" for s in SIDES]
    if all(c in log.columns for c in vfs_cols):
        src = log
    else:
        from grfguard.estimate.vfs import VirtualForceSensor

        src = VirtualForceSensor.for_log(log, cfg.vfs, warm=False).run(log)
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


def _corner_summary(runs: Sequence[pd.DataFrame], sigma_c: float) -> dict:
    """``calibrate_thresholds``' ``summary``: ``corner_median`` (each corner residual's
    median over its valid phase, ``SENSOR_NAMES`` order [fraction of the weight], all
    runs pooled), ``corner_median_per_log`` (the same per run) and ``corner_sigma``."""
    res = [np.concatenate([run[f"res_corner_{s}"].to_numpy(float) for run in runs])
           for s in SENSOR_NAMES]
    return {
        "corner_median": np.array([_median(r) for r in res]),
        "corner_sigma": sigma_c,
        "corner_median_per_log": [
            np.array([_median(run[f"res_corner_{s}"].to_numpy(float)) for s in SENSOR_NAMES])
            for run in runs],
    }


def _median(r: np.ndarray) -> float:
    """Median of the finite values of ``r`` (0 when there is none)."""
    f = r[np.isfinite(r)]
    return float(np.median(f)) if f.size else 0.0


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
    summary: dict | None = None,
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
        summary: When given, filled with the corner residuals' medians and noise scale
            (:func:`_corner_summary`): the input of :func:`tilt_hint`.

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
    inf_th = _unreachable(base)
    runs = []
    paper_max = np.zeros(_N)
    hours = 0.0
    for log in logs:
        _check_fault_free(log)
        diag, inputs = _fault_free_statistics(log, cfg)
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
    if summary is not None:
        summary.update(_corner_summary(runs, sigma_c))
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


@dataclass(frozen=True)
class CornerTilt:
    """The steady part of the per-corner residuals that a shifted centre of pressure
    explains (:func:`corner_tilt`).

    Attributes:
        cop_shift_m: Measured minus estimated centre of pressure of a stance sole, sole
            frame (forward, left) [m], the two soles averaged.
        share: RMS of the residual medians that shift explains, as a fraction of the
            per-corner noise scale.
    """

    cop_shift_m: tuple[float, float]
    share: float

    #: ``share`` from which :func:`tilt_hint` reports the pattern: on the exact model's
    #: walks, IMU attitude errors of 1-4 mrad give 0.56-0.67 (self-calibration on the same
    #: walk lowers their per-corner threshold by 8-49 %), about 1 mrad 0.27-0.28 (2 %),
    #: corrected walks 0.09-0.14 (``benchmarks/bench_attitude_bias.py``).
    REPORT_SHARE = 0.4


def corner_tilt(corner_median: np.ndarray, corner_sigma: float,
                sensor_xy: np.ndarray) -> CornerTilt:
    """The centre-of-pressure shift that best explains the per-corner residual medians.

    In single support a stance sole carries about the whole weight, so a measured minus
    estimated CoP shift ``d`` gives corner ``i`` (sole frame position ``p_i``) a
    residual of about ``a_i d`` [fraction of the weight] with ``a_i`` the corner's
    share of a moment, the same for both soles (a constant IMU attitude error or trunk
    CoM offset moves both feet's CoP alike). ``d`` is the least-squares fit over the
    eight medians.

    Args:
        corner_median: Residual medians of ``r1..r4, l1..l4`` [fraction of the weight]
            (``calibrate_thresholds(summary=...)``).
        corner_sigma: The per-corner noise scale [fraction of the weight].
        sensor_xy: (4, 2) sensor positions in the sole frame [m]
            (``RobotConfig.sensor_positions_in_foot``).
    """
    med = np.asarray(corner_median, float).reshape(2, 4)
    p = np.asarray(sensor_xy, float)
    c = p - p.mean(axis=0)
    # force pattern of a CoP shift d for a fixed load: minimum-norm corner loads with
    # sum f = 0 and sum f c = d, i.e. f = c (c^T c)^-1 d
    A = c @ np.linalg.inv(c.T @ c)  # (4, 2): residual per corner = A d
    A2 = np.vstack([A, A])
    d, *_ = np.linalg.lstsq(A2, med.ravel(), rcond=None)
    fit = A2 @ d
    share = float(np.sqrt(np.mean(fit ** 2)) / corner_sigma) if corner_sigma > 0 else 0.0
    return CornerTilt(cop_shift_m=(float(d[0]), float(d[1])), share=share)


def tilt_hint(summary: dict, sensor_xy: np.ndarray) -> str | None:
    """What ``grfguard calibrate`` says about the steady centre-of-pressure shift of its
    logs (``calibrate_thresholds(summary=...)``): None when it explains less than
    :attr:`CornerTilt.REPORT_SHARE` of the per-corner noise scale in every log.

    A shift common to several logs is a constant error of the robot (IMU mounting, trunk
    CoM), which ``calibrate --model`` fits. A shift that changes from log to log is an
    attitude error of the IMU's own estimate (the simulated IMU's is drawn per run):
    ``--model`` fitted on one run is then wrong for the next (false alarms) and fitted on
    all of them leaves it in the thresholds (``benchmarks/bench_attitude_bias.py``). One
    log cannot tell the two apart.
    """
    sigma = summary["corner_sigma"]
    per = [corner_tilt(m, sigma, sensor_xy) for m in summary["corner_median_per_log"]]
    if not per or max(t.share for t in per) < CornerTilt.REPORT_SHARE:
        return None

    def where(t: CornerTilt) -> str:
        dx, dy = (1000 * v for v in t.cop_shift_m)
        parts = [f"{abs(v):.1f} mm {word[v < 0]}" for v, word in
                 ((dx, ("forward", "back")), (dy, ("to the left", "to the right")))
                 if abs(v) >= 0.05]
        return " and ".join(parts) or "0 mm"

    head = ("the load cells put each stance sole's centre of pressure {} of where the "
            "model does, all along the log{}: a steady pattern worth {:.0%} of the "
            "per-corner noise scale, which it inflates. ")
    if len(per) == 1:
        return head.format(where(per[0]), "", per[0].share) + (
            "A constant error of the robot (IMU mounting, trunk CoM offset) does this, and "
            "`grfguard calibrate --model` would fit it; so does an attitude error of the "
            "IMU's own estimate that changes from run to run, and fitted on one run that "
            "lowers the threshold below what the next run needs. Calibrate on logs of "
            "several runs to tell them apart")
    d = np.array([t.cop_shift_m for t in per])
    mean = d.mean(axis=0)
    common = bool(np.max(np.linalg.norm(d - mean, axis=1)) <= 0.5 * np.linalg.norm(mean))
    each = "; ".join(f"log {k + 1}: {where(t)}" for k, t in enumerate(per))
    pooled = corner_tilt(summary["corner_median"], sigma, sensor_xy)
    if common:
        return head.format(where(pooled), "s", pooled.share) + (
            f"It is common to the {len(per)} logs ({each}): a constant error of the "
            "robot (IMU mounting, trunk CoM offset); `grfguard calibrate --model` fits it "
            "and lowers the per-corner threshold")
    return (f"the load cells' centre of pressure is off the model's by a steady amount "
            f"that changes from log to log ({each}): an attitude error of the IMU's own "
            "estimate, not its mounting. `grfguard calibrate --model` would not remove "
            "it (one run's fit is wrong for the next); these thresholds cover it")
