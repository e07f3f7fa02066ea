"""Reference helpers for the compiled-kernel tests: a random MuJoCo kinematic tree and an
exact rational solution of the sole-compliance corner QP."""

from __future__ import annotations

from fractions import Fraction

import numpy as np


def random_tree_xml(n_joints: int, seed: int) -> str:
    """MJCF of a random tree with a free root and ``n_joints`` hinge/slide/ball joints
    (random offsets, body and inertial rotations, masses and sites)."""
    rng = np.random.default_rng(seed)

    def quat() -> str:
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        return " ".join(f"{v:.17g}" for v in q)

    def vec(scale: float) -> str:
        return " ".join(f"{v:.17g}" for v in rng.uniform(-scale, scale, 3))

    def inertial() -> str:
        m = rng.uniform(0.2, 5.0)
        d = " ".join(f"{v:.17g}" for v in rng.uniform(0.1, 0.2, 3))
        return f'<inertial pos="{vec(0.05)}" quat="{quat()}" mass="{m:.17g}" diaginertia="{d}"/>'

    bodies: list[list[str]] = [[]]  # children xml per body
    parents = [-1]
    kinds = []
    for _ in range(n_joints):
        parents.append(int(rng.integers(0, len(parents))))
        bodies.append([])
        kinds.append(rng.choice(["hinge", "hinge", "hinge", "slide", "ball"]))

    def body_xml(i: int) -> str:
        if i == 0:
            head = f'<body name="b0" pos="0 0 1"><freejoint name="root"/>{inertial()}'
        else:
            k = kinds[i - 1]
            axis = "" if k == "ball" else f' axis="{vec(1.0)}"'
            head = (
                f'<body name="b{i}" pos="{vec(0.3)}" quat="{quat()}">'
                f'<joint name="j{i}" type="{k}" pos="{vec(0.05)}"{axis}/>{inertial()}'
            )
        site = f'<site name="s{i}" pos="{vec(0.1)}" quat="{quat()}"/>'
        kids = "".join(body_xml(c) for c in range(1, len(parents)) if parents[c] == i)
        return head + site + kids + "</body>"

    return f'<mujoco><worldbody>{body_xml(0)}</worldbody></mujoco>'


def exact_prior_qp(rel: np.ndarray, prior: np.ndarray, total: float, sw: float,
                   support: np.ndarray, rho: float = 100.0) -> np.ndarray:
    """Rescaled minimiser of the compliance QP on a given support, in exact rationals
    (normal equations solved by fraction-exact Gauss-Jordan elimination), as floats."""
    idx = [int(j) for j in np.flatnonzero(support)]
    k = len(idx)
    r = Fraction(rho)
    w = Fraction(sw) * Fraction(sw)
    F = Fraction(total)
    R = [[Fraction(float(rel[j, a])) for j in idx] for a in range(2)]
    A = [
        [R[0][p] * R[0][q] + R[1][p] * R[1][q] + r * r + (w if p == q else 0) for q in range(k)]
        + [r * r * F + w * Fraction(float(prior[idx[p]]))]
        for p in range(k)
    ]
    for c in range(k):
        piv = next(i for i in range(c, k) if A[i][c] != 0)
        A[c], A[piv] = A[piv], A[c]
        for i in range(k):
            if i != c and A[i][c] != 0:
                f = A[i][c] / A[c][c]
                A[i] = [a - f * b for a, b in zip(A[i], A[c], strict=True)]
    x = [A[i][k] / A[i][i] for i in range(k)]
    s = sum(x)
    out = np.zeros(len(prior))
    for c, j in enumerate(idx):
        out[j] = float(x[c] * F / s)
    return out
