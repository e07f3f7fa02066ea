"""Detection delay against the gait phase of the fault onset.

The paper's scenario (right foot: r1 frozen at 0, r2 +100 N, r3 +15 N/s, r4 -100 N)
injected at eight onsets spread over one 2 s stride of the 60 s default walk (seed 0),
both detection methods on the same virtual sensor. How fast a fault is seen depends on
where in the stride it starts (a swinging foot reads fault plus noise, a loaded one
fault plus virtual-sensor error), so one onset time says little: this table gives the
spread.

Writes the ``## Detection delay against onset phase`` section of BENCHMARKS.md.

Usage:
    .venv/bin/python benchmarks/bench_onset_phase.py [--no-write]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_monitor import update_benchmarks_md  # noqa: E402
from calibrate_default_thresholds import walk_with_vfs  # noqa: E402

from grfguard.detect.monitor import Monitor, MonitorConfig  # noqa: E402
from grfguard.evaluate.detection import evaluate_detection  # noqa: E402
from grfguard.faults import inject_faults  # noqa: E402

SECTION = "## Detection delay against onset phase"
ONSETS = tuple(5.0 + 0.25 * k for k in range(8))
FAULTS = ("r1=frozen:0", "r2=offset:100", "r3=drift:15", "r4=offset:-100")
WINDOW_S = 8.0  # each run: the walk up to onset + WINDOW_S


def first_loaded_after(log, side: str, t0: float) -> float:
    """First time >= t0 at which every corner of the foot carries load (truth) [s]."""
    t = log["time"].to_numpy(float)
    loaded = np.all([log[f"true_force_{side}{k}"].to_numpy(float) > 1.0 for k in range(1, 5)],
                    axis=0)
    idx = np.flatnonzero((t >= t0) & loaded)
    return float(t[idx[0]]) if idx.size else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    walk = walk_with_vfs(0.12, 1.0, 0, 60.0)
    rows = []
    delays: dict[tuple[str, str], list[float]] = {}
    for onset in ONSETS:
        part = walk[walk["time"] < onset + WINDOW_S]
        part.attrs = walk.attrs
        log = inject_faults(part, [f"{f}@{onset:g}" for f in FAULTS], seed=0)
        loaded = first_loaded_after(part, "r", onset)
        for method, label in (("default", "default"), ("paper", "paper observer")):
            res = Monitor.for_log(log, MonitorConfig().with_method(method)).run(log)
            tab = evaluate_detection(res)
            cells = []
            for s in ("r1", "r2", "r3", "r4"):
                d = tab.loc[s, "delay_s"]
                delays.setdefault((label, s), []).append(float(d))
                ok = "" if method != "default" or tab.loc[s, "kind_correct"] is True else "*"
                cells.append("missed" if not np.isfinite(d) else f"{d:.2f}{ok}")
            fa = int(tab["false_alarms"].sum())
            r1_after_load = tab.loc["r1", "delay_s"] + onset - loaded
            rows.append(f"| {onset:.2f} | {loaded - onset:.2f} | {label} | "
                        + " | ".join(cells)
                        + f" | {r1_after_load:.2f} | {fa} |")
    lines = [
        "Command: `.venv/bin/python benchmarks/bench_onset_phase.py` (60 s default walk, "
        "seed 0, the paper's four right-foot faults at each onset; the default detector and "
        "the paper's observer, both on the default virtual sensor; * = kind misclassified). "
        "'loaded' = first time after the "
        "onset with all four right corners carrying load (truth) minus the onset; "
        "'r1 after load' = r1's detection time minus that instant.",
        "",
        "| onset [s] | loaded after [s] | method | r1 frozen [s] | r2 +100 N [s] | "
        "r3 +15 N/s [s] | r4 -100 N [s] | r1 after load [s] | false alarms |",
        "|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        "| method | sensor | median delay [s] | worst delay [s] |",
        "|---|---|---|---|",
    ]
    for (method, s), ds in sorted(delays.items()):
        arr = np.array(ds)
        worst = "missed" if np.isnan(arr).any() else f"{arr.max():.2f}"
        lines.append(f"| {method} | {s} | {np.nanmedian(arr):.2f} | {worst} |")
    body = "\n".join(lines) + "\n"
    print(body)
    if not args.no_write:
        update_benchmarks_md(body, section=SECTION)


if __name__ == "__main__":
    main()
