"""Compiled solver of the sole-compliance corner QP of the virtual force sensor.

The pure-Python path solves, over the ``k`` corners in contact,

    min_{N >= 0} |rel^T N|^2 + (rho (1^T N - F))^2 + w |N - N_prior|^2

with ``scipy.optimize.nnls`` (``rho = 100``, ``w = qp_weight``) and rescales ``N`` to sum
to ``F``. The problem is strictly convex (``w > 0``), so its minimiser is unique and any
exact method finds it: here the unconstrained minimiser when it is positive (the usual
case), else Lawson-Hanson's active set, every sub-problem solved as a correction
``u = N - N_prior`` in closed form (:func:`_ls_correction`: a 2 x 2 system in centred
coordinates, O(k)). Working on the correction keeps the rounding relative to the (small)
correction instead of to the forces, and the multiplier of the sum row is taken from the
free corners' optimality conditions instead of the ``rho^2``-amplified residual. The only
difference to ``nnls`` is rounding (tests: a few 1e-12 N).
"""

from __future__ import annotations

import math

import numpy as np

from grfguard.kernels._jit import njit_nort

__all__ = ["RHO", "prior_qp", "prior_qp_warm", "MAX_CORNERS"]

#: Weight of the sum row (the math: ``tests/reference/corner_split.py``).
RHO = 100.0
#: Largest number of corners a call handles (scratch sizes).
MAX_CORNERS = 16


@njit_nort(inline="always")
def _ls_correction(rel, prior, total, sw, free, nfree, z, M, rhs, dots):
    """Least squares on the free corners (:func:`_ls_closed_form`, or the QR when the
    corners are close to a line)."""
    if not _ls_closed_form(rel, prior, total, sw, free, nfree, z):
        _ls_correction_qr(rel, prior, total, sw, free, nfree, z, M, rhs, dots)


@njit_nort(inline="always")
def _ls_closed_form(rel, prior, total, sw, free, nfree, z):
    """Least squares on the free corners: ``z[free] = prior + u``; other entries untouched.

    ``min_u |B u - d|^2 + w |u|^2`` with ``B = [rho 1^T; rel^T]`` has the solution
    ``u = B^T lam``, ``(B B^T + w I) lam = d`` (3 x 3). Eliminating the heavy sum row
    leaves a 2 x 2 system in centred coordinates (``c`` ~ the free corners' centroid):

        (sum (x_i - c)(x_i - c)^T + a (1 - k a) s s^T + w I) m = -sum (x_i - c) p_i - c F
        u_i = a (F - sum p) + (x_i - c)^T m,    a = rho^2 / (rho^2 k + w),  c = a s

    (``s`` = sum of the free corners' ``rel``). Every term is formed without
    cancellation, so the rounding stays relative to the correction: O(k) work instead of
    a QR of the (3 + k) x k system. When the free corners are close to a line (the 2 x 2
    matrix has a condition number above about 100) the multipliers grow like 1/w and
    their rounding would show: then nothing is written and False returned. Otherwise the
    2 x 2 system is solved by its inverse (one division; a Cholesky took two square
    roots and five divisions in a chain: the force split 6 % of the virtual sensor's
    step faster with the solver's helpers inlined, the answers within 7e-13 N).
    """
    k = nfree
    w = sw * sw
    r2 = RHO * RHO
    den = r2 * k + w
    a = r2 / den
    sx = 0.0
    sy = 0.0
    sp = 0.0
    for c in range(k):
        j = free[c]
        sx += rel[j, 0]
        sy += rel[j, 1]
        sp += prior[j]
    c0 = a * sx
    c1 = a * sy
    e = a * (w / den)
    m00 = w + e * sx * sx
    m01 = e * sx * sy
    m11 = w + e * sy * sy
    r0 = -c0 * total
    r1 = -c1 * total
    for c in range(k):
        j = free[c]
        dx = rel[j, 0] - c0
        dy = rel[j, 1] - c1
        m00 += dx * dx
        m01 += dx * dy
        m11 += dy * dy
        r0 -= dx * prior[j]
        r1 -= dy * prior[j]
    det = m00 * m11 - m01 * m01
    if det < 0.01 * (m00 + m11) * (m00 + m11):
        return False
    inv = 1.0 / det
    g0 = (m11 * r0 - m01 * r1) * inv
    g1 = (m00 * r1 - m01 * r0) * inv
    base = a * (total - sp)
    for c in range(k):
        j = free[c]
        z[j] = prior[j] + (base + ((rel[j, 0] - c0) * g0 + (rel[j, 1] - c1) * g1))
    return True


@njit_nort
def _ls_correction_qr(rel, prior, total, sw, free, nfree, z, M, rhs, dots):
    """:func:`_ls_correction` by a Householder QR of ``[B; sqrt(w) I]`` (heavy row
    first); ``M`` ((3 + K) x K) and ``rhs`` (3 + K) are scratch. Used when the corners
    are close to a line (the closed form would divide by a near-zero spread)."""
    k = nfree
    nr = 3 + k
    # B p - d  ->  rhs = d - B p
    g0 = 0.0
    g1 = 0.0
    s = 0.0
    for c in range(k):
        j = free[c]
        g0 += rel[j, 0] * prior[j]
        g1 += rel[j, 1] * prior[j]
        s += prior[j]
    # heavy row first (Householder QR of a weighted problem: rows by decreasing weight)
    rhs[0] = RHO * total - RHO * s
    rhs[1] = -g0
    rhs[2] = -g1
    for r in range(3, nr):
        rhs[r] = 0.0
    for c in range(k):
        j = free[c]
        M[0, c] = RHO
        M[1, c] = rel[j, 0]
        M[2, c] = rel[j, 1]
        for r in range(3, nr):
            M[r, c] = 0.0
        M[3 + c, c] = sw
    # Householder QR, applied to rhs on the fly
    for c in range(k):
        nrm = 0.0
        for r in range(c, nr):
            nrm += M[r, c] * M[r, c]
        nrm = math.sqrt(nrm)
        if nrm == 0.0:
            continue
        alpha = -nrm if M[c, c] >= 0.0 else nrm
        v0 = M[c, c] - alpha
        # v = [v0, M[c+1:, c]]; beta = 2 / |v|^2
        vv = v0 * v0
        for r in range(c + 1, nr):
            vv += M[r, c] * M[r, c]
        if vv == 0.0:
            continue
        M[c, c] = v0
        for cc in range(c + 1, k):
            d = 0.0
            for r in range(c, nr):
                d += M[r, c] * M[r, cc]
            f = 2.0 * d / vv
            for r in range(c, nr):
                M[r, cc] -= f * M[r, c]
        d = 0.0
        for r in range(c, nr):
            d += M[r, c] * rhs[r]
        f = 2.0 * d / vv
        for r in range(c, nr):
            rhs[r] -= f * M[r, c]
        M[c, c] = alpha
    # back substitution R u = Q^T rhs
    for c in range(k - 1, -1, -1):
        acc = rhs[c]
        for cc in range(c + 1, k):
            acc -= M[c, cc] * dots[cc]
        dots[c] = acc / M[c, c]
    for c in range(k):
        j = free[c]
        z[j] = prior[j] + dots[c]


@njit_nort
def prior_qp(rel, prior, total, sw, n, x, z, free, isfree, M, rhs, dots):
    """Minimiser ``x[:n]`` (not yet rescaled) of the compliance QP over ``n`` corners.

    Args:
        rel: (n, 2) corner points relative to the ZMP [m].
        prior: (n,) prior forces [N].
        total: total vertical force ``F`` [N] (> 0).
        sw: ``sqrt(qp_weight)``.
        n: number of corners.
        x, z: (n,) output / scratch; free, isfree: (n,) int scratch;
        M, rhs, dots: scratch of :func:`_ls_correction`.
    """
    # The problem is strictly convex: when the unconstrained minimiser over every corner
    # is positive it is the answer (the usual case with a compliance prior), one solve
    # instead of n active-set steps. Otherwise (or when the corners are close to a line,
    # where the QR's rounding depends on the corners' order) Lawson-Hanson from x = 0.
    if not _all_positive(rel, prior, total, sw, n, x, z, free):
        _lawson_hanson(rel, prior, total, sw, n, x, z, free, isfree, M, rhs, dots)


@njit_nort(inline="always")
def _all_positive(rel, prior, total, sw, n, x, z, free):
    """True, with the answer in ``x[:n]``, when the unconstrained minimiser over every
    corner (closed form) has every force positive."""
    for j in range(n):
        free[j] = j
    if not _ls_closed_form(rel, prior, total, sw, free, n, z):
        return False
    for j in range(n):
        if not z[j] > 0.0:
            return False
    for j in range(n):
        x[j] = z[j]
    return True


@njit_nort
def _lawson_hanson(rel, prior, total, sw, n, x, z, free, isfree, M, rhs, dots):
    """Lawson-Hanson active set from ``x = 0`` (arguments as :func:`prior_qp`)."""
    w2 = sw * sw
    for j in range(n):
        x[j] = 0.0
        isfree[j] = 0
    nfree = 0
    for _outer in range(3 * n + 3):
        best = _entering_corner(rel, prior, total, w2, n, x, free, isfree, nfree)
        if best < 0:
            break
        isfree[best] = 1
        free[nfree] = best
        nfree += 1
        for _inner in range(3 * n + 3):
            _ls_correction(rel, prior, total, sw, free, nfree, z, M, rhs, dots)
            ok = True
            for c in range(nfree):
                if z[free[c]] <= 0.0:
                    ok = False
                    break
            if ok:
                for c in range(nfree):
                    x[free[c]] = z[free[c]]
                break
            alpha = 2.0
            jmin = -1
            for c in range(nfree):
                j = free[c]
                if z[j] <= 0.0:
                    a = x[j] / (x[j] - z[j])
                    if a < alpha:
                        alpha = a
                        jmin = j
            for c in range(nfree):
                j = free[c]
                x[j] = x[j] + alpha * (z[j] - x[j])
            # drop the corner that reached zero (and any other at or below zero)
            keep = 0
            for c in range(nfree):
                j = free[c]
                if j == jmin or x[j] <= 0.0:
                    x[j] = 0.0
                    isfree[j] = 0
                else:
                    free[keep] = j
                    keep += 1
            nfree = keep
            if nfree == 0:
                break


@njit_nort(inline="always")
def prior_qp_warm(rel, prior, total, sw, n, x, z, free, isfree, M, rhs, dots, warm):
    """:func:`prior_qp` started from a guess of the corners with a positive force (bit
    ``j`` of ``warm``: corner ``j``; e.g. the previous sample's answer); returns the
    corners with a positive force of the answer (the next call's ``warm``).

    The minimiser is unique, so whichever way it is found only its rounding can differ;
    to keep the bits independent of the guess (a twin sensor that skips samples gives
    the same bits as one that does not), every answer with a zero corner is the least
    squares solve of its positive corners in ascending order (:func:`_solve_set`), found
    either straight from the guess (when that set is optimal: every force positive and
    no zero corner that would enter) or after Lawson-Hanson from zero. The all-positive
    answer is :func:`prior_qp`'s, bit for bit. Same arguments as :func:`prior_qp`.
    """
    full = (1 << n) - 1
    w2 = sw * sw
    if warm == full or warm == 0:
        if _all_positive(rel, prior, total, sw, n, x, z, free):
            return full
        _lawson_hanson(rel, prior, total, sw, n, x, z, free, isfree, M, rhs, dots)
    elif _solve_set(rel, prior, total, sw, w2, n, x, z, free, isfree, M, rhs, dots, warm):
        return warm
    else:
        prior_qp(rel, prior, total, sw, n, x, z, free, isfree, M, rhs, dots)
    mask = 0
    for j in range(n):
        if x[j] > 0.0:
            mask |= 1 << j
    if mask != 0 and mask != full:
        # the same set in ascending order (kept as it is if its rounding disagrees)
        _solve_set(rel, prior, total, sw, w2, n, x, z, free, isfree, M, rhs, dots, mask)
    return mask


@njit_nort(inline="always")
def _solve_set(rel, prior, total, sw, w2, n, x, z, free, isfree, M, rhs, dots, mask):
    """Least squares on the corners of ``mask`` (ascending order), the others at zero; if
    that is the minimiser (positive forces, no corner to enter) write it into ``x`` and
    return True, else leave ``x`` as it is and return False."""
    nfree = 0
    for j in range(n):
        if (mask >> j) & 1:
            free[nfree] = j
            nfree += 1
            isfree[j] = 1
        else:
            isfree[j] = 0
    _ls_correction(rel, prior, total, sw, free, nfree, z, M, rhs, dots)
    for c in range(nfree):
        if not z[free[c]] > 0.0:
            return False
    for j in range(n):
        if isfree[j] == 0:
            z[j] = 0.0
    if _entering_corner(rel, prior, total, w2, n, z, free, isfree, nfree) >= 0:
        return False
    for j in range(n):
        x[j] = z[j]
    return True


@njit_nort(inline="always")
def _entering_corner(rel, prior, total, w2, n, x, free, isfree, nfree):
    """Index of the bound corner with the largest positive gradient of the negative
    objective at ``x`` (the next to free), or -1 if none (``x`` optimal)."""
    # gradient of the negative objective at x (multiplier of the sum row from the
    # free corners' optimality conditions)
    gx = 0.0
    gy = 0.0
    sx = 0.0
    for j in range(n):
        gx += rel[j, 0] * x[j]
        gy += rel[j, 1] * x[j]
        sx += x[j]
    if nfree == 0:
        lam = RHO * (RHO * total - RHO * sx)
    else:
        lam = 0.0
        for c in range(nfree):
            j = free[c]
            lam += rel[j, 0] * gx + rel[j, 1] * gy - w2 * (prior[j] - x[j])
        lam /= nfree
    best = -1
    wbest = 0.0
    scale = abs(lam) + w2 * (abs(total) + 1.0)
    for j in range(n):
        if isfree[j] == 0:
            wj = -(rel[j, 0] * gx + rel[j, 1] * gy) + lam + w2 * (prior[j] - x[j])
            if wj > 1e-12 * scale and (best < 0 or wj > wbest):
                best = j
                wbest = wj
    return best


def new_scratch(n: int = MAX_CORNERS) -> tuple[np.ndarray, ...]:
    """Scratch arrays ``(x, z, free, isfree, M, rhs, dots)`` for up to ``n`` corners."""
    return (
        np.zeros(n), np.zeros(n), np.zeros(n, np.int64), np.zeros(n, np.int64),
        np.zeros((3 + n, n)), np.zeros(3 + n), np.zeros(n),
    )
