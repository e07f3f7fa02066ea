"""Import ROS 2 bags (MCAP or sqlite3 storage) and ROS 1 bags into a grfguard log.

A *topics map* (TOML, example in ``grfguard/data/topics_example.toml``) says which topic
and field gives each column of the log contract. Only the mapped topics are read, and
messages are decoded vectorised (:mod:`grfguard.io._cdr`): one numpy view per field for
all messages of a topic instead of one Python object per message.

Topics at different rates are put on one time grid (default: the IMU topic's rate,
starting at its first message); each signal is interpolated as the map says (``linear``,
``previous`` or ``nearest``; the IMU quaternion linearly and then normalised). Nothing
is interpolated across a gap (two consecutive messages further apart than ``max_gap``)
or beyond a topic's first/last message: those grid rows are NaN for that topic's
columns, ``import_gap`` is True there, and the gap is reported (warning and
``attrs["ros_import"]["gaps"]``). Times are header stamps or bag receive times (map
``[time] stamps``); a message without a header always uses its receive time, and the
choice per topic is recorded in ``attrs["ros_import"]["stamps"]``.
"""

from __future__ import annotations

import json
import tomllib
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import ConfigError, LogFormatError
from grfguard.io import _cdr
from grfguard.io.anyread import is_bag
from grfguard.io.bagwrite import META_TOPIC
from grfguard.io.schema import IMU_ACC, IMU_GYRO, IMU_QUAT, TIME, force_col
from grfguard.model.robot import JOINT_NAMES, SENSOR_NAMES

__all__ = [
    "TopicsMap",
    "Signal",
    "BagImportWarning",
    "load_topics_map",
    "read_bag",
    "read_raw",
    "is_bag",
    "EXAMPLE_MAP",
    "INTERPOLATIONS",
]

#: The example map shipped with grfguard (fits bags written by ``grfguard bag``).
EXAMPLE_MAP = Path(__file__).resolve().parent.parent / "data" / "topics_example.toml"
INTERPOLATIONS = ("linear", "previous", "nearest")
_STAMPS = ("header", "receive")
_IMU_FIELDS = {
    **{c: f"orientation.{a}" for c, a in zip(IMU_QUAT, "wxyz", strict=True)},
    **{c: f"angular_velocity.{a}" for c, a in zip(IMU_GYRO, "xyz", strict=True)},
    **{c: f"linear_acceleration.{a}" for c, a in zip(IMU_ACC, "xyz", strict=True)},
}
_STAMP_SEC, _STAMP_NSEC = "header.stamp.sec", "header.stamp.nanosec"


class BagImportWarning(UserWarning):
    """Something in a bag is usable but suspicious (a gap, a slow topic, duplicates)."""


@dataclass(frozen=True)
class Signal:
    """One log column from a bag: ``topic``'s numeric ``field`` (``index`` for arrays).

    ``field`` is a dotted path (``wrench.force.z``, ``data``); ``interpolation`` is one of
    :data:`INTERPOLATIONS`.
    """

    column: str
    topic: str
    field: str
    index: int | None = None
    interpolation: str = "linear"


@dataclass(frozen=True)
class TopicsMap:
    """Which topics and fields make the log (see the module doc and the README).

    Attributes:
        imu_topic: ``sensor_msgs/msg/Imu`` topic (orientation, angular velocity, linear
            acceleration).
        joints_topic: ``sensor_msgs/msg/JointState`` topic.
        joints_field: ``position`` (default), ``velocity`` or ``effort``.
        joint_names: grfguard joint name -> name in ``JointState.name``.
        signals: Force sensors and extra columns.
        stamps: ``header`` or ``receive``.
        rate_hz: Grid rate [Hz]; None: the IMU topic's median rate.
        max_gap_s: Gap threshold [s]; None: the larger of 10 ms and 5 median periods of
            each topic.
        min_rate_fraction: A topic slower than this fraction of the grid rate is an error.
        imu_interpolation, joints_interpolation: Interpolation of those signals.
        robot: Optional robot TOML for the log's metadata.
    """

    imu_topic: str = "/imu/data"
    joints_topic: str = "/joint_states"
    joints_field: str = "position"
    joint_names: Mapping[str, str] = field(default_factory=lambda: {j: j for j in JOINT_NAMES})
    signals: tuple[Signal, ...] = ()
    stamps: str = "header"
    rate_hz: float | None = None
    max_gap_s: float | None = None
    min_rate_fraction: float = 0.25
    imu_interpolation: str = "linear"
    joints_interpolation: str = "linear"
    robot: str | None = None

    def topics(self) -> list[str]:
        """Every topic the map reads, IMU first."""
        out = [self.imu_topic, self.joints_topic, *(s.topic for s in self.signals)]
        return list(dict.fromkeys(out))


def _where(path: Path | str, key: str) -> str:
    return f"topics map {path}: {key}"


def load_topics_map(path: str | Path) -> TopicsMap:
    """Read and check a topics map (TOML); errors name the key and say how to fix it."""
    path = Path(path)
    if not path.exists():
        raise ConfigError(f"topics map {path} does not exist (example: {EXAMPLE_MAP})")
    try:
        d = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"topics map {path} is not valid TOML ({exc})") from exc
    return topics_map_from_dict(d, where=str(path))


def topics_map_from_dict(d: Mapping[str, Any], where: str = "topics map") -> TopicsMap:
    """A :class:`TopicsMap` from the parsed TOML tables."""
    known = {"time", "imu", "joints", "sensors", "columns", "robot"}
    unknown = sorted(set(d) - known)
    if unknown:
        raise ConfigError(f"{where}: unknown table(s) {unknown}; known: {sorted(known)}")
    tm = d.get("time", {})
    stamps = tm.get("stamps", "header")
    if stamps not in _STAMPS:
        raise ConfigError(f"{_where(where, 'time.stamps')} must be 'header' or 'receive', "
                          f"got {stamps!r}")
    rate = tm.get("rate")
    if rate is not None and not (isinstance(rate, (int, float)) and 0 < rate <= 1e5):
        raise ConfigError(f"{_where(where, 'time.rate')} must be a rate in (0, 1e5] Hz, "
                          f"got {rate!r}")
    max_gap = tm.get("max_gap")
    if max_gap is not None and not (isinstance(max_gap, (int, float)) and max_gap > 0):
        raise ConfigError(f"{_where(where, 'time.max_gap')} must be > 0 s, got {max_gap!r}")
    frac = tm.get("min_rate_fraction", 0.25)
    if not (isinstance(frac, (int, float)) and 0 <= frac <= 1):
        raise ConfigError(f"{_where(where, 'time.min_rate_fraction')} must be in [0, 1], "
                          f"got {frac!r}")
    imu = d.get("imu", {})
    joints = d.get("joints", {})
    if "topic" not in imu:
        raise ConfigError(f"{_where(where, '[imu] topic')} is missing (e.g. topic = "
                          "\"/imu/data\", a sensor_msgs/msg/Imu topic)")
    if "topic" not in joints:
        raise ConfigError(f"{_where(where, '[joints] topic')} is missing (e.g. topic = "
                          "\"/joint_states\", a sensor_msgs/msg/JointState topic)")
    jfield = joints.get("field", "position")
    if jfield not in ("position", "velocity", "effort"):
        raise ConfigError(f"{_where(where, 'joints.field')} must be position, velocity or "
                          f"effort, got {jfield!r}")
    names = {j: j for j in JOINT_NAMES}
    extra = sorted(set(joints.get("names", {})) - set(JOINT_NAMES))
    if extra:
        raise ConfigError(f"{_where(where, 'joints.names')}: {extra} are not grfguard joints; "
                          f"keys must be among {list(JOINT_NAMES)}")
    names.update({k: str(v) for k, v in joints.get("names", {}).items()})
    for key, val in (("imu.interpolation", imu.get("interpolation", "linear")),
                     ("joints.interpolation", joints.get("interpolation", "linear"))):
        _check_interp(val, _where(where, key))

    signals: list[Signal] = []
    sensors = dict(d.get("sensors", {}))
    s_interp = sensors.pop("interpolation", "linear")
    _check_interp(s_interp, _where(where, "sensors.interpolation"))
    missing = [s for s in SENSOR_NAMES if s not in sensors]
    if missing:
        raise ConfigError(f"{_where(where, '[sensors]')} lacks sensor(s) {missing}; give each "
                          "as  r1 = { topic = \"/foot/r/load_cells\", field = \"data\", "
                          "index = 0 }")
    bad = sorted(set(sensors) - set(SENSOR_NAMES))
    if bad:
        raise ConfigError(f"{_where(where, '[sensors]')}: {bad} are not sensors of the robot "
                          f"({list(SENSOR_NAMES)})")
    for s in SENSOR_NAMES:
        signals.append(_signal(force_col(s), sensors[s], s_interp, _where(where, f"sensors.{s}")))
    for col, spec in d.get("columns", {}).items():
        signals.append(_signal(col, spec, "linear", _where(where, f"columns.{col}")))
    return TopicsMap(
        imu_topic=str(imu["topic"]),
        joints_topic=str(joints["topic"]),
        joints_field=jfield,
        joint_names=names,
        signals=tuple(signals),
        stamps=stamps,
        rate_hz=float(rate) if rate is not None else None,
        max_gap_s=float(max_gap) if max_gap is not None else None,
        min_rate_fraction=float(frac),
        imu_interpolation=imu.get("interpolation", "linear"),
        joints_interpolation=joints.get("interpolation", "linear"),
        robot=d.get("robot"),
    )


def _check_interp(val: Any, where: str) -> None:
    if val not in INTERPOLATIONS:
        raise ConfigError(f"{where} must be one of {list(INTERPOLATIONS)}, got {val!r}")


def _signal(column: str, spec: Any, interp: str, where: str) -> Signal:
    if not isinstance(spec, Mapping) or "topic" not in spec:
        raise ConfigError(f"{where} must be a table with topic (and field, index), got {spec!r}")
    unknown = sorted(set(spec) - {"topic", "field", "index", "interpolation"})
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {unknown}")
    idx = spec.get("index")
    if idx is not None and not (isinstance(idx, int) and idx >= 0):
        raise ConfigError(f"{where}.index must be an integer >= 0, got {idx!r}")
    interp = spec.get("interpolation", interp)
    _check_interp(interp, f"{where}.interpolation")
    return Signal(column, str(spec["topic"]), str(spec.get("field", "data")), idx, interp)


# --------------------------------------------------------------------------- reading
@dataclass
class _Topic:
    name: str
    msgtype: str
    packed: _cdr.Packed
    recv_ns: np.ndarray
    ros1: bool
    groups: list[_cdr.Group] | None = None

    @property
    def raws(self) -> list[bytes]:
        return [self.packed.get(i) for i in range(len(self.packed))]

    def first(self) -> bytes:
        return self.packed.get(0)


def _storage_files(path: Path) -> list[Path] | None:
    """The storage files of a bag if all are plain ``.mcap`` or all ``.db3``, else None."""
    files = sorted(q for q in path.iterdir() if q.is_file()) if path.is_dir() else [path]
    files = [q for q in files if q.suffix in (".mcap", ".db3")]
    if not files or len({q.suffix for q in files}) != 1:
        return None
    return files


def _raw_mcap(files: list[Path], topics: list[str]
              ) -> dict[str, tuple[_cdr.Packed, np.ndarray]] | None:
    """Messages of ``topics`` from indexed MCAP files, vectorised: the chunk and message
    indexes give every message's offset, so no record is parsed one by one. None if a
    file has no chunk or message index (then the caller reads message by message)."""
    from mcap.reader import make_reader

    blobs: list[bytes] = []
    base = 0
    parts: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {t: [] for t in topics}
    u64, u32 = np.dtype("<u8"), np.dtype("<u4")
    for f in files:
        with f.open("rb") as fh:
            summary = make_reader(fh).get_summary()
            if summary is None or not summary.chunk_indexes:
                return None
            chans = {cid: ch.topic for cid, ch in summary.channels.items() if ch.topic in parts}
            for ci in summary.chunk_indexes:
                wanted = [c for c in ci.message_index_offsets if c in chans]
                if not wanted:
                    continue
                if ci.compression not in ("", "zstd", "lz4"):
                    return None
                fh.seek(ci.chunk_start_offset)
                blob = fh.read(ci.chunk_length + ci.message_index_length)
                p = 9 + 16
                usize = int(np.frombuffer(blob, u64, 1, p)[0])
                p += 12
                clen = int(np.frombuffer(blob, u32, 1, p)[0])
                p += 4 + clen
                rlen = int(np.frombuffer(blob, u64, 1, p)[0])
                data = blob[p + 8 : p + 8 + rlen]
                if ci.compression == "zstd":
                    import zstandard

                    data = zstandard.ZstdDecompressor().decompress(data, max_output_size=usize)
                elif ci.compression == "lz4":
                    import lz4.frame

                    data = lz4.frame.decompress(data)
                blobs.append(data)
                rec = np.frombuffer(data, dtype=np.uint8)
                for c in wanted:
                    mo = ci.message_index_offsets[c] - ci.chunk_start_offset
                    nb = int(np.frombuffer(blob, u32, 1, mo + 11)[0])
                    pairs = np.frombuffer(blob, u64, nb // 8, mo + 15).reshape(-1, 2)
                    offs = pairs[:, 1].astype(np.int64)
                    if offs.size and (rec[offs] != 0x05).any():
                        return None  # the index does not point at message records
                    rl = rec[offs[:, None] + 1 + np.arange(8)].copy().view(u64)[:, 0]
                    parts[chans[c]].append((offs + 31 + base, rl.astype(np.int64) - 22,
                                            pairs[:, 0].astype(np.int64)))
                base += rec.size
    joined = b"".join(blobs)
    buf = np.frombuffer(joined, dtype=np.uint8)
    out = {}
    for t, ps in parts.items():
        if not ps:
            out[t] = (_cdr.Packed(buf, np.zeros(0, np.int64), np.zeros(0, np.int64), joined),
                      np.zeros(0, np.int64))
            continue
        offs, lens, ts = (np.concatenate(x) for x in zip(*ps, strict=True))
        out[t] = (_cdr.Packed(buf, offs, lens, joined), ts)
    return out


def _raw_sqlite(files: list[Path], topics: list[str]
                ) -> dict[str, tuple[_cdr.Packed, np.ndarray]] | None:
    """Messages of ``topics`` from rosbag2 sqlite3 files: per file one table scan (in
    row id order, no index) returns the times and ``length * 2**16 + topic id`` per
    message (as text, parsed by numpy) and the data concatenated into one buffer by
    sqlite itself; no Python work per message. None if a file is not plain rosbag2."""
    import sqlite3

    blobs: list[bytes] = []
    parts: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {t: [] for t in topics}
    base = 0
    for f in files:
        con = sqlite3.connect(f"file:{f}?mode=ro", uri=True)
        try:
            ids = {i: n for n, i in con.execute("SELECT name, id FROM topics") if n in parts}
            if not ids:
                continue
            if not all(isinstance(i, int) and 0 <= i < 1 << 16 for i in ids):
                return None
            # NOT INDEXED: a plain scan of the rowid table, so in row id order; the
            # blobs concatenated by sqlite (checked against the lengths below)
            ts_s, key_s, data = con.execute(
                "SELECT group_concat(timestamp), group_concat(length(data) * 65536 + "
                "topic_id), CAST(group_concat(data, '') AS BLOB) FROM messages NOT INDEXED "
                f"WHERE topic_id IN ({','.join('?' * len(ids))})", list(ids)).fetchone()
        except sqlite3.DatabaseError:
            return None
        finally:
            con.close()
        if ts_s is None:
            continue
        tstamp, key = (np.fromstring(x, dtype=np.int64, sep=",") for x in (ts_s, key_s))
        tid, lens = key & 0xFFFF, key >> 16
        if not isinstance(data, bytes) or tstamp.size != key.size or lens.sum() != len(data):
            return None
        offs = np.zeros(lens.size, dtype=np.int64)
        np.cumsum(lens[:-1], out=offs[1:])
        by = np.argsort(tid.astype(np.uint16), kind="stable")  # per topic, in row order
        st = tid[by]
        for i, name in ids.items():
            lo, hi = np.searchsorted(st, [i, i + 1]).tolist()
            sel = by[lo:hi]
            parts[name].append((offs[sel] + base, lens[sel], tstamp[sel]))
        blobs.append(data)
        base += len(data)
    joined = blobs[0] if len(blobs) == 1 else b"".join(blobs)
    buf = np.frombuffer(joined, dtype=np.uint8)
    out = {}
    for t, ps in parts.items():
        if ps:
            o, ln, ts_ = (np.concatenate(x) for x in zip(*ps, strict=True))
        else:
            o = ln = ts_ = np.zeros(0, dtype=np.int64)
        out[t] = (_cdr.Packed(buf, o, ln, joined), ts_)
    return out


def _sqlite_direct(path: Path, files: list[Path], topics: list[str]
                   ) -> tuple[dict[str, _Topic], Any, dict] | None:
    """sqlite3 storage without ``rosbags``' reader (which counts every topic's messages
    on opening): topics and types from the ``topics`` table, standard ROS 2 message
    definitions. None when a type is not standard or the file is not plain rosbag2."""
    import sqlite3

    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    types: dict[str, set[str]] = {}
    try:
        for f in files:
            con = sqlite3.connect(f"file:{f}?mode=ro", uri=True)
            try:
                for name, typ, fmt in con.execute(
                        "SELECT name, type, serialization_format FROM topics"):
                    if fmt != "cdr":
                        return None
                    types.setdefault(name, set()).add(typ)
            finally:
                con.close()
    except sqlite3.DatabaseError:
        return None
    missing = [t for t in topics if t not in types]
    if missing:
        have = ", ".join(f"{t} ({sorted(v)[0]})" for t, v in sorted(types.items()))
        raise LogFormatError(f"bag {path}: topic(s) {missing} not found; the bag has: {have}. "
                             "Fix the topic names in the topics map.")
    for t in topics:
        if len(types[t]) > 1:
            raise LogFormatError(f"bag {path}: topic {t} has several types {sorted(types[t])}")
        if next(iter(types[t])) not in ts.fielddefs:
            return None
    want = [*topics, META_TOPIC] if META_TOPIC in types else topics
    got = _raw_sqlite(files, want)
    if got is None:
        return None
    meta: dict[str, Any] = {}
    if META_TOPIC in got and len(got[META_TOPIC][0]):
        try:
            meta = json.loads(ts.deserialize_cdr(got[META_TOPIC][0].get(0),
                                                 "std_msgs/msg/String").data)
        except ValueError:
            meta = {}
    out = {t: _Topic(t, next(iter(types[t])), got[t][0], got[t][1], False) for t in topics}
    return out, ts, meta


def read_raw(path: str | Path, topics: list[str], fast: bool = True
             ) -> tuple[dict[str, _Topic], Any, dict]:
    """Serialised messages of ``topics`` (only those are read), their typestore and the
    bag's grfguard metadata (``custom_data``), if any.

    With ``fast`` (default), MCAP files are read through their indexes and sqlite3
    files with one query; otherwise (and for ROS 1 or compressed bags) message by
    message through ``rosbags``.

    Raises:
        LogFormatError: The bag cannot be read, or a topic is not in it (the message
            lists the bag's topics).
    """
    from rosbags.highlevel import AnyReader

    path = Path(path)
    if not path.exists():
        raise LogFormatError(f"bag {path} does not exist")
    files = _storage_files(path) if fast else None
    if files is not None and files[0].suffix == ".db3":
        direct = _sqlite_direct(path, files, topics)
        if direct is not None:
            return direct
    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as exc:  # rosbags raises several unrelated types
        raise LogFormatError(f"{path} is not a readable ROS bag ({exc})") from exc
    try:
        by_topic: dict[str, list[Any]] = {}
        for c in reader.connections:
            by_topic.setdefault(c.topic, []).append(c)
        missing = [t for t in topics if t not in by_topic]
        if missing:
            have = ", ".join(f"{t} ({cs[0].msgtype})" for t, cs in sorted(by_topic.items()))
            raise LogFormatError(
                f"bag {path}: topic(s) {missing} not found; the bag has: {have}. "
                "Fix the topic names in the topics map."
            )
        conns = [c for t in topics for c in by_topic[t]]
        for t in topics:
            types = {c.msgtype for c in by_topic[t]}
            if len(types) > 1:
                raise LogFormatError(f"bag {path}: topic {t} has several types {sorted(types)}")
        ros1 = not reader.is2
        got = None
        files = _storage_files(path) if fast and not ros1 else None
        if files is not None:
            compressed = any(getattr(r, "compression_mode", None) for r in reader.readers)
            if not compressed:
                reader_fn = _raw_mcap if files[0].suffix == ".mcap" else _raw_sqlite
                got = reader_fn(files, topics)
        if got is None:
            cid = {c.id: c.topic for c in conns}
            raws: dict[str, list[bytes]] = {t: [] for t in topics}
            recv: dict[str, list[int]] = {t: [] for t in topics}
            for conn, ts, raw in reader.messages(connections=conns):
                t = cid[conn.id]
                raws[t].append(raw)
                recv[t].append(ts)
            got = {t: (_cdr.Packed.from_list(raws[t]), np.asarray(recv[t], dtype=np.int64))
                   for t in topics}
        out = {t: _Topic(t, by_topic[t][0].msgtype, got[t][0], got[t][1], ros1)
               for t in topics}
        return out, reader.typestore, _bag_metadata(reader, by_topic)
    finally:
        reader.close()


def _bag_metadata(reader: Any, by_topic: dict[str, list[Any]]) -> dict[str, Any]:
    """grfguard's metadata of an open bag: the META_TOPIC message written by grfguard's
    bag writer, else the ``grfguard`` entry of the storage's custom metadata, else {}."""
    meta: dict[str, Any] = {}
    if META_TOPIC in by_topic:  # written by grfguard's bag writer
        for c, _, data in reader.messages(connections=by_topic[META_TOPIC]):
            try:
                meta = json.loads(reader.deserialize(data, c.msgtype).data)
            except (ValueError, AttributeError):
                meta = {}
            break
    for r in getattr(reader, "readers", []) if not meta else []:
        custom = getattr(getattr(getattr(r, "storage", None), "metadata", None),
                         "custom", None) or getattr(getattr(r, "metadata", None),
                                                    "custom", None)
        if custom and "grfguard" in custom:
            try:
                meta = json.loads(custom["grfguard"])
            except ValueError:
                meta = {}
    return meta


_Names = tuple[list[tuple[str, ...]], np.ndarray]


def _decode(top: _Topic, typestore: Any, paths: list[str], vectorised: bool,
            want_names: bool = False) -> tuple[dict[str, np.ndarray], _Names | None]:
    """Fields ``paths`` of every message, in message order: ``(n,)`` or ``(n, count)``.

    With ``want_names`` also the ``name`` lists (JointState): the distinct lists and, per
    message, the index of its list. A sequence whose length changes between messages is
    padded with NaN.
    """
    n = len(top.packed)
    if n == 0:
        raise LogFormatError(f"topic {top.name} has no messages")
    first = _cdr.layout_of(top.first(), top.msgtype, typestore, top.ros1)
    for p in paths:
        if p not in first.leaves:
            numeric = ", ".join(k for k in first.leaves if not k.startswith("header."))
            raise LogFormatError(
                f"topic {top.name} ({top.msgtype}) has no numeric field {p!r}; its numeric "
                f"fields are: {numeric}. Fix 'field' in the topics map."
            )
    if not vectorised:
        return _decode_per_message(top, typestore, paths, want_names)
    out: dict[str, np.ndarray] = {}
    keys: list[tuple[str, ...]] = []
    codes = np.full(n, -1, dtype=np.int64)
    if top.groups is None:
        top.groups = _cdr.split_groups(top.packed, top.msgtype, typestore, top.ros1)
    groups = top.groups
    for g in groups:
        for p in paths:
            v = _cdr.field(g, p)
            if p not in out:
                out[p] = np.full((n, *v.shape[1:]), np.nan)
            if v.ndim == 2 and v.shape[1] != out[p].shape[1]:
                width = max(v.shape[1], out[p].shape[1])
                grown = np.full((n, width), np.nan)
                grown[:, : out[p].shape[1]] = out[p]
                out[p] = grown
                v2 = np.full((v.shape[0], width), np.nan)
                v2[:, : v.shape[1]] = v
                v = v2
            out[p][g.index] = v
        if want_names:
            nm = tuple(g.layout.strings.get("name", []))
            if nm not in keys:
                keys.append(nm)
            codes[g.index] = keys.index(nm)
    return out, ((keys, codes) if want_names else None)


def _decode_per_message(top: _Topic, typestore: Any, paths: list[str], want_names: bool
                        ) -> tuple[dict[str, np.ndarray], _Names | None]:
    """The reference: one ``rosbags`` message object per message."""
    deser = typestore.deserialize_ros1 if top.ros1 else typestore.deserialize_cdr
    cols: dict[str, list[Any]] = {p: [] for p in paths}
    names: list[list[str]] | None = [] if want_names else None
    getters = [(p, p.split(".")) for p in paths]
    for raw in top.raws:
        msg = deser(raw, top.msgtype)
        for p, parts in getters:
            v = msg
            for a in parts:
                v = getattr(v, a)
            cols[p].append(v)
        if names is not None:
            names.append(list(msg.name))
    out: dict[str, np.ndarray] = {}
    for p, vals in cols.items():
        if vals and isinstance(vals[0], np.ndarray):
            width = max(len(v) for v in vals)
            arr = np.full((len(vals), width), np.nan)
            for i, v in enumerate(vals):
                arr[i, : len(v)] = v
            out[p] = arr
        else:
            out[p] = np.asarray(vals, dtype=float)
    if names is None:
        return out, None
    keys: list[tuple[str, ...]] = list(dict.fromkeys(tuple(x) for x in names))
    index = {k: i for i, k in enumerate(keys)}
    return out, (keys, np.asarray([index[tuple(x)] for x in names], dtype=np.int64))


def _times(top: _Topic, typestore: Any, stamps: str, vectorised: bool
           ) -> tuple[np.ndarray, str]:
    """Message times [ns] and which kind they are."""
    if stamps == "header":
        if not len(top.packed):
            raise LogFormatError(f"topic {top.name} has no messages")
        lay = _cdr.layout_of(top.first(), top.msgtype, typestore, top.ros1)
        if _STAMP_SEC in lay.leaves:
            v, _ = _decode(top, typestore, [_STAMP_SEC, _STAMP_NSEC], vectorised)
            ns = v[_STAMP_SEC].astype(np.int64) * 1_000_000_000 + v[_STAMP_NSEC].astype(
                np.int64)
            return ns, "header"
        return top.recv_ns, "receive (the message has no header)"
    return top.recv_ns, "receive"


def _order(ns: np.ndarray, topic: str, report: list[str]) -> np.ndarray:
    """Indices that sort ``ns`` and drop duplicate times (reported)."""
    order = np.argsort(ns, kind="stable")
    s = ns[order]
    keep = np.ones(len(s), dtype=bool)
    keep[1:] = np.diff(s) > 0
    if not keep.all():
        report.append(f"topic {topic}: {int((~keep).sum())} message(s) with a repeated time "
                      "dropped")
    if (np.diff(ns) < 0).any():
        report.append(f"topic {topic}: times not in order; sorted")
    return order[keep]


def _interp(t: np.ndarray, y: np.ndarray, grid: np.ndarray, how: str) -> np.ndarray:
    """``y`` (n,) or (n, c) sampled at ``t`` onto ``grid`` (inside ``t``'s range)."""
    y2 = y if y.ndim == 2 else y[:, None]
    if how == "linear":
        out = np.empty((len(grid), y2.shape[1]))
        for j in range(y2.shape[1]):
            out[:, j] = np.interp(grid, t, y2[:, j])
    else:
        i = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 1)
        if how == "nearest":
            nxt = np.clip(i + 1, 0, len(t) - 1)
            i = np.where(np.abs(t[nxt] - grid) < np.abs(grid - t[i]), nxt, i)
        out = y2[i]
    return out if y.ndim == 2 else out[:, 0]


def _holes(t: np.ndarray, grid: np.ndarray, max_gap: float) -> tuple[np.ndarray, list]:
    """Grid rows outside ``t``'s range or inside a gap, and the gaps ``(start, end)``."""
    bad = (grid < t[0]) | (grid > t[-1])
    d = np.diff(t)
    gaps = np.flatnonzero(d > max_gap)
    spans = []
    for k in gaps.tolist():
        a, b = t[k], t[k + 1]
        bad |= (grid > a) & (grid < b)
        spans.append((float(a), float(b)))
    return bad, spans


def read_bag(
    path: str | Path,
    topics_map: TopicsMap | str | Path | None = None,
    *,
    vectorised: bool = True,
    fast_read: bool | None = None,
) -> pd.DataFrame:
    """A grfguard log from a ROS bag.

    Args:
        path: rosbag2 directory, ``*.mcap``, ``*.db3``, or ROS 1 ``*.bag``.
        topics_map: A :class:`TopicsMap`, a TOML path, or None for the example map.
        vectorised: Decode with numpy (default); False deserialises every message with
            ``rosbags`` (the reference, same result, much slower).
        fast_read: Read raw messages through the MCAP index / one sqlite query
            (default: as ``vectorised``); False reads them one by one with ``rosbags``.

    Returns:
        The log: ``time`` [s since the first IMU message, at ``attrs["ros_import"]
        ["t0_ns"]``], IMU, joints, forces, extra columns, ``import_gap`` (bool); import
        details in ``attrs["ros_import"]``.

    Raises:
        LogFormatError: Missing topic or field, unknown joint names, a topic too slow
            for the grid.
    """
    if topics_map is None:
        topics_map = EXAMPLE_MAP
    tmap = topics_map if isinstance(topics_map, TopicsMap) else load_topics_map(topics_map)
    raw, typestore, meta = read_raw(
        path, tmap.topics(), fast=vectorised if fast_read is None else fast_read)
    report: list[str] = []
    times, orders, stamps_used, t0_ns = _topic_times(raw, typestore, tmap, vectorised, report)
    grid, rate = _grid(path, tmap, times)
    rates, holes, gap_any, gaps = _rates_and_gaps(tmap, times, grid, rate, report)
    rs = _Resampler(times, orders, holes, grid)
    _imu_columns(rs, raw, typestore, tmap, vectorised)
    _joint_columns(rs, raw, typestore, tmap, vectorised)
    _signal_columns(rs, raw, typestore, tmap, vectorised)
    rs.cols["import_gap"] = gap_any
    df = pd.DataFrame(rs.cols)
    attrs = dict(meta)
    if tmap.robot is not None:
        from grfguard.model.robot import load_robot

        attrs["robot"] = load_robot(tmap.robot).to_dict()
    attrs["source"] = str(path)
    attrs["ros_import"] = {
        "bag": str(path),
        "rate_hz": rate,
        "t0_ns": t0_ns,
        "stamps": stamps_used,
        "topic_rates_hz": rates,
        "messages": {t: len(raw[t].packed) for t in raw},
        "interpolation": rs.interp_used,
        "gaps": gaps,
        "decoder": "vectorised" if vectorised else "per-message",
    }
    df.attrs.update(attrs)
    for line in report:
        warnings.warn(line, BagImportWarning, stacklevel=2)
    return df


def _topic_times(raw: dict[str, _Topic], typestore: Any, tmap: TopicsMap, vectorised: bool,
                 report: list[str]) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray],
                                             dict[str, str], int]:
    """Times of every topic [s relative to the IMU's first message] in time order, the
    order of its messages, the stamp used per topic and the IMU's first stamp [ns]."""
    stamps_used: dict[str, str] = {}
    times: dict[str, np.ndarray] = {}
    orders: dict[str, np.ndarray] = {}
    t0_ns: int | None = None
    for name in tmap.topics():
        ns, kind = _times(raw[name], typestore, tmap.stamps, vectorised)
        stamps_used[name] = kind
        o = _order(ns, name, report)
        orders[name] = o
        if t0_ns is None:
            t0_ns = int(ns[o][0])
        times[name] = (ns[o] - t0_ns) * 1e-9
    assert t0_ns is not None
    return times, orders, stamps_used, t0_ns


def _grid(path: str | Path, tmap: TopicsMap,
          times: dict[str, np.ndarray]) -> tuple[np.ndarray, float]:
    """The output time grid [s] over the span every topic covers, and its rate [Hz]
    (the map's, else the IMU's with its period rounded to 1 us)."""
    t_imu = times[tmap.imu_topic]
    if len(t_imu) < 2:
        raise LogFormatError(f"topic {tmap.imu_topic} has fewer than 2 messages")
    imu_period = float(np.median(np.diff(t_imu)))
    # the IMU's rate, its period rounded to 1 us (header jitter averages out in the median)
    rate = tmap.rate_hz if tmap.rate_hz is not None else 1.0 / round(imu_period, 6)
    period = 1.0 / rate
    start = max(float(t[0]) for t in times.values())
    stop = min(float(t[-1]) for t in times.values())
    k0 = max(0, int(np.ceil(start / period - 1e-9)))
    k1 = int(np.floor(stop / period + 1e-9))
    if k1 <= k0:
        raise LogFormatError(f"bag {path}: the mapped topics do not overlap in time")
    return np.arange(k0, k1 + 1) * period, rate


def _rates_and_gaps(tmap: TopicsMap, times: dict[str, np.ndarray], grid: np.ndarray,
                    rate: float, report: list[str]):
    """Median rate of every topic [Hz], its grid rows inside a gap, the union of those
    rows and the list of gaps; refuses a topic too slow for the grid."""
    gap_any = np.zeros(len(grid), dtype=bool)
    gaps: list[dict[str, Any]] = []
    rates: dict[str, float] = {}
    holes: dict[str, np.ndarray] = {}
    for name, t in times.items():
        if len(t) < 2:
            raise LogFormatError(f"topic {name} has {len(t)} message(s): too few to import")
        med = float(np.median(np.diff(t)))
        rates[name] = 1.0 / med
        if rates[name] < tmap.min_rate_fraction * rate:
            raise LogFormatError(
                f"topic {name} is at {rates[name]:.4g} Hz, but the grid is at {rate:.4g} Hz: "
                f"a signal slower than {tmap.min_rate_fraction:g} x the grid rate cannot be "
                "interpolated faithfully. Record it faster, or set [time] rate (or "
                "min_rate_fraction) in the topics map."
            )
        max_gap = tmap.max_gap_s if tmap.max_gap_s is not None else max(0.01, 5 * med)
        bad, spans = _holes(t, grid, max_gap)
        holes[name] = bad
        gap_any |= bad
        for a, b in spans:
            gaps.append({"topic": name, "start_s": a, "end_s": b, "duration_s": b - a})
            report.append(f"topic {name}: gap of {b - a:.3f} s from t = {a:.3f} s to "
                          f"{b:.3f} s (no message); grid rows inside are NaN and flagged "
                          "import_gap")
    return rates, holes, gap_any, gaps


class _Resampler:
    """Output columns on the grid: every signal interpolated from its topic's times,
    NaN inside the topic's gaps, the interpolation used recorded per column."""

    def __init__(self, times: dict[str, np.ndarray], orders: dict[str, np.ndarray],
                 holes: dict[str, np.ndarray], grid: np.ndarray) -> None:
        self.times, self.orders, self.holes, self.grid = times, orders, holes, grid
        self.cols: dict[str, np.ndarray] = {TIME: grid}
        self.interp_used: dict[str, str] = {}

    def put(self, name: str, col: str, y: np.ndarray, how: str) -> None:
        v = _interp(self.times[name], y[self.orders[name]], self.grid, how)
        v[self.holes[name]] = np.nan
        self.cols[col] = v
        self.interp_used[col] = how


def _imu_columns(rs: _Resampler, raw: dict[str, _Topic], typestore: Any, tmap: TopicsMap,
                 vectorised: bool) -> None:
    """IMU quaternion (short-way interpolated, normalised), gyro and accelerometer."""
    imu = raw[tmap.imu_topic]
    _expect(imu, "sensor_msgs/msg/Imu")
    v, _ = _decode(imu, typestore, list(_IMU_FIELDS.values()), vectorised)
    q = np.stack([v[_IMU_FIELDS[c]] for c in IMU_QUAT], axis=1)
    # same hemisphere as the previous quaternion, so linear interpolation is short-way
    flip = np.concatenate([[False], np.einsum("ij,ij->i", q[1:], q[:-1]) < 0])
    sign = np.where(np.logical_xor.accumulate(flip), -1.0, 1.0)
    q = q * sign[:, None]
    qi = _interp(rs.times[tmap.imu_topic], q[rs.orders[tmap.imu_topic]], rs.grid,
                 tmap.imu_interpolation)
    qi /= np.linalg.norm(qi, axis=1, keepdims=True)
    qi[rs.holes[tmap.imu_topic]] = np.nan
    for j, c in enumerate(IMU_QUAT):
        rs.cols[c] = qi[:, j]
        rs.interp_used[c] = f"{tmap.imu_interpolation}, normalised"
    for c in (*IMU_GYRO, *IMU_ACC):
        rs.put(tmap.imu_topic, c, v[_IMU_FIELDS[c]], tmap.imu_interpolation)


def _joint_columns(rs: _Resampler, raw: dict[str, _Topic], typestore: Any, tmap: TopicsMap,
                   vectorised: bool) -> None:
    """``q_<joint>`` from the JointState topic, matched by name per message layout."""
    js = raw[tmap.joints_topic]
    _expect(js, "sensor_msgs/msg/JointState")
    v, names = _decode(js, typestore, [tmap.joints_field], vectorised, want_names=True)
    arr = v[tmap.joints_field]
    assert names is not None
    keys, codes = names
    jvals = np.full((len(codes), len(JOINT_NAMES)), np.nan)
    for ki, key in enumerate(keys):
        rows = codes == ki
        pos = {n: i for i, n in enumerate(key)}
        missing = [f"{j} (as {tmap.joint_names[j]!r})" for j in JOINT_NAMES
                   if tmap.joint_names[j] not in pos]
        if missing:
            raise LogFormatError(
                f"topic {tmap.joints_topic}: joint(s) {missing} not in JointState.name; the "
                f"bag's names are {list(key)}. Map them in [joints.names] of the topics map "
                "(grfguard joint = \"name in the bag\")."
            )
        for j, jn in enumerate(JOINT_NAMES):
            k = pos[tmap.joint_names[jn]]
            if k >= arr.shape[1]:
                raise LogFormatError(f"topic {tmap.joints_topic}: JointState.{tmap.joints_field}"
                                     f" has no value for joint {tmap.joint_names[jn]!r}")
            jvals[rows, j] = arr[rows, k]
    for j, jn in enumerate(JOINT_NAMES):
        rs.put(tmap.joints_topic, f"q_{jn}", jvals[:, j], tmap.joints_interpolation)


def _signal_columns(rs: _Resampler, raw: dict[str, _Topic], typestore: Any, tmap: TopicsMap,
                    vectorised: bool) -> None:
    """Force sensors and extra columns of the map's signals (one decode per topic)."""
    by_topic: dict[str, list[Signal]] = {}
    for s in tmap.signals:
        by_topic.setdefault(s.topic, []).append(s)
    for name, sigs in by_topic.items():
        v, _ = _decode(raw[name], typestore, sorted({s.field for s in sigs}), vectorised)
        for s in sigs:
            y = v[s.field]
            if y.ndim == 2:
                if s.index is None:
                    raise LogFormatError(f"topic {name}: field {s.field!r} is an array of "
                                         f"{y.shape[1]}; give 'index' for column {s.column}")
                if s.index >= y.shape[1]:
                    raise LogFormatError(f"topic {name}: field {s.field!r} has {y.shape[1]} "
                                         f"values, index {s.index} (column {s.column}) is "
                                         "out of range")
                y = y[:, s.index]
            elif s.index is not None:
                raise LogFormatError(f"topic {name}: field {s.field!r} is a scalar; remove "
                                     f"'index' for column {s.column}")
            rs.put(name, s.column, y, s.interpolation)

def _expect(top: _Topic, msgtype: str) -> None:
    if top.msgtype != msgtype:
        raise LogFormatError(f"topic {top.name} is {top.msgtype}, expected {msgtype}; fix the "
                             "topic in the topics map")
