"""The compiled Savitzky-Golay filters (:mod:`grfguard.kernels.savgol`) give scipy's
``savgol_filter(..., mode="interp")`` bit for bit (symmetric, antisymmetric and general
weights; the polynomial edges; windows from 5 to 1001 samples; several rates); the
sliding-moment form (``sliding=True``) within 100 rounding units of the direct sum."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import savgol_coeffs, savgol_filter

from grfguard.estimate.wrench import _derivs
from grfguard.kernels.savgol import _edge_maps, _symmetry, savgol_many


def _scipy(x: np.ndarray, win: int, order: int, dt: float) -> np.ndarray:
    return savgol_filter(x, win, 3, deriv=order, delta=dt, axis=0, mode="interp")


@pytest.fixture(scope="module")
def signals() -> np.ndarray:
    rng = np.random.default_rng(5)
    n = 6000
    t = np.arange(n)[:, None] * 0.001
    return (np.sin(t * (1.0 + np.arange(9))) * 0.7 + np.cumsum(rng.normal(size=(n, 9)), 0)
            * 1e-3 + rng.normal(size=(n, 9)) * 1e-4)


@pytest.mark.parametrize("win", [5, 11, 101, 1001])
@pytest.mark.parametrize("dt", [0.001, 0.004, 0.01, 1.0])
def test_bit_identical_to_scipy(signals, win, dt) -> None:
    got = savgol_many(signals, win, (0, 1, 2), dt)
    for order, g in zip((0, 1, 2), got, strict=True):
        np.testing.assert_array_equal(g, _scipy(signals, win, order, dt),
                                      err_msg=f"order {order}")
        assert g.shape == signals.shape and g.flags.c_contiguous


def test_every_weight_symmetry_is_exercised() -> None:
    """The three code paths of scipy's correlation (and so of the kernel) all occur in the
    parametrisation above."""
    seen = {_symmetry(np.asarray(savgol_coeffs(w, 3, deriv=o, delta=dt))[::-1])
            for w in (5, 11, 101, 1001) for o in (0, 1, 2) for dt in (0.001, 1.0)}
    assert seen == {-1, 0, 1}


def test_window_as_long_as_the_log_and_one_column(signals) -> None:
    x = signals[:101, :1]
    for order, g in zip((0, 2), savgol_many(x, 101, (0, 2), 0.001), strict=True):
        np.testing.assert_array_equal(g, _scipy(x, 101, order, 0.001))
    one = signals[:, 0]  # 1-D input: scipy itself
    np.testing.assert_array_equal(_derivs(one, 11, (1,), 0.001)[0], _scipy(one, 11, 1, 0.001))
    with pytest.raises(ValueError, match="odd window"):
        savgol_many(x, 103, (0,), 0.001)


def test_nan_stays_local_as_in_scipy(signals) -> None:
    x = signals.copy()
    x[3000, 2] = np.nan
    for order, g in zip((0, 1), savgol_many(x, 11, (0, 1), 0.001), strict=True):
        np.testing.assert_array_equal(g, _scipy(x, 11, order, 0.001))


def test_virtual_wrenches_as_with_scipy_filters(talos, monkeypatch) -> None:
    """The whole Talos virtual wrench estimate with the compiled filters (sliding moments)
    equals the one with scipy's ``savgol_filter`` on the same column groups to 1e-9 N."""
    pytest.importorskip("mujoco")
    import grfguard.estimate.wrench as wrench
    from grfguard.sim.config import NoiseConfig
    from grfguard.sim.wholebody import scaled_gait, simulate_robot

    df = simulate_robot(talos, scaled_gait(talos, duration=4.0), NoiseConfig(), seed=2)
    got = wrench.estimate_wrenches(df, talos)

    def scipy_derivs(x, win, orders, dt):
        return [_scipy(x, win, o, dt) for o in orders]

    monkeypatch.setattr(wrench, "_derivs", scipy_derivs)
    want = wrench.estimate_wrenches(df, talos)
    assert np.abs(got.ground - want.ground).max() <= 1e-9
    for k in want.sensor:
        assert np.abs(got.sensor[k] - want.sensor[k]).max() <= 1e-9, k


@pytest.mark.parametrize("win", [101, 1001])
def test_fft_interior_equals_direct_sum(signals, win) -> None:
    """``fft=True`` (the blend's long window): the interior within 1e-13 of the signal's
    scale of the direct (scipy-exact) sum, the polynomial edges bit for bit."""
    h = win // 2
    for o, (d, f) in enumerate(zip(savgol_many(signals, win, (0, 1, 2), 0.001),
                                   savgol_many(signals, win, (0, 1, 2), 0.001, fft=True),
                                   strict=True)):
        assert np.abs(f - d).max() <= 1e-13 * np.abs(d).max(), o
        np.testing.assert_array_equal(f[:h], d[:h])
        np.testing.assert_array_equal(f[-h:], d[-h:])
        assert f.shape == d.shape and f.flags.c_contiguous


@pytest.mark.parametrize("win", [33, 101, 201, 1001])
@pytest.mark.parametrize("dt", [0.001, 0.01])
def test_sliding_moments_equal_direct_sum(signals, win, dt) -> None:
    """``sliding=True``: the interior within 100 rounding units of scipy's direct sum
    (``eps max|x| sum|w|``; measured 8-45), the polynomial edges (a precomputed linear
    map) within 100 of theirs (``eps max|x|`` times the map's largest row sum)."""
    h = win // 2
    got = savgol_many(signals, win, (0, 1, 2), dt, sliding=True)
    for o, g in enumerate(got):
        want = _scipy(signals, win, o, dt)
        unit = np.finfo(float).eps * np.abs(signals).max() * np.abs(
            savgol_coeffs(win, 3, deriv=o, delta=dt)).sum()
        assert np.abs(g - want).max() <= 100 * unit, o
        assert not np.array_equal(g[h:-h], want[h:-h])  # the sliding path ran
        E = _edge_maps(win, 3, (0, 1, 2), dt)[o]
        e_unit = np.finfo(float).eps * np.abs(signals).max() * np.abs(E).sum(axis=-1).max()
        assert np.abs(g[:h] - want[:h]).max() <= 100 * e_unit, o
        assert np.abs(g[-h:] - want[-h:]).max() <= 100 * e_unit, o
        assert g.shape == signals.shape and g.flags.c_contiguous


def test_sliding_falls_back_to_the_direct_sum(signals) -> None:
    """Short windows and non-finite inputs keep the direct sum (scipy's bits): a NaN stays
    local instead of living in the moments."""
    x = signals.copy()
    x[3000, 2] = np.nan
    for xx, win in ((signals, 11), (x, 101)):
        for o, g in enumerate(savgol_many(xx, win, (0, 1), 0.001, sliding=True)):
            np.testing.assert_array_equal(g, _scipy(xx, win, o, 0.001))
