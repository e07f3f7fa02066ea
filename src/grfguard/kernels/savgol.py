"""Savitzky-Golay filters of several derivative orders over many columns in one compiled
pass, bit for bit as ``scipy.signal.savgol_filter(..., mode="interp")``.

scipy filters one column and one order at a time (``ndimage.correlate1d``, a scalar loop
over the taps per output sample). Here the taps run over blocks of 256 output samples of
one column at once (a loop the compiler vectorises), every requested order sharing the
column's block, in the same order of operations as scipy's ``NI_Correlate1D``: for a
filter symmetric within ``DBL_EPSILON`` ``y = x[k] w[h] + sum_{j=-h}^{-1} (x[k+j] +
x[k-j]) w[h+j]``; antisymmetric the same with ``x[k+j] - x[k-j]``; otherwise ``y =
x[k+h] w[2h] + sum_{j=-h}^{h-1} x[k+j] w[h+j]`` (the weights are ``savgol_coeffs``
reversed, as ``convolve1d`` passes them). The first and last ``h`` samples are scipy's
own polynomial fit of the edge windows (``_fit_edges_polyfit``).

``sliding=True`` (:func:`savgol_sliding`): the interior from sliding polynomial moments
instead, a few tens of operations per sample and column whatever the window (a cubic fit's
weights are a cubic in the tap index): equal to the direct sum within some 10-50 of its
own rounding units (``eps max|x| sum|w|``), not bit for bit.
"""

from __future__ import annotations

import functools

import numpy as np

from grfguard.kernels._jit import njit, view1d

__all__ = ["savgol_block", "savgol_many", "savgol_sliding", "warm"]

#: Output samples per block (a block of each order's accumulator stays in L1).
BLOCK = 256
#: Smallest half window filtered by :func:`savgol_sliding` (``sliding=True``): below it
#: the moving moments' drift between two direct sums grows (the shift by one sample is
#: ``1 / h`` of the window, cubed in the third moment) and the direct sum is short anyway.
SLIDE_MIN_HALF = 16


@njit
def _taps(flat, row, k0, nb, w, h, sym, a, t):
    """One order on the block ``[k0, k0 + nb)`` of the column starting at ``row`` into
    ``a`` (``t``: scratch). Each tap is one pass over the block: the passes keep scipy's
    order of additions per sample, and the loop over the block vectorises."""
    win = 2 * h + 1
    if sym == 0:
        xs = view1d(flat, row + k0 + h, nb)
        w0 = w[win - 1]
        for i in range(nb):
            a[i] = xs[i] * w0
        jj = -h
        while jj + 3 < h:  # four taps a pass: the same additions, in the same order
            w1, w2, w3, w4 = w[h + jj], w[h + jj + 1], w[h + jj + 2], w[h + jj + 3]
            x1 = view1d(flat, row + k0 + jj, nb)
            x2 = view1d(flat, row + k0 + jj + 1, nb)
            x3 = view1d(flat, row + k0 + jj + 2, nb)
            x4 = view1d(flat, row + k0 + jj + 3, nb)
            for i in range(nb):
                a[i] = (((a[i] + x1[i] * w1) + x2[i] * w2) + x3[i] * w3) + x4[i] * w4
            jj += 4
        while jj < h:
            wj = w[h + jj]
            xs = view1d(flat, row + k0 + jj, nb)
            for i in range(nb):
                a[i] += xs[i] * wj
            jj += 1
        return
    xs = view1d(flat, row + k0, nb)
    w0 = w[h]
    for i in range(nb):
        a[i] = xs[i] * w0
    for jj in range(-h, 0):
        wj = w[h + jj]
        xa = view1d(flat, row + k0 + jj, nb)
        xb = view1d(flat, row + k0 - jj, nb)
        if sym > 0:
            for i in range(nb):
                t[i] = xa[i] + xb[i]
        else:
            for i in range(nb):
                t[i] = xa[i] - xb[i]
        for i in range(nb):
            a[i] += t[i] * wj


@njit
def savgol_block(xt, W, sym, out):
    """Interior samples of every order: ``xt`` (m, n) C-contiguous columns, ``W``
    (orders, win) correlation weights, ``sym`` (orders,) 1 / -1 / 0, ``out`` (orders,
    n, m): the samples as rows, as the caller's arrays are (the first and last
    ``win // 2`` rows are left as they are)."""
    m, n = xt.shape
    no, win = W.shape
    h = win // 2
    flat = xt.ravel()
    a = np.empty(BLOCK)  # the order's block (plain arrays: kept alive by numba)
    tb = np.empty(BLOCK)  # pair sums / differences of one tap, rounded as in scipy
    for k0 in range(h, n - h, BLOCK):  # a block of rows of every column: stays in cache
        nb = min(BLOCK, n - h - k0)
        for c in range(m):
            row = c * n
            for o in range(no):
                _taps(flat, row, k0, nb, W[o], h, sym[o], a, tb)
                for i in range(nb):
                    out[o, k0 + i, c] = a[i]


@njit
def savgol_sliding(x, C, h, blk, out):
    """Interior samples ``h .. T - h - 1`` of every order from the sliding moments
    ``S_p(k) = sum_{j=-h}^{h} (j / h)^p x[k + j]`` (p = 0..3) of the (T, m) C-contiguous
    columns ``x``: ``out[o, k] = sum_p C[o, p] S_p(k)`` (``out`` (orders, T, m); a fit of
    degree <= 3 has weights cubic in ``j``: :func:`_moment_weights`). The moments are
    summed directly every ``blk`` samples and shifted by one sample in between
    (binomial shift, minus the leaving sample, plus the entering one): about 40
    operations per column and sample instead of ``2 (2h + 1)`` per order; every loop
    runs over the columns (vectorised). Finite inputs only (a NaN would stay in the
    moments until the next direct sum)."""
    T, m = x.shape
    no = C.shape[0]
    d = 1.0 / h
    d2, d3 = d * d, d * d * d
    e1 = 1.0 + d
    e2, e3 = e1 * e1, e1 * e1 * e1
    S0, S1, S2, S3 = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    for k0 in range(h, T - h, blk):
        k1 = min(k0 + blk, T - h)
        S0[:] = 0.0
        S1[:] = 0.0
        S2[:] = 0.0
        S3[:] = 0.0
        for j in range(-h, h + 1):
            u = j * d
            u2 = u * u
            u3 = u2 * u
            for c in range(m):
                v = x[k0 + j, c]
                S0[c] += v
                S1[c] += u * v
                S2[c] += u2 * v
                S3[c] += u3 * v
        for k in range(k0, k1):
            for o in range(no):
                c0, c1, c2, c3 = C[o, 0], C[o, 1], C[o, 2], C[o, 3]
                for c in range(m):
                    out[o, k, c] = c0 * S0[c] + c1 * S1[c] + c2 * S2[c] + c3 * S3[c]
            if k + 1 < k1:
                for c in range(m):
                    xo, xn = x[k - h, c], x[k + h + 1, c]
                    s0, s1, s2, s3 = S0[c], S1[c], S2[c], S3[c]
                    S0[c] = s0 - xo + xn
                    S1[c] = s1 - d * s0 + e1 * xo + xn
                    S2[c] = s2 - 2.0 * d * s1 + d2 * s0 - e2 * xo + xn
                    S3[c] = s3 - 3.0 * d * s2 + 3.0 * d2 * s1 - d3 * s0 + e3 * xo + xn


def _symmetry(w: np.ndarray) -> int:
    """scipy's test: 1 symmetric, -1 antisymmetric (within DBL_EPSILON), else 0."""
    h = w.size // 2
    eps = np.finfo(float).eps
    d = np.abs(w[h + 1:] - w[h - 1::-1]) if h else np.zeros(0)
    if (d <= eps).all():
        return 1
    s = np.abs(w[h + 1:] + w[h - 1::-1]) if h else np.zeros(0)
    return -1 if (s <= eps).all() else 0


@functools.lru_cache(maxsize=64)
def _weights(win: int, polyorder: int, orders: tuple[int, ...], dt: float
             ) -> tuple[np.ndarray, np.ndarray]:
    """Correlation weights (orders, win) and their symmetries (orders,) (cached: scipy's
    ``savgol_coeffs`` takes about 0.1 ms a call, 0.35 ms for 1001 taps)."""
    from scipy.signal import savgol_coeffs

    W = np.array([np.asarray(savgol_coeffs(win, polyorder, deriv=o, delta=dt))[::-1]
                  for o in orders])
    sym = np.array([_symmetry(w) for w in W], np.int64)
    W.setflags(write=False)
    sym.setflags(write=False)
    return W, sym


@functools.lru_cache(maxsize=64)
def _moment_weights(win: int, polyorder: int, orders: tuple[int, ...], dt: float
                    ) -> np.ndarray:
    """(orders, 4) ``C`` with ``W[o, h + j] = sum_p C[o, p] (j / h)^p`` for scipy's
    correlation weights ``W`` (:func:`_weights`; polyorder <= 3): the least-squares fit of
    the weights themselves, which follows scipy's rounding of them more closely than the
    fit's closed form (1e-15 against 1e-13 of the output's scale)."""
    W, _ = _weights(win, polyorder, orders, dt)
    h = win // 2
    V = np.vander(np.arange(-h, h + 1) / h, 4, increasing=True)
    C = np.ascontiguousarray(np.linalg.lstsq(V, W.T, rcond=None)[0].T)
    C.setflags(write=False)
    return C


@functools.lru_cache(maxsize=64)
def _edge_maps(win: int, polyorder: int, orders: tuple[int, ...], dt: float) -> np.ndarray:
    """(orders, 2, h, win): scipy's edge fit (:func:`_fit_edges`) as the linear map it is,
    first and last ``h`` outputs from the first and last ``win`` samples (scipy's fit of
    the unit samples; applied as a product: a few microseconds instead of scipy's
    ~1 ms of array-API polyfit per call, equal to it to rounding)."""
    h = win // 2
    outs = [np.zeros((win, win)) for _ in orders]
    _fit_edges(np.eye(win), win, polyorder, orders, dt, outs)
    E = np.ascontiguousarray(np.stack([np.stack([y[:h], y[win - h:]]) for y in outs]))
    E.setflags(write=False)
    return E


def _fit_edges(xt: np.ndarray, win: int, polyorder: int, orders: tuple[int, ...], dt: float,
               outs: list[np.ndarray]) -> None:
    """scipy's ``_fit_edges_polyfit`` (``mode="interp"``) of the (m, n) columns ``xt``
    along the last axis into each of ``outs`` ((n, m), one per order), the same
    operations, with each edge's polynomial fit done once for all orders instead of once
    per order."""
    from scipy._lib._array_api import array_namespace
    from scipy.signal import _polyutils as pu
    from scipy.signal._savitzky_golay import _polyder

    xp = array_namespace(xt)
    n, h = xt.shape[-1], win // 2
    for w0, w1, i0, i1 in ((0, win, 0, h), (n - win, n, n - h, n)):
        xx = xp.reshape(xt[:, w0:w1].swapaxes(-1, 0), (w1 - w0, -1))
        coeffs = pu.polyfit(xp.arange(0, w1 - w0, dtype=xt.dtype), xx, polyorder, xp=xp)
        i = xp.reshape(xp.arange(i0 - w0, i1 - w0, dtype=coeffs.dtype), (-1, 1))
        for o, y in zip(orders, outs, strict=True):
            pc = _polyder(coeffs, o, xp=xp) if o > 0 else coeffs
            y[i0:i1] = pu.polyval(pc, i, xp=xp) / (dt ** o)


def savgol_many(x: np.ndarray, win: int, orders: tuple[int, ...], dt: float,
                polyorder: int = 3, fft: bool = False, sliding: bool = False
                ) -> list[np.ndarray]:
    """``savgol_filter(x, win, polyorder, deriv=o, delta=dt, axis=0, mode="interp")`` of a
    (T, m) array for every ``o`` in ``orders``, the same bits, in one pass.

    ``fft=True``: the interior samples by FFT convolution (``scipy.signal.fftconvolve``)
    instead of the direct sum: for long windows (1001 taps: about 10x cheaper), equal to
    the direct sum to about 1e-15 of the signal's scale, not bit for bit; the edges are
    unchanged.

    ``sliding=True``: the interior by :func:`savgol_sliding` (direct sums every ``h // 2``
    samples) when ``polyorder <= 3``, the half window ``h >= SLIDE_MIN_HALF``, ``fft`` is
    off and every input is finite (else as without it): within some 10-50 rounding
    units (``eps max|x| sum|w|``) of the direct sum, several times cheaper for 101 taps;
    the edges by scipy's fit as a precomputed linear map (:func:`_edge_maps`, equal to
    it to rounding)."""
    x = np.asarray(x, float)
    if x.ndim != 2 or win % 2 == 0 or win > x.shape[0]:
        raise ValueError(f"savgol_many needs a (T, m) array and an odd window <= T, got "
                         f"{x.shape} and {win}")
    W, sym = _weights(int(win), int(polyorder), tuple(int(o) for o in orders), float(dt))
    out = np.empty((len(orders),) + x.shape)
    h = win // 2
    if (sliding and not fft and polyorder <= 3 and h >= SLIDE_MIN_HALF
            and np.isfinite(x).all()):
        C = _moment_weights(int(win), int(polyorder), tuple(int(o) for o in orders), float(dt))
        savgol_sliding(np.ascontiguousarray(x), C, h, max(1, h // 2), out)
        E = _edge_maps(int(win), int(polyorder), tuple(int(o) for o in orders), float(dt))
        n = x.shape[0]
        for i in range(len(orders)):
            np.matmul(E[i, 0], x[:win], out=out[i, :h])
            np.matmul(E[i, 1], x[n - win:], out=out[i, n - h:])
        return list(out)
    xt = np.ascontiguousarray(x.T)
    if fft:
        from scipy.signal import fftconvolve

        for i in range(len(orders)):  # y[k] = sum_j W[j] x[k - h + j]
            out[i, h:x.shape[0] - h] = fftconvolve(x, W[i, ::-1, None], mode="valid", axes=0)
    else:
        savgol_block(xt, W, sym, out)
    _fit_edges(xt, win, polyorder, tuple(orders), dt, list(out))
    return list(out)


def warm() -> None:
    """Compile (or load) the kernel on a tiny input, with the argument types of
    :func:`savgol_many`'s call but without importing ``scipy.signal`` (about 1 s of start-up
    that :func:`grfguard.kernels.warm_up`, run by every ``Monitor.for_log``, would pay)."""
    savgol_block(np.zeros((2, 7)), np.zeros((3, 5)), np.zeros(3, np.int64),
                 np.empty((3, 7, 2)))
    savgol_sliding(np.zeros((7, 2)), np.zeros((3, 4)), 2, 1, np.empty((3, 7, 2)))
