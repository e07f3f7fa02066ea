"""The work of a campaign: simulate a walk once, run one cell on it.

Both functions are pure (same input, same output) and run on Dask workers; they only
use grfguard's public entry points (``simulate``, ``inject_faults``, ``Monitor``,
``MonitorConfig``, ``Thresholds``, ``evaluate_detection``).
"""

from __future__ import annotations

import math
import os
import socket
import time
from typing import Any

import numpy as np
import pandas as pd

from grfguard.campaign.spec import Cell, Walk, size_magnitude
from grfguard.detect import Monitor, MonitorConfig, Thresholds
from grfguard.model.robot import SENSOR_NAMES

__all__ = ["simulate_walk", "run_cell", "scale_thresholds", "RESULT_COLUMNS"]

#: Truth columns the cells never read (dropped to keep shared walks small).
_UNUSED_PREFIXES = ("true_com", "true_base", "true_zmp", "true_cop", "true_sole",
                    "true_contact", "true_trunk")

#: Columns of one result row (method and kind are the dataset's partition keys).
RESULT_COLUMNS = (
    "cell_id", "walk_id", "scenario", "group", "threshold_scale", "size", "magnitude",
    "sensor", "onset_s", "onset_phase", "seed", "step_length_m", "step_period_s",
    "detected", "delay_s", "kind_estimated", "kind_correct", "false_alarms",
    "false_alarms_healthy", "observed_s", "compute_s", "worker", "grfguard_version",
)


def simulate_walk(walk: Walk) -> pd.DataFrame:
    """Simulate ``walk`` and add the virtual force sensor columns (shared by its cells).

    The default virtual sensor does not read the force sensors, so its output holds for
    every fault injected afterwards.
    """
    from grfguard.estimate.vfs import with_vfs_columns
    from grfguard.sim import GaitConfig, simulate

    gait = GaitConfig(step_length=walk.step_length_m, step_period=walk.step_period_s,
                      duration=walk.duration_s)
    log = simulate(gait=gait, seed=walk.seed)
    log = with_vfs_columns(log)
    keep = [c for c in log.columns if not c.startswith(_UNUSED_PREFIXES)]
    out = log[keep].copy()
    out.attrs = dict(log.attrs)
    return out


def scale_thresholds(th: Thresholds, scale: float) -> Thresholds:
    """Every alarm threshold times ``scale`` (CUSUM ``*_h`` and the paper's eq. 33 levels).

    Noise scales, drift allowances and the constant-reading count stay: the scale moves
    each test along its own delay/false-alarm trade-off.
    """
    if scale == 1.0:
        return th
    return th.replace(
        swing_h=th.swing_h * scale,
        total_h=th.total_h * scale,
        corner_h=th.corner_h * scale,
        paper_eta_n=tuple(v * scale for v in th.paper_eta_n),
        source=f"{th.source} x {scale:g}",
    )


def _onset_phase(cell: Cell, log: pd.DataFrame) -> float:
    """Onset as a fraction of the stride (two steps) after the first step [-]."""
    if cell.kind == "none":
        return math.nan
    gait = log.attrs.get("gait", {})
    t0 = float(gait.get("start_time", 1.0))
    stride = 2.0 * cell.walk.step_period_s
    return float(((cell.onset_s - t0) % stride) / stride)


def run_cell(cell: Cell, walk_log: pd.DataFrame) -> dict[str, Any]:
    """Inject the cell's fault into the shared walk, run the monitor, score it.

    Returns:
        One result row (keys :data:`RESULT_COLUMNS` plus ``method`` and ``kind``).
        ``detected``/``delay_s``/``kind_*`` refer to the faulty sensor (NaN when
        fault-free); ``false_alarms`` counts alarm episodes outside every fault window
        on all eight sensors, ``false_alarms_healthy`` those on the sensors without a
        fault; ``observed_s`` is the monitored time [s].
    """
    from grfguard import __version__
    from grfguard.evaluate.detection import evaluate_detection
    from grfguard.faults import inject_faults

    t_start = time.perf_counter()
    part = walk_log[walk_log["time"] < cell.end_s]
    part.attrs = walk_log.attrs
    faults = [cell.fault_string()] if cell.kind != "none" else []
    fault_seed = int(cell.walk.seed) * 1000 + 7
    log = inject_faults(part, faults, seed=fault_seed)
    base = MonitorConfig()
    cfg = base.with_method(cell.method).with_thresholds(
        scale_thresholds(base.thresholds, cell.threshold_scale)
    )
    res = Monitor.for_log(log, cfg).run(log)
    tab = evaluate_detection(log, res, tolerance_s=cell.tolerance_s)
    t = log["time"].to_numpy(float)
    observed = float(t[-1] - t[0] + (t[1] - t[0])) if len(t) > 1 else 0.0
    healthy = [s for s in SENSOR_NAMES if s != cell.sensor]
    row: dict[str, Any] = {
        "cell_id": cell.cell_id,
        "method": cell.method,
        "kind": cell.kind,
        "walk_id": cell.walk.walk_id,
        "scenario": cell.walk.scenario,
        "group": cell.group,
        "threshold_scale": float(cell.threshold_scale),
        "size": float(cell.size),
        "magnitude": float(size_magnitude(cell.kind, cell.size)),
        "sensor": cell.sensor,
        "onset_s": float(cell.onset_s),
        "onset_phase": _onset_phase(cell, log),
        "seed": int(cell.walk.seed),
        "step_length_m": float(cell.walk.step_length_m),
        "step_period_s": float(cell.walk.step_period_s),
        "detected": math.nan,
        "delay_s": math.nan,
        "kind_estimated": "",
        "kind_correct": math.nan,
        "false_alarms": int(tab["false_alarms"].sum()),
        "false_alarms_healthy": int(tab.loc[healthy, "false_alarms"].sum()),
        "observed_s": observed,
        "compute_s": 0.0,
        "worker": f"{socket.gethostname()}:{os.getpid()}",
        "grfguard_version": __version__,
    }
    if cell.kind != "none":
        r = tab.loc[cell.sensor]
        row["detected"] = float(bool(r["detected"]))
        row["delay_s"] = float(r["delay_s"])
        row["kind_estimated"] = str(r["kind_estimated"])
        kc = r["kind_correct"]
        row["kind_correct"] = math.nan if kc is None or (
            isinstance(kc, float) and np.isnan(kc)) else float(bool(kc))
    row["compute_s"] = time.perf_counter() - t_start
    return row
