"""Thrift compact protocol, generic: enough to read and rewrite a Parquet footer.

A struct decodes to a ``dict`` from field id to ``(type, value)`` in wire order; encoding
it again gives the same bytes (field ids are written in the dict's order, as read). No
Parquet field is interpreted here (:mod:`grfguard.io.splice` does that).

Values by compact type: ``BOOL_TRUE``/``BOOL_FALSE`` (fields: the type is the value;
list elements: the raw byte), ``BYTE``/``I16``/``I32``/``I64`` int, ``DOUBLE`` the 8
raw bytes, ``BINARY`` bytes, ``LIST``/``SET`` ``(element type, [values])``, ``MAP``
``(key type, value type, [(key, value)])``, ``STRUCT`` a dict.
"""

from __future__ import annotations

from typing import Any

__all__ = ["decode_struct", "encode_struct", "BOOL_TRUE", "BOOL_FALSE", "I16", "I32", "I64",
           "BINARY", "LIST", "STRUCT"]

BOOL_TRUE, BOOL_FALSE, BYTE, I16, I32, I64, DOUBLE, BINARY, LIST, SET, MAP, STRUCT = range(1, 13)


class ThriftError(ValueError):
    """The bytes are not a valid compact-protocol struct (truncated or corrupt)."""


def decode_struct(buf: bytes | memoryview, pos: int = 0) -> tuple[dict[int, tuple], int]:
    """The struct at ``buf[pos:]`` and the position after it.

    Raises:
        ThriftError: Truncated or malformed input.
    """
    try:
        return _Dec(bytes(buf)).struct(pos)
    except (IndexError, RecursionError) as exc:
        raise ThriftError(f"truncated or malformed Thrift data ({exc})") from None


def encode_struct(fields: dict[int, tuple]) -> bytes:
    """The compact-protocol bytes of ``fields`` (as :func:`decode_struct` returns)."""
    out = bytearray()
    _enc_struct(out, fields)
    return bytes(out)


class _Dec:
    def __init__(self, b: bytes) -> None:
        self.b = b

    def varint(self, p: int) -> tuple[int, int]:
        b, shift, v = self.b, 0, 0
        while True:
            x = b[p]
            p += 1
            v |= (x & 0x7F) << shift
            if x < 0x80:
                return v, p
            shift += 7
            if shift > 70:
                raise ThriftError("varint too long")

    def zigzag(self, p: int) -> tuple[int, int]:
        v, p = self.varint(p)
        return (v >> 1) ^ -(v & 1), p

    def value(self, t: int, p: int) -> tuple[Any, int]:
        if t in (BYTE,):
            return self.b[p], p + 1
        if t in (I16, I32, I64):
            return self.zigzag(p)
        if t == DOUBLE:
            if p + 8 > len(self.b):
                raise ThriftError("truncated double")
            return self.b[p:p + 8], p + 8
        if t == BINARY:
            n, p = self.varint(p)
            if p + n > len(self.b):
                raise ThriftError("truncated binary")
            return self.b[p:p + n], p + n
        if t in (LIST, SET):
            return self.seq(p)
        if t == MAP:
            return self.map(p)
        if t == STRUCT:
            return self.struct(p)
        if t in (BOOL_TRUE, BOOL_FALSE):  # a list element: one byte
            return self.b[p], p + 1
        raise ThriftError(f"unknown compact type {t}")

    def seq(self, p: int) -> tuple[tuple, int]:
        h = self.b[p]
        p += 1
        n, et = h >> 4, h & 0x0F
        if n == 15:
            n, p = self.varint(p)
        items = []
        for _ in range(n):
            v, p = self.value(et, p)
            items.append(v)
        return (et, items), p

    def map(self, p: int) -> tuple[tuple, int]:
        n, p = self.varint(p)
        if n == 0:
            return (0, 0, []), p
        h = self.b[p]
        p += 1
        kt, vt = h >> 4, h & 0x0F
        items = []
        for _ in range(n):
            k, p = self.value(kt, p)
            v, p = self.value(vt, p)
            items.append((k, v))
        return (kt, vt, items), p

    def struct(self, p: int) -> tuple[dict[int, tuple], int]:
        fields: dict[int, tuple] = {}
        last = 0
        while True:
            h = self.b[p]
            p += 1
            if h == 0:
                return fields, p
            t, delta = h & 0x0F, h >> 4
            if delta:
                fid = last + delta
            else:
                fid, p = self.zigzag(p)
            last = fid
            if t in (BOOL_TRUE, BOOL_FALSE):
                fields[fid] = (t, t == BOOL_TRUE)
            else:
                v, p = self.value(t, p)
                fields[fid] = (t, v)


def _varint(out: bytearray, v: int) -> None:
    while v >= 0x80:
        out.append((v & 0x7F) | 0x80)
        v >>= 7
    out.append(v)


def _zigzag(out: bytearray, v: int) -> None:
    _varint(out, (v << 1) ^ (v >> 63) if v < 0 else v << 1)


def _enc_value(out: bytearray, t: int, v: Any) -> None:
    if t in (BYTE, BOOL_TRUE, BOOL_FALSE):  # (booleans here only as list elements)
        out.append(v)
    elif t in (I16, I32, I64):
        _zigzag(out, v)
    elif t == DOUBLE:
        out += v
    elif t == BINARY:
        _varint(out, len(v))
        out += v
    elif t in (LIST, SET):
        et, items = v
        if len(items) < 15:
            out.append((len(items) << 4) | et)
        else:
            out.append(0xF0 | et)
            _varint(out, len(items))
        for x in items:
            _enc_value(out, et, x)
    elif t == MAP:
        kt, vt, items = v
        _varint(out, len(items))
        if items:
            out.append((kt << 4) | vt)
            for k, x in items:
                _enc_value(out, kt, k)
                _enc_value(out, vt, x)
    elif t == STRUCT:
        _enc_struct(out, v)
    else:
        raise ThriftError(f"unknown compact type {t}")


def _enc_struct(out: bytearray, fields: dict[int, tuple]) -> None:
    last = 0
    for fid, (t, v) in fields.items():
        if t in (BOOL_TRUE, BOOL_FALSE):
            t = BOOL_TRUE if v else BOOL_FALSE
        if 0 < fid - last <= 15:
            out.append(((fid - last) << 4) | t)
        else:
            out.append(t)
            _zigzag(out, fid)
        last = fid
        if t not in (BOOL_TRUE, BOOL_FALSE):
            _enc_value(out, t, v)
    out.append(0)
