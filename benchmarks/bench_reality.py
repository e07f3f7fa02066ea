"""Reality gap benchmark (issue 10): false alarms before/after self-calibration, and the
estimated vs true model corrections, for every shipped gap (``grfguard/data/reality``).

For each gap: a calibration walk (seed 1) and an evaluation walk (seed 2) of the same
robot (same gap draw), ``--duration`` s each. "Before": the Monitor (default thresholds)
on the evaluation walk with the nominal model; the CommonModeMonitor status
(``model_mismatch``, share of the loaded time) on the same virtual forces. "After":
corrections fitted on the calibration walk, applied to the evaluation walk.

Usage: ``python benchmarks/bench_reality.py [--duration 30] [--write]``; ``--write``
replaces the ``## Reality gap`` section at the end of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from grfguard.calib import apply_corrections, estimate_corrections
from grfguard.detect import Monitor
from grfguard.detect.system import CommonModeMonitor
from grfguard.model.robot import SENSOR_NAMES, RobotConfig
from grfguard.sim import simulate
from grfguard.sim.config import GaitConfig
from grfguard.sim.reality import REALITY_FILES, load_reality

HEADER = "## Reality gap"


def flagged(out) -> list[str]:
    return [s for s in SENSOR_NAMES if out[f"flag_{s}"].any()]


def mismatch_share(out, robot: RobotConfig) -> tuple[float, str]:
    cm = CommonModeMonitor(robot, 0.005)
    x = out[[f"force_{s}" for s in SENSOR_NAMES]].to_numpy(float)
    v = out[[f"vfs_{s}" for s in SENSOR_NAMES]].to_numpy(float)
    c = out[["contact_ref_r", "contact_ref_l"]].to_numpy(float) > 0.5
    n, reason = 0, ""
    for k in range(0, len(x), 5):  # every 5th sample (fit time constant 10 s)
        r = cm.update(x[k], v[k], c[k])
        n += r.model_mismatch
        reason = r.reason or reason
    return n / max(1, len(range(0, len(x), 5))), reason


def errors(corr, truth: dict, nominal: RobotConfig) -> dict[str, float]:
    """``bench_selfcal.errors`` plus the worst gyro-bias error [rad/s]."""
    from bench_selfcal import errors as calibration_errors

    return {**calibration_errors(corr, truth, nominal),
            "gyro": float(np.max(np.abs(np.array(corr.gyro_bias_rad_s)
                                        - np.array(truth["gyro_bias_rad_s"]))))}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--gaps", nargs="*", default=list(REALITY_FILES))
    args = ap.parse_args()
    gait = GaitConfig(duration=args.duration)
    nominal = RobotConfig()
    rows = []
    t0 = time.perf_counter()
    for name in args.gaps:
        gap = load_reality(name)
        cal = simulate(gait=gait, seed=1, reality=gap)
        ev = simulate(gait=gait, seed=2, reality=gap)
        before = Monitor.for_log(ev).run(ev)
        share, reason = mismatch_share(before, nominal)
        corr = estimate_corrections(cal)
        evc = apply_corrections(ev, corr)
        after = Monitor.for_log(evc).run(evc)
        e = errors(corr, ev.attrs["reality"], nominal)
        rows.append((name, flagged(before), share, reason, flagged(after), e))
        print(name, rows[-1], f"{time.perf_counter() - t0:.0f} s", flush=True)
    lines = [
        HEADER,
        "",
        f"`python benchmarks/bench_reality.py --duration {args.duration:g} --write` "
        f"({args.duration:g} s walks: calibration seed 1, evaluation seed 2, same robot; "
        "default thresholds; gap files in `grfguard/data/reality/`). *Flagged* lists the "
        "healthy sensors flagged at least once on the fault-free evaluation walk; "
        "*mismatch* is the share of time `CommonModeMonitor` raises `model_mismatch` "
        "(last reason). Errors: estimated minus true (IMU roll/pitch, trunk CoM x/y, "
        "zeros: worst; gains: worst deviation relative to the mean; weight: fitted mass "
        "vs true mass x mean gain).",
        "",
        "| gap | flagged before | mismatch | reason | flagged after calib | IMU err [deg] "
        "| CoM err [cm] | zero err [N] | rel. gain err [%] | weight err [%] | gyro err [rad/s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, fb, share, reason, fa, e in rows:
        lines.append(
            f"| {name} | {len(fb)} {' '.join(fb)} | {100 * share:.0f} % | {reason or '-'} | "
            f"{len(fa)} {' '.join(fa)} | {e['imu_deg']:.2f} | {e['com_cm']:.2f} | "
            f"{e['zero_n']:.2f} | {e['gain_pct']:.2f} | {e['weight_pct']:+.2f} | "
            f"{e['gyro']:.4f} |"
        )
    lines.append("")
    lines.append(f"Runtime {time.perf_counter() - t0:.0f} s on the shared 2-core machine.")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.write:
        p = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"
        old = p.read_text()
        if HEADER in old:
            old = old[: old.index(HEADER)].rstrip() + "\n"
        p.write_text(old.rstrip() + "\n\n" + text)


if __name__ == "__main__":
    main()
