"""The recovered-force tracker (grfguard.recover.track): streaming equals batch, no lag on
a ramp, white noise reduced, only flagged offset/drift/gain sensors touched."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.errors import ConfigError
from grfguard.recover.track import (
    ForceTracker,
    TrackConfig,
    alpha_beta_gains,
    track_recovered,
)

CFG = TrackConfig(noise_n=2.0, weight_n=327.0)


def test_streaming_equals_batch_with_a_gap() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(3000) * 1e-3
    z = 100 + 50 * np.sin(10 * t) + rng.normal(0, 2, t.size)
    z[500:503] = np.nan
    tr = ForceTracker(1, 1e-3, CFG)
    stream = np.array([tr.step([v])[0] for v in z])
    df = pd.DataFrame({"time": t, "flag_a": True, "kind_a": "offset", "recovered_a": z})
    batch = track_recovered(df, CFG.weight_n, CFG.noise_n)["recovered_a"].to_numpy()
    np.testing.assert_allclose(batch, stream, atol=1e-9)
    assert np.isfinite(batch).all()  # a missing value: the last reading, tracked


@pytest.mark.parametrize("dt_s", [1e-3, 5e-3, 1e-2])
def test_no_lag_on_a_ramp_and_less_noise(dt_s: float) -> None:
    n = int(20 / dt_s)
    t = np.arange(n) * dt_s
    ramp = 100.0 + 300.0 * t  # 300 N/s
    tr = ForceTracker(1, dt_s, CFG)
    y = np.array([tr.step([v])[0] for v in ramp])
    assert abs(y[-1] - ramp[-1]) < 1e-6  # type-2 tracker: no steady-state ramp error
    rng = np.random.default_rng(1)
    noise = rng.normal(0.0, 2.0, n)
    tr.reset()
    yn = np.array([tr.step([v])[0] for v in ramp + noise])
    a, _ = alpha_beta_gains(dt_s, CFG)
    assert 0 < a < 1
    assert np.std(yn[n // 2:] - ramp[n // 2:]) < 0.95 * np.std(noise)


def test_only_flagged_additive_or_gain_sensors_change() -> None:
    rng = np.random.default_rng(2)
    n = 2000
    z = 200 + rng.normal(0, 2, n)
    flag = np.arange(n) >= 1000
    df = pd.DataFrame({"time": np.arange(n) * 1e-3,
                       "flag_a": flag, "kind_a": np.where(flag, "offset", "none"),
                       "flag_b": flag, "kind_b": np.where(flag, "frozen", "none"),
                       "flag_c": False, "kind_c": "none",
                       "recovered_a": z, "recovered_b": z, "recovered_c": z})
    out = track_recovered(df, CFG.weight_n, CFG.noise_n)
    a = out["recovered_a"].to_numpy()
    assert np.array_equal(a[:1000], z[:1000])
    assert np.std(a[1000:] - 200) < 0.8 * np.std(z[1000:] - 200)
    assert np.array_equal(out["recovered_b"].to_numpy(), z)  # frozen: not from the reading
    assert np.array_equal(out["recovered_c"].to_numpy(), z)  # healthy


def test_bad_settings_are_named() -> None:
    with pytest.raises(ConfigError, match="noise_n"):
        TrackConfig(noise_n=0.0, weight_n=300.0)
    with pytest.raises(ConfigError, match="dt_s"):
        alpha_beta_gains(0.0, CFG)
