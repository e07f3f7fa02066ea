"""Fault injection: parsing, each kind's effect, truth columns, determinism."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from grfguard.errors import FaultSpecError
from grfguard.faults import (
    FaultSpec,
    faults_from_toml,
    faults_to_toml,
    inject_faults,
    parse_fault_spec,
    parse_faults,
)
from grfguard.model.robot import SENSOR_NAMES


@pytest.fixture(scope="module")
def log() -> pd.DataFrame:
    rng = np.random.default_rng(3)
    t = np.arange(0, 10, 1e-3)
    d = {"time": t}
    for i, s in enumerate(SENSOR_NAMES):
        true = 200 + 100 * np.sin(2 * np.pi * 0.5 * t + i)
        d[f"true_force_{s}"] = true
        d[f"force_{s}"] = true + rng.normal(0, 2, t.size)
    return pd.DataFrame(d)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("r2=offset:100@5", FaultSpec("r2", "offset", 100.0, 5.0)),
        ("r3=drift:15@5", FaultSpec("r3", "drift", 15.0, 5.0)),
        ("r1=frozen:0@5", FaultSpec("r1", "frozen", 0.0, 5.0)),
        ("r1=frozen@5", FaultSpec("r1", "frozen", 0.0, 5.0)),
        ("l2=noise:20@3-9", FaultSpec("l2", "noise", 20.0, 3.0, 9.0)),
        ("r4=stuck@2.5", FaultSpec("r4", "stuck", 0.0, 2.5)),
        ("l1=saturation:250@1e0-8", FaultSpec("l1", "saturation", 250.0, 1.0, 8.0)),
    ],
)
def test_parse_good(text: str, expected: FaultSpec) -> None:
    f = parse_fault_spec(text)
    assert f == expected
    assert parse_fault_spec(f.to_spec_string()) == f


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("x9=offset:1@5", "unknown sensor"),
        ("r1=bogus:1@5", "unknown fault kind"),
        ("r1=offset:abc@5", "not a number"),
        ("r1=offset@5", "needs a value"),
        ("r1=offset:5@5-4", "must be later"),
        ("r1=offset:5@5-5", "must be later"),
        ("r1=stuck:3@5", "takes no value"),
        ("r1offset", "cannot parse"),
        ("r1=offset:5@x", "not a number"),
    ],
)
def test_parse_bad(text: str, needle: str) -> None:
    with pytest.raises(FaultSpecError, match=needle) as exc:
        parse_fault_spec(text)
    assert "SENSOR=KIND" in str(exc.value) or "takes no value" in str(exc.value)


def test_toml_round_trip_and_errors() -> None:
    faults = parse_faults("r2=offset:100@5, r3=drift:15@5; l2=noise:20@3-9")
    assert len(faults) == 3
    text = faults_to_toml(faults)
    assert faults_from_toml(text) == faults
    doc = '[[fault]]\nsensor = "r1"\nkind = "frozen"\nstart = 5\n'
    assert faults_from_toml(doc) == [FaultSpec("r1", "frozen", 0.0, 5.0)]
    with pytest.raises(FaultSpecError, match="needs 'value'"):
        faults_from_toml('[[fault]]\nsensor = "r1"\nkind = "offset"\nstart = 5\n')
    with pytest.raises(FaultSpecError, match="missing key"):
        faults_from_toml('[[fault]]\nsensor = "r1"\nkind = "offset"\nvalue = 3\n')
    with pytest.raises(FaultSpecError, match=r"\[\[fault\]\]"):
        faults_from_toml("x = 1\n")
    with pytest.raises(FaultSpecError, match="unknown keys"):
        faults_from_toml('[[fault]]\nsensor="r1"\nkind="offset"\nvalue=1\nstart=1\nfoo=2\n')


def test_each_kind_effect(log: pd.DataFrame) -> None:
    t = log["time"].to_numpy()
    on = t >= 5
    specs = {
        "r1": "r1=frozen:0@5",
        "r2": "r2=offset:100@5",
        "r3": "r3=drift:15@5",
        "r4": "r4=gain:1.5@5",
        "l1": "l1=stuck@5",
        "l2": "l2=saturation:180@5",
        "l3": "l3=dropout@5-7",
        "l4": "l4=noise:20@5",
    }
    out = inject_faults(log, list(specs.values()), seed=1)
    f = {s: out[f"force_{s}"].to_numpy() for s in SENSOR_NAMES}
    g = {s: log[f"force_{s}"].to_numpy() for s in SENSOR_NAMES}
    assert np.all(f["r1"][on] == 0) and np.array_equal(f["r1"][~on], g["r1"][~on])
    np.testing.assert_allclose(f["r2"][on] - g["r2"][on], 100)
    np.testing.assert_allclose(f["r3"][on] - g["r3"][on], 15 * (t[on] - 5), atol=1e-9)
    np.testing.assert_allclose(f["r4"][on], 1.5 * g["r4"][on])
    i0 = np.flatnonzero(on)[0]
    assert np.all(f["l1"][on] == g["l1"][i0 - 1])
    assert f["l2"][on].max() == 180 and np.all(f["l2"][on] <= 180)
    drop = (t >= 5) & (t < 7)
    assert np.all(np.isnan(f["l3"][drop])) and np.all(np.isfinite(f["l3"][~drop]))
    assert 17 < np.std(f["l4"][on] - g["l4"][on]) < 23
    # truth columns
    for s in SENSOR_NAMES:
        fk = out[f"fault_kind_{s}"].to_numpy()
        fault = out[f"fault_{s}"].to_numpy()
        assert np.all(fk[~on] == "none")
        assert np.all(fault[~on] == 0)
        np.testing.assert_allclose(fault[on & ~drop], (f[s] - g[s])[on & ~drop], atol=1e-9)
    assert np.all(out["fault_kind_r3"].to_numpy()[on] == "drift")
    assert np.all(np.isnan(out["fault_l3"].to_numpy()[drop]))
    assert np.all(out["fault_kind_l3"].to_numpy()[t >= 7] == "none")


def test_spikes_and_determinism(log: pd.DataFrame) -> None:
    a = inject_faults(log, "r1=spikes:80@2-8", seed=7)
    b = inject_faults(log, "r1=spikes:80@2-8", seed=7)
    c = inject_faults(log, "r1=spikes:80@2-8", seed=8)
    pd.testing.assert_frame_equal(a, b)
    assert not a["force_r1"].equals(c["force_r1"])
    d = a["fault_r1"].to_numpy()
    n_spikes = int(np.count_nonzero(d))
    assert 10 < n_spikes < 60  # 5 per second over 6 s
    assert set(np.unique(np.abs(d[d != 0]).round(6))) == {80.0}
    # the input is not modified
    assert "fault_r1" not in log.columns


def test_spec_validation_direct() -> None:
    with pytest.raises(FaultSpecError, match="noise sigma"):
        FaultSpec("r1", "noise", -1.0, 0.0)
    with pytest.raises(FaultSpecError, match="number"):
        FaultSpec("r1", "offset", float("nan"), 0.0)
    assert math.isinf(FaultSpec("r1", "offset", 1.0, 0.0).end)
