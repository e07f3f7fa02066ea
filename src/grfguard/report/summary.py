"""Per-sensor summary of a ``grfguard run`` output: state, kind, size, delay, errors.

When ``grfguard.evaluate.detection`` metrics are given they win; otherwise a simple
fallback is computed here from the columns that are present:

* fault window: samples where ``fault_kind_<s>`` is not ``none`` (or, without a kind
  column, where ``fault_<s>`` is non-zero); onset = its first sample [s];
* alarm onsets: rising edges of ``flag_<s>`` (a flag already high at the first sample
  counts as an onset there);
* delay [s]: first alarm onset at or after the fault onset minus the fault onset (0
  if the flag was already high at the onset);
* false alarms: alarm episodes starting outside every fault window;
* size [N]: mean of the true fault (``fault_<s>``) and of the estimate (``eta_<s>``)
  over the last second of the fault window; size error = |estimate - true|;
* recovery RMSE [N]: RMS of ``recovered_<s> - true_force_<s>`` over the flagged
  samples of the fault window (``raw RMSE``: same for ``force_<s>``).

Undefined values are ``nan`` (never a sentinel number).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import LogFormatError
from grfguard.model.robot import SENSOR_NAMES

__all__ = [
    "sensor_summary",
    "normalize_metrics",
    "SUMMARY_COLUMNS",
    "detect_sensors",
    "fault_onsets",
    "alarm_onsets",
    "fault_mask",
]

#: Columns of :func:`sensor_summary`, with units in the names.
SUMMARY_COLUMNS: tuple[str, ...] = (
    "state",
    "injected_kind",
    "detected_kind",
    "kind_correct",
    "fault_onset_s",
    "alarm_onset_s",
    "delay_s",
    "false_alarms",
    "true_size_n",
    "estimated_size_n",
    "size_error_n",
    "recovery_rmse_n",
    "raw_rmse_n",
)

# Names other modules may use for the same quantity -> our column.
_METRIC_ALIASES: dict[str, str] = {
    "detected": "detected",
    "delay": "delay_s",
    "delay_s": "delay_s",
    "detection_delay_s": "delay_s",
    "false_alarms": "false_alarms",
    "n_false_alarms": "false_alarms",
    "false_alarm_episodes": "false_alarms",
    "kind_correct": "kind_correct",
    "recovery_rmse": "recovery_rmse_n",
    "recovery_rmse_n": "recovery_rmse_n",
    "fault_size_error": "size_error_n",
    "size_error": "size_error_n",
    "size_error_n": "size_error_n",
    "fault_size_error_n": "size_error_n",
    "detected_kind": "detected_kind",
    "kind": "detected_kind",
    "kind_estimated": "detected_kind",
    "injected_kind": "injected_kind",
    "true_kind": "injected_kind",
    "fault_kind": "injected_kind",
    "faulty": "faulty",
    "onset_s": "fault_onset_s",
    "fault_onset_s": "fault_onset_s",
    "alarm_onset_s": "alarm_onset_s",
    "first_alarm_s": "alarm_onset_s",
    "true_size_n": "true_size_n",
    "estimated_size_n": "estimated_size_n",
}


def detect_sensors(df: pd.DataFrame) -> list[str]:
    """Sensors that have at least one ``force_``/``vfs_``/``flag_`` column, in log order."""
    found = [
        s
        for s in SENSOR_NAMES
        if any(f"{p}_{s}" in df.columns for p in ("force", "vfs", "flag", "recovered", "eta"))
    ]
    # Other layouts (more sensors per foot): keep any force_<side><k> column too.
    for c in df.columns:
        if isinstance(c, str) and c.startswith("force_") and c[6:] not in found:
            name = c[6:]
            if len(name) >= 2 and name[0] in "rl" and name[1:].isdigit():
                found.append(name)
    return found


def _time(df: pd.DataFrame) -> np.ndarray:
    if "time" not in df.columns:
        raise LogFormatError(
            "the report needs a 'time' column [s]; got columns "
            f"{list(df.columns)[:8]}...; pass the output of `grfguard run`"
        )
    t = df["time"].to_numpy(dtype=float)
    if t.size > 1 and not np.all(np.diff(t) > 0):
        bad = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise LogFormatError(
            f"'time' must be strictly increasing; row {bad + 1} ({t[bad + 1]!r} s) does not "
            f"follow row {bad} ({t[bad]!r} s); sort the log or drop duplicate rows"
        )
    return t


def _not_none(ser: pd.Series) -> np.ndarray:
    """True where a text column holds a kind other than ``none``/empty/missing."""
    blank = ["none", "None", "NONE", "", "nan"]
    if isinstance(ser.dtype, pd.CategoricalDtype):  # decide per category, index by code
        ok = ~pd.Index(ser.cat.categories).isin(blank)
        codes = ser.cat.codes.to_numpy()
        return np.append(ok, False)[np.where(codes < 0, ok.size, codes)]
    bad = ser.isin(blank) | ser.isna()
    return ~bad.to_numpy(dtype=bool)


def fault_mask(df: pd.DataFrame, sensor: str) -> np.ndarray | None:
    """Boolean mask of the injected fault window of ``sensor``, or None if unknown."""
    kc, fc = f"fault_kind_{sensor}", f"fault_{sensor}"
    if kc in df.columns:
        return _not_none(df[kc])
    if fc in df.columns:
        f = df[fc].to_numpy(dtype=float)
        return np.nan_to_num(f) != 0.0
    return None


def fault_onsets(df: pd.DataFrame, sensor: str) -> np.ndarray:
    """Start times [s] of the injected fault windows of ``sensor`` (empty if none/unknown)."""
    m = fault_mask(df, sensor)
    if m is None or not m.any():
        return np.zeros(0)
    t = df["time"].to_numpy(dtype=float)
    return t[np.flatnonzero(np.diff(m.astype(np.int8), prepend=0) == 1)]


def alarm_onsets(df: pd.DataFrame, sensor: str) -> np.ndarray:
    """Times [s] at which ``flag_<sensor>`` rises (empty if no flag column)."""
    c = f"flag_{sensor}"
    if c not in df.columns:
        return np.zeros(0)
    f = df[c].fillna(False).to_numpy().astype(bool)
    t = df["time"].to_numpy(dtype=float)
    return t[np.flatnonzero(np.diff(f.astype(np.int8), prepend=0) == 1)]


def _mode(ser: pd.Series, mask: np.ndarray) -> str:
    """Most frequent kind other than ``none`` among the masked samples of a text column."""
    sub = ser[mask]
    sub = sub[_not_none(sub)]
    if sub.empty:
        return "none"
    counts = sub.value_counts()
    return str(counts.index[0])


def _rmse(a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(a**2))) if a.size else math.nan


def _fallback(df: pd.DataFrame, t: np.ndarray, s: str) -> dict[str, Any]:
    row: dict[str, Any] = dict.fromkeys(SUMMARY_COLUMNS, math.nan)
    fm = fault_mask(df, s)
    has_flag = f"flag_{s}" in df.columns
    flag = (
        df[f"flag_{s}"].fillna(False).to_numpy().astype(bool)
        if has_flag
        else np.zeros(t.size, dtype=bool)
    )
    rises = np.flatnonzero(np.diff(flag.astype(np.int8), prepend=0) == 1)
    injected = fm is not None and bool(fm.any())
    if fm is None:
        row["injected_kind"] = "unknown"
    elif not injected:
        row["injected_kind"] = "none"
    else:
        kc = f"fault_kind_{s}"
        row["injected_kind"] = _mode(df[kc], fm) if kc in df.columns else "fault"
    kc = f"kind_{s}"
    if kc in df.columns and flag.any():
        scope = flag & fm if injected and (flag & fm).any() else flag
        row["detected_kind"] = _mode(df[kc], scope)
    else:
        row["detected_kind"] = "none" if has_flag else "n/a"
    if injected:
        onset_i = int(np.flatnonzero(fm)[0])
        row["fault_onset_s"] = float(t[onset_i])
        in_fault_rises = rises[fm[rises]]
        if flag[onset_i]:
            row["alarm_onset_s"] = float(t[onset_i])
        elif in_fault_rises.size:
            row["alarm_onset_s"] = float(t[in_fault_rises[0]])
        if not math.isnan(row["alarm_onset_s"]):
            row["delay_s"] = row["alarm_onset_s"] - row["fault_onset_s"]
        row["false_alarms"] = int((~fm[rises]).sum()) if has_flag else math.nan
        row["kind_correct"] = (
            bool(row["detected_kind"] == row["injected_kind"])
            if row["detected_kind"] not in ("none", "n/a")
            else math.nan
        )
        last = fm & (t >= t[np.flatnonzero(fm)[-1]] - 1.0)
        if f"fault_{s}" in df.columns:
            row["true_size_n"] = float(np.nanmean(df[f"fault_{s}"].to_numpy(dtype=float)[last]))
        if f"eta_{s}" in df.columns:
            row["estimated_size_n"] = float(np.nanmean(df[f"eta_{s}"].to_numpy(dtype=float)[last]))
        row["size_error_n"] = abs(row["estimated_size_n"] - row["true_size_n"])
        tc = f"true_force_{s}"
        if tc in df.columns:
            true = df[tc].to_numpy(dtype=float)
            scope = fm & flag
            if f"recovered_{s}" in df.columns and scope.any():
                rec = df[f"recovered_{s}"].to_numpy(dtype=float)
                row["recovery_rmse_n"] = _rmse(rec[scope] - true[scope])
            if f"force_{s}" in df.columns and scope.any():
                raw = df[f"force_{s}"].to_numpy(dtype=float)
                row["raw_rmse_n"] = _rmse(raw[scope] - true[scope])
        detected = not math.isnan(row["alarm_onset_s"])
        row["state"] = "detected" if detected else ("missed" if has_flag else "faulty")
    else:
        row["false_alarms"] = int(rises.size) if has_flag else math.nan
        if rises.size:
            row["alarm_onset_s"] = float(t[rises[0]])
        if fm is None:
            row["state"] = "alarm" if flag.any() else "ok"
        else:
            row["state"] = "false alarm" if flag.any() else "healthy"
    return row


def normalize_metrics(metrics: Any) -> dict[str, dict[str, Any]]:
    """Per-sensor metrics as ``{sensor: {name: value}}``.

    Accepts None, a mapping sensor -> mapping, a DataFrame indexed by sensor (as
    ``grfguard.evaluate.detection.evaluate_detection`` returns) or with a ``sensor``
    column, or a list of records with a ``sensor`` key.

    Raises:
        LogFormatError: For any other shape.
    """
    if metrics is None:
        return {}
    if isinstance(metrics, pd.DataFrame):
        frame = metrics.set_index("sensor") if "sensor" in metrics.columns else metrics
        return {str(s): dict(r) for s, r in frame.to_dict(orient="index").items()}
    if isinstance(metrics, Mapping):
        out: dict[str, dict[str, Any]] = {}
        for s, m in metrics.items():
            if not isinstance(m, Mapping):
                raise LogFormatError(
                    f"metrics[{s!r}] must be a dict of metric values, got {type(m).__name__}; "
                    "pass {sensor: {metric: value}} or the DataFrame of evaluate_detection"
                )
            out[str(s)] = dict(m)
        return out
    if isinstance(metrics, (list, tuple)) and all(
        isinstance(r, Mapping) and "sensor" in r for r in metrics
    ):
        return {str(r["sensor"]): dict(r) for r in metrics}
    raise LogFormatError(
        f"metrics must be a dict sensor -> dict, a DataFrame indexed by sensor or a list of "
        f"records with a 'sensor' key; got {type(metrics).__name__}"
    )


def sensor_summary(
    df: pd.DataFrame, metrics: Mapping[str, Mapping[str, Any]] | None = None
) -> pd.DataFrame:
    """One row per sensor: state, kinds, onset, delay, false alarms, sizes, errors.

    Args:
        df: Output of ``grfguard run`` (``time`` [s] plus any of the per-sensor columns).
        metrics: Optional per-sensor metrics from ``grfguard.evaluate.detection``
            (anything :func:`normalize_metrics` accepts). Known keys (``delay_s``, ``false_alarms``,
            ``recovery_rmse_n``, ``size_error_n``, ``kind_correct``, ``detected`` ...)
            replace the fallback values; unknown keys are added as extra columns.

    Returns:
        DataFrame indexed by sensor name with :data:`SUMMARY_COLUMNS` (+ extras);
        ``nan`` where a value is undefined or its inputs are missing.

    Raises:
        LogFormatError: If ``time`` is missing or not strictly increasing, or
            ``metrics`` is not a mapping of mappings.
    """
    t = _time(df)
    rows = {s: _fallback(df, t, s) for s in detect_sensors(df)}
    for s, m in normalize_metrics(metrics).items():
        row = rows.setdefault(s, dict.fromkeys(SUMMARY_COLUMNS, math.nan))
        faulty, detected = None, None
        for key, value in m.items():
            col = _METRIC_ALIASES.get(str(key), str(key))
            v = value.item() if isinstance(value, np.generic) else value
            if col == "faulty":
                faulty = v if isinstance(v, bool) else None
            elif col == "detected":
                detected = v if isinstance(v, bool) else None
            elif col != "sensor":
                row[col] = v
        if detected is not None and faulty is not False:
            row["state"] = "detected" if detected else "missed"
        elif faulty is False:
            fa = row.get("false_alarms")
            row["state"] = (
                "false alarm" if isinstance(fa, (int, float)) and fa == fa and fa > 0 else "healthy"
            )
    out = pd.DataFrame.from_dict(rows, orient="index")
    out.index.name = "sensor"
    return out
