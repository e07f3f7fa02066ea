"""Described robots (Talos: ankle F/T, G1: corner cells): batch speed of the virtual foot
wrenches and of the whole described monitor, compiled inverse dynamics against the
per-sample MuJoCo path (issue 11, must-show 2: >= 300 k samples/s on a 30-joint robot,
kinematics included).

For each robot, on a noisy simulated walk (default noise, seed 1) at 1 kHz:

* ``estimate_wrenches`` (compiled, the default) and ``estimate_wrenches(compiled=False)``
  (per-sample ``mj_kinematics``, ``mj_comPos``, ``mj_comVel``, ``mj_rne``, ``mj_jacSite``,
  ``mj_rnePostConstraint`` from Python: the reference), alternated in one process;
* ``run_described`` (virtual wrenches, then the channel monitor (Talos) or the corner
  monitor with tracking (G1)) with either path;
* the largest difference of their outputs [N, N m].

Figures are process CPU time (``time.process_time``), the best of ``--repeats`` runs (the
reference: of ``--ref-repeats``), samples/s = samples / CPU seconds; the load average is
stated. Kernels are compiled (or loaded from the cache) before timing.

Updates the ``## Described robots: compiled inverse dynamics (issue 11)`` section of
BENCHMARKS.md.

Usage: ``.venv/bin/python benchmarks/bench_described_speed.py [--duration 20]
[--repeats 5] [--ref-repeats 2] [--no-write]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core

import argparse  # noqa: E402
import datetime  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from _common import update_section  # noqa: E402

import grfguard.estimate.wrench as wrench  # noqa: E402
from grfguard.estimate.described import run_described  # noqa: E402
from grfguard.model.description import load_description  # noqa: E402
from grfguard.model.loader import load_model  # noqa: E402
from grfguard.sim.config import NoiseConfig  # noqa: E402
from grfguard.sim.wholebody import scaled_gait, simulate_robot  # noqa: E402

SECTION = "## Described robots: compiled inverse dynamics (issue 11)"
_COMPILED = wrench.estimate_wrenches


#: Analysis written with the figures (kept in the section when the script re-runs).
NOTES = """
Where the time goes (Talos, 20,000 samples, `cProfile` of `estimate_wrenches` and
`run_described` on 2026-11-26 under load 6-11, shares of the profiled time): the compiled
inverse dynamics (`wrench_batch`: kinematics of 60 bodies, `cdof`, velocities,
accelerations, body forces, the sole and F/T wrenches) 39 %; the Savitzky-Golay filters
(101 taps at 1 kHz on 32 joints x 3 derivative orders, the soles, the gyro; scipy's
`correlate1d`) 24 %; the first kinematics pass (`frames_batch`: IMU and soles with the
base at identity) 11 %; the SVD that orthonormalises the leveled attitude 8 %; array
assembly and the rest 18 %. In `run_described`, the Talos channel monitor
(`grfguard.detect.channels.ChannelMonitor.run`, pure Python per sample: 12 channel steps
per sample) takes about as long as the virtual wrenches or longer.

Target (issue 11, must-show 2, second half: batch >= 300 k samples/s on a 30-joint robot,
kinematics included): **not met.** The virtual wrenches went from 5-12 k to 25-45 k
samples/s of CPU time (the figure moves with the load: G1's whole-monitor row coming out
faster than its wrenches alone is that noise); the whole Talos monitor to 13-18 k/s. Left:
(1) the channel monitor compiled (Python per sample today); (2) the Savitzky-Golay filters
(a 101-tap correlation per column and order; an FFT or recursive form, or one compiled
pass computing q, q', q'' together; a plain numba loop tap by tap was tried and ran
1.4-2.6x slower than scipy's `correlate1d`, not vectorised); (3) the inverse dynamics
itself, about 10 µs per sample for Talos's 60 bodies (28 of them welded to their parent:
summing their inertias into the parent's was tried and gained nothing measurable; the
arithmetic is MuJoCo's ~250 flops per body); (4) the leveled attitude's SVD (a closed
form). 300 k/s is 3.3 µs per sample for everything: the kinematics of 60 bodies alone take
about 3 µs.
"""


def _reference(*args, **kwargs):
    return _COMPILED(*args, compiled=False, **kwargs)


def _cpu(fn, repeats: int):
    best, out = float("inf"), None
    for _ in range(repeats):
        c0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - c0)
    return best, out


def _max_diff(a, b) -> float:
    cols = [c for c in a.columns if a[c].dtype.kind == "f" and c in b.columns]
    return max(float(np.nanmax(np.abs(a[c].to_numpy() - b[c].to_numpy()), initial=0.0))
               for c in cols)


def robot_rows(name: str, duration: float, repeats: int, ref_repeats: int) -> list[list[str]]:
    r = load_model(load_description(name))
    df = simulate_robot(r, scaled_gait(r, duration=duration), NoiseConfig(), seed=1)
    n = len(df)
    _COMPILED(df.iloc[:500], r)  # compile / load the kernels
    new_t, new = _cpu(lambda: _COMPILED(df, r), repeats)
    old_t, old = _cpu(lambda: _reference(df, r), ref_repeats)
    d_est = max(float(np.abs(new.ground - old.ground).max()),
                *(float(np.abs(new.sensor[k] - old.sensor[k]).max()) for k in new.sensor))
    run_described(df.iloc[:2000], robot=r)  # warm the monitor's kernels
    mon_t, mon = _cpu(lambda: run_described(df, robot=r), repeats)
    wrench.estimate_wrenches = _reference  # with_described_vfs looks it up at call time
    try:
        mref_t, mref = _cpu(lambda: run_described(df, robot=r), ref_repeats)
    finally:
        wrench.estimate_wrenches = _COMPILED
    d_mon = _max_diff(mon, mref)
    joints = len(r.joint_names)
    rows = []
    for stage, t_new, t_old, diff in (("`estimate_wrenches`", new_t, old_t, d_est),
                                      ("`run_described`, whole", mon_t, mref_t, d_mon)):
        rows.append([name, str(joints), str(r.model.nbody - 1), stage, f"{n}",
                     f"{1e6 * t_old / n:.1f}", f"{1e6 * t_new / n:.2f}",
                     f"{n / t_old / 1e3:.1f} k", f"{n / t_new / 1e3:.0f} k",
                     f"{t_old / t_new:.1f}x", f"{diff:.1e}"])
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0, help="walk length [s]")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--ref-repeats", type=int, default=2)
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    rows = [row for name in ("talos", "g1")
            for row in robot_rows(name, a.duration, a.repeats, a.ref_repeats)]
    load1 = os.getloadavg()[0]
    head = ("| robot | joints | bodies | stage | samples | before: µs/sample (CPU) | "
            "after: µs/sample (CPU) | before: samples/s | after: samples/s | speed-up | "
            "max output difference [N, N m] |\n|---|---|---|---|---|---|---|---|---|---|---|")
    table = "\n".join([head] + ["| " + " | ".join(r) + " |" for r in rows])
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    cmd = "taskset -c 1 .venv/bin/python benchmarks/bench_described_speed.py " + " ".join(
        sys.argv[1:] if argv is None else argv)
    body = (
        f"Command: `{cmd.strip()}` ({now}; {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}; load average {load0:.1f} -> {load1:.1f} on the "
        f"shared 2-core machine: CPU times are the figures, wall times would be inflated). "
        f"Noisy {a.duration:g} s walks at 1 kHz (seed 1). \"Before\": the per-sample MuJoCo "
        "path (`estimate_wrenches(compiled=False)`, kept as the reference); \"after\": "
        "the compiled kinematics and inverse dynamics (`grfguard.kernels.rne`), timed in "
        f"the same process. Best CPU time of {a.repeats} (after) / {a.ref_repeats} (before) "
        "runs.\n\n" + table + "\n" + NOTES)
    print(body)
    if not a.no_write:
        update_section(SECTION, body)


if __name__ == "__main__":
    main()
