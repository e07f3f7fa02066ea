"""The simulated IMU's attitude bias and the exact model's per-corner threshold.

Issue 10 compares the calibrated robot's per-corner threshold with the exact model's on
the same seed (``bench_selfcal.py``: 0.302 on seed 1, 0.313 on seed 2, 0.488 on seed 3).
The exact model is not noise-free: the simulated IMU's quaternion carries a constant
small-angle attitude error drawn per seed (``NoiseConfig.attitude_bias_sigma``, 2 mrad
per axis). A roll error ``d`` moves the estimated CoM sideways by about ``h d`` (``h``
the CoM height), a pitch error forwards, so each sole's estimated centre of pressure is
off by the same amount all walk long and every corner's residual carries a constant
bias: corners 1 and 3 (left edge) against 2 and 4 (right edge) for roll, 1 and 2 (front)
against 3 and 4 (rear) for pitch. The per-corner noise scale is the MAD of all eight
corners' residuals pooled, so those biases raise it.

Per seed, on the exact model's 60 s default walk (default monitor config):

* the attitude bias of the logged quaternion against the true trunk orientation (roll,
  pitch) [mrad] (truth columns: the benchmark reads them, the monitor does not);
* the per-corner residuals' medians over single support (``calibrate_thresholds``'
  ``summary``): the worst, and the roll and pitch patterns ``(r1 - r2 + r3 - r4 + l1 -
  l2 + l3 - l4) / 8`` and ``(r1 + r2 - r3 - r4 + l1 + l2 - l3 - l4) / 8`` [fraction of
  the weight], and the share of the corner
  noise scale that a steady CoP shift explains (``corner_tilt``, what ``grfguard
  calibrate`` reports);
* the per-corner threshold ``sigma * h`` calibrated on the walk (``calibrate_thresholds``,
  as in ``bench_selfcal.py``), and its noise scale ``sigma``;
* the same after ``estimate_corrections`` on the same walk (``grfguard calibrate
  --model``; it fits the IMU mounting, which takes the attitude bias with it) and the
  thresholds calibrated on the corrected walk with the config the corrections call for.

Usage: ``python benchmarks/bench_attitude_bias.py [--seeds 1-6] [--write]``; ``--write``
replaces the ``## Exact model: the IMU's attitude bias and the per-corner threshold``
section of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from grfguard.calib import apply_corrections, corrected_config, estimate_corrections
from grfguard.detect import Monitor, MonitorConfig, calibrate_thresholds
from grfguard.detect.calibrate import corner_tilt
from grfguard.model.robot import SURALP
from grfguard.sim import simulate
from grfguard.sim.config import GaitConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RunClock, alarm_episodes, finish_section  # noqa: E402
from bench_selfcal import other_walk  # noqa: E402

HEADER = "## Exact model: the IMU's attitude bias and the per-corner threshold"
READING = (
    "Reading. The exact model's per-corner threshold is set by the simulated IMU's attitud"
    'e error, not by the walk: the roll pattern of the medians follows the roll bias (seed'
    ' 3: -4.0 mrad, the left corners 0.011 of the weight under the right, the threshold 0.'
    '488; seeds 4-5, about 1 mrad: 0.25). Fitted on the same walk, `estimate_corrections` '
    'takes it out (noise scale 0.0082-0.0083, threshold 0.246-0.278), but in this simulati'
    'on the error is drawn per run, so the fit does not carry over: applied to the 10 minu'
    'tes of other walks, the corrections of seeds 2, 3 and 6 give 7, 3 and 23 alarm episod'
    'es (seeds 1, 4 and 5, errors of about 1 mrad: none); fitted on the six walks together'
    " they leave each run's error in the residuals and the threshold rises (0.311 -> 0.372"
    ', `h` 38.9; no false alarm). So `calibrate --model` removes a constant error of the r'
    "obot (an IMU mounting, as in issue 10's reality gap), not the run-to-run error of the"
    " IMU's own attitude estimate. `grfguard calibrate` reports a steady centre-of-pressur"
    'e shift from a share of 0.4 and, given logs of several runs, says whether it is commo'
    'n to them (then `--model` fits it) or changes from log to log (then it does not) (`gr'
    'fguard.detect.calibrate.tilt_hint`). For issue 10\'s per-corner ratio (section "Model '
    'self-calibration": the calibrated robot against the exact model without self-calibrat'
    'ion, same seed) this draw moves the reference: 2.02x on seed 1 (1.1 / 1.2 mrad), 1.98'
    'x on seed 2, 1.50x on seed 3 (4 mrad), 2.42x and 2.47x on seeds 4 and 5 (about 1 mrad'
    "; `bench_selfcal_fixedlag.py`, its `L` = 0 rows), the robot's own threshold being 0.6"
    '1-0.62 on seeds 1, 2, 4 and 5. Against the exact model put through the same self-cali'
    'bration on the same walk (seed 1: its correction holds on the other walks, no false a'
    "larm) the robot's seed-1 threshold (0.611) is 2.2x (0.278), the noise scales 2.5x (0."
    '0204 / 0.0083): the gap the accelerometer-free sensor leaves is wider than the 1 % th'
    'e seed-1 row shows.'
)
#: Corner patterns (r1..r4, l1..l4; 1 front-left, 2 front-right, 3 rear-left, 4 rear-right).
ROLL = np.array([1, -1, 1, -1] * 2) / 8.0
PITCH = np.array([1, 1, -1, -1] * 2) / 8.0


def attitude_bias_mrad(log) -> tuple[float, float]:
    """Mean roll and pitch of the logged IMU quaternion against the true trunk [mrad]."""
    qi = log[["imu_quat_x", "imu_quat_y", "imu_quat_z", "imu_quat_w"]].to_numpy(float)
    qt = log[["true_base_quat_x", "true_base_quat_y", "true_base_quat_z",
              "true_base_quat_w"]].to_numpy(float)
    e = (Rotation.from_quat(qt).inv() * Rotation.from_quat(qi)).as_rotvec().mean(axis=0)
    return 1000 * float(e[0]), 1000 * float(e[1])


def corner_figures(logs: list, cfg: MonitorConfig, walks: dict, corr=None
                   ) -> dict[str, float]:
    """Per-corner medians (worst, roll and pitch patterns), the share of the corner noise
    scale that a CoP shift explains (``corner_tilt``: what ``grfguard calibrate`` reports)
    and the threshold calibrated on ``logs`` under ``cfg``; the healthy-sensor alarm
    episodes on the other ``walks`` with those thresholds (and ``corr`` applied)."""
    summary: dict = {}
    th = calibrate_thresholds(logs, config=cfg, summary=summary)
    med = summary["corner_median"]
    tilt = corner_tilt(med, summary["corner_sigma"], SURALP.sensor_positions_in_foot())
    mon_cfg = cfg.with_thresholds(th)
    fa = 0
    for w in walks.values():
        wc = apply_corrections(w, corr) if corr is not None else w
        fa += alarm_episodes(Monitor.for_log(wc, config=mon_cfg).run(wc))
    return {"worst": float(np.max(np.abs(med))), "roll": float(ROLL @ med),
            "pitch": float(PITCH @ med), "share": tilt.share, "sigma": th.corner_sigma,
            "h": th.corner_h, "level": th.corner_sigma * th.corner_h, "fa": fa}


def cells(f: dict[str, float]) -> str:
    lv = f"{f['level']:.3f}" + ("" if f["h"] == 30.0 else f" (`h` {f['h']:.1f})")
    return (f"{f['worst']:.4f} / {f['roll']:+.4f} / {f['pitch']:+.4f} | "
            f"{f['share']:.2f} | {f['sigma']:.4f} | {lv} | {f['fa']}")


def seeds_arg(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b or a) + 1))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=seeds_arg, default=seeds_arg("1-6"))
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    clock = RunClock()
    lines = [
        HEADER, "",
        f"`python benchmarks/bench_attitude_bias.py --write` (seeds {args.seeds[0]}-"
        f"{args.seeds[-1]}). The exact model's 60 s default walk per seed: the simulated "
        "IMU's constant attitude error (`NoiseConfig.attitude_bias_sigma`, 2 mrad per "
        "axis) as roll / pitch [mrad]; the per-corner residuals' medians over single "
        "support [fraction of the weight]: the worst, the roll pattern (left corners "
        "against right) and the pitch pattern (front against rear); the share of the "
        "per-corner noise scale that a steady centre-of-pressure shift explains "
        "(`grfguard.detect.calibrate.corner_tilt`: `grfguard calibrate` reports "
        "it from 0.4); the per-corner "
        "threshold `sigma * h` calibrated on the walk (`h` at its floor of 30 unless "
        "stated). Then the same after `estimate_corrections` on that walk (`grfguard "
        "calibrate --model`: the IMU mounting it fits takes the attitude error with it), "
        "thresholds calibrated on the corrected walk. False alarms: healthy-sensor alarm "
        "episodes on the 10 minutes of other walks of `bench_selfcal.py` (seeds 11-20, "
        "five gaits; exact model, each run with its own IMU attitude error) with those "
        "thresholds (and those corrections). Last row: the six walks calibrated "
        "together (`grfguard calibrate` or `calibrate --model` given all six logs).", "",
        "| seed | attitude bias roll / pitch | medians worst / roll / pitch | CoP-shift "
        "share | sigma | threshold | false alarms | corrected: medians worst / roll / "
        "pitch | CoP-shift share | sigma | threshold | false alarms |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    walks = {11 + k: other_walk(k) for k in range(10)}
    logs = []
    for seed in args.seeds:
        log = simulate(gait=GaitConfig(duration=60.0), seed=seed)
        logs.append(log)
        roll, pitch = attitude_bias_mrad(log)
        raw = corner_figures([log], MonitorConfig(), walks)
        corr = estimate_corrections(log)
        cal = corner_figures([apply_corrections(log, corr)],
                             corrected_config(MonitorConfig(), corr), walks, corr)
        lines.append(f"| {seed} | {roll:+.2f} / {pitch:+.2f} | {cells(raw)} | {cells(cal)} |")
        print(lines[-1], flush=True)
    raw = corner_figures(logs, MonitorConfig(), walks)
    corr = estimate_corrections(logs)
    cal = corner_figures([apply_corrections(x, corr) for x in logs],
                         corrected_config(MonitorConfig(), corr), walks, corr)
    lines.append(f"| all {len(logs)} together | | {cells(raw)} | {cells(cal)} |")
    print(lines[-1], flush=True)
    lines += ["", READING]
    finish_section(HEADER, lines, clock, args.write)


if __name__ == "__main__":
    main()
