"""The package's corner QP (the compiled solver, via reference.corner_split.qp_split, in the form of
the exact reference tests/reference/corner_qp.py) against daqp and the exact enumeration,
known answers, degenerate input."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from grfguard.model.robot import SURALP

pytest.importorskip("qpsolvers")
pytest.importorskip("daqp")
from exact_qp import package_qp as solve_corner_qp  # noqa: E402  (tests/, after the skip)
from exact_qp import reference_qp  # noqa: E402
from reference.corner_qp import solve_corner_qp as exact_corner_qp  # noqa: E402

SOLE = SURALP.sensor_positions_in_foot()  # (4, 2) [m]
PAPER_WEIGHT = 1e-2  # the paper's W = 0.01 I [m²]


def _objective(points, d, w, N):
    return float(np.sum((points.T @ N - d) ** 2) + w * np.sum(N**2))


@pytest.mark.parametrize("w", [1e-6, 1e-4, 1e-2])
@pytest.mark.parametrize("fixed", [True, False])
def test_matches_daqp_on_random_problems(w: float, fixed: bool) -> None:
    """Fixed sole (paper split) and per-sample 8 corners with contact masks (rigid split).

    Agreement is checked on the forces (1e-6 N, daqp's own tolerance) and on optimality:
    ours is never worse than daqp's objective by more than rounding.
    """
    rng = np.random.default_rng(int(w * 1e6) + fixed)
    T = 400
    b = rng.uniform(-50.0, 1200.0, T)
    if fixed:
        pts, allowed = SOLE, None
        cop = rng.uniform(SOLE.min(0) - 0.03, SOLE.max(0) + 0.03, (T, 2))
        d = np.maximum(b, 0.0)[:, None] * cop
    else:
        pts = rng.uniform(-0.3, 0.3, (T, 8, 2))
        allowed = rng.random((T, 8)) < 0.7
        allowed[:, 0] = True
        d = np.zeros((T, 2))
    N = solve_corner_qp(pts, d, b, w, allowed)
    for t in range(T):
        p = pts if fixed else pts[t]
        a = None if allowed is None else allowed[t]
        ref = reference_qp(p, d[t], b[t], w, a)
        assert np.abs(N[t] - ref).max() < 1e-6 * max(1.0, b[t]), t
        assert _objective(p, d[t], w, N[t]) <= _objective(p, d[t], w, ref) * (1 + 1e-9) + 1e-9
        if b[t] > 0:
            assert N[t].min() >= 0.0 and N[t].sum() == pytest.approx(b[t], rel=1e-12)
            if a is not None:
                assert np.all(N[t][~a] == 0.0)


def test_one_sample_equals_batch() -> None:
    rng = np.random.default_rng(3)
    cop = rng.uniform(-0.1, 0.1, (50, 2))
    b = rng.uniform(100.0, 900.0, 50)
    batch = solve_corner_qp(SOLE, b[:, None] * cop, b, PAPER_WEIGHT)
    for t in range(50):
        one = solve_corner_qp(SOLE, b[t] * cop[t : t + 1], b[t : t + 1], PAPER_WEIGHT)
        assert np.array_equal(one[0], batch[t])


def test_centre_and_corners() -> None:
    fz = np.array([100.0, 800.0])
    assert np.allclose(solve_corner_qp(SOLE, np.zeros((2, 2)), fz, 1e-6), fz[:, None] / 4,
                       rtol=1e-12)
    for k in range(4):
        f = solve_corner_qp(SOLE, 600.0 * SOLE[k][None], np.array([600.0]), 1e-8)[0]
        assert f[k] > 0.9999 * 600.0
        paper = solve_corner_qp(SOLE, 600.0 * SOLE[k][None], np.array([600.0]), PAPER_WEIGHT)[0]
        assert paper[k] < 0.9 * 600.0 and np.count_nonzero(paper > 1.0) >= 3


def test_cop_outside_loads_nearest_edge() -> None:
    f = solve_corner_qp(SOLE, np.array([[0.5 * 500.0, 0.0]]), np.array([500.0]), 1e-6)[0]
    front = SOLE[:, 0] > 0
    assert np.allclose(f[front], 250.0, rtol=1e-6) and np.all(f[~front] == 0.0)


def test_paper_weight_pulls_cop_to_centre() -> None:
    """Inside the all-loaded region the shrink is exact: ``CoP · 4h² / (4h² + w)``."""
    hx, hy = np.abs(SOLE).max(axis=0)
    gx, gy = np.meshgrid(np.linspace(-hx, hx, 15), np.linspace(-hy, hy, 9))
    cop = np.stack([gx.ravel(), gy.ravel()], axis=1)
    fz = np.full(cop.shape[0], 600.0)
    f = solve_corner_qp(SOLE, fz[:, None] * cop, fz, PAPER_WEIGHT)
    rec = f @ SOLE / fz[:, None]
    inner = np.all(f > 0.0, axis=1)
    fac = 4 * np.array([hx, hy]) ** 2 / (4 * np.array([hx, hy]) ** 2 + PAPER_WEIGHT)
    assert inner.sum() > 20
    assert np.allclose(rec[inner], cop[inner] * fac, rtol=0, atol=1e-12)


@pytest.mark.parametrize("fixed", [True, False])
def test_matches_the_exact_enumeration(fixed: bool) -> None:
    """The package's solver (penalty row + rescale) against the exact free-set enumeration
    in extended precision (tests/reference/corner_qp.py, the former package solver)."""
    rng = np.random.default_rng(11 + fixed)
    T = 2000
    b = rng.uniform(-50.0, 1200.0, T)
    if fixed:
        pts, allowed, w = SOLE, None, PAPER_WEIGHT
        d = np.maximum(b, 0.0)[:, None] * rng.uniform(SOLE.min(0) - 0.03, SOLE.max(0) + 0.03,
                                                      (T, 2))
    else:
        pts, w = rng.uniform(-0.3, 0.3, (T, 8, 2)), 1e-6
        allowed = rng.random((T, 8)) < 0.7
        allowed[:, 0] = True
        d = np.zeros((T, 2))
    gap = np.abs(solve_corner_qp(pts, d, b, w, allowed) - exact_corner_qp(pts, d, b, w, allowed))
    assert gap.max() <= 1e-6  # [N]; measured 3e-13 (fixed sole) and 5e-12 (8 corners)


def test_degenerate_input() -> None:
    d = np.array([[0.0, 0.0], [np.nan, 0.0], [10.0, 5.0], [0.0, 0.0], [1.0, 1.0]])
    b = np.array([400.0, 400.0, 400.0, np.inf, -20.0])
    f = solve_corner_qp(SOLE, d, b, 1e-6)
    assert np.all(np.isnan(f[[1, 3]])) and np.all(np.isfinite(f[[0, 2]]))
    assert np.all(f[4] == 0.0)  # negative load: nothing carried
    pts = np.broadcast_to(SOLE, (3, 4, 2)).copy()
    pts[1, 2, 0] = np.nan
    allowed = np.ones((3, 4), bool)
    allowed[2] = False  # loaded but nothing may carry it: nothing carried
    g = solve_corner_qp(pts, np.zeros((3, 2)), np.full(3, 100.0), 1e-6, allowed)
    assert np.allclose(g[0], 25.0) and np.isnan(g[1]).all() and np.all(g[2] == 0.0)
    coincident = np.array([[0.1, 0.0], [0.1, 0.0], [-0.1, 0.0]])
    h = solve_corner_qp(coincident, np.array([[30.0, 0.0]]), np.array([300.0]), 1e-6)[0]
    assert h[0] == pytest.approx(h[1], rel=1e-9) and h.sum() == pytest.approx(300.0, rel=1e-12)


def test_no_qp_library_imported_at_run_time() -> None:
    code = (
        "import sys, numpy as np\n"
        "import grfguard.estimate.vfs\n"
        "from grfguard.kernels.nnls import new_scratch, prior_qp\n"
        "prior_qp(np.eye(2), np.ones(2), 2.0, 1e-3, 2, *new_scratch())\n"
        "print(sorted(m for m in ('quadprog', 'qpsolvers', 'daqp') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_compliance_split_is_the_exact_optimum_on_a_walk(monkeypatch) -> None:
    """The default split (NNLS with a penalty row, rescaled to the exact sum) against daqp
    on the exact problem, on the samples of a simulated walk (single and double support):
    the forces agree to 1e-6 N (measured gap to an exact enumeration: 2e-9 N), the sum is
    exact and the objective is never worse than daqp's beyond rounding."""
    import reference.vfs_stages as vfs_mod
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    seen = {}
    real = vfs_mod.split_with_prior

    def spy(*args):
        seen["args"] = args
        return real(*args)

    monkeypatch.setattr(vfs_mod, "split_with_prior", spy)
    log = simulate(gait=GaitConfig(duration=7.0), noise=NoiseConfig(), seed=2)
    vfs_mod.PythonVFS.for_log(log).run(log)  # the Python stages' split
    corners, contact, zmp, total, w, k = seen["args"]
    ds = np.flatnonzero(contact.all(axis=1))
    ss = np.flatnonzero(contact.sum(axis=1) == 4)
    assert ds.size > 100 and ss.size > 100
    rows = np.concatenate([ds[:: max(1, ds.size // 150)], ss[:: max(1, ss.size // 150)]])
    forces = real(corners[rows], contact[rows], zmp[rows], total[rows], w, k)
    rel = corners[rows, :, :2] - zmp[rows, None, :]
    for j, t in enumerate(rows):
        c, z = contact[t], corners[t, :, 2]
        prior = np.where(c, total[t] / c.sum() + k * (z[c].mean() - z), 0.0)
        ref = reference_qp(rel[j], np.zeros(2), total[t], w, c, prior)
        assert np.abs(forces[j] - ref).max() < 1e-6
        assert forces[j].sum() == pytest.approx(total[t], rel=1e-13)

        def objective(N, j=j, prior=prior):
            return float(np.sum((rel[j].T @ N) ** 2) + w * np.sum((N - prior) ** 2))

        assert objective(forces[j]) <= objective(ref) * (1 + 1e-9)
