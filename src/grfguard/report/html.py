"""A standalone, offline HTML report of one ``grfguard run`` output.

One file: plotly.js is inlined once (no CDN, no external fonts, no network), the
figure data is one JSON block of base64 float32 typed arrays, and the page shows

* the run's metadata (robot, gait, method, thresholds, ... from ``df.attrs``),
* a per-sensor summary table (state, kind, size, delay, recovery error), see
  :func:`grfguard.report.summary.sensor_summary`,
* an overview: detection timeline of all sensors and the vertical force per foot,
* one interactive figure per sensor: forces (measured, VFS, recovered, truth) on
  top, fault (estimated, true) and the detection flag below; planned stance of the
  sensor's foot and injected fault windows shaded, alarm onsets as red dashed lines.

Large logs: every trace is decimated for display to ``max_points`` buckets keeping
each bucket's min and max (peaks survive), with full resolution within
``focus_s`` [s] of every fault and alarm onset; 0/1 signals are stored exactly as
change points. A 10-minute 1 kHz log gives a ~10 MB file (see BENCHMARKS.md).

The time axes of all figures are linked (zoom or pan one, all follow). Figures are
drawn one per browser task so the table and the first figures show while the rest
draw; when every figure is drawn the page sets ``window.grfguardReport.ready = true``
(browser tests and benchmarks wait on it).
"""

from __future__ import annotations

import base64
import html as _html
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import ConfigError, LogFormatError
from grfguard.io.logio import to_jsonable
from grfguard.report._decimate import intervals, minmax_indices, step_edges, window_mask
from grfguard.report.style import (
    ALARM_COLOR,
    CONTACT_SHADE,
    FAULT_SHADE,
    SIGNAL_COLORS,
    SIGNAL_LABELS,
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
    "write_html_report",
    "build_html_report",
    "sensor_figure_specs",
    "overview_figure_specs",
]

_SIDE_NAMES = {"r": "right", "l": "left"}
_CORNER_NAMES = {1: "front-left", 2: "front-right", 3: "rear-left", 4: "rear-right"}
#: Maximum number of alarm-onset lines drawn per figure (the rest are counted).
MAX_ALARM_LINES = 200
#: Maximum number of fault-window rectangles drawn per figure.
MAX_FAULT_WINDOWS = 200


def _typed(a: np.ndarray) -> dict[str, str]:
    """plotly.js typed-array encoding (base64 little-endian float32)."""
    a32 = np.ascontiguousarray(np.asarray(a, dtype="<f4"))
    return {"dtype": "f4", "bdata": base64.b64encode(a32.tobytes()).decode("ascii")}


def _sensor_title(sensor: str) -> str:
    side = _SIDE_NAMES.get(sensor[:1], sensor[:1])
    try:
        corner = _CORNER_NAMES.get(int(sensor[1:]), f"sensor {sensor[1:]}")
    except ValueError:
        corner = sensor
    return f"{sensor}: {side} foot, {corner}"


def _line_trace(
    df: pd.DataFrame,
    t: np.ndarray,
    col: str,
    kind: str,
    yaxis: str,
    dash: str,
    width: float,
    keep: np.ndarray | None,
    max_points: int,
) -> dict[str, Any]:
    """One decimated line trace of column ``col`` (a signal of type ``kind``)."""
    y = df[col].to_numpy(dtype=float)
    idx = minmax_indices(y, max_points, keep)
    return {
        "type": "scatter",
        "mode": "lines",
        "name": SIGNAL_LABELS[kind],
        "legendgroup": kind,
        "x": _typed(t[idx]),
        "y": _typed(y[idx]),
        "yaxis": yaxis,
        "line": {"color": SIGNAL_COLORS[kind], "width": width, "dash": dash},
        "hovertemplate": f"{SIGNAL_LABELS[kind]}: %{{y:.1f}} N<extra></extra>",
        "meta": {"signal": kind, "column": col},
    }


def sensor_figure_specs(
    df: pd.DataFrame, max_points: int = 2000, focus_s: float = 1.5
) -> list[dict[str, Any]]:
    """Plotly figure specs (``{"id", "sensor", "data", "layout", "n_traces"}``) per sensor.

    Args:
        df: Output of ``grfguard run`` (``time`` [s] plus any per-sensor columns).
        max_points: Number of min/max buckets per trace (display decimation).
        focus_s: Half-width in [s] of the full-resolution windows around every fault
            and alarm onset.

    Returns:
        One JSON-serialisable spec per sensor found in ``df``.
    """
    t = _time(df)
    specs: list[dict[str, Any]] = []
    for k, s in enumerate(detect_sensors(df)):
        side = s[:1]
        centres = np.concatenate([fault_onsets(df, s), alarm_onsets(df, s)])
        keep = window_mask(t, centres, focus_s) if centres.size else None
        if keep is not None and keep.sum() > 20 * max_points:
            keep = None  # an alarm storm: fall back to plain decimation
        data: list[dict[str, Any]] = []

        def line(col: str, kind: str, yaxis: str, dash: str = "solid", width: float = 1.4,
                 data: list[dict[str, Any]] = data, keep: np.ndarray | None = keep) -> None:
            if col in df.columns:
                data.append(_line_trace(df, t, col, kind, yaxis, dash, width, keep, max_points))

        cc = f"contact_ref_{side}"
        if cc in df.columns:
            data.append(_contact_trace(df, t, cc, side))
        line(f"true_force_{s}", "true", "y", dash="dot", width=1.6)
        line(f"force_{s}", "measured", "y")
        line(f"vfs_{s}", "vfs", "y")
        line(f"recovered_{s}", "recovered", "y")
        line(f"fault_{s}", "fault", "y2", dash="dot", width=1.6)
        line(f"eta_{s}", "eta", "y2")
        fc = f"flag_{s}"
        if fc in df.columns:
            data.append(_flag_trace(df, t, fc))
        shapes, note = _sensor_shapes(df, t, s)
        has_y2 = any(d["yaxis"] in ("y2", "y4") for d in data)
        layout = _sensor_layout(_sensor_title(s) + note, shapes, has_y2)
        for d in data:
            d["xaxis"] = "x"
        specs.append(
            {
                "id": f"fig-{k}-{s}",
                "sensor": s,
                "data": data,
                "layout": layout,
                "n_traces": len(data),
            }
        )
    return specs


def _contact_trace(df: pd.DataFrame, t: np.ndarray, cc: str, side: str) -> dict[str, Any]:
    """Shaded strip of the planned stance of foot ``side`` (column ``cc``)."""
    x, y = step_edges(t, df[cc].fillna(0).to_numpy().astype(float) > 0.5)
    return {
        "type": "scatter",
        "mode": "lines",
        "name": f"stance ({_SIDE_NAMES.get(side, side)} foot, planned)",
        "x": _typed(x),
        "y": _typed(y),
        "yaxis": "y3",
        "fill": "tozeroy",
        "legendrank": 2000,
        "fillcolor": CONTACT_SHADE,
        "line": {"width": 0, "shape": "hv", "color": CONTACT_SHADE},
        "hoverinfo": "skip",
        "meta": {"signal": "contact", "column": cc},
    }


def _flag_trace(df: pd.DataFrame, t: np.ndarray, fc: str) -> dict[str, Any]:
    """Step trace of the 0/1 flag column ``fc``."""
    x, y = step_edges(t, df[fc].fillna(False).to_numpy().astype(bool))
    return {
        "type": "scatter",
        "mode": "lines",
        "name": "flag (0/1)",
        "x": _typed(x),
        "y": _typed(y),
        "yaxis": "y4",
        "line": {"color": SIGNAL_COLORS["flag"], "width": 1.2, "shape": "hv"},
        "hovertemplate": "flag: %{y:.0f}<extra></extra>",
        "meta": {"signal": "flag", "column": fc},
    }


def _sensor_shapes(df: pd.DataFrame, t: np.ndarray, s: str) -> tuple[list[dict[str, Any]], str]:
    """Shaded injected-fault windows and dashed alarm-onset lines of sensor ``s`` (capped),
    and a title note when the caps cut marks."""
    shapes: list[dict[str, Any]] = []
    fm = fault_mask(df, s)
    windows = intervals(t, fm) if fm is not None and fm.any() else []
    for i, (a, b) in enumerate(windows[:MAX_FAULT_WINDOWS]):
        shapes.append(
            {
                "type": "rect",
                "xref": "x",
                "yref": "paper",
                "x0": a,
                "x1": b,
                "y0": 0,
                "y1": 1,
                "fillcolor": FAULT_SHADE,
                "line": {"width": 0},
                "layer": "below",
                "name": "injected fault",
                "showlegend": i == 0,
            }
        )
    onsets = alarm_onsets(df, s)
    for i, a in enumerate(onsets[:MAX_ALARM_LINES]):
        shapes.append(
            {
                "type": "line",
                "xref": "x",
                "yref": "paper",
                "x0": float(a),
                "x1": float(a),
                "y0": 0,
                "y1": 1,
                "line": {"color": ALARM_COLOR, "width": 1.2, "dash": "dash"},
                "name": "alarm onset",
                "showlegend": i == 0,
            }
        )
    note = ""
    if onsets.size > MAX_ALARM_LINES or len(windows) > MAX_FAULT_WINDOWS:
        note = (
            f" (marks capped: {min(onsets.size, MAX_ALARM_LINES)}/{onsets.size} alarm "
            f"onsets, {min(len(windows), MAX_FAULT_WINDOWS)}/{len(windows)} fault windows)"
        )
    return shapes, note


def _sensor_layout(title: str, shapes: list[dict[str, Any]], has_y2: bool) -> dict[str, Any]:
    """Layout of a sensor figure: force panel (with the stance strip) on top, fault and
    flag panel below when ``has_y2``."""
    top = [0.42, 1.0] if has_y2 else [0.0, 1.0]
    layout: dict[str, Any] = {
        "title": {"text": title, "x": 0.01, "font": {"size": 15}},
        "height": 470 if has_y2 else 340,
        "margin": {"l": 70, "r": 60, "t": 40, "b": 90},
        "template": "none",
        "paper_bgcolor": "white",
        "plot_bgcolor": "white",
        "font": {"family": "system-ui, -apple-system, Segoe UI, Roboto, sans-serif"},
        "hovermode": "x",
        "legend": {
            "orientation": "h",
            "yref": "container",
            "y": 0.0,
            "yanchor": "bottom",
            "x": 0,
            "font": {"size": 12},
        },
        "xaxis": {
            "title": {"text": "time [s]"},
            "anchor": "y2" if has_y2 else "y",
            "showgrid": True,
            "gridcolor": "#e5e5e5",
            "zeroline": False,
        },
        "yaxis": {
            "title": {"text": "force [N]"},
            "domain": top,
            "showgrid": True,
            "gridcolor": "#e5e5e5",
            "zeroline": True,
            "zerolinecolor": "#bbbbbb",
        },
        "yaxis3": {  # stance strip: 0/1 fills the top 1/12 of the force panel
            "overlaying": "y",
            "range": [-11, 1],
            "visible": False,
            "fixedrange": True,
        },
        "shapes": shapes,
    }
    if has_y2:
        layout["yaxis2"] = {
            "title": {"text": "fault [N]"},
            "domain": [0.0, 0.34],
            "showgrid": True,
            "gridcolor": "#e5e5e5",
            "zeroline": True,
            "zerolinecolor": "#bbbbbb",
        }
        layout["yaxis4"] = {
            "overlaying": "y2",
            "side": "right",
            "range": [-0.05, 1.6],
            "tickvals": [0, 1],
            "title": {"text": "flag"},
            "showgrid": False,
            "fixedrange": True,
        }
    return layout

def _polygons(spans: list[tuple[float, float]], y: float, half: float) -> tuple[list, list]:
    """Rectangles ``[a, b] x [y - half, y + half]`` as one ``fill='toself'`` path."""
    xs: list[float | None] = []
    ys: list[float | None] = []
    for a, b in spans:
        xs += [a, a, b, b, a, None]
        ys += [y - half, y + half, y + half, y - half, y - half, None]
    return xs, ys


def overview_figure_specs(df: pd.DataFrame, max_points: int = 2000) -> list[dict[str, Any]]:
    """Overview figures: a detection timeline of all sensors and the per-foot totals.

    The timeline shows, per sensor, the injected fault windows (shaded) and the flag-on
    episodes (bars). The totals figure shows, per foot, the VFS total
    (``vfs_total_<side>``), the sum of the measured sensors and of the true forces [N],
    whichever are present.

    Returns:
        Specs like :func:`sensor_figure_specs` (``sensor`` is ``""``).
    """
    t = _time(df)
    sensors = detect_sensors(df)
    specs = [_timeline_spec(df, t, sensors), _feet_spec(df, t, sensors, max_points)]
    return [sp for sp in specs if sp is not None]


def _timeline_spec(df: pd.DataFrame, t: np.ndarray, sensors: list[str]) -> dict[str, Any] | None:
    """Detection timeline: per sensor, injected fault windows (shaded) and flag-on
    episodes (bars); None if there is neither."""
    fx: list[Any] = []
    fy: list[Any] = []
    ax_: list[Any] = []
    ay: list[Any] = []
    n = len(sensors)
    for i, s in enumerate(sensors):
        y = n - 1 - i
        fm = fault_mask(df, s)
        if fm is not None and fm.any():
            xs, ys = _polygons(intervals(t, fm), y, 0.42)
            fx += xs
            fy += ys
        if f"flag_{s}" in df.columns:
            fl = df[f"flag_{s}"].fillna(False).to_numpy().astype(bool)
            xs, ys = _polygons(intervals(t, fl), y, 0.2)
            ax_ += xs
            ay += ys
    data: list[dict[str, Any]] = []
    if fx:
        data.append({"type": "scatter", "mode": "lines", "x": fx, "y": fy, "fill": "toself",
                     "fillcolor": FAULT_SHADE, "line": {"width": 0}, "name": "injected fault",
                     "hoverinfo": "skip", "meta": {"signal": "fault_windows"}})
    if ax_:
        data.append({"type": "scatter", "mode": "lines", "x": ax_, "y": ay, "fill": "toself",
                     "fillcolor": SIGNAL_COLORS["flag"], "line": {"width": 0,
                                                                   "color": SIGNAL_COLORS["flag"]},
                     "name": "flag on", "hoverinfo": "x+name",
                     "meta": {"signal": "flag_episodes"}})
    if data:
        return {
            "id": "fig-timeline", "sensor": "", "data": data, "n_traces": len(data),
            "layout": {
                "title": {"text": "Detection timeline", "x": 0.01, "font": {"size": 15}},
                "height": 110 + 30 * n, "template": "none",
                "margin": {"l": 70, "r": 60, "t": 40, "b": 45},
                "font": {"family": "system-ui, -apple-system, Segoe UI, Roboto, sans-serif"},
                "xaxis": {"title": {"text": "time [s]"}, "range": [float(t[0]), float(t[-1])],
                          "showgrid": True, "gridcolor": "#e5e5e5", "zeroline": False},
                "yaxis": {"tickvals": list(range(n)), "ticktext": list(reversed(sensors)),
                          "range": [-0.6, n - 0.4], "fixedrange": True, "showgrid": False,
                          "zeroline": False},
                "legend": {"orientation": "h", "x": 0.3, "xanchor": "left", "y": 1.0,
                           "yanchor": "bottom"},
                "hovermode": "closest",
            },
        }
    return None


def _feet_spec(df: pd.DataFrame, t: np.ndarray, sensors: list[str],
               max_points: int) -> dict[str, Any] | None:
    """Per foot: VFS total, sum of the measured and of the true forces [N], whichever
    are present; None if none is."""
    data: list[dict[str, Any]] = []
    sides = [side for side in ("r", "l") if any(s[:1] == side for s in sensors)]
    for k, side in enumerate(sides):
        yaxis = "y" if k == 0 else f"y{k + 1}"
        own = [s for s in sensors if s[:1] == side]
        series: list[tuple[str, str, np.ndarray]] = []
        if all(f"force_{s}" in df.columns for s in own):
            series.append(("measured", "measured sum",
                           df[[f"force_{s}" for s in own]].to_numpy(dtype=float).sum(axis=1)))
        if f"vfs_total_{side}" in df.columns:
            series.append(("vfs", "VFS total", df[f"vfs_total_{side}"].to_numpy(dtype=float)))
        if all(f"true_force_{s}" in df.columns for s in own):
            series.append(("true", "true sum", df[[f"true_force_{s}" for s in own]]
                           .to_numpy(dtype=float).sum(axis=1)))
        for kind, label, y in series:
            idx = minmax_indices(y, max_points)
            data.append({
                "type": "scatter", "mode": "lines", "name": label, "legendgroup": kind,
                "showlegend": k == 0, "x": _typed(t[idx]), "y": _typed(y[idx]),
                "xaxis": "x", "yaxis": yaxis,
                "line": {"color": SIGNAL_COLORS[kind], "width": 1.3,
                         "dash": "dot" if kind == "true" else "solid"},
                "hovertemplate": f"{_SIDE_NAMES[side]} {label}: %{{y:.0f}} N<extra></extra>",
                "meta": {"signal": f"foot_{kind}", "side": side},
            })
    if data:
        gap = 0.12
        h = (1.0 - gap * (len(sides) - 1)) / len(sides)
        layout: dict[str, Any] = {
            "title": {"text": "Vertical force per foot", "x": 0.01, "font": {"size": 15}},
            "height": 170 + 190 * len(sides), "template": "none",
            "margin": {"l": 70, "r": 60, "t": 40, "b": 70},
            "font": {"family": "system-ui, -apple-system, Segoe UI, Roboto, sans-serif"},
            "hovermode": "x",
            "legend": {"orientation": "h", "x": 0.3, "xanchor": "left", "y": 1.0,
                       "yanchor": "bottom"},
            "xaxis": {"title": {"text": "time [s]"}, "anchor": f"y{len(sides)}"
                      if len(sides) > 1 else "y", "showgrid": True, "gridcolor": "#e5e5e5"},
        }
        for k, side in enumerate(sides):
            top = 1.0 - k * (h + gap)
            layout["yaxis" if k == 0 else f"yaxis{k + 1}"] = {
                "title": {"text": f"{_SIDE_NAMES[side]} foot [N]"},
                "domain": [max(top - h, 0.0), top], "showgrid": True, "gridcolor": "#e5e5e5",
            }
        return {"id": "fig-feet", "sensor": "", "data": data, "layout": layout,
                "n_traces": len(data)}
    return None

def _fmt(value: Any, digits: int = 2) -> str:
    if value is None:
        return "–"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return "–" if math.isnan(float(value)) else f"{float(value):.{digits}f}"
    return _html.escape(str(value))


_TABLE_COLUMNS: tuple[tuple[str, str, int], ...] = (
    ("state", "state", 0),
    ("injected_kind", "injected kind", 0),
    ("kind_estimated", "detected kind", 0),
    ("kind_correct", "kind correct", 0),
    ("onset_s", "fault onset [s]", 3),
    ("alarm_onset_s", "first alarm [s]", 3),
    ("delay_s", "delay [s]", 3),
    ("false_alarms", "false alarms", 0),
    ("false_alarm_time_s", "false-alarm time [s]", 2),
    ("true_size_n", "true size [N]", 1),
    ("estimated_size_n", "estimated size [N]", 1),
    ("fault_size_error_n", "fault-size error [N]", 1),
    ("recovery_rmse_n", "recovery RMSE [N]", 1),
    ("raw_rmse_n", "raw RMSE [N]", 1),
)


def _summary_html(summary: pd.DataFrame, thresholds: Any) -> str:
    cols = [c for c in _TABLE_COLUMNS if c[0] in summary.columns]
    extra = [c for c in summary.columns if c not in {c[0] for c in _TABLE_COLUMNS}]
    per_sensor_thr = isinstance(thresholds, Mapping) and all(
        isinstance(v, (int, float)) for v in thresholds.values()
    )
    head = "<th>sensor</th>" + "".join(f"<th>{_html.escape(h)}</th>" for _, h, _ in cols)
    head += "".join(f"<th>{_html.escape(str(c))}</th>" for c in extra)
    if per_sensor_thr:
        head += "<th>threshold [N]</th>"
    body = []
    for i, (s, row) in enumerate(summary.iterrows()):
        name = _html.escape(str(s))
        cells = [f"<td><a href='#fig-{i}-{name}'>{name}</a></td>"]
        for c, _, digits in cols:
            v = row[c]
            if c == "state":
                cls = str(v).replace(" ", "-")
                cells.append(f"<td><span class='state {cls}'>{_fmt(v)}</span></td>")
            else:
                cells.append(f"<td>{_fmt(v, digits)}</td>")
        cells += [f"<td>{_fmt(row[c])}</td>" for c in extra]
        if per_sensor_thr:
            cells.append(f"<td>{_fmt(thresholds.get(s, math.nan), 1)}</td>")
        body.append(f"<tr data-sensor='{_html.escape(str(s))}'>" + "".join(cells) + "</tr>")
    return (
        "<table class='summary' id='summary'><thead><tr>" + head + "</tr></thead><tbody>"
        + "".join(body) + "</tbody></table>"
    )


def _model_status_html(df: pd.DataFrame) -> str:
    """One line on the system-level status (``model_mismatch``) when the run has it."""
    if "model_mismatch" not in df.columns or not len(df):
        return ""
    mm = df["model_mismatch"].to_numpy(dtype=bool)
    if not mm.any():
        return "<p class='note' id='model-status'>Model: consistent with the sensors " \
            "(no model_mismatch).</p>"
    reason = ""
    if "model_mismatch_reason" in df.columns:
        reason = str(df["model_mismatch_reason"].to_numpy()[np.flatnonzero(mm)[-1]])
    return (f"<p class='note' id='model-status'>Model: model_mismatch over "
            f"{100 * mm.mean():.0f} % of the run; last reason: {_html.escape(reason)}</p>")


def _value_html(v: Any, depth: int = 0) -> str:
    """Compact HTML of a metadata value: dicts as flowing key/value chips, lists inline."""
    if isinstance(v, dict):
        if not v:
            return "{}"
        if depth >= 2:
            return _html.escape(json.dumps(v, sort_keys=True, default=str)[:600])
        items = "".join(
            f"<span class='kv'><b>{_html.escape(str(k))}</b> {_value_html(x, depth + 1)}</span>"
            for k, x in sorted(v.items(), key=lambda kv: str(kv[0]))
        )
        return f"<div class='kvs'>{items}</div>"
    if isinstance(v, list):
        text = json.dumps(v, default=str)
        if len(text) > 600:
            text = text[:600] + f" … ({len(v)} items)"
        return f"<code>{_html.escape(text)}</code>"
    if isinstance(v, float):
        return _html.escape(f"{v:.6g}")
    return _html.escape(str(v))


def _run_name(df: pd.DataFrame) -> str:
    robot = to_jsonable(df.attrs.get("robot", "run"))
    if isinstance(robot, dict):
        robot = robot.get("name", "run")
    return str(robot)


def _metadata_html(df: pd.DataFrame, t: np.ndarray) -> str:
    rows: list[tuple[str, str]] = []
    if t.size > 1:
        dt = float(np.median(np.diff(t)))
        rows.append(("samples", f"{t.size} ({t[0]:.3f} s to {t[-1]:.3f} s, {1 / dt:.0f} Hz)"))
    has = [
        name
        for name, prefix in (
            ("truth", "true_force_"),
            ("injected faults", "fault_kind_"),
            ("VFS", "vfs_"),
            ("recovery", "recovered_"),
            ("flags", "flag_"),
            ("planned contact", "contact_ref_"),
        )
        if any(str(c).startswith(prefix) for c in df.columns)
    ]
    rows.append(("signals present", ", ".join(has) if has else "forces only"))
    preferred = ("robot", "gait", "method", "thresholds", "seed", "scenario", "faults")
    keys = [k for k in preferred if k in df.attrs] + sorted(
        (str(k) for k in df.attrs if k not in preferred), key=str
    )
    for k in keys:
        rows.append((k, _value_html(to_jsonable(df.attrs[k]))))
    return (
        "<table class='meta' id='metadata'>"
        + "".join(f"<tr><th>{_html.escape(k)}</th><td>{v}</td></tr>" for k, v in rows)
        + "</table>"
    )


#: Page style shared by the HTML reports (this one and the campaign report).
BASE_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;margin:0;color:#222;
background:#fafafa}
header{background:#1f2d3d;color:#fff;padding:14px 24px}
header h1{margin:0;font-size:20px;font-weight:600}
header p{margin:4px 0 0;font-size:13px;opacity:.8}
main{padding:12px 24px;max-width:1500px}
h2{font-size:16px;margin:22px 0 8px}
table{border-collapse:collapse;font-size:13px;background:#fff}
th,td{border:1px solid #ddd;padding:4px 8px;text-align:right;vertical-align:top}
th{background:#f0f2f5}
"""

_CSS = BASE_CSS + """table.meta th,table.meta td{text-align:left}
table.meta{width:100%}
table.meta th{width:150px}
.kvs{display:flex;flex-wrap:wrap;gap:2px 14px}
.kv{white-space:nowrap;font-size:12px}
.kv b{font-weight:600;color:#445}
table.meta code{font-size:12px;white-space:normal;word-break:break-all}
td:first-child{text-align:left;font-weight:600}
.state{padding:1px 6px;border-radius:8px;font-size:12px;white-space:nowrap}
.state.detected{background:#fde2d6;color:#8a2a00}
.state.healthy,.state.ok{background:#dcf3e8;color:#0b5a3a}
.state.false-alarm,.state.alarm{background:#fff1c2;color:#6b5200}
.state.missed{background:#f9c5c5;color:#7a0000}
.state.faulty{background:#eee;color:#333}
.fig{background:#fff;border:1px solid #e3e3e3;margin:10px 0}
.note{font-size:12px;color:#555}
"""

_JS = """
(function () {
  var status = {ready: false, figures: [], errors: [], renderMs: null, readyAtMs: null,
                firstFigureAtMs: null};
  window.grfguardReport = status;
  var specs = JSON.parse(document.getElementById('grfguard-data').textContent);
  var config = {responsive: true, displaylogo: false, scrollZoom: false,
                modeBarButtonsToRemove: ['lasso2d', 'select2d']};
  var t0 = performance.now();
  // One figure per task: the page paints (table, first figures) while the rest draw.
  function nextTask() { return new Promise(function (r) { setTimeout(r, 0); }); }
  var chain = nextTask();
  specs.forEach(function (spec) {
    status.figures.push({id: spec.id, sensor: spec.sensor, n_traces: spec.n_traces});
    chain = chain.then(function () {
      return Plotly.newPlot(spec.id, spec.data, spec.layout, config);
    }).then(function () {
      if (status.firstFigureAtMs === null) { status.firstFigureAtMs = performance.now(); }
      return nextTask();
    }).catch(function (err) { status.errors.push(String(err)); });
  });
  // Linked time axes: zooming or panning one figure's time axis moves all the others.
  var syncing = false;
  function linkTimeAxes() {
    var divs = specs.map(function (sp) { return document.getElementById(sp.id); });
    divs.forEach(function (gd) {
      gd.on('plotly_relayout', function (ev) {
        if (syncing) { return; }
        var upd = null;
        if (ev['xaxis.range[0]'] !== undefined) {
          upd = {'xaxis.range': [ev['xaxis.range[0]'], ev['xaxis.range[1]']]};
        } else if (ev['xaxis.range'] !== undefined) {
          upd = {'xaxis.range': ev['xaxis.range']};
        } else if (ev['xaxis.autorange']) {
          upd = {'xaxis.autorange': true};
        }
        if (!upd) { return; }
        syncing = true;
        Promise.all(divs.filter(function (o) { return o !== gd; }).map(function (o) {
          return Plotly.relayout(o, upd);
        })).then(function () { syncing = false; }, function () { syncing = false; });
      });
    });
  }
  chain.then(function () {
    linkTimeAxes();
    status.renderMs = performance.now() - t0;
    status.readyAtMs = performance.now();  // since navigation start (timeOrigin)
    status.ready = true;
    document.body.setAttribute('data-ready', '1');
  });
})();
"""


def build_html_report(
    df: pd.DataFrame,
    metrics: Mapping[str, Mapping[str, Any]] | None = None,
    title: str | None = None,
    max_points: int = 2000,
    focus_s: float = 1.5,
) -> str:
    """The report as one HTML string (see :func:`write_html_report`)."""
    if not isinstance(df, pd.DataFrame):
        raise LogFormatError(
            f"the report needs a pandas DataFrame (output of `grfguard run`), got "
            f"{type(df).__name__}"
        )
    if not (isinstance(max_points, int) and max_points >= 10):
        raise ConfigError(f"max_points = {max_points!r} must be an integer >= 10")
    if not (focus_s >= 0 and math.isfinite(focus_s)):
        raise ConfigError(f"focus_s = {focus_s!r} must be a finite number of seconds >= 0")
    t = _time(df)
    if not detect_sensors(df):
        raise LogFormatError(
            "no sensor columns found (force_r1, vfs_r1, flag_r1, ...); pass the output of "
            "`grfguard run` or a log following the log contract"
        )
    from plotly.offline import get_plotlyjs

    summary = sensor_summary(df, metrics)
    overview = overview_figure_specs(df, max_points=max_points)
    specs = overview + sensor_figure_specs(df, max_points=max_points, focus_s=focus_s)
    title = title or f"grfguard report: {_run_name(df)}"
    payload = json.dumps(specs, separators=(",", ":"), allow_nan=False)
    payload = payload.replace("</", "<\\/")
    n_faulty = int((summary["state"] == "detected").sum() + (summary["state"] == "missed").sum())
    n_flagged = int(sum(alarm_onsets(df, s).size > 0 for s in summary.index))
    subtitle = (
        f"{t.size} samples, {t[-1] - t[0]:.1f} s; {len(summary)} sensors, "
        f"{n_faulty} with injected faults, {n_flagged} raised alarms"
    )
    def div(sp: dict[str, Any]) -> str:
        return (
            f"<div class='fig' id='{sp['id']}' data-sensor='{sp['sensor']}' "
            f"data-traces='{sp['n_traces']}' style='height:{sp['layout']['height']}px'></div>"
        )

    overview_divs = "".join(div(sp) for sp in overview)
    figs = "".join(div(sp) for sp in specs[len(overview):])
    return (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"<meta name='generator' content='grfguard'><title>{_html.escape(title)}</title>"
        f"<style>{_CSS}</style>"
        f"<script>{get_plotlyjs()}</script></head><body>"
        f"<header><h1>{_html.escape(title)}</h1><p>{_html.escape(subtitle)}</p></header><main>"
        "<h2>Sensors</h2>"
        + _summary_html(summary, df.attrs.get("thresholds"))
        + _model_status_html(df)
        + "<p class='note'>"
        + ("Metrics from grfguard.evaluate.detection where given, else: " if metrics is not None
           else "")
        + "Delay: first alarm at or after the fault onset. False alarms: alarm "
        "episodes starting outside injected fault windows. Size: mean over the last second of "
        "the fault window. Recovery / raw RMSE: recovered / measured minus true force over the "
        "flagged samples of the fault window. – : undefined or not in the log.</p>"
        + ("<h2>Overview</h2>" + overview_divs if overview_divs else "")
        + "<h2>Run</h2>" + _metadata_html(df, t)
        + "<h2>Signals</h2><p class='note'>Blue strip at the top: planned stance of the "
        "sensor's foot; shaded red: injected fault; red dashed lines: alarm onsets. Traces are "
        f"decimated for display ({max_points} min/max buckets, peaks kept; full resolution within "
        f"{focus_s:g} s of fault and alarm onsets). Click legend entries to hide traces, drag "
        "to zoom (all figures follow the time axis), double-click to reset.</p>"
        + figs
        + "<script type='application/json' id='grfguard-data'>" + payload + "</script>"
        + f"<script>{_JS}</script></main></body></html>"
    )


def write_html_report(
    df: pd.DataFrame,
    path: str | Path,
    metrics: Mapping[str, Mapping[str, Any]] | None = None,
    title: str | None = None,
    max_points: int = 2000,
    focus_s: float = 1.5,
) -> Path:
    """Write one self-contained HTML report of a ``grfguard run`` output.

    Args:
        df: Output of ``grfguard run``: ``time`` [s] and any of ``force_<s>``,
            ``true_force_<s>``, ``vfs_<s>``, ``recovered_<s>``, ``eta_<s>``,
            ``fault_<s>`` [N], ``flag_<s>``, ``kind_<s>``, ``fault_kind_<s>``,
            ``contact_ref_r/l``; metadata in ``df.attrs``. Missing columns are
            left out of the report.
        path: Output file (``.html``); parent directories are created.
        metrics: Optional per-sensor metrics (sensor -> dict) from
            ``grfguard.evaluate.detection``; a fallback summary is computed otherwise.
        title: Page title (default: ``grfguard report: <robot>``).
        max_points: Min/max buckets per trace for display.
        focus_s: Half-width in [s] of full-resolution windows around fault and alarm onsets.

    Returns:
        The path written.

    Raises:
        LogFormatError: If ``df`` has no ``time`` column, time is not strictly
            increasing, or there is no sensor column.
        ConfigError: If ``max_points`` or ``focus_s`` is out of range.
    """
    text = build_html_report(df, metrics=metrics, title=title, max_points=max_points,
                             focus_s=focus_s)
    from grfguard.io.safe import atomic_write_text

    return atomic_write_text(Path(path), text, what="HTML report")  # no partial report
