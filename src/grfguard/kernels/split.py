"""Compiled loop of the corner QP over samples (:func:`grfguard.estimate.compliance.qp_split`).

Here, not in ``estimate``, so the kernels' on-disk cache is cleared when
:mod:`grfguard.kernels.nnls` changes (the cache tracks this directory's sources).
"""

from __future__ import annotations

import math

import numpy as np

from grfguard.kernels._jit import njit
from grfguard.kernels.nnls import prior_qp

__all__ = ["qp_loop"]


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
