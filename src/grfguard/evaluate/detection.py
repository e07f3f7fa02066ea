"""Detection metrics: alarms matched to the injected truth windows (STYLE.md item 7).

The one definition of every detection metric: ``grfguard evaluate``, the demo, the
benchmarks and the report (:func:`grfguard.report.summary.sensor_summary`) all read them
from here.

For each sensor ``s`` the truth window is where ``fault_kind_<s> != "none"`` (from
:func:`grfguard.faults.inject_faults`), the alarms are the rising edges of
``flag_<s>`` (from a detector). Metrics, NaN where undefined:

- ``detected``: the flag is on at some sample inside a truth window (or within
  ``tolerance_s`` after its end);
- ``delay_s``: first flagged time in the window minus the onset [s];
- ``false_alarms`` / ``false_alarm_time_s``: flag episodes starting outside every
  window (extended by ``tolerance_s``) and their total duration [s];
- ``kind_estimated`` / ``kind_correct``: the estimated kind at the last flagged sample of
  the window vs the injected kind;
- ``recovery_rmse_n``: RMSE of ``recovered_<s> - true_force_<s>`` in stance (planned contact
  of the foot, or true foot load when no plan) after detection [N]; ``raw_rmse_n``: the
  same for the unrecovered reading ``force_<s>``;
- ``fault_size_error_n``: RMSE of ``eta_<s> - fault_<s>`` after detection [N];
- ``true_size_n`` / ``estimated_size_n``: mean of ``fault_<s>`` / ``eta_<s>`` over the last
  second of the window [N] (what the report shows as the fault size).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from grfguard.errors import LogFormatError
from grfguard.io.schema import (
    TIME,
    eta_col,
    fault_col,
    fault_kind_col,
    flag_col,
    force_col,
    kind_col,
    recovered_col,
    true_force_col,
)
from grfguard.model.robot import SENSOR_NAMES

__all__ = [
    "evaluate_detection",
    "sensor_detection",
    "truth_windows",
    "flag_episodes",
    "summarize_detection",
]

#: Foot load above which a foot counts as in stance when the log has no plan [N].
_STANCE_LOAD_N = 20.0
#: Length of the end of a fault window over which its size is averaged [s].
_SIZE_WINDOW_S = 1.0


def _segments(mask: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges ``[i0, i1)`` where ``mask`` is true."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]]).astype(int)
    d = np.flatnonzero(np.diff(m))
    return list(zip(d[0::2].tolist(), d[1::2].tolist(), strict=True))


def truth_windows(log: pd.DataFrame, sensor: str) -> list[tuple[float, float, str]]:
    """Injected fault windows of ``sensor`` as ``(start_s, end_s, kind)``."""
    col = fault_kind_col(sensor)
    if col not in log.columns:
        return []
    kinds = log[col].astype(str).to_numpy()
    t = log[TIME].to_numpy(dtype=float)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    out = []
    for i0, i1 in _segments(kinds != "none"):
        out.append((float(t[i0]), float(t[i1 - 1]) + dt, str(kinds[i0])))
    return out


def flag_episodes(time_s: np.ndarray, flag: np.ndarray) -> list[tuple[float, float]]:
    """Flag-on episodes as ``(start_s, end_s)``."""
    t = np.asarray(time_s, dtype=float)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    return [(float(t[a]), float(t[b - 1]) + dt) for a, b in _segments(flag)]


def _stance(log: pd.DataFrame, side: str) -> np.ndarray | None:
    """Planned stance of a foot, or its true load above 20 N; None if neither is known."""
    if f"contact_ref_{side}" in log.columns:
        return log[f"contact_ref_{side}"].to_numpy(dtype=float) > 0.5
    cols = [true_force_col(f"{side}{k}") for k in range(1, 5)]
    if not all(c in log.columns for c in cols):
        return None
    return sum(log[c].to_numpy(dtype=float) for c in cols) > _STANCE_LOAD_N


def _nanmean(x: np.ndarray) -> float:
    """Mean ignoring NaN; NaN (without a warning) when nothing is left."""
    return float(np.nanmean(x)) if np.any(~np.isnan(x)) else np.nan


def _rmse_between(a: pd.Series, b: pd.Series, mask: np.ndarray, finite: bool) -> float:
    """RMSE of ``a - b`` over ``mask`` [N] (``finite``: ignore non-finite differences)."""
    d = a.to_numpy(dtype=float)[mask] - b.to_numpy(dtype=float)[mask]
    if finite:
        d = d[np.isfinite(d)]
        return float(np.sqrt(np.mean(d**2))) if d.size else np.nan
    return float(np.sqrt(_nanmean(d**2)))


def _empty_row(sensor: str, wins: list[tuple[float, float, str]]) -> dict[str, object]:
    return {
        "sensor": sensor,
        "faulty": bool(wins),
        "fault_kind": wins[0][2] if wins else "none",
        "onset_s": wins[0][0] if wins else np.nan,
        "detected": np.nan,
        "delay_s": np.nan,
        "false_alarms": 0,
        "false_alarm_time_s": 0.0,
        "kind_estimated": "none",
        "kind_correct": np.nan,
        "recovery_rmse_n": np.nan,
        "fault_size_error_n": np.nan,
        "raw_rmse_n": np.nan,
        "true_size_n": np.nan,
        "estimated_size_n": np.nan,
    }


def _after_detection(
    row: dict[str, object], log: pd.DataFrame, out: pd.DataFrame, s: str,
    t: np.ndarray, i_det: int, end_s: float,
) -> None:
    """Recovery and fault-size errors from detection to the end of the window."""
    after = (t >= t[i_det]) & (t < end_s)
    truth = true_force_col(s)
    stance = _stance(log, s[0]) if truth in log.columns else None
    if stance is not None and (after & stance).any():
        m = after & stance
        if recovered_col(s) in out.columns:
            row["recovery_rmse_n"] = _rmse_between(out[recovered_col(s)], log[truth], m, False)
        if force_col(s) in log.columns:
            row["raw_rmse_n"] = _rmse_between(log[force_col(s)], log[truth], m, False)
    if eta_col(s) in out.columns and fault_col(s) in log.columns:
        row["fault_size_error_n"] = _rmse_between(out[eta_col(s)], log[fault_col(s)], after, True)


def sensor_detection(
    log: pd.DataFrame, output: pd.DataFrame, sensor: str, tolerance_s: float = 1.0
) -> dict[str, object]:
    """The metrics of one sensor (a row of :func:`evaluate_detection`).

    A missing ``flag_<s>`` column counts as a flag that never rose; other missing
    columns leave their metrics NaN.
    """
    s, out = sensor, output
    t = log[TIME].to_numpy(dtype=float)
    flag = (
        out[flag_col(s)].to_numpy(dtype=bool) if flag_col(s) in out.columns
        else np.zeros(len(t), bool)
    )
    wins = truth_windows(log, s)
    row = _empty_row(s, wins)
    in_win_tol = np.zeros(len(t), bool)
    for a, b, _ in wins:
        in_win_tol |= (t >= a) & (t < b + tolerance_s)
    fa = [(a, b) for a, b in flag_episodes(t, flag) if not np.any(in_win_tol[(t >= a) & (t < b)])]
    row["false_alarms"] = len(fa)
    row["false_alarm_time_s"] = float(sum(b - a for a, b in fa))
    if not wins:
        return row
    a0, b0, kind0 = wins[0]
    last = (t >= b0 - _SIZE_WINDOW_S) & (t < b0)
    if fault_col(s) in log.columns:
        row["true_size_n"] = _nanmean(log[fault_col(s)].to_numpy(dtype=float)[last])
    if eta_col(s) in out.columns:
        row["estimated_size_n"] = _nanmean(out[eta_col(s)].to_numpy(dtype=float)[last])
    sel = (t >= a0) & (t < b0 + tolerance_s) & flag
    row["detected"] = bool(sel.any())
    if not row["detected"]:
        return row
    i_det = int(np.flatnonzero(sel)[0])
    row["delay_s"] = float(t[i_det] - a0)
    in_w_flag = np.flatnonzero((t >= a0) & (t < b0) & flag)
    if kind_col(s) in out.columns and in_w_flag.size:
        row["kind_estimated"] = str(out[kind_col(s)].iloc[in_w_flag[-1]])
        row["kind_correct"] = row["kind_estimated"] == kind0
    _after_detection(row, log, out, s, t, i_det, b0)
    return row


def evaluate_detection(
    log: pd.DataFrame,
    output: pd.DataFrame | None = None,
    tolerance_s: float = 1.0,
    sensors: tuple[str, ...] = SENSOR_NAMES,
) -> pd.DataFrame:
    """Per-sensor detection metrics of a detector output against the injected truth.

    Args:
        log: Log with ``time``, ``fault_<s>``, ``fault_kind_<s>`` (and ``true_force_<s>``,
            ``contact_ref_<side>`` for the recovery error).
        output: Detector output with ``flag_<s>`` (and ``kind_<s>``, ``eta_<s>``,
            ``recovered_<s>``); defaults to ``log`` itself.
        tolerance_s: Time after a window's end during which a flag still counts as
            belonging to it [s].
        sensors: Sensors to evaluate.

    Returns:
        One row per sensor (index ``sensor``), see :func:`sensor_detection`.

    Raises:
        LogFormatError: If ``time`` or a ``flag_<s>`` column is missing.
    """
    out = log if output is None else output
    if TIME not in log.columns:
        raise LogFormatError("evaluate_detection: the log has no 'time' column [s]")
    if len(out) != len(log):
        raise LogFormatError(
            f"evaluate_detection: output has {len(out)} rows, the log {len(log)}; "
            "pass the detector output of this very log"
        )
    for s in sensors:
        if flag_col(s) not in out.columns:
            raise LogFormatError(f"evaluate_detection: output lacks column {flag_col(s)!r}")
    rows = [sensor_detection(log, out, s, tolerance_s) for s in sensors]
    return pd.DataFrame(rows).set_index("sensor")


def summarize_detection(table: pd.DataFrame, duration_s: float) -> dict[str, float]:
    """Aggregate a per-sensor table: detection rate, mean delay, false alarms per hour."""
    faulty = table[table["faulty"]]
    n_fa = float(table["false_alarms"].sum())
    return {
        "n_faults": float(len(faulty)),
        "detection_rate": float(faulty["detected"].astype(float).mean()) if len(faulty) else np.nan,
        "mean_delay_s": float(faulty["delay_s"].mean()) if len(faulty) else np.nan,
        "false_alarms": n_fa,
        "false_alarms_per_hour": n_fa / (duration_s / 3600.0) if duration_s > 0 else np.nan,
        "kind_accuracy": float(faulty["kind_correct"].astype(float).mean())
        if len(faulty)
        else np.nan,
    }
