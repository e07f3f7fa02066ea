"""Campaign analysis: detection rate, delays, false alarms, curves, smallest detectable fault.

All tables are computed from the long result table (:meth:`ResultStore.read`), one row
per cell. Intervals are exact at 95 %: Clopper-Pearson for a detection rate, the
Poisson (chi-square) interval for a false-alarm rate. False alarms are alarm episodes
starting outside every fault window (all eight sensors), per hour of monitored walking;
they come from the fault-free cells when the campaign has them at that method and
threshold scale, otherwise from the healthy sensors of the fault cells.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import stats

__all__ = [
    "clopper_pearson",
    "poisson_rate_ci",
    "detection_table",
    "false_alarm_table",
    "curve_table",
    "min_detectable",
    "min_detectable_side_by_side",
]


def clopper_pearson(k: int, n: int, conf: float = 0.95) -> tuple[float, float]:
    """Exact binomial interval of a rate ``k / n`` (NaN, NaN when ``n = 0``)."""
    if n <= 0:
        return (math.nan, math.nan)
    a = 1.0 - conf
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return (lo, hi)


def poisson_rate_ci(k: int, exposure_h: float, conf: float = 0.95) -> tuple[float, float, float]:
    """Rate ``k / exposure`` [1/h] and its exact Poisson interval (NaN when no exposure)."""
    if exposure_h <= 0:
        return (math.nan, math.nan, math.nan)
    a = 1.0 - conf
    lo = 0.0 if k == 0 else float(stats.chi2.ppf(a / 2, 2 * k)) / 2.0
    hi = float(stats.chi2.ppf(1 - a / 2, 2 * k + 2)) / 2.0
    return (k / exposure_h, lo / exposure_h, hi / exposure_h)


def _faulty(df: pd.DataFrame) -> pd.DataFrame:
    return df[df["kind"] != "none"]


def detection_table(df: pd.DataFrame, threshold_scale: float = 1.0) -> pd.DataFrame:
    """Per method, kind and size: runs, detection rate (+ CI), delay distribution [s].

    Only cells at ``threshold_scale``. Delays are over the detected runs.
    """
    f = _faulty(df)
    f = f[np.isclose(f["threshold_scale"], threshold_scale)]
    rows = []
    for (method, kind, size), g in f.groupby(["method", "kind", "size"], dropna=False):
        n = len(g)
        k = int(g["detected"].sum())
        lo, hi = clopper_pearson(k, n)
        d = g["delay_s"].dropna().to_numpy(float)
        kc = g["kind_correct"].dropna()
        rows.append({
            "method": method, "kind": kind, "size": size,
            "magnitude": float(g["magnitude"].iloc[0]),
            "runs": n, "detected": k, "rate": k / n, "rate_lo": lo, "rate_hi": hi,
            "delay_median_s": float(np.median(d)) if d.size else math.nan,
            "delay_p10_s": float(np.quantile(d, 0.1)) if d.size else math.nan,
            "delay_p90_s": float(np.quantile(d, 0.9)) if d.size else math.nan,
            "delay_max_s": float(d.max()) if d.size else math.nan,
            "kind_accuracy": float(kc.mean()) if len(kc) else math.nan,
        })
    cols = ["method", "kind", "size", "magnitude", "runs", "detected", "rate", "rate_lo",
            "rate_hi", "delay_median_s", "delay_p10_s", "delay_p90_s", "delay_max_s",
            "kind_accuracy"]
    out = pd.DataFrame(rows, columns=cols)
    return out.sort_values(["kind", "method", "magnitude", "size"]).reset_index(drop=True)


def false_alarm_table(df: pd.DataFrame) -> pd.DataFrame:
    """Per method and threshold scale: false alarms per hour of walking with a 95 % CI."""
    rows = []
    for (method, scale), g in df.groupby(["method", "threshold_scale"]):
        free = g[g["kind"] == "none"]
        if len(free):
            k, hours, source = int(free["false_alarms"].sum()), free["observed_s"].sum() / 3600, \
                "fault-free cells"
        else:
            k, hours, source = int(g["false_alarms_healthy"].sum()), g["observed_s"].sum() / 3600, \
                "healthy sensors of fault cells"
        rate, lo, hi = poisson_rate_ci(k, float(hours))
        rows.append({"method": method, "threshold_scale": float(scale),
                     "cells": len(free) or len(g),
                     "hours": float(hours), "false_alarms": k, "per_hour": rate,
                     "per_hour_lo": lo, "per_hour_hi": hi, "source": source})
    cols = ["method", "threshold_scale", "cells", "hours", "false_alarms", "per_hour",
            "per_hour_lo", "per_hour_hi", "source"]
    return pd.DataFrame(rows, columns=cols)


def curve_table(df: pd.DataFrame) -> pd.DataFrame:
    """Delay against false alarms over the threshold scale, per method.

    One row per method and scale: false alarms per hour (+ CI, as
    :func:`false_alarm_table`), and over the fault cells at that scale the detection
    rate and the median and 90th-percentile delay of the detected runs [s]. Only the
    fault sizes present at every scale of the method enter, so the points compare.
    """
    fa = false_alarm_table(df)
    f = _faulty(df)
    rows = []
    for method, gm in f.groupby("method"):
        scales = sorted(gm["threshold_scale"].unique())
        key = gm["kind"] + ":" + gm["size"].astype(str) + ":" + gm["sensor"]
        common = set.intersection(*(set(key[gm["threshold_scale"] == s]) for s in scales))
        gm = gm[key.isin(common)]
        for scale, g in gm.groupby("threshold_scale"):
            d = g["delay_s"].dropna().to_numpy(float)
            r = fa[(fa["method"] == method) & np.isclose(fa["threshold_scale"], scale)]
            rows.append({
                "method": method, "threshold_scale": float(scale), "fault_runs": len(g),
                "detection_rate": float(g["detected"].mean()),
                "delay_median_s": float(np.median(d)) if d.size else math.nan,
                "delay_p90_s": float(np.quantile(d, 0.9)) if d.size else math.nan,
                "false_alarms_per_hour": float(r["per_hour"].iloc[0]) if len(r) else math.nan,
                "per_hour_lo": float(r["per_hour_lo"].iloc[0]) if len(r) else math.nan,
                "per_hour_hi": float(r["per_hour_hi"].iloc[0]) if len(r) else math.nan,
                "fault_free_hours": float(r["hours"].iloc[0]) if len(r) else math.nan,
            })
    cols = ["method", "threshold_scale", "fault_runs", "detection_rate", "delay_median_s",
            "delay_p90_s", "false_alarms_per_hour", "per_hour_lo", "per_hour_hi",
            "fault_free_hours"]
    return pd.DataFrame(rows, columns=cols)


def min_detectable(
    df: pd.DataFrame, level: float = 0.95, threshold_scale: float = 1.0
) -> pd.DataFrame:
    """The smallest fault of each kind detected in at least ``level`` of its runs.

    Sizes are ordered by :func:`~grfguard.campaign.spec.size_magnitude`; the answer is the
    smallest size from which every larger tested size also reaches ``level`` (NaN when
    even the largest does not). Kinds without an ordered size are left out.
    """
    tab = detection_table(df, threshold_scale)
    tab = tab[np.isfinite(tab["magnitude"])]
    rows = []
    for (method, kind), g in tab.groupby(["method", "kind"]):
        g = g.sort_values("magnitude")
        ok = (g["rate"] >= level).to_numpy()
        # suffix-all: from index i on every size reaches the level
        suffix = np.flip(np.logical_and.accumulate(np.flip(ok)))
        idx = np.flatnonzero(suffix)
        best = g.iloc[idx[0]] if idx.size else None
        rows.append({
            "method": method, "kind": kind,
            "min_size": float(best["size"]) if best is not None else math.nan,
            "rate": float(best["rate"]) if best is not None else math.nan,
            "runs": int(best["runs"]) if best is not None else int(g["runs"].min()),
            "delay_median_s": float(best["delay_median_s"]) if best is not None else math.nan,
            "tested": ", ".join(f"{v:g}" for v in g["size"]),
        })
    cols = ["method", "kind", "min_size", "rate", "runs", "delay_median_s", "tested"]
    return pd.DataFrame(rows, columns=cols)


def min_detectable_side_by_side(
    df: pd.DataFrame, level: float = 0.95, threshold_scale: float = 1.0
) -> pd.DataFrame:
    """:func:`min_detectable` with one column per method (index: kind)."""
    m = min_detectable(df, level, threshold_scale)
    if m.empty:
        return pd.DataFrame()
    return m.pivot(index="kind", columns="method", values="min_size")
