"""Model self-calibration against the targets of issue 10, "Must show" 2.

One robot: every gap of ``grfguard/data/reality/all.toml`` at once (mass +5 %, trunk CoM
+3/-3 cm, IMU mounted 2 deg off in roll and pitch, gyro and accelerometer biases, the
iCub accelerometer vibration, encoder offsets +-0.5 deg, load-cell gains +-5 % and zeros
+-10 N, sensor positions +-2 mm, 2 % of the leg mass moved to the trunk; draw seed 7).

1. ``estimate_corrections`` on 60 s of fault-free data of it (seed 1): the calibration
   poses (``GaitConfig.calibration_poses``: each sole tilted onto each of its corners,
   about 30 s of standing) then a walk, without and with the measured mass: errors
   against the recorded truth (``attrs["reality"]``); the same on seeds 2, 3 and on a
   plain 60 s walk (seed 1, no poses).
2. Thresholds calibrated (``calibrate_thresholds``) on the corrected walk, with the
   monitor config the corrections call for, against those calibrated on a 60 s walk of
   the exact model (same seed) and on the exact model with the same vibrating
   accelerometer (calibrated the same way): per-corner and foot-total threshold
   ``sigma * h`` [fraction of the weight x samples].
3. False alarms on 10 minutes of other fault-free walks of that robot (seeds 11-20, five
   gaits), corrections and thresholds applied.
4. The paper's scenario (``r1=frozen:0@5 r2=offset:100@5 r3=drift:15@5 r4=offset:-100@5``)
   injected into a 60 s walk of that robot (seed 0): delays, frozen delay after the foot's
   next planned load, recovery RMSE.

The accelerometer-free sensor's rate low-pass is chosen on the calibration data as
``grfguard calibrate --model`` does (``grfguard.calib.choose_twin_filter``), for the robot
and for the exact model with the vibrating accelerometer alike.

Usage: ``python benchmarks/bench_selfcal.py [--minutes 10] [--seed 1]
[--controller open_loop|balanced] [--write]``; ``--write`` (seed 1 only) replaces the
``## Model self-calibration`` section of BENCHMARKS.md (with ``--controller balanced``,
the robot planned on its true body: ``## Model self-calibration: the robot walking
balanced``); ``--seed N`` re-runs the calibration data and the exact-model references
on seed N (the seed-spread line is skipped) and only prints.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np

from grfguard.calib import (
    apply_corrections,
    choose_twin_filter,
    corrected_config,
    estimate_corrections,
)
from grfguard.detect import Monitor, MonitorConfig, calibrate_thresholds
from grfguard.evaluate.frame import evaluate_frame
from grfguard.faults import inject_faults, parse_fault_spec
from grfguard.model.robot import SENSOR_NAMES, RobotConfig
from grfguard.sim import simulate
from grfguard.sim.config import GaitConfig
from grfguard.sim.reality import CONTROLLERS, RealityGap, load_reality

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import alarm_episodes, update_section  # noqa: E402

HEADER = "## Model self-calibration"
READING = (
    'Reading. With the weighed mass every target is met but the per-corner ratio (2.02x, b'
    'ound 2); the rows missed are argued below. What brought the gains within 1 % (2026-11'
    '-27): the calibration poses.\n\n* **Gains relative to each other.** On a walk alone all'
    ' eight cells stay off in the twist pattern of each sole (corners 1 and 4 against 2 an'
    'd 3; plain 60 s walks, seeds 1-3: 1.23, 1.25, 1.28 %): a flat sole on compliant groun'
    'd carries a planar load, so the whole-body balance sees a twist only in the partial c'
    'ontacts at contact changes, where its reference (the leg odometry; the accelerometer '
    "vibrates) is 1.1 N RMS off in the fit's 2 Hz band, correlated with the right sole's t"
    'wist (-0.68), and the ridge toward equal gains needed against that error pulls the tr'
    'ue twist (+1.4 % per cell on the left sole) toward zero. Tried on the walk alone befo'
    're (2026-11-26), none below 1.16 % on seed 1 nor better than the odometry on seeds 2-'
    '3: samples away from contact changes, a reference anchored on the load-weighted corne'
    'r heights (with the contact compliance fitted from the sole flatness or jointly with '
    "the gains), blends of both, other odometry settings, the fit's band and ridge (1-4 Hz"
    ' x 0.003-0.03; 2 Hz, 0.01 kept). The poses give partial contacts while standing still'
    ', where the reference is exact (nothing accelerates: the cells carry m g). `estimate_'
    'corrections` finds them in the log alone: standing still = every joint slower than 0.'
    '01 rad/s over 50 ms for 0.3 s or more, both feet planned in contact (encoders only); '
    'when each foot has at least 1 s of it with a load far from planar (`|f1 - f2 - f3 + f'
    "4|` over half the foot's load), every still 50 ms block joins the gain fit as a row w"
    'ith reference g, weighted 100 against a walking row, and the ridge drops to 1e-4. Mea'
    'sured on seed 1: still-row weight 10: 0.27 %, 100: 0.22 %, 1000: 0.21 %; still rows a'
    "lone: 0.36 %; the old fit on the poses' data (ridge 0.01, no still rows): 0.68 %; til"
    'ting 3 deg instead of 2: 0.61 % (trunk tilt 6 deg, IMU mounting 0.35 deg off). The po'
    'ses must stay out of the flat-sole fits (IMU mounting, encoder offsets; with them in,'
    " the mounting is 11.8 deg off): samples whose two soles' relative tilt (leg kinematic"
    's only) is more than 0.5 deg from its median, or within 0.6 s of a relative tilt over'
    ' 1 deg (the ramps into and out of a pose; without that margin 0.40 deg off), are drop'
    'ped there. On a walk no sample is dropped and no still row is posed: its calibration '
    'is bit-identical to before (the plain-walk line below the table). The same data with '
    "a quiet accelerometer (gains gap alone, seed 1): 0.22 % (walk alone 0.27 %).\n* **r2's"
    ' recovery** was that gain error (true / fitted gain 1.0118 on a 386 N mean stance loa'
    'd: 5.5 N): 2.16 N with the poses.\n* **Per-corner threshold against the exact model: 2'
    '.02x, missed by 1 % on seed 1 and by about a fifth on seeds 4 and 5 (end of this item'
    ')** (2.37x with the 10 Hz Butterworth before). Both thresholds have `h` at its floor '
    '(30), so the ratio is that of the corner noise scales (0.0204 / 0.0101); 2x needs the'
    ' robot at 0.604 or less. The accelerometer cannot be used (1.3 m/s^2 RMS of vibration'
    ' above 10 Hz); against the exact model with the same vibrating IMU, which is what cal'
    'ibration can correct toward, it is 0.97x (met). The error is mostly the lag of the ac'
    "celerometer-free sensor's rate low-pass on the CoM acceleration (`python benchmarks/b"
    'ench_selfcal_twin.py`, section "Model self-calibration: per-corner noise of the accel'
    'erometer-free sensor": the 10 Hz Butterworth\'s corner forces advanced 10 / 20 ms give'
    ' 1.93x / 1.78x), second a sole twist the sensor gets wrong (with the true twist 2.14x'
    "; not the encoder offsets left after calibration but the contact's stiffness, which g"
    "rows with penetration, under a centre of pressure off the sole's centre in both axes:"
    ' fitted from the data, it takes this ratio to 1.76x but the lower threshold raises fa'
    'lse alarms on other walks, so it is recorded, not applied; section "Model self-calibr'
    'ation: contact twist"). `calibrate --model` now chooses that low-pass on the calibrat'
    'ion data (`grfguard.calib.choose_twin_filter`, `VFSConfig.filter_damping`; the line b'
    'elow the table): 8 Hz with damping 0.45 (low-frequency delay 17.9 ms instead of 22.5)'
    '. Damped less, the calibration data measure lower still (8 Hz 0.42: 0.597, 1.98x; 0.4'
    ': 0.590, 1.95x; 7 Hz 0.3: 0.563, 1.86x), but the filter rings at the transients of ot'
    'her gaits, which the calibration walk does not show: alarm episodes on these 10 min o'
    'f other walks with 8 Hz 0.42: 1, 8 Hz 0.4: 4, 7 Hz 0.4: 5, 7 Hz 0.35: 7, 7 Hz 0.3: 20'
    '; with damping 0.45 or more: 0 (also 8.5 Hz 0.45: 0.610, and 7.5 Hz 0.45: 0.619, both'
    ' 0). So the grid stops at 0.45 (`TWIN_FILTER_GRID`), and the 2x bound is missed by 1 '
    '% rather than met without margin against false alarms. A phase lead on that low-pass '
    'does not close the gap either (section "Model self-calibration: phase lead on the rat'
    'e low-pass": as a second-order design much worse, the lead\'s noise gain taken back by'
    ' more poles 1.1-1.2 % better at most, with more resonance), nor does smoothing the le'
    'g odometry otherwise (section "Model self-calibration: smoothing the leg odometry": k'
    'inematic Kalman filters, fourth order, per-channel low-passes, a gyro low-pass; the l'
    "ag is a quarter of the single-support ZMP error; about 40 % of the odometry's noise a"
    "bove 10 Hz is the gyro-integrated attitude's). Other seeds (`python benchmarks/bench_"
    'selfcal.py --minutes 10 --seed N`, same day): seed 2 chooses 8 Hz 0.45, 0.620 / 0.313'
    ' = 1.98x (met); on seed 3 every damped setting rings on the calibration data itself ('
    '`h` 35-52), the Butterworth is kept, 0.732 / 0.488 = 1.50x (met, but not by the robot'
    ": the exact model's noise scale is 0.0163 on that seed, against 0.0101 on seed 1, bec"
    'ause the simulated IMU\'s quaternion is 4 mrad off in roll there; section "Exact model'
    ': the IMU\'s attitude bias and the per-corner threshold"); both with 0 false alarms on'
    " 10 min of other walks and the paper's scenario within its bounds (delays 0.024 / 0.3"
    '21 / 0.485 / 0.321 s and 0.024 / 0.321 / 0.483 / 0.321 s; recovery 2.14 / 3.46 / 2.02'
    ' N and 2.11 / 3.48 / 2.01 N). Earlier settings tried (robot; vibrating IMU): Butterwo'
    'rth 8, 9, 11 Hz, third order, the pendulum Kalman ZMP, attitude time constant, contac'
    't height and stiffness, `anchor_hold`: none below 0.712 (the twin section). Removing '
    "each corner's mean residual would not help the ratio (calibrated 0.0199, exact 0.0079"
    ' after it, measured before the poses). The thresholds are calibrated on the calibrati'
    'on data itself, poses included (as `calibrate --model` does). Against the exact model'
    " put through the same self-calibration (its IMU's attitude error fitted as mounting; "
    'that section), the seed-1 ratio is 2.2x (0.611 / 0.278), and on seeds 4 and 5, whose '
    "exact models' IMUs are about 1 mrad off, the plain ratio is 2.42x and 2.47x (0.614 / "
    '0.254, 0.617 / 0.250; `bench_selfcal_fixedlag.py`, its `L` = 0 rows, this pipeline): '
    'the per-corner bound is further off than the 1 % above.\n* Without a weighed mass the '
    "forces are in load-cell units: the mean gain's 1.4 % error (unknowable without weighi"
    'ng) goes into the recovered force, 7.4 N (11.9 N before the poses); a weighing is nee'
    'ded for the 5 N recovery bound.\n\nKept from earlier rounds: the vibrating acceleromete'
    'r is left out of the virtual sensor and its quiet twin low-passes the rates at 10 Hz '
    '(`quiet_vfs_config`; the corrected monitor runs the low-pass `calibrate --model` chos'
    "e); of the fitted encoder offsets only each leg's net sole tilt is applied, on its an"
    'kle (joint by joint: 3.38x). The IMU mounting includes the simulated per-walk attitud'
    'e bias (0.11 deg per axis, 1 sigma).'
)

HEADER_BALANCED = "## Model self-calibration: the robot walking balanced"
READING_BALANCED = (
    "Reading. The same robot, the same gaps and draws, the same pipeline as the section "
    '"Model self-calibration" (the open-loop robot); only the simulated walking '
    'controller differs (`controller = "balanced"` in the gap file, '
    "`grfguard.sim.reality.RealityGap.controller`): the walk is planned on the true body, "
    "so the true CoM follows the planned path over the planned ZMP, as on a robot whose "
    "balance controller has converged, instead of the open-loop rollout of a plan made "
    "for the description, which walks with the soles' centres of pressure about 2.3 cm "
    "forward and 1.5-2.4 cm to the right (section \"Model self-calibration: where the "
    "centres of pressure sit\"). The description in the log, the data the calibration "
    "reads and everything it must find (the trunk CoM 3 cm off included) are those of "
    "the open-loop robot; the other walks and the paper's scenario are walks of the "
    "balanced robot. Against the open-loop robot (2.02x on seed 1; 2.42x and 2.47x on "
    "seeds 4 and 5) the per-corner threshold drops by about a fifth (0.611 -> 0.468 on "
    "seed 1) and the relative gains, zeros and CoM come out at least as well; without the "
    "weighed mass the recovery is within 5 N too (4.85 N; open loop 7.43 N), the mean "
    "gain's error being smaller on this walk. From a plain walk without the poses the "
    "relative gains are 2.08 % off (open loop 1.23 %): the poses stay needed.\n\n"
    "Other seeds, the same command with `--seed N` (2026-11-27 15:38-15:47 UTC, print "
    "only; the robot's draws are the same, the seed draws the sensor noise of the "
    "calibration data and of the exact model's walk):\n\n"
    "| seed | IMU [deg] | CoM [cm] | zeros [N] | rel. gains [%] | false alarms (10 min) | "
    "delays r2 / r4 / r3 / r1 after load [s] | recovery r2 / r4 / r3 [N] | without the "
    "weighed mass: worst r2 / r4 [N] | per-corner: robot / exact (ratio) | foot-total "
    "ratio |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|\n"
    "| 2 | 0.261 | 0.212 | 0.048 | 0.182 | 0 | 0.321 / 0.321 / 0.485 / 0.024 | "
    "2.01 / 2.03 / 3.45 | 4.38 | 0.475 / 0.313 (1.52x) | 0.93x |\n"
    "| 3 | 0.102 | 0.218 | 0.034 | 0.134 | 0 | 0.321 / 0.321 / 0.481 / 0.024 | "
    "2.00 / 2.01 / 3.56 | 4.23 | 0.488 / 0.488 (1.00x) | 0.91x |\n"
    "| 4 | 0.197 | 0.098 | 0.039 | 0.332 | 0 | 0.321 / 0.321 / 0.484 / 0.024 | "
    "2.08 / 2.07 / 3.43 | 4.77 | 0.488 / 0.254 (1.92x) | 0.93x |\n"
    "| 5 | 0.161 | 0.131 | 0.019 | 0.242 | 0 | 0.321 / 0.321 / 0.484 / 0.024 | "
    "2.08 / 2.10 / 3.44 | 4.75 | 0.483 / 0.250 (1.93x) | 0.91x |\n\n"
    "Every bound of must-show 2 is met on each seed. The margin is smallest on seeds 4 "
    "and 5 (4 %), whose exact models' simulated IMUs are about 1 mrad off (the reference "
    "is lowest there: section \"Exact model: the IMU's attitude bias and the per-corner "
    "threshold\"); the robot's own threshold is 0.468-0.488 on every seed."
)
PAPER_FAULTS = ("r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5", "r4=offset:-100@5")
#: Gaits of the other walks: (step length [m], step period [s]).
GAITS = ((0.12, 1.0), (0.15, 0.8), (0.08, 1.2), (0.18, 1.0), (0.1, 0.9))


def errors(corr, truth: dict, nominal: RobotConfig) -> dict[str, float]:
    """Estimated minus true: worst IMU roll/pitch [deg], worst trunk CoM x/y [cm], worst
    zero [N], worst gain relative to the mean [%], weight seen vs true mass x mean gain
    [%]."""
    gt = np.array([truth["load_cell_gain"][s] for s in SENSOR_NAMES])
    ge = np.array([corr.load_cell_gain[s] for s in SENSOR_NAMES])
    zt = np.array([truth["load_cell_zero_n"][s] for s in SENSOR_NAMES])
    ze = np.array([corr.load_cell_zero_n[s] for s in SENSOR_NAMES])
    rel = ge / gt
    m_true = nominal.mass * (1 + truth["mass_error"])
    com_true = np.array([nominal.trunk_com_x, nominal.trunk_com_y]) + np.array(
        truth["trunk_com_offset_m"][:2])
    return {
        "imu_deg": float(np.max(np.abs(np.array(corr.imu_mount_rpy_deg[:2])
                                       - np.array(truth["imu_mount_rpy_deg"][:2])))),
        "com_cm": 100 * float(np.max(np.abs(
            np.array([corr.trunk_com_x_m, corr.trunk_com_y_m]) - com_true))),
        "zero_n": float(np.max(np.abs(ze - zt))),
        "gain_pct": 100 * float(np.max(np.abs(rel / rel.mean() - 1))),
        "weight_pct": 100 * float(corr.mass_kg / (m_true * gt.mean()) - 1),
        "scale_pct": 100 * float(ge.mean() / gt.mean() - 1),
    }


def thresholds_of(log, corr=None):
    """Thresholds calibrated on ``log`` (corrected, with the config the corrections call
    for, when ``corr`` is given; the accelerometer-free sensor's rate low-pass chosen on
    ``log`` as `grfguard calibrate --model` does), the config and the corrections with
    that choice, and the rows of the choice."""
    if corr is None:
        return calibrate_thresholds([log]), MonitorConfig(), None, []
    corr, rows = choose_twin_filter([apply_corrections(log, corr)], corr)
    cfg = corrected_config(MonitorConfig(), corr)
    return calibrate_thresholds([apply_corrections(log, corr)], config=cfg), cfg, corr, rows


def choice_text(rows: list[dict]) -> str:
    """The settings of the accelerometer-free sensor's rate low-pass tried by
    ``choose_twin_filter``: ``cut-off damping: corner / total`` each, the chosen marked."""
    return "; ".join(
        f"{r['cutoff_hz']:g} Hz "
        + ("Butterworth" if r["damping"] is None else f"damping {r['damping']:g}")
        + f": {r['corner']:.3f} / {r['total']:.3f}" + (" (**chosen**)" if r["chosen"] else "")
        for r in rows)


def level(th) -> tuple[float, float]:
    """Per-corner and foot-total thresholds ``sigma * h``."""
    return th.corner_sigma * th.corner_h, th.total_sigma * th.total_h


def other_walk(k: int, gap: RealityGap | None = None):
    """The ``k``-th of the other fault-free walks: 60 s, seed ``11 + k``, gait
    ``GAITS[k % 5]``, the robot of ``gap`` (None: the exact model)."""
    sl, sp = GAITS[k % len(GAITS)]
    return simulate(gait=GaitConfig(duration=60.0, step_length=sl, step_period=sp),
                    seed=11 + k, reality=gap)


def other_walks(gap: RealityGap, corr, cfg, minutes: float) -> tuple[int, list[str]]:
    """Healthy-sensor alarm episodes over ``minutes`` of other 60 s walks."""
    n_fa, rows = 0, []
    for k in range(int(round(minutes))):
        sl, sp = GAITS[k % len(GAITS)]
        wc = apply_corrections(other_walk(k, gap), corr)
        eps = alarm_episodes(Monitor.for_log(wc, config=cfg).run(wc))
        n_fa += eps
        rows.append(f"seed {11 + k} ({sl:g} m, {sp:g} s): {eps}")
        print(f"  other walk {rows[-1]}", flush=True)
    return n_fa, rows


def own_alarms(log, corr, cfg) -> list[str]:
    """Alarm episodes of the monitor on the (corrected) calibration data itself:
    ``sensor start-end s (kind)``."""
    lc = apply_corrections(log, corr)
    out = Monitor.for_log(lc, config=cfg).run(lc)
    t = out["time"].to_numpy(float)
    rows = []
    for s in SENSOR_NAMES:
        f = np.r_[0, out[f"flag_{s}"].to_numpy(bool).astype(int), 0]
        e = np.flatnonzero(np.diff(f))
        for a, b in zip(e[::2], e[1::2], strict=True):
            kind = out[f"kind_{s}"].iloc[a] if f"kind_{s}" in out.columns else "?"
            rows.append(f"{s} {t[a]:.1f}-{t[b - 1]:.1f} s ({kind})")
    return rows


def paper_scenario(gap: RealityGap, corr, cfg, prepare=None) -> dict[str, dict[str, float]]:
    """Delays [s], frozen delay after the next load [s] and recovery RMSE [N]
    (``prepare(log)``, if given, changes the faulty log before the corrections)."""
    walk = simulate(gait=GaitConfig(duration=60.0), seed=0, reality=gap)
    faulty = inject_faults(walk, [parse_fault_spec(s) for s in PAPER_FAULTS], seed=0)
    fc = apply_corrections(faulty if prepare is None else prepare(faulty), corr)
    out = Monitor.for_log(fc, config=cfg).run(fc)
    det = evaluate_frame(out)["detection"]["sensors"]
    t = out["time"].to_numpy(float)
    res = {}
    for spec in PAPER_FAULTS:
        s = spec.split("=")[0]
        m = det[s]
        row = {"delay_s": m.get("delay_s"), "recovery_rmse_n": m.get("recovery_rmse_n"),
               "false_alarms": m.get("false_alarms")}
        if "frozen" in spec:  # delay after the foot's next planned load
            onset = float(spec.split("@")[1])
            c = out["contact_ref_" + s[0]].to_numpy(float) > 0.5
            k0 = int(np.searchsorted(t, onset))
            k_load = k0 + int(np.argmax(c[k0:]))
            row["delay_after_load_s"] = float(onset + m["delay_s"] - t[k_load])
        res[s] = row
    res["all_false_alarms"] = {"n": float(sum(
        (det[s].get("false_alarms") or 0) for s in SENSOR_NAMES))}
    res["healthy_false_alarms"] = {"n": float(sum(
        (det[s].get("false_alarms") or 0) for s in SENSOR_NAMES if s not in
        {p.split("=")[0] for p in PAPER_FAULTS}))}
    return res


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=10.0,
                    help="minutes of other fault-free walks for the false-alarm count")
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--controller", choices=CONTROLLERS, default="open_loop",
                    help="the simulated robot's walking controller (RealityGap.controller);"
                         " --write with 'balanced' writes its own section")
    ap.add_argument("--seed", type=int, default=1,
                    help="seed of the calibration data and of the exact-model references "
                         "(the section written is the seed-1 one: --write needs 1)")
    args = ap.parse_args()
    if args.write and args.seed != 1:
        ap.error("--write records the seed-1 run; run other seeds without it")
    seed = args.seed
    t0 = time.time()
    load0 = os.getloadavg()[0]
    gap = dataclasses.replace(load_reality("all"), controller=args.controller)
    balanced = args.controller == "balanced"
    header, reading = (HEADER_BALANCED, READING_BALANCED) if balanced else (HEADER, READING)
    nominal = RobotConfig()
    lines = []

    exact = simulate(gait=GaitConfig(duration=60.0), seed=seed)
    th_exact, *_ = thresholds_of(exact)
    vib_gap = RealityGap(acc_vibration=gap.acc_vibration, seed=gap.seed)
    vib = simulate(gait=GaitConfig(duration=60.0), seed=seed, reality=vib_gap)
    th_vib, _, corr_v, _ = thresholds_of(vib, estimate_corrections(vib))
    print(f"exact thresholds done ({time.time() - t0:.0f} s)", flush=True)

    cal_gait = GaitConfig(duration=60.0, calibration_poses=True)
    cal = simulate(gait=cal_gait, seed=seed, reality=gap)
    truth = cal.attrs["reality"]
    corr = estimate_corrections(cal)
    m_true = nominal.mass * (1 + truth["mass_error"])
    corr_m = estimate_corrections(cal, measured_mass_kg=m_true)
    e, e_m = errors(corr, truth, nominal), errors(corr_m, truth, nominal)
    spread = []  # the IMU mounting error on other 60 s calibration walks of the robot
    for s_other in (2, 3) if args.write else ():
        other = simulate(gait=cal_gait, seed=s_other, reality=gap)
        spread.append(errors(estimate_corrections(other), other.attrs["reality"], nominal))
        print(f"calibration walk seed {s_other}: {spread[-1]}", flush=True)
    plain = simulate(gait=GaitConfig(duration=60.0), seed=seed, reality=gap)
    e_plain = errors(estimate_corrections(plain), plain.attrs["reality"], nominal)
    print(f"plain walk, no poses: {e_plain}", flush=True)
    # monitoring with the weighed mass (the forces in newtons, not in load-cell units)
    th, cfg, corr_m, choice = thresholds_of(cal, corr_m)
    (c_x, t_x), (c_v, t_v), (c_g, t_g) = level(th_exact), level(th_vib), level(th)
    print(f"corrections: {corr.summary()}\n{e}\nscale with mass: {e_m['scale_pct']:+.2f} %",
          flush=True)
    print("rate low-pass choice: " + choice_text(choice) + f"; vibrating IMU: "
          f"{corr_v.summary()}", flush=True)
    print(f"thresholds corner {c_g:.3f} / exact {c_x:.3f} / exact+vibration {c_v:.3f}; "
          f"total {t_g:.3f} / {t_x:.3f} / {t_v:.3f} ({time.time() - t0:.0f} s)", flush=True)

    own = own_alarms(cal, corr_m, cfg.with_thresholds(th))
    print("alarms on the calibration data itself:", own, flush=True)
    n_fa, fa_rows = other_walks(gap, corr_m, cfg.with_thresholds(th), args.minutes)
    sc = paper_scenario(gap, corr_m, cfg.with_thresholds(th))
    print(sc, flush=True)
    th_nm, cfg_nm, corr, _ = thresholds_of(cal, corr)
    sc_nm = paper_scenario(gap, corr, cfg_nm.with_thresholds(th_nm))
    print("without the measured mass:", sc_nm, flush=True)
    runtime = time.time() - t0

    def ok(v: float, lim: float) -> str:
        return "met" if v <= lim else "**missed**"

    fz = sc["r1"]
    rows = [
        ("IMU mounting (worst of roll, pitch) [deg]", e["imu_deg"], 0.3),
        ("horizontal trunk CoM (worst of x, y) [cm]", e["com_cm"], 1.0),
        ("load-cell zeros (worst) [N]", e["zero_n"], 3.0),
        ("load-cell gain relative to the others (worst) [%]", e["gain_pct"], 1.0),
        ("weight the load cells see, true mass x mean gain [%]", abs(e["weight_pct"]), 1.0),
        ("gains' common scale with the measured mass [%]", abs(e_m["scale_pct"]), 1.0),
        (f"false alarms on {args.minutes:g} min of other walks [episodes]", n_fa, 0),
        ("paper scenario: offset +100 N (r2) delay [s]", sc["r2"]["delay_s"], 0.5),
        ("paper scenario: offset -100 N (r4) delay [s]", sc["r4"]["delay_s"], 0.5),
        ("paper scenario: drift 15 N/s (r3) delay [s]", sc["r3"]["delay_s"], 1.0),
        ("paper scenario: frozen (r1) delay after the next load [s]",
         fz["delay_after_load_s"], 0.2),
        ("paper scenario: recovery RMSE offset r2 [N]", sc["r2"]["recovery_rmse_n"], 5.0),
        ("paper scenario: recovery RMSE offset r4 [N]", sc["r4"]["recovery_rmse_n"], 5.0),
        ("paper scenario: recovery RMSE drift r3 [N]", sc["r3"]["recovery_rmse_n"], 10.0),
        ("paper scenario: false alarms, all 8 sensors [episodes]",
         sc["all_false_alarms"]["n"], 0),
        ("paper scenario without the measured mass: recovery RMSE r2 / r4 [N] (worst)",
         max(sc_nm["r2"]["recovery_rmse_n"], sc_nm["r4"]["recovery_rmse_n"]), 5.0),
        ("paper scenario without the measured mass: recovery RMSE drift r3 [N]",
         sc_nm["r3"]["recovery_rmse_n"], 10.0),
        ("paper scenario without the measured mass: worst delay [s] (drift bound 1)",
         max(sc_nm[s]["delay_s"] for s in ("r2", "r4")), 0.5),
        ("per-corner threshold / exact model's", c_g / c_x, 2.0),
        ("foot-total threshold / exact model's", t_g / t_x, 2.0),
        ("per-corner threshold / exact model's with the same vibrating IMU", c_g / c_v, 2.0),
        ("foot-total threshold / exact model's with the same vibrating IMU", t_g / t_v, 2.0),
    ]
    lines += [
        header,
        "",
        f"`python benchmarks/bench_selfcal.py --minutes {args.minutes:g}"
        + (" --controller balanced" if balanced else "") + " --write` (issue 10, "
        "Must show 2). One robot with every gap of `grfguard/data/reality/all.toml` at "
        "once (draw seed 7); `estimate_corrections` on 60 s of its fault-free data (seed "
        "1): the calibration poses (`grfguard simulate --calibration-poses`: standing, "
        "each sole tilted 2 deg onto each of its corners in turn, held 1.5 s; 30.3 s) then "
        "a walk (28 steps); "
        "the measured (true) mass given for monitoring (without it the forces are in "
        "load-cell units: the mean gain's error, unknowable without weighing, goes into "
        "the recovered force; rows marked so); thresholds calibrated on the corrected "
        "calibration data (poses included) with the monitor config the corrections call "
        "for; false alarms on other 60 s walks of the same robot (seeds 11 on, gaits "
        "(step m, period s) "
        + ", ".join(f"({a:g}, {b:g})" for a, b in GAITS)
        + "); the paper's scenario injected into a 60 s walk of it (seed 0). "
        f"Accelerometer vibration seen: {corr.acc_vibration_rms_m_s2:.2f} m/s^2 RMS above "
        f"10 Hz, so the accelerometer is {'kept in' if corr.use_accelerometer else 'left out of'}"
        " the virtual sensor. Thresholds are `sigma * h` (exact model: corner "
        f"{c_x:.3f}, total {t_x:.3f}; exact model with the vibrating IMU: {c_v:.3f}, "
        f"{t_v:.3f}; calibrated robot: {c_g:.3f}, {t_g:.3f}).",
        "",
        "| target | measured | bound | |",
        "|---|---|---|---|",
    ]
    for name, v, lim in rows:
        lines.append(f"| {name} | {v:.3g} | {lim:g} | {ok(float(v), lim)} |")
    def brief(x: dict) -> str:
        return (f"IMU {x['imu_deg']:.2f} deg, CoM {x['com_cm']:.2f} cm, zeros "
                f"{x['zero_n']:.2f} N, gains {x['gain_pct']:.2f} %, weight "
                f"{x['weight_pct']:+.2f} %")

    lines += ["", "Rate low-pass of the accelerometer-free virtual sensor, chosen on the "
              "calibration data by `choose_twin_filter` (as `grfguard calibrate --model`; "
              "per-corner / foot-total threshold `sigma * h` of each setting tried): "
              + choice_text(choice) + ". The exact model with the vibrating IMU, "
              "calibrated the same way: " + corr_v._twin_filter_text().lstrip("; ") + "."]
    lines += ["", "The same fit on the poses + walk of two other seeds (2, 3): "
              + "; ".join(brief(x) for x in spread) + ". On a plain 60 s walk (seed 1, "
              "no poses): " + brief(e_plain) + "."]
    lines += ["", "The monitor on the calibration data itself (corrected, same thresholds), "
              f"walk from {cal.attrs['gait']['start_time']:g} s: "
              + ("; ".join(own) if own else "no alarm") + ". Its virtual sensor splits a "
              "foot's load over flat-sole corners, so a sole posed on one corner reads as "
              "offsets on the others; the poses are calibration data, not to be monitored."]
    lines += ["", reading]
    lines += ["", "Other walks, healthy-sensor alarm episodes: " + "; ".join(fa_rows) + ".",
              "", f"Runtime {runtime:.0f} s on the shared 2-core machine (load average "
              f"{load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end), measured "
              f"{time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC.", ""]
    text = "\n".join(lines)
    print(text)
    if args.write:
        update_section(header, text)


if __name__ == "__main__":
    main()
