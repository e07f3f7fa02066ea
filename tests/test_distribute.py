"""Tests of the contact-point force distribution QP (grfguard.estimate.distribute).

The reference is qpsolvers + quadprog (dev dependency only, GPL: never imported by
grfguard at run time, which one test checks in a fresh interpreter).
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import grfguard.estimate.distribute as dist
from grfguard.errors import ConfigError
from grfguard.estimate.distribute import (
    DEFAULT_WEIGHT,
    PAPER_WEIGHT,
    DistributionSolver,
    distribute_forces,
    distribute_forces_two_feet,
    reconstruct_cop,
    solve_distribution_batch,
    solve_distribution_one,
    two_feet_equality,
)
from grfguard.model.robot import SURALP

qpsolvers = pytest.importorskip("qpsolvers")
pytest.importorskip("quadprog")

SOLE = SURALP.sensor_positions_in_foot()  # (4, 2) [m]
WEIGHTS = (1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1)


def _reference(points: np.ndarray, d: np.ndarray, b: np.ndarray, w: float, G: np.ndarray):
    """quadprog through qpsolvers; loads clamped at 0 like the solver documents."""
    n = points.shape[0]
    P = 2.0 * (points @ points.T + w * np.eye(n))
    q = -2.0 * points @ d
    return qpsolvers.solve_qp(P, q, A=G, b=np.maximum(b, 0.0), lb=np.zeros(n), solver="quadprog")


def _random_problems(rng: np.random.Generator, T: int, n: int, g: int, fixed: bool):
    """Random points, loads and CoPs including degenerate cases.

    About 10 % each: zero load, negative load, CoP exactly on an edge or a corner,
    coincident points, collinear points; the CoP otherwise ranges past the polygon.
    """
    if fixed:
        pts = rng.uniform(-0.15, 0.15, (n, 2))
        P = np.broadcast_to(pts, (T, n, 2)).copy()
    else:
        P = rng.uniform(-0.15, 0.15, (T, n, 2))
    b = rng.uniform(0.0, 1000.0, (T, g))
    cop = rng.uniform(-0.2, 0.2, (T, 2))
    kind = rng.integers(0, 10, T)
    b[kind == 0] = 0.0
    b[kind == 1] *= -1.0
    on_vertex = kind == 2
    cop[on_vertex] = P[on_vertex, 0]
    on_edge = kind == 3
    s = rng.uniform(0, 1, (T, 1))
    cop[on_edge] = (s * P[:, 0] + (1 - s) * P[:, 1])[on_edge]
    if not fixed:
        coinc = kind == 4
        P[coinc, 1] = P[coinc, 0]
        coll = kind == 5
        t = rng.uniform(-1, 1, (T, n, 1))
        P[coll] = (P[:, :1] + t * (P[:, 1:2] - P[:, :1]))[coll]
    d = np.maximum(b.sum(axis=1), 0.0)[:, None] * cop
    return (P[0] if fixed else P), d, b


CASES = [
    # (n, g, fixed points, problems per weight)
    (4, 1, True, 2500),
    (4, 1, False, 2500),
    (8, 1, False, 2000),
    (8, 2, False, 2000),
    (8, 2, True, 1500),
    (5, 1, True, 2000),
]


@pytest.fixture(scope="module")
def cross_check_results():
    """Batch solutions and quadprog references for 1e5 random problems."""
    rng = np.random.default_rng(20261122)
    out = []
    for n, g, fixed, per_w in CASES:
        G = two_feet_equality(n // 2, n - n // 2) if g == 2 else np.ones((1, n))
        for w in WEIGHTS:
            pts, d, b = _random_problems(rng, per_w, n, g, fixed)
            sol = solve_distribution_batch(pts, d, b, w, G)
            ref = np.array(
                [_reference(pts if fixed else pts[t], d[t], b[t], w, G) for t in range(per_w)]
            )
            out.append((n, g, fixed, w, pts, d, b, G, sol, ref))
    return out


def test_cross_check_count(cross_check_results):
    total = sum(r[8].n_samples for r in cross_check_results)
    assert total >= 100_000


def _exact_on_free_set(points, d, b, w, G, free):
    """KKT solution of one free set in exact rational arithmetic: (N, μ) as floats."""
    from fractions import Fraction as Fr

    n, g = points.shape[0], G.shape[0]
    idx = np.flatnonzero(free).tolist()
    rows = [r for r in range(g) if b[r] > 0.0]
    m = len(idx) + len(rows)
    p = [[Fr(float(v)) for v in row] for row in points]
    dd = [Fr(float(v)) for v in d]
    K = [[Fr(0)] * (m + 1) for _ in range(m)]
    for a, i in enumerate(idx):
        for c, j in enumerate(idx):
            K[a][c] = p[i][0] * p[j][0] + p[i][1] * p[j][1] + (Fr(w) if i == j else Fr(0))
        for c, r in enumerate(rows):
            K[a][len(idx) + c] = -Fr(float(G[r, i]))
            K[len(idx) + c][a] = Fr(float(G[r, i]))
        K[a][m] = p[i][0] * dd[0] + p[i][1] * dd[1]
    for c, r in enumerate(rows):
        K[len(idx) + c][m] = Fr(float(b[r]))
    for c in range(m):  # Gauss-Jordan, exact
        piv = next(r for r in range(c, m) if K[r][c] != 0)
        K[c], K[piv] = K[piv], K[c]
        for r in range(m):
            if r != c and K[r][c] != 0:
                f = K[r][c] / K[c][c]
                K[r] = [x - f * y for x, y in zip(K[r], K[c], strict=True)]
    z = [K[r][m] / K[r][r] for r in range(m)]
    N = [Fr(0)] * n
    for a, i in enumerate(idx):
        N[i] = z[a]
    lam = [Fr(0)] * g
    for c, r in enumerate(rows):
        lam[r] = z[len(idx) + c]
    cn = [sum(p[i][k] * N[i] for i in range(n)) - dd[k] for k in range(2)]
    mu = [
        p[i][0] * cn[0]
        + p[i][1] * cn[1]
        + Fr(w) * N[i]
        - sum(Fr(float(G[r, i])) * lam[r] for r in range(g))
        for i in range(n)
    ]
    return np.array([float(v) for v in N]), np.array([float(v) for v in mu])


def test_matches_quadprog(cross_check_results):
    """Agree with quadprog to 1e-6 N; where quadprog itself is off (ill-conditioned
    problems with w = 1e-8), an exact rational solve of our free set decides."""
    n_exact = 0
    for n, g, fixed, w, pts, d, b, G, sol, ref in cross_check_results:
        assert np.all(sol.ok)
        err = np.abs(sol.forces - ref).max(axis=1)
        off = np.flatnonzero(err > 1e-6)
        assert off.size <= 5e-3 * err.size, (n, g, fixed, w, off.size, err.max())
        for t in off:
            p_t = pts if fixed else pts[t]
            N_ex, mu_ex = _exact_on_free_set(p_t, d[t], b[t], w, G, ~sol.active[t])
            held = sol.active[t]
            assert np.abs(sol.forces[t] - N_ex).max() < 1e-8, (n, g, fixed, w, t)
            assert np.all(N_ex >= 0.0) and np.all(mu_ex[held] >= -1e-15), (n, g, fixed, w, t)
            n_exact += 1
    assert n_exact < 100


def test_kkt_conditions(cross_check_results):
    for n, g, fixed, w, pts, d, b, G, sol, _ref in cross_check_results:
        N = sol.forces
        bc = np.maximum(b, 0.0)
        assert np.all(N >= 0.0)
        assert np.allclose(N @ G.T, bc, rtol=0, atol=1e-8 * max(1.0, bc.max()))
        assert sol.constraint_residual.max() < 1e-6
        # stationarity on free points, dual feasibility and complementarity on held ones
        P3 = np.broadcast_to(pts, (N.shape[0], n, 2)) if fixed else pts
        CN = np.einsum("tn,tnk->tk", N, P3)
        grad = np.einsum("tnk,tk->tn", P3, CN - d) + w * N - sol.eq_multipliers @ G
        mu = sol.bound_multipliers
        free = ~sol.active
        scale = 1.0 + np.abs(d).max() * 0.15 + bc.max() * 0.15**2
        assert np.abs(np.where(free, grad, 0.0)).max() < 1e-9 * scale
        assert np.abs(np.where(~free, grad - mu, 0.0)).max() < 1e-9 * scale
        assert mu.min() >= -1e-9 * scale
        assert np.abs(mu * N).max() < 1e-9 * scale * 1000.0
        assert sol.kkt_residual.max() < 1e-9 * scale, (n, g, fixed, w)


def test_objective_not_worse_than_quadprog(cross_check_results):
    for _n, _g, fixed, w, pts, d, _b, _G, sol, ref in cross_check_results:
        P3 = np.broadcast_to(pts, (ref.shape[0], *pts.shape[-2:])) if fixed else pts
        r = np.einsum("tn,tnk->tk", ref, P3) - d
        obj_ref = (r**2).sum(axis=1) + w * (ref**2).sum(axis=1)
        assert np.all(sol.objective <= obj_ref + 1e-9 * (1.0 + obj_ref))


def test_degenerate_flags(cross_check_results):
    for *_, b, _G, sol, _ref in cross_check_results:
        neg = np.any(b < 0.0, axis=1)
        assert np.array_equal(sol.load_clamped, neg)
        zero = np.all(b <= 0.0, axis=1)
        assert np.all(sol.forces[zero] == 0.0)


def test_enumeration_fallback_gives_same_answer(monkeypatch):
    rng = np.random.default_rng(3)
    pts, d, b = _random_problems(rng, 3000, 8, 2, fixed=False)
    G = two_feet_equality()
    sol = solve_distribution_batch(pts, d, b, 1e-6, G)
    monkeypatch.setattr(dist, "_MAX_ITER", 1)
    sol_enum = solve_distribution_batch(pts, d, b, 1e-6, G)
    assert np.any(sol_enum.iterations == -1)
    assert np.abs(sol.forces - sol_enum.forces).max() < 1e-9


# ------------------------------------------------------------------ scalar vs batch


@pytest.mark.parametrize("weight", [1e-8, DEFAULT_WEIGHT, PAPER_WEIGHT])
def test_streaming_solver_matches_batch(weight):
    rng = np.random.default_rng(11)
    T = 3000
    fz = rng.uniform(-50.0, 1200.0, T)
    cop = rng.uniform([-0.14, -0.09], [0.14, 0.09], (T, 2))
    cop[::7] = SOLE[rng.integers(0, 4, cop[::7].shape[0])]  # exactly on corners
    d = np.maximum(fz, 0.0)[:, None] * cop
    batch = solve_distribution_batch(SOLE, d, fz, weight).forces
    solver = DistributionSolver(SOLE, weight)
    stream = np.array([solver.solve(d[t, 0], d[t, 1], fz[t]) for t in range(T)])
    assert np.abs(stream - batch).max() < 1e-9


def test_streaming_solver_two_rows_matches_batch():
    rng = np.random.default_rng(12)
    pts = np.concatenate([SOLE + [0.0, 0.1], SOLE + [0.05, -0.1]])
    G = two_feet_equality()
    T = 1500
    b = rng.uniform(0.0, 700.0, (T, 2))
    b[::5, 1] = 0.0
    zmp = rng.uniform([-0.15, -0.2], [0.2, 0.2], (T, 2))
    d = b.sum(axis=1)[:, None] * zmp
    batch = solve_distribution_batch(pts, d, b, DEFAULT_WEIGHT, G).forces
    solver = DistributionSolver(pts, DEFAULT_WEIGHT, G)
    stream = np.array([solver.solve(d[t, 0], d[t, 1], tuple(b[t])) for t in range(T)])
    assert np.abs(stream - batch).max() < 1e-9


@pytest.mark.parametrize(("n", "g", "w"), [(4, 1, 1e-6), (8, 2, 1e-6), (8, 1, 1e-8)])
def test_solve_one_matches_batch(n, g, w):
    rng = np.random.default_rng(13)
    pts, d, b = _random_problems(rng, 300, n, g, fixed=False)
    G = two_feet_equality() if g == 2 else None
    batch = solve_distribution_batch(pts, d, b, w, G).forces
    one = np.array([solve_distribution_one(pts[t], d[t], b[t], w, G) for t in range(300)])
    assert np.abs(one - batch).max() < 1e-9


def test_solve_one_degenerate():
    assert np.all(np.isnan(solve_distribution_one(SOLE, [np.nan, 0.0], 100.0)))
    assert np.all(solve_distribution_one(SOLE, [1.0, 0.0], -5.0) == 0.0)
    G = two_feet_equality()
    pts = np.concatenate([SOLE, SOLE + [0.0, 0.2]])
    zero = np.r_[np.zeros(4, bool), np.ones(4, bool)]
    assert np.all(
        np.isnan(solve_distribution_one(pts, [0.0, 0.0], [100.0, 100.0], G=G, zero_mask=zero))
    )
    out = solve_distribution_one(pts, [0.0, 0.0], [100.0, 0.0], G=G, zero_mask=zero)
    assert out[:4].sum() == pytest.approx(100.0) and np.all(out[4:] == 0.0)


def test_streaming_nan_and_negative():
    solver = DistributionSolver(SOLE)
    assert all(np.isnan(solver.solve(np.nan, 0.0, 100.0)))
    assert solver.solve(1.0, 2.0, -30.0) == (0.0, 0.0, 0.0, 0.0)
    with pytest.raises(ConfigError, match="needs 1 value"):
        solver.solve(0.0, 0.0, (1.0, 2.0))


# ------------------------------------------------------------------ known answers


def test_centre_of_symmetric_rectangle_gives_quarter_load():
    fz = np.array([100.0, 800.0, 1.0])
    forces = distribute_forces(SOLE, np.zeros((3, 2)), fz)
    assert np.allclose(forces, fz[:, None] / 4.0, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("corner", range(4))
def test_cop_at_corner_loads_that_corner(corner):
    fz = np.array([600.0])
    forces = distribute_forces(SOLE, SOLE[corner][None], fz, weight=1e-8)[0]
    assert forces[corner] > 0.9999 * fz[0]
    assert forces.sum() == pytest.approx(fz[0], rel=1e-12)
    # with the paper's weight the corner load is spread over the neighbours
    paper = distribute_forces(SOLE, SOLE[corner][None], fz, weight=PAPER_WEIGHT)[0]
    assert paper[corner] < 0.9 * fz[0]
    assert np.count_nonzero(paper > 1.0) >= 3


def test_cop_outside_polygon_loads_nearest_edge():
    fz = np.array([500.0])
    cop = np.array([[0.5, 0.0]])  # far in front of the foot
    forces = distribute_forces(SOLE, cop, fz)[0]
    assert forces[0] == pytest.approx(250.0, rel=1e-6)
    assert forces[1] == pytest.approx(250.0, rel=1e-6)
    assert forces[2] == 0.0 and forces[3] == 0.0


def test_reconstructs_cop_inside_polygon_with_default_weight():
    rng = np.random.default_rng(5)
    cop = rng.uniform(SOLE.min(axis=0), SOLE.max(axis=0), (2000, 2))
    fz = rng.uniform(50.0, 1000.0, 2000)
    forces = distribute_forces(SOLE, cop, fz)
    assert np.abs(reconstruct_cop(SOLE, forces) - cop).max() < 2e-4  # 0.2 mm


def test_paper_weight_pulls_cop_to_centre():
    """The paper's W = 0.01 I shrinks the reconstructed CoP toward the sole centre.

    Inside the region where all four corners are loaded the shrink is exact: per axis
    ``CoP_rec = CoP · 4h² / (4h² + w)`` for a symmetric rectangle of half-size ``h``.
    SURALP (h = 0.110 m, 0.065 m): factors 0.829 (x) and 0.628 (y), so a CoP 5 cm
    forward and 3 cm to the side comes back 8.6 mm and 11.2 mm closer to the centre
    (14 mm); at the corner of the sensor rectangle the pull is 40 mm.
    """
    hx, hy = SOLE[0]
    gx, gy = np.meshgrid(np.linspace(-hx, hx, 45), np.linspace(-hy, hy, 27))
    cop = np.stack([gx.ravel(), gy.ravel()], axis=1)
    fz = np.full(cop.shape[0], 600.0)
    forces = distribute_forces(SOLE, cop, fz, weight=PAPER_WEIGHT)
    rec = reconstruct_cop(SOLE, forces)
    assert np.all(np.abs(rec) <= np.abs(cop) + 1e-12)  # never farther out
    inner = np.all(forces > 0.0, axis=1)
    fac = np.array([4 * hx**2 / (4 * hx**2 + PAPER_WEIGHT), 4 * hy**2 / (4 * hy**2 + PAPER_WEIGHT)])
    assert np.allclose(rec[inner], cop[inner] * fac, rtol=0, atol=1e-12)
    walk = rec[(np.abs(cop[:, 0]) <= 0.05) & (np.abs(cop[:, 1]) <= 0.03)]
    walk_cop = cop[(np.abs(cop[:, 0]) <= 0.05) & (np.abs(cop[:, 1]) <= 0.03)]
    assert 0.012 < np.linalg.norm(walk - walk_cop, axis=1).max() < 0.016
    assert np.linalg.norm(rec - cop, axis=1).max() > 0.035
    rec_default = reconstruct_cop(SOLE, distribute_forces(SOLE, cop, fz))
    assert np.linalg.norm(rec_default - cop, axis=1).max() < 2e-4


# ------------------------------------------------------------------ degenerate input


def test_nan_sample_gives_nan_with_mask_others_unaffected():
    d = np.array([[0.0, 0.0], [np.nan, 0.0], [10.0, 5.0], [0.0, 0.0]])
    b = np.array([400.0, 400.0, 400.0, np.inf])
    sol = solve_distribution_batch(SOLE, d, b)
    assert np.array_equal(sol.invalid_input, [False, True, False, True])
    assert np.array_equal(sol.ok, [True, False, True, False])
    assert np.all(np.isnan(sol.forces[[1, 3]]))
    assert np.all(np.isfinite(sol.forces[[0, 2]]))
    clean = solve_distribution_batch(SOLE, d[[0, 2]], b[[0, 2]])
    assert np.array_equal(clean.forces, sol.forces[[0, 2]])


def test_nan_in_per_sample_points():
    P = np.broadcast_to(SOLE, (3, 4, 2)).copy()
    P[1, 2, 0] = np.nan
    sol = solve_distribution_batch(P, np.zeros((3, 2)), np.full(3, 100.0))
    assert np.array_equal(sol.invalid_input, [False, True, False])
    assert np.allclose(sol.forces[[0, 2]], 25.0)


def test_zero_and_negative_load():
    sol = solve_distribution_batch(SOLE, np.array([[1.0, 1.0], [-3.0, 2.0]]), [0.0, -20.0])
    assert np.all(sol.forces == 0.0)
    assert np.array_equal(sol.load_clamped, [False, True])
    assert np.all(sol.ok)


def test_coincident_points_share_equally():
    pts = np.array([[0.1, 0.0], [0.1, 0.0], [-0.1, 0.0]])
    sol = solve_distribution_batch(pts, np.array([[30.0, 0.0]]), [300.0])
    assert sol.forces[0, 0] == pytest.approx(sol.forces[0, 1], rel=1e-9)
    assert sol.forces[0].sum() == pytest.approx(300.0, rel=1e-12)


def test_single_point_carries_everything():
    sol = solve_distribution_batch(np.array([[0.02, -0.01]]), np.array([[5.0, 5.0]]), [321.0])
    assert sol.forces[0, 0] == pytest.approx(321.0, rel=1e-14)


def test_infeasible_group_is_flagged():
    G = two_feet_equality()
    pts = np.concatenate([SOLE, SOLE + [0.0, 0.2]])
    zero = np.zeros((2, 8), dtype=bool)
    zero[1, 4:] = True  # left foot masked out but asked to carry 300 N
    sol = solve_distribution_batch(
        pts, np.zeros((2, 2)), np.array([[300.0, 300.0]] * 2), 1e-6, G, zero_mask=zero
    )
    assert np.array_equal(sol.infeasible, [False, True])
    assert np.all(np.isnan(sol.forces[1])) and np.all(np.isfinite(sol.forces[0]))


# ------------------------------------------------------------------ two feet


def test_two_feet_total_and_zmp():
    rng = np.random.default_rng(8)
    T = 500
    right = SOLE + [0.0, -0.1]
    left = np.broadcast_to(SOLE + [0.1, 0.1], (T, 4, 2)) + rng.normal(0, 0.01, (T, 1, 2))
    fz = rng.uniform(500.0, 1200.0, T)
    zmp = rng.uniform([0.0, -0.05], [0.1, 0.05], (T, 2))  # between the feet
    sol = distribute_forces_two_feet(right, left, fz, zmp)
    assert np.all(sol.ok)
    assert np.allclose(sol.forces.sum(axis=1), fz, rtol=1e-12)
    pts = np.concatenate([np.broadcast_to(right, (T, 4, 2)), left], axis=1)
    assert np.abs(reconstruct_cop(pts, sol.forces) - zmp).max() < 1e-4


def test_two_feet_contact_and_per_foot_sums():
    T = 4
    right, left = SOLE + [0.0, -0.1], SOLE + [0.0, 0.1]
    fz = np.full(T, 1000.0)
    zmp = np.zeros((T, 2))
    contact = np.array([[True, True], [True, False], [False, True], [True, True]])
    sol = distribute_forces_two_feet(right, left, fz, zmp, in_contact=contact)
    assert np.all(sol.forces[1, 4:] == 0.0) and np.all(sol.forces[2, :4] == 0.0)
    assert np.allclose(sol.forces.sum(axis=1), 1000.0)
    split = distribute_forces_two_feet(
        right, left, fz, zmp, foot_forces=np.array([[700.0, 300.0]] * T)
    )
    assert np.allclose(split.forces[:, :4].sum(axis=1), 700.0)
    assert np.allclose(split.forces[:, 4:].sum(axis=1), 300.0)


# ------------------------------------------------------------------ errors and isolation


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"points": np.zeros((4, 3))}, "points"),
        ({"weight": 0.0}, "weight"),
        ({"weight": np.ones(3)}, "weight"),
        ({"G": -np.ones((1, 4))}, "non-negative"),
        ({"G": np.ones((2, 4))}, "more than one row"),
        ({"d": np.zeros((5, 3))}, "`d`"),
        ({"b": np.zeros((5, 2))}, "`b`"),
    ],
)
def test_bad_input_raises_config_error(kwargs, match):
    args = {"points": SOLE, "d": np.zeros((5, 2)), "b": np.ones(5), "weight": 1e-6, "G": None}
    args.update(kwargs)
    with pytest.raises(ConfigError, match=match):
        solve_distribution_batch(**args)


def test_quadprog_not_imported_at_run_time():
    code = (
        "import sys, numpy as np\n"
        "import grfguard.estimate.distribute as d\n"
        "d.solve_distribution_batch(np.eye(2), np.zeros((1, 2)), np.ones(1))\n"
        "bad = [m for m in ('quadprog', 'qpsolvers', 'daqp') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("fixed", [True, False])
def test_point_outside_every_row_matches_quadprog(fixed):
    """A point in no row of G is only bounded below (e.g. an extra contact)."""
    rng = np.random.default_rng(21)
    n, T = 5, 400
    G = np.array([[1.0, 1.0, 1.0, 1.0, 0.0]])
    pts = rng.uniform(-0.15, 0.15, (n, 2) if fixed else (T, n, 2))
    b = rng.uniform(0.0, 800.0, (T, 1))
    d = b * rng.uniform(-0.2, 0.2, (T, 2))
    sol = solve_distribution_batch(pts, d, b, 1e-5, G)
    ref = np.array([_reference(pts if fixed else pts[t], d[t], b[t], 1e-5, G) for t in range(T)])
    assert np.abs(sol.forces - ref).max() < 1e-6
    assert np.any(sol.forces[:, 4] > 1.0) and np.any(sol.forces[:, 4] == 0.0)
    if fixed:
        solver = DistributionSolver(pts, 1e-5, G)
        stream = np.array([solver.solve(d[t, 0], d[t, 1], b[t, 0]) for t in range(T)])
        assert np.abs(stream - sol.forces).max() < 1e-9
