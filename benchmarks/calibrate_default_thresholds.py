"""Make the shipped thresholds (src/grfguard/detect/*_thresholds.toml).

Fault-free walks of the three gaits (0.12 m/1.0 s, 0.15 m/0.8 s, 0.08 m/1.2 s) with
calibration seeds 101-103 (the tests and benchmarks use other seeds),
:func:`grfguard.detect.monitor.calibrate_thresholds` for 0.1 false alarm per hour.

``--vfs default`` (grfguard's virtual sensor) writes ``default_thresholds.toml``;
``--vfs paper`` (the paper's virtual sensor, eq. 1-23) writes
``paper_vfs_thresholds.toml``, used when the paper's method runs on the paper's own
virtual sensor: its eq. 33 thresholds are then picked, as the paper does, from
fault-free runs of that very pipeline.

Usage:
    .venv/bin/python benchmarks/calibrate_default_thresholds.py [--vfs default|paper]
        [--cache-dir DIR] [--dry-run]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import pandas as pd

from grfguard.detect.monitor import MonitorConfig, calibrate_thresholds
from grfguard.detect.thresholds import Thresholds

GAITS = {"a": (0.12, 1.0), "b": (0.15, 0.8), "c": (0.08, 1.2)}
SEEDS = (101, 102, 103)
DURATION_S = 60.0
RATE_PER_HOUR = 0.1
DETECT = Path(__file__).resolve().parents[1] / "src/grfguard/detect"
OUT = {"default": DETECT / "default_thresholds.toml",
       "paper": DETECT / "paper_vfs_thresholds.toml"}


def walk_with_vfs(step_length: float, step_period: float, seed: int, duration: float,
                  cache: Path | None = None, name: str = "",
                  vfs_method: str = "default") -> pd.DataFrame:
    """A fault-free simulated walk plus the VFS columns (cached as pickle if asked)."""
    if cache is not None and (cache / f"{name}.pkl").is_file():
        return pd.read_pickle(cache / f"{name}.pkl")
    from grfguard.estimate.config import VFSConfig
    from grfguard.estimate.vfs import with_vfs_columns
    from grfguard.sim import GaitConfig, simulate

    log = simulate(gait=GaitConfig(step_length=step_length, step_period=step_period,
                                   duration=duration), seed=seed)
    vfs_cfg = VFSConfig.paper() if vfs_method == "paper" else VFSConfig()
    df = with_vfs_columns(log, vfs_cfg)
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
        df.to_pickle(cache / f"{name}.pkl")
    return df


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cache-dir", type=Path, default=None)
    ap.add_argument("--dry-run", action="store_true")
    ap.add_argument("--vfs", choices=sorted(OUT), default="default")
    args = ap.parse_args()
    t0 = time.time()
    logs = [
        walk_with_vfs(*GAITS[g], seed, DURATION_S, args.cache_dir,
                      f"cal_{args.vfs}_{g}_{seed}", vfs_method=args.vfs)
        for g in GAITS for seed in SEEDS
    ]
    t1 = time.time()
    base = MonitorConfig(thresholds=Thresholds())
    th = calibrate_thresholds(logs, RATE_PER_HOUR, base)
    th = th.replace(source=f"benchmarks/calibrate_default_thresholds.py --vfs {args.vfs}: gaits "
                    f"{sorted(GAITS.values())}, seeds {list(SEEDS)}, {DURATION_S:g} s each, "
                    f"{RATE_PER_HOUR} false alarms/h")
    print(th.to_toml())
    print(f"walks {t1 - t0:.1f} s, calibration {time.time() - t1:.1f} s")
    if not args.dry_run:
        OUT[args.vfs].write_text(
            "# Made by benchmarks/calibrate_default_thresholds.py; do not edit.\n" + th.to_toml()
        )
        print(f"wrote {OUT[args.vfs]}")


if __name__ == "__main__":
    main()
