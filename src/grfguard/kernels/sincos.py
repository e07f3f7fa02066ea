"""Sines and cosines of many angles in a loop the compiler vectorises (the joint angles of
:mod:`grfguard.kernels.rne`'s and :mod:`grfguard.kernels.front`'s blocks)."""

from __future__ import annotations

import math

from grfguard.kernels._jit import njit_nort

__all__ = ["SINCOS_MAX", "sincos_flat"]

# sin and cos of many angles in a loop the compiler vectorises: fdlibm's kernels (FreeBSD
# k_sin.c, k_cos.c) on [-pi/4, pi/4] after its Cody-Waite reduction by pi/2
# (e_rem_pio2.c, medium case); within an ulp of libm's (scalar calls, about 20 ns a
# pair here: 0.6 us of every Talos sample's inverse dynamics)
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11
_INV_PIO2 = 6.36619772367581382433e-01
_PIO2_1, _PIO2_2, _PIO2_2T = (1.57079632673412561417e+00, 6.07710050630396597660e-11,
                              2.02226624879595063154e-21)
_ROUND = 6755399441055744.0  # 1.5 * 2^52: (x + _ROUND) - _ROUND rounds x to an integer
#: Largest |angle| reduced by :func:`_sincos_one` (``k * _PIO2_1`` stays exact); larger
#: ones take libm's.
SINCOS_MAX = 1.0e5


@njit_nort(inline="always")
def _sincos_one(x):
    """``(sin x, cos x)`` within an ulp of libm's for ``|x| <= SINCOS_MAX`` (NaN for a NaN
    or infinite ``x``), branch-free."""
    k = (x * _INV_PIO2 + _ROUND) - _ROUND
    y = ((x - k * _PIO2_1) - k * _PIO2_2) - k * _PIO2_2T
    z = y * y
    v = z * y
    sn = y + v * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    r = z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    cs = w + (((1.0 - w) - hz) + z * r)
    qd = k - 4.0 * math.floor(k * 0.25)  # quadrant 0..3 (NaN: neither branch below)
    s1 = cs if qd == 1.0 else (-sn if qd == 2.0 else (-cs if qd == 3.0 else sn))
    c1 = -sn if qd == 1.0 else (-cs if qd == 2.0 else (sn if qd == 3.0 else cs))
    return s1, c1


@njit_nort
def sincos_flat(th, m, sn, cs):
    """``sn[k], cs[k]`` = sin, cos of ``th[k]`` for ``k < m`` (1-D arrays)."""
    for k in range(m):
        sn[k], cs[k] = _sincos_one(th[k])
    for k in range(m):
        if abs(th[k]) > SINCOS_MAX:
            sn[k], cs[k] = math.sin(th[k]), math.cos(th[k])
