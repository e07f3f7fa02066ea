"""Issue 10's per-corner ratio gap by gap: which part of the all-gaps robot's reality gap
keeps its calibrated per-corner threshold above 2x the exact model's.

For each seed: the exact model's per-corner threshold (60 s walk, as ``bench_selfcal.py``)
and that of robots self-calibrated as ``bench_selfcal.py`` does (calibration poses + walk,
``estimate_corrections`` with the weighed mass, the accelerometer-free sensor's rate
low-pass chosen on the data, thresholds calibrated on the corrected data):

* every gap of ``grfguard/data/reality/all.toml`` (the robot of ``bench_selfcal.py``);
* every gap but one, for each gap (the draw seed kept: the other gaps' draws unchanged);
* the accelerometer vibration alone (the robot exactly as described; its accelerometer
  vibrates, so the sensor runs without it, as on the all-gaps robot).

Each row also gives the per-corner residual's noise scale split into each stance sole's
four corner modes (``H4``: total, front-rear, left-right, twist ``f1 - f2 - f3 + f4``;
robust scales of the residuals in units of the weight, right / left sole).

Usage: ``python benchmarks/bench_selfcal_gaps.py [--seeds 1,4] [--jobs 2] [--write]``;
``--write`` replaces the section ``## Model self-calibration: the per-corner threshold
gap by gap`` of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from grfguard.calib import apply_corrections, estimate_corrections
from grfguard.detect.blocks import robust_scale
from grfguard.detect.calibrate import _fault_free_statistics
from grfguard.model.robot import SENSOR_NAMES, RobotConfig
from grfguard.sim import simulate
from grfguard.sim.config import GaitConfig
from grfguard.sim.reality import RealityGap, load_reality

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RunClock, finish_section  # noqa: E402
from bench_selfcal import level, thresholds_of  # noqa: E402
from bench_selfcal_twin import H4  # noqa: E402  (a sole's four corner modes)

HEADER = "## Model self-calibration: the per-corner threshold gap by gap"
GAPS = tuple(f.name for f in dataclasses.fields(RealityGap) if f.name != "seed")
READING = (
    'Reading (2026-11-27). Two things set the ratio, and neither is a model error left '
    'after the calibration. (1) The accelerometer-free sensor: the robot exactly as '
    'described, its accelerometer vibrating, measures 1.70x (seed 1) and 2.08x (seed 4); '
    "its left-right mode is 2.1-2.4x the exact model's (the lateral centre of pressure from"
    " the leg odometry's CoM acceleration), its twist mode the exact model's. With a quiet "
    'accelerometer (every gap but the vibration: the accelerometer fused) the robot is at '
    '1.34x / 1.58x. (2) The trunk CoM offset: the calibration puts it into the model '
    '(within 0.26 cm), but the robot still walks with its centres of pressure off the '
    "soles' centres in both axes, where the soft contact carries a twisted load (section "
    '"Model self-calibration: contact twist"; the fitted twist that would model it raises '
    "false alarms on other walks there) that the sensor's planar split does not give: with "
    "the offset the left sole's twist mode is eight times the exact model's (0.016 of the "
    "weight), without it the exact model's, and the robot is at 1.55x / 1.92x (under the "
    'bound on both seeds). The 2 % of leg mass moved to the trunk interacts with it: '
    "without that gap the ratio rises to 2.52x / 3.02x (its soles' centres of pressure sit "
    'further off: section "Model self-calibration: where the centres of pressure sit"). The '
    'gaps the '
    'calibration fits (mass, IMU mounting, gyro and accelerometer biases, load-cell gains '
    'and zeros) move the threshold by 1.2 % or less; the encoder offsets and sensor '
    'positions, not fitted, by up to 3-4 % (seed 1: 1.96x and 1.94x without each).'
)


def corner_modes(log, cfg) -> tuple[float, list[float]]:
    """Noise scale of the per-corner residuals (all corners pooled, as
    ``calibrate_thresholds``) and the scale of each sole's four modes (right, then
    left)."""
    diag, _ = _fault_free_statistics(log, cfg)
    res = diag[[f"res_corner_{s}" for s in SENSOR_NAMES]].to_numpy(float)
    modes = []
    for f in range(2):
        m = res[:, 4 * f:4 * f + 4] @ H4.T
        ok = np.isfinite(m).all(axis=1)
        modes += [float(robust_scale(m[ok, j])) for j in range(4)]
    return float(robust_scale(res.ravel())), modes


def case(seed: int, label: str, gap: RealityGap | None) -> dict:
    """Per-corner threshold, `h`, noise scale and sole modes of one robot (None: the
    exact model, thresholds calibrated on a plain 60 s walk)."""
    if gap is None:
        log = simulate(gait=GaitConfig(duration=60.0), seed=seed)
        th, cfg, *_ = thresholds_of(log)
    else:
        cal = simulate(gait=GaitConfig(duration=60.0, calibration_poses=True), seed=seed,
                       reality=gap)
        m_true = RobotConfig().mass * (1 + cal.attrs["reality"]["mass_error"])
        th, cfg, corr, _ = thresholds_of(cal, estimate_corrections(cal,
                                                                   measured_mass_kg=m_true))
        log = apply_corrections(cal, corr)
    sigma, modes = corner_modes(log, cfg)
    return {"seed": seed, "label": label, "corner": level(th)[0], "h": th.corner_h,
            "sigma": sigma, "modes": modes}


def cases(seed: int) -> list[tuple[int, str, RealityGap | None]]:
    gap = load_reality("all")
    out = [(seed, "exact model", None), (seed, "every gap", gap)]
    for name in GAPS:
        if getattr(gap, name) != getattr(RealityGap(), name):
            out.append((seed, f"every gap but `{name}`",
                        dataclasses.replace(gap, **{name: getattr(RealityGap(), name)})))
    out.append((seed, "accelerometer vibration alone",
                RealityGap(acc_vibration=gap.acc_vibration, seed=gap.seed)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="1,4")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    clock = RunClock()
    todo = [c for s in args.seeds.split(",") for c in cases(int(s))]
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        rows = list(pool.map(case, *zip(*todo, strict=True)))
    lines = [
        HEADER, "",
        f"`python benchmarks/bench_selfcal_gaps.py --seeds {args.seeds} --write` (issue 10, "
        "Must show 2: per-corner threshold at most 2x the exact model's). Robots "
        "self-calibrated as in \"Model self-calibration\" (calibration poses + walk, "
        "weighed mass, rate low-pass chosen on the data, thresholds calibrated on the "
        "corrected data), with every gap of `grfguard/data/reality/all.toml`, every gap "
        "but one (its draws kept), or the accelerometer vibration alone; the exact model "
        "calibrated on a 60 s walk. Per-corner threshold `sigma * h`, ratio to the exact "
        "model's of the same seed, the residual's noise scale `sigma` [weight] and the "
        "robust scales of each stance sole's corner modes [weight], right / left sole.", "",
        "| seed | robot | corner | `h` | ratio | `sigma` | total | front-rear | left-right "
        "| twist |",
        "|---|---|---|---|---|---|---|---|---|---|"]
    exact = {r["seed"]: r["corner"] for r in rows if r["label"] == "exact model"}
    for r in rows:
        m = r["modes"]
        mode = [f"{m[j]:.4f} / {m[4 + j]:.4f}" for j in range(4)]
        lines.append(f"| {r['seed']} | {r['label']} | {r['corner']:.3f} | {r['h']:.1f} | "
                     f"{r['corner'] / exact[r['seed']]:.2f} | {r['sigma']:.5f} | "
                     + " | ".join(mode) + " |")
    lines += ["", READING]
    finish_section(HEADER, lines, clock, args.write)


if __name__ == "__main__":
    main()
