"""Every metric a log's truth columns allow, as plain JSON-able dicts.

One entry point for the CLI (``grfguard evaluate``), the demo and the report: the
virtual-sensor accuracy (:mod:`grfguard.evaluate.vfs_metrics`) and the detection
metrics (:mod:`grfguard.evaluate.detection`).
"""

from __future__ import annotations

import math
from typing import Any

import pandas as pd

from grfguard.errors import LogFormatError
from grfguard.evaluate.detection import evaluate_detection, summarize_detection
from grfguard.evaluate.vfs_metrics import evaluate_vfs

__all__ = ["evaluate_frame", "detection_metrics", "has_detection_truth"]


def has_detection_truth(df: pd.DataFrame) -> bool:
    """True when ``df`` has both flags (a run output) and injected faults (the truth)."""
    return "flag_r1" in df.columns and "fault_r1" in df.columns


def evaluate_frame(df: pd.DataFrame) -> dict[str, Any]:
    """All metrics the truth in ``df`` allows (VFS accuracy, detection).

    Raises:
        LogFormatError: If ``df`` has no ``vfs_*`` columns (not a ``grfguard run`` output).
    """
    result: dict[str, Any] = {"source": df.attrs.get("source")}
    if "vfs_r1" not in df.columns:
        raise LogFormatError(
            "the log has no vfs_* columns: evaluate the output of `grfguard run`, not its input"
        )
    if "true_force_r1" in df.columns:
        result["vfs"] = evaluate_vfs(df)
    if has_detection_truth(df):
        result["detection"] = detection_metrics(df)
    return result


def _clean(v: Any) -> Any:
    if hasattr(v, "item"):
        v = v.item()
    if isinstance(v, float) and math.isnan(v):
        return None
    return v


def detection_metrics(df: pd.DataFrame) -> dict[str, Any]:
    """Per-sensor detection metrics and their summary (``{"sensors": ..., "summary": ...}``)."""
    table = evaluate_detection(df)
    duration = float(df["time"].iloc[-1] - df["time"].iloc[0])
    sensors = {
        str(s): {k: _clean(v) for k, v in row.items()} for s, row in table.iterrows()
    }
    summary = {k: _clean(v) for k, v in summarize_detection(table, duration).items()}
    return {"sensors": sensors, "summary": summary}
