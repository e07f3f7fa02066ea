"""Batch throughput of the monitor, stage by stage (issue 11, must-show 2, first half).

SURALP (60 s paper-scenario walk, default settings, VFS inside) and Talos (32 joints,
ankle F/T, 20 s walk): ``Monitor.run`` / ``run_described`` end to end (kinematics
included, DataFrame in and out) and each stage timed alone on the same log's arrays:

* SURALP: the compiled virtual force sensor alone (``vfs_run`` over the (T, 24) inputs),
  the whole compiled monitor loop (``MonitorKernel.run``: guards, VFS, detector,
  recovery, standing layer) and the rest of ``Monitor.run`` (columns in, output frame);
  and ``Monitor.run`` with the optional layers off (:data:`LAYERS`: the standing layer,
  the system layer, both), what each layer costs;
* Talos: the virtual wrenches (``estimate_wrenches``: MuJoCo kinematics and inverse
  dynamics per sample, called from Python) and the channel monitor
  (``ChannelMonitor.run``).

Timing: every SURALP figure over the whole log, best process CPU time
(``time.process_time``) and wall time of five runs alternated with one another (each
round runs every one once: this machine's slow and fast phases fall on all of them
alike); the compiled stages write into output arrays reused from run to run, as
``Monitor.run``'s blocks are, so that none of them pays for fresh memory's page faults.
(Until session 39 the compiled stages were the minimum over 2,000-sample slices started
from a reset monitor: the cheapest stretch of the walk, with no sensor flagged yet,
0.88 against 0.97-1.04 µs per sample for the whole paper run.) Talos: best of a few
whole runs. A
plain reference (``numpy.sort`` of 10^6 floats) is timed in the same run so that figures
from differently loaded runs can be compared (``ratio`` columns). Pin it to one core::

    taskset -c 1 .venv/bin/python benchmarks/bench_batch_stages.py

Used by ``bench_compiled_monitor.py`` (``make bench``), which puts the table into
BENCHMARKS.md.
"""

from __future__ import annotations

import sys
import time
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import reference_us  # noqa: E402


def _whole(fn: Any, n: int, reps: int) -> tuple[float, float]:
    """(best wall, best CPU) µs/sample of ``fn()`` over ``reps`` runs."""
    return _alternated({"": fn}, n, reps)[""]


def _alternated(fns: dict[str, Any], n: int, reps: int) -> dict[str, tuple[float, float]]:
    """:func:`_whole` of each of ``fns``, their runs alternated (each round runs every
    one once: this machine's slow and fast phases fall on all of them alike)."""
    best = {k: (float("inf"), float("inf")) for k in fns}
    for _ in range(reps):
        for k, fn in fns.items():
            t0, c0 = time.perf_counter(), time.process_time()
            fn()
            w, c = (time.perf_counter() - t0) / n * 1e6, (time.process_time() - c0) / n * 1e6
            best[k] = (min(best[k][0], w), min(best[k][1], c))
    return best


#: ``Monitor.for_log`` switches of the layer rows (key: what is off).
LAYERS = {"standing": {"standing": False}, "system": {"common_mode": False},
          "both": {"common_mode": False, "standing": False}}


def suralp_stages(raw: pd.DataFrame, reps: int = 5) -> dict[str, float]:
    """µs/sample of the SURALP stages (module docstring)."""
    from grfguard.detect import Monitor
    from grfguard.io.schema import CONTACT_REF, IMU_GYRO
    from grfguard.kernels.monitor import N_EX, monitor_run_packed
    from grfguard.kernels.vfs import N_OUT, log_to_array, vfs_run

    n = len(raw)
    mon = Monitor.for_log(raw)
    assert mon.compiled_reason() == "", mon.compiled_reason()
    has_gyro = all(c in raw for c in IMU_GYRO)
    has_ref = all(c in raw for c in CONTACT_REF)
    k = mon._kernel(has_gyro, has_ref)
    X = np.ascontiguousarray(np.column_stack([
        raw[c].to_numpy(float) if c in raw else np.full(n, np.nan) for c in k.in_cols]))
    vk = k.vfs_kernel
    Xv = np.ascontiguousarray(log_to_array(raw)[0])
    mon.run(raw)  # warm
    Y, EX, Yv = np.empty((n, len(k.out_cols))), np.empty((n, N_EX)), np.empty((n, N_OUT))

    def kern() -> None:  # MonitorKernel.run into the reused arrays
        k.reset()
        monitor_run_packed(X, Y, EX, k.F, k.I)

    def vfs() -> None:  # VFSKernel.run into the reused array
        vk.reset()
        vfs_run(Xv, Yv, *vk.packed_args())

    mons = {"": mon, **{k: Monitor.for_log(raw, **kw) for k, kw in LAYERS.items()}}
    fns = {"vfs": vfs, "kernel": kern, **{k: (lambda m_=m_: m_.run(raw)) for k, m_ in mons.items()}}
    for fn in fns.values():
        fn()  # warm (the first run touches fresh memory)
    runs = _alternated(fns, n, reps)
    out = {"vfs": runs["vfs"][1], "kernel": runs["kernel"][1]}
    out["run_wall"], out["run_cpu"] = runs[""]
    for k in LAYERS:
        out[f"run_no_{k}"] = runs[k][1]
    return out


def talos_stages(duration: float = 20.0, reps: int = 2) -> dict[str, float]:
    """µs/sample of the Talos stages (module docstring); ``n``: samples."""
    from grfguard.detect.channels import ChannelConfig, ChannelMonitor
    from grfguard.estimate.described import run_described, with_described_vfs
    from grfguard.estimate.wrench import estimate_wrenches
    from grfguard.model.description import load_description
    from grfguard.model.loader import load_model
    from grfguard.sim.config import NoiseConfig
    from grfguard.sim.wholebody import scaled_gait, simulate_robot

    r = load_model(load_description("talos"))
    walk = simulate_robot(r, scaled_gait(r, duration=duration), NoiseConfig(), seed=1)
    n = len(walk)
    f = resources.files("grfguard") / "data" / "talos_channels.toml"
    cm = ChannelMonitor(ChannelConfig.from_toml_text(f.read_text()))
    wv = with_described_vfs(walk, r)
    out = {"n": float(n), "joints": float(r.model.njnt), "bodies": float(r.model.nbody - 1)}
    out["wrench_wall"], out["wrench_cpu"] = _whole(lambda: estimate_wrenches(walk, r), n, reps)
    out["channels_wall"], out["channels_cpu"] = _whole(lambda: cm.run(wv), n, reps)
    out["run_wall"], out["run_cpu"] = _whole(lambda: run_described(walk, robot=r), n, reps)
    return out


def table(s: dict[str, float], t: dict[str, float], ref_us: float) -> list[str]:
    """Markdown rows: stage, µs/sample, samples/s, share, ratio to the reference."""
    def row(robot: str, what: str, us: float, whole: float) -> str:
        return (f"| {robot} | {what} | {us:.2f} | {1e6 / us:,.0f} | {100 * us / whole:.0f} % | "
                f"{us / ref_us * 1e6:.1f} |")

    rc = s["run_cpu"]
    tc = t["run_cpu"]
    return [
        "| robot | stage | µs/sample | samples/s | share | ratio to the reference x 10^6 |",
        "|---|---|---|---|---|---|",
        row("SURALP", "`Monitor.run`, whole (CPU; wall "
            f"{s['run_wall']:.2f} µs = {1e6 / s['run_wall']:,.0f}/s)", rc, rc),
        row("SURALP", "compiled monitor loop (`MonitorKernel.run`)", s["kernel"], rc),
        row("SURALP", "of which the virtual force sensor (`vfs_run`)", s["vfs"], rc),
        row("SURALP", "of which guards, twin sensor, system layer, detector, recovery, "
            "standing (difference)",
            max(s["kernel"] - s["vfs"], 1e-3), rc),
        row("SURALP", "columns in, output frame (difference)",
            max(rc - s["kernel"], 1e-3), rc),
        row("SURALP", "`Monitor.run` without the standing layer (`standing=False`)",
            s["run_no_standing"], rc),
        row("SURALP", "`Monitor.run` without the system layer (`common_mode=False`: no "
            "common-mode fit, sensor zeros, IMU corrections, twin sensor)",
            s["run_no_system"], rc),
        row("SURALP", "`Monitor.run` without either (virtual sensor, guards, detector, "
            "recovery)", s["run_no_both"], rc),
        row(f"Talos ({t['joints']:.0f} joints incl. free)", "`run_described`, whole (CPU; "
            f"wall {t['run_wall']:.1f} µs)", tc, tc),
        row("Talos", "virtual wrenches (`estimate_wrenches`)", t["wrench_cpu"], tc),
        row("Talos", "channel monitor (`ChannelMonitor.run`)", t["channels_cpu"], tc),
    ]


def main() -> None:
    from grfguard.faults import inject_faults
    from grfguard.kernels import warm_up
    from grfguard.model.robot import SURALP
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    warm_up()
    walk = simulate(SURALP, GaitConfig(duration=60.0), NoiseConfig(), seed=0)
    raw = inject_faults(walk, ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5",
                               "r4=offset:-100@5"], seed=0)
    ref = reference_us()
    s = suralp_stages(raw)
    t = talos_stages()
    print(f"reference np.sort(1e6): {ref:.0f} µs")
    print("\n".join(table(s, t, ref)))


if __name__ == "__main__":
    main()
