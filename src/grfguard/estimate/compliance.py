r"""Contact-point forces with a sole-compliance prior.

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
remaining freedom (for the affine part of the prior the constraints override it). Solved
per sample as a non-negative least-squares problem (``scipy.optimize.nnls``) with the
equality as a heavily weighted row, then rescaled so the sum is exact. Measured against the
exact optimum (every free set of the KKT conditions, as in
:mod:`grfguard.estimate.corner_qp`, on a 12 s default walk): at most 2.1e-9 N apart and
never a worse objective; the exact enumeration took twice as long in batch, so the NNLS
stays. ``tests/test_corner_qp.py`` checks the gap against daqp.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import nnls

__all__ = ["compliance_prior", "solve_with_prior", "split_with_prior"]

_RHO = 100.0


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


def _solve_core(rel: np.ndarray, prior: np.ndarray, total: float, sw: float) -> np.ndarray:
    """NNLS on the contact corners only: rel (m, 2) [m], prior (m,) [N]."""
    m = rel.shape[0]
    A = np.zeros((3 + m, m))
    A[0:2] = rel.T
    A[2] = _RHO
    A.reshape(-1)[3 * m :: m + 1] = sw
    y = np.zeros(3 + m)
    y[2] = _RHO * total
    y[3:] = sw * prior
    x = nnls(A, y, maxiter=50 * m)[0]
    s = x.sum()
    if s > 0:
        x *= total / s
    return x


def solve_with_prior(
    points_rel_m: np.ndarray,
    prior_n: np.ndarray,
    total_force_n: float,
    weight: float,
    contact: np.ndarray,
) -> np.ndarray:
    """One sample of the prior-regularized corner QP.

    Args:
        points_rel_m: (n, 2) corner points relative to the ZMP [m].
        prior_n: (n,) prior forces [N].
        total_force_n: Total vertical force [N] (<= 0 gives zeros).
        weight: ``w`` [m^2].
        contact: (n,) corners allowed to carry load.

    Returns:
        (n,) forces [N] (NaN if the input is not finite).
    """
    n = points_rel_m.shape[0]
    out = np.zeros(n)
    idx = np.flatnonzero(contact)
    rel = points_rel_m[idx]
    pr = prior_n[idx]
    if not (math.isfinite(total_force_n) and np.isfinite(rel.sum() + pr.sum())):
        return np.full(n, np.nan)
    if idx.size == 0 or total_force_n <= 0.0:
        return out
    out[idx] = _solve_core(rel, pr, total_force_n, math.sqrt(weight))
    return out


def split_with_prior(
    corners_W: np.ndarray,
    contact: np.ndarray,
    zmp_W: np.ndarray,
    total_force_n: np.ndarray,
    weight: float,
    stiffness_n_m: float,
) -> np.ndarray:
    """Batch over T samples: corners (T, n, 3) in world [m], contact (T, n), ZMP (T, 2) [m],
    total force (T,) [N]; returns (T, n) forces [N]."""
    T, n = contact.shape
    out = np.empty((T, n))
    # vectorized prior (same arithmetic as compliance_prior)
    z = corners_W[:, :, 2]
    cnt = contact.sum(axis=1)
    safe = np.maximum(cnt, 1)
    zbar = np.where(contact, z, 0.0).sum(axis=1) / safe
    prior = np.where(
        contact, (total_force_n / safe)[:, None] + stiffness_n_m * (zbar[:, None] - z), 0.0
    )
    rel = corners_W[:, :, :2] - zmp_W[:, None, :]
    for i in range(T):
        out[i] = solve_with_prior(rel[i], prior[i], float(total_force_n[i]), weight, contact[i])
    return out
