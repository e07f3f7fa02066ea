"""One definition of each metric: the report and ``grfguard evaluate --json`` agree.

On a real simulated walk (MuJoCo, default noise) with the paper's four fault kinds, the
report's summary (computed by the report itself, no metrics passed in) and its HTML
table show, for every metric both have, the number ``grfguard evaluate`` prints.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from grfguard.cli import app
from grfguard.detect import Monitor
from grfguard.faults import inject_faults
from grfguard.io.logio import read_log, write_log
from grfguard.report import sensor_summary, write_html_report
from grfguard.report.html import _TABLE_COLUMNS, _fmt
from grfguard.sim import GaitConfig, NoiseConfig, simulate

FAULTS = ["r1=frozen:0@3", "r2=offset:100@3", "r3=drift:15@3", "l4=offset:-100@3"]


@pytest.fixture(scope="module")
def run_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    walk = simulate(gait=GaitConfig(duration=8.0), noise=NoiseConfig(), seed=4)
    faulty = inject_faults(walk, FAULTS, seed=4)
    path = tmp_path_factory.mktemp("agree") / "run.parquet"
    write_log(Monitor.for_log(faulty).run(faulty), path)
    return path


def _evaluate_json(path: Path) -> dict:
    res = CliRunner().invoke(app, ["evaluate", str(path), "--json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)["detection"]["sensors"]


def _same(a: object, b: object) -> bool:
    if a is None or (isinstance(a, float) and math.isnan(a)):
        return b is None or (isinstance(b, float) and math.isnan(b))
    if isinstance(a, float) or isinstance(b, float):
        return b is not None and float(a) == pytest.approx(float(b), rel=1e-12, abs=1e-12)
    return a == b


def test_report_and_evaluate_print_the_same_numbers(run_log: Path, tmp_path: Path) -> None:
    ev = _evaluate_json(run_log)
    df = read_log(run_log)
    summary = sensor_summary(df)  # the report's own computation
    shared = [c for c in summary.columns if c in ev["r1"]]
    assert {"delay_s", "false_alarms", "recovery_rmse_n", "fault_size_error_n",
            "raw_rmse_n", "true_size_n", "estimated_size_n", "kind_estimated"} <= set(shared)
    # the scenario exercises the metrics: every injected fault found, errors finite
    for s in ("r1", "r2", "r3", "l4"):
        assert ev[s]["detected"] and ev[s]["recovery_rmse_n"] < ev[s]["raw_rmse_n"]
    for s, metrics in ev.items():
        for name in shared:
            assert _same(metrics[name], summary.loc[s, name]), (s, name)
    html = write_html_report(df, tmp_path / "report.html").read_text(encoding="utf-8")
    head = re.search(r"<table class='summary' id='summary'><thead><tr>(.*?)</tr>", html, re.S)
    header = re.findall(r"<th>(.*?)</th>", head.group(1))
    for tr in re.findall(r"<tr data-sensor='(\w+)'>(.*?)</tr>", html, re.S):
        cells = [re.sub(r"<[^>]+>", "", c) for c in re.findall(r"<td>(.*?)</td>", tr[1], re.S)]
        for name, label, digits in _TABLE_COLUMNS:
            if name in shared:
                assert cells[header.index(label)] == _fmt(ev[tr[0]][name], digits), (tr[0], name)
