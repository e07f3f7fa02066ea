"""Publication figures of a ``grfguard run`` output (matplotlib, pure).

Every ``plot_*`` function returns ``(fig, axes)`` and never calls ``show()``; figures
are :class:`matplotlib.figure.Figure` objects made without pyplot (no global state, Agg
when saved). One colour per signal type everywhere (:mod:`grfguard.report.style`);
injected fault windows are shaded, alarm onsets are dashed vertical lines and the
planned stance of the foot is a thin strip along the top of each force axis.

The paper's figures (Hashlamon & Erbatur, section IV):

* :func:`plot_vfs_vs_true` (Fig. 4): VFS vs true force, each sensor of the faulty foot;
* :func:`plot_fault_estimate` (Fig. 5): true fault, estimated filtered and unfiltered;
* :func:`plot_recovery` (Fig. 6): recovered vs true signal;
* :func:`plot_flags` (Fig. 7): detection flags (0/1) with the fault onset.

Plus :func:`plot_sensor` (everything about one sensor), :func:`plot_detection_timeline`
(all sensors: injected windows vs alarms), :func:`plot_summary_table` and
:func:`write_png_figures`.

Time range: ``t_range=(t0, t1)`` [s]; by default the whole log if it lasts at most
120 s, else 10 s before to 30 s after the first injected fault onset (or, without
injected faults, the first alarm onset). Long logs are
decimated for drawing with per-bucket min/max (peaks kept).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from grfguard.errors import ConfigError, LogFormatError
from grfguard.report._decimate import intervals, minmax_indices
from grfguard.report.style import (
    ALARM_COLOR,
    CONTACT_SHADE,
    FAULT_SHADE,
    SIGNAL_COLORS,
    SIGNAL_LABELS,
    rgba_to_mpl,
)
from grfguard.report.summary import (
    _time,
    alarm_onsets,
    detect_sensors,
    fault_mask,
    fault_onsets,
    sensor_summary,
)

__all__ = [
    "plot_vfs_vs_true",
    "plot_fault_estimate",
    "plot_recovery",
    "plot_flags",
    "plot_sensor",
    "plot_detection_timeline",
    "plot_summary_table",
    "write_png_figures",
    "faulty_foot",
]

_CORNERS = {1: "front-left", 2: "front-right", 3: "rear-left", 4: "rear-right"}
_SIDES = {"r": "right", "l": "left"}
_DRAW_BUCKETS = 1500  # min/max buckets per line when drawing long logs (~3 per pixel)
_MAX_MARKS = 200  # cap on shaded windows / alarm lines per axis
_RAW_ETA_PREFIXES = ("eta_raw_", "eta_unfiltered_", "eta_kf_")
_FONT = {"axes.titlesize": 10, "axes.labelsize": 9, "xtick.labelsize": 8, "ytick.labelsize": 8}


# ----------------------------------------------------------------------------- helpers
def _new_figure(nrows: int, ncols: int, width_in: float, height_in: float,
                sharex: bool = True, sharey: bool | str = False) -> tuple[Figure, np.ndarray]:
    fig = Figure(figsize=(width_in, height_in), layout="constrained", dpi=100)
    axes = fig.subplots(nrows, ncols, sharex=sharex, sharey=sharey, squeeze=False)
    for ax in axes.flat:
        ax.grid(True, color="#e3e3e3", linewidth=0.6)
        ax.set_axisbelow(True)
        ax.tick_params(labelsize=_FONT["xtick.labelsize"])
        for side in ("top", "right"):
            ax.spines[side].set_visible(False)
    return fig, axes


def faulty_foot(df: pd.DataFrame) -> str:
    """The foot (``"r"`` or ``"l"``) with the most injected faults, else the most alarms.

    Defaults to ``"r"`` when neither tells (the paper's faulty foot).
    """
    score = {"r": 0.0, "l": 0.0}
    for s in detect_sensors(df):
        if s[:1] not in score:
            continue
        m = fault_mask(df, s)
        if m is not None and m.any():
            score[s[:1]] += 1000.0
        score[s[:1]] += alarm_onsets(df, s).size
    return "l" if score["l"] > score["r"] else "r"


def _foot_sensors(df: pd.DataFrame, foot: str | None) -> list[str]:
    foot = foot or faulty_foot(df)
    if foot not in _SIDES:
        raise ConfigError(f"foot = {foot!r} must be 'r' (right) or 'l' (left)")
    sensors = [s for s in detect_sensors(df) if s[:1] == foot]
    if not sensors:
        raise LogFormatError(
            f"no sensor columns of the {_SIDES[foot]} foot ({foot}1..{foot}4) in the log"
        )
    return sensors


def _default_range(df: pd.DataFrame, t: np.ndarray) -> tuple[float, float]:
    if t[-1] - t[0] <= 120.0:
        return float(t[0]), float(t[-1])
    sensors = detect_sensors(df)
    onsets = np.concatenate([fault_onsets(df, s) for s in sensors] + [np.zeros(0)])
    if not onsets.size:
        onsets = np.concatenate([alarm_onsets(df, s) for s in sensors] + [np.zeros(0)])
    c = float(onsets.min()) if onsets.size else float(t[0]) + 10.0
    return max(float(t[0]), c - 10.0), min(float(t[-1]), c + 30.0)


def _select(df: pd.DataFrame, t_range: tuple[float, float] | None) -> tuple[np.ndarray, slice]:
    """Times [s] and the row slice of the requested range."""
    t = _time(df)
    if t.size == 0:
        raise LogFormatError("the log has no rows; nothing to plot")
    if t_range is None:
        t_range = _default_range(df, t)
    t0, t1 = (float(v) for v in t_range)
    if not t1 > t0:
        raise ConfigError(f"t_range = {t_range!r} must be (start, end) with end > start, in [s]")
    i0 = int(np.searchsorted(t, t0, side="left"))
    i1 = int(np.searchsorted(t, t1, side="right"))
    if i1 - i0 < 2:
        raise ConfigError(
            f"t_range = {t_range!r} s selects {i1 - i0} samples; the log spans "
            f"{t[0]:.3f} to {t[-1]:.3f} s"
        )
    return t[i0:i1], slice(i0, i1)


def _line(ax: Axes, t: np.ndarray, df: pd.DataFrame, rows: slice, col: str, kind: str,
          label: str | None = None, **kw: Any) -> bool:
    """Draw column ``col`` as signal type ``kind``; False if the column is missing."""
    if col not in df.columns:
        return False
    y = df[col].to_numpy(dtype=float)[rows]
    idx = minmax_indices(y, _DRAW_BUCKETS) if y.size > 3 * _DRAW_BUCKETS else slice(None)
    style = {"color": SIGNAL_COLORS[kind], "linewidth": 1.1}
    if kind in ("true", "fault"):
        style.update(linestyle=(0, (3, 1.5)), linewidth=1.2)
    style.update(kw)
    ax.plot(t[idx], y[idx], label=label or SIGNAL_LABELS[kind], **style)
    return True


def _shade_faults(ax: Axes, t: np.ndarray, df: pd.DataFrame, rows: slice, sensor: str) -> bool:
    m = fault_mask(df, sensor)
    if m is None or not m[rows].any():
        return False
    for a, b in intervals(t, m[rows])[:_MAX_MARKS]:
        ax.axvspan(a, b, color=rgba_to_mpl(FAULT_SHADE), linewidth=0, zorder=0)
    return True


def _mark_alarms(ax: Axes, t: np.ndarray, df: pd.DataFrame, sensor: str) -> bool:
    on = alarm_onsets(df, sensor)
    on = on[(on >= t[0]) & (on <= t[-1])]
    for a in on[:_MAX_MARKS]:
        ax.axvline(a, color=ALARM_COLOR, linestyle="--", linewidth=1.0, zorder=3)
    return bool(on.size)


def _contact_strip(ax: Axes, t: np.ndarray, df: pd.DataFrame, rows: slice, side: str) -> bool:
    c = f"contact_ref_{side}"
    if c not in df.columns:
        return False
    st = df[c].fillna(0).to_numpy(dtype=float)[rows] > 0.5
    tr = ax.get_xaxis_transform()
    for a, b in intervals(t, st):
        ax.fill_between([a, b], 0.965, 1.0, transform=tr, color=rgba_to_mpl(CONTACT_SHADE),
                        linewidth=0, zorder=1)
    return True


def _legend_extras(faults: bool, alarms: bool, contact: bool) -> list[Any]:
    h: list[Any] = []
    if faults:
        h.append(Patch(color=rgba_to_mpl(FAULT_SHADE), label="injected fault"))
    if alarms:
        h.append(Line2D([], [], color=ALARM_COLOR, linestyle="--", linewidth=1.0,
                        label="alarm onset"))
    if contact:
        h.append(Patch(color=rgba_to_mpl(CONTACT_SHADE), label="stance (planned)"))
    return h


def _figure_legend(fig: Figure, axes: np.ndarray, extras: list[Any]) -> None:
    handles, labels = [], []
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    for h in extras:
        if h.get_label() not in labels:
            handles.append(h)
            labels.append(h.get_label())
    if handles:
        ncols = len(handles)
        if sum(len(lab) + 6 for lab in labels) > 120:  # too wide for one row: two rows
            ncols = math.ceil(len(handles) / 2)
        fig.legend(handles, labels, loc="outside lower center", ncols=ncols, fontsize=9,
                   frameon=False)


def _sensor_title(sensor: str) -> str:
    try:
        corner = _CORNERS.get(int(sensor[1:]), "")
    except ValueError:
        corner = ""
    return f"sensor {sensor}" + (f" ({corner})" if corner else "")


def _corner_grid(sensors: Sequence[str]) -> list[tuple[int, int]]:
    """Grid position of each sensor: 1 front-left top-left ... 4 rear-right bottom-right."""
    pos = []
    for i, s in enumerate(sensors):
        try:
            k = int(s[1:]) - 1
        except ValueError:
            k = i
        pos.append((k // 2, k % 2) if 0 <= k < 4 and len(sensors) <= 4 else (i // 2, i % 2))
    return pos


def _four_panel(
    df: pd.DataFrame,
    foot: str | None,
    t_range: tuple[float, float] | None,
    title: str,
    ylabel: str,
    draw: Any,
) -> tuple[Figure, np.ndarray]:
    sensors = _foot_sensors(df, foot)
    t, rows = _select(df, t_range)
    nrows = max(r for r, _ in _corner_grid(sensors)) + 1
    fig, axes = _new_figure(nrows, 2, 10.0, 2.6 * nrows + 0.9, sharey=False)
    used = set()
    any_f = any_a = any_c = False
    for s, (r, c) in zip(sensors, _corner_grid(sensors), strict=True):
        ax = axes[r, c]
        used.add((r, c))
        any_c |= _contact_strip(ax, t, df, rows, s[:1])
        any_f |= _shade_faults(ax, t, df, rows, s)
        draw(ax, t, rows, s)
        any_a |= _mark_alarms(ax, t, df, s)
        ax.set_title(_sensor_title(s), loc="left", fontsize=10)
        ax.set_ylabel(ylabel)
        ax.set_xlim(t[0], t[-1])
    for r in range(nrows):
        for c in range(2):
            if (r, c) not in used:
                axes[r, c].set_visible(False)
    for c in range(2):
        axes[nrows - 1, c].set_xlabel("time [s]")
    _figure_legend(fig, axes, _legend_extras(any_f, any_a, any_c))
    fig.suptitle(title, fontsize=12, x=0.01, ha="left")
    return fig, axes


# ------------------------------------------------------------------ the paper's figures
def plot_vfs_vs_true(
    df: pd.DataFrame, foot: str | None = None, t_range: tuple[float, float] | None = None
) -> tuple[Figure, np.ndarray]:
    """Fig. 4: virtual force sensor vs true force for each sensor of one foot.

    Args:
        df: Output of ``grfguard run``. Without ``true_force_<s>`` the measured force is
            drawn instead (and labelled so).
        foot: ``"r"`` or ``"l"``; default :func:`faulty_foot`.
        t_range: ``(start, end)`` in [s]; default see module docstring.

    Returns:
        ``(fig, axes)``, axes shape (2, 2) in the sole layout (front row on top).
    """

    def draw(ax: Axes, t: np.ndarray, rows: slice, s: str) -> None:
        if not _line(ax, t, df, rows, f"true_force_{s}", "true", zorder=4):
            _line(ax, t, df, rows, f"force_{s}", "measured")
        _line(ax, t, df, rows, f"vfs_{s}", "vfs", zorder=3)

    return _four_panel(df, foot, t_range, "Virtual force sensor vs true force",
                       "force [N]", draw)


def _unfiltered(df: pd.DataFrame, s: str) -> tuple[np.ndarray | None, str]:
    for p in _RAW_ETA_PREFIXES:
        if f"{p}{s}" in df.columns:
            return df[f"{p}{s}"].to_numpy(dtype=float), "unfiltered estimate"
    if f"force_{s}" in df.columns and f"vfs_{s}" in df.columns:
        r = df[f"force_{s}"].to_numpy(dtype=float) - df[f"vfs_{s}"].to_numpy(dtype=float)
        return r, "unfiltered: measured − VFS"
    return None, ""


def plot_fault_estimate(
    df: pd.DataFrame, foot: str | None = None, t_range: tuple[float, float] | None = None
) -> tuple[Figure, np.ndarray]:
    """Fig. 5: true fault, estimated filtered fault and the unfiltered estimate.

    The unfiltered estimate is the column ``eta_raw_<s>`` (or ``eta_unfiltered_<s>``)
    when the run wrote it, else the raw residual ``force_<s> - vfs_<s>`` [N]. The y range
    covers the true and filtered fault fully and the unfiltered one from its 2nd to its
    98th percentile (its spikes are clipped, not allowed to squash the estimates).

    Returns:
        ``(fig, axes)``, axes shape (2, 2) in the sole layout.
    """

    def draw(ax: Axes, t: np.ndarray, rows: slice, s: str) -> None:
        raw, label = _unfiltered(df, s)
        core: list[np.ndarray] = []
        if _line(ax, t, df, rows, f"eta_{s}", "eta", label="estimated fault (filtered)",
                 linewidth=1.5, zorder=4):
            core.append(df[f"eta_{s}"].to_numpy(dtype=float)[rows])
        if _line(ax, t, df, rows, f"fault_{s}", "fault", zorder=5):
            core.append(df[f"fault_{s}"].to_numpy(dtype=float)[rows])
        if raw is not None:
            y = raw[rows]
            idx = minmax_indices(y, _DRAW_BUCKETS) if y.size > 3 * _DRAW_BUCKETS else slice(None)
            ax.plot(t[idx], y[idx], color=SIGNAL_COLORS["residual"], linewidth=0.7,
                    label=label, zorder=2)
            fin = y[np.isfinite(y)]
            if fin.size:  # the raw residual's spikes must not squash the estimates
                core.append(np.percentile(fin, [2.0, 98.0]))
        ax.axhline(0.0, color="#999999", linewidth=0.6, zorder=1)
        vals = np.concatenate([c[np.isfinite(c)] for c in core] + [np.zeros(1)])
        lo, hi = float(vals.min()), float(vals.max())
        pad = 0.12 * max(hi - lo, 1.0)
        ax.set_ylim(lo - pad, hi + pad)

    return _four_panel(df, foot, t_range, "Fault: true and estimated", "fault [N]", draw)


def plot_recovery(
    df: pd.DataFrame, foot: str | None = None, t_range: tuple[float, float] | None = None
) -> tuple[Figure, np.ndarray]:
    """Fig. 6: recovered vs true force (measured, faulty, in the background).

    Returns:
        ``(fig, axes)``, axes shape (2, 2) in the sole layout.
    """

    def draw(ax: Axes, t: np.ndarray, rows: slice, s: str) -> None:
        _line(ax, t, df, rows, f"force_{s}", "measured", linewidth=0.9, alpha=0.9, zorder=2)
        _line(ax, t, df, rows, f"recovered_{s}", "recovered", linewidth=1.3, zorder=3)
        _line(ax, t, df, rows, f"true_force_{s}", "true", zorder=4)

    return _four_panel(df, foot, t_range, "Recovered vs true force", "force [N]", draw)


def plot_flags(
    df: pd.DataFrame,
    sensors: Sequence[str] | None = None,
    t_range: tuple[float, float] | None = None,
    metrics: Mapping[str, Mapping[str, Any]] | Any | None = None,
) -> tuple[Figure, np.ndarray]:
    """Fig. 7: detection flag (0/1) of each sensor over time, with the fault onset.

    Each detected fault is annotated with its detection delay (from ``metrics`` when
    given, else the fallback of :func:`grfguard.report.summary.sensor_summary`).

    Args:
        df: Output of ``grfguard run`` with ``flag_<s>`` columns.
        sensors: Sensors to show, one row each; default the faulty foot's sensors.
        t_range: ``(start, end)`` in [s].
        metrics: Optional per-sensor metrics (``delay_s``).

    Returns:
        ``(fig, axes)``, axes shape (n_sensors, 1).

    Raises:
        LogFormatError: If none of the sensors has a ``flag_<s>`` column.
    """
    sensors = list(sensors) if sensors is not None else _foot_sensors(df, None)
    sensors = [s for s in sensors if f"flag_{s}" in df.columns]
    if not sensors:
        raise LogFormatError("no flag_<sensor> columns to plot; pass the output of `grfguard run`")
    t, rows = _select(df, t_range)
    summ = sensor_summary(df, metrics)
    fig, axes = _new_figure(len(sensors), 1, 10.0, 0.95 * len(sensors) + 1.3)
    any_f = any_o = False
    for ax, s in zip(axes[:, 0], sensors, strict=True):
        f = df[f"flag_{s}"].fillna(False).to_numpy().astype(float)[rows]
        any_f |= _shade_faults(ax, t, df, rows, s)
        ax.fill_between(t, 0, f, step="post", color=SIGNAL_COLORS["flag"], alpha=0.25,
                        linewidth=0)
        ax.step(t, f, where="post", color=SIGNAL_COLORS["flag"], linewidth=1.2, label="flag")
        on = fault_onsets(df, s)
        for a in on[(on >= t[0]) & (on <= t[-1])][:_MAX_MARKS]:
            ax.axvline(a, color="black", linestyle="--", linewidth=1.0, zorder=4)
            any_o = True
        if s in summ.index and np.isfinite(summ.loc[s, "delay_s"]):
            d = float(summ.loc[s, "delay_s"])
            x = float(summ.loc[s, "onset_s"]) + d
            if t[0] <= x <= t[-1]:
                ax.annotate(f"delay {d:.2f} s", (x, 1.0), xytext=(4, 2),
                            textcoords="offset points", fontsize=8, va="bottom",
                            color=SIGNAL_COLORS["flag"])
        ax.set_ylim(-0.15, 1.25)
        ax.set_yticks([0, 1])
        ax.set_ylabel(s, rotation=0, ha="right", va="center", fontsize=10)
        ax.set_xlim(t[0], t[-1])
        ax.grid(True, axis="x", color="#e3e3e3", linewidth=0.6)
        ax.grid(False, axis="y")
    axes[-1, 0].set_xlabel("time [s]")
    extras = _legend_extras(any_f, False, False)
    if any_o:
        extras.append(Line2D([], [], color="black", linestyle="--", label="fault onset"))
    _figure_legend(fig, axes, extras)
    fig.suptitle("Detection flags (0/1)", fontsize=12, x=0.01, ha="left")
    return fig, axes


# --------------------------------------------------------------------------- extras
def plot_sensor(
    df: pd.DataFrame, sensor: str, t_range: tuple[float, float] | None = None
) -> tuple[Figure, np.ndarray]:
    """Everything about one sensor: forces on top, fault and flag below.

    Returns:
        ``(fig, axes)``, axes shape (2, 1).
    """
    if sensor not in detect_sensors(df):
        raise LogFormatError(
            f"sensor {sensor!r} has no columns in the log; sensors present: {detect_sensors(df)}"
        )
    t, rows = _select(df, t_range)
    fig, axes = _new_figure(2, 1, 10.0, 5.2)
    fig.get_layout_engine().set(h_pad=0.02)
    ax0, ax1 = axes[:, 0]
    c = _contact_strip(ax0, t, df, rows, sensor[:1])
    f = _shade_faults(ax0, t, df, rows, sensor)
    _shade_faults(ax1, t, df, rows, sensor)
    _line(ax0, t, df, rows, f"force_{sensor}", "measured", zorder=2)
    _line(ax0, t, df, rows, f"vfs_{sensor}", "vfs", zorder=3)
    _line(ax0, t, df, rows, f"recovered_{sensor}", "recovered", zorder=3)
    _line(ax0, t, df, rows, f"true_force_{sensor}", "true", zorder=4)
    _line(ax1, t, df, rows, f"eta_{sensor}", "eta", zorder=3)
    _line(ax1, t, df, rows, f"fault_{sensor}", "fault", zorder=4)
    a = _mark_alarms(ax0, t, df, sensor)
    _mark_alarms(ax1, t, df, sensor)
    if f"flag_{sensor}" in df.columns:
        axf = ax1.twinx()
        fl = df[f"flag_{sensor}"].fillna(False).to_numpy().astype(float)[rows]
        axf.step(t, fl, where="post", color=SIGNAL_COLORS["flag"], linewidth=1.0, label="flag")
        axf.set_ylim(-0.05, 1.6)
        axf.set_yticks([0, 1])
        axf.set_ylabel("flag")
        axf.spines["top"].set_visible(False)
    ax0.set_ylabel("force [N]")
    ax1.set_ylabel("fault [N]")
    ax1.set_xlabel("time [s]")
    ax0.set_xlim(t[0], t[-1])
    extras = _legend_extras(f, a, c)
    if f"flag_{sensor}" in df.columns:
        extras.append(Line2D([], [], color=SIGNAL_COLORS["flag"], label="flag (0/1)"))
    _figure_legend(fig, axes, extras)
    fig.suptitle(f"{_SIDES.get(sensor[:1], '')} foot, {_sensor_title(sensor)}", fontsize=12,
                 x=0.01, ha="left")
    return fig, axes


def plot_detection_timeline(
    df: pd.DataFrame, t_range: tuple[float, float] | None = None
) -> tuple[Figure, Axes]:
    """All sensors on one axis: injected fault windows (shaded) and alarms (bars).

    Returns:
        ``(fig, ax)``.
    """
    sensors = detect_sensors(df)
    t, rows = _select(df, t_range)
    fig, axes = _new_figure(1, 1, 10.0, 0.42 * len(sensors) + 1.5)
    ax = axes[0, 0]
    any_f = any_a = False
    for i, s in enumerate(sensors):
        y = len(sensors) - 1 - i
        m = fault_mask(df, s)
        if m is not None and m[rows].any():
            for a, b in intervals(t, m[rows])[:_MAX_MARKS]:
                ax.fill_between([a, b], y - 0.42, y + 0.42, color=rgba_to_mpl(FAULT_SHADE),
                                linewidth=0)
            any_f = True
        if f"flag_{s}" in df.columns:
            fl = df[f"flag_{s}"].fillna(False).to_numpy().astype(bool)[rows]
            for a, b in intervals(t, fl):
                ax.fill_between([a, max(b, a + 1e-3 * (t[-1] - t[0]))], y - 0.2, y + 0.2,
                                color=SIGNAL_COLORS["flag"], linewidth=0)
                any_a = True
    ax.set_yticks(range(len(sensors)), list(reversed(sensors)))
    ax.set_ylim(-0.6, len(sensors) - 0.4)
    ax.set_xlim(t[0], t[-1])
    ax.set_xlabel("time [s]")
    ax.grid(False, axis="y")
    h = _legend_extras(any_f, False, False)
    if any_a:
        h.append(Patch(color=SIGNAL_COLORS["flag"], label="flag on"))
    if h:
        fig.legend(handles=h, loc="outside lower center", ncols=len(h), fontsize=9,
                   frameon=False)
    fig.suptitle("Detection timeline", fontsize=12, x=0.01, ha="left")
    return fig, ax


def _cell(v: Any, digits: int) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return "–" if math.isnan(float(v)) else f"{float(v):.{digits}f}"
    return str(v)


def plot_summary_table(
    df: pd.DataFrame, metrics: Mapping[str, Mapping[str, Any]] | Any | None = None
) -> tuple[Figure, Axes]:
    """The per-sensor summary (:func:`grfguard.report.summary.sensor_summary`) as a table.

    Returns:
        ``(fig, ax)``.
    """
    summ = sensor_summary(df, metrics)
    cols = [
        ("state", "state", 0),
        ("injected_kind", "injected", 0),
        ("kind_estimated", "detected", 0),
        ("delay_s", "delay [s]", 2),
        ("false_alarms", "false\nalarms", 0),
        ("true_size_n", "true size\n[N]", 1),
        ("estimated_size_n", "est. size\n[N]", 1),
        ("fault_size_error_n", "size error\n[N]", 1),
        ("recovery_rmse_n", "recovery\nRMSE [N]", 1),
    ]
    cols = [c for c in cols if c[0] in summ.columns]
    text = [[str(s)] + [_cell(summ.loc[s, c], d) for c, _, d in cols] for s in summ.index]
    fig = Figure(figsize=(10.0, 0.3 * len(summ) + 0.9), layout="constrained", dpi=100)
    ax = fig.subplots()
    ax.axis("off")
    tab = ax.table(cellText=text, colLabels=["sensor"] + [h for _, h, _ in cols],
                   loc="upper center", cellLoc="center", bbox=[0.0, 0.0, 1.0, 1.0])
    tab.auto_set_font_size(False)
    tab.set_fontsize(9)
    state_colors = {"detected": "#fde2d6", "missed": "#f9c5c5", "false alarm": "#fff1c2",
                    "healthy": "#dcf3e8", "ok": "#dcf3e8", "alarm": "#fff1c2"}
    for i, s in enumerate(summ.index):
        tab[i + 1, 0].set_text_props(fontweight="bold")
        tab[i + 1, 1].set_facecolor(state_colors.get(str(summ.loc[s, "state"]), "white"))
    for j in range(len(cols) + 1):
        tab[0, j].set_facecolor("#f0f2f5")
        for i in range(len(summ) + 1):
            tab[i, j].set_edgecolor("#bbbbbb")
    fig.suptitle("Per-sensor summary", fontsize=12, x=0.01, ha="left")
    return fig, ax


def write_png_figures(
    df: pd.DataFrame,
    out_dir: str | Path,
    metrics: Mapping[str, Mapping[str, Any]] | Any | None = None,
    dpi: int = 150,
    t_range: tuple[float, float] | None = None,
    per_sensor: bool | Sequence[str] | None = None,
) -> list[Path]:
    """Write the paper's Figures 4-7 and the extras as PNG files (Agg backend).

    Files: ``fig4_vfs_vs_true``, ``fig5_fault_estimate``, ``fig6_recovery``,
    ``fig7_flags``, ``detection_timeline``, ``summary_table`` and ``sensor_<s>`` per
    sensor. Figures whose columns are missing from ``df`` are skipped (Fig. 5 needs
    ``eta_*``, Fig. 6 ``recovered_*``, Fig. 7 and the timeline ``flag_*``).

    Args:
        df: Output of ``grfguard run``.
        out_dir: Directory to write to (created).
        metrics: Optional per-sensor metrics for the summary table and Fig. 7.
        dpi: Resolution in dots per inch.
        t_range: ``(start, end)`` in [s]; default see module docstring.
        per_sensor: Which ``sensor_<s>`` figures to write: None (default) the sensors
            with an injected fault or an alarm, True all, False none, or a list of names.

    Returns:
        The PNG paths written, in order.

    Raises:
        ConfigError: If ``dpi`` is not a positive integer.
    """
    if not (isinstance(dpi, int) and 10 <= dpi <= 1200):
        raise ConfigError(f"dpi = {dpi!r} must be an integer in [10, 1200]")
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cols = set(map(str, df.columns))
    has = {p: any(c.startswith(p) for c in cols) for p in ("eta_", "recovered_", "flag_",
                                                            "vfs_")}
    jobs: list[tuple[str, Any]] = []
    if has["vfs_"]:
        jobs.append(("fig4_vfs_vs_true", lambda: plot_vfs_vs_true(df, t_range=t_range)))
    if has["eta_"]:
        jobs.append(("fig5_fault_estimate", lambda: plot_fault_estimate(df, t_range=t_range)))
    if has["recovered_"]:
        jobs.append(("fig6_recovery", lambda: plot_recovery(df, t_range=t_range)))
    if has["flag_"]:
        jobs.append(("fig7_flags", lambda: plot_flags(df, t_range=t_range, metrics=metrics)))
        jobs.append(("detection_timeline", lambda: plot_detection_timeline(df, t_range=t_range)))
    jobs.append(("summary_table", lambda: plot_summary_table(df, metrics)))
    if per_sensor is None:
        chosen = [
            s for s in detect_sensors(df)
            if alarm_onsets(df, s).size
            or ((m := fault_mask(df, s)) is not None and bool(m.any()))
        ]
    elif per_sensor is True:
        chosen = detect_sensors(df)
    elif per_sensor is False:
        chosen = []
    else:
        chosen = [str(s) for s in per_sensor]
    for s in chosen:
        jobs.append((f"sensor_{s}", lambda s=s: plot_sensor(df, s, t_range=t_range)))
    paths = []
    for name, make in jobs:
        fig, _ = make()
        FigureCanvasAgg(fig)
        p = out / f"{name}.png"
        fig.savefig(p, dpi=dpi, facecolor="white")
        paths.append(p)
    return paths
