"""The compiled Savitzky-Golay filters (:mod:`grfguard.kernels.savgol`) give scipy's
``savgol_filter(..., mode="interp")`` bit for bit (symmetric, antisymmetric and general
weights; the polynomial edges; windows from 5 to 1001 samples; several rates), and the
leveled attitude's closed-form orthonormalisation equals the SVD's."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import savgol_coeffs, savgol_filter

from grfguard.estimate.wrench import _derivs, _small_rotations
from grfguard.kernels.savgol import _symmetry, savgol_many


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


def test_leveled_attitude_closed_form_equals_svd() -> None:
    rng = np.random.default_rng(2)
    for scale in (1e-7, 1e-3, 0.05, 0.5):
        rv = rng.normal(size=(500, 3)) * scale
        K = np.zeros((500, 3, 3))
        K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -rv[:, 2], rv[:, 1], -rv[:, 0]
        K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = rv[:, 2], -rv[:, 1], rv[:, 0]
        U, _, Vt = np.linalg.svd(np.eye(3) + K)
        R = _small_rotations(rv)
        assert np.abs(R - U @ Vt).max() <= 1e-12
        assert np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max() <= 1e-14
        np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)
