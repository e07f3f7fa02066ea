"""Accuracy of the virtual force sensor against the simulation truth.

The windows (DESIGN.md, "Estimation and detection facts"):

* **single support (SS)**: one foot fully loaded (every corner's true force above
  ``loaded_threshold``), the other foot fully unloaded, and no corner changed state within
  ``ss_margin`` seconds either side; errors are taken on the stance foot.
* **double support (DS)**: both feet fully loaded, no corner change within ``ds_margin``.

Errors are ``vfs - true`` in [N]: RMSE and bias (mean error) per contact point, per foot
total vertical force, and the worst corner. Everything returned is JSON-able
(``nan`` becomes ``None``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import LogFormatError
from grfguard.io.schema import TIME, true_force_col, vfs_col
from grfguard.model.robot import SENSOR_NAMES, SIDES

__all__ = ["evaluate_vfs", "support_windows"]


def _dilate(mask: np.ndarray, n: int) -> np.ndarray:
    """True where ``mask`` is True within ``n`` samples either side."""
    if n <= 0 or not mask.any():
        return mask.copy()
    c = np.concatenate([[0], np.cumsum(mask.astype(np.int64))])
    idx = np.arange(mask.size)
    lo = np.clip(idx - n, 0, mask.size)
    hi = np.clip(idx + n + 1, 0, mask.size)
    return (c[hi] - c[lo]) > 0


def support_windows(
    true_forces_n: np.ndarray,
    dt_s: float,
    loaded_threshold_n: float = 1.0,
    ss_margin_s: float = 0.05,
    ds_margin_s: float = 0.01,
) -> dict[str, np.ndarray]:
    """Single/double support masks from the true corner forces.

    Args:
        true_forces_n: (T, 8) true corner forces [N], sensor order ``r1..r4, l1..l4``.
        dt_s: Sampling period in [s].
        loaded_threshold_n: A corner is loaded above this force [N].
        ss_margin_s: Distance from any corner state change required for SS [s].
        ds_margin_s: Distance from any corner state change required for DS [s].

    Returns:
        Dict with boolean (T,) masks ``ss_r``, ``ss_l`` (that foot is the stance foot)
        and ``ds``.
    """
    loaded = true_forces_n > loaded_threshold_n
    change = np.zeros(loaded.shape[0], dtype=bool)
    change[1:] = np.any(loaded[1:] != loaded[:-1], axis=1)
    near_ss = _dilate(change, int(round(ss_margin_s / dt_s)))
    near_ds = _dilate(change, int(round(ds_margin_s / dt_s)))
    full_r, full_l = loaded[:, :4].all(axis=1), loaded[:, 4:].all(axis=1)
    none_r, none_l = ~loaded[:, :4].any(axis=1), ~loaded[:, 4:].any(axis=1)
    return {
        "ss_r": full_r & none_l & ~near_ss,
        "ss_l": full_l & none_r & ~near_ss,
        "ds": full_r & full_l & ~near_ds,
    }


def _f(x: float) -> float | None:
    x = float(x)
    return None if not math.isfinite(x) else x


def _stats(err: np.ndarray) -> dict[str, float | None]:
    if err.size == 0:
        return {"rmse": None, "bias": None, "n": 0}
    return {
        "rmse": _f(np.sqrt(np.mean(err**2))),
        "bias": _f(np.mean(err)),
        "n": int(err.size),
    }


def evaluate_vfs(
    out_df: pd.DataFrame,
    sensors: Sequence[str] = SENSOR_NAMES,
    loaded_threshold_n: float = 1.0,
    ss_margin_s: float = 0.05,
    ds_margin_s: float = 0.01,
    t_start_s: float = 0.5,
) -> dict[str, Any]:
    """VFS error statistics in single and double support.

    Args:
        out_df: Frame with ``time``, ``true_force_<s>`` and ``vfs_<s>`` for every sensor.
        sensors: Sensor names, four per foot, right foot first.
        loaded_threshold_n: A corner is loaded above this true force [N].
        ss_margin_s: Margin from any contact change for single support [s].
        ds_margin_s: Margin from any contact change for double support [s].
        t_start_s: Samples before this time (start-up transient) are ignored [s].

    Returns:
        ``{"ss": {...}, "ds": {...}}`` where each phase holds ``n_samples``,
        ``per_sensor`` ({sensor: {rmse, bias, n}}), ``corner_rmse`` (all loaded-foot corners
        pooled), ``corner_rmse_worst``, ``bias_worst`` (largest ``|bias|``, signed),
        ``foot_rmse`` (per-foot total force, pooled) and ``foot_bias``; all in [N].

    Raises:
        LogFormatError: a needed column is missing.
    """
    need = [TIME] + [true_force_col(s) for s in sensors] + [vfs_col(s) for s in sensors]
    missing = [c for c in need if c not in out_df.columns]
    if missing:
        raise LogFormatError(
            f"evaluate_vfs needs columns {missing}; run the virtual force sensor on a "
            "simulated log (with true_force_* truth) first"
        )
    t = out_df[TIME].to_numpy(float)
    # one sample has no rate (and no contact change to keep away from)
    dt = float(np.median(np.diff(t))) if t.size > 1 else float("inf")
    true = out_df[[true_force_col(s) for s in sensors]].to_numpy(float)
    est = out_df[[vfs_col(s) for s in sensors]].to_numpy(float)
    win = support_windows(true, dt, loaded_threshold_n, ss_margin_s, ds_margin_s)
    keep = t >= t_start_s
    n_foot = len(sensors) // 2
    foot_idx = {SIDES[0]: np.arange(n_foot), SIDES[1]: np.arange(n_foot, 2 * n_foot)}
    err = est - true
    result: dict[str, Any] = {}
    for phase in ("ss", "ds"):
        if phase == "ss":
            masks = {s: win[f"ss_{s}"] & keep for s in SIDES}
        else:
            masks = {s: win["ds"] & keep for s in SIDES}
        per_sensor: dict[str, Any] = {}
        pooled, foot_err = [], []
        for side in SIDES:
            m = masks[side]
            for j in foot_idx[side]:
                e = err[m, j]
                e = e[np.isfinite(e)]
                per_sensor[sensors[j]] = _stats(e)
                pooled.append(e)
            fe = err[m][:, foot_idx[side]].sum(axis=1)
            foot_err.append(fe[np.isfinite(fe)])
        allc = np.concatenate(pooled) if pooled else np.zeros(0)
        allf = np.concatenate(foot_err) if foot_err else np.zeros(0)
        rm = [v["rmse"] for v in per_sensor.values() if v["rmse"] is not None]
        bi = [v["bias"] for v in per_sensor.values() if v["bias"] is not None]
        n_samples = int(np.count_nonzero(masks[SIDES[0]] | masks[SIDES[1]]))
        result[phase] = {
            "n_samples": n_samples,
            "per_sensor": per_sensor,
            "corner_rmse": _stats(allc)["rmse"],
            "corner_rmse_worst": max(rm) if rm else None,
            "bias_worst": max(bi, key=abs) if bi else None,
            "foot_rmse": _stats(allf)["rmse"],
            "foot_bias": _stats(allf)["bias"],
        }
    return result


