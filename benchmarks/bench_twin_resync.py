"""The vibration twin sensor after a stretch of NaN joint angles (analysis, no timing).

A 5 s SURALP walk with the iCub accelerometer vibration (``reality=vibration``, seed 0:
double support until 1.2 s, right single support 1.2-2.0 s, double 2.0-2.2 s, left
single 2.2-3.0 s, final double support from 3.0 s), 1, 2, 30 or 31 ms of NaN joint
angles at 0.8 s, 2.5 s, 3.0 s or 3.2 s. The twin sensor (``quiet_vfs_config``: no
accelerometer, 10 Hz rate low-pass) is resynced after the stretch as the monitor does
(``run_resynced``; bit for bit the monitor's ``vfs_*`` on this walk) and compared with
the same walk without the stretch: max |vfs_<s> difference| [N] in windows after the
stretch, with the leg odometry's former anchor rule and with ``anchor_hold``; then the
twin's error against the true forces without a stretch (from 1 s on). Usage::

    .venv/bin/python benchmarks/bench_twin_resync.py
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from grfguard.detect.system import quiet_vfs_config
from grfguard.estimate.config import VFSConfig
from grfguard.estimate.vfs import VirtualForceSensor
from grfguard.model.robot import SENSOR_NAMES, SURALP
from grfguard.sim import GaitConfig, NoiseConfig, simulate
from grfguard.sim.reality import load_reality

VFS = [f"vfs_{s}" for s in SENSOR_NAMES]
WINDOWS = [(0.0, 0.05), (0.05, 0.1), (0.1, 0.2), (0.2, 0.3), (0.3, 0.5), (0.5, 1.0),
           (1.0, 1.5)]


def _gap(log: pd.DataFrame, t0: float, ms: int) -> tuple[pd.DataFrame, np.ndarray, int]:
    t = log["time"].to_numpy()
    gap = (t >= t0 - 1e-9) & (t < t0 + ms * 1e-3 - 1e-9)
    bad = log.copy()
    bad.loc[gap, [c for c in log.columns if c.startswith("q_")]] = np.nan
    first = int(np.flatnonzero(gap)[-1]) + 1
    resync = np.zeros(len(log), bool)
    resync[first] = True
    return bad, resync, first


def main() -> None:
    log = simulate(SURALP, GaitConfig(duration=5.0), NoiseConfig(), seed=0,
                   reality=load_reality("vibration"))
    t = log["time"].to_numpy()
    dt = float(np.median(np.diff(t)))
    truth = log[[f"true_force_{s}" for s in SENSOR_NAMES]].to_numpy(float)
    ds = (log[["contact_ref_r", "contact_ref_l"]].to_numpy(float) > 0.5).all(axis=1)
    head = " ".join(f"{a:g}-{b:g}" for a, b in WINDOWS)
    print(f"| anchor rule | stretch | max abs dvfs [N] in windows after it [s]: {head} |")
    print("|---|---|---|")
    errs = {}
    for name, hold in (("former", False), ("anchor_hold", True)):
        twin = VirtualForceSensor.for_log(log, quiet_vfs_config(VFSConfig(anchor_hold=hold)))
        ref = twin.run(log)[VFS].to_numpy(float)
        e = ref - truth
        m = t >= 1.0
        errs[name] = (np.sqrt(np.mean(e[m & ds] ** 2)), np.abs(e[m & ds]).max(),
                      np.sqrt(np.mean(e[m & ~ds] ** 2)), np.abs(e[m & ~ds]).max())
        for t0 in (0.8, 2.5, 3.0, 3.2):
            for ms in (1, 2, 30, 31):
                bad, resync, first = _gap(log, t0, ms)
                out = twin.run_resynced(bad, resync)[VFS].to_numpy(float)
                d = np.abs(out - ref).max(axis=1)
                cells = " ".join(
                    f"{d[first + int(round(a / dt)):first + int(round(b / dt))].max():.1f}"
                    for a, b in WINDOWS)
                print(f"| {name} | {ms} ms at {t0} s | {cells} |")
    print("\n| anchor rule | twin error vs true forces, no stretch, t >= 1 s: "
          "DS rms / max, SS rms / max [N] |\n|---|---|")
    for name, (a, b, c, d) in errs.items():
        print(f"| {name} | {a:.1f} / {b:.0f}, {c:.1f} / {d:.0f} |")


if __name__ == "__main__":
    main()
