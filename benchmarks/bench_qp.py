"""Benchmark of the corner-force QPs: grfguard's exact solvers against daqp.

Measures, on walking-like data (seeded):

* :func:`grfguard.estimate.corner_qp.solve_corner_qp`, the paper split's per-foot QP
  (n = 4, fixed sole points: the tabulated path) and the rigid 8-corner split (per-sample
  world points relative to the ZMP, contact masks: the enumeration path), ns per sample in
  batch and µs per one-sample call (what streaming pays);
* :func:`grfguard.estimate.compliance.solve_with_prior`, the default split (8 corners,
  sole-compliance prior, NNLS with a penalty row), µs per sample;
* the same QPs solved by daqp directly (``daqp.solve``, MIT; dev dependency) and through
  qpsolvers, µs per solve, and the largest force difference to grfguard.

Data: 20 % unloaded feet (swing), CoP uniform over the sensor rectangle, 10 % up to 2 cm
outside it; the 8-corner problems are single support (80 %) or double support (20 %).

Run: ``.venv/bin/python benchmarks/bench_qp.py [--samples 100000] [--write]``;
``--write`` replaces the ``## Contact-point QP`` section of ``BENCHMARKS.md``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
from _common import BENCHMARKS_MD, update_section

from grfguard.estimate.compliance import compliance_prior, solve_with_prior
from grfguard.estimate.corner_qp import solve_corner_qp
from grfguard.model.robot import SURALP

SECTION = "## Contact-point QP"
W_PAPER, W_DEFAULT = 1e-2, 1e-6  # [m²]


def problems(rng: np.random.Generator, T: int):
    """Per-foot (n = 4) and two-feet (n = 8) problems as a walking log would give them."""
    sole = SURALP.sensor_positions_in_foot()
    lo, hi = sole.min(axis=0), sole.max(axis=0)
    fz = rng.uniform(50.0, 1100.0, T)
    fz[rng.uniform(size=T) < 0.2] = 0.0
    cop = rng.uniform(lo, hi, (T, 2))
    out = rng.uniform(size=T) < 0.1
    cop[out] = rng.uniform(lo - 0.02, hi + 0.02, (int(out.sum()), 2))
    feet = np.concatenate([sole + [0.0, -0.1], sole + [0.12, 0.1]])  # (8, 2) world [m]
    zmp = rng.uniform([-0.05, -0.12], [0.17, 0.12], (T, 2))
    rel = feet[None] - zmp[:, None, :]
    contact = np.ones((T, 8), bool)
    ss = rng.uniform(size=T) < 0.8
    right = rng.uniform(size=T) < 0.5
    contact[ss & right, 4:] = False
    contact[ss & ~right, :4] = False
    total = rng.uniform(800.0, 1300.0, T)
    return sole, fz, np.maximum(fz, 0.0)[:, None] * cop, rel, contact, total


def best_of(fn, repeat: int) -> tuple[float, float]:
    """Smallest wall and process CPU time of ``repeat`` calls [s]."""
    best = best_cpu = np.inf
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return best, best_cpu


def per_call(fn, K: int, repeat: int) -> tuple[float, float]:
    """Wall and CPU time per call of ``fn(i)``, i < K [s]."""
    t, c = best_of(lambda: [fn(i) for i in range(K)], repeat)
    return t / K, c / K


def _daqp(p: np.ndarray, d: np.ndarray, b: float, w: float, allowed: np.ndarray | None):
    import daqp

    n = p.shape[0]
    H = 2.0 * (p @ p.T + w * np.eye(n))
    ub = np.append(np.full(n, 1e30) if allowed is None else np.where(allowed, 1e30, 0.0), b)
    lb = np.append(np.zeros(n), b)
    sense = np.append(np.zeros(n, np.int32), 5).astype(np.int32)
    x, _, flag, _ = daqp.solve(H, -2.0 * p @ d, np.ones((1, n)), ub, lb, sense)
    return x if flag == 1 else np.full(n, np.nan)


def _qpsolvers(p: np.ndarray, d: np.ndarray, b: float, w: float, allowed: np.ndarray | None):
    import qpsolvers

    n = p.shape[0]
    ub = None if allowed is None else np.where(allowed, np.inf, 0.0)
    return qpsolvers.solve_qp(2.0 * (p @ p.T + w * np.eye(n)), -2.0 * p @ d,
                              A=np.ones((1, n)), b=np.array([b]), lb=np.zeros(n), ub=ub,
                              solver="daqp")


def measure(T: int, K: int, repeat: int, seed: int) -> list[tuple[str, str, str, str]]:
    sole, fz, d4, rel, contact, total = problems(np.random.default_rng(seed), T)
    z8 = np.zeros((T, 2))
    rows = []
    cases = (
        ("n=4, paper split (fixed sole, W=0.01)", sole, d4, fz, W_PAPER, None),
        ("n=8, rigid split (per-sample points, contact)", rel, z8, total, W_DEFAULT, contact),
    )
    for label, p, d, b, w, ok in cases:
        t, c = best_of(lambda p=p, d=d, b=b, w=w, ok=ok: solve_corner_qp(p, d, b, w, ok), repeat)
        rows.append(("batch `solve_corner_qp`", label,
                     f"{t / T * 1e9:.0f} / {c / T * 1e9:.0f} ns/sample", f"{T} samples"))
        fixed = p.ndim == 2
        ours = solve_corner_qp(p, d, b, w, ok)

        def one(i, p=p, d=d, b=b, w=w, ok=ok, fixed=fixed):
            return solve_corner_qp(p if fixed else p[i : i + 1], d[i : i + 1], b[i : i + 1], w,
                                   None if ok is None else ok[i : i + 1])

        t, c = per_call(one, K, repeat)
        diff = max(np.abs(one(i)[0] - ours[i]).max() for i in range(K))
        rows.append(("one sample `solve_corner_qp`", label,
                     f"{t * 1e6:.1f} / {c * 1e6:.1f} µs/solve", f"max diff to batch {diff:.1e} N"))
        for name, fn in (("daqp.solve", _daqp), ("qpsolvers + daqp", _qpsolvers)):
            def call(i, p=p, d=d, b=b, w=w, ok=ok, fixed=fixed, fn=fn):
                return fn(p if fixed else p[i], d[i], max(b[i], 0.0), w,
                          None if ok is None else ok[i])

            t, c = per_call(call, K, repeat)
            ref = np.array([call(i) if b[i] > 0 else np.zeros(p.shape[-2]) for i in range(K)])
            rows.append((name, label, f"{t * 1e6:.1f} / {c * 1e6:.1f} µs/solve",
                         f"max diff to grfguard {np.nanmax(np.abs(ref - ours[:K])):.1e} N"))
    prior = [compliance_prior(np.zeros(8), contact[i], total[i], 4.2e3 * 100) for i in range(K)]
    t, c = per_call(lambda i: solve_with_prior(rel[i], prior[i], total[i], W_DEFAULT, contact[i]),
                    K, repeat)
    rows.append(("one sample `solve_with_prior` (default split)", "n=8, compliance prior",
                 f"{t * 1e6:.1f} / {c * 1e6:.1f} µs/solve", "NNLS + penalty row, then rescaled"))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=100_000)
    ap.add_argument("--calls", type=int, default=2000, help="one-sample calls timed")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    rows = measure(args.samples, args.calls, args.repeat, args.seed)
    share = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
    env = (f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, load average "
           f"{os.getloadavg()[0]:.1f}, this process got {share:.0%} of a CPU, numpy "
           f"{np.__version__}")
    table = ["| solver | problem | time (wall / CPU) | notes |", "|---|---|---|---|"]
    table += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows]
    text = "\n".join([
        SECTION, "",
        f"`.venv/bin/python benchmarks/bench_qp.py --samples {args.samples} --write` "
        f"(seed {args.seed}; {env}). Walking-like data: 20 % unloaded feet, CoP over the "
        "sensor rectangle and up to 2 cm outside it; 8-corner problems 80 % single support. "
        "Compare rows within one run (other sessions share the machine).", "",
        *table, "",
    ])
    print(text)
    if args.write:
        update_section(SECTION, text)
        print(f"wrote {BENCHMARKS_MD}")


if __name__ == "__main__":
    main()
