"""Where the accelerometer-free virtual sensor's CoM-acceleration error is made (issue 10,
Must show 2: the per-corner threshold within 2x of the exact model's; 2.02x on seed 1).

The robot of ``bench_selfcal.py`` (all gaps, draw seed 7; calibration poses + walk, seed
``--seed``, corrected with the weighed mass). Each row: the per-corner and foot-total
thresholds ``sigma * h`` calibrated on the corrected calibration data (as ``grfguard
calibrate --model`` does) with one change to the accelerometer-free sensor or to its
inputs, against the exact model's (accelerometer fused, 60 s walk, same seed). Rows:

* *kinematic Kalman filter*: the steady-state Kalman filter of a constant-acceleration
  (white jerk, PSD ``q``) or constant-jerk (white snap) model on the leg odometry's
  position (1 mm measurement noise) in place of the rate low-pass; its acceleration
  estimate is an IIR on the position with a double zero at DC, applied as the same filter
  on the second differences (substituted for the rate low-pass's design; not a library
  option).
* *fourth order*: two second-order sections (cut-off Hz / damping).
* *per channel*: the rate low-pass of the kinematic channels (CoM relative to the IMU,
  angular momentum) and of the IMU's world acceleration from the leg odometry set
  separately (measured through the fusion path with a gravity-only accelerometer, whose
  horizontal world acceleration is then 0: ``cdd = LP_fusion(odometry)``).
* *anchor*: ``VFSConfig.anchor_hold``, ``anchor_attitude_time_constant``.
* *gyro*: the logged gyro low-passed before the sensor (second-order Butterworth; causal,
  or zero-phase = an oracle reading the future).
* *measured forces delayed*: the load cells' columns delayed by D (every test then
  compares the sensor at t with the cells at t - D: the "advanced" oracle of
  ``bench_selfcal_twin.py`` made causal, at D ms of detection delay).

Plus the horizontal ZMP error in single support (the corner test's gate) of the chosen
setting against a zero-phase low-pass (oracle) of a 40 Hz sensor's ZMP, and that 40 Hz
sensor's error above 10 Hz with its attitude inputs smoothed (oracles) or ``anchor_hold``.

Usage: ``python benchmarks/bench_selfcal_odom.py [--seed N] [--write]``; ``--write``
replaces the ``## Model self-calibration: smoothing the leg odometry`` section of
BENCHMARKS.md (seed 1 only). ``--other-walks 10``: instead, whether the per-channel
low-passes ring on other gaits (healthy-sensor alarm episodes on 10 min of other walks of
the robot, as ``bench_selfcal.py`` counts them; printed only).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

import numpy as np
from scipy.linalg import expm, solve_discrete_are
from scipy.signal import bilinear, butter, filtfilt, group_delay, lfilter, lfilter_zi, ss2tf

import grfguard._iir as iir
from grfguard.calib import apply_corrections, corrected_config, estimate_corrections
from grfguard.detect import MonitorConfig, calibrate_thresholds
from grfguard.detect.config import config_for_log
from grfguard.estimate.vfs import VirtualForceSensor
from grfguard.model.robot import SENSOR_NAMES, RobotConfig
from grfguard.sim import simulate
from grfguard.sim.config import GaitConfig
from grfguard.sim.reality import load_reality

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RunClock, alarm_episodes, finish_section  # noqa: E402
from bench_selfcal import other_walk  # noqa: E402

HEADER = "## Model self-calibration: smoothing the leg odometry"
FS = 1000.0
#: Sentinel cut-offs [Hz] whose Butterworth design is replaced by a substituted one.
SENT_RATE, SENT_FUSE, SENT_ACC = 77.0, 78.0, 79.0
CHOSEN = {"filter_cutoff": 8.0, "filter_damping": 0.45}


def kalman_design(q: float, nst: int = 3, r: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state Kalman filter of an ``nst``-state kinematic chain (white derivative
    of the last state, PSD ``q``; position measured with variance ``r`` [m^2]) from the
    position to the acceleration, as a filter ``(b, a)`` on the second differences."""
    dt = 1.0 / FS
    ac = np.diag(np.ones(nst - 1), 1)
    f = expm(ac * dt)
    e = np.zeros(nst)
    e[-1] = 1.0
    m = np.zeros((2 * nst, 2 * nst))
    m[:nst, :nst], m[:nst, nst:], m[nst:, nst:] = -ac, np.outer(e, e) * q, ac.T
    em = expm(m * dt)
    qd = em[nst:, nst:].T @ em[:nst, nst:]
    h = np.eye(nst)[:1]
    p = solve_discrete_are(f.T, h.T, qd, np.array([[r]]))
    k = p @ h.T / (h @ p @ h.T + r)
    a_ = (np.eye(nst) - k @ h) @ f
    c = np.eye(nst)[2:3]
    b, a = ss2tf(a_, k, c @ a_, c @ k)
    quo, rem = np.polydiv(np.ravel(b), [1.0, -2.0, 1.0])
    assert np.abs(rem).max() < 1e-6 * np.abs(b).max()
    a = np.ravel(a)
    return quo * dt * dt / a[0], a / a[0]


def sections(*pairs: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Cascade of second-order low-passes ``(cut-off Hz, damping)``, bilinear."""
    num, den = np.array([1.0]), np.array([1.0])
    for fc, z in pairs:
        w = 2 * np.pi * fc
        num, den = np.polymul(num, [w * w]), np.polymul(den, [1.0, 2 * z * w, w * w])
    b, a = bilinear(num, den, FS)
    return b / a[0], a / a[0]


@contextlib.contextmanager
def designs(sub: dict[float, tuple[np.ndarray, np.ndarray]]):
    """Substitute ``sub[cut-off]`` for the Butterworth designs at those sentinel cut-offs
    (orders padded with zeros to the longest)."""
    orig = iir.butter_lowpass
    n = max(max(len(b), len(a)) for b, a in sub.values()) - 1

    def pad(v):
        return np.r_[v, np.zeros(n + 1 - len(v))]

    def patched(order, cutoff_hz, fs_hz):
        if float(cutoff_hz) in sub:
            b, a = sub[float(cutoff_hz)]
            return pad(b), pad(a)
        return orig(order, cutoff_hz, fs_hz)

    iir.butter_lowpass = patched
    try:
        yield n
    finally:
        iir.butter_lowpass = orig


def delay_ms(ba) -> float:
    """Low-frequency group delay of ``(b, a)`` [ms]."""
    _, gd = group_delay(ba, w=[0.2], fs=FS)
    return float(gd[0]) / FS * 1e3


def gravity_only(log):
    """``log`` with the accelerometer reading gravity only (world horizontal 0)."""
    out = log.copy()
    q = log[["imu_quat_w", "imu_quat_x", "imu_quat_y", "imu_quat_z"]].to_numpy(float)
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    g = 9.81
    out["imu_acc_x"] = g * 2 * (x * z - w * y)
    out["imu_acc_y"] = g * 2 * (y * z + w * x)
    out["imu_acc_z"] = g * (1 - 2 * (x * x + y * y))
    return out


def gyro_lowpassed(log, cut: float, zero_phase: bool):
    """``log`` with the gyro columns low-passed (second-order Butterworth)."""
    out = log.copy()
    b, a = butter(2, cut, fs=FS)
    for k in "xyz":
        g = log[f"imu_gyro_{k}"].to_numpy(float)
        out[f"imu_gyro_{k}"] = (filtfilt(b, a, g) if zero_phase
                                else lfilter(b, a, g, zi=lfilter_zi(b, a) * g[0])[0])
    return out


def forces_delayed(log, n: int):
    """``log`` with the load cells' columns delayed by ``n`` samples."""
    out = log.copy()
    for s in SENSOR_NAMES:
        x = log[f"force_{s}"].to_numpy(float)
        out[f"force_{s}"] = np.r_[np.full(n, x[0]), x[:len(x) - n]]
    return out


def cases(log):
    """(group, label, log, VFSConfig changes, substituted designs or None)."""
    bw10 = {"filter_cutoff": 10.0, "filter_damping": None}
    rate = {"filter_cutoff": SENT_RATE, "filter_damping": None}
    out = [("reference", "8 Hz, damping 0.45 (chosen by `calibrate --model`)", log, CHOSEN,
            None),
           ("reference", "10 Hz, Butterworth (default quiet twin)", log, bw10, None)]
    for q, nst in ((1e3, 3), (10**2.5, 3), (1.0, 4)):
        ba = kalman_design(q, nst)
        kind = "acceleration" if nst == 3 else "jerk"
        out.append(("kinematic Kalman filter", f"constant {kind}, q = {q:.3g} "
                    f"(delay {delay_ms(ba):.1f} ms)", log, rate, {SENT_RATE: ba}))
    for pr in (((9.0, 0.4), (30.0, 0.707)), ((8.0, 0.45), (30.0, 0.707))):
        out.append(("fourth order", " x ".join(f"{f:g} Hz / {z:g}" for f, z in pr), log,
                    rate, {SENT_RATE: sections(*pr)}))
    grav = gravity_only(log)
    fused = {"use_accelerometer": True, "fusion_cutoff": SENT_FUSE, "acc_cutoff": SENT_ACC}
    d845, b10 = iir.damped_lowpass(8.0, FS, 0.45), iir.butter_lowpass(2, 10.0, FS)
    for lab, kin, imu in (("kinematic 8 Hz / 0.45, odometry 8 Hz / 0.45 (= chosen)", CHOSEN,
                           d845), ("kinematic 10 Hz BW, odometry 8 Hz / 0.45", bw10, d845),
                          ("kinematic 15 Hz BW, odometry 8 Hz / 0.45",
                           {"filter_cutoff": 15.0, "filter_damping": None}, d845),
                          ("kinematic 8 Hz / 0.45, odometry 10 Hz BW", CHOSEN, b10)):
        out.append(("per channel", lab, grav, {**kin, **fused},
                    {SENT_FUSE: imu, SENT_ACC: imu}))
    out += [("anchor", "anchor_hold, 8 Hz / 0.45", log, {**CHOSEN, "anchor_hold": True},
             None),
            ("anchor", "anchor_hold, 10 Hz BW", log, {**bw10, "anchor_hold": True}, None),
            ("anchor", "anchor attitude 0.05 s, 8 Hz / 0.45", log,
             {**CHOSEN, "anchor_attitude_time_constant": 0.05}, None)]
    for cut, zp in ((20.0, False), (10.0, False), (10.0, True)):
        out.append(("gyro", f"{cut:g} Hz {'zero-phase (oracle)' if zp else 'causal'}, "
                    "8 Hz / 0.45", gyro_lowpassed(log, cut, zp), CHOSEN, None))
    for n in (10, 20):
        out.append(("measured forces delayed", f"{n} ms, 8 Hz / 0.45",
                    forces_delayed(log, n), CHOSEN, None))
    return out


def threshold(log, cfg0, change, sub):
    """``(corner, h, total)`` thresholds calibrated on ``log`` with ``change``."""
    ctx = designs(sub) if sub else contextlib.nullcontext(None)
    with ctx as n:
        if n is not None:
            change = {**change, "filter_order": n}
        th = calibrate_thresholds([log], config=cfg0.replace(vfs=cfg0.vfs.replace(**change)))
    return th.corner_sigma * th.corner_h, th.corner_h, th.total_sigma * th.total_h


def single_support_zmp(log, cfg0) -> list[tuple[str, float, float]]:
    """Horizontal ZMP error RMS [mm] in single support (walk part): the chosen setting,
    a 40 Hz Butterworth sensor, and that one zero-phase low-passed at 10 Hz (oracle)."""
    t = log["time"].to_numpy(float)
    cr, cl = log["true_contact_r"].to_numpy() > 0, log["true_contact_l"].to_numpy() > 0
    ss = (t > t[-1] - 29.0) & (cr ^ cl)

    def zmp(change):
        vfs = config_for_log(log, cfg0.replace(vfs=cfg0.vfs.replace(**change))).vfs
        out = VirtualForceSensor.for_log(log, vfs).run(log)
        return out[["zmp_est_x", "zmp_est_y"]].to_numpy(float)

    zt = log[["true_zmp_x", "true_zmp_y"]].to_numpy(float)
    z40 = zmp({"filter_cutoff": 40.0, "filter_damping": None})
    b, a = butter(2, 10.0, fs=FS)
    zp = filtfilt(b, a, np.nan_to_num(z40), axis=0)
    m = ss & np.isfinite(z40).all(axis=1)
    rows = []
    for lab, z in (("8 Hz / 0.45 (chosen)", zmp(CHOSEN)), ("40 Hz Butterworth", z40),
                   ("40 Hz, zero-phase 10 Hz low-pass after (oracle)", zp)):
        e = (z - zt)[m]
        rows.append((lab, *(1e3 * float(np.std(e[:, k])) for k in range(2))))
    return rows


def high_frequency_zmp(log, cfg0) -> list[tuple[str, float, float, float, float]]:
    """ZMP error of a 40 Hz Butterworth sensor above 10 Hz (zero-phase fourth-order
    high-pass), RMS [mm] in single / double support (walk part), x and y, with the
    attitude inputs smoothed with zero phase at 10 Hz (oracles) or ``anchor_hold``."""
    t = log["time"].to_numpy(float)
    cr, cl = log["true_contact_r"].to_numpy() > 0, log["true_contact_l"].to_numpy() > 0
    walk, one = t > t[-1] - 29.0, cr ^ cl
    b, a = butter(2, 10.0, fs=FS)
    bh, ah = butter(4, 10.0, "highpass", fs=FS)

    def smoothed(cols):
        out = log.copy()
        for c in cols:
            out[c] = filtfilt(b, a, log[c].to_numpy(float))
        return out

    gyro = [f"imu_gyro_{k}" for k in "xyz"]
    rows = []
    for lab, lg, hold in (("as logged", log, False),
                          ("gyro zero-phase 10 Hz", smoothed(gyro), False),
                          ("gyro and quaternion zero-phase 10 Hz",
                           smoothed([*gyro, *(f"imu_quat_{k}" for k in "wxyz")]), False),
                          ("`anchor_hold`", log, True)):
        change = {"filter_cutoff": 40.0, "filter_damping": None, "anchor_hold": hold}
        vfs = config_for_log(lg, cfg0.replace(vfs=cfg0.vfs.replace(**change))).vfs
        out = VirtualForceSensor.for_log(lg, vfs).run(lg)
        e = np.nan_to_num(out[["zmp_est_x", "zmp_est_y"]].to_numpy(float)
                          - lg[["true_zmp_x", "true_zmp_y"]].to_numpy(float))
        eh = filtfilt(bh, ah, e, axis=0)
        rows.append((lab, *(1e3 * float(np.std(eh[walk & sel, k]))
                            for sel in (one, ~one) for k in range(2))))
    return rows


#: (label, kinematic channels' VFSConfig changes, odometry channel (cut-off, damping) or
#: None for one low-pass on every channel)
RING_CASES = (
    ("8 Hz / 0.45, every channel (chosen)", CHOSEN, None),
    ("7 Hz / 0.35, every channel", {"filter_cutoff": 7.0, "filter_damping": 0.35}, None),
    ("kinematic 8 Hz / 0.45, odometry 8 Hz / 0.45 (per-channel path)", CHOSEN, (8.0, 0.45)),
    ("kinematic 10 Hz BW, odometry 7 Hz / 0.35",
     {"filter_cutoff": 10.0, "filter_damping": None}, (7.0, 0.35)),
    ("kinematic 10 Hz BW, odometry 8 Hz / 0.4",
     {"filter_cutoff": 10.0, "filter_damping": None}, (8.0, 0.4)),
)


def other_walks(log, cfg0, corr, minutes: int) -> list[tuple[str, float, list[int]]]:
    """Per-corner threshold on the calibration data and healthy-sensor alarm episodes on
    ``minutes`` other 60 s walks of the robot (seeds 11 on, `bench_selfcal.GAITS`) for
    :data:`RING_CASES` (the per-channel ones through the gravity-only accelerometer)."""
    from grfguard.detect import Monitor

    walks = []
    for k in range(minutes):
        walks.append(apply_corrections(other_walk(k, load_reality("all")), corr))
    rows = []
    for lab, kin, odo in RING_CASES:
        change, sub, prep = dict(kin), None, (lambda lg: lg)
        if odo is not None:
            ba = iir.damped_lowpass(odo[0], FS, odo[1])
            change.update(use_accelerometer=True, fusion_cutoff=SENT_FUSE, acc_cutoff=SENT_ACC)
            sub, prep = {SENT_FUSE: ba, SENT_ACC: ba}, gravity_only
        cfg = cfg0.replace(vfs=cfg0.vfs.replace(**change))
        with designs(sub) if sub else contextlib.nullcontext():
            th = calibrate_thresholds([prep(log)], config=cfg)
            eps = []
            for w in walks:
                wc = prep(w)
                out = Monitor.for_log(wc, config=cfg.with_thresholds(th)).run(wc)
                eps.append(alarm_episodes(out))
        rows.append((lab, th.corner_sigma * th.corner_h, eps))
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--other-walks", type=int, default=0, metavar="MINUTES",
                    help="only the ringing check: alarm episodes on MINUTES other walks "
                         "for the per-channel low-passes (printed, not written)")
    args = ap.parse_args()
    clock = RunClock()
    exact = simulate(gait=GaitConfig(duration=60.0), seed=args.seed)
    th_x = calibrate_thresholds([exact])
    c_x = th_x.corner_sigma * th_x.corner_h
    cal = simulate(gait=GaitConfig(duration=60.0, calibration_poses=True), seed=args.seed,
                   reality=load_reality("all"))
    m_true = RobotConfig().mass * (1 + cal.attrs["reality"]["mass_error"])
    corr = estimate_corrections(cal, measured_mass_kg=m_true)
    log, cfg0 = apply_corrections(cal, corr), corrected_config(MonitorConfig(), corr)
    print(f"exact model corner threshold {c_x:.4f} ({time.time() - clock.t0:.0f} s)", flush=True)
    if args.other_walks:
        for lab, c, eps in other_walks(log, cfg0, corr, args.other_walks):
            print(f"{lab}: corner {c:.4f} ({c / c_x:.3f}x); alarm episodes {sum(eps)} "
                  f"({', '.join(map(str, eps))})")
        print(clock.line())
        return
    rows = []
    for group, lab, lg, change, sub in cases(log):
        c, h, tot = threshold(lg, cfg0, change, sub)
        rows.append((group, lab, c, h, tot))
        print(rows[-1], flush=True)
    zrows = single_support_zmp(log, cfg0)
    hrows = high_frequency_zmp(log, cfg0)
    print(zrows, hrows, flush=True)
    lines = [
        HEADER, "",
        f"`python benchmarks/bench_selfcal_odom.py --seed {args.seed}"
        f"{' --write' if args.write else ''}`. The all-gaps robot of \"Model "
        f"self-calibration\" (calibration poses + walk, seed {args.seed}, corrected with the "
        "weighed mass); per-corner and foot-total thresholds `sigma * h` calibrated on the "
        "corrected calibration data (as `grfguard calibrate --model`) with one change to the "
        "accelerometer-free sensor or its inputs (the script's docstring defines each "
        f"group). Ratio against the exact model ({c_x:.4f}; bound 2: <= {2 * c_x:.4f}).", "",
        "| group | setting | corner | h | ratio | total |", "|---|---|---|---|---|---|",
    ]
    lines += [f"| {g} | {lab} | {c:.4f} | {h:.1f} | {c / c_x:.3f} | {t:.4f} |"
              for g, lab, c, h, t in rows]
    lines += ["", "Horizontal ZMP error in single support (walk part), RMS [mm]:", "",
              "| sensor | x | y |", "|---|---|---|"]
    lines += [f"| {lab} | {x:.1f} | {y:.1f} |" for lab, x, y in zrows]
    lines += ["", "ZMP error of a 40 Hz Butterworth sensor above 10 Hz, RMS [mm] (walk part; "
              "attitude inputs smoothed with zero phase: oracles):", "",
              "| inputs | single support x | y | double support x | y |",
              "|---|---|---|---|---|"]
    lines += [f"| {lab} | {a:.1f} | {b:.1f} | {c:.1f} | {d:.1f} |"
              for lab, a, b, c, d in hrows]
    finish_section(HEADER, lines, clock, args.write and args.seed == 1)


if __name__ == "__main__":
    main()
