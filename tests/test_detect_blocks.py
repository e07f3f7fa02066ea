"""Detector building blocks on synthetic signals with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from grfguard.detect.blocks import (
    cusum,
    cusum_step,
    excursion_peaks,
    robust_scale,
    threshold_for_rate,
)
from grfguard.errors import ConfigError


class Cusum:
    """Independent array-at-a-time CUSUM (test reference for :func:`cusum`)."""

    def __init__(self, kappa: float, h: float, shape: tuple[int, ...] = ()) -> None:
        if kappa < 0:
            raise ConfigError("kappa must be >= 0")
        self.kappa, self.h = kappa, h
        self.g_pos = np.zeros(shape)
        self.g_neg = np.zeros(shape)

    def update(self, z: np.ndarray | float, mask: np.ndarray | bool = True) -> np.ndarray:
        z = np.asarray(z, dtype=float)
        ok = np.asarray(mask, bool) & np.isfinite(z)
        gp = np.where(ok, np.maximum(0.0, self.g_pos + np.where(ok, z, 0) - self.kappa),
                      self.g_pos)
        gn = np.where(ok, np.maximum(0.0, self.g_neg - np.where(ok, z, 0) - self.kappa),
                      self.g_neg)
        alarm = np.maximum(gp, gn) > self.h
        self.g_pos = np.where(alarm, 0.0, gp)
        self.g_neg = np.where(alarm, 0.0, gn)
        return alarm


def test_cusum_detects_mean_shift_with_known_delay() -> None:
    z = np.zeros(200)
    z[100:] = 3.0
    r = cusum(z, kappa=1.0, h=10.0)
    first = int(np.flatnonzero(r.alarm)[0])
    assert first == 105  # 2 per sample past kappa: 6 samples to exceed 10
    # reset: next alarm again 6 samples later
    assert int(np.flatnonzero(r.alarm)[1]) == 111
    neg = cusum(-z, kappa=1.0, h=10.0)
    assert int(np.flatnonzero(neg.alarm)[0]) == 105
    assert neg.g_pos.max() == 0


def test_cusum_gating_and_nan_hold() -> None:
    z = np.full(50, 3.0)
    mask = np.zeros(50, bool)
    mask[::2] = True
    z[10] = np.nan
    r = cusum(z, kappa=1.0, h=1e9, mask=mask)
    # only masked, finite samples add 2
    assert r.g_pos[-1] == pytest.approx(2.0 * 24)  # 25 masked samples, one NaN
    assert r.g_pos[1] == r.g_pos[0]


def test_cusum_batch_equals_streaming_multichannel() -> None:
    rng = np.random.default_rng(1)
    z = rng.normal(0, 1, (500, 3)) + np.array([0, 0.5, -2])
    mask = rng.random((500, 3)) < 0.8
    b = cusum(z, 0.5, 8.0, mask=mask)
    c = Cusum(0.5, 8.0, shape=(3,))
    for i in range(500):
        a = c.update(z[i], mask[i])
        assert np.array_equal(a, b.alarm[i])
        np.testing.assert_array_equal(c.g_pos, b.g_pos[i])
    assert b.alarm[:, 2].sum() > b.alarm[:, 0].sum()
    with pytest.raises(ConfigError):
        cusum(z, -1.0, 1.0)


def test_robust_scale_ignores_outliers() -> None:
    rng = np.random.default_rng(2)
    x = rng.normal(0, 2.0, (20000, 2))
    x[::100, 0] = 1e4
    s = robust_scale(x)
    assert s == pytest.approx([2.0, 2.0], rel=0.05)
    m = np.zeros(20000, bool)
    m[:5000] = True
    assert robust_scale(x[:, 1], mask=m) == pytest.approx(2.0, rel=0.08)


def test_threshold_for_rate_exponential_tail() -> None:
    rng = np.random.default_rng(4)
    peaks = rng.exponential(2.0, 10000)  # rate of peaks > x: 10000 exp(-x/2) per hour
    h = threshold_for_rate(peaks, duration_h=1.0, rate_per_hour=1e-2, safety=1.0)
    expected = 2.0 * np.log(10000 / 1e-2)
    assert h == pytest.approx(expected, rel=0.15)
    assert threshold_for_rate(peaks, 1.0, 1e-2, safety=10.0) >= 10 * peaks.max()
    assert threshold_for_rate([], 1.0, 1.0, floor=3.0) == 3.0
    stat = np.array([0, 1, 2, 0, 0, 5, 1, 0, 3])
    assert excursion_peaks(stat).tolist() == [2, 5, 3]


def test_scalar_cusum_step_matches_the_streaming_detector() -> None:
    rng = np.random.default_rng(7)
    z = rng.normal(2.0, 2.0, 500)
    det = Cusum(kappa=1.0, h=1e9)
    gp = gn = 0.0
    for zi in z:
        det.update(zi)
        gp, gn = cusum_step(gp, gn, float(zi), 1.0)
        assert gp == pytest.approx(float(det.g_pos)) and gn == pytest.approx(float(det.g_neg))
    assert gp > 100.0  # the 2 σ mean shift (above κ = 1) has accumulated
