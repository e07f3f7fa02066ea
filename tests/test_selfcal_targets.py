"""Model self-calibration with EVERY gap of issue 10 at once (``reality/all.toml``: mass,
trunk CoM, IMU mounting, gyro/accelerometer biases, iCub accelerometer vibration, encoder
offsets, load-cell gains and zeros, sensor positions), on a 40 s simulated walk.

The issue's targets are stated for 60 s of calibration data (benchmarks/bench_selfcal.py
measures them); on 40 s the bounds here are looser where said: gains relative to each
other 2 % (target 1 %)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from grfguard.calib import (
    ModelCorrections,
    apply_corrections,
    choose_twin_filter,
    corrected_config,
    estimate_corrections,
    selfcal,
)
from grfguard.detect import Monitor, MonitorConfig, calibrate_thresholds
from grfguard.detect.system import quiet_vfs_config
from grfguard.errors import ConfigError
from grfguard.estimate.vfs import VFSConfig, VirtualForceSensor
from grfguard.evaluate.vfs_metrics import evaluate_vfs
from grfguard.faults import inject_faults, parse_fault_spec
from grfguard.model.robot import JOINT_NAMES, SENSOR_NAMES, SURALP
from grfguard.sim import GaitConfig, simulate
from grfguard.sim.reality import RealityGap, load_reality


@pytest.fixture(scope="module")
def gap():
    return load_reality("all")


@pytest.fixture(scope="module")
def cal_walk(gap):
    return simulate(gait=GaitConfig(duration=40.0), seed=1, reality=gap)


@pytest.fixture(scope="module")
def corr(cal_walk) -> ModelCorrections:
    return estimate_corrections(cal_walk)


@pytest.fixture(scope="module")
def corr_m(cal_walk, corr) -> ModelCorrections:
    """The same fit with the weighed (true) mass: ``gain_i = (gain_i m)_fit / m``."""
    m_true = SURALP.mass * (1 + cal_walk.attrs["reality"]["mass_error"])
    km = {s: g * corr.mass_kg for s, g in corr.load_cell_gain.items()}
    return dataclasses.replace(corr, mass_kg=m_true, measured_mass=True,
                               load_cell_gain={s: v / m_true for s, v in km.items()})


def test_all_gaps_corrections_meet_the_targets(cal_walk, corr, corr_m):
    truth = cal_walk.attrs["reality"]
    rpy = np.array(corr.imu_mount_rpy_deg[:2])
    assert np.max(np.abs(rpy - truth["imu_mount_rpy_deg"][:2])) < 0.3
    com = np.array([corr.trunk_com_x_m - SURALP.trunk_com_x,
                    corr.trunk_com_y_m - SURALP.trunk_com_y])
    assert np.max(np.abs(com - truth["trunk_com_offset_m"][:2])) < 0.01
    zt = np.array([truth["load_cell_zero_n"][s] for s in SENSOR_NAMES])
    ze = np.array([corr.load_cell_zero_n[s] for s in SENSOR_NAMES])
    assert np.max(np.abs(ze - zt)) < 3.0
    gt = np.array([truth["load_cell_gain"][s] for s in SENSOR_NAMES])
    ge = np.array([corr.load_cell_gain[s] for s in SENSOR_NAMES])
    rel = ge / gt
    assert np.max(np.abs(rel / rel.mean() - 1)) < 0.02  # 40 s walk; target 1 % on 60 s
    assert ge.mean() == pytest.approx(1.0, abs=1e-9)
    m_seen = SURALP.mass * (1 + truth["mass_error"]) * gt.mean()
    assert corr.mass_kg == pytest.approx(m_seen, rel=0.01)  # the weight the cells see
    gm = np.array([corr_m.load_cell_gain[s] for s in SENSOR_NAMES])
    assert gm.mean() == pytest.approx(gt.mean(), rel=0.01)  # weighed mass: common scale
    # the vibrating accelerometer is recognised and kept out of the virtual sensor
    assert corr.acc_vibration_rms_m_s2 > 0.5 and not corr.use_accelerometer
    cfg = corrected_config(MonitorConfig(), corr)
    assert cfg.vfs.use_accelerometer is False
    assert cfg.vfs == quiet_vfs_config(VFSConfig())  # the monitor's quiet twin
    assert corrected_config(None, None) == MonitorConfig()
    # of the encoder offsets only each leg's net sole tilt is kept, on its ankle
    assert set(corr.encoder_offset_deg) == set(JOINT_NAMES)
    assert all(v == 0.0 for j, v in corr.encoder_offset_deg.items() if "ankle" not in j)
    assert 0.0 < max(abs(v) for v in corr.encoder_offset_deg.values()) < 2.5


def test_calibrated_robot_detects_the_paper_offsets_without_false_alarms(
        gap, cal_walk, corr_m):
    """Thresholds on the first 25 s of the corrected walk (weighed mass), then a 12 s
    walk of another seed with the paper's offsets on r2 and r4 at 5 s: both found within
    0.5 s, no healthy sensor flagged, recovered force within 5 N RMS of the truth."""
    corr = corr_m
    cfg = corrected_config(MonitorConfig(), corr)
    fixed = apply_corrections(cal_walk, corr)
    th = calibrate_thresholds([fixed[fixed["time"] < 25.0]], config=cfg)
    # per-corner threshold within 3x the exact model's (0.30 on its 60 s walk); the
    # issue's 2x is measured in benchmarks/bench_selfcal.py (2.02x on 60 s, seed 1)
    assert th.corner_sigma * th.corner_h < 0.9
    walk = simulate(gait=GaitConfig(duration=12.0), seed=3, reality=gap)
    faulty = inject_faults(
        walk, [parse_fault_spec(s) for s in ("r2=offset:100@5", "r4=offset:-100@5")], seed=0)
    fc = apply_corrections(faulty, corr)
    out = Monitor.for_log(fc, config=cfg.with_thresholds(th)).run(fc)
    t = out["time"].to_numpy(float)
    for s in ("r2", "r4"):
        flag = out[f"flag_{s}"].to_numpy(bool)
        assert not flag[t < 5.0].any()
        assert flag.any() and t[np.argmax(flag)] - 5.0 <= 0.5
        stance = (t > 7.0) & (out["contact_ref_r"].to_numpy(float) > 0.5)
        err = out[f"recovered_{s}"].to_numpy(float) - out[f"true_force_{s}"].to_numpy(float)
        assert np.sqrt(np.mean(err[stance] ** 2)) < 5.0
    healthy = [s for s in SENSOR_NAMES if s not in ("r2", "r4")]
    assert not out[[f"flag_{s}" for s in healthy]].any().any()


def test_old_calibration_files_without_the_new_keys_still_load(tmp_path, corr):
    d = corr.to_dict()
    for k in ("acc_vibration_rms_m_s2", "use_accelerometer", "encoder_offset_deg"):
        d.pop(k)
    old = ModelCorrections.from_dict(d)
    assert old.use_accelerometer and all(v == 0 for v in old.encoder_offset_deg.values())
    p = tmp_path / "th.toml"
    p.write_text(corr.to_toml())
    back = ModelCorrections.from_toml(p)
    assert back.encoder_offset_deg == pytest.approx(corr.encoder_offset_deg)
    assert back.use_accelerometer is False


def test_repeated_gap_simulations_are_identical(gap):
    """The sensor position errors perturb a copy of the cached MuJoCo model: before, they
    added up over the calls of one process (two identical calls differed by 95 N)."""
    a = simulate(gait=GaitConfig(duration=2.0), seed=0, reality=gap)
    b = simulate(gait=GaitConfig(duration=2.0), seed=0, reality=gap)
    cols = [f"force_{s}" for s in SENSOR_NAMES]
    assert np.array_equal(a[cols].to_numpy(), b[cols].to_numpy())


def test_quiet_twin_is_the_more_accurate_sensor_under_vibration(gap):
    """On a walk with the iCub accelerometer vibration, the quiet twin's corner forces
    (no accelerometer, 10 Hz rate low-pass) beat the accelerometer-free sensor at the
    default 15 Hz in single support, and both beat the default sensor by far."""
    walk = simulate(gait=GaitConfig(duration=12.0), seed=1,
                    reality=RealityGap(acc_vibration=gap.acc_vibration, seed=gap.seed))
    truth = walk[["time", *(f"true_force_{s}" for s in SENSOR_NAMES)]]

    def ss_rmse(cfg: VFSConfig) -> float:
        out = VirtualForceSensor.for_log(walk, cfg).run(walk)
        cols = [f"vfs_{s}" for s in SENSOR_NAMES]
        frame = truth.reset_index(drop=True).join(out[cols].reset_index(drop=True))
        return evaluate_vfs(frame)["ss"]["corner_rmse"]

    twin = ss_rmse(quiet_vfs_config(VFSConfig()))
    no_acc = ss_rmse(VFSConfig(use_accelerometer=False))
    default = ss_rmse(VFSConfig())
    assert twin < 0.9 * no_acc
    assert no_acc < 0.5 * default


def test_calibration_chooses_records_and_uses_the_twin_filter(gap, cal_walk, corr_m, tmp_path):
    """The accelerometer-free sensor's rate low-pass chosen on the corrected calibration
    data (first 25 s; two settings to keep the test short, `calibrate --model` tries
    ``TWIN_FILTER_GRID``): the lower per-corner threshold wins, the choice is written
    into the calibration file and read back, the monitor runs the chosen filter, and a
    12 s walk of another seed of the robot is not flagged with it."""
    fixed = apply_corrections(cal_walk, corr_m)
    part = fixed[fixed["time"] < 25.0]
    grid = ((10.0, None), (8.0, 0.5))
    chosen, rows = choose_twin_filter([part], corr_m, grid=grid)
    assert [(r["cutoff_hz"], r["damping"]) for r in rows] == list(grid)
    ref, damped = rows
    # damping 0.5 at 8 Hz lags 6 ms less than the 10 Hz Butterworth: a lower threshold
    assert damped["corner"] < 0.97 * ref["corner"] and damped["chosen"] and not ref["chosen"]
    assert (chosen.twin_filter_cutoff_hz, chosen.twin_filter_damping) == (8.0, 0.5)
    assert "rate low-pass 8 Hz, damping 0.5" in chosen.summary()
    p = tmp_path / "th.toml"
    p.write_text(chosen.to_toml())
    back = ModelCorrections.from_toml(p)
    assert (back.twin_filter_cutoff_hz, back.twin_filter_damping) == (8.0, 0.5)
    assert ModelCorrections.from_dict(corr_m.to_dict()).twin_filter_damping is None  # old file
    cfg = corrected_config(MonitorConfig(), back)
    assert (cfg.vfs.use_accelerometer, cfg.vfs.filter_cutoff, cfg.vfs.filter_damping) == (
        False, 8.0, 0.5)
    th = calibrate_thresholds([part], config=cfg)
    assert th.corner_sigma * th.corner_h == pytest.approx(damped["corner"], rel=1e-12)
    walk = simulate(gait=GaitConfig(duration=12.0), seed=3, reality=gap)
    wc = apply_corrections(walk, back)
    mon = Monitor.for_log(wc, config=cfg.with_thresholds(th))
    assert mon.vfs.config.filter_damping == 0.5 and mon.vfs.config.filter_cutoff == 8.0
    out = mon.run(wc)
    assert not out[[f"flag_{s}" for s in SENSOR_NAMES]].any().any()
    butter = VirtualForceSensor.for_log(wc, quiet_vfs_config(VFSConfig())).run(wc)
    assert not np.allclose(out["vfs_r1"], butter["vfs_r1"])  # the damped filter, not 10 Hz
    with pytest.raises(ConfigError, match="twin_filter_damping"):
        dataclasses.replace(chosen, twin_filter_damping=0.05)


def test_contact_twist_is_fitted_recorded_and_brings_the_twin_closer(cal_walk, corr_m,
                                                                      tmp_path, monkeypatch):
    """The all-gaps robot walks with its trunk CoM 3 cm off in x and y, so the stance
    sole's centre of pressure sits off its centre in both axes and the nonlinear contact
    twists the sole's load (20-50 N) where the planar split says 0. The fitted twist
    coefficient is near MuJoCo's (0.42 on the true forces of exact-model walks), survives
    the calibration file, and brings the accelerometer-free sensor's single-support corner
    forces closer to the corrected readings; the corrected monitor applies it only with
    ``APPLY_CONTACT_TWIST`` (off: its lower threshold flags other walks, BENCHMARKS.md)."""
    k = corr_m.contact_twist
    assert k is not None and 0.3 < k < 0.55 and corr_m.sigma["contact_twist"] < 0.05
    assert f"contact twist {k:.2f}" in corr_m.summary()
    p = tmp_path / "th.toml"
    p.write_text(corr_m.to_toml())
    back = ModelCorrections.from_toml(p)
    assert back.contact_twist == pytest.approx(k)
    cfg = corrected_config(MonitorConfig(), back)
    assert cfg.vfs.contact_twist == 0.0  # APPLY_CONTACT_TWIST off: monitor unchanged
    monkeypatch.setattr(selfcal, "APPLY_CONTACT_TWIST", True)
    assert corrected_config(MonitorConfig(), back).vfs.contact_twist == pytest.approx(k)
    d = corr_m.to_dict()
    d.pop("contact_twist")
    old = ModelCorrections.from_dict(d)  # a file written before the twist
    assert old.contact_twist is None
    assert corrected_config(MonitorConfig(), old).vfs.contact_twist == 0.0
    lc = apply_corrections(cal_walk, back)
    cfg = cfg.replace(vfs=cfg.vfs.replace(contact_twist=k))
    x = lc[[f"force_{s}" for s in SENSOR_NAMES]].to_numpy(float)
    ref = lc[["contact_ref_r", "contact_ref_l"]].to_numpy(float) > 0.5
    planar = VirtualForceSensor.for_log(lc, cfg.vfs.replace(contact_twist=0.0)).run(lc)
    twisted = VirtualForceSensor.for_log(lc, cfg.vfs).run(lc)
    tw = np.array([1.0, -1.0, -1.0, 1.0])
    err = {"planar": [], "twisted": []}
    for si, side in enumerate("rl"):
        cols = [f"vfs_{side}{k}" for k in range(1, 5)]
        xs = x[:, 4 * si:4 * si + 4]
        # stance sole in single support, flat: the four cells and corners loaded
        m = (ref[:, si] & ~ref[:, 1 - si] & (xs.min(axis=1) > 0.02 * SURALP.weight)
             & (planar[cols].to_numpy(float).min(axis=1) > 0))
        for name, out in (("planar", planar), ("twisted", twisted)):
            err[name].append(((xs - out[cols].to_numpy(float)) @ tw)[m])
    rms = {k: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for k, v in err.items()}
    print(f"flat stance sole twist error RMS: {rms['twisted']:.2f} N, planar {rms['planar']:.2f} N")
    assert rms["twisted"] < 0.7 * rms["planar"]


def test_balanced_robot_per_corner_threshold_within_twice_the_exact_models(gap):
    """Issue 10, must-show 2's threshold bound on the all-gaps robot walking balanced
    (``controller = "balanced"``: the walk planned on its true body): calibrated with the
    weighed mass as ``grfguard calibrate --model`` does (rate low-pass chosen on the
    data; two settings here), its per-corner and foot-total thresholds stay within 2x
    those of the exact
    model calibrated on a walk of the same length and seed (40 s here; 60 s in
    ``bench_selfcal.py --controller balanced``: 1.55x on seed 1)."""
    robot = dataclasses.replace(gap, controller="balanced")
    walk = simulate(gait=GaitConfig(duration=40.0), seed=1, reality=robot)
    m_true = SURALP.mass * (1 + walk.attrs["reality"]["mass_error"])
    corr = estimate_corrections(walk, measured_mass_kg=m_true)
    # two settings of TWIN_FILTER_GRID to keep the test short: the 10 Hz Butterworth and
    # the setting calibrate --model chooses on this robot
    corr_b, rows = choose_twin_filter([apply_corrections(walk, corr)], corr,
                                      grid=((10.0, None), (8.0, 0.45)))
    th = calibrate_thresholds([apply_corrections(walk, corr_b)],
                              config=corrected_config(MonitorConfig(), corr_b))
    th_exact = calibrate_thresholds([simulate(gait=GaitConfig(duration=40.0), seed=1)])
    corner = th.corner_sigma * th.corner_h / (th_exact.corner_sigma * th_exact.corner_h)
    total = th.total_sigma * th.total_h / (th_exact.total_sigma * th_exact.total_h)
    assert corner <= 2.0 and total <= 2.0, (corner, total)
    assert not corr_b.use_accelerometer  # the vibrating IMU's accelerometer is left out
    assert rows[1]["chosen"]
