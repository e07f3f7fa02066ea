"""Detection metrics: alarms matched to the injected truth windows (STYLE.md item 7).

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
  of the foot, or true foot load when no plan) after detection [N];
- ``fault_size_error_n``: RMSE of ``eta_<s> - fault_<s>`` after detection [N].
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
    kind_col,
    recovered_col,
    true_force_col,
)
from grfguard.model.robot import SENSOR_NAMES

__all__ = ["evaluate_detection", "truth_windows", "flag_episodes", "summarize_detection"]


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
        One row per sensor (index ``sensor``).

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
    t = log[TIME].to_numpy(dtype=float)
    rows = []
    for s in sensors:
        if flag_col(s) not in out.columns:
            raise LogFormatError(f"evaluate_detection: output lacks column {flag_col(s)!r}")
        flag = out[flag_col(s)].to_numpy(dtype=bool)
        wins = truth_windows(log, s)
        in_win = np.zeros(len(t), bool)
        in_win_tol = np.zeros(len(t), bool)
        for a, b, _ in wins:
            in_win |= (t >= a) & (t < b)
            in_win_tol |= (t >= a) & (t < b + tolerance_s)
        eps = flag_episodes(t, flag)
        fa = [(a, b) for a, b in eps if not np.any(in_win_tol[(t >= a) & (t < b)])]
        row: dict[str, object] = {
            "sensor": s,
            "faulty": bool(wins),
            "fault_kind": wins[0][2] if wins else "none",
            "onset_s": wins[0][0] if wins else np.nan,
            "detected": np.nan,
            "delay_s": np.nan,
            "false_alarms": len(fa),
            "false_alarm_time_s": float(sum(b - a for a, b in fa)),
            "kind_estimated": "none",
            "kind_correct": np.nan,
            "recovery_rmse_n": np.nan,
            "fault_size_error_n": np.nan,
        }
        if wins:
            a0, b0, kind0 = wins[0]
            sel = (t >= a0) & (t < b0 + tolerance_s) & flag
            detected = bool(sel.any())
            row["detected"] = detected
            if detected:
                i_det = int(np.flatnonzero(sel)[0])
                row["delay_s"] = float(t[i_det] - a0)
                in_w_flag = np.flatnonzero((t >= a0) & (t < b0) & flag)
                if kind_col(s) in out.columns and in_w_flag.size:
                    k_est = str(out[kind_col(s)].iloc[in_w_flag[-1]])
                    row["kind_estimated"] = k_est
                    row["kind_correct"] = k_est == kind0
                after = (t >= t[i_det]) & (t < b0)
                if recovered_col(s) in out.columns and true_force_col(s) in log.columns:
                    side = s[0]
                    if f"contact_ref_{side}" in log.columns:
                        stance = log[f"contact_ref_{side}"].to_numpy(dtype=float) > 0.5
                    else:
                        tot = sum(
                            log[true_force_col(f"{side}{k}")].to_numpy(dtype=float)
                            for k in range(1, 5)
                        )
                        stance = tot > 20.0
                    m = after & stance
                    if m.any():
                        err = out[recovered_col(s)].to_numpy(dtype=float)[m] - log[
                            true_force_col(s)
                        ].to_numpy(dtype=float)[m]
                        row["recovery_rmse_n"] = float(np.sqrt(np.nanmean(err**2)))
                if eta_col(s) in out.columns and fault_col(s) in log.columns:
                    d = (
                        out[eta_col(s)].to_numpy(dtype=float)[after]
                        - log[fault_col(s)].to_numpy(dtype=float)[after]
                    )
                    d = d[np.isfinite(d)]
                    if d.size:
                        row["fault_size_error_n"] = float(np.sqrt(np.mean(d**2)))
        rows.append(row)
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
