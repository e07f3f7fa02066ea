"""Per-sensor summary of a ``grfguard run`` output: state, kind, size, delay, errors.

Every metric (delay, false alarms, kind, fault size and its error, recovery and raw RMSE)
is :func:`grfguard.evaluate.detection.sensor_detection`'s, under the same name, so the
report and ``grfguard evaluate`` print the same numbers. The report adds what only it
needs:

* ``state``: detected / missed (faulty sensor), false alarm / healthy (no fault), alarm /
  ok (no truth in the log);
* ``injected_kind``: the injected kind (``unknown`` without truth columns, ``none`` when
  healthy); ``alarm_onset_s``: fault onset plus delay, or the first flag rise of a sensor
  without a fault [s].

The fault windows drawn in the figures are where ``fault_kind_<s>`` is not ``none`` (or,
without a kind column, where ``fault_<s>`` is non-zero). Undefined values are ``nan``
(never a sentinel number).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import LogFormatError
from grfguard.evaluate.detection import sensor_detection
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
    "kind_estimated",
    "kind_correct",
    "onset_s",
    "alarm_onset_s",
    "delay_s",
    "false_alarms",
    "false_alarm_time_s",
    "true_size_n",
    "estimated_size_n",
    "fault_size_error_n",
    "recovery_rmse_n",
    "raw_rmse_n",
)

# evaluate_detection's name of the injected kind -> the report's column (every other
# metric has the same name in both).
_METRIC_ALIASES: dict[str, str] = {"fault_kind": "injected_kind"}


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


def _report_row(df: pd.DataFrame, s: str) -> dict[str, Any]:
    """The metrics of ``evaluate`` for one sensor plus the report's state and kinds."""
    m = sensor_detection(df, df, s)
    row: dict[str, Any] = dict.fromkeys(SUMMARY_COLUMNS, math.nan)
    row.update({k: v for k, v in m.items() if k in SUMMARY_COLUMNS})
    fm = fault_mask(df, s)
    has_flag = f"flag_{s}" in df.columns
    injected = fm is not None and bool(fm.any())
    if fm is None:
        row["injected_kind"] = "unknown"
    elif not injected:
        row["injected_kind"] = "none"
    else:
        kc = f"fault_kind_{s}"
        row["injected_kind"] = _mode(df[kc], fm) if kc in df.columns else "fault"
    if not has_flag:
        row["false_alarms"] = row["false_alarm_time_s"] = math.nan
        row["kind_estimated"] = "n/a"
    if m["faulty"]:
        row["alarm_onset_s"] = row["onset_s"] + row["delay_s"]
        row["state"] = "detected" if m["detected"] else ("missed" if has_flag else "faulty")
        return row
    if injected:  # a fault column without kinds: a window the metrics cannot match
        row["state"] = "faulty"
        return row
    rises = alarm_onsets(df, s)
    if rises.size:
        row["alarm_onset_s"] = float(rises[0])
    if fm is None:
        row["state"] = "alarm" if rises.size else "ok"
    else:
        row["state"] = "false alarm" if rises.size else "healthy"
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
        metrics: Optional per-sensor metrics (anything :func:`normalize_metrics`
            accepts). Known keys (``delay_s``, ``false_alarms``, ``recovery_rmse_n``,
            ``fault_size_error_n``, ``kind_correct``, ``detected`` ...) replace the values
            computed here; unknown keys are added as extra columns.

    Returns:
        DataFrame indexed by sensor name with :data:`SUMMARY_COLUMNS` (+ extras);
        ``nan`` where a value is undefined or its inputs are missing.

    Raises:
        LogFormatError: If ``time`` is missing or not strictly increasing, or
            ``metrics`` is not a mapping of mappings.
    """
    _time(df)  # validates the time axis
    rows = {s: _report_row(df, s) for s in detect_sensors(df)}
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
