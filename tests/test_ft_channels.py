"""Talos in ankle-F/T mode (issue 9, must-show 4): offset, drift and frozen faults on
``fz`` and on ``tx`` detected, classified and recovered on a simulated walk by the
per-channel monitor (:mod:`grfguard.detect.channels`), with the channel thresholds
shipped for Talos (calibrated on fault-free walks with other seeds). Real Talos URDF
(example-robot-data), real MuJoCo physics."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from grfguard.detect.channels import channel_valid_mask  # noqa: E402
from grfguard.errors import ConfigError  # noqa: E402
from grfguard.estimate.described import run_described, with_described_vfs  # noqa: E402
from grfguard.faults.inject import apply_fault  # noqa: E402
from grfguard.faults.spec import parse_fault_spec  # noqa: E402
from grfguard.model.description import FT_AXES  # noqa: E402
from grfguard.sim.config import NoiseConfig  # noqa: E402
from grfguard.sim.wholebody import scaled_gait, simulate_robot  # noqa: E402

CHANNELS = [f"ft_{s}_{a}" for s in "rl" for a in FT_AXES]
ONSET_S = 5.0



@pytest.fixture(scope="module")
def walk(talos):
    """A 10 s noisy Talos walk (seed 1) with its virtual channels."""
    df = simulate_robot(talos, scaled_gait(talos, duration=10.0), NoiseConfig(), seed=1)
    return with_described_vfs(df, talos)


def _scales(talos) -> tuple[float, float]:
    W = talos.mass * 9.81
    return W, W * talos.description.feet[0].length


def _inject(walk, faults: dict[str, str]):
    out = walk.copy()
    t = walk["time"].to_numpy()
    for ch, spec in faults.items():
        out[ch] = apply_fault(t, walk[ch].to_numpy(), parse_fault_spec(f"r1={spec}"),
                              np.random.default_rng(0))
    return out


@pytest.fixture(scope="module", params=["A", "B"])
def case(request, talos, walk):
    W, WL = _scales(talos)
    w, wt = 0.09 * W, 0.09 * WL  # 9 % of the weight (x foot length for torques)
    faults = {  # one fault per kind on fz and on tx, over two logs
        "A": {"ft_r_fz": f"offset:{w:.2f}@5", "ft_l_fz": f"drift:{w:.2f}@5",
              "ft_r_tx": "frozen:0@5"},
        "B": {"ft_r_tx": f"offset:{-wt:.2f}@5", "ft_l_tx": f"drift:{wt:.2f}@5",
              "ft_r_fz": "frozen:0@5"},
    }[request.param]
    return faults, run_described(_inject(walk, faults), robot=talos)


def test_no_false_alarm_on_the_fault_free_walk(talos, walk) -> None:
    out = run_described(walk, robot=talos)
    for ch in CHANNELS:
        assert not out[f"flag_{ch}"].any(), ch


def test_faults_detected_classified_isolated(case) -> None:
    faults, out = case
    t = out["time"].to_numpy()
    bound = {"offset": 0.5, "drift": 1.0, "frozen": 0.2}
    for ch, spec in faults.items():
        kind = spec.split(":")[0]
        flag = out[f"flag_{ch}"].to_numpy()
        assert flag.any() and not flag[t < ONSET_S].any(), ch
        delay = t[np.argmax(flag)] - ONSET_S
        assert delay <= bound[kind], (ch, delay)
        assert out[f"kind_{ch}"].iloc[-1] == kind, ch
    for ch in set(CHANNELS) - set(faults):
        assert not out[f"flag_{ch}"].any(), ch


def test_recovery(talos, walk, case) -> None:
    """Offsets and drifts: the fitted fault taken out, within 0.5 % of the weight (x foot
    length for torques) over the whole fault; frozen: the virtual channel, within 0.5 %
    where it is accurate (single support and swing)."""
    faults, out = case
    W, WL = _scales(talos)
    t = out["time"].to_numpy()
    ok = channel_valid_mask(walk, 0.15)
    for ch, spec in faults.items():
        scale = WL if ch[-2] == "t" else W
        late = t >= ONSET_S + 1.0
        if spec.startswith("frozen"):
            late &= ok[:, 0 if ch.startswith("ft_r") else 1]
        err = out[f"recovered_{ch}"].to_numpy()[late] - walk[ch].to_numpy()[late]
        assert 100 * np.sqrt(np.mean(err**2)) / scale <= 0.5, ch


def test_shipped_channel_config_is_checked() -> None:
    from grfguard.detect.channels import ChannelConfig

    with pytest.raises(ConfigError, match="channels"):
        ChannelConfig.from_toml_text("[channels]\nh = 3.0\n")


def test_cli_run_on_a_talos_log(tmp_path, talos, walk) -> None:
    """`grfguard run` with the shipped channel thresholds, and `grfguard calibrate` on a
    fault-free Talos log writing channel thresholds that `run --thresholds` takes."""
    from typer.testing import CliRunner

    from grfguard.cli import app
    from grfguard.io.logio import read_log, write_log

    df = simulate_robot(talos, scaled_gait(talos, duration=8.0), NoiseConfig(), seed=4)
    wt = 0.09 * _scales(talos)[1]
    df.loc[df["time"] >= 3.0, "ft_l_tx"] += wt
    write_log(df, tmp_path / "talos.parquet")
    r = CliRunner().invoke(app, ["run", str(tmp_path / "talos.parquet"),
                                 "-o", str(tmp_path / "out.parquet")])
    assert r.exit_code == 0, r.output
    out = read_log(tmp_path / "out.parquet")
    flagged = [ch for ch in CHANNELS if out[f"flag_{ch}"].any()]
    assert flagged == ["ft_l_tx"]
    assert out.loc[out["flag_ft_l_tx"], "time"].min() - 3.0 <= 0.5
    assert out["kind_ft_l_tx"].iloc[-1] == "offset"

    write_log(walk, tmp_path / "clean.parquet")  # seed 1, fault-free
    r = CliRunner().invoke(app, ["calibrate", str(tmp_path / "clean.parquet"),
                                 "-o", str(tmp_path / "ch.toml")])
    assert r.exit_code == 0, r.output
    assert "[channels.sigma]" in (tmp_path / "ch.toml").read_text()
    r = CliRunner().invoke(app, ["run", str(tmp_path / "talos.parquet"), "--thresholds",
                                 str(tmp_path / "ch.toml"), "-o", str(tmp_path / "o2.parquet")])
    assert r.exit_code == 0, r.output
    out = read_log(tmp_path / "o2.parquet")
    assert out.attrs["channel_monitor"]["source"].startswith("calibrated on 1")
    assert out.loc[out["flag_ft_l_tx"], "time"].min() - 3.0 <= 0.5


@pytest.fixture(scope="module")
def one_foot(talos, walk):
    """The paper's scenario transposed to four channels of the right F/T sensor at once
    (w = 9 % of the weight; x foot length for torques): fz frozen at 0, fx +w, tx drift
    w per s, ty -w; and on the left foot an offset of +w on fz from 7.0 s to 7.6 s only."""
    W, WL = _scales(talos)
    w, wt = 0.09 * W, 0.09 * WL
    faults = {"ft_r_fz": "frozen:0@5", "ft_r_fx": f"offset:{w:.2f}@5",
              "ft_r_tx": f"drift:{wt:.2f}@5", "ft_r_ty": f"offset:{-wt:.2f}@5"}
    faulty = _inject(walk, faults)
    t = faulty["time"].to_numpy()
    faulty.loc[(t >= 7.0) & (t < 7.6), "ft_l_fz"] += w
    return faults, faulty, run_described(faulty, robot=talos)


def test_one_foot_four_channels_detected_and_recovered(talos, walk, one_foot) -> None:
    faults, _, out = one_foot
    W, WL = _scales(talos)
    t = out["time"].to_numpy()
    bound = {"offset": 0.5, "drift": 1.0, "frozen": 0.2}
    for ch, spec in faults.items():
        kind = spec.split(":")[0]
        flag = out[f"flag_{ch}"].to_numpy()
        first = int(np.argmax(flag))
        assert flag.any() and not flag[t < ONSET_S].any(), ch
        assert flag[first:].all(), ch  # a persistent fault's flag never clears
        assert t[first] - ONSET_S <= bound[kind], ch
        assert out[f"kind_{ch}"].iloc[-1] == kind, ch
        if kind == "offset":
            late = t >= ONSET_S + 1.0
            err = out[f"recovered_{ch}"].to_numpy()[late] - walk[ch].to_numpy()[late]
            scale = WL if ch[-2] == "t" else W
            assert 100 * np.sqrt(np.mean(err**2)) / scale <= 0.5, ch
    assert not any(out[f"flag_{ch}"].any() for ch in set(CHANNELS) - set(faults) - {"ft_l_fz"})


def test_flag_clears_after_an_intermittent_fault(one_foot) -> None:
    """ft_l_fz carries +w from 7.0 s to 7.6 s: flagged within 0.5 s, cleared within
    1.5 s after the fault ended, and the recovered channel is the reading again."""
    _, faulty, out = one_foot
    t = out["time"].to_numpy()
    flag = out["flag_ft_l_fz"].to_numpy()
    assert flag.any() and t[np.argmax(flag)] - 7.0 <= 0.5
    assert not flag[t >= 7.6 + 1.5].any()
    assert int(np.abs(np.diff(flag.astype(int))).sum()) == 2  # raised once, cleared once
    after = t >= 9.1
    assert (out["kind_ft_l_fz"].to_numpy()[after] == "none").all()
    np.testing.assert_array_equal(out["recovered_ft_l_fz"].to_numpy()[after],
                                  faulty["ft_l_fz"].to_numpy()[after])


def test_streaming_update_equals_batch(talos, one_foot) -> None:
    from importlib import resources

    from grfguard.detect.channels import ChannelConfig, ChannelMonitor

    _, faulty, out = one_foot
    cfg = ChannelConfig.from_toml_text(
        (resources.files("grfguard") / "data" / "talos_channels.toml").read_text())
    live = ChannelMonitor(cfg)
    rows = [live.update(r) for r in faulty.to_dict("records")]
    for key in rows[0]:
        got = np.array([r[key] for r in rows])
        want = out[key].to_numpy()
        if got.dtype.kind in "fc":
            np.testing.assert_array_equal(got, want.astype(float), err_msg=key)
        else:
            assert (got == want).all(), key
    assert live.update({"time": 10.5}) is not None  # a sample without channels: no crash


def test_a_gain_fault_stays_flagged_through_the_swings(talos, walk) -> None:
    """A gain fault only shows under load; the quiet swings must not clear its flag."""
    out = run_described(_inject(walk, {"ft_r_fz": "gain:1.2@5"}), robot=talos)
    flag = out["flag_ft_r_fz"].to_numpy()
    first = int(np.argmax(flag))
    assert flag.any() and flag[first:].all()
    assert out["kind_ft_r_fz"].iloc[-1] == "gain"
