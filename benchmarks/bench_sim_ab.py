"""Simulation speed of two source trees in one process, alternated (issue 11, must-show 5).

This machine's speed moves by a third within minutes, so a change to the simulator is
judged by running both trees side by side: the other tree's ``src/grfguard`` is copied as
``grfguard_before`` (``_common.renamed_copy``), and each round plans and simulates the same
60 s walk with both (order alternating), in CPU time of this one process. Every round also
checks that the two logs are equal bit for bit.

Usage: ``taskset -c 1 .venv/bin/python benchmarks/bench_sim_ab.py <before>/src [--rounds 6]``
(``<before>``: e.g. ``git archive <commit> src | tar -x -C <before>``).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core

import argparse  # noqa: E402
import importlib  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _common import reference_us, renamed_copy  # noqa: E402

BEFORE = "grfguard_before"


def _tree(package: str):
    sim = importlib.import_module(f"{package}.sim")
    pattern = importlib.import_module(f"{package}.sim.pattern")
    robot = importlib.import_module(f"{package}.model.robot")
    return sim, pattern, robot.SURALP


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path, help="the other tree's src directory")
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--duration", type=float, default=60.0, help="walk length [s]")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="sim_ab_"))
    renamed_copy(args.before, BEFORE, work)
    sys.path.insert(0, str(work))
    trees = {"before": _tree(BEFORE), "after": _tree("grfguard")}
    times: dict[str, dict[str, list[float]]] = {k: {"plan": [], "sim": []} for k in trees}
    print(f"reference (np.sort of 10^6 floats): {reference_us() / 1e3:.1f} ms")
    for r in range(args.rounds):
        logs = {}
        for name in list(trees)[:: 1 if r % 2 == 0 else -1]:
            sim, pattern, robot = trees[name]
            gait = sim.GaitConfig(duration=args.duration)
            c = time.process_time()
            pattern.plan_walk(robot, gait)
            times[name]["plan"].append(time.process_time() - c)
            c = time.process_time()
            logs[name] = sim.simulate(robot, gait, sim.NoiseConfig(), seed=0)
            times[name]["sim"].append(time.process_time() - c)
        a, b = logs["before"], logs["after"]
        same = list(a.columns) == list(b.columns) and all(
            np.array_equal(a[c].to_numpy(), b[c].to_numpy(), equal_nan=True) for c in a.columns)
        print(f"round {r}: " + " | ".join(
            f"{k} plan {times[k]['plan'][-1]:.3f} s, simulate {times[k]['sim'][-1]:.3f} s"
            for k in trees) + f" | logs equal bit for bit: {same}", flush=True)
    print(f"reference (np.sort of 10^6 floats): {reference_us() / 1e3:.1f} ms")
    d = args.duration
    for stage in ("plan", "sim"):
        b, n = np.array(times["before"][stage]), np.array(times["after"][stage])
        print(f"{stage}: before min {b.min():.3f} / median {np.median(b):.3f} s; after min "
              f"{n.min():.3f} / median {np.median(n):.3f} s; median of round ratios "
              f"{np.median(n / b):.3f}"
              + (f"; x real time (CPU) at the minima {d / b.min():.1f} -> {d / n.min():.1f}"
                 if stage == "sim" else ""))


if __name__ == "__main__":
    main()
