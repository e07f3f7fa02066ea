"""The detector's stages on synthetic inputs with known answers (fit, kinds, clearing,
constant-reading test, foot-total isolation)."""

from __future__ import annotations

import numpy as np
import pytest

from grfguard.detect.classify import add_swing_sample, classify, maybe_clear
from grfguard.detect.config import MonitorConfig
from grfguard.detect.residual_tests import FootTotalTest, constant_test, swing_test
from grfguard.detect.sensor_state import SensorState, SwingFit
from grfguard.detect.thresholds import Thresholds
from grfguard.detect.tuning import DetectTuning

DT = 1e-3
SIG = 2.0
TN = DetectTuning()


def test_swing_fit_recovers_an_exact_line() -> None:
    fit = SwingFit()
    for k in range(200):
        fit.add(k * DT, 30.0 + 15.0 * k * DT)
    a, b, sd, se = fit.fit()
    assert a == pytest.approx(30.0, abs=1e-9)
    assert b == pytest.approx(15.0, abs=1e-6)
    assert sd < 1e-6 and se < 1e-6
    assert SwingFit().fit()[0] != SwingFit().fit()[0]  # NaN without data


def _flagged_in_swing(signal: np.ndarray) -> SensorState:
    s = SensorState()
    s.flag, s.source, s.flag_time_s = True, "swing", 0.0
    for k, xi in enumerate(signal):
        add_swing_sample(s, k * DT, float(xi), SIG, TN, DT)
        classify(s, k * DT, float(xi), SIG, TN, DT)
    return s


@pytest.mark.parametrize(
    ("name", "kind"), [("offset", "offset"), ("drift", "drift"), ("noise", "noise"),
                       ("spikes", "spikes")])
def test_swing_kinds(name: str, kind: str) -> None:
    rng = np.random.default_rng(0)
    t = np.arange(400) * DT
    noise = rng.normal(0.0, SIG, t.size)
    signal = {
        "offset": 50.0 + noise,
        "drift": 10.0 + 30.0 * t + noise,
        "noise": rng.normal(0.0, 25.0, t.size),
        "spikes": noise + np.where(np.arange(t.size) % 97 == 50, 120.0, 0.0),
    }[name]
    s = _flagged_in_swing(signal)
    assert s.kind == kind
    if kind == "offset":
        assert s.eta_n == pytest.approx(50.0, abs=0.5)
    if kind == "drift":
        assert s.eta_n == pytest.approx(10.0 + 30.0 * t[-1], abs=1.0)
    if kind == "spikes":
        assert s.swing.outliers == 4  # isolated, excluded from the fit


def test_stance_only_gain_and_offset() -> None:
    rng = np.random.default_rng(1)
    loads = rng.uniform(100.0, 600.0, 200)
    for true_gain, kind in ((1.6, "gain"), (1.0, "offset")):
        s = SensorState()
        s.flag, s.source = True, "total"
        for load in loads:
            res = (true_gain - 1.0) * load + (40.0 if kind == "offset" else 0.0)
            s.stance.add(res + rng.normal(0, 2.0), load, TN.stance_eta_factor)
        classify(s, 1.0, 0.0, SIG, TN, DT)
        assert s.kind == kind
        if kind == "gain":
            assert s.gain == pytest.approx(1.6, abs=0.01)
        else:
            assert s.eta_n == pytest.approx(40.0, abs=3.0)


def test_dropout_clears_after_a_fifth_of_clear_s() -> None:
    cfg = MonitorConfig()
    s = SensorState()
    s.flag, s.source, s.last_alarm_s = True, "nan", 1.0
    t_clear = None
    for k in range(1, 1000):
        t = 1.0 + k * DT
        maybe_clear(s, t, 10.0, True, cfg, TN)
        if not s.flag:
            t_clear = t
            break
    assert t_clear == pytest.approx(1.0 + TN.clear_dropout_fraction * cfg.clear_s, abs=2 * DT)


def test_constant_reading_alarms_only_when_loaded() -> None:
    n = DetectTuning().const_samples(Thresholds().const_s, 1e-3)
    for loaded, expect in ((True, True), (False, False)):
        s = SensorState()
        hits = [constant_test(s, 123.0, loaded, n) for _ in range(n)]
        assert hits[-1] is expect and not any(hits[:-1])


def test_swing_test_threshold_in_sigma_samples() -> None:
    th = Thresholds()
    s = SensorState()
    z = 5.0  # a 10 N offset: (5 - kappa) per sample above the allowance
    k_alarm = next(k for k in range(1000) if swing_test(s, z * th.sigma_swing_n, th)[0])
    assert k_alarm + 1 == int(np.floor(th.swing_h / (z - th.swing_kappa))) + 1


def test_foot_total_votes_isolate_the_biased_corner() -> None:
    th = Thresholds()
    test = FootTotalTest()
    sens = [SensorState() for _ in range(4)]
    vfs = [150.0, 150.0, 100.0, 100.0]
    corr = [150.0, 150.0 + 60.0, 100.0, 100.0]  # corner 2 reads 60 N high
    alarmed: list[int] = []
    for _ in range(500):
        _, _, stat = test.step(0, corr, vfs, sum(vfs), 1000.0, th)
        if stat > th.total_h:
            alarmed = test.isolate(0, sens)
            break
    assert alarmed == [1]
