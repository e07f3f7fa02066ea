"""Simulation speed: simulated seconds per wall second of a 60 s walk, on one core.

Splits the cost into pattern generation (footsteps, preview control, IK, CoM
corrections), physics (MuJoCo rollout) and log assembly (noise, truth columns), prints
a markdown table and updates the ``## Simulation speed`` section of BENCHMARKS.md.

Usage: ``.venv/bin/python benchmarks/bench_sim.py [--duration 60] [--repeat 3]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from _common import SMALL, reference_us, update_section  # noqa: E402

from grfguard.model.robot import SURALP, RobotConfig  # noqa: E402
from grfguard.sim import GaitConfig, NoiseConfig, simulate  # noqa: E402
from grfguard.sim.pattern import plan_walk  # noqa: E402
from grfguard.sim.simulate import _log_columns, run_physics  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SECTION = "## Simulation speed"


def _best(fn, repeat: int) -> tuple[float, float, object]:
    """Best wall time [s], best CPU time of this process [s], last result."""
    best, best_cpu, out = np.inf, np.inf, None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return best, best_cpu, out


def measure(robot: RobotConfig, gait: GaitConfig, repeat: int) -> dict[str, float]:
    """Best-of-``repeat`` wall times [s] of each stage and of ``simulate`` (+ CPU time)."""
    t_plan, _, plan = _best(lambda: plan_walk(robot, gait), repeat)
    t_phys, _, phys = _best(lambda: run_physics(robot, plan), repeat)
    t_log, _, _ = _best(lambda: _log_columns(robot, plan, phys, NoiseConfig(), 0), repeat)
    t_all, cpu_all, _ = _best(lambda: simulate(robot, gait, NoiseConfig(), seed=0), repeat)
    return {"plan": t_plan, "physics": t_phys, "log": t_log, "total": t_all, "cpu": cpu_all}


def table(rows: list[tuple[str, float, dict[str, float]]]) -> str:
    lines = [
        "| walk | simulated [s] | pattern [s] | physics [s] | log [s] | simulate() [s] "
        "| pattern x RT | physics x RT | total x RT | total x RT (CPU time) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, dur, t in rows:
        lines.append(
            f"| {name} | {dur:.0f} | {t['plan']:.2f} | {t['physics']:.2f} | {t['log']:.2f} "
            f"| {t['total']:.2f} | {dur / t['plan']:.0f} | {dur / t['physics']:.0f} "
            f"| **{dur / t['total']:.1f}** | {dur / t['cpu']:.1f} |"
        )
    return "\n".join(lines)


def update_benchmarks_md(body: str, path: Path = ROOT / "BENCHMARKS.md") -> None:
    """Replace (or append) only this script's section of ``path``."""
    update_section(SECTION, body, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0, help="walk length [s]")
    ap.add_argument("--repeat", type=int, default=3, help="best of N runs")
    ap.add_argument("--no-write", action="store_true", help="do not touch BENCHMARKS.md")
    ap.add_argument("--write", action="store_true",
                    help="update BENCHMARKS.md (the default; for `make bench`)")
    args = ap.parse_args()
    d = args.duration
    walks = [
        ("SURALP 0.12 m / 1.0 s (default)", SURALP, GaitConfig(duration=d)),
        ("SURALP 0.15 m / 0.8 s", SURALP, GaitConfig(step_length=0.15, step_period=0.8,
                                                    duration=d)),
        ("small robot 60 kg, 0.12 m / 1.0 s", SMALL, GaitConfig(duration=d)),
    ]
    plan_walk(SURALP, GaitConfig(duration=2.0))  # warm up caches (model build, imports)
    ref0 = reference_us()
    rows = [(name, d, measure(robot, gait, args.repeat)) for name, robot, gait in walks]
    ref1 = reference_us()
    md = table(rows)
    cpu = platform.processor() or platform.machine()
    body = (
        f"`{Path(__file__).relative_to(ROOT)}` (best of {args.repeat}, one thread, "
        f"MuJoCo {mujoco.__version__}, numpy {np.__version__}, {cpu}, "
        f"{os.cpu_count()} logical CPUs, load average {os.getloadavg()[0]:.1f} at the end: "
        "other jobs share the cores, so treat a high load as a lower bound). "
        "x RT = simulated seconds per wall second; pattern = footsteps + two-stage ZMP "
        "preview control + leg IK + CoM corrections + inverse-dynamics feed-forward; "
        "physics = `mujoco.rollout` at 1 ms in 1 s chunks with fall checks; "
        "log = noise + truth columns; CPU time = `time.process_time` of this (single-"
        "threaded) process, the load-independent figure. Goal: >= 10x real time (issue 11: "
        ">= 30x for SURALP). The machine's speed in the same run (`np.sort` of 10^6 floats, "
        f"best of 5, before / after the walks): {ref0 / 1e3:.1f} / {ref1 / 1e3:.1f} ms.\n\n" + md
    )
    print(md)
    if not args.no_write:
        update_benchmarks_md(body)
        print(f"updated {ROOT / 'BENCHMARKS.md'} ({SECTION})")


if __name__ == "__main__":
    main()
