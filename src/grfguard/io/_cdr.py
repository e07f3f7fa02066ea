"""Vectorised decoding of serialised ROS messages with numpy.

A topic's messages usually share one byte layout: the same ``frame_id``, the same joint
names, the same array lengths. For such messages every numeric field sits at the same
byte offset in every message, so a whole topic decodes as strided views into one
``(n_messages, n_bytes)`` array instead of one Python object per message.

:func:`layout_of` walks one serialised message (ROS 2 CDR, either byte order, or ROS 1)
with the message definition from a ``rosbags`` typestore and returns where each numeric
leaf field is and which bytes fix the layout (encapsulation, string and sequence
lengths, string contents). :func:`split_groups` puts the messages of a topic into groups
that share a layout (checked byte for byte on those positions, vectorised), and
:func:`field` reads one leaf of a group as a float array.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from dataclasses import field as _dc_field
from typing import Any

import numpy as np

__all__ = ["Layout", "Group", "Packed", "layout_of", "split_groups", "field", "fill", "CdrError"]

_SIZES = {
    "bool": 1, "byte": 1, "char": 1, "int8": 1, "uint8": 1,
    "int16": 2, "uint16": 2, "int32": 4, "uint32": 4, "int64": 8, "uint64": 8,
    "float32": 4, "float64": 8,
}
_KINDS = {
    "bool": "u", "byte": "u", "char": "u", "int8": "i", "uint8": "u",
    "int16": "i", "uint16": "u", "int32": "i", "uint32": "u", "int64": "i", "uint64": "u",
    "float32": "f", "float64": "f",
}
# Node types of rosbags' parse tree (rosbags.interfaces.Nodetype).
_BASE, _NAME, _ARRAY, _SEQUENCE = 1, 2, 3, 4


class CdrError(ValueError):
    """A serialised message does not match its message definition."""


@dataclass
class Layout:
    """Where the numeric leaves of one serialised message are.

    Attributes:
        leaves: Field path (``"orientation.x"``, ``"position"``) -> (byte offset, numpy
            dtype, element count, is_array). Arrays and sequences are one leaf.
        strings: Field path -> string value(s) (``"header.frame_id"``, ``"name"``).
        struct_idx: Byte positions that fix the layout; two messages of the same length
            with the same bytes there have the same layout.
        size: Message length [bytes].
    """

    leaves: dict[str, tuple[int, np.dtype, int, bool]] = _dc_field(default_factory=dict)
    strings: dict[str, Any] = _dc_field(default_factory=dict)
    struct_idx: np.ndarray = _dc_field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    size: int = 0


class _Walker:
    def __init__(self, raw: bytes, typestore: Any, ros1: bool) -> None:
        self.raw = raw
        self.ts = typestore
        self.ros1 = ros1
        self.lay = Layout(size=len(raw))
        self.struct: list[range] = []
        if ros1:
            self.base = 0
            self.order = "<"
        else:
            if len(raw) < 4:
                raise CdrError("message shorter than the 4-byte CDR encapsulation header")
            self.base = 4
            self.order = "<" if raw[1] & 1 else ">"
            self.struct.append(range(0, 2))
        self.pos = self.base

    def align(self, n: int) -> None:
        if not self.ros1 and n > 1:
            rel = self.pos - self.base
            self.pos += (-rel) % n

    def u32(self) -> int:
        self.align(4)
        p = self.pos
        if p + 4 > len(self.raw):
            raise CdrError(f"message ends at byte {len(self.raw)}, a length field is at {p}")
        self.struct.append(range(p, p + 4))
        self.pos = p + 4
        return int.from_bytes(self.raw[p : p + 4], "little" if self.order == "<" else "big")

    def string(self, path: str) -> str:
        n = self.u32()
        p = self.pos
        if p + n > len(self.raw):
            raise CdrError(f"string {path!r} of {n} bytes runs past the message end")
        self.struct.append(range(p, p + n))
        self.pos = p + n
        text = self.raw[p : p + n]
        if not self.ros1:
            text = text[:-1] if text.endswith(b"\x00") else text
        return text.decode("utf-8", errors="replace")

    def prim(self, path: str, typ: str, count: int, is_array: bool) -> None:
        size = _SIZES[typ]
        if count:
            self.align(size)
        dt = np.dtype(f"{self.order}{_KINDS[typ]}{size}")
        if self.pos + size * count > len(self.raw):
            raise CdrError(f"field {path!r} runs past the message end")
        self.lay.leaves[path] = (self.pos, dt, count, is_array)
        self.pos += size * count

    def node(self, path: str, desc: tuple[Any, Any]) -> None:
        kind, args = int(desc[0]), desc[1]
        if kind == _BASE:
            typ = args[0]
            if typ == "string":
                self.lay.strings[path] = self.string(path)
            elif typ in _SIZES:
                self.prim(path, typ, 1, False)
            else:
                raise CdrError(f"field {path!r}: type {typ} is not supported")
        elif kind == _NAME:
            self.message(args, path)
        elif kind in (_ARRAY, _SEQUENCE):
            sub, length = args
            n = self.u32() if kind == _SEQUENCE else int(length)
            if int(sub[0]) == _BASE and sub[1][0] in _SIZES:
                self.prim(path, sub[1][0], n, True)
            elif int(sub[0]) == _BASE and sub[1][0] == "string":
                self.lay.strings[path] = [self.string(f"{path}[{i}]") for i in range(n)]
            else:
                for i in range(n):
                    self.node(f"{path}[{i}]", sub)
        else:  # pragma: no cover - rosbags has no other node types
            raise CdrError(f"field {path!r}: unknown node type {kind}")

    def message(self, typename: str, prefix: str = "") -> None:
        try:
            fields = self.ts.fielddefs[typename][1]
        except KeyError:
            raise CdrError(f"message type {typename} is not in the typestore") from None
        for name, desc in fields:
            self.node(f"{prefix}.{name}" if prefix else name, desc)


def layout_of(raw: bytes, typename: str, typestore: Any, ros1: bool = False) -> Layout:
    """The layout of one serialised message of ``typename``.

    Args:
        raw: The serialised message (ROS 2 CDR with its 4-byte header, or ROS 1).
        typename: Message type, e.g. ``sensor_msgs/msg/Imu``.
        typestore: A ``rosbags`` typestore that knows ``typename``.
        ros1: ROS 1 serialisation (no alignment, no encapsulation header).

    Raises:
        CdrError: The bytes do not fit the definition.
    """
    w = _Walker(bytes(raw), typestore, ros1)
    w.message(typename)
    if w.pos > len(raw):
        raise CdrError(f"message of {len(raw)} bytes is shorter than its fields ({w.pos})")
    idx = [i for r in w.struct for i in r]
    w.lay.struct_idx = np.asarray(idx, dtype=np.intp)
    return w.lay


@dataclass
class Packed:
    """Serialised messages packed in one buffer: message ``i`` is
    ``buf[offs[i] : offs[i] + lens[i]]``."""

    buf: np.ndarray
    offs: np.ndarray
    lens: np.ndarray
    _bytes: bytes | None = None

    @classmethod
    def from_list(cls, raws: Sequence[bytes]) -> Packed:
        lens = np.fromiter(map(len, raws), dtype=np.int64, count=len(raws))
        offs = np.zeros(len(raws), dtype=np.int64)
        if len(raws) > 1:
            np.cumsum(lens[:-1], out=offs[1:])
        joined = b"".join(raws)
        return cls(np.frombuffer(joined, dtype=np.uint8), offs, lens, joined)

    def __len__(self) -> int:
        return int(self.offs.size)

    def get(self, i: int) -> bytes:
        o = int(self.offs[i])
        return self.buf[o : o + int(self.lens[i])].tobytes()

    def rows(self, idx: np.ndarray, length: int) -> np.ndarray:
        """``(len(idx), length)`` uint8 array of messages ``idx`` (all ``length`` long)."""
        o = self.offs[idx]
        if idx.size > 1 and (np.diff(o) == length).all():  # contiguous: one slice
            return self.buf[o[0] : o[0] + idx.size * length].reshape(idx.size, length)
        if length == 0 or idx.size == 0:
            return np.zeros((idx.size, length), dtype=np.uint8)
        # scattered (topics interleaved in the file): one gather, each message one
        # ``length``-byte item of a window view that starts at every byte of the buffer
        win = np.ndarray((self.buf.size - length + 1,), dtype=np.dtype((np.void, length)),
                         buffer=self.buf, strides=(1,))
        return win[o].view(np.uint8).reshape(idx.size, length)


@dataclass
class Group:
    """Messages of one topic that share a layout.

    Attributes:
        index: Positions of the messages in the topic's message list.
        layout: Their common layout.
        data: ``(len(index), layout.size)`` uint8 array of the raw messages.
    """

    index: np.ndarray
    layout: Layout
    data: np.ndarray


def split_groups(
    raws: Packed | Sequence[bytes], typename: str, typestore: Any, ros1: bool = False
) -> list[Group]:
    """Group serialised messages by layout (one group when the layout never changes)."""
    packed = raws if isinstance(raws, Packed) else Packed.from_list(raws)
    if not len(packed):
        return []
    lengths = packed.lens
    groups: list[Group] = []
    for length in np.unique(lengths):
        idx = np.flatnonzero(lengths == length)
        arr = packed.rows(idx, int(length))
        todo = np.arange(idx.size)
        while todo.size:
            lay = layout_of(arr[todo[0]].tobytes(), typename, typestore, ros1)
            si = lay.struct_idx
            sub = arr if todo.size == arr.shape[0] else arr[todo]
            same = (sub[:, si] == sub[0, si]).all(axis=1) if si.size else np.ones(
                todo.size, dtype=bool
            )
            keep = todo[same]
            data = sub if same.all() else sub[same]
            groups.append(Group(idx[keep], lay, np.ascontiguousarray(data)))
            todo = todo[~same]
    return groups


def field(group: Group, path: str) -> np.ndarray:
    """Leaf ``path`` of every message in ``group`` as float64: shape ``(n,)`` for a
    scalar, ``(n, count)`` for an array or sequence.

    Raises:
        KeyError: ``path`` is not a numeric leaf of the layout.
    """
    off, dt, count, is_array = group.layout.leaves[path]
    n, size = group.data.shape
    view = np.ndarray(
        (n, count), dtype=dt, buffer=group.data, offset=off, strides=(size, dt.itemsize)
    )
    out = view.astype(np.float64)
    return out if is_array else out[:, 0]


def fill(
    template: bytes, typename: str, typestore: Any, n: int, values: dict[str, Any]
) -> np.ndarray:
    """``n`` serialised messages: copies of ``template`` with the numeric leaves in
    ``values`` (path -> array of shape ``(n,)`` or ``(n, count)``) written in, vectorised.

    Only leaves whose layout does not change (numbers, not lengths) can be written, so
    ``template`` must already have the right string and sequence lengths.

    Returns:
        ``(n, len(template))`` uint8 array; row ``i`` is message ``i``.
    """
    lay = layout_of(template, typename, typestore)
    arr = np.tile(np.frombuffer(template, dtype=np.uint8), (n, 1))
    size = arr.shape[1]
    for path, val in values.items():
        off, dt, count, is_array = lay.leaves[path]
        view = np.ndarray(
            (n, count), dtype=dt, buffer=arr, offset=off, strides=(size, dt.itemsize)
        )
        v = np.asarray(val)
        view[...] = v.reshape(n, count) if is_array or v.ndim == 1 else v
    return arr
