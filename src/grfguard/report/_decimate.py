"""Peak-preserving decimation for display.

A 10-minute 1 kHz log has 600 000 samples per signal; a screen shows ~2000 pixels
across. :func:`minmax_indices` keeps, in each of ``n_buckets`` equal buckets, the
samples holding the bucket's minimum and maximum (so spikes and steps survive), and
keeps every sample inside ``keep`` (full resolution around fault and alarm onsets).
:func:`step_edges` encodes a 0/1 signal exactly by its change points.
"""

from __future__ import annotations

import numpy as np

__all__ = ["minmax_indices", "step_edges", "intervals", "window_mask"]


def minmax_indices(
    y: np.ndarray, n_buckets: int, keep: np.ndarray | None = None
) -> np.ndarray:
    """Indices of the samples to draw so that every bucket's min and max survive.

    Args:
        y: Signal, shape (n,). NaN samples are skipped; an all-NaN bucket keeps its
            first sample (so the line shows a gap).
        n_buckets: Number of equal-count buckets over the whole signal.
        keep: Optional boolean mask (n,): samples kept at full resolution.

    Returns:
        Sorted unique sample indices (int64), always including the first and last.
    """
    y = np.asarray(y, dtype=float)
    n = y.size
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if n <= 2 * n_buckets and keep is None:
        return np.arange(n, dtype=np.int64)
    starts = np.unique(np.linspace(0, n, max(int(n_buckets), 1) + 1).astype(np.int64)[:-1])
    if keep is not None:
        k = np.flatnonzero(keep)
        starts = np.union1d(starts, np.concatenate([k, k + 1]))
        starts = starts[starts < n]
    counts = np.diff(np.append(starts, n))
    bucket = np.repeat(np.arange(starts.size), counts)
    nan = np.isnan(y)
    lo = np.where(nan, np.inf, y)
    hi = np.where(nan, -np.inf, y)
    mins = np.minimum.reduceat(lo, starts)
    maxs = np.maximum.reduceat(hi, starts)
    # First index in each bucket attaining the min (max): mask, then first per bucket.
    at_min = np.flatnonzero(lo == mins[bucket])
    at_max = np.flatnonzero(hi == maxs[bucket])
    _, first_min = np.unique(bucket[at_min], return_index=True)
    _, first_max = np.unique(bucket[at_max], return_index=True)
    idx = np.concatenate([starts, at_min[first_min], at_max[first_max], [0, n - 1]])
    # `starts` keeps all-NaN buckets visible as gaps; drop starts whose bucket has data
    # unless the start is itself a min/max (it usually is not; removing saves ~1/3).
    has_data = np.isfinite(mins)
    idx = np.concatenate([idx[starts.size :], starts[~has_data]])
    return np.unique(idx).astype(np.int64)


def step_edges(time_s: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact change-point encoding of a 0/1 signal, to draw with ``line_shape='hv'``.

    Args:
        time_s: Sample times in [s], shape (n,).
        state: 0/1 or bool signal, shape (n,).

    Returns:
        ``(x, y)``: times of the first sample, of every change and of the last sample,
        and the value from that time on (float 0/1).
    """
    s = np.asarray(state).astype(float)
    if s.size == 0:
        return np.zeros(0), np.zeros(0)
    change = np.flatnonzero(np.diff(s) != 0) + 1
    idx = np.concatenate([[0], change, [s.size - 1]])
    return np.asarray(time_s)[idx], s[idx]


def intervals(time_s: np.ndarray, state: np.ndarray) -> list[tuple[float, float]]:
    """The ``(start, end)`` times [s] of every run where ``state`` is true.

    A run's end is the time of its first false sample (or the last sample's time).
    """
    s = np.asarray(state).astype(bool)
    if s.size == 0:
        return []
    t = np.asarray(time_s, dtype=float)
    d = np.diff(s.astype(np.int8), prepend=0, append=0)
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1)
    return [(float(t[a]), float(t[min(b, t.size - 1)])) for a, b in zip(starts, ends, strict=True)]


def window_mask(time_s: np.ndarray, centres_s: np.ndarray, half_width_s: float) -> np.ndarray:
    """Boolean mask of samples within ``half_width_s`` [s] of any centre time [s]."""
    t = np.asarray(time_s, dtype=float)
    c = np.sort(np.asarray(centres_s, dtype=float))
    mask = np.zeros(t.size, dtype=bool)
    if c.size == 0 or t.size == 0:
        return mask
    lo = np.searchsorted(t, c - half_width_s, side="left")
    hi = np.searchsorted(t, c + half_width_s, side="right")
    d = np.zeros(t.size + 1, dtype=np.int64)
    np.add.at(d, lo, 1)
    np.add.at(d, hi, -1)
    return np.cumsum(d[:-1]) > 0
