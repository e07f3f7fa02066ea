"""Make the shipped thresholds of a described robot (src/grfguard/data/<robot>_thresholds.toml).

Corner-cell robots (G1): thresholds of the default detector; ankle F/T robots (Talos):
the per-channel scales and CUSUM threshold of :mod:`grfguard.detect.channels`
(``<robot>_channels.toml``, :func:`~grfguard.detect.channels.calibrate_channels`).

Fault-free walks of the robot on its scaled default gait
(:func:`grfguard.sim.wholebody.scaled_gait`, default sensor noise) with calibration
seeds 101-104, 60 s each (the tests and benchmarks use other seeds); the virtual sensor
columns from :func:`grfguard.estimate.described.with_described_vfs`;
:func:`grfguard.detect.calibrate.calibrate_thresholds` for 0.1 false alarm per hour, as
``benchmarks/calibrate_default_thresholds.py`` does for SURALP.

Usage:
    .venv/bin/python benchmarks/calibrate_described_thresholds.py [--robot g1] [--dry-run]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

from grfguard.detect.calibrate import calibrate_thresholds
from grfguard.detect.config import MonitorConfig
from grfguard.detect.thresholds import Thresholds
from grfguard.estimate.described import with_described_vfs
from grfguard.model.description import load_description
from grfguard.model.loader import load_model
from grfguard.sim.config import NoiseConfig
from grfguard.sim.wholebody import scaled_gait, simulate_robot

SEEDS = (101, 102, 103, 104)
DURATION_S = 60.0
RATE_PER_HOUR = 0.1
DATA = Path(__file__).resolve().parents[1] / "src/grfguard/data"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--robot", default="g1")
    ap.add_argument("--dry-run", action="store_true")
    args = ap.parse_args()
    t0 = time.time()
    r = load_model(load_description(args.robot))
    logs = [with_described_vfs(simulate_robot(r, scaled_gait(r, duration=DURATION_S),
                                              NoiseConfig(), seed=s), r) for s in SEEDS]
    t1 = time.time()
    if r.description.sensing == "ft":
        from grfguard.detect.channels import calibrate_channels

        cc = calibrate_channels(logs, RATE_PER_HOUR)
        cc = replace(cc, source=f"benchmarks/calibrate_described_thresholds.py --robot "
                     f"{args.robot}: seeds {list(SEEDS)}, {DURATION_S:g} s each")
        print(cc.to_toml())
        print(f"walks {t1 - t0:.1f} s, calibration {time.time() - t1:.1f} s")
        if not args.dry_run:
            out = DATA / f"{args.robot}_channels.toml"
            out.write_text("# Made by benchmarks/calibrate_described_thresholds.py; do not "
                           "edit.\n" + cc.to_toml())
            print(f"wrote {out}")
        return
    th = calibrate_thresholds(logs, RATE_PER_HOUR, MonitorConfig(thresholds=Thresholds()))
    th = th.replace(source=f"benchmarks/calibrate_described_thresholds.py --robot "
                    f"{args.robot}: scaled default gait, seeds {list(SEEDS)}, "
                    f"{DURATION_S:g} s each, {RATE_PER_HOUR} false alarms/h")
    print(th.to_toml())
    print(f"walks {t1 - t0:.1f} s, calibration {time.time() - t1:.1f} s")
    if not args.dry_run:
        out = DATA / f"{args.robot}_thresholds.toml"
        out.write_text("# Made by benchmarks/calibrate_described_thresholds.py; do not edit.\n"
                       + th.to_toml())
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
