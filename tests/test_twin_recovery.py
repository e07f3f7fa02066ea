"""The vibration twin sensor after a stretch of unusable samples: back by ``settle_s``.

A 5 s simulated SURALP walk with the accelerometer vibration of the iCub spectrum
(``reality=vibration``: the monitor uses the twin virtual sensor without the
accelerometer from 0.5 s on), 30 or 31 ms of NaN joint angles in the final double
support (3.0 s) or in single support (2.5 s), compared with the same walk without the
stretch.

The leg odometry's former rule moves the anchor to the other stance foot whenever that
one is flat: in a flat double support the anchor alternates every sample, and the twin's
forces (the IMU acceleration is the odometry's second difference, no accelerometer to
take over above 1 Hz) depend on that alternation's parity. A stretch of an odd number of
samples (as seen from the alternation) flips it: ~100 N apart from the walk without the
stretch until the next single support, both equally far from the true forces. With
``VFSConfig.anchor_hold`` the flat anchor stays and the twin is back within 2 N by
``settle_s`` after every stretch. BENCHMARKS.md "Twin sensor after a break".
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from grfguard.detect import Monitor
from grfguard.detect.config import MonitorConfig
from grfguard.estimate.config import VFSConfig
from grfguard.guard import GuardConfig
from grfguard.model.robot import SENSOR_NAMES, SURALP
from grfguard.sim import GaitConfig, NoiseConfig, simulate
from grfguard.sim.reality import load_reality

VFS = [f"vfs_{s}" for s in SENSOR_NAMES]
FLAGS = [f"flag_{s}" for s in SENSOR_NAMES]
SETTLE = GuardConfig().settle_s
HOLD = MonitorConfig(vfs=VFSConfig(anchor_hold=True))


@pytest.fixture(scope="module")
def walk() -> pd.DataFrame:
    return simulate(SURALP, GaitConfig(duration=5.0), NoiseConfig(), seed=0,
                    reality=load_reality("vibration"))


def _nan_joints(log: pd.DataFrame, t0: float, ms: int) -> tuple[pd.DataFrame, int]:
    t = log["time"].to_numpy()
    gap = (t >= t0 - 1e-9) & (t < t0 + ms * 1e-3 - 1e-9)
    bad = log.copy()
    bad.loc[gap, [c for c in log.columns if c.startswith("q_")]] = np.nan
    return bad, int(np.flatnonzero(gap)[-1]) + 1


def _after(out: pd.DataFrame, ref: pd.DataFrame, first: int, dt: float) -> float:
    """max |vfs - vfs without the stretch| from ``settle_s`` after the stretch on [N]."""
    k = first + int(round(SETTLE / dt))
    return float(np.abs(out[VFS].to_numpy(float)[k:] - ref[VFS].to_numpy(float)[k:]).max())


@pytest.fixture(scope="module")
def reference(walk):
    return {name: Monitor.for_log(walk, config=cfg).run(walk)
            for name, cfg in (("hold", HOLD), ("former", None))}


def test_the_anchor_rule_is_documented_by_the_former_parity(walk, reference):
    """Without ``anchor_hold`` the twin's forces after 30 ms of NaN joints in the final
    double support stay ~100 N from the walk without the stretch (31 ms: back)."""
    dt = float(walk["time"].diff().median())
    ref = reference["former"]
    errs = {}
    for ms in (30, 31):
        bad, first = _nan_joints(walk, 3.0, ms)
        errs[ms] = _after(Monitor.for_log(bad).run(bad), ref, first, dt)
    assert errs[30] > 50.0 and errs[31] < 5.0, errs


@pytest.mark.parametrize("t0", [3.0, 2.5])
@pytest.mark.parametrize("ms", [30, 31])
def test_the_twin_is_back_by_settle_s_with_anchor_hold(walk, reference, t0, ms):
    dt = float(walk["time"].diff().median())
    bad, first = _nan_joints(walk, t0, ms)
    mon = Monitor.for_log(bad, config=HOLD)
    assert mon.vibration is not None and mon.compiled_reason() == ""
    out = mon.run(bad)
    ref = reference["hold"]
    err = _after(out, ref, first, dt)
    print(f"NaN joints {ms} ms at {t0} s: max |dvfs| from settle_s after: {err:.3g} N")
    assert err < 2.0, err
    assert not (out[FLAGS].to_numpy(bool) & ~ref[FLAGS].to_numpy(bool)).any()
    # the pure-Python monitor gives the same bits
    py = Monitor.for_log(bad, config=HOLD, compiled=False).run(bad)
    for c in out.columns:
        a, b = out[c].to_numpy(), py[c].to_numpy()
        if a.dtype.kind in "fb" and b.dtype.kind in "fb":
            np.testing.assert_array_equal(a.astype(float).view(np.int64),
                                          b.astype(float).view(np.int64), err_msg=c)
        else:
            np.testing.assert_array_equal(a.astype(str), b.astype(str), err_msg=c)


def test_anchor_hold_keeps_the_twin_as_accurate(walk, reference):
    """The held anchor does not cost accuracy: the twin's error against the true forces
    in double and single support (from 1 s on) is no larger than with the former rule."""
    t = walk["time"].to_numpy()
    truth = walk[[f"true_force_{s}" for s in SENSOR_NAMES]].to_numpy(float)
    cref = walk[["contact_ref_r", "contact_ref_l"]].to_numpy(float) > 0.5
    ds = cref.all(axis=1)
    rms = {}
    for name, out in reference.items():
        e = out[VFS].to_numpy(float) - truth
        rms[name] = [float(np.sqrt(np.mean(e[m & (t >= 1.0)] ** 2))) for m in (ds, ~ds)]
    assert rms["hold"][0] < rms["former"][0], rms
    assert rms["hold"][1] < 1.02 * rms["former"][1], rms


def test_anchor_hold_is_a_setting_of_its_own():
    cfg = VFSConfig()
    assert cfg.anchor_hold is False
    hold = dataclasses.replace(cfg, anchor_hold=True)
    assert hold.anchor_hold is True
    assert VFSConfig.from_toml(hold.to_toml()) == hold != cfg
    with pytest.raises(Exception, match="anchor_hold"):
        VFSConfig(anchor_hold=1)  # type: ignore[arg-type]


def test_a_twin_with_another_anchor_rule_does_not_share_the_front(walk):
    """The twin takes the main sensor's odometry only when both follow the same rule."""
    from grfguard.detect.system import quiet_vfs_config
    from grfguard.estimate.vfs import VirtualForceSensor
    from grfguard.kernels.vfs import twin_shareable

    def shareable(main_hold: bool, twin_hold: bool) -> bool:
        m = VirtualForceSensor.for_log(walk, VFSConfig(anchor_hold=main_hold))
        q = VirtualForceSensor.for_log(walk, quiet_vfs_config(VFSConfig(anchor_hold=twin_hold)))
        return twin_shareable(m.kernel(), q.kernel())

    assert shareable(False, False) and shareable(True, True)
    assert not shareable(False, True) and not shareable(True, False)


def test_streaming_equals_batch_with_anchor_hold(walk):
    bad, first = _nan_joints(walk, 3.0, 30)
    n = first + 400  # through the stretch and the settling
    rows = bad.iloc[:n].to_dict("records")
    for compiled in (True, False):
        mon = Monitor.for_log(bad, config=HOLD, compiled=compiled)
        out = mon.run(bad)
        mon.reset()
        st = pd.DataFrame([mon.update(r) for r in rows], index=bad.index[:n])
        for c in VFS:
            np.testing.assert_array_equal(st[c].to_numpy(float),
                                          out[c].to_numpy(float)[:n], err_msg=c)
        np.testing.assert_array_equal(st[FLAGS].to_numpy(bool),
                                      out[FLAGS].to_numpy(bool)[:n])
