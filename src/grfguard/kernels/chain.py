"""Forward kinematics of a serial-hinge tree over a trajectory, compiled with numpy's bits.

:func:`grfguard.model.kinematics.body_poses` and
:func:`~grfguard.model.kinematics.center_of_mass` (the pattern generator's kinematics:
a dozen calls per planned walk) compose, body by body, ``R = R_parent @ rot(q)`` and
``p = p_parent + R_parent @ offset`` as stacked numpy products over the samples. Each of
those products makes one BLAS call per sample; here one loop does the same arithmetic in
the order numpy's products use, so the values are the same to the bit:

* a stacked 3x3 ``matmul`` (also with a broadcast first operand): each entry the fused
  multiply-adds ``fma(a2, b2, fma(a1, b1, a0 * b0))`` (:func:`grfguard.kernels._jit.fma`,
  as the virtual sensor's kernels already rely on);
* a stacked matrix times one vector: ``fma(a2, v2, fma(a0, v0, a1 * v1))`` (OpenBLAS's
  small ``gemv``); a broadcast matrix times a vector (numpy's loop without BLAS):
  ``(a0 v0 + a1 v1) + a2 v2``.

``tests/test_pattern_bits.py`` checks every output against the numpy path bit for bit.
Another CPU or BLAS may order numpy's products otherwise: the planner compares both paths
once per process (``grfguard.model.kinematics._use_compiled``) and keeps numpy's there.
"""

from __future__ import annotations

import numpy as np

from grfguard.kernels._jit import fma, njit

__all__ = ["chain_poses", "chain_com"]


@njit(inline="always")
def _rot_entry(axis, c, s, r, k):
    """Entry (r, k) of the rotation about coordinate axis ``axis`` (0, 1, 2) by the angle
    of cosine ``c`` and sine ``s``, built as :func:`grfguard.rotations._rot` builds it."""
    # _rot(angle, i, j): (k, k) = 1, (i, i) = (j, j) = c, (i, j) = -s, (j, i) = s, else +0
    i = (axis + 1) % 3
    j = (axis + 2) % 3
    if r == axis and k == axis:
        return 1.0
    if (r == i and k == i) or (r == j and k == j):
        return c
    if r == i and k == j:
        return -s
    if r == j and k == i:
        return s
    return 0.0


@njit
def chain_poses(p0, R0, parent, offset, axis, C, S, P, R):
    """Poses of bodies 1.. of a tree whose body 0 (the root) has position ``p0`` (T, 3)
    and the one orientation ``R0`` (3, 3) at every sample.

    Args:
        p0: Root positions (T, 3).
        R0: Root orientation (3, 3) (numpy's broadcast operand).
        parent: (nb,) parent index of each body (< its own; entry 0 unused).
        offset: (nb, 3) body origin in its parent's frame.
        axis: (nb,) coordinate axis (0, 1, 2) of the body's hinge.
        C, S: (nb, T) cosine and sine of each body's joint angle.
        P: (nb, T, 3) output positions (row 0 untouched).
        R: (nb, T, 3, 3) output orientations (row 0 untouched).
    """
    nb, T = C.shape[0], p0.shape[0]
    for b in range(1, nb):
        pb = parent[b]
        ax = axis[b]
        o0, o1, o2 = offset[b, 0], offset[b, 1], offset[b, 2]
        for t in range(T):
            c, s = C[b, t], S[b, t]
            for r in range(3):
                if pb == 0:
                    a0, a1, a2 = R0[r, 0], R0[r, 1], R0[r, 2]
                    P[b, t, r] = p0[t, r] + ((a0 * o0 + a1 * o1) + a2 * o2)
                else:
                    a0, a1, a2 = R[pb, t, r, 0], R[pb, t, r, 1], R[pb, t, r, 2]
                    P[b, t, r] = P[pb, t, r] + fma(a2, o2, fma(a0, o0, a1 * o1))
                for k in range(3):
                    m0 = _rot_entry(ax, c, s, 0, k)
                    m1 = _rot_entry(ax, c, s, 1, k)
                    m2 = _rot_entry(ax, c, s, 2, k)
                    R[b, t, r, k] = fma(a2, m2, fma(a1, m1, a0 * m0))


@njit
def chain_com(p0, R0, mass, com, P, R, out):
    """Whole-body CoM (T, 3) of the poses of :func:`chain_poses` (body 0 the root with
    ``p0``, ``R0``): ``sum_b m_b (p_b + R_b c_b) / sum_b m_b`` summed in body order from
    0.0, as :func:`grfguard.model.kinematics.center_of_mass`."""
    nb, T = mass.shape[0], p0.shape[0]
    total = 0.0
    for b in range(nb):
        total += mass[b]
    for t in range(T):
        for r in range(3):
            acc = 0.0
            for b in range(nb):
                c0, c1, c2 = com[b, 0], com[b, 1], com[b, 2]
                if b == 0:
                    v = p0[t, r] + ((R0[r, 0] * c0 + R0[r, 1] * c1) + R0[r, 2] * c2)
                else:
                    v = P[b, t, r] + fma(R[b, t, r, 2], c2, fma(R[b, t, r, 0], c0,
                                                                 R[b, t, r, 1] * c1))
                acc = acc + mass[b] * v
            out[t, r] = acc / total


def warm() -> None:
    """Compile (or load) both kernels on a two-body tree."""
    T = 2
    p0, R0 = np.zeros((T, 3)), np.eye(3)
    C, S = np.ones((2, T)), np.zeros((2, T))
    P, R = np.zeros((2, T, 3)), np.zeros((2, T, 3, 3))
    chain_poses(p0, R0, np.zeros(2, np.int64), np.zeros((2, 3)), np.zeros(2, np.int64), C, S,
                P, R)
    chain_com(p0, R0, np.ones(2), np.zeros((2, 3)), P, R, np.empty((T, 3)))
