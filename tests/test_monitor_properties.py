"""Issue 12, must-show 8 (monitor part): any row sequence, no exception, sane outputs.

A short real walk (0.3 s of the default walk, after 1.5 s of warm-up rows) is the base;
hypothesis corrupts rows (NaN, inf, huge, tiny, strings, None, missing keys, time
jumps) and streams them through one :class:`Monitor` with the VFS in the loop.
"""

from __future__ import annotations

import math
import pickle

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from grfguard.detect import Monitor
from grfguard.model.robot import SENSOR_NAMES

BAD_VALUES = st.one_of(
    st.just(float("nan")), st.just(float("inf")), st.just(-float("inf")),
    st.just(1e30), st.just(-1e30), st.just(1e6), st.just(0.0), st.just(None),
    st.just("x"), st.just("1e3"), st.just([1.0]), st.floats(allow_nan=True),
)


@pytest.fixture(scope="module")
def base(default_walk: pd.DataFrame) -> tuple[bytes, list[dict]]:
    """A monitor streamed through 2 s of the walk (pickled) and the next 0.3 s of rows."""
    log = default_walk.iloc[:1800].copy()
    log.attrs = dict(default_walk.attrs)
    rows = log.to_dict("records")
    mon = Monitor.for_log(log)
    for r in rows[:1500]:
        mon.update(r)
    return pickle.dumps(mon), rows[1500:]


@st.composite
def corruptions(draw: st.DrawFn, n_rows: int, columns: list[str]) -> list[tuple]:
    """A list of (row index, action, column, value)."""
    n = draw(st.integers(1, 12))
    out = []
    for _ in range(n):
        k = draw(st.integers(0, n_rows - 1))
        action = draw(st.sampled_from(["set", "drop", "time", "stretch"]))
        col = draw(st.sampled_from(columns))
        val = draw(BAD_VALUES) if action != "time" else draw(
            st.sampled_from([-1.0, 0.0, 0.3, 5.0, float("nan"), 1e9]))
        out.append((k, action, col, val))
    return out


COLS = ["imu_acc_z", "imu_gyro_x", "imu_quat_w", "q_r_knee", "force_r2", "force_l3",
        "contact_ref_r", "time"]


@settings(max_examples=6, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_any_row_sequence_gives_sane_outputs(base, data) -> None:
    state, tail = base
    rows = tail
    cols = [c for c in COLS if c in rows[0]]
    plan = data.draw(corruptions(len(tail), cols))
    seq = [dict(r) for r in tail]
    for k, action, col, val in plan:
        if action == "set":
            seq[k][col] = val
        elif action == "drop":
            seq[k].pop(col, None)
        elif action == "time":
            for r in seq[k:]:
                r["time"] = r["time"] + val if isinstance(r.get("time"), float) else val
        else:  # a stretch of up to 50 ms of the bad value
            for r in seq[k:k + 50]:
                r[col] = val
    mon = pickle.loads(state)
    lo, hi = mon.inputs.force_lo, mon.inputs.force_hi
    for r in seq:
        out = mon.update(r)
        for s in SENSOR_NAMES:
            rec = out[f"recovered_{s}"]
            assert math.isnan(rec) or lo <= rec <= hi
            assert isinstance(out[f"flag_{s}"], bool)
            assert math.isfinite(out[f"eta_{s}"]) or math.isnan(out[f"eta_{s}"])
        assert out["system_state"] in ("ok", "time_gap", "time_backwards", "time_constant",
                                       "time_missing", "input_invalid", "settling")
        for c in ("vfs_r1", "vfs_total_r", "com_est_x", "zmp_est_x"):
            v = out.get(c, float("nan"))
            assert math.isnan(v) or abs(v) < 1e5, (c, v)
    # not a single row poisons the monitor: a garbage row is fine, and so is None
    out = mon.update({"time": "soon"})
    assert out["system_state"] == "time_missing"
    mon.update(None)  # type: ignore[arg-type]
