r"""Reference (tests and benchmarks only; formerly ``grfguard.estimate.compliance`` and
``grfguard.kernels.split``): the corner QP of T samples around the package's compiled
solver :func:`grfguard.kernels.nnls.prior_qp` (the one inside the compiled virtual force
sensor), for the numpy stages of ``reference.vfs_stages`` and the QP tests.

Contact-point forces with a sole-compliance prior.

The total force and the ZMP fix only three combinations of the corner forces. In double
support the other five (and the twist of a single foot) depend on internal forces between
the legs (statically indeterminate): a rigid-body QP that pulls the forces toward zero
cannot see them. The soles are compliant, so a corner that sinks deeper carries more load;
the kinematic corner heights (encoders + attitude; relative heights within and between
the feet are accurate to a few micrometres) give a prior

.. math::

    N^p_k = \frac{F_z}{n} + k_c (\bar z - z_k), \qquad k \in K,

with ``k_c`` the corner contact stiffness [N/m] and ``\bar z`` the mean height of the
corners in contact ``K``. The forces solve

.. math::

    \min_{N \ge 0} \Big\lVert \sum_{k \in K} N_k (r_k - p) \Big\rVert^2
    + w \lVert N - N^p \rVert^2 \quad \text{s.t.} \quad \sum_k N_k = F_z .

With a small ``w`` the total force and the ZMP are met and the prior only picks the
remaining freedom (for the affine part of the prior the constraints override it).

One solver for every corner QP of the package (:func:`qp_split`): the compiled
active-set solver of :func:`grfguard.kernels.nnls.prior_qp` (the one inside the compiled
virtual force sensor) with the equality as a heavily weighted row, then rescaled so the
sum is exact, looped over the samples in one compiled call. The rigid split
(``N^p = 0``) and the paper's per-foot split are the same problem with the uniform prior
``F_z / n`` (on ``sum N = F_z``, ``|N - F_z/n|^2 = |N|^2 - F_z^2/n``), and the paper's
``|C N - d|^2`` with ``d = F_z p_CoP`` is ``|sum_k N_k (r_k - p_CoP)|^2``. Measured
(BENCHMARKS.md, "Contact-point QP"): within 1e-8 N of the exact-equality optimum
(rationals), the sum exact to rounding; ``tests/reference/corner_qp.py`` keeps the exact
enumeration the tests hold it to.
"""

from __future__ import annotations

import math

import numpy as np

from grfguard.kernels._jit import njit
from grfguard.kernels.nnls import MAX_CORNERS, new_scratch, prior_qp

__all__ = ["compliance_prior", "qp_loop", "qp_split", "solve_with_prior"]


def compliance_prior(
    corner_z_m: np.ndarray, contact: np.ndarray, total_force_n: float, stiffness_n_m: float
) -> np.ndarray:
    """Prior corner forces (n,) [N] from corner heights (n,) [m]; zero off contact."""
    out = np.zeros(corner_z_m.shape[0])
    idx = np.flatnonzero(contact)
    if idx.size == 0:
        return out
    z = corner_z_m[idx]
    out[idx] = total_force_n / idx.size + stiffness_n_m * (z.mean() - z)
    return out


def qp_split(
    points_rel_m: np.ndarray,
    prior_n: np.ndarray,
    total_force_n: np.ndarray,
    weight: float,
    allowed: np.ndarray | None = None,
) -> np.ndarray:
    """Corner forces of T samples (see the module header).

    Args:
        points_rel_m: (T, n, 2) corner points relative to the ZMP (or the CoP) [m],
            ``n <= 16``.
        prior_n: (T, n) prior forces [N].
        total_force_n: (T,) total vertical force [N] (<= 0: zeros).
        weight: ``w`` [m^2], > 0.
        allowed: (T, n) corners allowed to carry load (default: all).

    Returns:
        (T, n) forces [N]: zero off ``allowed`` and for samples without load or allowed
        corner, NaN for a sample with a non-finite input on an allowed corner.
    """
    rel = np.ascontiguousarray(points_rel_m, dtype=float)
    T, n = rel.shape[0], rel.shape[1]
    if n > MAX_CORNERS:
        raise ValueError(f"qp_split handles at most {MAX_CORNERS} corners, got {n}")
    ok = np.ones((T, n), bool) if allowed is None else np.ascontiguousarray(allowed, bool)
    out = np.empty((T, n))
    qp_loop(rel, np.ascontiguousarray(prior_n, dtype=float),
             np.ascontiguousarray(total_force_n, dtype=float).reshape(T), ok,
             math.sqrt(weight), out, *new_scratch(), np.zeros(MAX_CORNERS, np.int64),
             np.zeros((MAX_CORNERS, 2)), np.zeros(MAX_CORNERS))
    return out


def solve_with_prior(
    points_rel_m: np.ndarray,
    prior_n: np.ndarray,
    total_force_n: float,
    weight: float,
    contact: np.ndarray,
) -> np.ndarray:
    """One sample of :func:`qp_split`: points (n, 2) relative to the ZMP [m], prior (n,)
    [N], total force [N], ``w`` [m^2], corners in contact (n,); returns (n,) forces [N]."""
    return qp_split(np.asarray(points_rel_m, float)[None], np.asarray(prior_n, float)[None],
                    np.array([total_force_n], float), weight,
                    np.asarray(contact, bool)[None])[0]


@njit
def qp_loop(rel, prior, total, allowed, sw, out, x, z, free, isfree, M, rhs, dots, idx,
             relc, pc):
    """:func:`prior_qp` + rescale for every sample (``out`` (T, n) written)."""
    for t in range(total.shape[0]):
        m = 0
        fin = math.isfinite(total[t])
        for j in range(allowed.shape[1]):
            out[t, j] = 0.0
            if allowed[t, j]:
                if not (math.isfinite(rel[t, j, 0]) and math.isfinite(rel[t, j, 1])
                        and math.isfinite(prior[t, j])):
                    fin = False
                relc[m, 0] = rel[t, j, 0]
                relc[m, 1] = rel[t, j, 1]
                pc[m] = prior[t, j]
                idx[m] = j
                m += 1
        if not fin:
            out[t, :] = np.nan
            continue
        if m == 0 or total[t] <= 0.0:
            continue
        prior_qp(relc[:m], pc[:m], total[t], sw, m, x, z, free, isfree, M, rhs, dots)
        if m == 8:  # numpy's pairwise order, as the compiled sensor
            s = ((x[0] + x[1]) + (x[2] + x[3])) + ((x[4] + x[5]) + (x[6] + x[7]))
        else:
            s = x[0]
            for c in range(1, m):
                s += x[c]
        f = total[t] / s if s > 0 else 1.0
        for c in range(m):
            out[t, idx[c]] = x[c] * f if s > 0 else x[c]
