"""The paper's fault observer: steady-state vs full KF, batch vs streaming, threshold."""

from __future__ import annotations

import numpy as np
import pytest

from grfguard.detect.observer import (
    FaultObserver,
    ObserverConfig,
    kalman_gain_sequence,
    lowpass,
    paper_threshold,
    run_observer,
    steady_state_gain,
)
from grfguard.errors import ConfigError


@pytest.fixture(scope="module")
def signals() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    t = np.arange(0, 20, 1e-3)
    true = 200 + 150 * np.sin(2 * np.pi * 0.5 * t[:, None] + np.arange(8))
    fault = np.zeros_like(true)
    fault[t >= 5, 1] = 100.0
    fault[t >= 5, 2] = 15 * (t[t >= 5] - 5)
    meas = true + fault + rng.normal(0, 2, true.shape)
    vfs = true + rng.normal(0, 5, true.shape)
    return meas, vfs, fault


def test_gain_matches_riccati_iteration_and_sqrt_rule() -> None:
    g = steady_state_gain()
    ks = kalman_gain_sequence(20000)
    assert g.k_eta < 0 < g.k_n
    np.testing.assert_allclose(ks[-1], [g.k_eta, g.k_n], rtol=1e-6)
    assert g.k == pytest.approx(np.sqrt(1e-10 / 1e-4), rel=0.01)
    # only q/r matters
    g2 = steady_state_gain(ObserverConfig(q=1e-8, r=1e-2))
    assert g2.k == pytest.approx(g.k, rel=1e-6)


def test_full_and_steady_state_converge(signals) -> None:
    meas, vfs, fault = signals
    full = run_observer(meas, vfs, full=True)
    ss = run_observer(meas, vfs)
    late = slice(15000, None)
    np.testing.assert_allclose(full.eta_n[late], ss.eta_n[late], atol=1e-3)
    # the fault estimate tracks the offset within a few N after ~5 time constants
    assert abs(ss.eta_filtered_n[-1, 1] - 100) < 5
    assert abs(ss.eta_filtered_n[-1, 0]) < 3
    # N̂ is close to the true force
    true = meas - fault
    assert np.sqrt(np.mean((ss.force_n[late, 0] - true[late, 0]) ** 2)) < 5


@pytest.mark.parametrize("full", [False, True])
def test_batch_equals_streaming(signals, full: bool) -> None:
    meas, vfs, _ = signals
    meas = meas[:3000].copy()
    vfs = vfs[:3000]
    meas[1000:1010, 3] = np.nan  # missing samples: predict only
    batch = run_observer(meas, vfs, full=full)
    obs = FaultObserver(8, full=full)
    eta = np.empty_like(meas)
    force = np.empty_like(meas)
    etaf = np.empty_like(meas)
    for i in range(len(meas)):
        eta[i], force[i], etaf[i] = obs.update(meas[i], vfs[i])
    np.testing.assert_allclose(eta, batch.eta_n, rtol=0, atol=1e-9)
    np.testing.assert_allclose(force, batch.force_n, rtol=0, atol=1e-9)
    np.testing.assert_allclose(etaf, batch.eta_filtered_n, rtol=0, atol=1e-9)
    assert np.all(np.isfinite(eta))
    obs.reset()
    assert np.all(obs.eta_n == 0)


def test_lowpass_step_and_threshold() -> None:
    cfg = ObserverConfig(lowpass_hz=1.0)
    y = lowpass(np.ones(1000), cfg)
    # first-order: 1 - exp(-2π f t) at t = 1 s
    assert y[-1] == pytest.approx(1 - np.exp(-2 * np.pi * 0.999 - 2 * np.pi * 1e-3), rel=1e-3)
    flags = paper_threshold(np.array([[1.0, -5.0], [3.0, 0.5]]), np.array([2.0, 4.0]))
    assert flags.tolist() == [[False, True], [True, False]]


def test_config_validation() -> None:
    with pytest.raises(ConfigError, match="observer.q"):
        ObserverConfig(q=-1.0)
    with pytest.raises(ConfigError, match="dt_s"):
        ObserverConfig(dt_s=0.0)
    with pytest.raises(ConfigError, match="shape"):
        run_observer(np.zeros((3, 8)), np.zeros((3, 7)))
