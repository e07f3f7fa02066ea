"""A Parquet file made of column chunks of other Parquet files, copied byte for byte.

``grfguard run`` writes the log's own columns unchanged next to the monitor's. Instead
of encoding them again, :class:`Splicer` copies their column chunks (pages, already
encoded and compressed) from the input file, row group by row group, and lets a
pyarrow ``ParquetWriter`` write the other columns with the same row groups into the
same file; the footer then describes both: the schema, key-value metadata
(``ARROW:schema``, ``grfguard``), ``created_by`` and column orders of an empty file
written by pyarrow with the output schema (a reader sees the types and metadata pyarrow
would have written), each chunk's metadata with its page offsets moved to where the
chunk now lies.

Only plain files are copied from (:meth:`ParquetFooter.plain`): flat schema, no
encryption, no chunk in another file. Page indexes and bloom filters of copied chunks
are left out of the new footer (optional structures; grfguard writes neither).
"""

from __future__ import annotations

import contextlib
import errno
import os
import struct
from pathlib import Path
from typing import Any, BinaryIO

from grfguard.io._thrift import I16, I32, I64, LIST, STRUCT, decode_struct, encode_struct

__all__ = ["ParquetFooter", "Splicer", "same_leaf_type"]

_MAGIC = b"PAR1"
# FileMetaData / RowGroup / ColumnChunk / ColumnMetaData / SchemaElement field ids
_FM_SCHEMA, _FM_ROWS, _FM_RGS, _FM_ENC_ALGO, _FM_SIGN_KEY = 2, 3, 4, 8, 9
_RG_COLS, _RG_BYTES, _RG_ROWS, _RG_OFFSET, _RG_COMPRESSED, _RG_ORDINAL = 1, 2, 3, 5, 6, 7
_CC_PATH, _CC_OFFSET, _CC_META, _CC_CRYPTO, _CC_ENC_META = 1, 2, 3, 8, 9
_CC_PAGE_INDEX = (4, 5, 6, 7)  # offset index and column index offsets and lengths
_CM_UNCOMPRESSED, _CM_COMPRESSED, _CM_DATA, _CM_INDEX, _CM_DICT = 6, 7, 9, 10, 11
_CM_BLOOM = (14, 15)
_SE_NAME, _SE_CHILDREN = 4, 5
#: SchemaElement fields that define how a leaf's pages are read (type, length,
#: repetition, converted type, scale, precision, logical type): not name or field id.
_SE_TYPE_FIELDS = (1, 2, 3, 6, 7, 8, 10)


class ParquetFooter:
    """The parsed footer of a Parquet file (``path``) or of Parquet bytes (``data``)."""

    def __init__(self, path: str | Path | None = None, data: bytes | None = None) -> None:
        if data is None:
            with open(path, "rb") as fh:  # type: ignore[arg-type]
                size = fh.seek(0, os.SEEK_END)
                fh.seek(max(0, size - 8))
                tail = fh.read(8)
                n = _footer_length(tail, size)
                fh.seek(size - 8 - n)
                raw = fh.read(n)
        else:
            size = len(data)
            n = _footer_length(data[-8:], size)
            raw = data[size - 8 - n:size - 8]
        self.path, self.data = path, data
        self.body_end = size - 8 - n
        self.meta, _ = decode_struct(raw)

    def _get(self, fid: int, default: Any = None) -> Any:
        v = self.meta.get(fid)
        return default if v is None else v[1]

    @property
    def num_rows(self) -> int:
        return int(self._get(_FM_ROWS, 0))

    @property
    def schema(self) -> list[dict]:
        return self._get(_FM_SCHEMA, (STRUCT, []))[1]

    @property
    def leaves(self) -> list[str]:
        """Leaf column names in file order (the schema must be :meth:`plain`)."""
        return [el[_SE_NAME][1].decode("utf-8") for el in self.schema[1:]]

    @property
    def row_groups(self) -> list[dict]:
        return self._get(_FM_RGS, (STRUCT, []))[1]

    def rows_per_group(self) -> list[int]:
        return [int(rg[_RG_ROWS][1]) for rg in self.row_groups]

    def plain(self) -> bool:
        """Flat schema (one level of columns, unique names), no encryption, every column
        chunk in this file with its metadata, chunk ranges inside the file body."""
        sch = self.schema
        if (not sch or _FM_ENC_ALGO in self.meta or _FM_SIGN_KEY in self.meta
                or sch[0].get(_SE_CHILDREN, (I32, -1))[1] != len(sch) - 1
                or any(_SE_CHILDREN in el or _SE_NAME not in el for el in sch[1:])):
            return False
        names = self.leaves
        if len(set(names)) != len(names):
            return False
        for rg in self.row_groups:
            cols = rg[_RG_COLS][1][1]
            if len(cols) != len(names):
                return False
            for cc in cols:
                if (_CC_PATH in cc or _CC_CRYPTO in cc or _CC_ENC_META in cc
                        or _CC_META not in cc):
                    return False
                a, n = chunk_range(cc)
                if a < len(_MAGIC) or n <= 0 or a + n > self.body_end:
                    return False
        return True

    def element(self, name: str) -> dict:
        return self.schema[1 + self.leaves.index(name)]


def same_leaf_type(a: dict, b: dict) -> bool:
    """Two schema elements whose pages are read the same way."""
    return all(a.get(f) == b.get(f) for f in _SE_TYPE_FIELDS)


def chunk_range(cc: dict) -> tuple[int, int]:
    """``(start, length)`` of a column chunk's pages in its file (as Arrow computes it:
    the dictionary page first when there is one)."""
    cm = cc[_CC_META][1]
    start = int(cm[_CM_DATA][1])
    d = cm.get(_CM_DICT)
    if d is not None and 0 < d[1] < start:
        start = int(d[1])
    return start, int(cm[_CM_COMPRESSED][1])


def _footer_length(tail: bytes, size: int) -> int:
    if size < 12 or tail[4:] != _MAGIC:
        raise ValueError("not a Parquet file (no PAR1 at its end; encrypted footers are "
                         "not read here)")
    n = struct.unpack("<I", tail[:4])[0]
    if n + 12 > size:
        raise ValueError("Parquet footer longer than the file")
    return n


class Splicer:
    """Writes a Parquet file to ``dst`` (an unbuffered binary file at position 0) whose
    columns are copied from ``source`` (a parsed plain file, :meth:`copy_group`) or
    written by a pyarrow ``ParquetWriter`` into :attr:`sink` (a file-like object) with
    the source's row groups; :meth:`finish` writes the footer.

    For each row group: :meth:`copy_group` appends that group's copied chunks, then the
    caller writes the same group with the writer (one ``write_table``). The writer's
    bytes go to ``dst`` as they come (its own ``PAR1`` is left as 4 unused bytes); its
    footer is kept back (:meth:`finish` reads it)."""

    def __init__(self, dst: BinaryIO, source: ParquetFooter) -> None:
        self.dst, self.source = dst, source
        self.pos = dst.write(_MAGIC)
        self.sink = _Sink(self)
        self.copied: list[dict[str, dict]] = []  # per group: name -> moved chunk metadata
        self.shift: list[int] = []  # per group: file position - writer position
        self._index = {n: i for i, n in enumerate(source.leaves)}
        self._fh: Any = None

    def copy_group(self, g: int, names: list[str]) -> None:
        """Append the chunks of columns ``names`` of the source's row group ``g`` and
        start writing them to disk (:func:`start_writeback`): called before the group's
        other columns are computed, the disk works while the caller does."""
        if self._fh is None:
            self._fh = open(self.source.path, "rb", buffering=0)  # type: ignore[arg-type]
        out: dict[str, dict] = {}
        first = self.pos
        for name in names:
            cc = _copied(self.source.row_groups[g][_RG_COLS][1][1][self._index[name]])
            start, n = chunk_range(cc)
            _copy_range(self.dst, self._fh, start, n, self.source.path)
            _moved(cc, self.pos - start)
            out[name] = cc
            self.pos += n
        self.copied.append(out)
        self.shift.append(self.pos - self.sink.written)
        start_writeback(self.dst, first)

    def close(self) -> None:
        """Close the source file (if open); the footer may still be written."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def finish(self, template: ParquetFooter, names: list[str]) -> None:
        """The footer: ``template``'s schema and metadata (an empty file of the output
        schema, columns ``names`` in order), each row group's chunks (copied, or the
        writer's, moved to where they lie)."""
        self.close()
        side = ParquetFooter(data=_MAGIC + bytes(self.sink.held))
        rows = self.source.rows_per_group()
        if side.rows_per_group() != rows or len(self.copied) != len(rows):
            raise ValueError("the written row groups differ from the source's")
        if template.leaves != names:
            raise ValueError("the template's columns differ from the output's")
        where = {n: i for i, n in enumerate(side.leaves)}
        groups = []
        for g, nrows in enumerate(rows):
            cols = []
            for name in names:
                cc = self.copied[g].get(name)
                if cc is None:
                    cc = _copied(side.row_groups[g][_RG_COLS][1][1][where[name]])
                    _moved(cc, self.shift[g])
                cols.append(cc)
            groups.append(_row_group(cols, nrows, g))
        meta = {f: v for f, v in template.meta.items() if f not in (_FM_ROWS, _FM_RGS)}
        meta[_FM_ROWS] = (I64, sum(rows))
        meta[_FM_RGS] = (LIST, (STRUCT, groups))
        footer = encode_struct(dict(sorted(meta.items())))
        _write_all(self.dst, memoryview(footer + struct.pack("<I", len(footer)) + _MAGIC))


class _Sink:
    """pyarrow's output stream: its bytes appended to the splicer's file; after
    :meth:`hold` (before the writer closes) kept in :attr:`held` instead."""

    def __init__(self, sp: Splicer) -> None:
        self.sp, self.written, self.closed = sp, 0, False
        self.held: bytearray | None = None

    def hold(self) -> None:
        self.held = bytearray()

    def write(self, data: Any) -> int:
        view = memoryview(data).cast("B")
        if self.held is not None:
            self.held += view
        else:
            _write_all(self.sp.dst, view)
            self.sp.pos += len(view)
        self.written += len(view)
        return len(view)

    def tell(self) -> int:
        return self.written

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self.closed = True

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return False

    def readable(self) -> bool:
        return False


def _copied(cc: dict) -> dict:
    """A column chunk's metadata with its own top two levels (what :func:`_moved`
    changes); the values below are shared, never changed."""
    out = dict(cc)
    out[_CC_META] = (cc[_CC_META][0], dict(cc[_CC_META][1]))
    return out


def _moved(cc: dict, delta: int) -> None:
    """Column chunk metadata for its pages moved by ``delta`` bytes."""
    cm = cc[_CC_META][1]
    for f in (_CM_DATA, _CM_INDEX, _CM_DICT):
        if f in cm and cm[f][1] > 0:
            cm[f] = (cm[f][0], cm[f][1] + delta)
    for f in _CM_BLOOM:
        cm.pop(f, None)
    if cc.get(_CC_OFFSET, (I64, 0))[1] > 0:
        cc[_CC_OFFSET] = (I64, cc[_CC_OFFSET][1] + delta)
    for f in _CC_PAGE_INDEX:
        cc.pop(f, None)


def _row_group(cols: list[dict], nrows: int, g: int) -> dict:
    total = sum(int(cc[_CC_META][1][_CM_UNCOMPRESSED][1]) for cc in cols)
    ranges = [chunk_range(cc) for cc in cols]
    return {
        _RG_COLS: (LIST, (STRUCT, cols)),
        _RG_BYTES: (I64, total),
        _RG_ROWS: (I64, nrows),
        _RG_OFFSET: (I64, min(a for a, _ in ranges)),
        _RG_COMPRESSED: (I64, sum(n for _, n in ranges)),
        _RG_ORDINAL: (I16, g),
    }


def _copy_range(dst: BinaryIO, fh: Any, start: int, n: int, what: Any) -> None:
    """``n`` bytes of the file ``fh`` from ``start`` appended to ``dst``."""
    done = 0
    if hasattr(os, "copy_file_range"):
        try:
            while done < n:  # the kernel copies (no pass through Python's memory)
                k = os.copy_file_range(fh.fileno(), dst.fileno(), n - done, start + done)
                if k == 0:
                    break
                done += k
        except OSError as exc:
            if exc.errno not in _NO_COPY_RANGE:
                raise
    while done < n:
        block = os.pread(fh.fileno(), min(n - done, 1 << 24), start + done)
        if not block:
            raise OSError(errno.EIO, f"{what}: unexpected end of the file")
        _write_all(dst, memoryview(block))
        done += len(block)


#: copy_file_range errors that mean "not here" (another file system, old kernel, ...).
_NO_COPY_RANGE = {errno.EXDEV, errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP, errno.ENOTSUP,
                  errno.EPERM, errno.EBADF}


def start_writeback(dst: BinaryIO, start: int) -> None:
    """Ask the operating system to start writing ``dst``'s bytes from ``start`` to disk
    now, without waiting (Linux: ``posix_fadvise(DONTNEED)`` starts the write-back of
    dirty pages and leaves them cached until written). The final ``fsync`` of the output
    then waits only for what was written since; where the call does not exist nothing
    changes but the timing."""
    if hasattr(os, "posix_fadvise"):
        with contextlib.suppress(OSError, ValueError):
            os.posix_fadvise(dst.fileno(), start, 0, os.POSIX_FADV_DONTNEED)


def _write_all(dst: BinaryIO, view: memoryview) -> None:
    while view:
        view = view[dst.write(view):]
