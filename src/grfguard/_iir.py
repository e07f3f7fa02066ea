"""Butterworth low- and high-pass design without importing :mod:`scipy.signal`.

``scipy.signal`` takes about one second of CPU to import (it pulls in most of scipy),
which was a third of ``grfguard run``'s start-up although the monitor needs only the
coefficients of its low-pass filters. :func:`butter_lowpass` and :func:`lfilter_zi`
repeat scipy's own steps (``buttap`` → ``lp2lp_zpk`` → ``bilinear_zpk`` → ``zpk2tf``;
``lfilter_zi``) with numpy, operation for operation, so the coefficients are the same
to the last bit (``tests/test_iir.py`` compares them with scipy over orders 1-8 and
a grid of cut-off and sampling frequencies).
"""

from __future__ import annotations

import numpy as np

__all__ = ["butter_lowpass", "butter_highpass", "damped_lowpass", "lfilter_zi"]


def _poly(zeros: np.ndarray) -> np.ndarray:
    """Coefficients of the monic polynomial with these roots (scipy's ``_pu.poly``)."""
    if zeros.shape[0] == 0:
        return np.asarray(1.0, dtype=np.real(zeros).dtype)
    a = np.ones((1,), dtype=zeros.dtype)
    one = np.ones_like(zeros[0])
    for zero in zeros:
        a = np.convolve(a, np.stack((one, -zero)), mode="full")
    if np.iscomplexobj(a):
        roots = np.asarray(zeros, dtype=np.complex128)
        if np.all(np.sort(np.imag(roots)) == np.sort(np.imag(np.conj(roots)))):
            a = np.asarray(np.real(a), copy=True)
    return a


def butter_lowpass(order: int, cutoff_hz: float, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.signal.butter(order, cutoff_hz, btype="low", fs=fs_hz)``: ``(b, a)``.

    Raises:
        ValueError: ``order`` is not a non-negative integer or the cut-off is not in
            ``(0, fs_hz / 2)`` (scipy's conditions).
    """
    wn = np.asarray(cutoff_hz, dtype=np.float64)
    fs = float(fs_hz)
    return _butter(order, wn / (fs / 2), "low", f" (fs={fs} -> fs/2={fs / 2})")


def damped_lowpass(cutoff_hz: float, fs_hz: float, zeta: float, lead_s: float = 0.0,
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Second-order low-pass ``w^2 (1 + lead_s s) / (s^2 + 2 zeta w s + w^2)`` discretised
    by the bilinear transform prewarped at the cut-off: ``(b, a)`` with ``a[0] = 1``.
    ``zeta = 1/sqrt(2)`` is the second-order Butterworth (equal to :func:`butter_lowpass`
    to rounding, not bit for bit: use that one for the Butterworth); smaller ``zeta`` lags
    less and peaks. ``lead_s`` (default 0: the plain low-pass, same coefficients) adds a
    phase lead, ``y = LP(x) + lead_s d/dt LP(x)``: the low-frequency group delay drops
    from ``2 zeta / w`` to ``2 zeta / w - lead_s``, the DC gain stays 1, and the gain
    above the cut-off falls as ``1/f`` instead of ``1/f^2`` (more high-frequency noise).

    Raises:
        ValueError: the cut-off is not in ``(0, fs_hz / 2)``, ``zeta`` is not positive or
            ``lead_s`` is negative.
    """
    fs = float(fs_hz)
    cut = float(cutoff_hz)
    if not (0.0 < cut < fs / 2.0):
        raise ValueError(f"Digital filter critical frequencies must be 0 < Wn < fs/2 "
                         f"(fs={fs} -> fs/2={fs / 2}); got {cut}")
    if not (float(zeta) > 0.0):
        raise ValueError(f"the damping of a low-pass must be positive; got {zeta}")
    if not (float(lead_s) >= 0.0):
        raise ValueError(f"the lead of a low-pass must be 0 or positive [s]; got {lead_s}")
    w = 2.0 * fs * np.tan(np.pi * cut / fs)
    k = 2.0 * fs
    a = np.array([k * k + 2.0 * zeta * w * k + w * w, 2.0 * w * w - 2.0 * k * k,
                  k * k - 2.0 * zeta * w * k + w * w])
    if lead_s:
        tk = float(lead_s) * k  # (1 + tau s)(1 + z^-1)^2 with s = k (1 - z^-1) / (1 + z^-1)
        b = np.array([w * w * (1.0 + tk), 2.0 * w * w, w * w * (1.0 - tk)])
    else:
        b = np.array([w * w, 2.0 * w * w, w * w])
    return b / a[0], a / a[0]


def butter_highpass(order: int, wn: float) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.signal.butter(order, wn, "highpass")``: ``(b, a)``, ``wn`` the cut-off as
    a fraction of the Nyquist frequency.

    Raises:
        ValueError: ``order`` is not a non-negative integer or ``wn`` is not in ``(0, 1)``.
    """
    return _butter(order, np.asarray(wn, dtype=np.float64), "high", "")


def _butter(order: int, wn: np.ndarray, btype: str, fs_text: str
            ) -> tuple[np.ndarray, np.ndarray]:
    """scipy's ``iirfilter`` for a Butterworth low- or high-pass, ``wn`` normalised."""
    if abs(int(order)) != order:
        raise ValueError("Filter order must be a nonnegative integer")
    if np.ndim(wn) != 0:
        raise ValueError("a low- or high-pass filter has a single cut-off frequency")
    if np.any(wn <= 0) or np.any(wn >= 1):
        if fs_text:
            raise ValueError(f"Digital filter critical frequencies must be 0 < Wn < fs/2"
                             f"{fs_text}")
        raise ValueError("Digital filter critical frequencies must be 0 < Wn < 1")
    # analog prototype (buttap)
    z = np.asarray([], dtype=np.float64)
    m = np.arange(-order + 1, order, 2, dtype=np.float64)
    p = -np.exp(1j * np.pi * m / (2 * order))
    k = 1.0
    # pre-warp (fs = 2 from here on, as scipy)
    fs = 2.0
    warped = 2 * fs * np.tan(np.pi * wn / fs)
    wo = float(warped)
    degree = p.shape[0] - z.shape[0]
    if btype == "low":  # lp2lp_zpk
        z = wo * z
        p = wo * p
        k = k * wo**degree
    else:  # lp2hp_zpk
        z_hp = wo / z
        p_hp = wo / p
        z_hp = np.concatenate((z_hp, np.zeros(degree)))
        k = k * np.real(np.prod(-z) / np.prod(-p))
        z, p = z_hp, p_hp
        degree = 0
    # bilinear_zpk
    fs2 = 2.0 * fs
    z_z = (fs2 + z) / (fs2 - z)
    p_z = (fs2 + p) / (fs2 - p)
    z_z = np.concatenate((z_z, -np.ones(degree)))
    k_z = k * np.real(np.prod(fs2 - z) / np.prod(fs2 - p))
    # zpk2tf
    kk = np.asarray(k_z, dtype=np.result_type(np.real(z_z), np.real(p_z), k_z))
    b = np.multiply(np.atleast_1d(kk), _poly(z_z))
    a = np.atleast_1d(np.asarray(_poly(p_z)))
    return b, a


def lfilter_zi(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """``scipy.signal.lfilter_zi(b, a)``: the state of a filter at rest under a unit step."""
    b = np.atleast_1d(np.asarray(b))
    a = np.atleast_1d(np.asarray(a))
    if b.ndim != 1 or a.ndim != 1:
        raise ValueError("b and a must be 1-D")
    while a.shape[0] > 1 and a[0] == 0.0:
        a = a[1:]
    if a.size < 1:
        raise ValueError("There must be at least one nonzero `a` coefficient.")
    if a[0] != 1.0:
        b = b / a[0]
        a = a / a[0]
    n = max(a.shape[0], b.shape[0])
    if a.shape[0] < n:
        a = np.concatenate((a, np.zeros(n - a.shape[0], dtype=a.dtype)))
    elif b.shape[0] < n:
        b = np.concatenate((b, np.zeros(n - b.shape[0], dtype=b.dtype)))
    dt = np.result_type(a, b)
    # scipy.linalg.companion(a): first row -a[1:] / a[0], ones below the diagonal
    c = np.zeros((n - 1, n - 1), dtype=np.result_type(a.dtype, 1.0))
    if n > 1:
        c[0] = -a[1:] / (1.0 * a[0])
        c[list(range(1, n - 1)), list(range(0, n - 2))] = 1
    iminus_a = np.asarray(np.eye(n - 1) - c.T, dtype=dt)
    bb = b[1:] - a[1:] * b[0]
    return np.linalg.solve(iminus_a, bb)
