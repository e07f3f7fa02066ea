"""Described robots (Talos, G1) beside SURALP: 60 s walks and virtual foot wrenches.

1. Walks (``grfguard simulate --robot NAME`` on the scaled default gait, default noise):
   joints, mass, gait, wall time (model loading included) and real-time factor, mean
   vertical contact force / m g, largest trunk tilt, distance walked.
2. Virtual foot wrenches (:func:`grfguard.estimate.wrench.estimate_wrenches`) against the
   simulated truth in single support, on clean and noisy (default noise) logs at 1 kHz,
   200 Hz and 100 Hz: per-foot vertical force [% m g], worst corner [% m g] (G1), ankle
   F/T force [% m g] and torque [% m g x foot length] (Talos).

Updates the ``## Robots from URDF (Talos, G1)`` section of BENCHMARKS.md.

Usage: ``.venv/bin/python benchmarks/bench_robots.py [--duration 60] [--wrench-duration 20]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

from _common import update_section  # noqa: E402

from grfguard.estimate.wrench import estimate_wrenches, evaluate_wrenches  # noqa: E402
from grfguard.model.description import load_description  # noqa: E402
from grfguard.model.loader import load_model  # noqa: E402
from grfguard.sim import GaitConfig, NoiseConfig, simulate  # noqa: E402
from grfguard.sim.wholebody import decimate, scaled_gait, simulate_robot  # noqa: E402

SECTION = "## Robots from URDF (Talos, G1)"
ALL_ROWS: list[list[str]] = []


def walk_row(name: str, duration: float) -> list[str]:
    t0, c0 = time.perf_counter(), time.process_time()
    if name == "suralp":
        from grfguard.model.robot import SURALP

        df = simulate(SURALP, GaitConfig(duration=duration), NoiseConfig(), seed=0)
        fz = df[[c for c in df.columns if c.startswith("true_force_")]].sum(axis=1)
        mass, joints, gait = SURALP.mass, 12, df.attrs["gait"]
    else:
        r = load_model(load_description(name))
        df = simulate_robot(r, scaled_gait(r, duration=duration), NoiseConfig(), seed=0)
        fz = df["true_grf_r_z"] + df["true_grf_l_z"]
        mass, joints, gait = r.mass, len(r.joint_names), df.attrs["gait"]
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    ratio = fz.mean() / (mass * 9.81)
    return [name, str(joints), f"{mass:.2f}", f"{gait['step_length']:.3f}",
            f"{gait['step_period']:.3f}", f"{wall:.1f}", f"{duration / wall:.1f}",
            f"{cpu:.1f}", f"{duration / cpu:.1f}",
            f"{ratio:.6f}", f"{df['true_trunk_tilt'].max():.2f}",
            f"{df['true_com_x'].iloc[-1]:.2f}"]


def wrench_rows(name: str, duration: float) -> list[list[str]]:
    r = load_model(load_description(name))
    rows = []
    for label, noise in (("clean", NoiseConfig.none()), ("noisy", NoiseConfig())):
        df = simulate_robot(r, scaled_gait(r, duration=duration), noise, seed=1)
        for rate in (1000, 200, 100):
            d = df if rate == 1000 else decimate(df, rate)
            t0 = time.perf_counter()
            est = estimate_wrenches(d, r)
            el = time.perf_counter() - t0
            acc = evaluate_wrenches(d, est, r)
            al = evaluate_wrenches(d, est, r, phase="all")
            extra = (f"{acc['corner']:.2f}" if "corner" in acc else "-")
            ft = ([f"{acc['ft_fz']:.3f}", f"{max(acc['ft_fx'], acc['ft_fy']):.3f}",
                   f"{acc['ft_tx']:.3f}", f"{acc['ft_ty']:.3f}", f"{acc['ft_tz']:.3f}"]
                  if "ft_fz" in acc else ["-"] * 5)
            rows.append([name, label, str(rate), f"{acc['foot_fz']:.3f}", extra, *ft,
                         f"{len(d) / el:.0f}"])
            ALL_ROWS.append([name, label, str(rate), f"{al['foot_fz']:.3f}",
                             f"{al['corner']:.2f}" if "corner" in al else "-",
                             f"{al['ft_fz']:.3f}" if "ft_fz" in al else "-",
                             f"{max(al['ft_tx'], al['ft_ty']):.3f}" if "ft_tx" in al else "-"])
            print(rows[-1], flush=True)
    return rows


def table(header: list[str], rows: list[list[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--wrench-duration", type=float, default=20.0)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    walks = []
    for name in ("suralp", "talos", "g1"):
        walks.append(walk_row(name, args.duration))
        print(walks[-1], flush=True)
    wr = wrench_rows("talos", args.wrench_duration) + wrench_rows("g1", args.wrench_duration)
    body = "\n\n".join([
        f"Command: `.venv/bin/python benchmarks/bench_robots.py --duration {args.duration:g} "
        f"--wrench-duration {args.wrench_duration:g}` ({platform.processor() or 'cpu'}, "
        "one core; the machine is shared by other jobs: wall times are upper bounds, CPU "
        "times of this process are the fairer measure).",
        f"Walks of {args.duration:g} s, default noise, seed 0, the default gait scaled to "
        "each robot (step 0.12 m x L / 0.674 m, period 1 s x sqrt(L / 0.674 m), L = hip to "
        "sole). Wall time includes loading the URDF.",
        table(["robot", "joints", "mass [kg]", "step [m]", "period [s]", "wall [s]",
               "x real time", "CPU [s]",
               "x real time (CPU)", "mean Fz / m g", "max tilt [deg]", "walked [m]"], walks),
        f"Virtual foot wrenches (`estimate_wrenches`, window 0.1 s) on {args.wrench_duration:g}"
        " s walks (seed 1), RMSE in single support (true contact, 50 ms from any contact "
        "change): foot Fz and corners in % of m g; F/T forces in % of m g, torques in % of "
        "m g x foot length.",
        table(["robot", "log", "rate [Hz]", "foot Fz [%]", "worst corner [%]", "F/T fz [%]",
               "F/T fx,fy [%]", "F/T tx [%]", "F/T ty [%]", "F/T tz [%]", "samples/s"], wr),
        "The same estimates over every sample after 0.5 s, both feet (double support, "
        "swing and contact changes included): what a monitor's residual sees. For the "
        "paper's scenario transposed, a fault of 9 % of m g is to be detected.",
        table(["robot", "log", "rate [Hz]", "foot Fz [%]", "worst corner [%]", "F/T fz [%]",
               "F/T tx, ty [%]"], ALL_ROWS),
    ])
    print(body)
    if not args.no_write:
        update_section(SECTION, body)


if __name__ == "__main__":
    main()
