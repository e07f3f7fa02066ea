r"""Reference (tests and benchmarks only; formerly ``grfguard.estimate.corner_qp``): the exact
corner-force QP of the rigid and the paper split (the paper's eq. 13-23, corrected). The
package solves these with :func:`grfguard.kernels.nnls.prior_qp` (batch form:
:func:`reference.corner_split.qp_split`).

``n`` contact points ``p_i = (x_i, y_i)`` in one planar frame, ``T`` samples:

.. math::

    \min_{N} \; \lVert C N - d \rVert^2 + w \lVert N \rVert^2
    \quad \text{s.t.} \quad N \ge 0, \quad \textstyle\sum_i N_i = b, \quad
    N_i = 0 \;\; (i \text{ not allowed}),

with ``C = [x_1 .. x_n; y_1 .. y_n]``, ``d = F_z p_CoP`` [N m] (zero when the points are
given relative to the ZMP), ``b = F_z`` [N] and ``w > 0`` [m²] (the paper's ``W = 0.01 I``
biases the CoP toward the sole centre; the default 1e-6 does not). Corrections to the
paper (DESIGN.md item 4): the right-hand side of eq. (21) is ``d``, the linear term of
eq. (23) is ``-2 Cᵀd`` and ``N ≥ 0`` is an inequality.

Solution (explicit, exact): for a guessed free set ``S`` the KKT conditions are linear.
With ``ν̃ = (d - CN)/w`` and ``λ̃ = λ/w`` every free point carries
``N_i = h_i = p_iᵀ ν̃ + λ̃`` and the 3 × 3 system

.. math::

    \begin{bmatrix} w I + C_S C_S^\top & C_S 1 \\ 1^\top C_S^\top & |S| \end{bmatrix}
    \begin{bmatrix} \tilde\nu \\ \tilde\lambda \end{bmatrix}
    = \begin{bmatrix} d \\ b \end{bmatrix}

is positive definite (no cancellation for tiny ``w``). ``S`` is optimal iff ``h_i ≥ 0`` on
``S`` and ``h_i ≤ 0`` (the multiplier of ``N_i ≥ 0``, divided by ``-w``) off ``S``; strict
convexity makes the optimum unique. Every non-empty subset of the allowed points is
tried at once and the one with the smallest KKT violation [N] is kept:

* fixed points (one sole, the paper split): ``h`` of each subset is a linear map of
  ``(d, b)``, tabulated once per point set in extended precision (``np.longdouble``); a
  sample is one small product and an arg-min (explicit "multi-parametric" solution);
* per-sample points (the rigid 8-corner split): vectorised over samples and subsets,
  samples grouped by their allowed set; the chosen subset is re-solved in extended
  precision: with a tiny ``w`` and an unreachable CoP a double solve loses up to ~1e-9
  relative. ``n`` is at most 8 here (255 subsets).

Degenerate input: ``b ≤ 0`` gives zero forces; a non-finite input gives NaN for that
sample; a loaded sample with no allowed point is infeasible and gives NaN.
"""

from __future__ import annotations

from functools import cache

import numpy as np

__all__ = ["solve_corner_qp"]

#: Subset-sample pairs evaluated per block (bounds temporary memory, ~16 MB per array).
_BLOCK = 1 << 18


@cache
def _subsets(k: int) -> np.ndarray:
    """(2^k - 1, k) float 0/1: every non-empty subset of k points."""
    codes = np.arange(1, 1 << k)
    return ((codes[:, None] >> np.arange(k)) & 1).astype(float)


def _solve_free_set(
    x: np.ndarray, y: np.ndarray, a: np.ndarray, w: float, d: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """``h`` (..., k) of the free sets ``a`` (..., k) by an entry-wise Cholesky solve.

    ``x``, ``y`` (..., k) point coordinates [m]; ``d`` (..., 2) [N m]; ``b`` (...) [N];
    broadcast against each other. Works in the dtype of the inputs.
    """
    ax, ay = a * x, a * y
    a00 = (ax * x).sum(-1) + w
    a01 = (ax * y).sum(-1)
    a02 = ax.sum(-1)
    a11 = (ay * y).sum(-1) + w
    a12 = ay.sum(-1)
    a22 = a.sum(-1)
    l00 = np.sqrt(a00)
    l10, l20 = a01 / l00, a02 / l00
    l11 = np.sqrt(a11 - l10 * l10)
    l21 = (a12 - l20 * l10) / l11
    l22 = np.sqrt(a22 - l20 * l20 - l21 * l21)
    y0 = d[..., 0] / l00
    y1 = (d[..., 1] - l10 * y0) / l11
    y2 = (b - l20 * y0 - l21 * y1) / l22
    z2 = y2 / l22
    z1 = (y1 - l21 * z2) / l11
    z0 = (y0 - l10 * z1 - l20 * z2) / l00
    return x * z0[..., None] + y * z1[..., None] + z2[..., None]


def _solve_group(
    x: np.ndarray, y: np.ndarray, d: np.ndarray, b: np.ndarray, w: float
) -> np.ndarray:
    """Forces (m, k) of m loaded samples whose k points are all allowed."""
    subs = _subsets(x.shape[1])
    h = _solve_free_set(x[:, None], y[:, None], subs, w, d[:, None], b[:, None])
    viol = np.where(subs > 0, -h, h).max(axis=-1)  # (m, S): worst KKT violation [N]
    free = subs[np.argmin(viol, axis=1)]
    ld = np.longdouble
    h = _solve_free_set(x.astype(ld), y.astype(ld), free.astype(ld), w, d.astype(ld),
                        b.astype(ld))
    return (free * h).astype(float)


@cache
def _table(points: tuple[float, ...], w: float) -> np.ndarray:
    """(3, S·k) map of ``(d_x, d_y, b)`` to ``h`` of every subset of fixed points."""
    ld = np.longdouble
    xy = np.array(points, dtype=ld).reshape(-1, 2)
    subs = _subsets(xy.shape[0]).astype(ld)
    eye = np.eye(3, dtype=ld)[:, None, :]  # (3 right-hand sides, 1 subset axis, 3)
    h = _solve_free_set(xy[:, 0], xy[:, 1], subs, w, eye[..., :2], eye[..., 2])
    return h.reshape(3, -1).astype(float)


def _solve_fixed(points: np.ndarray, d: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    """Forces (m, k) of m loaded samples on the same k points (table path)."""
    k = points.shape[0]
    subs = _subsets(k)
    table = _table(tuple(points.ravel().tolist()), w)
    sign = np.where(subs > 0, -1.0, 1.0)
    out = np.empty((b.size, k))
    step = max(1, _BLOCK // subs.shape[0])
    for i in range(0, b.size, step):
        dd, bb = d[i : i + step], b[i : i + step, None]
        # element-wise (not BLAS): a sample's numbers do not depend on the batch size
        h = (dd[:, :1] * table[0] + dd[:, 1:] * table[1] + bb * table[2]).reshape(-1, *subs.shape)
        best = np.argmin((sign * h).max(axis=-1), axis=1)
        out[i : i + step] = subs[best] * h[np.arange(h.shape[0]), best]
    return out


def solve_corner_qp(
    points_m: np.ndarray,
    d: np.ndarray,
    total_n: np.ndarray,
    weight: float,
    allowed: np.ndarray | None = None,
) -> np.ndarray:
    """Corner forces of T samples (see the module header).

    Args:
        points_m: (n, 2) fixed or (T, n, 2) per-sample points [m].
        d: (T, 2) ``F_z · CoP`` in the frame of the points [N m].
        total_n: (T,) total vertical force ``b`` [N].
        weight: ``w`` [m²], > 0.
        allowed: (T, n) points allowed to carry load (default: all).

    Returns:
        (T, n) forces [N]: zeros where ``b ≤ 0``, NaN for non-finite or infeasible samples.
    """
    b = np.asarray(total_n, float).reshape(-1)
    T = b.shape[0]
    d = np.asarray(d, float).reshape(T, 2)
    finite = np.isfinite(d).all(axis=1) & np.isfinite(b)
    if np.ndim(points_m) == 2 and allowed is None:  # fixed points: the table
        pts = np.asarray(points_m, float)
        out = np.zeros((T, pts.shape[0]))
        todo = finite & (b > 0) & bool(np.isfinite(pts).all())
        out[~finite | ~np.isfinite(pts).all()] = np.nan
        if todo.any():
            out[todo] = _solve_fixed(pts, d[todo], b[todo], float(weight))
        return out
    pts = np.broadcast_to(np.asarray(points_m, float), (T, *np.shape(points_m)[-2:]))
    n = pts.shape[1]
    ok = np.ones((T, n), bool) if allowed is None else np.asarray(allowed, bool)
    out = np.zeros((T, n))
    finite &= np.isfinite(pts).all(axis=(1, 2))
    loaded = finite & (b > 0)
    out[~finite | (loaded & ~ok.any(axis=1))] = np.nan
    todo = loaded & ok.any(axis=1)
    codes = ok @ (1 << np.arange(n))
    for code in np.unique(codes[todo]):
        rows = np.flatnonzero(todo & (codes == code))
        idx = np.flatnonzero(ok[rows[0]])
        step = max(1, _BLOCK // (1 << idx.size))
        for i in range(0, rows.size, step):
            r = rows[i : i + step]
            p = pts[r][:, idx]
            out[np.ix_(r, idx)] = _solve_group(p[..., 0], p[..., 1], d[r], b[r], float(weight))
    return out
