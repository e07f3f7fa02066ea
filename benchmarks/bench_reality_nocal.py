"""Reality gap WITHOUT calibration (issue 10, must-show 1 and 4).

For the exact model, each shipped gap alone (``grfguard/data/reality/``) and all of them
together, with the default monitor ``Monitor.for_log(log)`` (its system layer on, compiled;
``--off``: ``common_mode=False``) and the default thresholds (no ``grfguard calibrate``):

- a fault-free walk (``--duration`` s, seed 1): healthy sensors flagged (count, first flag
  time, share of the walk flagged), ``model_mismatch`` (share of the walk, last reason);
- the paper's scenario (``grfguard demo``: r1 frozen at 0, r2 +100 N, r3 +15 N/s,
  r4 -100 N at 5 s) injected on a ``--scenario-duration`` s walk of the same robot
  (seed 0): detection delays vs the bounds (offsets <= 0.5 s, drift <= 1 s, frozen
  <= 0.2 s after the sensor's next load, i.e. its true force above 50 N) and false alarms
  of the four healthy left sensors;
- with ``--ladder``: the smallest offset, drift and gain detected (within 3 s of onset)
  among a few sizes, one fault per level on r2 (offset), l3 (drift) and r4 (gain) at 6 s
  of a 12 s walk.

Usage: ``python benchmarks/bench_reality_nocal.py [--duration 60] [--jobs 2] [--write]``;
``--write`` replaces the ``## Reality gap without calibration`` section at the end of
BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

HEADER = "## Reality gap without calibration"
HEADER_BALANCED = "## Reality gap without calibration: robots walking balanced"
GAPS = ("exact", "mass_plus5", "mass_minus5", "com_x", "com_y", "imu_roll", "imu_pitch",
        "gyro_bias", "acc_bias", "vibration", "encoders", "gains", "zeros", "all")
BOUNDS = {"r1": 0.2, "r2": 0.5, "r3": 1.0, "r4": 0.5}
LADDER = {  # (offset on r2 [N], drift on l3 [N/s], gain on r4)
    "offset": (10.0, 20.0, 40.0, 80.0),
    "drift": (2.0, 5.0, 10.0, 15.0),
    "gain": (1.1, 1.2, 1.5, 2.0),
}


def _gap(name: str, controller: str = "open_loop"):
    import dataclasses

    from grfguard.sim.reality import load_reality

    if name == "exact":
        return None
    return dataclasses.replace(load_reality(name), controller=controller)


def _walk(name: str, duration: float, seed: int, controller: str = "open_loop"):
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    return simulate(gait=GaitConfig(duration=duration), noise=NoiseConfig(), seed=seed,
                    reality=_gap(name, controller))


def _monitor(log, common_mode: bool):
    """The default monitor (its system layer on), or with ``common_mode=False``."""
    from grfguard.detect import Monitor

    return Monitor.for_log(log) if common_mode else Monitor.for_log(log, common_mode=False)


def fault_free(name: str, duration: float, common_mode: bool,
               controller: str = "open_loop") -> dict:
    from grfguard.model.robot import SENSOR_NAMES

    log = _walk(name, duration, 1, controller)
    t0 = time.perf_counter()
    out = _monitor(log, common_mode).run(log)
    run_s = time.perf_counter() - t0
    t = out["time"].to_numpy()
    flagged = []
    for s in SENSOR_NAMES:
        f = out[f"flag_{s}"].to_numpy(bool)
        if f.any():
            flagged.append((s, float(t[f][0]), float(f.mean())))
    mm = out["model_mismatch"].to_numpy(bool) if "model_mismatch" in out else np.zeros(len(t))
    reason = str(out["model_mismatch_reason"].iloc[-1]) if "model_mismatch_reason" in out else ""
    return {"flagged": flagged, "mismatch": float(np.mean(mm)), "reason": reason,
            "run_s": run_s}


def scenario(name: str, duration: float, common_mode: bool,
             controller: str = "open_loop") -> dict:
    from grfguard.demo import PAPER_FAULTS
    from grfguard.evaluate.detection import evaluate_detection
    from grfguard.faults import inject_faults, parse_fault_spec

    walk = _walk(name, duration, 0, controller)
    faulty = inject_faults(walk, [parse_fault_spec(s) for s in PAPER_FAULTS], seed=0)
    out = _monitor(faulty, common_mode).run(faulty)
    det = evaluate_detection(faulty, out)
    t = faulty["time"].to_numpy()
    res = {}
    for s in BOUNDS:
        d = det.loc[s, "delay_s"]
        d = float(d) if np.isfinite(d) else float("nan")
        if s == "r1":  # frozen at 0: counted from the sensor's next load
            load = (t >= 5.0) & (faulty["true_force_r1"].to_numpy() > 50.0)
            t_load = float(t[load][0]) if load.any() else 5.0
            d = d - (t_load - 5.0)
        res[s] = d
    res["fa"] = int(det.loc[["l1", "l2", "l3", "l4"], "false_alarms"].sum())
    res["fa_right"] = int(det.loc[list(BOUNDS), "false_alarms"].sum())
    return res


def ladder(name: str, common_mode: bool, controller: str = "open_loop") -> dict:
    from grfguard.evaluate.detection import evaluate_detection
    from grfguard.faults import inject_faults, parse_fault_spec

    walk = _walk(name, 12.0, 3, controller)
    found = {"offset": None, "drift": None, "gain": None}
    for k in range(len(LADDER["offset"])):
        o, d, g = (LADDER[key][k] for key in ("offset", "drift", "gain"))
        specs = [f"r2=offset:{o:g}@6", f"l3=drift:{d:g}@6", f"r4=gain:{g:g}@6"]
        faulty = inject_faults(walk, [parse_fault_spec(s) for s in specs], seed=0)
        out = _monitor(faulty, common_mode).run(faulty)
        det = evaluate_detection(faulty, out)
        for key, s, size in (("offset", "r2", o), ("drift", "l3", d), ("gain", "r4", g)):
            dl = det.loc[s, "delay_s"]
            if found[key] is None and np.isfinite(dl) and dl <= 3.0:
                found[key] = size
        if all(v is not None for v in found.values()):
            break
    return found


def one_gap(args: tuple) -> tuple:
    name, duration, scen_duration, common_mode, with_ladder, controller = args
    t0 = time.perf_counter()
    ff = fault_free(name, duration, common_mode, controller)
    sc = scenario(name, scen_duration, common_mode, controller)
    ld = ladder(name, common_mode, controller) if with_ladder else None
    return name, ff, sc, ld, time.perf_counter() - t0


def _fmt_flagged(ff: dict) -> str:
    if not ff["flagged"]:
        return "0"
    first = min(f[1] for f in ff["flagged"])
    names = " ".join(f"{s} ({100 * share:.0f} %)" for s, _, share in ff["flagged"])
    return f"{len(ff['flagged'])}: {names}, first {first:.2f} s"


def _fmt_delay(sc: dict, s: str) -> str:
    d = sc[s]
    if not np.isfinite(d):
        return "missed ✗"
    return f"{d:.3f}{'' if d <= BOUNDS[s] else ' ✗'}"


def _fmt_ladder(ld: dict | None) -> str:
    if ld is None:
        return "-"

    def f(v, unit):
        return f"{v:g}{unit}" if v is not None else "> max"

    return f"{f(ld['offset'], ' N')} / {f(ld['drift'], ' N/s')} / {f(ld['gain'], '')}"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--scenario-duration", type=float, default=20.0)
    ap.add_argument("--gaps", nargs="*", default=list(GAPS))
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--off", action="store_true", help="common_mode off (the plain monitor)")
    ap.add_argument("--ladder", action="store_true")
    ap.add_argument("--only-ladder", action="store_true",
                    help="print only the smallest detected offset / drift / gain per gap")
    ap.add_argument("--controller", choices=("open_loop", "balanced"), default="open_loop",
                    help="the simulated robots' walking controller (RealityGap.controller);"
                         " 'balanced' writes its own section")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    cm = not args.off
    balanced = args.controller == "balanced"
    header = HEADER_BALANCED if balanced else HEADER
    t0 = time.perf_counter()
    if args.only_ladder:
        for g in args.gaps:
            print(f"| {g} | {_fmt_ladder(ladder(g, cm, args.controller))} |", flush=True)
        print(f"runtime {time.perf_counter() - t0:.0f} s")
        return
    work = [(g, args.duration, args.scenario_duration, cm, args.ladder, args.controller)
            for g in args.gaps]
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as ex:
            results = list(ex.map(one_gap, work))
    else:
        results = [one_gap(w) for w in work]
    gap_list = "" if args.gaps == list(GAPS) else " --gaps " + " ".join(args.gaps)
    lines = [
        header,
        "",
        f"`python benchmarks/bench_reality_nocal.py --duration {args.duration:g} "
        f"--scenario-duration {args.scenario_duration:g} --jobs {args.jobs}{gap_list}"
        f"{' --controller balanced' if balanced else ''}"
        f"{' --off' if args.off else ''}{' --ladder' if args.ladder else ''} --write` "
        f"(`Monitor.for_log(log{'' if cm else ', common_mode=False'})`, the default "
        f"monitor{'' if cm else ' without its system layer'}, compiled; default "
        "thresholds, no calibration; "
        + ("the gaps' robots walk balanced (`controller = \"balanced\"`: the walk planned "
           "on the true body); " if balanced else "") +
        f"gap files in `grfguard/data/reality/`). Fault-free: a {args.duration:g} s walk, "
        "seed 1: healthy sensors flagged (share of the walk flagged), share of the walk with "
        "`model_mismatch` and its last reason. Paper scenario (r1 frozen at 0 / r2 +100 N / "
        f"r3 +15 N/s / r4 -100 N at 5 s) on a {args.scenario_duration:g} s walk of the same "
        "robot, seed 0: delays [s] (r1 from its next load above 50 N; bounds 0.2 / 0.5 / 1 "
        "/ 0.5 s, ✗ = beyond) and false alarms of the healthy left sensors."
        + (" Smallest detected (within 3 s; 12 s walk, seed 3, faults at 6 s: offset on "
           "r2 of 10/20/40/80 N, drift on l3 of 2/5/10/15 N/s, gain on r4 of "
           "1.1/1.2/1.5/2): offset / drift / gain." if args.ladder else ""),
        "",
        f"| gap | healthy flagged ({args.duration:g} s) | model_mismatch | reason (end) | "
        "r1 frozen | r2 +100 N | r3 drift | r4 -100 N | left FA | smallest offset / drift / gain |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, ff, sc, ld, _ in results:
        lines.append(
            f"| {name} | {_fmt_flagged(ff)} | {100 * ff['mismatch']:.0f} % | "
            f"{ff['reason'] or '-'} | {_fmt_delay(sc, 'r1')} | {_fmt_delay(sc, 'r2')} | "
            f"{_fmt_delay(sc, 'r3')} | {_fmt_delay(sc, 'r4')} | {sc['fa']} | "
            f"{_fmt_ladder(ld)} |"
        )
    lines += ["", f"Runtime {time.perf_counter() - t0:.0f} s ({args.jobs} process(es)) on the "
              "shared 2-core machine; monitor time per fault-free walk: "
              + ", ".join(f"{n} {ff['run_s']:.0f} s" for n, ff, *_ in results) + "."]
    text = "\n".join(lines) + "\n"
    print(text, flush=True)
    if args.write:
        p = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"
        old = p.read_text()
        if header + "\n" in old:
            head, _, tail = old.partition(header + "\n")
            nxt = tail.find("\n## ")
            old = head.rstrip() + "\n" + (tail[nxt:] if nxt >= 0 else "")
        p.write_text(old.rstrip() + "\n\n" + text)


if __name__ == "__main__":
    main()
