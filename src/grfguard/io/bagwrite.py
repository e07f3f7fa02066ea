"""Write a log (a simulated walk) as a realistic ROS 2 bag, so the whole ROS path can be
tried without a robot.

Topics (the example map ``grfguard/data/topics_example.toml`` reads them back):

======================  ==================================  ========  ==================
topic                   type                                rate      stamps
======================  ==================================  ========  ==================
``/imu/data``           ``sensor_msgs/msg/Imu``             1 kHz     header + receive
``/joint_states``       ``sensor_msgs/msg/JointState``      500 Hz    header + receive
``/foot/<s>/load_cells`` ``std_msgs/msg/Float64MultiArray``  1 kHz     receive only
``/foot/<s>/wrench``    ``geometry_msgs/msg/WrenchStamped`` 1 kHz     header + receive
``/gait/zmp_ref``       ``geometry_msgs/msg/PointStamped``  1 kHz     header + receive
``/gait/contact_ref``   ``std_msgs/msg/Float64MultiArray``  1 kHz     receive only
======================  ==================================  ========  ==================

The two ``/gait`` topics are the walking planner's plan (planned ZMP; planned stance
``[right, left]``, 1 = stance), written when the log has them; the monitor gates its
tests with the planned stance, so a bag should carry it when the robot has one.

``<s>`` is ``r`` or ``l``; a load-cell array holds the foot's four sensors in the order
1..4. The wrench is the foot's total force and its moment about the sole centre (from the
four cells). Header stamps are the sample times plus a driver jitter (Gaussian,
``stamp_jitter_s``); receive times add a transport latency (``latency_s`` plus an
exponential part of mean ``latency_jitter_s``), and messages are written in receive
order, as ``ros2 bag record`` does. Every random number comes from ``seed``.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import ConfigError, LogFormatError
from grfguard.io import _cdr
from grfguard.io.schema import (
    CONTACT_REF,
    IMU_ACC,
    IMU_GYRO,
    IMU_QUAT,
    JOINT_COLUMNS,
    TIME,
    ZMP_REF,
    force_col,
)
from grfguard.model.robot import JOINT_NAMES, SIDES

__all__ = ["write_bag", "BAG_TOPICS", "START_NS", "META_TOPIC"]

#: Topic of one ``std_msgs/msg/String``: the log's metadata (robot, gait, faults) as JSON.
META_TOPIC = "/grfguard/metadata"

#: Topic -> message type of the bags :func:`write_bag` writes.
BAG_TOPICS: dict[str, str] = {
    "/imu/data": "sensor_msgs/msg/Imu",
    "/joint_states": "sensor_msgs/msg/JointState",
    **{f"/foot/{s}/load_cells": "std_msgs/msg/Float64MultiArray" for s in SIDES},
    **{f"/foot/{s}/wrench": "geometry_msgs/msg/WrenchStamped" for s in SIDES},
    "/gait/zmp_ref": "geometry_msgs/msg/PointStamped",
    "/gait/contact_ref": "std_msgs/msg/Float64MultiArray",
}
#: Bag time of log time 0 [ns since the epoch] (2023-11-14 22:13:20 UTC).
START_NS = 1_700_000_000_000_000_000


def _typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _template(ts: Any, typename: str, **kw: Any) -> bytes:
    return bytes(ts.serialize_cdr(_build(ts, typename, **kw), typename))


def _build(ts: Any, typename: str, **kw: Any) -> Any:
    T = ts.types
    hdr = T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=kw.get("frame", "")
    )
    v3 = T["geometry_msgs/msg/Vector3"]
    if typename == "sensor_msgs/msg/Imu":
        cov = np.diag([1e-4, 1e-4, 1e-4]).ravel()
        return T[typename](
            header=hdr,
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=cov,
            angular_velocity=v3(x=0.0, y=0.0, z=0.0),
            angular_velocity_covariance=cov,
            linear_acceleration=v3(x=0.0, y=0.0, z=0.0),
            linear_acceleration_covariance=cov,
        )
    if typename == "sensor_msgs/msg/JointState":
        n = len(kw["names"])
        return T[typename](
            header=hdr, name=list(kw["names"]), position=np.zeros(n), velocity=np.zeros(n),
            effort=np.zeros(0),
        )
    if typename == "std_msgs/msg/Float64MultiArray":
        n = kw["n"]
        dim = T["std_msgs/msg/MultiArrayDimension"](label="sensor", size=n, stride=n)
        return T[typename](
            layout=T["std_msgs/msg/MultiArrayLayout"](dim=[dim], data_offset=0),
            data=np.zeros(n),
        )
    if typename == "geometry_msgs/msg/PointStamped":
        return T[typename](header=hdr, point=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0))
    if typename == "geometry_msgs/msg/WrenchStamped":
        return T[typename](
            header=hdr,
            wrench=T["geometry_msgs/msg/Wrench"](force=v3(x=0.0, y=0.0, z=0.0),
                                                 torque=v3(x=0.0, y=0.0, z=0.0)),
        )
    raise ConfigError(f"write_bag: no template for {typename}")  # pragma: no cover


def _stamp_values(ns: np.ndarray) -> dict[str, np.ndarray]:
    return {"header.stamp.sec": ns // 1_000_000_000, "header.stamp.nanosec": ns % 1_000_000_000}


def write_bag(
    log: pd.DataFrame,
    path: str | Path,
    storage: str | None = None,
    *,
    imu_rate_hz: float = 1000.0,
    joint_rate_hz: float = 500.0,
    force_rate_hz: float = 1000.0,
    rates_hz: Mapping[str, float] | None = None,
    stamp_jitter_s: float = 30e-6,
    latency_s: float = 0.2e-3,
    latency_jitter_s: float = 0.1e-3,
    gaps: Mapping[str, tuple[float, float]] | None = None,
    omit: Iterable[str] = (),
    joint_names: Iterable[str] | None = None,
    seed: int = 0,
) -> Path:
    """Write ``log`` as a ROS 2 bag (see the module doc for topics and timing).

    Args:
        log: A log of the contract (1 kHz; ``time``, IMU, joints, forces).
        path: ``*.mcap`` or ``*.db3``: one storage file; anything else: a rosbag2
            directory (``metadata.yaml`` + storage file, as ``ros2 bag record`` writes).
        storage: ``mcap`` or ``sqlite3``; default from the suffix, else ``mcap``.
        imu_rate_hz, joint_rate_hz, force_rate_hz: Topic rates [Hz]; each must divide the
            log's rate (the log is decimated, not interpolated).
        rates_hz: Per-topic rate overrides [Hz] (e.g. ``{"/foot/r/wrench": 10}``).
        stamp_jitter_s: Std of the header-stamp jitter [s].
        latency_s: Minimum transport latency (receive minus sample time) [s].
        latency_jitter_s: Mean of the exponential part of the latency [s].
        gaps: Per topic, a window ``(start, end)`` of log time [s] with no message.
        omit: Topics not to write.
        joint_names: Names written in ``JointState.name`` (default grfguard's).
        seed: Seed of the jitter and latency.

    Returns:
        The path written.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    storage, single = _storage_of(path, storage)
    missing = [c for c in (TIME, *IMU_ACC, *IMU_GYRO, *IMU_QUAT, *JOINT_COLUMNS) if c not in log]
    if missing:
        raise LogFormatError(f"write_bag: the log lacks column(s) {missing}")

    t = log[TIME].to_numpy(float)
    dt = float(np.median(np.diff(t)))
    rng = np.random.default_rng(seed)
    ts = _typestore()
    names = list(joint_names) if joint_names is not None else list(JOINT_NAMES)
    if len(names) != len(JOINT_NAMES):
        raise ConfigError(f"joint_names needs {len(JOINT_NAMES)} names, got {len(names)}")
    rates = _rates(imu_rate_hz, joint_rate_hz, force_rate_hz, 1.0 / dt, rates_hz)
    from grfguard.estimate.vfs import _robot_from_attrs

    pos = _robot_from_attrs(log.attrs).sensor_positions_in_foot()
    # per topic: (typename, serialised rows, receive ns)
    out: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
    omit = set(omit)
    for topic, typename in BAG_TOPICS.items():
        if topic in omit:
            continue
        if topic.startswith("/gait/") and not all(c in log for c in (*ZMP_REF, *CONTACT_REF)):
            continue
        step = max(1, round(1.0 / (rates[topic] * dt)))
        idx = np.arange(0, len(t), step)
        if gaps and topic in gaps:
            g0, g1 = gaps[topic]
            idx = idx[(t[idx] < g0) | (t[idx] >= g1)]
        n = idx.size
        stamp_ns, recv_ns = _stamps(t[idx], rng, stamp_jitter_s, latency_s, latency_jitter_s)
        tpl, vals = _topic_values(topic, typename, log, idx, ts, names, pos, stamp_ns)
        out[topic] = (typename, _cdr.fill(tpl, typename, ts, n, vals), recv_ns)
    _write_storage(path, suffix, storage, single, out, log.attrs, ts)
    return path


def _rates(imu_rate_hz: float, joint_rate_hz: float, force_rate_hz: float, log_rate_hz: float,
           rates_hz: Mapping[str, float] | None) -> dict[str, float]:
    """Rate of every topic [Hz] (the gait topics at the log's rate), overrides applied."""
    rates = {
        "/imu/data": imu_rate_hz,
        "/joint_states": joint_rate_hz,
        **{f"/foot/{s}/load_cells": force_rate_hz for s in SIDES},
        **{f"/foot/{s}/wrench": force_rate_hz for s in SIDES},
        "/gait/zmp_ref": log_rate_hz,
        "/gait/contact_ref": log_rate_hz,
    }
    rates.update(rates_hz or {})
    return rates


def _storage_of(path: Path, storage: str | None) -> tuple[str, bool]:
    """The storage plugin name and whether ``path`` is a single storage file.

    Raises:
        ConfigError: Unknown storage, a suffix that contradicts it, or ``path`` exists.
    """
    suffix = path.suffix.lower()
    if storage is None:
        storage = {".db3": "sqlite3"}.get(suffix, "mcap")
    if storage not in ("mcap", "sqlite3"):
        raise ConfigError(f"bag storage must be 'mcap' or 'sqlite3', got {storage!r}")
    single = suffix in (".mcap", ".db3")
    if single and {".mcap": "mcap", ".db3": "sqlite3"}[suffix] != storage:
        raise ConfigError(f"{path}: suffix {suffix} does not match storage {storage!r}")
    if path.exists():
        raise ConfigError(f"{path} exists already; remove it or choose another name")
    return storage, single


def _stamps(t: np.ndarray, rng: np.random.Generator, stamp_jitter_s: float, latency_s: float,
            latency_jitter_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Header stamps and receive times [ns] of messages sampled at ``t`` [s]: clipped
    Gaussian stamp jitter, latency plus an exponential part; receive times in order per
    topic, at least 1 us apart (a transport queues, it does not reorder)."""
    n = t.size
    sample_ns = START_NS + np.round(t * 1e9).astype(np.int64)
    jit = np.clip(rng.normal(0.0, stamp_jitter_s, n), -3 * stamp_jitter_s, 3 * stamp_jitter_s)
    stamp_ns = sample_ns + np.round(jit * 1e9).astype(np.int64)
    lat = latency_s + rng.exponential(latency_jitter_s, n) if latency_jitter_s > 0 else (
        np.full(n, latency_s))
    step_ns = np.arange(n, dtype=np.int64) * 1000
    recv_ns = sample_ns + np.round(lat * 1e9).astype(np.int64)
    recv_ns = np.maximum.accumulate(recv_ns - step_ns) + step_ns
    return stamp_ns, recv_ns


def _topic_values(topic: str, typename: str, log: pd.DataFrame, idx: np.ndarray, ts: Any,
                  names: list[str], pos: np.ndarray,
                  stamp_ns: np.ndarray) -> tuple[Any, dict[str, np.ndarray]]:
    """Message template and field values (rows ``idx`` of ``log``) of one topic."""
    cols = log.iloc[idx]
    if topic == "/imu/data":
        tpl = _template(ts, typename, frame="imu_link")
        vals = {
            **{f"orientation.{a}": cols[c].to_numpy(float) for a, c in zip("wxyz", IMU_QUAT,
                                                                          strict=True)},
            **{f"angular_velocity.{a}": cols[c].to_numpy(float)
               for a, c in zip("xyz", IMU_GYRO, strict=True)},
            **{f"linear_acceleration.{a}": cols[c].to_numpy(float)
               for a, c in zip("xyz", IMU_ACC, strict=True)},
            **_stamp_values(stamp_ns),
        }
    elif topic == "/joint_states":
        tpl = _template(ts, typename, frame="", names=names)
        q = log[list(JOINT_COLUMNS)].to_numpy(float)
        qd = np.gradient(q, log[TIME].to_numpy(float), axis=0)
        vals = {"position": q[idx], "velocity": qd[idx], **_stamp_values(stamp_ns)}
    elif topic == "/gait/zmp_ref":
        tpl = _template(ts, typename, frame="world")
        vals = {"point.x": cols[ZMP_REF[0]].to_numpy(float),
                "point.y": cols[ZMP_REF[1]].to_numpy(float), **_stamp_values(stamp_ns)}
    elif topic == "/gait/contact_ref":
        tpl = _template(ts, typename, n=2)
        vals = {"data": cols[list(CONTACT_REF)].to_numpy(float)}
    else:
        side = topic.split("/")[2]
        f = np.stack([log[force_col(f"{side}{k}")].to_numpy(float)[idx]
                      for k in range(1, 5)], axis=1)
        if typename == "std_msgs/msg/Float64MultiArray":
            tpl = _template(ts, typename, n=4)
            vals = {"data": f}
        else:
            tpl = _template(ts, typename, frame=f"{side}_sole")
            vals = {
                "wrench.force.z": f.sum(axis=1),
                "wrench.torque.x": f @ pos[:, 1],
                "wrench.torque.y": -(f @ pos[:, 0]),
                **_stamp_values(stamp_ns),
            }
    return tpl, vals


def _write_storage(path: Path, suffix: str, storage: str, single: bool,
                   out: dict[str, tuple[str, np.ndarray, np.ndarray]], attrs: dict,
                   ts: Any) -> None:
    """Write the serialised rows of every topic in receive order, with grfguard's
    metadata (custom data and a META_TOPIC message); a single file is written through a
    temporary rosbag2 directory."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    tmpdir = path.with_name(path.name + ".bagtmp") if single else path
    if single and tmpdir.exists():
        shutil.rmtree(tmpdir)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    order_topic = np.concatenate([np.full(len(v[2]), i) for i, v in enumerate(out.values())])
    order_row = np.concatenate([np.arange(len(v[2])) for v in out.values()])
    recv_all = np.concatenate([v[2] for v in out.values()])
    order = np.argsort(recv_all, kind="stable")
    try:
        with Writer(tmpdir, version=9, storage_plugin=plugin) as writer:
            meta = {k: v for k, v in attrs.items() if k != "source"}
            writer.set_custom_data("grfguard", json.dumps(_jsonable(meta), sort_keys=True))
            conns = [writer.add_connection(tp, v[0], typestore=ts) for tp, v in out.items()]
            # the same metadata as a message: a single .mcap/.db3 file has no metadata.yaml
            mconn = writer.add_connection(META_TOPIC, "std_msgs/msg/String", typestore=ts)
            writer.write(mconn, int(recv_all.min()), bytes(ts.serialize_cdr(
                ts.types["std_msgs/msg/String"](data=json.dumps(_jsonable(meta))),
                "std_msgs/msg/String")))
            rows = [v[1] for v in out.values()]
            for k in order.tolist():
                i = order_topic[k]
                writer.write(conns[i], int(recv_all[k]), rows[i][order_row[k]].tobytes())
    except BaseException:
        shutil.rmtree(tmpdir, ignore_errors=True)
        raise
    if single:
        (file,) = [p for p in tmpdir.iterdir() if p.suffix == suffix]
        file.replace(path)
        shutil.rmtree(tmpdir)


def _jsonable(v: Any) -> Any:
    from grfguard.io.logio import to_jsonable

    return to_jsonable(v)
