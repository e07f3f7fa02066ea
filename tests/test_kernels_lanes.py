"""Vector lanes (grfguard.kernels.lanes): each lane computes the bits of the same
expression on floats."""

from __future__ import annotations

import numba
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from grfguard.kernels.lanes import LANES, lane, lanes2d, lanes_size, splat, vload

njit = numba.njit(error_model="numpy")  # as the kernels (x / 0 is inf), not cached


@numba.njit(inline="always")
def _expr(a, b, c):
    """Every operator the lanes support, mixed with a float constant (written once; run
    on floats and on vectors)."""
    x = a * b + c - 2.5 * a / (b - c)
    y = -x * 3.0 + (c / 7.0 - a)
    y += a
    y -= 0.5
    y *= b
    y /= 3
    return x, y


@njit
def _scalar(A, B, C, X, Y):
    for i in range(A.shape[0]):
        X[i], Y[i] = _expr(A[i], B[i], C[i])


@njit
def _lanes(A, B, C, X, Y):
    buf = np.empty(lanes_size(2, 1))
    V = lanes2d(buf, 2, 1)  # stored and loaded through an aligned vector array
    for i0 in range(0, A.shape[0], LANES):
        x, y = _expr(vload(A, i0), vload(B, i0), vload(C, i0))
        V[0, 0], V[1, 0] = x, y
        for j in range(LANES):
            X[i0 + j], Y[i0 + j] = lane(V[0, 0], j), lane(V[1, 0], j)
    buf[0] = 0.0


_f = st.floats(allow_nan=True, allow_infinity=True, width=64)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(_f, _f, _f), min_size=1, max_size=3 * LANES))
def test_lanes_compute_the_scalar_bits(vals) -> None:
    n = -(-len(vals) // LANES) * LANES
    A, B, C = (np.zeros(n) for _ in range(3))
    for i, (a, b, c) in enumerate(vals):
        A[i], B[i], C[i] = a, b, c
    X1, Y1, X2, Y2 = (np.empty(n) for _ in range(4))
    with np.errstate(all="ignore"):
        _scalar(A, B, C, X1, Y1)
    _lanes(A, B, C, X2, Y2)
    # the same bits, NaN payloads aside (numpy compares NaN as equal with equal_nan)
    for s, v in ((X1, X2), (Y1, Y2)):
        same = (s.view(np.int64) == v.view(np.int64)) | (np.isnan(s) & np.isnan(v))
        assert same.all(), (s[~same], v[~same])


@njit
def _splat_lanes(x):
    v = splat(x)
    return [lane(v, j) for j in range(LANES)]


def test_splat_fills_every_lane_and_views_are_aligned() -> None:
    assert _splat_lanes(-0.0) == [-0.0] * LANES
    assert all(np.signbit(x) for x in _splat_lanes(-0.0))
    assert _splat_lanes(3) == [3.0] * LANES
    # lanes2d starts at the buffer's first vector-aligned entry, whatever the offset
    for off in range(LANES):
        buf = np.zeros(lanes_size(3, 2) + off)
        _fill(buf[off:], 3, 2)
        start = (-(buf[off:].ctypes.data) % (8 * LANES)) // 8
        v = buf[off + start: off + start + 3 * 2 * LANES].reshape(3, 2, LANES)
        assert np.array_equal(v[..., 0], np.arange(6.0).reshape(3, 2))
        assert np.array_equal(v[..., -1], np.arange(6.0).reshape(3, 2))


@njit
def _fill(buf, n, m):
    V = lanes2d(buf, n, m)
    for i in range(n):
        for k in range(m):
            V[i, k] = splat(float(i * m + k))
