"""Export the results of ``grfguard run`` as standard ROS 2 messages in MCAP, for
Foxglove and PlotJuggler (plus an optional Foxglove layout).

Topics (``<s>`` a sensor ``r1..l4``, ``<side>`` ``r`` or ``l``; every sample unless said):

=============================  ===================================  =========================
topic                          type                                 content
=============================  ===================================  =========================
``/grfguard/<s>/measured``     ``std_msgs/msg/Float64``             measured force [N]
``/grfguard/<s>/vfs``          ``std_msgs/msg/Float64``             virtual force sensor [N]
``/grfguard/<s>/recovered``    ``std_msgs/msg/Float64``             recovered force [N]
``/grfguard/<s>/flag``         ``std_msgs/msg/Bool``                fault flag
``/grfguard/<s>/kind``         ``std_msgs/msg/String``              fault kind; on change only
``/grfguard/<side>/wrench``    ``geometry_msgs/msg/WrenchStamped``  VFS total force (force.z)
``/grfguard/<side>/cop``       ``geometry_msgs/msg/PointStamped``   VFS centre of pressure [m]
``/grfguard/com``              ``geometry_msgs/msg/PointStamped``   estimated CoM [m]
``/grfguard/status``           ``diagnostic_msgs/msg/DiagnosticArray``  system status, at
                                                                    ``status_rate_hz`` and on
                                                                    every change
=============================  ===================================  =========================

Status levels: OK (0) no sensor flagged; WARN (1) a sensor is flagged and its recovered
force replaces it; ERROR (2) the virtual sensor is not valid (``vfs_valid`` false). One
``DiagnosticStatus`` for the system (``grfguard``) and one per sensor (``grfguard/<s>``,
message = fault kind). Log and publish times are the sample times (``time`` plus
``attrs["ros_import"]["t0_ns"]`` for a log imported from a bag, else 0 = the epoch);
header stamps are the same times.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import LogFormatError
from grfguard.io import _cdr
from grfguard.io.schema import (
    COM_EST_COLUMNS,
    TIME,
    flag_col,
    force_col,
    kind_col,
    recovered_col,
    vfs_col,
)
from grfguard.model.robot import SENSOR_NAMES, SIDES

__all__ = ["export_mcap", "foxglove_layout"]


def _series_topics() -> dict[str, tuple[str, str]]:
    """topic -> (type, column) of the per-sample scalar topics."""
    out: dict[str, tuple[str, str]] = {}
    for s in SENSOR_NAMES:
        out[f"/grfguard/{s}/measured"] = ("std_msgs/msg/Float64", force_col(s))
        out[f"/grfguard/{s}/vfs"] = ("std_msgs/msg/Float64", vfs_col(s))
        out[f"/grfguard/{s}/recovered"] = ("std_msgs/msg/Float64", recovered_col(s))
        out[f"/grfguard/{s}/flag"] = ("std_msgs/msg/Bool", flag_col(s))
    return out


def _levels(df: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """Per-row system level and (n, 8) per-sensor levels."""
    flags = np.stack([df[flag_col(s)].to_numpy(bool) for s in SENSOR_NAMES], axis=1)
    valid = df["vfs_valid"].to_numpy(bool) if "vfs_valid" in df else np.ones(len(df), bool)
    sensor = flags.astype(np.int8)
    system = np.where(~valid, 2, np.where(flags.any(axis=1), 1, 0)).astype(np.int8)
    return system, sensor


def _status_rows(df: pd.DataFrame, rate_hz: float) -> np.ndarray:
    t = df[TIME].to_numpy(float)
    system, sensor = _levels(df)
    tick = np.floor((t - t[0]) * rate_hz + 1e-9).astype(np.int64)
    rows = np.zeros(len(t), dtype=bool)
    rows[0] = True
    rows[1:] |= tick[1:] != tick[:-1]
    rows[1:] |= system[1:] != system[:-1]
    rows[1:] |= (sensor[1:] != sensor[:-1]).any(axis=1)
    return np.flatnonzero(rows)


def export_mcap(
    df: pd.DataFrame,
    path: str | Path,
    *,
    status_rate_hz: float = 10.0,
    layout: str | Path | None = None,
) -> dict[str, int]:
    """Write the results in ``df`` (output of ``grfguard run``) to an MCAP file.

    Args:
        df: Output of :meth:`grfguard.detect.Monitor.run`.
        path: The ``.mcap`` file to write.
        status_rate_hz: Rate of ``/grfguard/status`` between changes [Hz].
        layout: Also write a Foxglove layout (JSON) there.

    Returns:
        Topic -> messages written.

    Raises:
        LogFormatError: ``df`` lacks result columns (it is not an output of ``run``).
    """
    from rosbags.typesys import Stores, get_typestore

    _check_result_columns(df)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    t = df[TIME].to_numpy(float)
    t0 = int(df.attrs.get("ros_import", {}).get("t0_ns", 0)) if isinstance(
        df.attrs.get("ros_import"), dict) else 0
    ns = t0 + np.round(t * 1e9).astype(np.int64)
    n = len(df)
    stamp = {"header.stamp.sec": ns // 1_000_000_000, "header.stamp.nanosec": ns % 1_000_000_000}
    T = ts.types
    templates = _templates(ts)

    # (topic, type, rows (m, L) uint8, times ns)
    streams: list[tuple[str, str, Iterable[bytes], np.ndarray]] = []
    for topic, (typ, col) in _series_topics().items():
        vals = df[col].to_numpy(bool if typ == "std_msgs/msg/Bool" else float)
        rows = _cdr.fill(templates[typ], typ, ts, n, {"data": vals.astype(np.uint8) if
                                                      typ == "std_msgs/msg/Bool" else vals})
        streams.append((topic, typ, rows, ns))
    for side in SIDES:
        typ = "geometry_msgs/msg/WrenchStamped"
        rows = _cdr.fill(templates[typ], typ, ts, n, {
            "wrench.force.z": df[f"vfs_total_{side}"].to_numpy(float), **stamp})
        streams.append((f"/grfguard/{side}/wrench", typ, rows, ns))
        typ = "geometry_msgs/msg/PointStamped"
        rows = _cdr.fill(templates[typ], typ, ts, n, {
            "point.x": df[f"vfs_cop_{side}_x"].to_numpy(float),
            "point.y": df[f"vfs_cop_{side}_y"].to_numpy(float), **stamp})
        streams.append((f"/grfguard/{side}/cop", typ, rows, ns))
    typ = "geometry_msgs/msg/PointStamped"
    rows = _cdr.fill(templates[typ], typ, ts, n, {
        f"point.{a}": df[c].to_numpy(float) for a, c in zip("xyz", COM_EST_COLUMNS, strict=True)
    } | stamp)
    streams.append(("/grfguard/com", typ, rows, ns))

    # fault kinds: on change only
    for s in SENSOR_NAMES:
        k = df[kind_col(s)].astype(str).to_numpy()
        idx = np.concatenate([[0], np.flatnonzero(k[1:] != k[:-1]) + 1])
        msgs = [_ser(ts, "std_msgs/msg/String", T["std_msgs/msg/String"](data=str(k[i])))
                for i in idx]
        streams.append((f"/grfguard/{s}/kind", "std_msgs/msg/String", msgs, ns[idx]))

    streams.append(_status_stream(df, ns, status_rate_hz, ts))
    _write_mcap(path, streams, ts)
    counts = {topic: len(tt) for (topic, _, _, tt) in streams}
    if layout is not None:
        Path(layout).write_text(json.dumps(foxglove_layout(), indent=2))
    return counts


def _check_result_columns(df: pd.DataFrame) -> None:
    """Raise :class:`LogFormatError` if ``df`` is not an output of ``grfguard run``."""
    need = [TIME, *COM_EST_COLUMNS, *(c for s in SENSOR_NAMES for c in (
        force_col(s), vfs_col(s), recovered_col(s), flag_col(s), kind_col(s))),
        *(f"vfs_total_{side}" for side in SIDES),
        *(f"vfs_cop_{side}_{a}" for side in SIDES for a in "xy")]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise LogFormatError(
            f"export: the log lacks {missing[:6]}{'...' if len(missing) > 6 else ''}; export "
            "the output of `grfguard run`, not its input"
        )


def _ser(ts: Any, typename: str, msg: Any) -> bytes:
    """CDR bytes of ``msg``."""
    return bytes(ts.serialize_cdr(msg, typename))


def _templates(ts: Any) -> dict[str, bytes]:
    """Zero-valued serialised messages of the numeric topic types (filled per row)."""
    T = ts.types
    hdr = T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="world")
    v3 = T["geometry_msgs/msg/Vector3"]
    return {
        "std_msgs/msg/Float64": _ser(ts, "std_msgs/msg/Float64",
                                     T["std_msgs/msg/Float64"](data=0.0)),
        "std_msgs/msg/Bool": _ser(ts, "std_msgs/msg/Bool", T["std_msgs/msg/Bool"](data=False)),
        "geometry_msgs/msg/WrenchStamped": _ser(
            ts, "geometry_msgs/msg/WrenchStamped", T["geometry_msgs/msg/WrenchStamped"](
                header=hdr, wrench=T["geometry_msgs/msg/Wrench"](
                    force=v3(x=0.0, y=0.0, z=0.0), torque=v3(x=0.0, y=0.0, z=0.0)))),
        "geometry_msgs/msg/PointStamped": _ser(
            ts, "geometry_msgs/msg/PointStamped", T["geometry_msgs/msg/PointStamped"](
                header=hdr, point=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0))),
    }


def _status_stream(df: pd.DataFrame, ns: np.ndarray, status_rate_hz: float,
                   ts: Any) -> tuple[str, str, list[bytes], np.ndarray]:
    """``/grfguard/status`` DiagnosticArray messages: the system level and one status per
    sensor, at ``status_rate_hz`` and on every change."""
    T = ts.types
    system, sensor = _levels(df)
    idx = _status_rows(df, status_rate_hz)
    DS, KV = T["diagnostic_msgs/msg/DiagnosticStatus"], T["diagnostic_msgs/msg/KeyValue"]
    words = ("OK", "WARN: a sensor is flagged, its recovered force is used",
             "ERROR: the virtual force sensor is not valid")
    kinds = {s: df[kind_col(s)].astype(str).to_numpy() for s in SENSOR_NAMES}
    msgs = []
    for i in idx.tolist():
        h = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
            sec=int(ns[i] // 1_000_000_000), nanosec=int(ns[i] % 1_000_000_000)), frame_id="")
        status = [DS(level=int(system[i]), name="grfguard",
                     message=words[int(system[i])], hardware_id="grfguard",
                     values=[KV(key="flagged", value=",".join(
                         s for j, s in enumerate(SENSOR_NAMES) if sensor[i, j])) ])]
        for j, s in enumerate(SENSOR_NAMES):
            status.append(DS(level=int(sensor[i, j]),
                             name=f"grfguard/{s}", message=kinds[s][i], hardware_id=s,
                             values=[]))
        msgs.append(_ser(ts, "diagnostic_msgs/msg/DiagnosticArray",
                         T["diagnostic_msgs/msg/DiagnosticArray"](header=h, status=status)))
    return "/grfguard/status", "diagnostic_msgs/msg/DiagnosticArray", msgs, ns[idx]


def _write_mcap(path: Path, streams: list[tuple[str, str, Any, np.ndarray]], ts: Any) -> None:
    """Write every stream's messages in time order (through a temporary file)."""
    from mcap.writer import Writer

    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2", library="grfguard")
        schemas: dict[str, int] = {}
        chans: list[int] = []
        for topic, typ, _, _ in streams:
            if typ not in schemas:
                msgdef, _ = ts.generate_msgdef(typ, ros_version=2)
                schemas[typ] = w.register_schema(name=typ, encoding="ros2msg",
                                                 data=msgdef.encode())
            chans.append(w.register_channel(topic=topic, message_encoding="cdr",
                                            schema_id=schemas[typ]))
        which = np.concatenate([np.full(len(s[3]), k) for k, s in enumerate(streams)])
        row = np.concatenate([np.arange(len(s[3])) for s in streams])
        times = np.concatenate([s[3] for s in streams])
        order = np.argsort(times, kind="stable")
        seqs = [0] * len(streams)
        payloads = [s[2] for s in streams]
        for k in order.tolist():
            j = int(which[k])
            r = int(row[k])
            p = payloads[j]
            data = p[r].tobytes() if isinstance(p, np.ndarray) else p[r]
            w.add_message(channel_id=chans[j], log_time=int(times[k]), data=data,
                          publish_time=int(times[k]), sequence=seqs[j])
            seqs[j] += 1
        w.finish()
    tmp.replace(path)


def foxglove_layout() -> dict[str, Any]:
    """A Foxglove layout: per foot a plot of measured, virtual and recovered forces of
    its sensors, a plot of the flags, and the diagnostics (status) panel."""
    cfg: dict[str, Any] = {}
    for side in SIDES:
        paths = []
        for s in (x for x in SENSOR_NAMES if x.startswith(side)):
            for what in ("measured", "vfs", "recovered"):
                paths.append({"value": f"/grfguard/{s}/{what}.data", "enabled": True,
                              "timestampMethod": "receiveTime"})
        cfg[f"Plot!forces_{side}"] = {"title": f"forces {side} [N]", "paths": paths,
                                      "showLegend": True}
    cfg["Plot!flags"] = {"title": "fault flags", "paths": [
        {"value": f"/grfguard/{s}/flag.data", "enabled": True, "timestampMethod": "receiveTime"}
        for s in SENSOR_NAMES], "showLegend": True}
    cfg["DiagnosticSummary!status"] = {"topicToRender": "/grfguard/status"}
    return {
        "configById": cfg,
        "globalVariables": {},
        "userNodes": {},
        "layout": {
            "direction": "column",
            "first": {"direction": "row", "first": "Plot!forces_r", "second": "Plot!forces_l"},
            "second": {"direction": "row", "first": "Plot!flags",
                       "second": "DiagnosticSummary!status"},
            "splitPercentage": 60,
        },
    }
