"""grfguard's inlining without numba's defensive deep copies (:func:`grfguard.kernels._jit.
inline_without_copies`): active on the pinned numba, the same results as numba's own
inlining, and only for grfguard's functions."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from grfguard.kernels import _jit

_SOURCE = """
@numba.njit(inline="always")
def leaf(a, b):
    if a > b:
        return a - b
    return b * 0.5 + a


@numba.njit(inline="always")
def mid(x, k):
    s = 0.0
    for j in range(k):
        s += leaf(x[j], s)
    return s + leaf(s, x[0])


@numba.njit
def top(x):
    out = 0.0
    for r in range(3):
        out += mid(x, x.shape[0] - r) - leaf(out, x[r])
    return out
"""


def _make(module: str | None):
    """A caller with nested ``inline="always"`` callees (loops, branches, an inner callee
    inlined at several sites), defined in a namespace named ``module`` (None: a namespace
    without a name, the functions' ``__module__`` None)."""
    ns = {"numba": numba} if module is None else {"__name__": module, "numba": numba}
    exec(compile(_SOURCE, f"<{module}>", "exec"), ns)  # noqa: S102 - the test's own code
    return ns["top"]


def _python(x: np.ndarray) -> float:
    def leaf(a, b):
        return a - b if a > b else b * 0.5 + a

    def mid(k):
        s = 0.0
        for j in range(k):
            s += leaf(x[j], s)
        return s + leaf(s, x[0])

    out = 0.0
    for r in range(3):
        out += mid(len(x) - r) - leaf(out, x[r])
    return out


@pytest.mark.parametrize("module", ["grfguard.kernels.fake", "someone_else.kernels", None])
def test_inlining_gives_numba_s_results_and_skips_copies_only_for_grfguard(
        monkeypatch, module) -> None:
    assert _jit.inline_without_copies()  # the pinned numba: the patch is on
    copies: list[int] = []
    real = _jit._NoDeepCopy.deepcopy
    monkeypatch.setattr(_jit._NoDeepCopy, "deepcopy",
                        staticmethod(lambda x, memo=None: copies.append(1) or real(x, memo)))
    compiled = _make(module)
    rng = np.random.default_rng(7)
    for _ in range(20):
        x = rng.normal(size=rng.integers(3, 12))
        got, want = compiled(x), _python(x)
        assert got == want or (math.isnan(got) and math.isnan(want)), (got, want)
    if module is not None and module.startswith("grfguard."):
        assert copies, "grfguard's callees must be inlined without the deep copies"
    else:
        assert not copies, "another package's numba code keeps numba's inlining"


def test_the_patch_is_applied_once_and_says_so() -> None:
    from numba.core import inline_closurecall as icc

    assert _jit.inline_without_copies() is True
    first = icc.InlineWorker.inline_function
    assert _jit.inline_without_copies() is True
    assert icc.InlineWorker.inline_function is first  # not wrapped twice
    assert icc.copy.__name__ == "copy"  # numba's module keeps the real copy outside a call


def test_the_environment_switch_keeps_numba_s_inlining(monkeypatch) -> None:
    """``GRFGUARD_NUMBA_INLINE_COPIES=1`` leaves numba alone (a fresh process's first
    call; here the module's flag is reset for it)."""
    from numba.core import inline_closurecall as icc

    monkeypatch.setattr(_jit, "_INLINE_PATCHED", None)
    monkeypatch.setattr(icc.InlineWorker, "inline_function", icc.InlineWorker.inline_function)
    monkeypatch.setenv("GRFGUARD_NUMBA_INLINE_COPIES", "1")
    before = icc.InlineWorker.inline_function
    assert _jit.inline_without_copies() is False
    assert icc.InlineWorker.inline_function is before
    assert _jit.inline_without_copies() is False  # decided once per process
