"""Campaign report: figures (pure matplotlib functions) and one offline HTML page.

``write_campaign_report(results, out_dir)`` writes ``index.html`` (tables and the
figures inlined as PNG, no network), the figures as PNG files, the tables as CSV and
``summary.json`` (the smallest detectable faults and the curve, for scripts).
"""

from __future__ import annotations

import base64
import html as _html
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from grfguard.campaign import analysis as an
from grfguard.campaign.store import ResultStore
from grfguard.io.logio import to_jsonable
from grfguard.report.html import BASE_CSS

__all__ = [
    "plot_detection_rates",
    "plot_delays",
    "plot_delay_vs_false_alarms",
    "write_campaign_report",
    "CampaignReport",
]

#: Method colours (Okabe-Ito, as the rest of the reports).
METHOD_COLORS = {"default": "#0072B2", "paper": "#D55E00"}
#: Line style per method (the paper's curve stays visible on top of the default's).
_STYLE: dict[str, dict[str, Any]] = {
    "default": {"marker": "o", "ls": "-"},
    "paper": {"marker": "s", "ls": "--", "mfc": "none", "ms": 8},
}
_UNITS = {"offset": "N", "drift": "N/s", "gain": "×", "noise": "σ N", "spikes": "N",
          "saturation": "N", "frozen": "N"}


def _kinds(tab: pd.DataFrame) -> list[str]:
    return sorted(tab["kind"].unique())


def _axes_grid(n: int, width: float = 4.0, height: float = 3.0):
    import matplotlib.figure

    cols = min(3, max(1, n))
    rows = max(1, math.ceil(n / cols))
    fig = matplotlib.figure.Figure(figsize=(width * cols, height * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes


def plot_detection_rates(tab: pd.DataFrame, level: float = 0.95):
    """Detection rate (95 % CI bars) against fault size, one panel per kind.

    Args:
        tab: :func:`~grfguard.campaign.analysis.detection_table`.
        level: Drawn as a dashed line.

    Returns:
        ``(fig, axes)``.
    """
    kinds = _kinds(tab)
    fig, axes = _axes_grid(len(kinds))
    for ax, kind in zip(axes, kinds, strict=False):
        for method, g in tab[tab["kind"] == kind].groupby("method"):
            g = g.sort_values("size")
            x = np.arange(len(g)) if not np.isfinite(g["size"]).all() else g["size"]
            err = np.vstack([g["rate"] - g["rate_lo"], g["rate_hi"] - g["rate"]])
            ax.errorbar(x, g["rate"], yerr=err, capsize=3, label=method,
                        color=METHOD_COLORS.get(method), **_STYLE.get(method, {}))
        ax.axhline(level, color="0.4", ls="--", lw=0.8)
        ax.set_ylim(-0.05, 1.05)
        ax.set_title(kind)
        ax.set_xlabel(f"size [{_UNITS.get(kind, '-')}]")
        ax.set_ylabel("detection rate")
        ax.legend(fontsize=8)
    return fig, axes


def plot_delays(df: pd.DataFrame, threshold_scale: float = 1.0):
    """Distribution of the detection delay [s] per size, one panel per kind, both methods."""
    f = df[(df["kind"] != "none") & np.isclose(df["threshold_scale"], threshold_scale)]
    kinds = sorted(f["kind"].unique())
    fig, axes = _axes_grid(len(kinds))
    methods = sorted(f["method"].unique())
    for ax, kind in zip(axes, kinds, strict=False):
        g = f[f["kind"] == kind]
        sizes = sorted(g["size"].unique(), key=lambda v: (math.isnan(v), v))
        for j, method in enumerate(methods):
            gm = g[g["method"] == method]
            data = [gm[(gm["size"] == s) | (np.isnan(s) & gm["size"].isna())]["delay_s"]
                    .dropna().to_numpy() for s in sizes]
            pos = np.arange(len(sizes)) + (j - (len(methods) - 1) / 2) * 0.35
            keep = [i for i, d in enumerate(data) if d.size]
            if keep:
                bp = ax.boxplot([data[i] for i in keep], positions=pos[keep], widths=0.3,
                                patch_artist=True, showfliers=True,
                                medianprops={"color": "black"})
                for b in bp["boxes"]:
                    b.set_facecolor(METHOD_COLORS.get(method, "0.7"))
                    b.set_alpha(0.6)
            ax.plot([], [], "s", color=METHOD_COLORS.get(method), label=method)
        ax.set_xticks(np.arange(len(sizes)), ["–" if math.isnan(s) else f"{s:g}" for s in sizes])
        ax.set_title(kind)
        ax.set_xlabel(f"size [{_UNITS.get(kind, '-')}]")
        ax.set_ylabel("delay of detected runs [s]")
        ax.legend(fontsize=8)
    return fig, axes


def plot_delay_vs_false_alarms(curve: pd.DataFrame):
    """Median detection delay (left) and detection rate (right) against false alarms per
    hour over the threshold scale; points labelled ``×scale``.

    Args:
        curve: :func:`~grfguard.campaign.analysis.curve_table`.

    Returns:
        ``(fig, axes)``.
    """
    import matplotlib.figure

    fig = matplotlib.figure.Figure(figsize=(11, 4.2), layout="constrained")
    axes = fig.subplots(1, 2)
    for method, g in curve.groupby("method"):
        g = g.sort_values("threshold_scale")
        c = METHOD_COLORS.get(method)
        x = g["false_alarms_per_hour"].to_numpy(float)
        xerr = np.vstack([x - g["per_hour_lo"], g["per_hour_hi"] - x])
        for ax, col in zip(axes, ("delay_median_s", "detection_rate"), strict=True):
            ax.errorbar(x, g[col], xerr=xerr, capsize=3, color=c, label=method,
                        **_STYLE.get(method, {}))
            for _, r in g.iterrows():
                if np.isfinite(r[col]):
                    ax.annotate(f"×{r['threshold_scale']:g}", (r["false_alarms_per_hour"],
                                r[col]), fontsize=7, xytext=(4, 3),
                                textcoords="offset points", color=c)
    for ax in axes:
        ax.set_xscale("symlog", linthresh=1.0)
        ax.set_xlabel("false alarms per hour of walking (95 % CI)")
        ax.legend(fontsize=8)
    axes[0].set_ylabel("median delay of detected faults [s]")
    axes[1].set_ylabel("detection rate")
    axes[1].set_ylim(-0.05, 1.05)
    fig.suptitle("over the threshold scale ×k")
    return fig, axes


_CSS = BASE_CSS + """td:first-child{text-align:left;font-weight:600}
.fig{background:#fff;border:1px solid #e3e3e3;margin:10px 0;max-width:100%}
.note{font-size:12px;color:#555}
"""


def _fmt(v: Any, digits: int = 3) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return "–" if math.isnan(float(v)) else f"{float(v):.{digits}g}"
    return _html.escape(str(v))


def _table_html(df: pd.DataFrame, index: bool = False) -> str:
    d = df.reset_index() if index else df
    head = "".join(f"<th>{_html.escape(str(c))}</th>" for c in d.columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{_fmt(v)}</td>" for v in row) + "</tr>"
        for row in d.itertuples(index=False)
    )
    return f"<table><tr>{head}</tr>{body}</table>"


def _png(fig: Any, path: Path) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    data = buf.getvalue()
    path.write_bytes(data)
    return base64.b64encode(data).decode()


class CampaignReport:
    """The tables of one campaign's results (computed once, written by :meth:`write`).

    Args:
        results: Results folder or the long result table.
        level: Detection rate that counts as "detectable".
    """

    def __init__(self, results: str | Path | pd.DataFrame, level: float = 0.95) -> None:
        self.df = results if isinstance(results, pd.DataFrame) else ResultStore(results).read()
        self.level = level
        self.name = str(results) if not isinstance(results, pd.DataFrame) else "campaign"
        self.detection = an.detection_table(self.df)
        self.false_alarms = an.false_alarm_table(self.df)
        self.curve = an.curve_table(self.df)
        self.min_detectable = an.min_detectable(self.df, level)
        self.side_by_side = an.min_detectable_side_by_side(self.df, level)

    def summary(self) -> dict[str, Any]:
        """Plain-data summary (goes to ``summary.json``)."""
        d = self.df
        return to_jsonable({
            "cells": len(d),
            "walks": int(d["walk_id"].nunique()),
            "methods": sorted(d["method"].unique()),
            "level": self.level,
            "min_detectable": self.min_detectable.to_dict(orient="records"),
            "false_alarms": self.false_alarms.to_dict(orient="records"),
            "curve": self.curve.to_dict(orient="records"),
            "compute_s_mean": float(d["compute_s"].mean()),
        })

    def write(self, out_dir: str | Path, title: str | None = None) -> Path:
        """Write ``index.html``, figures (PNG), tables (CSV) and ``summary.json``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        for name, tab in (("detection", self.detection), ("false_alarms", self.false_alarms),
                          ("curve", self.curve), ("min_detectable", self.min_detectable)):
            tab.to_csv(out / f"{name}.csv", index=False)
        (out / "summary.json").write_text(json.dumps(self.summary(), indent=1))
        figs: list[tuple[str, str]] = []
        if not self.detection.empty:
            fig, _ = plot_detection_rates(self.detection, self.level)
            figs.append(("Detection rate against fault size", _png(fig, out / "rates.png")))
            fig, _ = plot_delays(self.df)
            figs.append(("Detection delay distribution", _png(fig, out / "delays.png")))
        if not self.curve.empty:
            fig, _ = plot_delay_vs_false_alarms(self.curve)
            figs.append(("Delay against false alarms", _png(fig, out / "curve.png")))
        d = self.df
        title = title or f"grfguard campaign report: {self.name}"
        sub = (f"{len(d)} cells on {d['walk_id'].nunique()} walks; methods "
               f"{', '.join(sorted(d['method'].unique()))}; scenarios "
               f"{', '.join(sorted(d['scenario'].unique()))}")
        side = self.side_by_side
        parts = [
            "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
            f"<meta name='generator' content='grfguard'><title>{_html.escape(title)}</title>",
            f"<style>{_CSS}</style></head><body>",
            f"<header><h1>{_html.escape(title)}</h1><p>{_html.escape(sub)}</p></header><main>",
            f"<h2>Smallest fault detected in {self.level:.0%} of runs (paper vs default)</h2>",
            _table_html(side, index=True) if not side.empty else "<p>no sized faults</p>",
            "<p class='note'>At threshold scale 1. The smallest tested size from which every "
            "larger tested size reaches the level; – : not reached by any tested size.</p>",
            "<h2>False alarms per hour of walking</h2>", _table_html(self.false_alarms),
            "<p class='note'>Alarm episodes outside fault windows on all eight sensors; "
            "exact Poisson 95 % interval.</p>",
            "<h2>Delay against false alarms over the threshold scale</h2>",
            _table_html(self.curve),
            "<h2>Detection by kind and size</h2>", _table_html(self.detection),
            "<p class='note'>rate_lo/rate_hi: Clopper-Pearson 95 %. Delays over detected "
            "runs [s].</p>",
        ]
        for caption, b64 in figs:
            parts.append(f"<h2>{_html.escape(caption)}</h2><img class='fig' alt='"
                         f"{_html.escape(caption)}' src='data:image/png;base64,{b64}'>")
        parts.append("</main></body></html>")
        path = out / "index.html"
        path.write_text("".join(parts))
        return path


def write_campaign_report(
    results: str | Path | pd.DataFrame, out_dir: str | Path, level: float = 0.95
) -> Path:
    """Analyse a campaign's results and write the report; returns ``index.html``."""
    return CampaignReport(results, level).write(out_dir)
