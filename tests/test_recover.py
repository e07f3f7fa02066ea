"""Recovery building blocks: hand-over blend, never NaN."""

from __future__ import annotations

import math

import pytest

from grfguard.recover import HandOver


def test_hand_over_is_smooth_and_reaches_target() -> None:
    h = HandOver(tau_s=0.03, dt_s=1e-3)
    ws = [h.update(1.0) for _ in range(300)]
    assert all(b > a for a, b in zip(ws, ws[1:], strict=False))
    assert ws[0] == pytest.approx(1 / 30)
    assert ws[-1] > 0.999
    # largest step of the blended output between a measurement of 100 N and a
    # reconstruction of 0 N is small (no jump at the hand-over)
    h.reset()
    outs = [HandOver.mix(h.update(1.0), 100.0, 0.0, 0.0) for _ in range(200)]
    assert max(abs(b - a) for a, b in zip([100.0, *outs], outs, strict=False)) < 3.5
    back = [HandOver.mix(h.update(0.0), 100.0, 0.0, 0.0) for _ in range(300)]
    assert back[-1] == pytest.approx(100.0, abs=0.1)


def test_mix_never_nan() -> None:
    nan = float("nan")
    assert HandOver.mix(0.0, 5.0, nan, 1.0) == 5.0
    assert HandOver.mix(0.5, nan, 7.0, 1.0) == 7.0
    assert HandOver.mix(0.5, nan, nan, 1.0) == 1.0
    assert HandOver.mix(0.5, 10.0, 20.0, 0.0) == 15.0
    assert not math.isnan(HandOver.mix(1.0, nan, nan, 0.0))
