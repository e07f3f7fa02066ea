"""The compliance split by ``scipy.optimize.nnls`` (the equality as a weighted row, then
rescaled): the independent reference of the compiled solver
(:func:`grfguard.kernels.nnls.prior_qp`)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

RHO = 100.0


def nnls_prior_qp(rel: np.ndarray, prior: np.ndarray, total: float, sw: float) -> np.ndarray:
    """NNLS on the contact corners only: rel (m, 2) [m], prior (m,) [N], ``sw = sqrt(w)``."""
    m = rel.shape[0]
    A = np.zeros((3 + m, m))
    A[0:2] = rel.T
    A[2] = RHO
    A.reshape(-1)[3 * m :: m + 1] = sw
    y = np.zeros(3 + m)
    y[2] = RHO * total
    y[3:] = sw * prior
    x = nnls(A, y, maxiter=50 * m)[0]
    s = x.sum()
    if s > 0:
        x *= total / s
    return x
