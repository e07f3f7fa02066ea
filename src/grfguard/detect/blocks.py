"""Building blocks of detectors: gated two-sided CUSUM, robust scale, calibration tails.

The CUSUM has a batch function on arrays (:func:`cusum`, used by the calibration) and a
scalar step (:func:`cusum_step`, used by the 1 kHz detector); both give identical
numbers (tests assert it). Residuals are normalised (divided by their
noise scale) before they reach a CUSUM, so thresholds are in units of σ·samples.

Two-sided CUSUM with drift allowance ``κ`` and threshold ``h`` on a normalised
residual ``z``, updated only where ``mask`` is true (elsewhere it holds):

.. math::

    g^+_k = \\max(0, g^+_{k-1} + z_k - κ),\\qquad g^-_k = \\max(0, g^-_{k-1} - z_k - κ)

An alarm is raised when ``max(g^+, g^-) > h``; with ``reset=True`` both sums restart
from zero after an alarm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grfguard.errors import ConfigError

__all__ = [
    "CusumResult",
    "cusum",
    "cusum_step",
    "robust_scale",
    "excursion_peaks",
    "threshold_for_rate",
]


@dataclass(frozen=True)
class CusumResult:
    """Output of :func:`cusum`, arrays of shape (T,) or (T, n).

    Attributes:
        g_pos: Upper sum ``g⁺`` [σ].
        g_neg: Lower sum ``g⁻`` [σ].
        alarm: True where ``max(g⁺, g⁻) > h`` (the sums are stored after the reset).
    """

    g_pos: np.ndarray
    g_neg: np.ndarray
    alarm: np.ndarray


def _check_cusum(kappa: float, h: float) -> None:
    if not (kappa >= 0 and math.isfinite(kappa)):
        raise ConfigError(f"cusum kappa = {kappa!r} must be a finite number >= 0 [σ]")
    if not (h > 0):
        raise ConfigError(f"cusum h = {h!r} must be > 0 [σ·samples]")


def cusum(
    z: np.ndarray,
    kappa: float,
    h: float,
    mask: np.ndarray | None = None,
    reset: bool = True,
) -> CusumResult:
    """Gated two-sided CUSUM over a normalised residual (batch).

    Args:
        z: Normalised residual [σ], shape (T,) or (T, n). NaN samples are skipped.
        kappa: Drift allowance ``κ`` [σ].
        h: Alarm threshold [σ·samples] (``inf`` never alarms).
        mask: Where the test is valid (bool, broadcastable to ``z``); elsewhere the sums hold.
        reset: Restart the sums from zero after an alarm.

    Returns:
        :class:`CusumResult`.
    """
    _check_cusum(kappa, h)
    z = np.asarray(z, dtype=float)
    m = np.ones(z.shape, bool) if mask is None else np.broadcast_to(mask, z.shape)
    gp = np.empty(z.shape)
    gn = np.empty(z.shape)
    al = np.empty(z.shape, bool)
    g_pos = np.zeros(z.shape[1:])
    g_neg = np.zeros(z.shape[1:])
    for i in range(z.shape[0]):
        ok = m[i] & np.isfinite(z[i])
        zz = np.where(ok, z[i], 0.0)
        g_pos = np.where(ok, np.maximum(0.0, g_pos + zz - kappa), g_pos)
        g_neg = np.where(ok, np.maximum(0.0, g_neg - zz - kappa), g_neg)
        al[i] = np.maximum(g_pos, g_neg) > h
        if reset and np.any(al[i]):
            g_pos = np.where(al[i], 0.0, g_pos)
            g_neg = np.where(al[i], 0.0, g_neg)
        gp[i] = g_pos
        gn[i] = g_neg
    return CusumResult(gp, gn, al)


def cusum_step(g_pos: float, g_neg: float, z: float, kappa: float) -> tuple[float, float]:
    """One scalar step of the two-sided CUSUM (plain floats, for the 1 kHz loop).

    Args:
        g_pos: Upper sum before the sample [σ·samples].
        g_neg: Lower sum before the sample [σ·samples].
        z: Normalised residual of the sample [σ].
        kappa: Drift allowance [σ].

    Returns:
        The new ``(g_pos, g_neg)``, both >= 0.
    """
    gp = g_pos + z - kappa
    gn = g_neg - z - kappa
    return (gp if gp > 0.0 else 0.0), (gn if gn > 0.0 else 0.0)


def robust_scale(x: np.ndarray, mask: np.ndarray | None = None, axis: int = 0) -> np.ndarray:
    """Robust standard deviation ``1.4826 · median(|x - median(x)|)`` ignoring NaN.

    Args:
        x: Samples, shape (T,) or (T, n).
        mask: Samples to use (bool, same shape or (T,)).
        axis: Time axis.

    Returns:
        Scale per channel (NaN where no sample is usable).
    """
    x = np.array(x, dtype=float, copy=True)
    if mask is not None:
        m = np.asarray(mask, bool)
        if m.ndim < x.ndim:
            m = m.reshape(m.shape + (1,) * (x.ndim - m.ndim))
        x = np.where(np.broadcast_to(m, x.shape), x, np.nan)
    if np.all(np.isnan(x)):
        return np.full(np.delete(np.array(x.shape), axis), np.nan) if x.ndim > 1 else np.nan
    med = np.nanmedian(x, axis=axis, keepdims=True)
    return 1.4826 * np.nanmedian(np.abs(x - med), axis=axis)


def excursion_peaks(stat: np.ndarray) -> np.ndarray:
    """Peak value of every excursion of a non-negative statistic away from zero (1-D)."""
    s = np.asarray(stat, dtype=float)
    s = np.where(np.isfinite(s), s, 0.0)
    pos = s > 0
    if not pos.any():
        return np.zeros(0)
    edges = np.flatnonzero(np.diff(np.concatenate([[False], pos, [False]]).astype(int)))
    starts, ends = edges[0::2], edges[1::2]
    return np.maximum.reduceat(s, starts)[: len(ends)]


def threshold_for_rate(
    peaks: np.ndarray,
    duration_h: float,
    rate_per_hour: float,
    safety: float = 1.5,
    floor: float = 0.0,
) -> float:
    """Threshold on a statistic for a target false-alarm rate from fault-free excursion peaks.

    The tail of the excursion peaks is fitted with an exponential (CUSUM peaks have
    an exponential tail); the threshold where the fitted rate equals ``rate_per_hour``
    is returned, never below ``safety`` × the largest observed peak nor ``floor``.

    Args:
        peaks: Excursion peaks observed in ``duration_h`` hours of fault-free data.
        duration_h: Observed (valid) time in [h].
        rate_per_hour: Target false-alarm rate [1/h].
        safety: Factor on the largest observed peak.
        floor: Lower bound of the threshold.
    """
    if not (rate_per_hour > 0) or not (duration_h > 0):
        raise ConfigError(
            f"threshold_for_rate needs rate_per_hour > 0 and duration_h > 0, got "
            f"{rate_per_hour!r}, {duration_h!r}"
        )
    p = np.sort(np.asarray(peaks, dtype=float)[np.isfinite(peaks)])[::-1]
    if p.size == 0:
        return float(floor)
    top = p[: max(5, min(p.size, 50))]
    if top.size >= 5 and top[0] > top[-1]:
        # rate(x) = (i+1)/duration for x = top[i]; fit log rate = a - b x
        ranks = np.arange(1, top.size + 1) / duration_h
        b, a = np.polyfit(top, np.log(ranks), 1)
        x = (a - math.log(rate_per_hour)) / (-b) if b < 0 else top[0]
    else:
        x = top[0]
    return float(max(x, safety * p[0], floor))
