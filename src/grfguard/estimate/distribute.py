r"""Contact-point force distribution: the QP of the paper's eq. (13)-(23), corrected.

Notation: ``n`` contact points ``p_i = (x_i, y_i)`` in one planar frame (a foot's
sole frame F, or the world frame W when both feet share one problem), ``T`` samples.

.. math::

    C = \begin{bmatrix} x_1 & \cdots & x_n \\ y_1 & \cdots & y_n \end{bmatrix},
    \qquad d = F_z \, p_{CoP} \in \mathbb{R}^2,

    \min_{N \in \mathbb{R}^n} \; \lVert C N - d \rVert^2 + N^\top W N
    \quad \text{s.t.} \quad N \ge 0, \quad G N = b,

with ``W = diag(w)``, ``w > 0`` [m²] (scalar or per point), ``G`` (g, n) and ``b``
(g,) [N]. By default ``G = 1ᵀ`` and ``b = F_z``: the forces sum to the foot load and
their moment about the frame origin reproduces the CoP. Two feet in one problem use
``G = [[1 1 1 1 0 0 0 0], [0 0 0 0 1 1 1 1]]`` (per-foot sums) or ``G = 1ᵀ`` (only the
total force and the ZMP known).

Corrections to the paper (DESIGN.md item 4): the right-hand side of eq. (21) is
``d``, not ``b``; the linear term of eq. (23) is ``-2 Cᵀd`` (the paper drops the 2);
the matrix of the inequality ``N ≥ 0`` is not an equality matrix; the indices of
eq. (16) are mixed. The paper's ``W = 0.01 I`` (:data:`PAPER_WEIGHT`) is not small
next to ``CᵀC`` (entries ≈ 0.01 m² for a 0.24 × 0.15 m sole): it pulls the
reconstructed CoP toward the sole centre (SURALP: CoP scaled by 0.83 in x and
0.63 in y while all four corners are loaded, 14 mm at 5 cm forward / 3 cm sideways,
40 mm at a corner of the sensor rectangle). The default is
:data:`DEFAULT_WEIGHT` = 1e-6 m².

Solution method (exact). With ``P = CᵀC + W`` (positive definite because ``w > 0``)
the KKT conditions are

.. math::

    P N - C^\top d - G^\top \lambda - \mu = 0, \quad G N = b, \quad
    N \ge 0, \quad \mu \ge 0, \quad \mu_i N_i = 0 .

For a guess of the free set ``S`` (the points allowed to carry load) the KKT system
is linear; its solution is *the* optimum if and only if ``N_S ≥ 0`` and ``μ ≥ 0``
off ``S`` (strict convexity makes the optimum unique). Stationarity gives
``N_i = (p_iᵀ ν + (Gᵀλ)_i) / w_i`` on ``S`` with the moment residual ``ν = d - C N``,
so each guess costs one (2 + g) × (2 + g) positive-definite solve (see
:func:`_evaluate`), done entry-wise for all samples at once.

* Fixed points, ``2ⁿ·n ≤ 160`` (one foot, n ≤ 5): every admissible free set's
  linear map ``(d, b) → (N or μ)`` is tabulated once in extended precision; a sample
  is one small product and an arg-max over the free sets of the worst KKT violation
  (explicit, "multi-parametric" solution).
* Otherwise: primal-dual active-set iterations (free set ← {N > 0} ∪ {μ < 0}),
  vectorized over samples, then the primal active-set method (feasible iterates,
  finite) for the few samples that have not converged, then enumeration of every
  admissible free set for any sample still open (degenerate cycling). A sample is
  accepted when its KKT conditions hold to 1e-12 relative. Fixed points use cached
  exact maps per free set; per-sample points redo the final solve in extended
  precision (``np.longdouble``), because with a tiny ``w`` and an unreachable CoP
  the double-precision solve loses up to ~1e-9 relative to cancellation.

Degenerate input, handled on purpose:

* ``b_j ≤ 0``: a group with zero load carries no force (all its points are held at
  zero and its equality row is dropped). A negative load ``b_j < 0`` (a sensor
  or estimator reading the foot pulled off the ground) is **treated as zero** and
  flagged in :attr:`DistributionSolution.load_clamped`.
* CoP on or outside the support polygon: nothing special; the solution loads the
  nearest edge or corner (the residual ``‖CN - d‖`` says how far it is).
* Coincident or collinear points: ``P`` stays positive definite, the weight shares
  the load between them.
* Non-finite input in a sample: forces ``NaN`` for that sample and
  :attr:`DistributionSolution.invalid_input` set; other samples are unaffected.
* Infeasible samples (a loaded group whose points are all masked out): forces
  ``NaN`` and :attr:`DistributionSolution.infeasible` set.

Streaming: :class:`DistributionSolver` (fixed points, plain Python floats, ~10 µs
per solve) and :func:`solve_distribution_one` (any points, one sample, the batch
path with T = 1) return the numbers of :func:`solve_distribution_batch` to 1e-9 N.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from grfguard.errors import ConfigError

__all__ = [
    "DEFAULT_WEIGHT",
    "PAPER_WEIGHT",
    "DistributionSolution",
    "DistributionSolver",
    "solve_distribution_batch",
    "solve_distribution_one",
    "distribute_forces",
    "distribute_forces_two_feet",
    "two_feet_equality",
    "reconstruct_cop",
]

#: Default regularization weight ``w`` in [m²]: small next to ``CᵀC`` (≈ 1e-2 m²).
DEFAULT_WEIGHT: float = 1e-6
#: The paper's ``W = 0.01 I`` in [m²]; biases the reconstructed CoP toward the centre.
PAPER_WEIGHT: float = 1e-2

#: Relative KKT tolerance for accepting a free set.
_TOL: float = 1e-12
#: Samples per block in the batch solver (bounds temporary memory).
_CHUNK: int = 4096
#: Primal-dual active-set iterations before the primal method.
_PDAS_ITER: int = 6
#: Per-sample points: redo every final free-set solve in extended precision (double
#: alone loses up to ~1e-6 relative when the CoP is unreachable and w is tiny).
_POLISH_ALL: bool = True
#: Pivot ratio below which a free-set solve is redone in extended precision.
_ILL_CONDITIONED: float = 1e-4
#: Active-set iterations of the batch solver before enumeration (None: 4 n + 4).
_MAX_ITER: int | None = None
#: Samples per block on the table path (fixed points): fits the cache.
_CHUNK_TABLE: int = 8192
#: Fixed points use the table of all free sets when 2^n · n is at most this.
_TABLE_MAX_ROWS: int = 160
#: Largest number of contact points (2^n free sets are enumerated in the fallback).
_MAX_POINTS: int = 16


# --------------------------------------------------------------------------- result


@dataclass(frozen=True)
class DistributionSolution:
    """Result of :func:`solve_distribution_batch` for ``T`` samples and ``n`` points.

    Attributes:
        forces: (T, n) normal forces ``N`` in [N]; ``NaN`` where not :attr:`ok`.
        eq_multipliers: (T, g) multipliers ``λ`` of ``G N = b`` in [N·m²]
            (0 for a dropped zero-load row).
        bound_multipliers: (T, n) multipliers ``μ ≥ 0`` of ``N ≥ 0`` in [N·m²]
            (0 on free points).
        active: (T, n) bool, point held at ``N = 0`` (bound active or masked out).
        kkt_residual: (T,) largest stationarity error on free points and dual
            infeasibility on held points in [N·m²].
        constraint_residual: (T,) ``max(|G N - b|, max(-N, 0))`` in [N] (against the
            clamped ``b``).
        objective: (T,) ``‖C N - d‖² + Nᵀ W N`` in [N²·m²].
        ok: (T,) bool, a solution was found (finite input, feasible).
        invalid_input: (T,) bool, some input of the sample was NaN or infinite.
        infeasible: (T,) bool, a group with positive load had no admissible point.
        load_clamped: (T,) bool, some ``b_j < 0`` was treated as 0.
        iterations: (T,) active-set iterations used; ``-1`` when the enumeration
            fallback settled the sample, ``0`` for invalid or infeasible samples.
    """

    forces: np.ndarray
    eq_multipliers: np.ndarray
    bound_multipliers: np.ndarray
    active: np.ndarray
    kkt_residual: np.ndarray
    constraint_residual: np.ndarray
    objective: np.ndarray
    ok: np.ndarray
    invalid_input: np.ndarray
    infeasible: np.ndarray
    load_clamped: np.ndarray
    iterations: np.ndarray

    @property
    def n_samples(self) -> int:
        """Number of samples ``T``."""
        return int(self.forces.shape[0])


# --------------------------------------------------------------------------- validation


def _as_float(name: str, value: Any) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"distribute: `{name}` must be numeric, got {value!r}") from exc
    return arr


def _check_points(points: Any) -> np.ndarray:
    pts = _as_float("points", points)
    if pts.ndim not in (2, 3) or pts.shape[-1] != 2:
        raise ConfigError(
            f"distribute: `points` must have shape (n, 2) or (T, n, 2) [m], got {pts.shape}; "
            "stack the (x, y) contact-point coordinates in the last axis"
        )
    n = pts.shape[-2]
    if not 1 <= n <= _MAX_POINTS:
        raise ConfigError(
            f"distribute: number of contact points n = {n} is outside [1, {_MAX_POINTS}]"
        )
    return pts


def _check_weight(weight: Any, n: int) -> np.ndarray:
    w = _as_float("weight", weight)
    if w.ndim == 0:
        w = np.full(n, float(w))
    if w.shape != (n,):
        raise ConfigError(
            f"distribute: `weight` must be a scalar or shape ({n},) [m²], got shape {w.shape}"
        )
    if not np.all(np.isfinite(w)) or np.any(w <= 0.0):
        raise ConfigError(
            f"distribute: `weight` must be finite and > 0 (strict convexity), got {w}; "
            f"use DEFAULT_WEIGHT = {DEFAULT_WEIGHT} m² or PAPER_WEIGHT = {PAPER_WEIGHT} m²"
        )
    return w


def _check_equality(G: Any, n: int) -> np.ndarray:
    if G is None:
        return np.ones((1, n))
    g_mat = _as_float("G", G)
    if g_mat.ndim == 1:
        g_mat = g_mat[None, :]
    if g_mat.ndim != 2 or g_mat.shape[1] != n or g_mat.shape[0] < 1:
        raise ConfigError(
            f"distribute: `G` must have shape (g, {n}) with g >= 1, got {g_mat.shape}"
        )
    if not np.all(np.isfinite(g_mat)) or np.any(g_mat < 0.0):
        raise ConfigError("distribute: `G` must be finite and non-negative (load sums)")
    support = g_mat > 0.0
    if np.any(support.sum(axis=0) > 1):
        cols = np.flatnonzero(support.sum(axis=0) > 1).tolist()
        raise ConfigError(
            f"distribute: points {cols} appear in more than one row of `G`; each row must "
            "sum over its own group of points (e.g. one row per foot)"
        )
    if np.any(support.sum(axis=1) == 0):
        rows = np.flatnonzero(support.sum(axis=1) == 0).tolist()
        raise ConfigError(f"distribute: rows {rows} of `G` are all zero; remove them")
    return g_mat


def _check_rhs(d: Any, b: Any, g: int) -> tuple[np.ndarray, np.ndarray]:
    d_arr = _as_float("d", d)
    if d_arr.ndim != 2 or d_arr.shape[1] != 2:
        raise ConfigError(
            f"distribute: `d` must have shape (T, 2) [N·m] (F_z times the CoP), got {d_arr.shape}"
        )
    b_arr = _as_float("b", b)
    if b_arr.ndim == 1 and g == 1:
        b_arr = b_arr[:, None]
    if b_arr.ndim != 2 or b_arr.shape != (d_arr.shape[0], g):
        raise ConfigError(
            f"distribute: `b` must have shape ({d_arr.shape[0]}, {g}) [N] (one load per row "
            f"of G and sample), got {b_arr.shape}"
        )
    return d_arr, b_arr


def _check_zero_mask(zero_mask: Any, T: int, n: int) -> np.ndarray:
    if zero_mask is None:
        return np.zeros((T, n), dtype=bool)
    zm = np.asarray(zero_mask, dtype=bool)
    if zm.ndim == 1:
        zm = np.broadcast_to(zm, (T, n))
    if zm.shape != (T, n):
        raise ConfigError(
            f"distribute: `zero_mask` must have shape ({n},) or ({T}, {n}), got {zm.shape}"
        )
    return zm


def _rmax(a: np.ndarray) -> np.ndarray:
    """Row maximum of a (m, k) array with small k (faster than ``max(axis=1)``)."""
    if a.shape[1] == 0:
        return np.full(a.shape[0], -np.inf)
    r = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        np.maximum(r, a[:, j], out=r)
    return r


def _rany(a: np.ndarray) -> np.ndarray:
    """Row ``any`` of a (m, k) bool array with small k."""
    r = np.zeros(a.shape[0], dtype=bool)
    for j in range(a.shape[1]):
        r |= a[:, j]
    return r


def _rsum(a: np.ndarray) -> np.ndarray:
    """Row sum of a (m, k) array with small k."""
    r = np.zeros(a.shape[0], dtype=np.result_type(a.dtype, np.float64))
    for j in range(a.shape[1]):
        r += a[:, j]
    return r


# --------------------------------------------------------------------------- core algebra


def _chol_solve(A: list[list[Any]], rhs: list[Any]) -> tuple[list[Any], Any]:
    """Solve symmetric positive-definite k × k systems given entry-wise as arrays (m,).

    Returns the solution and the smallest pivot ratio ``L_jj² / A_jj`` (a cheap
    conditioning indicator: rounding errors grow like its inverse).
    """
    k = len(rhs)
    L: list[list[Any]] = [[0.0] * k for _ in range(k)]
    ratio: Any = 1.0
    for j in range(k):
        acc = A[j][j]
        for p in range(j):
            acc = acc - L[j][p] * L[j][p]
        L[j][j] = np.sqrt(acc)
        r_j = acc / A[j][j]
        ratio = np.minimum(ratio, r_j)
        for i in range(j + 1, k):
            acc = A[i][j]
            for p in range(j):
                acc = acc - L[i][p] * L[j][p]
            L[i][j] = acc / L[j][j]
    y: list[Any] = [0.0] * k
    for i in range(k):
        acc = rhs[i]
        for p in range(i):
            acc = acc - L[i][p] * y[p]
        y[i] = acc / L[i][i]
    z: list[Any] = [0.0] * k
    for i in reversed(range(k)):
        acc = y[i]
        for p in range(i + 1, k):
            acc = acc - L[p][i] * z[p]
        z[i] = acc / L[i][i]
    return z, ratio


def _evaluate(
    X: np.ndarray,
    Y: np.ndarray,
    w: np.ndarray,
    G: np.ndarray,
    free: np.ndarray,
    kept: np.ndarray,
    d: np.ndarray,
    b: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Solve the KKT system of a guessed free set for ``m`` samples at once.

    Stationarity gives ``w_i N_i = p_iᵀ ν + (Gᵀλ)_i + μ_i`` with the moment residual
    ``ν = d - C N``: a free point carries ``N_i = (p_iᵀ ν + (Gᵀλ)_i) / w_i``, a held
    one has ``μ_i = -(p_iᵀ ν + (Gᵀλ)_i)``. Substituting in ``ν = d - CN`` and
    ``GN = b`` leaves the symmetric positive-definite (2 + g) system, with
    ``A = diag(a_i w_min / w_i)``, ``ν̃ = ν / w_min``, ``λ̃ = λ / w_min``,

    .. math::

        \begin{bmatrix} w_{min} I + C A C^\top & C A G^\top \\
        G A C^\top & G A G^\top \end{bmatrix}
        \begin{bmatrix} \tilde\nu \\ \tilde\lambda \end{bmatrix}
        = \begin{bmatrix} d \\ b \end{bmatrix},

    solved entry-wise (Cholesky) for all samples; no cancellation for tiny ``w``.

    Args:
        X: (m, n) or (n,) point x coordinates [m].
        Y: (m, n) or (n,) point y coordinates [m].
        w: (n,) weights [m²].
        G: (g, n) equality matrix.
        free: (m, n) bool free set.
        kept: (m, g) bool kept equality rows (dropped rows get ``λ = 0``).
        d: (m, 2) ``F_z · CoP`` [N·m].
        b: (m, g) loads [N].

    Returns:
        N (m, n) [N], λ (m, g) and μ (m, n) [N·m²] (μ = 0 on free points), and the
        smallest Cholesky pivot ratio (m,) (conditioning indicator).
    """
    g = G.shape[0]
    w_min = float(w.min())
    a = free * (w_min / w)
    rows = [X, Y, *G]
    ar = [a * r for r in rows]
    k = 2 + g
    A: list[list[Any]] = [[None] * k for _ in range(k)]
    for p in range(k):
        for q in range(p + 1):
            A[p][q] = np.sum(ar[p] * rows[q], axis=1)
            A[q][p] = A[p][q]
    A[0][0] = A[0][0] + w_min
    A[1][1] = A[1][1] + w_min
    rhs = [d[:, 0], d[:, 1]]
    for j in range(g):
        kj = kept[:, j]
        rhs.append(np.where(kj, b[:, j], 0.0))
        for q in range(k):
            if q != 2 + j:
                A[2 + j][q] = np.where(kj, A[2 + j][q], 0.0)
                A[q][2 + j] = A[2 + j][q]
        A[2 + j][2 + j] = np.where(kj, A[2 + j][2 + j], 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        z, ratio = _chol_solve(A, rhs)
    h = X * z[0][:, None] + Y * z[1][:, None]
    for j in range(g):
        h = h + G[j] * z[2 + j][:, None]
    N = a * h
    mu = np.where(free, 0.0, -h * w_min)
    lam = np.stack(z[2:], axis=1) * w_min
    return N, lam, mu, ratio


def _violation(
    N: np.ndarray,
    mu: np.ndarray,
    free: np.ndarray,
    checkable: np.ndarray,
    s_n: np.ndarray,
    s_mu: np.ndarray,
) -> np.ndarray:
    """Relative KKT violation: negative free forces and negative held multipliers."""
    v_n = np.max(np.where(free, -N, 0.0), axis=1) / s_n
    v_mu = np.max(np.where(checkable & ~free, -mu, 0.0), axis=1) / s_mu
    return np.maximum(np.maximum(v_n, v_mu), 0.0)


class _MapCache:
    """Exact linear maps ``(d, b) → (N, λ, μ)`` of free sets for fixed points, lazily.

    Computed once per free set in extended precision (:func:`_evaluate` on unit
    inputs), so fixed-point solves need neither refactoring nor polishing.
    """

    def __init__(self, X: np.ndarray, Y: np.ndarray, w: np.ndarray, G: np.ndarray) -> None:
        ld = np.longdouble
        self.X, self.Y, self.w, self.G = X.astype(ld), Y.astype(ld), w.astype(ld), G.astype(ld)
        self.n, self.g = G.shape[1], G.shape[0]
        self.cache: dict[int, np.ndarray] = {}

    def get(self, code: int) -> np.ndarray:
        """(2n + g, 2 + g) map of the free set / kept rows in ``code``: rows N, λ, μ."""
        B = self.cache.get(code)
        if B is None:
            n, g = self.n, self.g
            k = 2 + g
            free, kept = _decode(np.array([code], dtype=np.int64), n, g)
            eye = np.eye(k, dtype=np.longdouble)
            N, lam, mu, _ = _evaluate(
                self.X,
                self.Y,
                self.w,
                self.G,
                np.repeat(free, k, axis=0),
                np.repeat(kept, k, axis=0),
                eye[:, :2],
                eye[:, 2:],
            )
            B = np.concatenate([N, lam, mu], axis=1).T.astype(float)  # (2n + g, k)
            self.cache[code] = B
        return B


class _Block:
    """Samples of one chunk: coordinates, targets, masks and KKT scales."""

    def __init__(
        self,
        X: np.ndarray,
        Y: np.ndarray,
        w: np.ndarray,
        G: np.ndarray,
        d: np.ndarray,
        b: np.ndarray,
        forced: np.ndarray,
        kept: np.ndarray,
        maps: _MapCache | None = None,
    ) -> None:
        self.X, self.Y, self.w, self.G = X, Y, w, G
        self.d, self.b, self.forced, self.kept = d, b, forced, kept
        self.maps = maps
        p_scale = np.maximum(np.max(np.abs(X), axis=-1), np.max(np.abs(Y), axis=-1))
        p_scale = np.where(p_scale > 0.0, p_scale, 1.0)
        dn = _rmax(np.abs(d))
        self.s_n = np.maximum(np.maximum(_rmax(b), 0.0), dn / p_scale) + 1e-300
        self.p_scale = np.broadcast_to(p_scale, dn.shape)
        self.w_max = float(w.max())
        # a-priori multiplier scale (only weights N- against μ-violations on the table path)
        self.s_mu = self.w_max * self.s_n + self.p_scale * dn + 1e-300

    def mu_scale(self, sel: np.ndarray, N: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """Scale of the multipliers of a candidate: ``w s_N + |p| |d - C N| + |λ|`` [N·m²]."""
        X, Y = self.take(sel)
        d = self.d[sel]
        nu = np.maximum(
            np.abs(d[:, 0] - np.sum(N * X, axis=1)), np.abs(d[:, 1] - np.sum(N * Y, axis=1))
        )
        lam_max = np.max(np.abs(lam), axis=1, initial=0.0)
        return self.w_max * self.s_n[sel] + self.p_scale[sel] * nu + lam_max + 1e-300

    def take(self, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.X.ndim == 1:
            return self.X, self.Y
        return self.X[sel], self.Y[sel]

    def evaluate(
        self, sel: np.ndarray, free: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """N, λ, μ and pivot ratio of free sets ``free`` for samples ``sel``.

        Fixed points: through the cached exact linear map of each free set (ratio 1, no
        polishing needed). Per-sample points: :func:`_evaluate` in double precision.
        """
        if self.maps is None:
            X, Y = self.take(sel)
            return _evaluate(X, Y, self.w, self.G, free, self.kept[sel], self.d[sel], self.b[sel])
        n, g = self.G.shape[1], self.G.shape[0]
        m = sel.size
        x = np.concatenate([self.d[sel], self.b[sel]], axis=1)
        codes = _encode(free, self.kept[sel])
        uniq, inv = np.unique(codes, return_inverse=True)
        out = np.empty((m, 2 * n + g))
        if uniq.size == 1:
            out[:] = np.einsum("tk,rk->tr", x, self.maps.get(int(uniq[0])))
        else:
            order = np.argsort(inv, kind="stable")
            bounds = np.cumsum(np.bincount(inv, minlength=uniq.size))[:-1]
            for code, part in zip(uniq.tolist(), np.split(order, bounds), strict=True):
                out[part] = np.einsum("tk,rk->tr", x[part], self.maps.get(code))
        N = np.where(free, out[:, :n], 0.0)
        mu = np.where(free, 0.0, out[:, n + g :])
        return N, out[:, n : n + g], mu, np.ones(m)


def _solve_block(blk: _Block) -> tuple[np.ndarray, ...]:
    """Active-set solution of a block of samples, vectorized over samples.

    Phase 1, primal-dual active set (a few iterations): free set ← {N > 0} ∪ {μ < 0};
    it usually lands on the optimum in 1-3 solves but can cycle. Phase 2, for the
    samples left, the primal active-set method from a feasible start (each loaded
    group's load spread evenly): a full step to the free-set minimizer if it is
    non-negative, else a step to the first bound hit, which is then held; at the
    minimizer the held point with the most negative multiplier is released. Strict
    convexity makes phase 2 finite; samples still open after ``4 n + 4`` iterations
    (degenerate cycling) are settled by enumerating every admissible free set.
    A sample is accepted when its KKT conditions hold to a relative :data:`_TOL`.
    Samples whose free-set system is ill-conditioned are solved again in extended
    precision.
    """
    G, forced, kept = blk.G, blk.forced, blk.kept
    m, n = forced.shape
    sup = G > 0.0
    supf = sup.astype(float)
    grouped = sup.any(axis=0)
    adm = ~forced & grouped[None, :]
    N = np.zeros((m, n))
    lam = np.zeros((m, G.shape[0]))
    mu = np.zeros((m, n))
    iters = np.zeros(m, dtype=np.int64)
    ill = np.zeros(m, dtype=bool)
    rows = np.arange(m)
    free = adm.copy()
    todo = np.arange(m)
    # ---------------------------------------------------------------- phase 1
    for it in range(1, _PDAS_ITER + 1):
        if todo.size == 0:
            break
        f_t = free[todo]
        Ns, lt, mt, rt = blk.evaluate(todo, f_t)
        Nc = np.where(f_t, Ns, 0.0)
        s_mu = blk.mu_scale(todo, Nc, lt)
        viol = _violation(Ns, mt, f_t, ~forced[todo], blk.s_n[todo], s_mu)
        done = viol <= _TOL
        di = todo[done]
        N[di] = np.maximum(Nc[done], 0.0)
        lam[di], mu[di] = lt[done], mt[done]
        iters[di] = it
        ill[di] = rt[done] < _ILL_CONDITIONED
        nd = ~done
        todo = todo[nd]
        f_new = ~forced[todo] & (
            (f_t[nd] & (Ns[nd] > 0.0)) | (~f_t[nd] & (mt[nd] < -_TOL * s_mu[nd, None]))
        )
        empty = kept[todo] & ~np.any(f_new[:, None, :] & sup[None], axis=2)
        if np.any(empty):
            f_new |= np.any(empty[:, :, None] & sup[None], axis=1) & ~forced[todo]
        free[todo] = f_new
    # ---------------------------------------------------------------- phase 2
    if todo.size:
        denom = np.einsum("tn,gn->tg", adm[todo] * 1.0, G)  # (m', g)
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.where(kept[todo], blk.b[todo] / denom, 0.0)
        N[todo] = np.einsum("tg,gn->tn", share, supf) * adm[todo]
        free[todo] = adm[todo]
    max_iter = _MAX_ITER if _MAX_ITER is not None else 4 * n + 4
    for it in range(_PDAS_ITER + 1, _PDAS_ITER + max_iter + 1):
        if todo.size == 0:
            break
        f_t = free[todo]
        Ns, lt, mt, rt = blk.evaluate(todo, f_t)
        s_n = blk.s_n[todo][:, None]
        neg = f_t & (Ns < -_TOL * s_n)
        blocked = neg.any(axis=1)
        if np.any(blocked):
            bi = todo[blocked]
            Nb = N[bi]
            Nsb = Ns[blocked]
            with np.errstate(divide="ignore", invalid="ignore"):
                alpha = np.where(neg[blocked], Nb / (Nb - Nsb), np.inf)
            k = np.argmin(alpha, axis=1)
            a_min = alpha[rows[: bi.size], k][:, None]
            Nb = Nb + a_min * (Nsb - Nb)
            Nb[rows[: bi.size], k] = 0.0
            N[bi] = np.maximum(Nb, 0.0) * free[bi]
            free[bi, k] = False
        ok = ~blocked
        oi = todo[ok]
        No = np.where(f_t[ok], np.maximum(Ns[ok], 0.0), 0.0)
        N[oi] = No
        mo = mt[ok]
        check = ~f_t[ok] & ~forced[oi]
        rel = np.where(check, mo, np.inf) / blk.mu_scale(oi, No, lt[ok])[:, None]
        k = np.argmin(rel, axis=1)
        worst = rel[rows[: oi.size], k]
        done = worst >= -_TOL
        di = oi[done]
        lam[di] = lt[ok][done]
        mu[di] = mo[done]
        iters[di] = it
        ill[di] = rt[ok][done] < _ILL_CONDITIONED
        ri = oi[~done]
        free[ri, k[~done]] = True
        todo = np.concatenate([todo[blocked], ri])
    if todo.size:
        _enumerate(blk, todo, N, lam, mu, free)
        iters[todo] = -1
        ill[todo] = True
    if blk.maps is None and _POLISH_ALL:
        ill[:] = True
    pi = np.flatnonzero(ill)
    if pi.size:
        # cancellation-free final solve of the chosen free sets in extended precision
        ld = np.longdouble
        X, Y = blk.take(pi)
        Nl, ll, ml, _ = _evaluate(
            X.astype(ld),
            Y.astype(ld),
            blk.w.astype(ld),
            G.astype(ld),
            free[pi],
            kept[pi],
            blk.d[pi].astype(ld),
            blk.b[pi].astype(ld),
        )
        N[pi] = np.where(free[pi], np.maximum(Nl, 0.0), 0.0).astype(float)
        lam[pi] = ll.astype(float)
        mu[pi] = ml.astype(float)
    return N, lam, mu, free, iters


def _enumerate(
    blk: _Block,
    todo: np.ndarray,
    N: np.ndarray,
    lam: np.ndarray,
    mu: np.ndarray,
    free_out: np.ndarray,
) -> None:
    """Try every admissible free set for samples ``todo``; keep the least KKT violation."""
    forced, kept = blk.forced, blk.kept
    n = forced.shape[1]
    sup = blk.G > 0.0
    best = np.full(todo.size, np.inf)
    all_sets = ((np.arange(1 << n)[:, None] >> np.arange(n)) & 1).astype(bool)
    for s in all_sets:
        ok = ~np.any(s & forced[todo], axis=1)
        has = (s[None, None, :] & sup[None]).any(axis=2)  # (1, g)
        ok &= ~np.any(kept[todo] & ~has, axis=1)
        if not np.any(ok):
            continue
        sel = todo[ok]
        fs = np.broadcast_to(s, (sel.size, n))
        Nt, lt, mt, _ = blk.evaluate(sel, fs)
        s_mu = blk.mu_scale(sel, np.where(fs, Nt, 0.0), lt)
        viol = _violation(Nt, mt, fs, ~forced[sel], blk.s_n[sel], s_mu)
        viol = np.where(np.isfinite(viol), viol, np.inf)
        cur = best[ok]
        better = viol < cur
        if np.any(better):
            b_sel = sel[better]
            N[b_sel] = np.where(fs[better], np.maximum(Nt[better], 0.0), 0.0)
            lam[b_sel], mu[b_sel] = lt[better], mt[better]
            free_out[b_sel] = fs[better]
            cur[better] = viol[better]
            best[ok] = cur


def _decode(codes: np.ndarray, n: int, g: int) -> tuple[np.ndarray, np.ndarray]:
    """Bit codes -> (m, n) and (m, g) bool masks."""
    bits = (codes[:, None] >> np.arange(n + g)) & 1
    return bits[:, :n].astype(bool), bits[:, n:].astype(bool)


def _encode(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """(m, n) and (m, g) bool masks -> int64 bit codes."""
    n, g = first.shape[1], second.shape[1]
    w = np.left_shift(np.int64(1), np.arange(n + g, dtype=np.int64))
    return (first * w[:n]).sum(axis=1) + (second * w[n:]).sum(axis=1)


class _RegionTable:
    """Every admissible free set of one (held, kept) pattern for fixed points.

    The KKT solution of a free set is linear in ``x = (d, b)``: the table stores, per
    free set ``c`` and point ``i``, the row giving ``N_i`` (free) or ``μ_i`` (held),
    computed once in extended precision. A sample is solved by evaluating every row
    (one matrix product) and taking the free set whose KKT conditions hold best;
    the optimum is unique, so exactly one set satisfies them (up to ties on region
    boundaries, where the candidate solutions coincide).
    """

    def __init__(
        self,
        X: np.ndarray,
        Y: np.ndarray,
        w: np.ndarray,
        G: np.ndarray,
        held: np.ndarray,
        kept: np.ndarray,
    ) -> None:
        n, g = G.shape[1], G.shape[0]
        sup = G > 0.0
        sets = ((np.arange(1 << n)[:, None] >> np.arange(n)) & 1).astype(bool)
        adm = ~np.any(sets & held[None, :], axis=1)
        has = (sets[:, None, :] & sup[None]).any(axis=2)  # (2^n, g)
        adm &= ~np.any(kept[None, :] & ~has, axis=1)
        self.free = sets[adm]  # (R, n)
        R = self.free.shape[0]
        k = 2 + g
        ld = np.longdouble
        eye = np.eye(k, dtype=ld)
        fr = np.repeat(self.free, k, axis=0)
        Nm, lm, mm, _ = _evaluate(
            X.astype(ld),
            Y.astype(ld),
            w.astype(ld),
            G.astype(ld),
            fr,
            np.broadcast_to(kept, (R * k, g)),
            np.tile(eye[:, :2], (R, 1)),
            np.tile(eye[:, 2:], (R, 1)),
        )
        Nm = Nm.reshape(R, k, n).transpose(0, 2, 1).astype(float)  # (R, n, k)
        mm = mm.reshape(R, k, n).transpose(0, 2, 1).astype(float)
        self.lam = lm.reshape(R, k, g).transpose(0, 2, 1).astype(float)  # (R, g, k)
        self.rows = np.where(self.free[:, :, None], Nm, mm)  # (R, n, k)
        self.checkable = ~held  # (n,)
        # scaled test rows, layout (2k, n R): [x / s_n, x / s_mu] @ flat gives N_i / s_n on
        # free entries, μ_i / s_mu on held checkable ones and 0 on held unchecked ones
        fn = np.where(self.free[:, :, None], Nm, 0.0)
        fm = np.where(~self.free[:, :, None] & self.checkable[None, :, None], mm, 0.0)
        flat = np.concatenate([fn, fm], axis=2)  # (R, n, 2k)
        self.flat = np.ascontiguousarray(flat.transpose(2, 1, 0).reshape(2 * k, n * R))
        self.n, self.g, self.R = n, g, R
        # the largest free set (last row) has held points to check only if some point
        # belongs to no equality row
        self.full_needs_mu = bool(np.any(self.checkable & ~self.free[R - 1]))

    def _finish(
        self, x: np.ndarray, c: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        rows = self.rows[c]  # (m, n, k)
        V = np.einsum("tnk,tk->tn", rows, x)
        free = self.free[c]
        N = np.where(free, np.maximum(V, 0.0), 0.0)
        mu = np.where(free | ~self.checkable, 0.0, V)
        lam = np.einsum("tgk,tk->tg", self.lam[c], x)
        return N, lam, mu, free


def _solve_tables(
    tables: dict[int, _RegionTable],
    pts: np.ndarray,
    w: np.ndarray,
    G: np.ndarray,
    d: np.ndarray,
    b: np.ndarray,
    held: np.ndarray,
    kept: np.ndarray,
    good: np.ndarray,
    forces: np.ndarray,
    lam: np.ndarray,
    mu: np.ndarray,
    active: np.ndarray,
) -> None:
    """Fixed points, table path, whole log at once; writes into the output arrays.

    Samples are grouped by (held, kept) pattern; in each group the largest free set is
    tried for every sample with one product, and only the samples it does not solve
    go through the arg-max over all free sets (in cache-sized blocks).
    """
    n, g = G.shape[1], G.shape[0]
    X, Y = pts[:, 0], pts[:, 1]
    p_scale = float(max(np.max(np.abs(X)), np.max(np.abs(Y)))) or 1.0
    w_max = float(w.max())
    codes = _encode(held, kept)
    codes[~good] = -1
    present = np.flatnonzero(np.bincount(codes + 1, minlength=1)[1:]).tolist()
    x_all = np.concatenate([d, b], axis=1)
    everything = len(present) == 1 and bool(np.all(good))
    for code in present:
        tab = tables.get(code)
        if tab is None:
            h, kp = _decode(np.array([code], dtype=np.int64), n, g)
            tab = _RegionTable(X, Y, w, G, h[0], kp[0])
            tables[code] = tab
        sel = np.arange(codes.size) if everything else np.flatnonzero(codes == code)
        x = x_all if everything else x_all[sel]
        R = tab.R
        if tab.full_needs_mu or R == 1:
            rest = np.arange(sel.size) if R > 1 else np.zeros(0, dtype=np.int64)
            if R == 1 and not tab.free[0].any() and not tab.checkable.any():
                # nothing loaded (zero load or all points masked): all forces zero
                forces[sel], lam[sel], mu[sel], active[sel] = 0.0, 0.0, 0.0, True
            elif R == 1:
                c = np.zeros(sel.size, dtype=np.int64)
                N_, lam_, mu_, free_ = tab._finish(x, c)
                forces[sel], lam[sel], mu[sel], active[sel] = N_, lam_, mu_, ~free_
        else:
            f_full = tab.free[R - 1]
            V = np.einsum("nk,tk->tn", tab.rows[R - 1], x)
            neg = _rany((V < 0.0) & f_full)
            ok = np.flatnonzero(~neg)
            rest = np.flatnonzero(neg)
            lam_full = np.einsum("gk,tk->tg", tab.lam[R - 1], x[ok])
            if rest.size == 0:
                forces[sel] = np.where(f_full, V, 0.0)
                lam[sel] = lam_full
                mu[sel] = 0.0
                active[sel] = ~f_full
            else:
                so = sel[ok]
                forces[so] = np.where(f_full, V[ok], 0.0)
                lam[so] = lam_full
                mu[so] = 0.0
                active[so] = ~f_full
        for start in range(0, rest.size, _CHUNK_TABLE):
            r = rest[start : start + _CHUNK_TABLE]
            xr = x[r]
            dn = np.maximum(np.abs(xr[:, 0]), np.abs(xr[:, 1]))
            s_n = np.maximum(np.maximum(_rmax(xr[:, 2:]), 0.0), dn / p_scale) + 1e-300
            s_mu = w_max * s_n + p_scale * dn + 1e-300
            xs = np.concatenate([xr / s_n[:, None], xr / s_mu[:, None]], axis=1)
            score = np.einsum("tk,kr->tr", xs, tab.flat).reshape(r.size, n, R).min(axis=1)
            c = np.argmax(score, axis=1)
            N_, lam_, mu_, free_ = tab._finish(xr, c)
            sr = sel[r]
            forces[sr], lam[sr], mu[sr], active[sr] = N_, lam_, mu_, ~free_


# --------------------------------------------------------------------------- batch API


def solve_distribution_batch(
    points: Any,
    d: Any,
    b: Any,
    weight: Any = DEFAULT_WEIGHT,
    G: Any = None,
    zero_mask: Any = None,
) -> DistributionSolution:
    r"""Solve the contact-point QP exactly for every sample of a log.

    .. math::

        \min_N \lVert C N - d_t \rVert^2 + N^\top W N
        \quad \text{s.t.} \quad N \ge 0,\; G N = \max(b_t, 0),\;
        N_i = 0 \text{ where zero\_mask}_{t,i}.

    Args:
        points: (n, 2) contact points shared by all samples, or (T, n, 2) per
            sample, in [m], in the frame of ``d``.
        d: (T, 2) target first moment ``F_z · p_CoP`` in [N·m].
        b: (T, g) loads of the equality rows in [N] (``(T,)`` allowed when g = 1).
            Negative loads are treated as 0 (flagged in ``load_clamped``).
        weight: ``w`` in [m²], scalar or (n,), > 0. Default :data:`DEFAULT_WEIGHT`;
            the paper uses :data:`PAPER_WEIGHT`.
        G: (g, n) non-negative equality matrix whose rows sum over disjoint groups of
            points; default ``1ᵀ`` (one row).
        zero_mask: optional (n,) or (T, n) bool, points forced to carry no load
            (e.g. a foot in swing).

    Returns:
        :class:`DistributionSolution` with forces (T, n) in [N] and diagnostics.

    Raises:
        ConfigError: shapes or values of the arguments are impossible.
    """
    pts = _check_points(points)
    n = pts.shape[-2]
    w = _check_weight(weight, n)
    g_mat = _check_equality(G, n)
    g = g_mat.shape[0]
    d_arr, b_arr = _check_rhs(d, b, g)
    T = d_arr.shape[0]
    if pts.ndim == 3 and pts.shape[0] != T:
        raise ConfigError(
            f"distribute: per-sample `points` has {pts.shape[0]} samples but `d` has {T}"
        )
    zm = _check_zero_mask(zero_mask, T, n)

    invalid = _rany(~np.isfinite(d_arr)) | _rany(~np.isfinite(b_arr))
    if pts.ndim == 3:
        invalid |= ~np.all(np.isfinite(pts), axis=(1, 2))
    elif not np.all(np.isfinite(pts)):
        invalid[:] = True
    clamped = _rany(b_arr < 0.0) & ~invalid
    b_c = np.where(b_arr > 0.0, b_arr, 0.0)
    kept = b_c > 0.0  # (T, g)
    sup = g_mat > 0.0
    in_dropped = np.any(~kept[:, :, None] & sup[None], axis=1)  # (T, n)
    forced = zm | in_dropped
    has_free = np.any(~forced[:, None, :] & sup[None], axis=2)  # (T, g)
    infeasible = _rany(kept & ~has_free) & ~invalid
    good = ~invalid & ~infeasible

    forces = np.full((T, n), np.nan)
    lam = np.full((T, g), np.nan)
    mu = np.full((T, n), np.nan)
    active = np.ones((T, n), dtype=bool)
    iters = np.zeros(T, dtype=np.int64)

    if pts.ndim == 2 and (1 << n) * n <= _TABLE_MAX_ROWS:
        tables: dict[int, _RegionTable] = {}
        _solve_tables(
            tables, pts, w, g_mat, d_arr, b_c, forced, kept, good, forces, lam, mu, active
        )
        iters[good] = 1
    else:
        maps = _MapCache(pts[:, 0], pts[:, 1], w, g_mat) if pts.ndim == 2 else None
        good_idx = np.flatnonzero(good)
        for start in range(0, good_idx.size, _CHUNK):
            idx = good_idx[start : start + _CHUNK]
            if pts.ndim == 2:
                X, Y = pts[:, 0], pts[:, 1]
            else:
                X, Y = pts[idx, :, 0], pts[idx, :, 1]
            blk = _Block(X, Y, w, g_mat, d_arr[idx], b_c[idx], forced[idx], kept[idx], maps)
            N, lt, mt, fr, it = _solve_block(blk)
            forces[idx] = N
            lam[idx] = lt
            mu[idx] = np.where(forced[idx], 0.0, mt)
            active[idx] = ~fr
            iters[idx] = it

    kkt, cres, obj = _residuals(pts, w, g_mat, d_arr, b_c, forces, lam, mu, active, forced)
    return DistributionSolution(
        forces=forces,
        eq_multipliers=lam,
        bound_multipliers=mu,
        active=active,
        kkt_residual=kkt,
        constraint_residual=cres,
        objective=obj,
        ok=good,
        invalid_input=invalid,
        infeasible=infeasible,
        load_clamped=clamped,
        iterations=iters,
    )


def _residuals(
    pts: np.ndarray,
    w: np.ndarray,
    G: np.ndarray,
    d: np.ndarray,
    b: np.ndarray,
    N: np.ndarray,
    lam: np.ndarray,
    mu: np.ndarray,
    active: np.ndarray,
    forced: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Independent KKT, constraint residuals and objective from the final forces."""
    if pts.ndim == 2:
        CN = np.einsum("tn,nk->tk", N, pts)
        ctd = np.einsum("nk,tk->tn", pts, d)
        PN = np.einsum("nk,tk->tn", pts, CN) + N * w
    else:
        CN = np.einsum("tn,tnk->tk", N, pts)
        ctd = np.einsum("tnk,tk->tn", pts, d)
        PN = np.einsum("tnk,tk->tn", pts, CN) + N * w
    grad = PN - ctd - np.einsum("tg,gn->tn", lam, G)  # stationarity: grad - mu = 0
    stat = np.where(active, 0.0, np.abs(grad))
    dual = np.where(active & ~forced, np.maximum(-grad, 0.0), 0.0)
    kkt = np.maximum(_rmax(stat), _rmax(dual))
    eq_err = _rmax(np.abs(np.einsum("tn,gn->tg", N, G) - b))
    cres = np.maximum(eq_err, np.maximum(_rmax(-N), 0.0))
    obj = _rsum((CN - d) ** 2) + _rsum(w * N * N)
    return kkt, cres, obj


# --------------------------------------------------------------------------- convenience


def distribute_forces(
    points: Any, cop: Any, total_force: Any, weight: Any = DEFAULT_WEIGHT
) -> np.ndarray:
    """Split one foot's load over its contact points (``Σ N = F_z``, ``C N ≈ F_z·CoP``).

    Args:
        points: (n, 2) or (T, n, 2) contact points in the foot (sole) frame in [m].
        cop: (T, 2) centre of pressure in the same frame in [m].
        total_force: (T,) vertical load ``F_z`` in [N]; ``F_z ≤ 0`` gives zero forces.
        weight: regularization ``w`` in [m²] (default :data:`DEFAULT_WEIGHT`).

    Returns:
        (T, n) forces in [N]; rows are ``NaN`` where the input was not finite.
    """
    cop_arr = _as_float("cop", cop)
    fz = _as_float("total_force", total_force)
    if cop_arr.ndim != 2 or cop_arr.shape[1] != 2 or fz.shape != (cop_arr.shape[0],):
        raise ConfigError(
            f"distribute_forces: `cop` must be (T, 2) [m] and `total_force` (T,) [N], got "
            f"{cop_arr.shape} and {fz.shape}"
        )
    d = np.maximum(fz, 0.0)[:, None] * cop_arr
    d = np.where(np.isfinite(fz)[:, None], d, np.nan)
    return solve_distribution_batch(points, d, fz, weight).forces


def two_feet_equality(n_right: int = 4, n_left: int = 4, per_foot: bool = True) -> np.ndarray:
    """Equality matrix ``G`` for the right then left foot's points in one problem.

    Args:
        n_right: points of the right foot.
        n_left: points of the left foot.
        per_foot: two rows (per-foot sums) if True, else one row (total only).

    Returns:
        (2, n_right + n_left) or (1, n_right + n_left) matrix.
    """
    if per_foot:
        G = np.zeros((2, n_right + n_left))
        G[0, :n_right] = 1.0
        G[1, n_right:] = 1.0
        return G
    return np.ones((1, n_right + n_left))


def distribute_forces_two_feet(
    points_right_in_world: Any,
    points_left_in_world: Any,
    total_force: Any,
    zmp_in_world: Any,
    weight: Any = DEFAULT_WEIGHT,
    foot_forces: Any = None,
    in_contact: Any = None,
) -> DistributionSolution:
    """One QP over the contact points of both feet (double support), world frame.

    With only the total force and the ZMP known the program has one equality row
    (``Σ N = F_z``): a rigid body on equal springs, which a prototype found the best
    split in double support. With ``foot_forces`` the per-foot sums are imposed.

    Args:
        points_right_in_world: (n_r, 2) or (T, n_r, 2) right-foot points in [m].
        points_left_in_world: (n_l, 2) or (T, n_l, 2) left-foot points in [m].
        total_force: (T,) total vertical ground force ``F_z`` in [N].
        zmp_in_world: (T, 2) ZMP (overall CoP) in [m].
        weight: regularization ``w`` in [m²].
        foot_forces: optional (T, 2) loads of the right and left foot in [N].
        in_contact: optional (T, 2) bool; a foot not in contact carries no force.

    Returns:
        :class:`DistributionSolution` with forces (T, n_r + n_l), right foot first.
    """
    pr = _check_points(points_right_in_world)
    pl = _check_points(points_left_in_world)
    zmp = _as_float("zmp_in_world", zmp_in_world)
    fz = _as_float("total_force", total_force)
    if zmp.ndim != 2 or zmp.shape[1] != 2 or fz.shape != (zmp.shape[0],):
        raise ConfigError(
            "distribute_forces_two_feet: `zmp_in_world` must be (T, 2) [m] and "
            f"`total_force` (T,) [N], got {zmp.shape} and {fz.shape}"
        )
    T = zmp.shape[0]
    if pr.ndim == 3 or pl.ndim == 3:
        pr = np.broadcast_to(pr, (T, *pr.shape[-2:]))
        pl = np.broadcast_to(pl, (T, *pl.shape[-2:]))
        pts = np.concatenate([pr, pl], axis=1)
    else:
        pts = np.concatenate([pr, pl], axis=0)
    n_r, n_l = pr.shape[-2], pl.shape[-2]
    d = np.maximum(fz, 0.0)[:, None] * zmp
    d = np.where(np.isfinite(fz)[:, None], d, np.nan)
    if foot_forces is None:
        G = two_feet_equality(n_r, n_l, per_foot=False)
        b = fz[:, None]
    else:
        G = two_feet_equality(n_r, n_l, per_foot=True)
        b = _as_float("foot_forces", foot_forces)
        if b.shape != (T, 2):
            raise ConfigError(
                f"distribute_forces_two_feet: `foot_forces` must be ({T}, 2) [N], got {b.shape}"
            )
    zero_mask = None
    if in_contact is not None:
        c = np.asarray(in_contact, dtype=bool)
        if c.shape != (T, 2):
            raise ConfigError(
                f"distribute_forces_two_feet: `in_contact` must be ({T}, 2) bool, got {c.shape}"
            )
        zero_mask = np.concatenate(
            [np.repeat(~c[:, :1], n_r, axis=1), np.repeat(~c[:, 1:], n_l, axis=1)], axis=1
        )
    return solve_distribution_batch(pts, d, b, weight, G=G, zero_mask=zero_mask)


def reconstruct_cop(points: Any, forces: Any) -> np.ndarray:
    """Centre of pressure ``Σ p_i N_i / Σ N_i`` of a force distribution.

    Args:
        points: (n, 2) or (T, n, 2) contact points in [m].
        forces: (T, n) forces in [N].

    Returns:
        (T, 2) CoP in [m], ``NaN`` where the total force is not positive.
    """
    pts = _check_points(points)
    N = _as_float("forces", forces)
    if pts.ndim == 2:
        num = np.einsum("tn,nk->tk", N, pts)
    else:
        num = np.einsum("tn,tnk->tk", N, pts)
    tot = N.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(tot[:, None] > 0.0, num / tot[:, None], np.nan)


# --------------------------------------------------------------------------- streaming


def _dot_rows(rows: Any, x: tuple[float, ...]) -> list[float]:
    """``[r · x for r in rows]`` in plain floats (unrolled for 3 and 4 inputs)."""
    if len(x) == 3:
        x0, x1, x2 = x
        return [a * x0 + b * x1 + c * x2 for a, b, c in rows]
    if len(x) == 4:
        x0, x1, x2, x3 = x
        return [a * x0 + b * x1 + c * x2 + e * x3 for a, b, c, e in rows]
    return [sum(a * v for a, v in zip(r, x, strict=True)) for r in rows]


def _primal_step(
    current: list[float], target: list[float], free: list[bool], tol_n: float
) -> tuple[list[float], bool]:
    """One step of the primal active-set method (in place on ``free``).

    Moves from the feasible ``current`` toward the equality-constrained optimum ``target``
    of the free set; if a free point would go negative (below ``-tol_n`` [N]) the step
    stops at the first such point, which is fixed to zero and leaves the free set.

    Returns:
        The new point and whether a point was blocked (True: solve again).
    """
    n = len(current)
    alpha, blk = 1.0, -1
    for i in range(n):
        if free[i] and target[i] < -tol_n:
            a_i = current[i] / (current[i] - target[i])
            if a_i < alpha:
                alpha, blk = a_i, i
    if blk < 0:
        return current, False
    moved = [current[i] + alpha * (target[i] - current[i]) if free[i] else 0.0
             for i in range(n)]
    moved[blk] = 0.0
    free[blk] = False
    return moved, True


class DistributionSolver:
    r"""Per-sample solver for fixed contact points (one foot in its sole frame), 1 kHz.

    Same program and same answer as :func:`solve_distribution_batch`: the linear map
    ``(d, b) → (N, μ)`` of every free set comes from the same extended-precision
    table, and a primal active-set iteration in plain Python floats (no numpy call on
    the hot path) walks to the free set whose KKT conditions hold to 1e-12 relative.

    Args:
        points: (n, 2) contact points in [m].
        weight: ``w`` in [m²], scalar or (n,).
        G: (g, n) equality matrix (default ``1ᵀ``).

    Example:
        >>> solver = DistributionSolver(SURALP.sensor_positions_in_foot())
        >>> forces = solver.solve(f_z * cop_x, f_z * cop_y, f_z)  # tuple of n floats [N]
    """

    def __init__(self, points: Any, weight: Any = DEFAULT_WEIGHT, G: Any = None) -> None:
        pts = _check_points(points)
        if pts.ndim != 2 or not np.all(np.isfinite(pts)):
            raise ConfigError(
                "DistributionSolver: `points` must be a finite (n, 2) array [m]; use "
                "solve_distribution_one for points that change every sample"
            )
        self.points = pts.copy()
        self.n = pts.shape[0]
        self.weight = _check_weight(weight, self.n)
        self.G = _check_equality(G, self.n)
        self.g = self.G.shape[0]
        self._groups = [tuple(np.flatnonzero(row > 0.0).tolist()) for row in self.G]
        self._gshare = [float(self.G[j, list(grp)].sum()) for j, grp in enumerate(self._groups)]
        p_scale = float(np.max(np.abs(pts)))
        self._p_scale = p_scale if p_scale > 0.0 else 1.0
        self._w_max = float(self.weight.max())
        self._px = [float(v) for v in pts[:, 0]]
        self._py = [float(v) for v in pts[:, 1]]
        self._tables: dict[int, Any] = {}
        #: Iterations of the last solve (-1: enumeration fallback, 0: trivial/invalid).
        self.last_iterations = 0
        self._table(0)  # warm the all-loaded pattern

    def _table(self, code: int) -> Any:
        entry = self._tables.get(code)
        if entry is None:
            held, kept = _decode(np.array([code], dtype=np.int64), self.n, self.g)
            tab = _RegionTable(
                self.points[:, 0], self.points[:, 1], self.weight, self.G, held[0], kept[0]
            )
            bits = (tab.free * (1 << np.arange(self.n))).sum(axis=1).tolist()
            rows = {
                int(bt): (
                    tuple(tuple(r) for r in tab.rows[c].tolist()),
                    tuple(tuple(r) for r in tab.lam[c].tolist()),
                )
                for c, bt in enumerate(bits)
            }
            full = None if tab.full_needs_mu or tab.R < 1 else rows[int(bits[-1])][0]
            entry = (rows, [bool(v) for v in tab.checkable], full)
            self._tables[code] = entry
        return entry

    def solve(
        self, d_x: float, d_y: float, b: tuple[float, ...] | list[float] | float
    ) -> tuple[float, ...]:
        """Forces for one sample.

        Args:
            d_x: ``F_z · CoP_x`` in [N·m].
            d_y: ``F_z · CoP_y`` in [N·m].
            b: loads of the equality rows in [N] (a float when g = 1); negative loads
                are treated as 0.

        Returns:
            Tuple of ``n`` forces in [N]; all ``NaN`` if the input is not finite.
        """
        n, g = self.n, self.g
        if isinstance(b, (int, float)):
            b = (float(b),)
        if len(b) != g:
            raise ConfigError(f"DistributionSolver.solve: `b` needs {g} value(s), got {len(b)}")
        inf = float("inf")
        for v in (d_x, d_y, *b):
            if v != v or v == inf or v == -inf:
                self.last_iterations = 0
                return (float("nan"),) * n
        bc = [float(v) if v > 0.0 else 0.0 for v in b]
        held = [False] * n
        code = 0
        for j, grp in enumerate(self._groups):
            if bc[j] > 0.0:
                code |= 1 << (n + j)
            else:
                for i in grp:
                    held[i] = True
                    code |= 1 << i
        rows, checkable, rows_full = self._table(code)
        x = (float(d_x), float(d_y), *bc)
        dn = max(abs(x[0]), abs(x[1]))
        s_n = max(max(bc), dn / self._p_scale) + 1e-300
        tol_n = _TOL * s_n
        px, py = self._px, self._py
        # feasible start: each loaded group's load spread over its points
        free = [not held[i] for i in range(n)]
        N = [0.0] * n
        for j, grp in enumerate(self._groups):
            if bc[j] > 0.0:
                share = bc[j] / self._gshare[j]
                for i in grp:
                    N[i] = share
        full = rows_full
        if full is not None:
            # common case: every admissible point loaded at the unconstrained optimum
            V = _dot_rows(full, x)
            if min((V[i] for i in range(n) if free[i]), default=0.0) >= -tol_n:
                self.last_iterations = 1
                return tuple(V[i] if free[i] and V[i] > 0.0 else 0.0 for i in range(n))
        for it in range(1, 4 * n + 5):
            bits = 0
            for i in range(n):
                if free[i]:
                    bits |= 1 << i
            entry = rows.get(bits)
            if entry is None:
                break
            R, L = entry
            V = _dot_rows(R, x)
            N, blocked = _primal_step(N, V, free, tol_n)
            if blocked:
                continue
            # multiplier scale of this candidate: w s_N + |p| |d - C N| + |λ|
            cx = x[0]
            cy = x[1]
            for i in range(n):
                if free[i]:
                    cx -= px[i] * V[i]
                    cy -= py[i] * V[i]
            lam_max = max(abs(v) for v in _dot_rows(L, x))
            s_mu = self._w_max * s_n + self._p_scale * max(abs(cx), abs(cy)) + lam_max + 1e-300
            worst = -_TOL * s_mu
            k = -1
            for i in range(n):
                if not free[i] and checkable[i] and V[i] < worst:
                    worst, k = V[i], i
            if k < 0:
                self.last_iterations = it
                return tuple(V[i] if free[i] and V[i] > 0.0 else 0.0 for i in range(n))
            N = [V[i] if free[i] and V[i] > 0.0 else 0.0 for i in range(n)]
            free[k] = True
        # rare (degenerate cycling): the exact batch path
        self.last_iterations = -1
        sol = solve_distribution_batch(
            self.points, np.array([[d_x, d_y]]), np.array([list(b)]), self.weight, self.G
        )
        return tuple(float(v) for v in sol.forces[0])


def _evaluate_one(
    px: list[float],
    py: list[float],
    w: list[float],
    Gl: list[list[float]],
    free: list[bool],
    kept: list[bool],
    x: tuple[float, ...],
) -> tuple[list[float], list[float], list[float]]:
    """:func:`_evaluate` for one sample in plain Python floats: N, λ, μ."""
    n, g = len(px), len(Gl)
    k = 2 + g
    w_min = min(w)
    a = [w_min / w[i] if free[i] else 0.0 for i in range(n)]
    rows = [px, py, *Gl]
    ar = [[a[i] * r[i] for i in range(n)] for r in rows]
    A = [[0.0] * k for _ in range(k)]
    for p in range(k):
        for q in range(p + 1):
            v = 0.0
            arp, rq = ar[p], rows[q]
            for i in range(n):
                v += arp[i] * rq[i]
            A[p][q] = v
            A[q][p] = v
    A[0][0] += w_min
    A[1][1] += w_min
    rhs = [x[0], x[1]]
    for j in range(g):
        if kept[j]:
            rhs.append(x[2 + j])
        else:
            rhs.append(0.0)
            for q in range(k):
                A[2 + j][q] = 0.0
                A[q][2 + j] = 0.0
            A[2 + j][2 + j] = 1.0
    # Cholesky
    L = [[0.0] * k for _ in range(k)]
    for j in range(k):
        acc = A[j][j] - sum(L[j][p] * L[j][p] for p in range(j))
        if not acc > 0.0:
            return [math.nan] * n, [math.nan] * g, [math.nan] * n
        L[j][j] = math.sqrt(acc)
        for i in range(j + 1, k):
            L[i][j] = (A[i][j] - sum(L[i][p] * L[j][p] for p in range(j))) / L[j][j]
    y = [0.0] * k
    for i in range(k):
        y[i] = (rhs[i] - sum(L[i][p] * y[p] for p in range(i))) / L[i][i]
    z = [0.0] * k
    for i in reversed(range(k)):
        z[i] = (y[i] - sum(L[p][i] * z[p] for p in range(i + 1, k))) / L[i][i]
    h = [px[i] * z[0] + py[i] * z[1] + sum(Gl[j][i] * z[2 + j] for j in range(g)) for i in range(n)]
    N = [a[i] * h[i] for i in range(n)]
    mu = [0.0 if free[i] else -h[i] * w_min for i in range(n)]
    lam = [z[2 + j] * w_min for j in range(g)]
    return N, lam, mu


def solve_distribution_one(
    points: Any,
    d: Any,
    b: Any,
    weight: Any = DEFAULT_WEIGHT,
    G: Any = None,
    zero_mask: Any = None,
) -> np.ndarray:
    """Solve one sample of the contact-point QP (points may change every call).

    The active-set search runs in plain Python floats (same steps and tolerances as
    the batch solver); the free set found is then solved once more in extended
    precision, exactly as :func:`solve_distribution_batch` does for per-sample
    points, so both agree to rounding. For fixed points at 1 kHz
    :class:`DistributionSolver` is faster still.

    Args:
        points: (n, 2) contact points in [m].
        d: (2,) ``F_z · CoP`` in [N·m].
        b: (g,) loads in [N] (a float when g = 1); negative loads count as 0.
        weight: ``w`` in [m²].
        G: (g, n) equality matrix (default ``1ᵀ``).
        zero_mask: optional (n,) bool, points forced to zero.

    Returns:
        (n,) forces in [N]; ``NaN`` if the input is not finite or infeasible.
    """
    pts = _check_points(points)
    if pts.ndim != 2:
        raise ConfigError(f"solve_distribution_one: `points` must be (n, 2) [m], got {pts.shape}")
    n = pts.shape[0]
    w_arr = _check_weight(weight, n)
    g_mat = _check_equality(G, n)
    g = g_mat.shape[0]
    d_arr = _as_float("d", d).reshape(-1)
    b_arr = np.atleast_1d(_as_float("b", b)).reshape(-1)
    if d_arr.shape != (2,) or b_arr.shape != (g,):
        raise ConfigError(
            f"solve_distribution_one: `d` must be (2,) [N·m] and `b` ({g},) [N], got "
            f"{d_arr.shape} and {b_arr.shape}"
        )
    zm = [False] * n if zero_mask is None else [bool(v) for v in np.asarray(zero_mask).reshape(-1)]
    if len(zm) != n:
        raise ConfigError(f"solve_distribution_one: `zero_mask` must be ({n},), got {len(zm)}")
    px, py = pts[:, 0].tolist(), pts[:, 1].tolist()
    dl, bl = d_arr.tolist(), b_arr.tolist()
    if not all(math.isfinite(v) for v in (*px, *py, *dl, *bl)):
        return np.full(n, np.nan)
    w = w_arr.tolist()
    Gl = g_mat.tolist()
    groups = [[i for i in range(n) if Gl[j][i] > 0.0] for j in range(g)]
    bc = [v if v > 0.0 else 0.0 for v in bl]
    kept = [v > 0.0 for v in bc]
    forced = list(zm)
    for j in range(g):
        if not kept[j]:
            for i in groups[j]:
                forced[i] = True
    for j in range(g):
        if kept[j] and all(forced[i] for i in groups[j]):
            return np.full(n, np.nan)  # infeasible
    x = (dl[0], dl[1], *bc)
    p_scale = max(max(abs(v) for v in px), max(abs(v) for v in py)) or 1.0
    dn = max(abs(dl[0]), abs(dl[1]))
    s_n = max(max(bc), dn / p_scale) + 1e-300
    w_max = max(w)
    grouped = [any(Gl[j][i] > 0.0 for j in range(g)) for i in range(n)]

    def mu_scale(N: list[float], lam: list[float]) -> float:
        cx = dl[0] - sum(px[i] * N[i] for i in range(n))
        cy = dl[1] - sum(py[i] * N[i] for i in range(n))
        return w_max * s_n + p_scale * max(abs(cx), abs(cy)) + max(map(abs, lam)) + 1e-300

    def repair(f: list[bool]) -> list[bool]:
        for j in range(g):
            if kept[j] and not any(f[i] for i in groups[j]):
                for i in groups[j]:
                    f[i] = not forced[i]
        return f

    free = [not forced[i] and grouped[i] for i in range(n)]
    found = None
    for _ in range(_PDAS_ITER):  # phase 1: primal-dual active set
        N, lam, mu = _evaluate_one(px, py, w, Gl, free, kept, x)
        smu = mu_scale(N, lam)
        bad_n = any(free[i] and N[i] < -_TOL * s_n for i in range(n))
        bad_mu = any(not free[i] and not forced[i] and mu[i] < -_TOL * smu for i in range(n))
        if not (bad_n or bad_mu):
            found = free
            break
        free = repair(
            [
                not forced[i]
                and ((free[i] and N[i] > 0.0) or (not free[i] and mu[i] < -_TOL * smu))
                for i in range(n)
            ]
        )
    if found is None:  # phase 2: primal active set from a feasible start
        free = [not forced[i] and grouped[i] for i in range(n)]
        Ncur = [0.0] * n
        for j in range(g):
            if kept[j]:
                tot = sum(Gl[j][i] for i in groups[j] if free[i])
                for i in groups[j]:
                    if free[i]:
                        Ncur[i] = bc[j] / tot
        for _ in range(4 * n + 4):
            N, lam, mu = _evaluate_one(px, py, w, Gl, free, kept, x)
            Ncur, blocked = _primal_step(Ncur, N, free, _TOL * s_n)
            if blocked:
                continue
            Ncur = [N[i] if free[i] and N[i] > 0.0 else 0.0 for i in range(n)]
            smu = mu_scale(Ncur, lam)
            worst, k = -_TOL * smu, -1
            for i in range(n):
                if not free[i] and not forced[i] and mu[i] < worst:
                    worst, k = mu[i], i
            if k < 0:
                found = free
                break
            free[k] = True
    if found is None:  # degenerate cycling: the batch path with its enumeration
        sol = solve_distribution_batch(
            pts[None], d_arr[None], b_arr[None], w_arr, g_mat, zero_mask=np.array([zm])
        )
        return sol.forces[0]
    ld = np.longdouble
    Nl, _, _, _ = _evaluate(
        pts[None, :, 0].astype(ld),
        pts[None, :, 1].astype(ld),
        w_arr.astype(ld),
        g_mat.astype(ld),
        np.array([found]),
        np.array([kept]),
        np.array([dl], dtype=ld),
        np.array([bc], dtype=ld),
    )
    return np.where(found, np.maximum(Nl[0], 0.0), 0.0).astype(float)
