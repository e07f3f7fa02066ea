"""The monitor on described robots: G1 (corner cells) and Talos (ankle F/T channels).

1. G1, the paper's scenario transposed (w = 9 % of m g; frozen 0, +w, drift w/s, -w on
   the right foot's four cells at 5 s) on a 20 s walk (seed 1): delay, kind, offset-size
   error and recovery RMSE; fault-free 60 s walks, seeds 1..N (thresholds shipped in
   ``grfguard/data/g1_thresholds.toml``, calibrated on seeds 101-104): false alarms, with
   the shipped SURALP thresholds for comparison.
2. Talos, ``ft_r_fz`` and ``ft_r_tx``, one fault per run (offset +-w, drift w/s, frozen 0,
   gain 1.2; w = 9 % of m g, x foot length for torques) at 5 s on a 20 s walk (seed 1):
   delay, kind, recovery RMSE (whole fault from 1 s after onset; frozen: where the
   virtual channel is valid); fault-free 60 s walks: false alarms (channel thresholds
   shipped in ``grfguard/data/talos_channels.toml``, seeds 101-104).

Updates the ``## Monitoring Talos and G1`` section of BENCHMARKS.md.

Usage: ``.venv/bin/python benchmarks/bench_described_monitor.py [--clean-walks 10]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from _common import update_section  # noqa: E402

from grfguard.detect.channels import channel_valid_mask  # noqa: E402
from grfguard.detect.config import MonitorConfig  # noqa: E402
from grfguard.estimate.described import run_described, with_described_vfs  # noqa: E402
from grfguard.evaluate.detection import evaluate_detection  # noqa: E402
from grfguard.faults import inject_faults  # noqa: E402
from grfguard.faults.inject import apply_fault  # noqa: E402
from grfguard.faults.spec import parse_fault_spec  # noqa: E402
from grfguard.model.description import FT_AXES, load_description  # noqa: E402
from grfguard.model.loader import load_model  # noqa: E402
from grfguard.model.robot import SENSOR_NAMES  # noqa: E402
from grfguard.sim.config import NoiseConfig  # noqa: E402
from grfguard.sim.wholebody import scaled_gait, simulate_robot  # noqa: E402

SECTION = "## Monitoring Talos and G1"


def _walk(r, duration: float, seed: int):
    return with_described_vfs(
        simulate_robot(r, scaled_gait(r, duration=duration), NoiseConfig(), seed=seed), r)


def g1_part(n_clean: int) -> list[str]:
    r = load_model(load_description("g1"))
    W = r.mass * 9.81
    w = 0.09 * W
    faults = ["r1=frozen:0@5", f"r2=offset:{w:.2f}@5", f"r3=drift:{w:.2f}@5",
              f"r4=offset:{-w:.2f}@5"]
    walk = _walk(r, 20.0, 1)
    faulty = inject_faults(walk, faults, seed=0)
    res = run_described(faulty, MonitorConfig(), r)
    raw = run_described(faulty, MonitorConfig(), r, track=False)
    tab, tab_raw = evaluate_detection(res), evaluate_detection(raw)
    lines = [f"G1 ({r.mass:.2f} kg, w = 9 % of m g = {w:.1f} N), paper scenario at 5 s, "
             "20 s walk, seed 1, shipped G1 thresholds. Recovery RMSE against the true "
             "force from 6 s (all samples) and in stance after detection "
             "(`evaluate_detection`'s `recovery_rmse_n`), tracked (the default of "
             "`run_described`, `grfguard.recover.track`) and untracked (`track=False`: "
             "reading - offset):", "",
             "| sensor | fault | delay [s] | kind | size error [% m g] | "
             "recovered - true, from 6 s [% m g] | untracked [% m g] | "
             "stance after detection [% m g] | untracked [% m g] |",
             "|---|---|---|---|---|---|---|---|---|"]
    late = res["time"].to_numpy() >= 6.0

    def rmse(out, s: str, truth: str = "true_force") -> float:
        e = out[f"recovered_{s}"].to_numpy()[late] - walk[f"{truth}_{s}"].to_numpy()[late]
        return 100 * float(np.sqrt(np.nanmean(e**2))) / W

    for s, f in zip(("r1", "r2", "r3", "r4"), faults, strict=True):
        lines.append(f"| {s} | {f.split('=')[1]} | {tab.loc[s, 'delay_s']:.3f} | "
                     f"{tab.loc[s, 'kind_estimated']} | "
                     f"{100 * abs(tab.loc[s, 'fault_size_error_n']) / W:.3f} | "
                     f"{rmse(res, s):.3f} | {rmse(raw, s):.3f} | "
                     f"{100 * tab.loc[s, 'recovery_rmse_n'] / W:.3f} | "
                     f"{100 * tab_raw.loc[s, 'recovery_rmse_n'] / W:.3f} |")
    noise = walk["force_l1"].to_numpy() - walk["true_force_l1"].to_numpy()
    lines += ["", f"Sensor noise floor (healthy l1, measured - true): "
              f"{100 * np.std(noise) / W:.3f} % of m g. Untracked, the recovered offsets "
              f"equal the fault-free reading (r2: {rmse(raw, 'r2', 'force'):.3f} % of m g "
              "apart), so what remains against the truth is the cell's own 2 N noise "
              "(0.61 % of G1's weight, 0.18 % of SURALP's): neither bias "
              f"(mean error r2 {100 * float(np.mean((raw['recovered_r2'] - walk['true_force_r2']).to_numpy()[late])) / W:+.3f} %) "  # noqa: E501
              "nor lag. The tracker (a steady-state Kalman filter of force and force rate "
              "with the calibrated cell noise, no lag on a ramp) estimates the true force "
              "better than reading - offset.", ""]
    lines += suralp_tracking()
    return lines + g1_clean(r, n_clean)


def suralp_tracking() -> list[str]:
    """SURALP's paper scenario (20 s, seed 1): the default monitor's offset recovery and
    the same output through ``track_recovered`` (not applied by default to SURALP)."""
    from grfguard.detect.monitor import Monitor
    from grfguard.recover.track import track_recovered
    from grfguard.sim import simulate
    from grfguard.sim.config import GaitConfig

    walk = simulate(gait=GaitConfig(duration=20.0), seed=1)
    faulty = inject_faults(walk, ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:100@5",
                                  "r4=offset:-100@5"], seed=0)
    cfg = MonitorConfig()
    out = Monitor.for_log(faulty, cfg).run(faulty)
    W = float(walk.attrs["robot"]["mass"]) * 9.81
    trk = track_recovered(out, W, cfg.thresholds.sigma_swing_n, sensors=SENSOR_NAMES)
    a, b = evaluate_detection(faulty, out), evaluate_detection(faulty, trk)
    cells = "; ".join(f"{s} {a.loc[s, 'recovery_rmse_n']:.2f} N -> "
                      f"{b.loc[s, 'recovery_rmse_n']:.2f} N" for s in ("r2", "r3", "r4"))
    return [f"SURALP ({W:.0f} N), paper scenario (20 s, seed 1), recovery in stance after "
            f"detection, default monitor -> through `track_recovered`: {cells} (the default "
            "SURALP monitor does not track: its outputs are unchanged).", ""]


def g1_clean(r, n_clean: int) -> list[str]:
    """G1 fault-free walks of 60 s, seeds 1..n_clean: false alarms with G1's and SURALP's
    thresholds."""
    lines: list[str] = []
    if n_clean <= 0:
        return lines
    fa = {"G1 thresholds": 0, "SURALP thresholds": 0}
    flagged = {"G1 thresholds": 0.0, "SURALP thresholds": 0.0}
    from grfguard.detect.thresholds import default_thresholds

    for seed in range(1, n_clean + 1):
        log = _walk(r, 60.0, seed)
        for name, cfg in (("G1 thresholds", MonitorConfig()),
                          ("SURALP thresholds", MonitorConfig().with_thresholds(
                              default_thresholds().replace(source="suralp")))):
            out = run_described(log, cfg, r)
            for s in SENSOR_NAMES:
                f = out[f"flag_{s}"].to_numpy()
                fa[name] += int(np.sum(f[1:] & ~f[:-1]) + f[0])
                flagged[name] += float(f.mean()) / len(SENSOR_NAMES)
        print(f"g1 seed {seed}: {fa} false alarm(s) so far", flush=True)
    lines.append(f"G1 fault-free: {n_clean} walks x 60 s (seeds 1-{n_clean}): "
                 + "; ".join(f"{k}: {v} false alarm(s), {100 * flagged[k] / n_clean:.2f} % "
                             "of sensor-time flagged" for k, v in fa.items()) + ".")
    return lines


def talos_part(n_clean: int) -> list[str]:
    r = load_model(load_description("talos"))
    W = r.mass * 9.81
    WL = W * r.description.feet[0].length
    walk = _walk(r, 20.0, 1)
    t = walk["time"].to_numpy()
    ok = channel_valid_mask(walk, 0.15)
    lines = ["", f"Talos ({r.mass:.2f} kg), one fault per run at 5 s, 20 s walk, seed 1, "
             "shipped Talos channel thresholds:", "",
             "| channel | fault | delay [s] | kind | recovered - true RMSE [% scale] | "
             "recovered - fault-free reading [% scale] | other channels flagged |",
             "|---|---|---|---|---|---|---|"]

    def errs(out, ch: str, sel: np.ndarray, scale: float) -> str:
        rec = out[f"recovered_{ch}"].to_numpy()[sel]
        e_true = rec - walk[f"true_{ch}"].to_numpy()[sel]
        e_read = rec - walk[ch].to_numpy()[sel]
        return (f"{100 * np.sqrt(np.mean(e_true**2)) / scale:.3f} | "
                f"{100 * np.sqrt(np.mean(e_read**2)) / scale:.3f}")

    for ch, scale in (("ft_r_fz", W), ("ft_r_tx", WL)):
        w = 0.09 * scale
        for spec in (f"offset:{w:.2f}@5", f"offset:{-w:.2f}@5", f"drift:{w:.2f}@5",
                     "frozen:0@5", "gain:1.2@5"):
            f = walk.copy()
            f[ch] = apply_fault(t, walk[ch].to_numpy(), parse_fault_spec(f"r1={spec}"),
                                np.random.default_rng(0))
            out = run_described(f, robot=r)
            flag = out[f"flag_{ch}"].to_numpy()
            others = sum(int(out[f"flag_ft_{s}_{a}"].any()) for s in "rl" for a in FT_AXES
                         if f"ft_{s}_{a}" != ch)
            sel = t >= 6.0
            if spec.startswith("frozen"):
                sel &= ok[:, 0]
            delay = f"{t[np.argmax(flag)] - 5.0:.3f}" if flag.any() else "missed"
            lines.append(f"| {ch} | {spec} | {delay} | {out[f'kind_{ch}'].iloc[-1]} | "
                         f"{errs(out, ch, sel, scale)} | {others} |")
    lines.append("")
    lines.append("Scale: m g for forces, m g x foot length (0.20 m) for torques; frozen "
                 "recovery measured in single support and swing (the virtual channel "
                 "there), the others over the whole fault from 6 s. True: the simulated "
                 "wrench at the sensor frame (`true_ft_*`); fault-free reading: the same "
                 "channel without the fault (with its noise, 2 N and 0.02 N m).")
    lines += ["", "The paper's scenario transposed to four channels of the right F/T sensor "
              "at once (5 s, same walk): fz frozen at 0, fx +w, tx drift w/s, ty -w "
              f"(w = 9 % of m g = {0.09 * W:.1f} N, x foot length = {0.09 * WL:.2f} N m):",
              "", "| channel | fault | delay [s] | kind | recovered - true RMSE [% scale] | "
              "recovered - fault-free reading [% scale] |", "|---|---|---|---|---|---|"]
    four = {"ft_r_fz": ("frozen:0@5", W), "ft_r_fx": (f"offset:{0.09 * W:.2f}@5", W),
            "ft_r_tx": (f"drift:{0.09 * WL:.2f}@5", WL),
            "ft_r_ty": (f"offset:{-0.09 * WL:.2f}@5", WL)}
    f = walk.copy()
    for ch, (spec, _) in four.items():
        f[ch] = apply_fault(t, walk[ch].to_numpy(), parse_fault_spec(f"r1={spec}"),
                            np.random.default_rng(0))
    out = run_described(f, robot=r)
    for ch, (spec, scale) in four.items():
        flag = out[f"flag_{ch}"].to_numpy()
        sel = (t >= 6.0) & (ok[:, 0] if spec.startswith("frozen") else True)
        delay = f"{t[np.argmax(flag)] - 5.0:.3f}" if flag.any() else "missed"
        lines.append(f"| {ch} | {spec} | {delay} | {out[f'kind_{ch}'].iloc[-1]} | "
                     f"{errs(out, ch, sel, scale)} |")
    others = [c for c in (f"ft_{s}_{a}" for s in "rl" for a in FT_AXES)
              if c not in four and out[f"flag_{c}"].any()]
    lines += ["", f"Other channels flagged: {len(others)} {others if others else ''}".rstrip()]
    return lines + talos_clean(r, n_clean)


def talos_clean(r, n_clean: int) -> list[str]:
    """Talos fault-free walks of 60 s, seeds 1..n_clean: false alarms on its 12 channels."""
    if n_clean <= 0:
        return []
    fa = chans = 0
    for seed in range(1, n_clean + 1):
        out = run_described(_walk(r, 60.0, seed), robot=r)
        for s in "rl":
            for a in FT_AXES:
                fl = out[f"flag_ft_{s}_{a}"].to_numpy()
                chans += int(fl.any())
                fa += int(np.sum(fl[1:] & ~fl[:-1]) + fl[0])
        print(f"talos seed {seed}: {fa} false alarm(s) so far", flush=True)
    return ["", f"Talos fault-free: {n_clean} walks x 60 s (seeds 1-{n_clean}), 12 "
              f"channels: {fa} false alarm(s), {chans} channel(s) flagged."]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clean-walks", type=int, default=10)
    ap.add_argument("--part", choices=("both", "g1", "talos", "clean"), default="both",
                    help="g1 or talos alone, or only the fault-free walks of both (clean): "
                    "print only, BENCHMARKS.md is not updated")
    ap.add_argument("--no-write", action="store_true",
                    help="print only; BENCHMARKS.md is not updated (to compare with it)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    part = "" if args.part == "both" else f"--part {args.part} "
    lines = [f"Command: `.venv/bin/python benchmarks/bench_described_monitor.py {part}"
             f"--clean-walks {args.clean_walks}` (one core).", ""]
    if args.part in ("both", "g1"):
        lines += g1_part(args.clean_walks)
    if args.part in ("both", "talos"):
        lines += talos_part(args.clean_walks)
    if args.part == "clean":
        lines += g1_clean(load_model(load_description("g1")), args.clean_walks)
        lines += talos_clean(load_model(load_description("talos")), args.clean_walks)
    lines += ["", f"Wall time {time.perf_counter() - t0:.0f} s."]
    body = "\n".join(lines)
    print(body)
    if args.part == "both" and not args.no_write:
        update_section(SECTION, body)


if __name__ == "__main__":
    main()
