"""Reports: the standalone HTML report, the summary table and the PNG figures.

Built on the seeded synthetic run of :mod:`helpers.synthetic` (paper scenario:
at 5 s r1 frozen 0, r2 +100 N, r3 +15 N/s, r4 -100 N; a 0.15 s false alarm on l2 at 2 s),
and on a real simulated walk when the monitor is available.
"""

from __future__ import annotations

import base64
import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from grfguard.errors import ConfigError, LogFormatError
from grfguard.model.robot import SENSOR_NAMES
from grfguard.report import build_html_report, sensor_summary, write_html_report
from grfguard.report._decimate import intervals, minmax_indices, step_edges, window_mask
from grfguard.report.summary import normalize_metrics
from helpers.synthetic import synthetic_run

# ------------------------------------------------------------------------------ helpers


def _all_specs(html: str) -> list[dict]:
    m = re.search(r"<script type='application/json' id='grfguard-data'>(.*?)</script>", html,
                  re.S)
    assert m, "figure data block missing"
    return json.loads(m.group(1))


def _payload(html: str) -> list[dict]:
    """The per-sensor figure specs (overview figures left out)."""
    return [sp for sp in _all_specs(html) if sp["sensor"]]


def _decode(arr: dict | list) -> np.ndarray:
    if isinstance(arr, list):
        return np.asarray(arr, dtype=float)
    assert arr["dtype"] == "f4"
    return np.frombuffer(base64.b64decode(arr["bdata"]), dtype="<f4").astype(float)


def _table_rows(html: str) -> dict[str, list[str]]:
    body = re.search(r"<table class='summary' id='summary'>.*?<tbody>(.*?)</tbody>", html, re.S)
    assert body
    rows = {}
    for tr in re.findall(r"<tr data-sensor='(\w+)'>(.*?)</tr>", body.group(1), re.S):
        cells = [re.sub(r"<[^>]+>", "", c) for c in re.findall(r"<td>(.*?)</td>", tr[1], re.S)]
        rows[tr[0]] = cells
    return rows


def _table_header(html: str) -> list[str]:
    head = re.search(r"<table class='summary' id='summary'><thead><tr>(.*?)</tr>", html, re.S)
    assert head
    return re.findall(r"<th>(.*?)</th>", head.group(1))


@pytest.fixture(scope="module")
def run_df() -> pd.DataFrame:
    return synthetic_run(duration_s=12.0, seed=3)


@pytest.fixture(scope="module")
def report_html(run_df: pd.DataFrame, tmp_path_factory: pytest.TempPathFactory) -> str:
    path = write_html_report(run_df, tmp_path_factory.mktemp("rep") / "sub" / "report.html")
    assert path.is_file()
    return path.read_text(encoding="utf-8")


# ---------------------------------------------------------------------------- decimation


def test_minmax_indices_keep_peaks_and_focus() -> None:
    rng = np.random.default_rng(0)
    y = rng.normal(size=100_000)
    y[12_345], y[77_777] = 50.0, -40.0
    idx = minmax_indices(y, 500)
    assert idx.size <= 2 * 500 + 2
    assert np.all(np.diff(idx) > 0)
    assert y[idx].max() == 50.0 and y[idx].min() == -40.0
    assert idx[0] == 0 and idx[-1] == y.size - 1
    # Every bucket's extremes survive, not only the global ones.
    starts = np.linspace(0, y.size, 501).astype(int)
    for a, b in zip(starts[:-1:37], starts[1::37], strict=True):
        sel = idx[(idx >= a) & (idx < b)]
        assert y[sel].max() == y[a:b].max() and y[sel].min() == y[a:b].min()
    keep = np.zeros(y.size, bool)
    keep[40_000:41_000] = True
    idx2 = minmax_indices(y, 500, keep)
    assert np.isin(np.arange(40_000, 41_000), idx2).all()


def test_minmax_indices_nan_gap_and_short() -> None:
    y = np.arange(10_000, dtype=float)
    y[3000:4000] = np.nan
    idx = minmax_indices(y, 100)
    assert np.isnan(y[idx]).any()  # the gap stays a gap
    assert np.array_equal(minmax_indices(np.ones(50), 100), np.arange(50))


def test_step_edges_intervals_window() -> None:
    t = np.arange(8) * 0.5
    s = np.array([0, 0, 1, 1, 0, 0, 1, 1])
    x, y = step_edges(t, s)
    assert x.tolist() == [0.0, 1.0, 2.0, 3.0, 3.5] and y.tolist() == [0, 1, 0, 1, 1]
    assert intervals(t, s) == [(1.0, 2.0), (3.0, 3.5)]
    m = window_mask(np.arange(10.0), np.array([2.0, 8.0]), 1.0)
    assert np.flatnonzero(m).tolist() == [1, 2, 3, 7, 8, 9]


# ------------------------------------------------------------------------------ summary


def test_summary_fallback_on_paper_scenario(run_df: pd.DataFrame) -> None:
    s = sensor_summary(run_df)
    assert list(s.index) == list(SENSOR_NAMES)
    for sensor, kind, delay in (("r1", "frozen", 0.85), ("r2", "offset", 0.25),
                                ("r3", "drift", 0.9), ("r4", "offset", 0.3)):
        assert s.loc[sensor, "state"] == "detected"
        assert s.loc[sensor, "injected_kind"] == kind
        assert s.loc[sensor, "kind_estimated"] == kind
        assert s.loc[sensor, "delay_s"] == pytest.approx(delay, abs=1.5e-3)
        assert s.loc[sensor, "false_alarms"] == 0
    assert s.loc["r2", "true_size_n"] == pytest.approx(100.0)
    assert s.loc["r4", "true_size_n"] == pytest.approx(-100.0)
    assert s.loc["r2", "estimated_size_n"] == pytest.approx(100.0, abs=15.0)
    # Recovery beats the raw faulty signal by far on the offsets.
    assert s.loc["r2", "recovery_rmse_n"] < 0.3 * s.loc["r2", "raw_rmse_n"]
    assert s.loc["l2", "state"] == "false alarm" and s.loc["l2", "false_alarms"] == 1
    assert s.loc["l1", "state"] == "healthy"
    assert math.isnan(s.loc["l1", "delay_s"])


def test_summary_without_truth(run_df: pd.DataFrame) -> None:
    df = run_df[[c for c in run_df.columns if not c.startswith(("true_", "fault"))]]
    s = sensor_summary(df)
    assert s.loc["r2", "state"] == "alarm" and s.loc["l1", "state"] == "ok"
    assert s.loc["r2", "injected_kind"] == "unknown"
    assert math.isnan(s.loc["r2", "recovery_rmse_n"])


def test_summary_metrics_override_and_shapes(run_df: pd.DataFrame) -> None:
    s = sensor_summary(run_df, {"r2": {"delay_s": 0.123, "my_metric": 7}})
    assert s.loc["r2", "delay_s"] == 0.123 and s.loc["r2", "my_metric"] == 7
    assert s.loc["r1", "delay_s"] == pytest.approx(0.85, abs=1.5e-3)  # untouched
    frame = pd.DataFrame({"sensor": ["r2"], "detected": [False], "faulty": [True]})
    assert sensor_summary(run_df, frame).loc["r2", "state"] == "missed"
    assert normalize_metrics([{"sensor": "l1", "x": 1}]) == {"l1": {"sensor": "l1", "x": 1}}
    with pytest.raises(LogFormatError, match="metrics"):
        sensor_summary(run_df, {"r2": 3})
    with pytest.raises(LogFormatError, match="metrics"):
        sensor_summary(run_df, 42)


def test_summary_accepts_evaluate_detection(run_df: pd.DataFrame) -> None:
    detection = pytest.importorskip("grfguard.evaluate.detection")
    table = detection.evaluate_detection(run_df)
    s = sensor_summary(run_df, table)
    assert s.loc["r2", "delay_s"] == pytest.approx(table.loc["r2", "delay_s"])
    assert s.loc["r2", "state"] == "detected" and s.loc["l2", "state"] == "false alarm"


# --------------------------------------------------------------------------------- HTML


def test_html_traces_per_sensor(report_html: str, run_df: pd.DataFrame) -> None:
    specs = _payload(report_html)
    assert [sp["sensor"] for sp in specs] == list(SENSOR_NAMES)
    for sp in specs:
        s = sp["sensor"]
        cols = {tr["meta"]["column"] for tr in sp["data"]}
        assert cols == {f"force_{s}", f"true_force_{s}", f"vfs_{s}", f"recovered_{s}",
                        f"eta_{s}", f"fault_{s}", f"flag_{s}", f"contact_ref_{s[0]}"}
        assert sp["n_traces"] == len(sp["data"]) == 8
        assert f"id='{sp['id']}'" in report_html and f"data-traces='{sp['n_traces']}'" in \
            report_html
        for tr in sp["data"]:
            x, y = _decode(tr["x"]), _decode(tr["y"])
            assert x.size == y.size > 1 and np.all(np.diff(x) >= 0)
    # Peaks survive decimation: the force trace's extremes are the column's.
    force = next(tr for tr in specs[0]["data"] if tr["meta"]["column"] == "force_r1")
    y = _decode(force["y"])
    col = run_df["force_r1"].to_numpy()
    assert y.max() == pytest.approx(col.max(), rel=1e-6)
    assert y.min() == pytest.approx(col.min(), rel=1e-6, abs=1e-4)
    # Flags are exact change points.
    flag = next(tr for tr in specs[1]["data"] if tr["meta"]["column"] == "flag_r2")
    fx, fy = _decode(flag["x"]), _decode(flag["y"])
    assert fy.tolist() == [0.0, 1.0, 1.0] and fx[1] == pytest.approx(5.25, abs=1e-6)


def test_html_shading_and_alarm_marks(report_html: str) -> None:
    specs = {sp["sensor"]: sp for sp in _payload(report_html)}
    for s, onset in (("r1", 5.85), ("r2", 5.25), ("r3", 5.9), ("r4", 5.3)):
        shapes = specs[s]["layout"]["shapes"]
        rects = [sh for sh in shapes if sh["type"] == "rect"]
        lines = [sh for sh in shapes if sh["type"] == "line"]
        assert len(rects) == 1 and rects[0]["x0"] == pytest.approx(5.0)
        assert rects[0]["x1"] == pytest.approx(11.999)
        assert [ln["x0"] for ln in lines] == [pytest.approx(onset, abs=1e-9)]
    l2 = specs["l2"]["layout"]["shapes"]
    assert [sh["type"] for sh in l2] == ["line"] and l2[0]["x0"] == pytest.approx(2.0)
    assert specs["l1"]["layout"]["shapes"] == []
    contact = next(tr for tr in specs["l1"]["data"] if tr["meta"]["signal"] == "contact")
    assert contact["fill"] == "tozeroy" and contact["line"]["shape"] == "hv"


def test_html_overview(report_html: str, run_df: pd.DataFrame) -> None:
    specs = {sp["id"]: sp for sp in _all_specs(report_html) if not sp["sensor"]}
    assert list(specs) == ["fig-timeline", "fig-feet"]
    tl = {tr["meta"]["signal"]: tr for tr in specs["fig-timeline"]["data"]}
    # 4 injected windows and 5 flag episodes (4 faults + the l2 false alarm), 6 points each.
    assert len(tl["fault_windows"]["x"]) == 4 * 6 and len(tl["flag_episodes"]["x"]) == 5 * 6
    assert min(x for x in tl["flag_episodes"]["x"] if x is not None) == pytest.approx(2.0)
    assert specs["fig-timeline"]["layout"]["yaxis"]["ticktext"] == list(reversed(SENSOR_NAMES))
    feet = specs["fig-feet"]["data"]
    assert [tr["meta"]["signal"] for tr in feet] == ["foot_measured", "foot_vfs", "foot_true"] * 2
    true_r = _decode(feet[2]["y"])
    total = run_df[[f"true_force_r{k}" for k in range(1, 5)]].to_numpy().sum(axis=1)
    assert true_r.max() == pytest.approx(total.max(), rel=1e-6)
    assert "<h2>Overview</h2>" in report_html


def test_html_table_and_metadata(report_html: str) -> None:
    header = _table_header(report_html)
    rows = _table_rows(report_html)
    assert list(rows) == list(SENSOR_NAMES)

    def cell(sensor: str, name: str) -> str:
        return rows[sensor][header.index(name)]

    assert cell("r2", "state") == "detected" and cell("r2", "delay [s]") == "0.250"
    assert cell("r1", "injected kind") == "frozen" and cell("r3", "detected kind") == "drift"
    assert cell("r4", "true size [N]") == "-100.0"
    assert cell("l2", "state") == "false alarm" and cell("l2", "false alarms") == "1"
    assert cell("l1", "delay [s]") == "–"
    assert cell("r2", "threshold [N]") == "40.0"
    meta = re.search(r"<table class='meta' id='metadata'>(.*?)</table>", report_html, re.S)
    assert meta
    for key in ("robot", "gait", "method", "thresholds", "seed"):
        assert f"<th>{key}</th>" in meta.group(1)
    assert "step_period_s" in meta.group(1) and "12000 (0.000 s to 11.999 s, 1000 Hz)" in \
        meta.group(1)


def test_html_metadata_from_dicts(run_df: pd.DataFrame) -> None:
    df = run_df.copy()
    df.attrs = {"robot": {"name": "bot<1>", "mass": 60.0}, "step_times": list(range(500))}
    html = build_html_report(df)
    assert "<title>grfguard report: bot&lt;1&gt;</title>" in html
    assert "<span class='kv'><b>mass</b> 60</span>" in html
    assert "(500 items)" in html  # long lists are cut, not dumped


def test_html_metrics_win(run_df: pd.DataFrame) -> None:
    html = build_html_report(run_df, metrics={"r2": {"delay_s": 0.4321}}, title="T <x>")
    header, rows = _table_header(html), _table_rows(html)
    assert rows["r2"][header.index("delay [s]")] == "0.432"
    assert "<title>T &lt;x&gt;</title>" in html  # escaped


def test_html_self_contained(report_html: str) -> None:
    assert report_html.count("plotly.js v") == 1  # one inlined copy
    tags = re.findall(r"<(?:script|link|img|iframe|source|embed)\b[^>]*>", report_html, re.I)
    for tag in tags:
        assert not re.search(r"\b(?:src|href)\s*=\s*['\"]?(?:https?:)?//", tag, re.I), tag
    assert not re.search(r"<link\b", report_html, re.I)
    assert not re.search(r"@import|@font-face|url\(\s*['\"]?https?:", report_html, re.I)
    assert "window.grfguardReport" in report_html
    # Script tags inside the data block are escaped.
    assert report_html.count("</script>") == 3


def test_html_missing_columns(run_df: pd.DataFrame) -> None:
    keep = [c for c in run_df.columns
            if not c.startswith(("true_", "fault", "recovered_", "contact_ref"))]
    html = build_html_report(run_df[keep])
    for sp in _payload(html):
        signals = {tr["meta"]["signal"] for tr in sp["data"]}
        assert signals == {"measured", "vfs", "eta", "flag"}
        assert all(sh["type"] == "line" for sh in sp["layout"]["shapes"])
    rows, header = _table_rows(html), _table_header(html)
    assert rows["r2"][header.index("state")] == "alarm"
    # Forces only: still a report.
    only = run_df[["time", *[f"force_{s}" for s in SENSOR_NAMES]]]
    specs = _payload(build_html_report(only))
    assert all(len(sp["data"]) == 1 for sp in specs)
    assert all("yaxis2" not in sp["layout"] for sp in specs)


def test_html_nan_samples(run_df: pd.DataFrame) -> None:
    df = run_df.copy()
    df.loc[:499, ["vfs_r1", "eta_r1", "recovered_r1", "vfs_total_r"]] = np.nan  # start-up
    df["flag_r1"] = df["flag_r1"].astype(object)
    df.loc[:99, "flag_r1"] = None
    sp = _payload(build_html_report(df))[0]
    vfs = next(tr for tr in sp["data"] if tr["meta"]["column"] == "vfs_r1")
    y = _decode(vfs["y"])
    assert np.isnan(y).any() and np.isfinite(y).sum() > 100  # a gap, then the signal


def test_html_deterministic(run_df: pd.DataFrame) -> None:
    assert build_html_report(run_df) == build_html_report(synthetic_run(duration_s=12.0, seed=3))


def test_html_bad_input(run_df: pd.DataFrame, tmp_path: Path) -> None:
    with pytest.raises(LogFormatError, match="'time'"):
        write_html_report(run_df.drop(columns="time"), tmp_path / "x.html")
    bad = run_df.copy()
    bad.loc[10, "time"] = bad.loc[9, "time"]
    with pytest.raises(LogFormatError, match="strictly increasing.*row 10"):
        write_html_report(bad, tmp_path / "x.html")
    with pytest.raises(LogFormatError, match="no sensor columns"):
        write_html_report(run_df[["time"]], tmp_path / "x.html")
    with pytest.raises(ConfigError, match="max_points"):
        write_html_report(run_df, tmp_path / "x.html", max_points=1)
    with pytest.raises(LogFormatError, match="DataFrame"):
        write_html_report({"time": [0.0]}, tmp_path / "x.html")  # type: ignore[arg-type]
    assert not (tmp_path / "x.html").exists()


def test_html_long_log_size_bound(tmp_path: Path) -> None:
    df = synthetic_run(duration_s=600.0, seed=1)
    path = write_html_report(df, tmp_path / "long.html")
    size_mb = path.stat().st_size / 1e6
    assert size_mb < 20.0, f"10-minute 1 kHz report is {size_mb:.1f} MB"
    specs = _payload(path.read_text(encoding="utf-8"))
    n_points = max(_decode(tr["x"]).size for sp in specs for tr in sp["data"])
    assert n_points < 20_000  # decimated from 600 000
    # Full resolution kept around the fault onset (5 s +- 1.5 s) of r2's force trace.
    force = next(tr for tr in specs[1]["data"] if tr["meta"]["column"] == "force_r2")
    x = _decode(force["x"])
    near = x[(x > 4.0) & (x < 6.0)]
    assert near.size >= 1900


# ------------------------------------------------------------------------------ figures


@pytest.fixture(scope="module")
def pngs(run_df: pd.DataFrame, tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    from grfguard.report import write_png_figures

    return write_png_figures(run_df, tmp_path_factory.mktemp("png"), dpi=50)


def test_pngs_written_and_not_blank(pngs: list[Path]) -> None:
    from matplotlib.image import imread

    names = {p.stem for p in pngs}
    assert {"fig4_vfs_vs_true", "fig5_fault_estimate", "fig6_recovery", "fig7_flags",
            "detection_timeline", "summary_table"} <= names
    # Per-sensor figures by default only where something happened (faults r1-r4, alarm l2).
    assert {n for n in names if n.startswith("sensor_")} == {
        "sensor_r1", "sensor_r2", "sensor_r3", "sensor_r4", "sensor_l2"}
    for p in pngs:
        img = imread(p)[..., :3]
        assert img.shape[0] > 100 and img.shape[1] > 300
        non_white = (img < 0.95).any(axis=2).mean()
        assert 0.02 < non_white < 0.9, f"{p.name}: {non_white:.3f} non-white"
        colours = (img[::3, ::3] * 255).astype(np.int64).reshape(-1, 3)
        assert np.unique(colours[:, 0] * 65536 + colours[:, 1] * 256 + colours[:, 2]).size > 20


def test_png_options(run_df: pd.DataFrame, tmp_path: Path) -> None:
    from grfguard.report import write_png_figures

    few = run_df[["time", "force_r1", "vfs_r1", "force_l1", "vfs_l1"]]
    paths = write_png_figures(few, tmp_path, dpi=30, per_sensor=["l1"])
    assert [p.stem for p in paths] == ["fig4_vfs_vs_true", "summary_table", "sensor_l1"]
    with pytest.raises(ConfigError, match="dpi"):
        write_png_figures(few, tmp_path, dpi=0)


def test_figures_content(run_df: pd.DataFrame) -> None:
    from matplotlib.figure import Figure

    from grfguard.report import figures as F

    fig, axes = F.plot_vfs_vs_true(run_df)
    assert isinstance(fig, Figure) and axes.shape == (2, 2)
    assert [ax.get_title(loc="left") for ax in axes.flat] == [
        "sensor r1 (front-left)", "sensor r2 (front-right)",
        "sensor r3 (rear-left)", "sensor r4 (rear-right)"]
    assert all(ax.get_ylabel() == "force [N]" for ax in axes.flat)
    assert axes[1, 0].get_xlabel() == "time [s]"
    labels = {ln.get_label() for ln in axes[0, 0].get_lines()}
    assert {"true", "VFS"} <= labels
    legend_texts = {t.get_text() for t in fig.legends[0].get_texts()}
    assert {"true", "VFS", "injected fault", "alarm onset", "stance (planned)"} <= legend_texts

    fig, axes = F.plot_fault_estimate(run_df)
    labels = {ln.get_label() for ln in axes[0, 1].get_lines()}
    assert {"true fault", "estimated fault (filtered)", "unfiltered: measured − VFS"} <= labels
    assert axes[0, 1].get_ylabel() == "fault [N]"

    fig, axes = F.plot_flags(run_df)
    assert axes.shape == (4, 1)
    onsets = [ln.get_xdata()[0] for ln in axes[1, 0].get_lines() if ln.get_linestyle() == "--"]
    assert onsets == [pytest.approx(5.0)]
    step = next(ln for ln in axes[1, 0].get_lines() if ln.get_label() == "flag")
    y = np.asarray(step.get_ydata())
    assert y.min() == 0 and y.max() == 1

    notes = [t.get_text() for ax in axes[:, 0] for t in ax.texts]
    assert notes == ["delay 0.85 s", "delay 0.25 s", "delay 0.90 s", "delay 0.30 s"]
    _, axes = F.plot_flags(run_df, metrics={"r2": {"delay_s": 0.5}})
    assert axes[1, 0].texts[0].get_text() == "delay 0.50 s"

    fig, axes = F.plot_flags(run_df, sensors=["l2"], t_range=(1.0, 3.0))
    assert axes.shape == (1, 1) and axes[0, 0].get_xlim() == pytest.approx((1.0, 3.0), abs=1e-3)
    fig, ax = F.plot_detection_timeline(run_df)
    assert [t.get_text() for t in ax.get_yticklabels()] == list(reversed(SENSOR_NAMES))
    assert F.faulty_foot(run_df) == "r"
    with pytest.raises(ConfigError, match="foot"):
        F.plot_recovery(run_df, foot="x")
    with pytest.raises(ConfigError, match="t_range"):
        F.plot_recovery(run_df, t_range=(5.0, 1.0))
    with pytest.raises(LogFormatError, match="sensor 'z9'"):
        F.plot_sensor(run_df, "z9")


def test_figures_long_log_default_window() -> None:
    from grfguard.report import figures as F

    df = synthetic_run(duration_s=200.0, seed=2, fault_onset_s=100.0)
    fig, axes = F.plot_recovery(df)
    assert axes[0, 0].get_xlim() == pytest.approx((90.0, 130.0), abs=1e-2)
    # Drawn lines are decimated (no 40 000-point lines).
    assert max(len(ln.get_xdata()) for ln in axes[0, 0].get_lines()) <= 3002


# ------------------------------------------------------------------------ real pipeline


def test_report_on_real_run(clean_walk: pd.DataFrame, tmp_path: Path) -> None:
    monitor = pytest.importorskip("grfguard.detect.monitor")
    faults = pytest.importorskip("grfguard.faults")
    specs = [faults.parse_fault_spec(s) for s in ("r2=offset:100@5", "r3=drift:15@5")]
    faulty = faults.inject_faults(clean_walk, specs, seed=0)
    out = monitor.Monitor.for_log(faulty).run(faulty)
    path = write_html_report(out, tmp_path / "real.html")
    html = path.read_text(encoding="utf-8")
    specs_html = {sp["sensor"]: sp for sp in _payload(html)}
    assert set(specs_html) == set(SENSOR_NAMES)
    signals = {tr["meta"]["signal"] for tr in specs_html["r2"]["data"]}
    assert {"measured", "true", "vfs", "flag"} <= signals
    rects = [sh for sh in specs_html["r2"]["layout"]["shapes"] if sh["type"] == "rect"]
    assert rects and rects[0]["x0"] == pytest.approx(5.0, abs=2e-3)
    from grfguard.report.figures import plot_flags, plot_vfs_vs_true

    fig, axes = plot_vfs_vs_true(out)
    assert {"true", "VFS"} <= {ln.get_label() for ln in axes[0, 1].get_lines()}
    fig, axes = plot_flags(out)
    assert axes.shape == (4, 1)


def test_html_alarm_storm_is_capped(tmp_path: Path) -> None:
    df = synthetic_run(duration_s=120.0, seed=4)
    t = df["time"].to_numpy()
    df["flag_l3"] = (np.floor(t / 0.05) % 2).astype(bool)  # 1200 alarm episodes
    path = write_html_report(df, tmp_path / "storm.html")
    html = path.read_text(encoding="utf-8")
    sp = next(sp for sp in _payload(html) if sp["sensor"] == "l3")
    lines = [sh for sh in sp["layout"]["shapes"] if sh["type"] == "line"]
    assert len(lines) == 200
    assert "capped: 200/1200 alarm onsets" in sp["layout"]["title"]["text"]
    flag = next(tr for tr in sp["data"] if tr["meta"]["signal"] == "flag")
    n_changes = np.count_nonzero(np.diff(df["flag_l3"].to_numpy().astype(int)))
    assert _decode(flag["y"]).size == n_changes + 2  # exact change points, never decimated
    rows, header = _table_rows(html), _table_header(html)
    assert rows["l3"][header.index("false alarms")] == "1200"
