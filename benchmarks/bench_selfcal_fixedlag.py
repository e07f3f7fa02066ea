"""A fixed-lag gyro smoother for the accelerometer-free virtual sensor (issue 10, Must show 2:
the per-corner threshold within 2x of the exact model's; 2.02x on seed 1).

``bench_selfcal_odom.py`` found that only a non-causal gyro low-pass brings the per-corner
ratio well under 2x (about 40 % of the odometry's noise above 10 Hz is the
gyro-integrated attitude's), and no causal filter does. A monitor can afford a little
non-causality: deciding ``L`` seconds late, it can smooth the gyro with a symmetric FIR
filter of half-width ``L`` (taps ``t - L .. t + L`` for the sample at ``t``; the monitor's
other inputs delayed by ``L`` with it). Offline, that monitor's outputs are those of the
monitor fed the gyro smoothed by the same symmetric filter, shifted by ``L``: this script
measures them so (an emulation: the library has no such option yet), for ``L`` = 0 (as
today), 20, 40 and 60 ms (Hamming-windowed sinc, 10 Hz cut-off, ``scipy.signal.firwin``;
edges padded with the first / last sample):

* the per-corner threshold calibrated on the all-gaps robot's calibration data (poses +
  walk, corrected with the weighed mass, the rate low-pass chosen on the unsmoothed data
  as ``grfguard calibrate --model`` does), against the exact model's (same seed,
  unsmoothed: the reference of ``bench_selfcal.py``);
* healthy-sensor alarm episodes on the 10 minutes of other walks of ``bench_selfcal.py``;
* the paper's scenario on that robot: delays of the batch run, plus ``L`` for the
  streaming monitor that decides ``L`` late.

Usage: ``python benchmarks/bench_selfcal_fixedlag.py [--seeds 1,2,3,4,5] [--write]``; ``--write``
replaces the ``## Model self-calibration: a fixed-lag gyro smoother`` section of
BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.signal import firwin

from grfguard.calib import apply_corrections, estimate_corrections
from grfguard.detect import Monitor, calibrate_thresholds
from grfguard.model.robot import RobotConfig
from grfguard.sim import simulate
from grfguard.sim.config import GaitConfig
from grfguard.sim.reality import load_reality

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RunClock, alarm_episodes, finish_section  # noqa: E402
from bench_selfcal import level, other_walk, paper_scenario, thresholds_of  # noqa: E402

HEADER = "## Model self-calibration: a fixed-lag gyro smoother"
LAGS_MS = (0, 20, 40, 60)
CUTOFF_HZ = 10.0
READING = (
    "Reading. The fixed lag lowers the robot's per-corner threshold by 4-6 % at 20 ms and "
    '9-11 % at 40-60 ms on every seed, but the ratio is set mostly by the reference: the e'
    'xact model\'s threshold follows its simulated IMU\'s attitude error (section "Exact mod'
    'el: the IMU\'s attitude bias and the per-corner threshold"): 0.302 / 0.313 / 0.488 / 0'
    ".254 / 0.250 on seeds 1-5, while the robot's is 0.61-0.62 on seeds 1, 2, 4 and 5 (0.7"
    '3 on seed 3). So 20 ms takes seeds 1 and 2 under 2x (1.93x, 1.87x) but leaves seeds 4'
    ' and 5 at 2.31x and 2.36x (2.42x / 2.47x today; 60 ms: 2.18x / 2.21x). False alarms d'
    'o not follow `L` (20 ms: one episode on seed 3; 40 ms: one on seed 2; 60 ms: 2, 3 and'
    " 2 on seeds 1, 2 and 5). The paper's scenario is detected at the same samples at ever"
    'y `L` (a streaming monitor reports them `L` later: at 20 ms 0.044 / 0.341 / 0.504 / 0'
    ".341 s, within issue 10's bounds). So the per-corner bound is missed by about a fifth"
    ' on seeds whose IMU attitude error is small, and no gyro smoothing closes that: the a'
    'ccelerometer-free sensor itself must get better (its noise scale is 2.5x the self-cal'
    "ibrated exact model's, 0.0204 / 0.0083 on seed 1)."
)


def gyro_fixed_lag(log, half: int):
    """``log`` with its gyro columns smoothed by the symmetric FIR of ``half`` samples
    each side (none for 0)."""
    if half == 0:
        return log
    fs = 1.0 / float(np.median(np.diff(log["time"].to_numpy(float))))
    h = firwin(2 * half + 1, CUTOFF_HZ, fs=fs)
    out = log.copy()
    for k in "xyz":
        x = log[f"imu_gyro_{k}"].to_numpy(float)
        xp = np.r_[np.full(half, x[0]), x, np.full(half, x[-1])]
        out[f"imu_gyro_{k}"] = np.convolve(xp, h, mode="valid")
    out.attrs = log.attrs
    return out


def alarms(walks: dict, corr, cfg, half: int) -> list[int]:
    """Healthy-sensor alarm episodes per walk."""
    eps = []
    for w in walks.values():
        wc = apply_corrections(gyro_fixed_lag(w, half), corr)
        eps.append(alarm_episodes(Monitor.for_log(wc, config=cfg).run(wc)))
    return eps


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="1,2,3,4,5")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    clock = RunClock()
    gap = load_reality("all")
    nominal = RobotConfig()
    walks = {11 + k: other_walk(k, gap) for k in range(10)}
    lines = [
        HEADER, "",
        "`python benchmarks/bench_selfcal_fixedlag.py --write` (issue 10, Must show 2; an "
        "emulation, not a library option). The all-gaps robot of `bench_selfcal.py`; its "
        "gyro smoothed by a symmetric FIR filter of half-width `L` (Hamming-windowed sinc, "
        f"{CUTOFF_HZ:g} Hz cut-off): what a monitor deciding `L` late can do, its other "
        "inputs delayed by `L` with the gyro. Per-corner threshold calibrated on the "
        "smoothed calibration data (the rate low-pass chosen on the unsmoothed data) "
        "against the exact model's (unsmoothed, same seed); healthy-sensor alarm "
        "episodes on the 10 minutes of other walks (seeds 11-20, five gaits, smoothed "
        "alike); the paper's scenario (seed 0): delays of the batch run r1 / r2 / r3 / r4 "
        "[s] (the streaming monitor reports each `L` later) and the frozen sensor's "
        "delay after its foot's next load (bound 0.2 s, plus `L` when streaming).", "",
        "| seed | `L` [ms] | per-corner threshold | ratio (bound 2) | false alarms | "
        "paper scenario delays | frozen after the next load |",
        "|---|---|---|---|---|---|---|"]
    for seed in (int(s) for s in args.seeds.split(",")):
        cal = simulate(gait=GaitConfig(duration=60.0, calibration_poses=True), seed=seed,
                       reality=gap)
        m_true = nominal.mass * (1 + cal.attrs["reality"]["mass_error"])
        _, cfg, corr, _ = thresholds_of(cal, estimate_corrections(cal,
                                                                  measured_mass_kg=m_true))
        th_exact, *_ = thresholds_of(simulate(gait=GaitConfig(duration=60.0), seed=seed))
        c_x = level(th_exact)[0]
        for lag in LAGS_MS:
            half = int(round(lag * 1e-3 * 1000))
            th = calibrate_thresholds([apply_corrections(gyro_fixed_lag(cal, half), corr)],
                                      config=cfg)
            c_g = level(th)[0]
            mcfg = cfg.with_thresholds(th)
            eps = alarms(walks, corr, mcfg, half)
            sc = paper_scenario(gap, corr, mcfg, prepare=lambda w, h=half: gyro_fixed_lag(w, h))
            d = " / ".join(f"{sc[s]['delay_s']:.3f}" for s in ("r1", "r2", "r3", "r4"))
            lines.append(f"| {seed} | {lag} | {c_g:.4f} (`h` {th.corner_h:.1f}) | "
                         f"{c_g / c_x:.3f} | {sum(eps)} | {d} | "
                         f"{sc['r1']['delay_after_load_s']:.3f} |")
            print(lines[-1], flush=True)
    lines += ["", READING]
    finish_section(HEADER, lines, clock, args.write)


if __name__ == "__main__":
    main()
