"""Benchmark of the contact-point force distribution QP (grfguard.estimate.distribute).

Measures:

* the exact batch solver, ns per sample at 1e6 samples: one foot (n = 4, fixed sole
  points: table path; per-sample points: active-set path), two feet (n = 8, per-foot
  sums, fixed points; total only, per-sample world points);
* the per-sample solvers, µs per solve: :class:`DistributionSolver` (fixed points,
  plain Python floats) and :func:`solve_distribution_one` (any points);
* the same problems through qpsolvers with quadprog and daqp (dev dependencies; quadprog
  is GPL and never a runtime dependency), plus the largest force difference to them.

Data: walking-like samples (seeded): 20 % unloaded (swing), CoP uniform over the sensor
rectangle for 70 %, and within 2 cm outside it for the other 10 %.

Run: ``.venv/bin/python benchmarks/bench_qp.py [--samples 1000000] [--write]``;
``--write`` replaces the ``## Contact-point QP`` section of ``BENCHMARKS.md``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np
from _common import BENCHMARKS_MD, update_section

from grfguard.estimate.distribute import (
    DEFAULT_WEIGHT,
    DistributionSolver,
    solve_distribution_batch,
    solve_distribution_one,
    two_feet_equality,
)
from grfguard.model.robot import SURALP

ROOT = Path(__file__).resolve().parents[1]
SECTION = "## Contact-point QP"


def walking_like(rng: np.random.Generator, T: int, sole: np.ndarray):
    """Foot loads [N] and CoPs [m] in the sole frame, as a walking log would give."""
    lo, hi = sole.min(axis=0), sole.max(axis=0)
    fz = rng.uniform(50.0, 1100.0, T)
    fz[rng.uniform(size=T) < 0.2] = 0.0
    cop = rng.uniform(lo, hi, (T, 2))
    out = rng.uniform(size=T) < 0.1
    cop[out] = rng.uniform(lo - 0.02, hi + 0.02, (int(out.sum()), 2))
    return fz, cop


def best_of(fn, repeat: int) -> tuple[float, float]:
    """Smallest wall time and smallest process CPU time of ``repeat`` calls [s]."""
    best, best_cpu = np.inf, np.inf
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return best, best_cpu


def per_call(fn, calls: int, repeat: int) -> tuple[float, float]:
    """Median over ``repeat`` rounds of the mean wall and CPU time per call [s]."""
    times, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        for i in range(calls):
            fn(i)
        times.append((time.perf_counter() - t0) / calls)
        cpu.append((time.process_time() - c0) / calls)
    return float(np.median(times)), float(np.median(cpu))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--calls", type=int, default=3000, help="per-sample solves per round")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--write", action="store_true", help="update BENCHMARKS.md")
    args = ap.parse_args()

    rng = np.random.default_rng(args.seed)
    T = args.samples
    wall0, cpu0 = time.perf_counter(), time.process_time()
    sole = SURALP.sensor_positions_in_foot()
    w = DEFAULT_WEIGHT
    rows: list[tuple[str, str, str, str]] = []

    # ---------------------------------------------------------------- problems
    fz, cop = walking_like(rng, T, sole)
    d1 = fz[:, None] * cop
    pts1_var = np.broadcast_to(sole, (T, 4, 2)) + rng.normal(0.0, 0.002, (T, 4, 2))
    right, left = sole + [0.0, -0.1], sole + [0.06, 0.1]
    pts2 = np.concatenate([right, left])
    G2 = two_feet_equality()
    b2 = np.stack([fz, rng.uniform(0.0, 1100.0, T)], axis=1)
    b2[rng.uniform(size=T) < 0.3, 1] = 0.0
    zmp = rng.uniform(pts2.min(axis=0) - 0.01, pts2.max(axis=0) + 0.01, (T, 2))
    d2 = b2.sum(axis=1)[:, None] * zmp
    drift = rng.normal(0.0, 0.01, (T, 1, 2))
    pts2_var = np.concatenate(
        [np.broadcast_to(right, (T, 4, 2)), np.broadcast_to(left, (T, 4, 2)) + drift], axis=1
    )
    ftot = b2.sum(axis=1)

    cases = {
        "n=4, fixed sole points (table path)": (sole, d1, fz, None),
        "n=4, per-sample points (active-set path)": (pts1_var, d1, fz, None),
        "n=8, two feet, per-foot sums, fixed points": (pts2, d2, b2, G2),
        "n=8, two feet, total only, per-sample points": (pts2_var, d2, ftot, None),
    }
    sols = {}
    for name, (p, d, b, G) in cases.items():
        t, c = best_of(
            lambda p=p, d=d, b=b, G=G: solve_distribution_batch(p, d, b, w, G), args.repeat
        )
        sols[name] = solve_distribution_batch(p, d, b, w, G)
        fb = int(np.sum(sols[name].iterations == -1))
        rows.append(
            (
                "batch `solve_distribution_batch`",
                name,
                f"{t / T * 1e9:.0f} / {c / T * 1e9:.0f} ns/sample",
                f"{T:.0e} samples, best of {args.repeat}; {fb} enumeration fallbacks",
            )
        )
        print(rows[-1])

    # ---------------------------------------------------------------- per sample
    K = min(args.calls, T)
    solver4 = DistributionSolver(sole, w)
    r4 = [(float(d1[i, 0]), float(d1[i, 1]), float(fz[i])) for i in range(K)]
    t, c = per_call(lambda i: solver4.solve(*r4[i]), K, args.repeat)
    stream4 = np.array([solver4.solve(*r4[i]) for i in range(K)])
    diff = np.abs(stream4 - sols[list(cases)[0]].forces[:K]).max()
    rows.append(
        (
            "streaming `DistributionSolver.solve`",
            "n=4, fixed sole points",
            f"{t * 1e6:.1f} / {c * 1e6:.1f} µs/solve",
            f"max diff to batch {diff:.1e} N",
        )
    )
    print(rows[-1])
    solver8 = DistributionSolver(pts2, w, G2)
    r8 = [(float(d2[i, 0]), float(d2[i, 1]), (float(b2[i, 0]), float(b2[i, 1]))) for i in range(K)]
    t, c = per_call(lambda i: solver8.solve(*r8[i]), K, args.repeat)
    stream8 = np.array([solver8.solve(*r8[i]) for i in range(K)])
    diff = np.abs(stream8 - sols[list(cases)[2]].forces[:K]).max()
    rows.append(
        (
            "streaming `DistributionSolver.solve`",
            "n=8, two feet, per-foot sums",
            f"{t * 1e6:.1f} / {c * 1e6:.1f} µs/solve",
            f"max diff to batch {diff:.1e} N",
        )
    )
    print(rows[-1])
    K1 = min(K, 1000)
    t, c = per_call(lambda i: solve_distribution_one(pts1_var[i], d1[i], fz[i], w), K1, args.repeat)
    rows.append(
        (
            "one sample `solve_distribution_one`",
            "n=4, any points",
            f"{t * 1e6:.1f} / {c * 1e6:.1f} µs/solve",
            "active set in plain floats, final solve in longdouble",
        )
    )
    print(rows[-1])

    # ---------------------------------------------------------------- qpsolvers
    try:
        import qpsolvers
    except ImportError:  # pragma: no cover - dev dependency
        qpsolvers = None
    if qpsolvers is not None:
        for solver_name in ("quadprog", "daqp"):
            if solver_name not in qpsolvers.available_solvers:
                continue
            for label, p, d, b, G, ref_name in (
                ("n=4, fixed sole points", sole, d1, fz[:, None], np.ones((1, 4)), list(cases)[0]),
                ("n=8, two feet, per-foot sums", pts2, d2, b2, G2, list(cases)[2]),
            ):
                n = p.shape[0]
                P = 2.0 * (p @ p.T + w * np.eye(n))
                lb = np.zeros(n)

                def call(i, P=P, p=p, d=d, b=b, G=G, lb=lb, s=solver_name):
                    return qpsolvers.solve_qp(
                        P, -2.0 * p @ d[i], A=G, b=np.maximum(b[i], 0.0), lb=lb, solver=s
                    )

                t, c = per_call(call, K, args.repeat)
                ref = [call(i) for i in range(K)]
                failed = sum(r is None for r in ref)
                ref = np.array([np.full(n, np.nan) if r is None else r for r in ref])
                diff = np.nanmax(np.abs(ref - sols[ref_name].forces[:K]))
                rows.append(
                    (
                        f"qpsolvers + {solver_name}",
                        label,
                        f"{t * 1e6:.1f} / {c * 1e6:.1f} µs/solve",
                        f"max diff to grfguard {diff:.1e} N; {failed} of {K} failed",
                    )
                )
                print(rows[-1])

    load = os.getloadavg()
    share = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
    env = (
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"load average {load[0]:.1f}, this process got {share:.0%} of a CPU over the run, "
        f"numpy {np.__version__}"
    )
    table = ["| solver | problem | time (wall / CPU) | notes |", "|---|---|---|---|"]
    table += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows]
    text = "\n".join(
        [
            SECTION,
            "",
            f"`.venv/bin/python benchmarks/bench_qp.py --samples {T} --write` "
            f"(seed {args.seed}, w = {w} m²; {env}).",
            "Walking-like data: 20 % unloaded, CoP uniform over the sensor rectangle, 10 % up to "
            "2 cm outside it. Batch times include validation, NaN handling and the KKT "
            "diagnostics. Times scale with the CPU share above (other sessions share the "
            "machine); compare rows within one run.",
            "",
            *table,
            "",
        ]
    )
    print(text)
    if args.write:
        update_section(SECTION, text)
        print(f"wrote {BENCHMARKS_MD}")


if __name__ == "__main__":
    main()
