"""Reference solution of the corner QP with a maintained solver (daqp through qpsolvers).

Dev dependency only: the package never imports it. Same problem as
:mod:`grfguard.estimate.corner_qp`: ``min ‖C N - d‖² + w ‖N - N^p‖²`` s.t. ``N ≥ 0``,
``Σ N = b``, ``N_i = 0`` off the allowed points (``N^p = 0`` there; the prior ``N^p`` of
:mod:`reference.corner_split` otherwise); ``b ≤ 0`` gives zeros.
"""

from __future__ import annotations

import numpy as np
import qpsolvers


def reference_qp(
    points: np.ndarray,
    d: np.ndarray,
    b: float,
    w: float,
    allowed: np.ndarray | None = None,
    prior: np.ndarray | None = None,
) -> np.ndarray:
    """Forces (n,) [N] of one sample: points (n, 2) [m], d (2,) [N m], b [N], w [m²],
    prior (n,) [N]."""
    n = points.shape[0]
    if b <= 0.0:
        return np.zeros(n)
    P = 2.0 * (points @ points.T + w * np.eye(n))
    q = -2.0 * points @ d - (0.0 if prior is None else 2.0 * w * prior)
    ub = np.full(n, np.inf) if allowed is None else np.where(allowed, np.inf, 0.0)
    x = qpsolvers.solve_qp(P, q, A=np.ones((1, n)), b=np.array([b]), lb=np.zeros(n), ub=ub,
                           solver="daqp")
    assert x is not None, "daqp failed"
    return x


def package_qp(
    points: np.ndarray,
    d: np.ndarray,
    total: np.ndarray,
    w: float,
    allowed: np.ndarray | None = None,
) -> np.ndarray:
    """The package's corner QP (the compiled solver via
    :func:`reference.corner_split.qp_split`) in the form of
    :func:`reference.corner_qp.solve_corner_qp`: points (n, 2) fixed or (T, n, 2),
    ``d = F_z CoP`` (T, 2) [N m], totals (T,) [N]; the rigid / paper problem is the uniform
    prior ``F_z / n`` with the points taken relative to the CoP. A loaded sample with no
    allowed corner carries nothing (zeros), as in the virtual force sensor."""
    from reference.corner_split import qp_split

    b = np.asarray(total, float).reshape(-1)
    T = b.size
    dd = np.asarray(d, float).reshape(T, 2)
    pts = np.broadcast_to(np.asarray(points, float), (T, *np.shape(points)[-2:]))
    loaded = b > 0
    cop = np.zeros((T, 2))
    cop[loaded] = dd[loaded] / b[loaded, None]
    cop[~np.isfinite(dd).all(axis=1)] = np.nan
    ok = np.ones(pts.shape[:2], bool) if allowed is None else np.asarray(allowed, bool)
    prior = np.where(ok, (b / np.maximum(ok.sum(axis=1), 1))[:, None], 0.0)
    return qp_split(pts - cop[:, None, :], prior, b, w, ok)
