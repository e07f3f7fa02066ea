"""Campaigns on Dask: spec expansion, a killed worker, rerun, external scheduler, report.

Everything runs for real (MuJoCo walks, real ``dask.distributed`` clusters and
``dask scheduler`` / ``dask worker`` processes) on a tiny campaign of 5 s walks.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import psutil
import pytest

from grfguard.campaign import ResultStore, parse_spec
from grfguard.campaign.analysis import (
    clopper_pearson,
    min_detectable,
    poisson_rate_ci,
)
from grfguard.campaign.report import write_campaign_report
from grfguard.campaign.runner import local_cluster, run_campaign
from grfguard.errors import ConfigError

TINY = """
[campaign]
name = "tiny"
tolerance_s = 1.0

[[group]]
name = "sizes"
methods = ["default", "paper"]
sensors = ["r2"]
onsets_s = [2.5, 3.0]
window_s = 2.0
[group.faults]
offset = [10.0, 60.0]
stuck = []
[group.walks]
gaits = [[0.12, 1.0]]
seeds = [0, 1]
duration_s = 5.0

[[group]]
name = "fault-free"
methods = ["default", "paper"]
threshold_scales = [1.0, 2.0]
fault_free = true
[group.walks]
gaits = [[0.12, 1.0]]
seeds = [0, 1]
duration_s = 5.0
"""
N_TINY = 2 * 2 * 3 * 2 + 2 * 2 * 2  # walks x methods x faults x onsets + fault-free
BIN = Path(sys.executable).parent
#: Result columns that depend only on the cell (not on where or how fast it ran).
DETERMINISTIC = ["cell_id", "method", "kind", "size", "onset_s", "detected", "delay_s",
                 "kind_estimated", "false_alarms", "observed_s"]


def _files(root: Path) -> list[Path]:
    return sorted((root / "cells").glob("method=*/kind=*/*.parquet"))


# ----------------------------------------------------------------------------- spec
def test_spec_expands_to_cells_with_stable_ids():
    spec = parse_spec(TINY)
    cells = spec.cells()
    assert len(cells) == N_TINY
    ids = [c.cell_id for c in cells]
    assert len(set(ids)) == len(ids)
    # walks are shared: 2 seeds -> 2 walks for all 32 cells, scenario id versioned
    walks = spec.walks()
    assert len(walks) == 2
    assert all(w.walk_id.startswith("suralp-walk-v1-") for w in walks)
    # the order of groups and list entries does not change the ids
    swapped = TINY.replace('methods = ["default", "paper"]', 'methods = ["paper", "default"]')
    swapped = swapped.replace("offset = [10.0, 60.0]", "offset = [60.0, 10.0]")
    assert {c.cell_id for c in parse_spec(swapped).cells()} == set(ids)
    # a parameter that changes the result changes the id
    longer = TINY.replace("window_s = 2.0", "window_s = 1.5")
    changed = {c.cell_id for c in parse_spec(longer).cells() if c.kind != "none"}
    assert changed.isdisjoint(ids)


@pytest.mark.parametrize(
    ("bad", "needle"),
    [
        (('offset = [10.0, 60.0]', 'offsett = [10.0]'), "fault kind 'offsett' unknown"),
        (("onsets_s = [2.5, 3.0]", "onsets_s = [4.0]"), "past the end"),
        (('methods = ["default", "paper"]', 'methods = ["best"]'), "method 'best' unknown"),
        (("[campaign]", "[campain]"), "[campaign] table"),
    ],
)
def test_bad_spec_says_what_and_where(bad, needle):
    with pytest.raises(ConfigError, match=None) as exc:
        parse_spec(TINY.replace(*bad, 1), "tiny.toml")
    assert needle in str(exc.value)
    assert "tiny.toml" in str(exc.value)


def test_store_write_is_idempotent(tmp_path):
    store = ResultStore(tmp_path)
    row = {"cell_id": "offset-abc", "method": "default", "kind": "offset", "delay_s": 0.1}
    assert store.write(row) is True
    assert store.write(dict(row, delay_s=9.9)) is False
    assert store.done_ids() == {"offset-abc"}
    df = store.read()
    assert len(df) == 1 and df["delay_s"].iloc[0] == 0.1 and df["kind"].iloc[0] == "offset"


# ------------------------------------------------------------------------- analysis
def test_exact_intervals():
    lo, hi = clopper_pearson(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.3085, abs=1e-4)
    lo, hi = clopper_pearson(10, 10)
    assert hi == 1.0 and lo == pytest.approx(0.6915, abs=1e-4)
    rate, lo, hi = poisson_rate_ci(0, 2.0)
    assert rate == 0.0 and lo == 0.0 and hi == pytest.approx(3.689 / 2.0, abs=1e-3)
    rate, lo, hi = poisson_rate_ci(4, 1.0)
    assert (lo, hi) == (pytest.approx(1.0899, abs=1e-3), pytest.approx(10.242, abs=1e-2))


def test_min_detectable_needs_every_larger_size():
    rows = []
    for size, hits in ((5.0, 2), (10.0, 10), (20.0, 9), (40.0, 10)):
        for k in range(10):
            rows.append({"method": "default", "kind": "offset", "size": size,
                         "magnitude": size, "threshold_scale": 1.0, "detected": float(k < hits),
                         "delay_s": 0.1 if k < hits else math.nan, "kind_correct": 1.0})
    m = min_detectable(pd.DataFrame(rows), level=0.95)
    # 10 N reaches 100 % but 20 N only 90 %: the answer is 40 N
    assert m["min_size"].tolist() == [40.0]
    m = min_detectable(pd.DataFrame(rows), level=0.9)
    assert m["min_size"].tolist() == [10.0]


# -------------------------------------------------------------- local cluster runs
@pytest.fixture(scope="module")
def local_results(tmp_path_factory):
    """Run the tiny campaign on a 2-worker local cluster, SIGKILL one worker mid-run."""
    out = tmp_path_factory.mktemp("campaign") / "results"
    spec = parse_spec(TINY)
    cluster = local_cluster(2)
    from distributed import Client

    client = Client(cluster)
    info: dict = {"killed": None, "results_at_kill": None}
    try:
        workers = client.scheduler_info()["workers"]
        addrs = [cluster.scheduler_address, *workers,
                 *(w["nanny"] for w in workers.values() if w.get("nanny"))]
        pids_before = client.run(os.getpid)
        pids = [os.getpid(), *pids_before.values(), *client.run(os.getpid, nanny=True).values()]
        listening = {(c.laddr.ip, c.laddr.port) for pid in pids
                     for c in psutil.Process(pid).net_connections(kind="inet")
                     if c.status == psutil.CONN_LISTEN}
        lock = threading.Lock()

        def kill_one(row):
            with lock:
                n = len(_files(out))
                if info["killed"] is None and n >= 4:
                    addr, pid = sorted(pids_before.items())[0]
                    info["in_flight"] = list(client.processing([addr]).get(addr, []))
                    os.kill(pid, signal.SIGKILL)
                    info["killed"], info["results_at_kill"] = pid, n

        summary = run_campaign(spec, out, client=client, progress=False, on_result=kill_one)
        # the nanny restarted the killed worker
        deadline = time.time() + 30
        while time.time() < deadline and len(client.scheduler_info()["workers"]) < 2:
            time.sleep(0.2)
        pids_after = client.run(os.getpid)
    finally:
        client.close()
        cluster.close()
    return {"out": out, "spec": spec, "summary": summary, "addrs": addrs, "info": info,
            "listening": listening,
            "pids_before": pids_before, "pids_after": pids_after}


def test_local_cluster_listens_on_localhost_only(local_results):
    addrs = local_results["addrs"]
    assert len(addrs) == 5  # scheduler, 2 workers, 2 nannies
    assert all(a.startswith("tcp://127.0.0.1:") for a in addrs), addrs
    # every listening socket of the scheduler, workers and nannies (HTTP servers included)
    listening = local_results["listening"]
    assert len(listening) >= 5
    assert {ip for ip, _ in listening} == {"127.0.0.1"}, listening


def test_killed_worker_every_cell_exactly_once(local_results):
    out, info, s = local_results["out"], local_results["info"], local_results["summary"]
    assert info["killed"] is not None and info["results_at_kill"] < N_TINY
    # the killed worker had cells in flight (running or queued on it)
    assert any(k.startswith("cell-") for k in info["in_flight"]), info["in_flight"]
    assert info["killed"] not in local_results["pids_after"].values()
    assert s.n_cells == N_TINY and s.n_computed == N_TINY and s.n_failed == 0
    files = _files(out)
    assert len(files) == N_TINY
    assert not list(out.rglob("*.tmp"))
    df = ResultStore(out).read()
    assert len(df) == N_TINY and df["cell_id"].is_unique
    assert set(df["cell_id"]) == {c.cell_id for c in local_results["spec"].cells()}
    # partitioned: the file lies under its method and kind
    for f in files:
        row = df[df["cell_id"] == f.stem].iloc[0]
        assert f.parent.name == f"kind={row['kind']}"
        assert f.parent.parent.name == f"method={row['method']}"


def test_rerun_recomputes_nothing(local_results):
    out = local_results["out"]
    before = {f: f.stat().st_mtime_ns for f in _files(out)}
    again = run_campaign(local_results["spec"], out, progress=False)
    assert (again.n_computed, again.n_skipped, again.n_walks) == (0, N_TINY, 0)
    assert {f: f.stat().st_mtime_ns for f in _files(out)} == before


def test_results_are_right_on_real_walks(local_results):
    df = ResultStore(local_results["out"]).read()
    # a stuck sensor reads the same value while loaded: both methods see it every time
    stuck = df[df["kind"] == "stuck"]
    assert len(stuck) == 8 and stuck["detected"].eq(1.0).all()
    default_stuck = stuck[stuck["method"] == "default"]
    assert (default_stuck["kind_estimated"] == "stuck").all()
    assert default_stuck["delay_s"].max() < 0.5
    # fault-free cells at the shipped thresholds: the default detector stays quiet
    free = df[(df["kind"] == "none") & (df["method"] == "default")]
    assert len(free) == 4 and free["false_alarms"].sum() == 0
    assert free["detected"].isna().all()


def test_report_from_results(local_results, tmp_path):
    path = write_campaign_report(local_results["out"], tmp_path / "rep")
    text = path.read_text()
    assert "Smallest fault detected in 95% of runs" in text
    assert "False alarms per hour" in text and "data:image/png;base64," in text
    for name in ("rates.png", "delays.png", "curve.png", "detection.csv", "summary.json"):
        assert (tmp_path / "rep" / name).stat().st_size > 100
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert summary["cells"] == N_TINY
    fa = pd.read_csv(tmp_path / "rep" / "false_alarms.csv")
    # two methods x two scales, each 2 fault-free cells of 5 s = 10 s of walking
    assert len(fa) == 4 and np.allclose(fa["hours"], 10.0 / 3600)
    assert (fa["per_hour_hi"] > fa["per_hour"]).all()


# ------------------------------------------------------------ external scheduler
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.skipif(shutil.which("dask", path=str(BIN)) is None, reason="dask CLI missing")
def test_same_spec_on_external_scheduler_and_worker(local_results, tmp_path):
    spec_file = tmp_path / "tiny.toml"
    spec_file.write_text(TINY)
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, DASK_DISTRIBUTED__LOGGING__DISTRIBUTED="error")
    sched = subprocess.Popen(
        [str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
         "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    worker = subprocess.Popen(
        [str(BIN / "dask"), "worker", addr, "--nworkers", "2", "--nthreads", "1",
         "--host", "127.0.0.1", "--no-dashboard"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    try:
        from distributed import Client

        with Client(addr, timeout="30s") as c:
            c.wait_for_workers(2, timeout=60)
        res = subprocess.run(
            [str(BIN / "grfguard"), "campaign", "run", str(spec_file), "-o",
             str(tmp_path / "ext"), "--scheduler", addr, "--no-progress"],
            capture_output=True, text=True, timeout=120)
        assert res.returncode == 0, res.stderr
        line = json.loads(res.stdout.strip().splitlines()[-1])
        assert line["computed"] == N_TINY and line["scheduler"] == addr
    finally:
        for p in (worker, sched):
            p.send_signal(signal.SIGINT)
        for p in (worker, sched):
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
    ext = ResultStore(tmp_path / "ext").read().sort_values("cell_id").reset_index(drop=True)
    loc = ResultStore(local_results["out"]).read().sort_values("cell_id").reset_index(drop=True)
    # same cells, same numbers: the engine does not change the results
    pd.testing.assert_frame_equal(ext[DETERMINISTIC], loc[DETERMINISTIC])
    assert ext["worker"].nunique() >= 1


def test_results_folder_of_another_spec_is_refused(tmp_path):
    store = ResultStore(tmp_path)
    cells = pd.DataFrame({"cell_id": ["offset-abc"]})
    store.prepare(TINY, cells)
    store.write({"cell_id": "offset-abc", "method": "default", "kind": "offset"})
    store.prepare(TINY, cells)  # the same spec again: fine (resume)
    with pytest.raises(ConfigError, match="another campaign spec"):
        store.prepare(TINY.replace("window_s = 2.0", "window_s = 1.5"), cells)


def test_cli_bad_spec_exits_2_with_message(tmp_path):
    from typer.testing import CliRunner

    from grfguard.cli import app

    spec = tmp_path / "bad.toml"
    spec.write_text(TINY.replace("stuck = []", "stuk = []"))
    res = CliRunner().invoke(app, ["campaign", "run", str(spec), "-o", str(tmp_path / "r")])
    assert res.exit_code == 2
    assert "fault kind 'stuk' unknown" in res.output
    assert not (tmp_path / "r").exists()
