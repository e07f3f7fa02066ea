"""`grfguard demo` (what `make demo` runs) on a short walk: every file it announces is
written, the figure counts it prints are the PNGs on disk, and the default method finds
the paper's four faults."""

from __future__ import annotations

import json
import re

from typer.testing import CliRunner

from grfguard.cli import app


def test_demo_writes_what_it_announces(tmp_path) -> None:
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["demo", "--out", str(out), "--duration", "8"])
    assert res.exit_code == 0, res.output
    text = "".join(res.output.split())  # rich wraps long paths, even inside a word
    found = re.findall(r"(\d+)in(/\S+?)(?=,\d+in/|report:|$)", text.split("figures:")[1])
    counts = {folder: n for n, folder in found}
    assert set(counts) == {str(out / d) for d in ("figures", "figures_zoom", "figures_paper")}
    for folder, n in counts.items():
        pngs = list((tmp_path / folder).glob("*.png"))
        assert len(pngs) == int(n) > 0, folder
    for name in ("walk.parquet", "metrics.json", "metrics.md", "report.html",
                 "report_paper.html", "run_default.parquet", "run_paper.parquet",
                 "run_paper-observer.parquet", "corner_forces.png"):
        assert (out / name).stat().st_size > 0, name
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics) == {"paper", "paper-observer", "default"}
    sensors = metrics["default"]["detection"]["sensors"]
    assert all(sensors[s]["detected"] for s in ("r1", "r2", "r3", "r4")), sensors
    assert all(sensors[s]["false_alarms"] == 0 for s in sensors), sensors
