"""The compiled channel monitor (:mod:`grfguard.kernels.channels`, behind
:class:`grfguard.detect.channels.ChannelMonitor`) against the former pure-Python one
(``tests/reference/channels.py``) on a Talos walk with faults of every kind injected:
every output bit-identical, batch and streaming; the compiled streaming path equal to the
compiled batch path; the compiled contact gate equal to the Python one."""

from __future__ import annotations

import math
from importlib import resources

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("mujoco")

import grfguard.detect.channels as chmod  # noqa: E402
from grfguard.detect.channels import ChannelConfig, ChannelMonitor, ContactPhases  # noqa: E402
from grfguard.estimate.described import with_described_vfs  # noqa: E402
from grfguard.faults.inject import apply_fault  # noqa: E402
from grfguard.faults.spec import parse_fault_spec  # noqa: E402
from grfguard.sim.config import NoiseConfig  # noqa: E402
from grfguard.sim.wholebody import scaled_gait, simulate_robot  # noqa: E402
from reference import channels as ref  # noqa: E402


@pytest.fixture(scope="module")
def cfg() -> ChannelConfig:
    f = resources.files("grfguard") / "data" / "talos_channels.toml"
    return ChannelConfig.from_toml_text(f.read_text())


@pytest.fixture(scope="module")
def faulty(talos) -> pd.DataFrame:
    """A 12 s noisy Talos walk (seed 3) with virtual channels and faults of every kind:
    offset, drift, gain, frozen (at 0 and at a loaded value), an intermittent offset that
    clears, NaN readings and a NaN virtual channel."""
    df = with_described_vfs(simulate_robot(talos, scaled_gait(talos, duration=12.0),
                                           NoiseConfig(), seed=3), talos)
    W = talos.mass * 9.81
    WL = W * talos.description.feet[0].length
    t = df["time"].to_numpy()
    specs = {"ft_r_fz": f"offset:{0.09 * W:.2f}@4", "ft_l_fz": f"drift:{0.09 * W:.2f}@5",
             "ft_r_tx": "frozen:0@6", "ft_l_ty": f"offset:{-0.09 * WL:.2f}@4.5",
             "ft_r_fx": "gain:1.25@5", "ft_l_tz": "frozen:3.0@7"}
    for ch, spec in specs.items():
        df[ch] = apply_fault(t, df[ch].to_numpy(), parse_fault_spec(f"r1={spec}"),
                             np.random.default_rng(0))
    df.loc[(t >= 7.0) & (t < 7.6), "ft_l_fx"] += 0.09 * W  # intermittent: flag clears
    df.loc[(t >= 3.0) & (t < 3.05), "ft_r_fy"] = np.nan
    df.loc[(t >= 8.0) & (t < 8.02), "vfs_l_tx"] = np.nan
    return df


def _assert_same(got: pd.DataFrame, want: pd.DataFrame) -> None:
    assert list(got.columns) == list(want.columns)
    for c in want.columns:
        g, w = got[c].to_numpy(), want[c].to_numpy()
        assert got[c].dtype == want[c].dtype, c
        if w.dtype.kind == "f":
            np.testing.assert_array_equal(g, w, err_msg=c)  # NaN == NaN, bits otherwise
        else:
            assert (g == w).all(), c


def test_batch_equals_python_reference(cfg, faulty) -> None:
    got = ChannelMonitor(cfg).run(faulty)
    want = ref.PyChannelMonitor(cfg).run(faulty)
    _assert_same(got, want)
    assert got.attrs == want.attrs
    kinds = {k for c in got.columns if c.startswith("kind_") for k in got[c].unique()}
    assert {"offset", "drift", "gain", "frozen", "none"} <= kinds  # every path taken
    flag = got["flag_ft_l_fx"].to_numpy()
    assert int(np.abs(np.diff(flag.astype(int))).sum()) >= 2  # raised and cleared


def test_streaming_equals_batch_and_reference(cfg, faulty) -> None:
    rows = faulty.iloc[:6000].to_dict("records")
    live, py = ChannelMonitor(cfg), ref.PyChannelMonitor(cfg)
    got = [live.update(r) for r in rows]
    want = [py.update(r) for r in rows]
    batch = ChannelMonitor(cfg).run(faulty.iloc[:6000])
    for key in want[0]:
        g = [r[key] for r in got]
        assert all(type(a) is type(b) for a, b in zip(g, (r[key] for r in want), strict=True))
        if isinstance(g[0], float):
            np.testing.assert_array_equal(g, [r[key] for r in want], err_msg=key)
            np.testing.assert_array_equal(g, batch[key].to_numpy(float), err_msg=key)
        else:
            assert g == [r[key] for r in want], key
            assert g == batch[key].tolist(), key
    assert any(r["flag_ft_r_fz"] for r in got)


def test_streaming_without_time_and_rate(cfg, faulty) -> None:
    """Samples without a time, and a rate learnt from the first step: as the reference."""
    rows = faulty.iloc[3000:4500].to_dict("records")
    for r in rows[::7]:
        r.pop("time")
    live, py = ChannelMonitor(cfg), ref.PyChannelMonitor(cfg)
    for r in rows:
        g, w = live.update(r), py.update(r)
        for k in w:
            assert g[k] == w[k] or (isinstance(w[k], float) and math.isnan(w[k])
                                    and math.isnan(g[k])), k
    assert live.dt_s == py.dt_s


def test_excursion_halving_as_the_reference(cfg, faulty, monkeypatch) -> None:
    """With a tiny excursion bound the onset evidence is cut in half as in Python."""
    monkeypatch.setattr(chmod, "_MAX_EXCURSION", 40)
    monkeypatch.setattr(ref, "_MAX_EXCURSION", 40)
    _assert_same(ChannelMonitor(cfg).run(faulty), ref.PyChannelMonitor(cfg).run(faulty))
    rows = faulty.iloc[3500:5500].to_dict("records")
    live, py = ChannelMonitor(cfg), ref.PyChannelMonitor(cfg)
    got = pd.DataFrame([live.update(r) for r in rows])
    want = pd.DataFrame([py.update(r) for r in rows])
    _assert_same(got, want)


def test_gate_equals_python(faulty) -> None:
    t = faulty["time"].to_numpy(float)
    cr = faulty["contact_ref_r"].to_numpy(float) > 0.5
    cl = faulty["contact_ref_l"].to_numpy(float) > 0.5
    py = ref.PyContactPhases(0.15)
    want = np.array([py.step(float(a), bool(b), bool(c)) for a, b, c in zip(t, cr, cl,
                                                                            strict=True)])
    got = ContactPhases(0.15).run(t, cr, cl)
    np.testing.assert_array_equal(got, want)
    assert want.any() and not want.all()
    g = ContactPhases(0.15)
    np.testing.assert_array_equal([g.step(a, b, c) for a, b, c in zip(t, cr, cl, strict=True)],
                                  want)
