"""Property tests of the force split (issue 12, must-show 8): for any contact set, sole
geometry, total force and CoP, the corner forces are feasible (non-negative, zero off
contact), sum exactly to the total, and equal a maintained solver's optimum (daqp)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grfguard.model.robot import SURALP

pytest.importorskip("daqp")
from exact_qp import package_qp as solve_corner_qp  # noqa: E402  (tests/, after the skip)
from exact_qp import reference_qp  # noqa: E402
from reference.corner_split import solve_with_prior  # noqa: E402

SOLE = SURALP.sensor_positions_in_foot()  # (4, 2) [m]

coord = st.floats(-0.3, 0.3, allow_nan=False, allow_infinity=False)
total = st.floats(1.0, 3000.0, allow_nan=False, allow_infinity=False)
weight = st.sampled_from([1e-6, 1e-4, 1e-2])


@st.composite
def problems(draw: st.DrawFn, n: int = 8) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Points (n, 2) [m], CoP-weighted target d (2,) [N m], total b [N], contact mask (n,)."""
    pts = np.array(draw(st.lists(st.tuples(coord, coord), min_size=n, max_size=n)))
    b = draw(total)
    cop = np.array(draw(st.tuples(coord, coord)))
    allowed = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    allowed[draw(st.integers(0, n - 1))] = True  # at least one corner in contact
    return pts, b * cop, b, allowed


def _check_feasible(N: np.ndarray, b: float, allowed: np.ndarray | None) -> None:
    assert np.all(np.isfinite(N))
    assert N.min() >= 0.0
    assert N.sum() == pytest.approx(b, rel=1e-9)
    if allowed is not None:
        assert np.all(N[~allowed] == 0.0)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(problems(), weight)
def test_rigid_split_is_feasible_exact_and_optimal(prob, w) -> None:
    pts, d, b, allowed = prob
    N = solve_corner_qp(pts[None], d[None], np.array([b]), w, allowed[None])[0]
    _check_feasible(N, b, allowed)
    ref = reference_qp(pts, d, b, w, allowed)
    assert np.abs(N - ref).max() <= 1e-6 * max(1.0, b)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(total, st.tuples(coord, coord), weight)
def test_paper_split_on_the_sole_is_feasible_exact_and_optimal(b, cop, w) -> None:
    d = b * np.asarray(cop)
    N = solve_corner_qp(SOLE, d[None], np.array([b]), w)[0]
    _check_feasible(N, b, None)
    assert np.abs(N - reference_qp(SOLE, d, b, w)).max() <= 1e-6 * max(1.0, b)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(problems(), st.lists(st.floats(-500.0, 500.0), min_size=8, max_size=8), weight)
def test_compliance_split_is_feasible_exact_and_near_optimal(prob, prior, w) -> None:
    """The default (compliance-prior) split: relative to the ZMP, so d = 0."""
    pts, _, b, allowed = prob
    prior = np.where(allowed, np.asarray(prior), 0.0)
    N = solve_with_prior(pts, prior, b, w, allowed)
    _check_feasible(N, b, allowed)
    ref = reference_qp(pts, np.zeros(2), b, w, allowed, prior=prior)

    def objective(x: np.ndarray) -> float:
        return float(np.sum((pts.T @ x) ** 2) + w * np.sum((x - prior) ** 2))

    # NNLS with a weighted equality row, rescaled: never measurably worse than daqp
    assert objective(N) <= objective(ref) * (1 + 1e-6) + 1e-6 * b


@settings(max_examples=30, deadline=None, derandomize=True)
@given(problems(), weight)
def test_non_finite_or_unloaded_input_never_raises(prob, w) -> None:
    pts, d, b, allowed = prob
    for bb, dd in ((np.nan, d), (b, np.array([np.inf, 0.0])), (-b, d), (0.0, d)):
        N = solve_corner_qp(pts[None], dd[None], np.array([bb]), w, allowed[None])[0]
        if np.isfinite(bb) and np.isfinite(dd).all():
            assert np.all(N == 0.0)  # no load: no force
        else:
            assert np.all(np.isnan(N))  # unusable input: NaN, never a made-up force
