"""Fault detection benchmark: detection table of both methods, false alarms, speed.

Writes the ``## Fault detection`` section of BENCHMARKS.md:

1. the paper's scenario on the right foot and its mirror on the left foot (60 s default
   walk, seed 0, onset 5 s), one single-fault run per other kind; both methods
   (``default`` and ``paper``) on the same input (same VFS);
2. fault-free walks, 3 gaits x seeds 1-2 x 100 s = 10 min (thresholds were calibrated
   on seeds 101-103 by ``calibrate_default_thresholds.py``): alarm episodes;
3. speed: streaming ``Monitor.update`` [µs/sample] and batch ``Monitor.run``
   [samples/s], detection alone (VFS columns precomputed) and with the VFS.

Usage:
    .venv/bin/python benchmarks/bench_monitor.py [--cache-dir DIR] [--no-write]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import update_section  # noqa: E402
from calibrate_default_thresholds import walk_with_vfs  # noqa: E402

from grfguard.config import monitor_config  # noqa: E402
from grfguard.detect.monitor import Monitor, MonitorConfig  # noqa: E402
from grfguard.estimate.vfs import VFS_OUTPUT_COLUMNS  # noqa: E402
from grfguard.evaluate.detection import evaluate_detection  # noqa: E402
from grfguard.faults import inject_faults  # noqa: E402
from grfguard.model.robot import SENSOR_NAMES  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SECTION = "## Fault detection"
GAITS = {"0.12 m / 1.0 s": (0.12, 1.0), "0.15 m / 0.8 s": (0.15, 0.8),
         "0.08 m / 1.2 s": (0.08, 1.2)}
FREE_SEEDS = (1, 2)
FREE_DURATION = 100.0
SCENARIOS = {
    "paper, right foot": ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5",
                          "r4=offset:-100@5"],
    "mirror, left foot": ["l1=frozen:0@5", "l2=offset:100@5", "l3=drift:15@5",
                          "l4=offset:-100@5"],
    "stuck": ["l2=stuck@5.3"],
    "gain 1.6": ["l2=gain:1.6@5"],
    "noise 25 N": ["l2=noise:25@5"],
    "spikes 120 N": ["l2=spikes:120@5"],
    "dropout 5-6.5 s": ["l2=dropout@5-6.5"],
    "saturation 200 N": ["l2=saturation:200@5"],
    "offset 20 N": ["l2=offset:20@5"],
}


def _fmt(v: object, nd: int = 2) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (float, np.floating)):
        return "–" if not np.isfinite(v) else f"{v:.{nd}f}"
    return str(v)


#: Compared methods: name -> (detection method, virtual sensor). "paper" is the paper as
#: published (its VFS and observer, thresholds from its own fault-free runs);
#: "paper observer" is its observer on grfguard's VFS.
METHODS = {
    "default": ("default", "default"),
    "paper observer": ("paper", "default"),
    "paper": ("paper", "paper"),
}


def run_method(log: pd.DataFrame, name: str) -> pd.DataFrame:
    """Run one of :data:`METHODS` over ``log`` (precomputed default-VFS columns are reused
    by the methods on grfguard's VFS and dropped for the paper's own VFS)."""
    observer, vfs = METHODS[name]
    cfg = monitor_config(method=observer, vfs=vfs)
    if vfs == "paper":
        log = log.drop(columns=[c for c in VFS_OUTPUT_COLUMNS if c in log.columns])
    return Monitor.for_log(log, cfg).run(log)


def detection_table(walk: pd.DataFrame) -> tuple[list[str], dict]:
    lines = [
        "| scenario | sensor | injected | method | detected | delay [s] | kind | "
        "recovery RMSE [N] | fault-size error [N] | false alarms |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    summary: dict = {}
    for name, faults in SCENARIOS.items():
        log = inject_faults(walk, faults, seed=0)
        for method in METHODS:
            res = run_method(log, method)
            tab = evaluate_detection(res)
            fa = int(tab["false_alarms"].sum())
            summary[(name, method)] = tab
            for s in [f.split("=")[0] for f in faults]:
                r = tab.loc[s]
                lines.append(
                    f"| {name} | {s} | {r['fault_kind']} | {method} | "
                    f"{_fmt(bool(r['detected']))} | {_fmt(r['delay_s'])} | "
                    f"{r['kind_estimated']} | {_fmt(r['recovery_rmse_n'], 1)} | "
                    f"{_fmt(r['fault_size_error_n'], 1)} | {fa} |"
                )
    return lines, summary


def fault_free(cache: Path | None) -> list[str]:
    lines = [
        "| gait | seeds | minutes | method | alarm episodes | false alarms per hour | "
        "sensors that alarmed |",
        "|---|---|---|---|---|---|---|",
    ]
    tot = dict.fromkeys(METHODS, 0)
    minutes = 0.0
    for gname, (sl, sp) in GAITS.items():
        logs = [walk_with_vfs(sl, sp, seed, FREE_DURATION, cache, f"free_{sl}_{sp}_{seed}")
                for seed in FREE_SEEDS]
        mins = sum(len(x) for x in logs) / 1000.0 / 60.0
        minutes += mins
        for method in METHODS:
            n = 0
            who: set[str] = set()
            for log in logs:
                res = run_method(log, method)
                tab = evaluate_detection(res)
                n += int(tab["false_alarms"].sum())
                who |= {s for s in SENSOR_NAMES if tab.loc[s, "false_alarms"] > 0}
            tot[method] += n
            lines.append(
                f"| {gname} | {', '.join(map(str, FREE_SEEDS))} | {mins:.1f} | {method} | {n} | "
                f"{n / (mins / 60.0):.1f} | {', '.join(sorted(who)) or '–'} |"
            )
    for method in METHODS:
        lines.append(f"| **all** | | **{minutes:.1f}** | {method} | **{tot[method]}** | "
                     f"{tot[method] / (minutes / 60.0):.1f} | |")
    return lines


def speed(walk: pd.DataFrame) -> list[str]:
    log = inject_faults(walk, SCENARIOS["paper, right foot"], seed=0)
    raw = log.drop(columns=[c for c in log.columns if c.startswith(("vfs_", "com_est_",
                                                                     "contact_est_", "zmp_est",
                                                                     ))])
    lines = [
        "| method | input | streaming median [µs/sample] | p99 [µs/sample] | "
        "batch [samples/s] |",
        "|---|---|---|---|---|",
    ]
    for method in ("default", "paper"):
        for label, frame, n_stream in (("VFS columns precomputed", log, 20000),
                                       ("raw log (VFS inside)", raw, 3000)):
            mon = Monitor.for_log(frame, MonitorConfig(method=method))
            rows = frame.iloc[4000:4000 + n_stream].to_dict("records")
            mon.reset()
            dts = []
            for r in rows:
                t0 = time.perf_counter()
                mon.update(r)
                dts.append(time.perf_counter() - t0)
            med = statistics.median(dts) * 1e6
            p99 = float(np.percentile(dts, 99)) * 1e6
            t0 = time.perf_counter()
            mon.run(frame)
            el = time.perf_counter() - t0
            lines.append(f"| {method} | {label} | {med:.1f} | {p99:.1f} | "
                         f"{len(frame) / el:,.0f} |")
    return lines


def update_benchmarks_md(
    body: str, path: Path = ROOT / "BENCHMARKS.md", section: str = SECTION
) -> None:
    """Replace (or append) only ``section`` (default ``## Fault detection``) of ``path``."""
    update_section(section, body, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache-dir", type=Path, default=None)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    t0 = time.time()
    walk = walk_with_vfs(0.12, 1.0, 0, 60.0, args.cache_dir, "bench_default_0")
    det, _ = detection_table(walk)
    free = fault_free(args.cache_dir)
    spd = speed(walk)
    th = MonitorConfig().thresholds
    body = "\n".join([
        f"Command: `.venv/bin/python benchmarks/bench_monitor.py` ({os.cpu_count()} cores, "
        f"CPython {platform.python_version()}; {time.time() - t0:.0f} s). Shipped thresholds "
        f"(`src/grfguard/detect/default_thresholds.toml`, {th.source}). Both methods run on "
        "the same input: the default multibody VFS of the same log. Onset 5.0 s; in this "
        "walk (right foot steps first) the right foot swings 5.2-6.0 s, as the faulty foot "
        "in DESIGN.md's prototype, and the left foot lands at 5.0 s and swings 6.2-7.0 s "
        "(the mirror scenario is the unfavourable phase; `bench_onset_phase.py` sweeps the "
        "onset over a whole stride). Delay = first flag after "
        "the onset; recovery RMSE over planned stance after detection; fault-size error = "
        "RMSE of `eta` - truth after detection.",
        "",
        "Why the default detector looks the way it does (residual scales measured on the "
        "fault-free calibration walks, as shipped in the thresholds file):",
        "",
        f"- swing: the true force is exactly 0, the reading is noise with robust σ = "
        f"{th.sigma_swing_n:.2f} N; CUSUM allowance {th.swing_kappa:g} σ, threshold "
        f"{th.swing_h:.0f} σ·samples: a 100 N offset is flagged on the first valid swing "
        "sample, 20 N in ~5 samples, and the test isolates each sensor;",
        f"- foot total in clean single support: robust σ = {100 * th.total_sigma:.2f} % of the "
        f"weight ({th.total_sigma * 114 * 9.81:.1f} N for SURALP); threshold {th.total_h:.0f};",
        f"- per corner in clean single support: robust σ = {100 * th.corner_sigma:.1f} % of "
        f"the weight ({th.corner_sigma * 114 * 9.81:.0f} N, "
        f"{th.corner_sigma / th.total_sigma:.1f}x the foot total): it isolates stance faults, "
        "also when another sensor of the foot carries no information (then the foot-total "
        "test is blind);",
        "- gates: measured on the calibration walks, feet carry load up to 74 ms after the "
        "planned lift-off and from up to 109 ms before the planned touchdown, so the swing "
        "window is [lift-off + 0.12 s, expected touchdown - 0.18 s] and is only used once a "
        "swing duration is known; the first single support after the start (unknown "
        "touchdown time of the other foot) gave the only large foot-total excursions and is "
        "skipped;",
        f"- frozen/stuck/clipped: the same reading of a loaded sensor for {th.const_s} s (a "
        "healthy load cell always shows noise).",
        "",
        "### Detection on the 60 s default walk (seed 0)",
        "",
        *det,
        "",
        "### Fault-free walks (10 min, seeds not used for calibration)",
        "",
        *free,
        "",
        "### Speed (plain Python floats, one thread)",
        "",
        *spd,
        "",
        "Notes:",
        "",
        "- Mirror (left-foot) scenario: the left foot lands at the onset, the drift "
        "(15 N/s) stays below the corner noise during its single support and the "
        "foot-total test is blind while l1 is frozen, so the drift is caught at the start "
        "of the next swing window, about 1.3 s after the onset. The same holds for the "
        "right foot at that phase (see the onset-phase section): a drift that starts on a "
        "loaded foot whose other sensor is frozen is limited by the per-corner VFS error.",
        "- Recovery of sensors without information (frozen, stuck, dropout, clipped, noisy) "
        "uses the whole-body balance: VFS total force minus the other seven (healthy or "
        "corrected) sensors; the VFS per-foot split and corners are much coarser in double "
        "support.",
        "- 'paper observer' = the paper's observer (eq. 24-33, thresholds = 1.5 x the "
        "largest fault-free low-passed η̂ per sensor, its own tuning rule) on grfguard's "
        "VFS: no kinds, misses noise, spikes, dropout and a 20 N offset, slow on drift, and "
        "its recovery of a frozen sensor is the observer's N̂ (> 100 N error). 'paper' = "
        "the paper as published: its own VFS (LIPM CoM, alpha split, eq. 10-12, W = 0.01) "
        "with thresholds picked by the same rule on fault-free runs of that pipeline "
        "(`paper_vfs_thresholds.toml`): its VFS errors of 100-200 N per corner force "
        "thresholds of 150-220 N, above the ±100 N offsets of its own scenario.",
        "- Streaming speed: one `update(row)` in plain Python floats (dict in, dict out); "
        "batch `run` is the same step in a loop (exact equality), except the paper's "
        "observer, which uses `scipy.signal.lfilter`. 'raw log' includes the streaming VFS.",
    ])
    print(body)
    if not args.no_write:
        update_benchmarks_md(body)
        print(f"updated {ROOT / 'BENCHMARKS.md'} ({SECTION})")


if __name__ == "__main__":
    main()
