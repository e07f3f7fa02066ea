"""ROS 2 bags and MCAP: simulate -> bag -> run gives the same detection as the Parquet log;
exported MCAP read back with the mcap reader; clear errors on bad bags."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from grfguard.cli import app
from grfguard.errors import ConfigError, LogFormatError
from grfguard.faults import inject_faults
from grfguard.io import _cdr
from grfguard.io.bagwrite import write_bag
from grfguard.io.logio import read_log, write_log
from grfguard.io.mcap_export import _series_topics, _status_rows
from grfguard.io.rosbag import EXAMPLE_MAP, BagImportWarning, load_topics_map, read_bag
from grfguard.io.schema import kind_col
from grfguard.model.robot import JOINT_NAMES, SENSOR_NAMES, SIDES
from grfguard.sim import GaitConfig, simulate

runner = CliRunner()
FAULT = "r2=offset:100@4"


def expected_topics(df: pd.DataFrame, status_rate_hz: float = 10.0) -> dict[str, int]:
    """Topic -> number of messages ``export_mcap`` writes for ``df``."""
    n = len(df)
    out = {t: n for t in _series_topics()}
    for s in SENSOR_NAMES:
        k = df[kind_col(s)].astype(str).to_numpy()
        out[f"/grfguard/{s}/kind"] = 1 + int((k[1:] != k[:-1]).sum())
    for side in SIDES:
        out[f"/grfguard/{side}/wrench"] = n
        out[f"/grfguard/{side}/cop"] = n
    out["/grfguard/com"] = n
    out["/grfguard/status"] = int(_status_rows(df, status_rate_hz).size)
    return out


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    """A 7 s walk with the paper's offset fault on r2 at 4 s, and the run on its log."""
    d = tmp_path_factory.mktemp("ros")
    log = inject_faults(simulate(gait=GaitConfig(duration=7.0), seed=5), [FAULT], seed=1)
    p = write_log(log, d / "faulty.parquet")
    out = d / "out.parquet"
    res = runner.invoke(app, ["run", str(p), "-o", str(out)])
    assert res.exit_code == 0, res.output
    return {"dir": d, "log": p, "out": read_log(out)}


@pytest.fixture(scope="module")
def short_log(walk):
    """The first 2 s of the walk (small bags for the error cases)."""
    df = read_log(walk["log"])
    return df[df["time"] < 2.0].reset_index(drop=True)


def _by_ms(df: pd.DataFrame) -> pd.DataFrame:
    return df.set_index(np.round(df["time"].to_numpy() * 1000).astype(int))


def _rms(a: pd.Series, b: pd.Series) -> float:
    e = (a - b).to_numpy(float)
    return float(np.sqrt(np.nanmean(e**2)))


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_run_on_bag_matches_run_on_log(walk, storage: str) -> None:
    d = walk["dir"]
    bag = d / ("walk.mcap" if storage == "mcap" else "walk_sqlite")  # file / rosbag2 dir
    res = runner.invoke(app, ["bag", str(walk["log"]), "-o", str(bag), "--storage", storage])
    assert res.exit_code == 0, res.output
    out = d / f"out_{storage}.parquet"
    res = runner.invoke(app, ["run", str(bag), "--map", str(EXAMPLE_MAP), "-o", str(out)])
    assert res.exit_code == 0, res.output
    a, b = _by_ms(walk["out"]), _by_ms(read_log(out))
    rows = a.index.intersection(b.index)
    assert len(rows) >= len(a) - 3  # the grid is the log's 1 kHz grid
    imported = _by_ms(read_bag(bag))
    assert walk["out"].attrs["faults"] == [FAULT] and b.attrs.get("faults") == [FAULT]
    for s in SENSOR_NAMES:
        fa, fb = a[f"flag_{s}"], b[f"flag_{s}"]
        assert fa.any() == fb.any(), s
        assert set(a[f"kind_{s}"][fa]) == set(b[f"kind_{s}"][fb]), s
        if fa.any():  # detection delay within 2 ms
            assert abs(a["time"][fa].iloc[0] - b["time"][fb].iloc[0]) <= 0.002 + 1e-9, s
        resampling = _rms(imported[f"force_{s}"], a[f"force_{s}"])
        assert resampling < 2.0, s  # the load cells carry receive times only
        recovered = _rms(a.loc[rows, f"recovered_{s}"], b.loc[rows, f"recovered_{s}"])
        assert recovered <= 1.25 * resampling, (s, recovered, resampling)
    assert a["flag_r2"].any() and not a[[f"flag_{s}" for s in SENSOR_NAMES if s != "r2"]].any(
        axis=None)


def test_vectorised_import_equals_per_message(walk) -> None:
    bag = walk["dir"] / "walk.mcap"
    if not bag.exists():
        write_bag(read_log(walk["log"]), bag)
    fast = read_bag(bag)
    slow = read_bag(bag, vectorised=False)
    assert fast.attrs["ros_import"]["decoder"] == "vectorised"
    pd.testing.assert_frame_equal(fast, slow)
    info = fast.attrs["ros_import"]
    assert info["rate_hz"] == pytest.approx(1000.0)
    assert info["stamps"]["/imu/data"] == "header"
    assert info["stamps"]["/foot/r/load_cells"].startswith("receive")
    assert info["interpolation"]["imu_quat_w"] == "linear, normalised"
    assert info["interpolation"]["contact_ref_r"] == "nearest"
    assert round(info["topic_rates_hz"]["/joint_states"]) == 500
    assert not fast["import_gap"].any()


def test_receive_times_can_be_chosen(walk, tmp_path) -> None:
    bag = tmp_path / "w.db3"
    write_bag(read_log(walk["log"]).iloc[:1500], bag)
    text = EXAMPLE_MAP.read_text().replace('stamps = "header"', 'stamps = "receive"')
    m = tmp_path / "map.toml"
    m.write_text(text)
    df = read_bag(bag, m)
    assert set(df.attrs["ros_import"]["stamps"].values()) == {"receive"}
    ref = _by_ms(read_log(walk["log"]))
    got = _by_ms(df)
    # receive times lag the samples by 0.2-0.5 ms: the IMU still matches closely
    assert _rms(got["imu_gyro_x"], ref["imu_gyro_x"]) < 0.01


def test_exported_mcap_reads_back_with_the_mcap_reader(walk, tmp_path) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    mc, layout = tmp_path / "results.mcap", tmp_path / "layout.json"
    res = runner.invoke(app, ["export", str(walk["dir"] / "out.parquet"), "-o", str(mc),
                              "--layout", str(layout)])
    assert res.exit_code == 0, res.output
    df = read_log(walk["dir"] / "out.parquet")
    want = expected_topics(df)
    counts: dict[str, int] = {}
    last: dict[str, int] = {}
    flags_r2: list[bool] = []
    kinds_r2: list[str] = []
    with mc.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for _, channel, message, msg in reader.iter_decoded_messages(log_time_order=False):
            t = channel.topic
            counts[t] = counts.get(t, 0) + 1
            assert message.log_time > last.get(t, -1), t  # strictly increasing per topic
            last[t] = message.log_time
            if t == "/grfguard/r2/flag":
                flags_r2.append(bool(msg.data))
            if t == "/grfguard/r2/kind":
                kinds_r2.append(msg.data)
            if t == "/grfguard/status" and msg.status[0].level:
                assert msg.status[0].name == "grfguard"
    assert counts == want
    assert len(want) == 8 * 5 + 2 * 2 + 2  # per sensor 5, per foot 2, CoM and status
    assert flags_r2 == df["flag_r2"].tolist()
    assert "offset" in kinds_r2 and kinds_r2[0] == "none"
    doc = json.loads(layout.read_text())
    paths = [p["value"].split(".")[0] for c in doc["configById"].values()
             for p in c.get("paths", [])]
    assert paths and set(paths) <= set(want)


# ------------------------------------------------------------------ bad bags (must show 4)
def _bag(short_log, tmp_path, name="b.mcap", **kw):
    return write_bag(short_log, tmp_path / name, **kw)


def test_missing_topic_names_it(short_log, tmp_path) -> None:
    bag = _bag(short_log, tmp_path, omit=["/joint_states"])
    with pytest.raises(LogFormatError, match=r"/joint_states.*not found.*/imu/data"):
        read_bag(bag)
    res = runner.invoke(app, ["import", str(bag), "-o", str(tmp_path / "x.parquet")])
    assert res.exit_code == 2 and "/joint_states" in res.output


def test_field_not_in_message_names_it(short_log, tmp_path) -> None:
    bag = _bag(short_log, tmp_path)
    m = tmp_path / "map.toml"
    m.write_text(EXAMPLE_MAP.read_text().replace('field = "wrench.force.z"',
                                                 'field = "wrench.force.w"'))
    with pytest.raises(LogFormatError, match=r"/foot/r/wrench.*'wrench.force.w'.*wrench.force.z"):
        read_bag(bag, m)


def test_slow_topic_is_an_error(short_log, tmp_path) -> None:
    bag = _bag(short_log, tmp_path, rates_hz={"/foot/l/load_cells": 10.0})
    with pytest.raises(LogFormatError, match=r"/foot/l/load_cells is at 10 Hz.*1000 Hz"):
        read_bag(bag)


def test_gap_is_reported_flagged_and_not_interpolated(short_log, tmp_path) -> None:
    bag = _bag(short_log, tmp_path, gaps={"/foot/l/load_cells": (0.8, 1.3)})
    with pytest.warns(BagImportWarning, match=r"/foot/l/load_cells: gap of 0.50\d s"):
        df = read_bag(bag)
    gap = df["import_gap"].to_numpy()
    assert 495 <= gap.sum() <= 502
    t = df["time"].to_numpy()
    assert gap[(t > 0.81) & (t < 1.29)].all() and not gap[t < 0.79].any()
    assert df["force_l1"][gap].isna().all() and df["force_r1"][gap].notna().all()
    (g,) = df.attrs["ros_import"]["gaps"]
    assert g["topic"] == "/foot/l/load_cells" and g["duration_s"] == pytest.approx(0.5, abs=2e-3)


def test_joint_names_that_do_not_match_name_the_joints(short_log, tmp_path) -> None:
    names = [f"{j}_joint" for j in JOINT_NAMES]
    bag = _bag(short_log, tmp_path, joint_names=names)
    with pytest.raises(LogFormatError, match=r"r_hip_yaw.*not in JointState.name.*joints.names"):
        read_bag(bag)
    m = tmp_path / "map.toml"
    body = "\n".join(f'{j} = "{j}_joint"' for j in JOINT_NAMES if j != "r_hip_yaw")
    m.write_text(EXAMPLE_MAP.read_text().replace('r_hip_yaw = "r_hip_yaw"',
                                                 'r_hip_yaw = "r_hip_yaw_joint"\n' + body))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        df = read_bag(bag, m)
    ref = _by_ms(short_log)
    assert _rms(_by_ms(df)["q_l_knee"], ref["q_l_knee"]) < 1e-3


def test_bad_maps_say_which_key(tmp_path) -> None:
    m = tmp_path / "m.toml"
    m.write_text(EXAMPLE_MAP.read_text().replace('stamps = "header"', 'stamps = "both"'))
    with pytest.raises(ConfigError, match="time.stamps"):
        load_topics_map(m)
    m.write_text(EXAMPLE_MAP.read_text().replace("r4 = {", "r9 = {"))
    with pytest.raises(ConfigError, match=r"lacks sensor\(s\) \['r4'\]"):
        load_topics_map(m)


def test_run_with_map_on_a_parquet_log_is_a_clear_error(walk, tmp_path) -> None:
    res = runner.invoke(app, ["run", str(walk["log"]), "--map", str(EXAMPLE_MAP),
                              "-o", str(tmp_path / "o.parquet")])
    assert res.exit_code == 2 and "--map is for ROS bags" in res.output


# ------------------------------------------------------------------------ CDR decoding
def test_cdr_groups_match_rosbags_on_changing_layouts() -> None:
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    rng = np.random.default_rng(0)
    msgs = []
    for i in range(40):  # frame_id and joint order change; an empty velocity now and then
        names = ["a", "bb", "ccc"] if i % 3 else ["ccc", "a", "bb"]
        msgs.append(T["sensor_msgs/msg/JointState"](
            header=T["std_msgs/msg/Header"](
                stamp=T["builtin_interfaces/msg/Time"](sec=i, nanosec=7 * i),
                frame_id="base" if i % 5 else "base_link"),
            name=names, position=rng.normal(size=3),
            velocity=np.zeros(0) if i % 4 == 0 else rng.normal(size=3), effort=np.zeros(0)))
    raws = [bytes(ts.serialize_cdr(m, "sensor_msgs/msg/JointState")) for m in msgs]
    groups = _cdr.split_groups(raws, "sensor_msgs/msg/JointState", ts)
    assert len(groups) > 2 and sum(len(g.index) for g in groups) == len(raws)
    for g in groups:
        pos = _cdr.field(g, "position")
        sec = _cdr.field(g, "header.stamp.nanosec")
        for k, i in enumerate(g.index.tolist()):
            assert g.layout.strings["name"] == list(msgs[i].name)
            np.testing.assert_array_equal(pos[k], msgs[i].position)
            assert sec[k] == msgs[i].header.stamp.nanosec


def test_ros1_bag_imports_like_the_ros2_bag(short_log, tmp_path) -> None:
    from rosbags.convert import convert
    from rosbags.typesys import Stores, get_typestore

    ros2 = write_bag(short_log.iloc[:1000], tmp_path / "ros2", "sqlite3")
    ros1 = tmp_path / "walk.bag"
    convert([ros2], ros1, "sqlite3", 9, None, "file", None,
            get_typestore(Stores.ROS1_NOETIC), [], [], [], [])
    a, b = read_bag(ros1), read_bag(ros2)
    slow = read_bag(ros1, vectorised=False)
    for df in (a, b, slow):
        df.attrs = {}
    pd.testing.assert_frame_equal(a, slow)  # ROS 1 serialisation decoded vectorised
    pd.testing.assert_frame_equal(a, b)
