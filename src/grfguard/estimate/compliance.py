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
exactly per sample as a non-negative least-squares problem (``scipy.optimize.nnls``) with
the equality as a heavily weighted row, then rescaled to the exact sum.
"""

from __future__ import annotations

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
    if not (np.isfinite(total_force_n) and np.all(np.isfinite(points_rel_m[idx]))
            and np.all(np.isfinite(prior_n[idx]))):
        return np.full(n, np.nan)
    if idx.size == 0 or total_force_n <= 0.0:
        return out
    m = idx.size
    sw = np.sqrt(weight)
    A = np.empty((3 + m, m))
    A[0:2] = points_rel_m[idx].T
    A[2] = _RHO
    A[3:] = sw * np.eye(m)
    y = np.empty(3 + m)
    y[0:2] = 0.0
    y[2] = _RHO * total_force_n
    y[3:] = sw * prior_n[idx]
    x, _ = nnls(A, y, maxiter=50 * m)
    s = x.sum()
    if s > 0:
        x *= total_force_n / s
    out[idx] = x
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
    for i in range(T):
        prior = compliance_prior(corners_W[i, :, 2], contact[i], total_force_n[i], stiffness_n_m)
        rel = corners_W[i, :, :2] - zmp_W[i]
        out[i] = solve_with_prior(rel, prior, float(total_force_n[i]), weight, contact[i])
    return out
