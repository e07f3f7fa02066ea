"""``grfguard run``'s output written block by block from the compiled monitor's arrays.

:func:`write_run` is ``write_log(monitor.run(log), path)`` for a Parquet ``path`` without
the output DataFrame: the compiled loop (:func:`grfguard.kernels.monitor.monitor_run_packed`)
runs over blocks of :data:`BLOCK_ROWS` rows, each block's output columns go straight
from the kernel's arrays into Arrow arrays (text columns from their integer codes, no
Python string per row) and are written as one Parquet row group, then the buffers are
reused. The file holds the same columns, in the same order, with the same Arrow types,
values, nulls and metadata as the frame path (``tests/test_run_io.py`` compares the two
files column by column); only the row groups differ (one per block).

Given the Parquet file the log was read from (``source``), the log's unchanged columns
are instead copied from it column chunk by column chunk (:mod:`grfguard.io.splice`),
the monitor's columns encoded with the file's row groups (``tests/test_splice.py``
compares with the frame path); a simulated log's ground truth need not even be read
(:func:`copy_only_columns`).

Everything the frame path does per column is repeated here: a NaN of a float column is
written as a null (as :meth:`pyarrow.Table.from_pandas` does), the log's own columns
keep their types (non-float ones converted by ``from_pandas``), the output columns that
the log already carries replace them in place, and the metadata is the log's ``attrs``
plus ``monitor`` (:meth:`grfguard.pipeline.Monitor.describe`) under the key
``grfguard``, without pandas' own.
"""

from __future__ import annotations

import contextlib
import errno
import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["write_run", "BLOCK_ROWS"]

#: Rows per block (and per Parquet row group) of :func:`write_run`: the block's output
#: buffers (about 30 MB) are reused, so no fresh memory is page-faulted per block.
BLOCK_ROWS = 1 << 17
#: Rows per block when the output's row groups are the log file's (the log's columns
#: copied, :func:`_write_spliced`): the float columns are then copied out of the block
#: into the group's own buffer, so a small block buffer (10 MB instead of 80) is enough
#: and less fresh memory is page-faulted ("Memory reuse in grfguard run", BENCHMARKS.md).
SPLICE_BLOCK_ROWS = 1 << 14
#: Rows per call of the compiled loop inside a block: its row-major input and output
#: buffers stay in the cache while they are transposed into the column-major block.
_CHUNK = 1 << 12


def write_run(mon: Any, log: Any, path: str | Path, rows: int = BLOCK_ROWS,
              phase: Any = None, source: str | Path | None = None,
              partial: bool = False) -> int | None:
    """Run ``mon`` (a :class:`~grfguard.pipeline.Monitor`, reset first) over ``log`` and
    write the output to the Parquet file ``path`` (atomically, as
    :func:`~grfguard.io.logio.write_log`), block by block of ``rows`` rows (one row
    group each; with ``source``, the file's row groups and blocks of at most
    :data:`SPLICE_BLOCK_ROWS`).

    ``phase("kernel_setup")`` (optional) is called once the compiled loop is loaded (from
    numba's on-disk cache, or compiled), before the first row runs.

    ``source``: the Parquet file ``log`` was read from, unchanged (every row, columns
    as read: :func:`grfguard.io.logio.read_log` with the default ``time_order``). The
    log's columns that the output keeps as they are (not replaced by the monitor's;
    numbers and booleans without NaN or null, of the file's type) are then copied from
    it byte for byte instead of being encoded again (:func:`_write_spliced`); the file
    read back is the same. A file that does not qualify is ignored. ``partial``: ``log``
    was read without some of the file's columns (:func:`copy_only_columns`), which are
    then copied too, in their place; if they cannot be, nothing is written (None).

    Returns:
        The number of rows written, or None (nothing written) when the monitor does not
        run compiled (or ``partial`` and the columns cannot be copied): then
        ``write_log(mon.run(log), path)`` is the way (with every column of the log).

    Raises:
        LogFormatError: ``time`` or a ``force_<s>`` column is missing.
        OutputError: ``path`` could not be written (nothing is changed).
    """
    import pyarrow as pa

    from grfguard.io.logio import METADATA_KEY, to_jsonable

    k = mon._batch_kernel(log)
    if k is None:
        return None
    from grfguard import compiled_monitor as km

    # load the loop now (a call over no rows): the blocks then time only the rows
    km.monitor_run_packed(np.empty((0, len(k.in_cols))), np.empty((0, len(k.out_cols))),
                          np.empty((0, km.N_EX)), k.F, k.I)
    if phase is not None:
        phase("kernel_setup")
    n = len(log)
    meta = json.dumps(to_jsonable({**log.attrs, "monitor": mon.describe()}), sort_keys=True)
    metadata = {METADATA_KEY: meta.encode()}
    src = _splice_source(source, log, km, k) if source is not None and n else None
    if src is None and partial:
        return None
    try:
        if src is not None:
            footer, types, columns = src
            rows = min(rows, SPLICE_BLOCK_ROWS)
            blocks = _Blocks(mon, k, log, max(1, min(rows, n)), raw=set(types),
                             columns=columns)
            try:
                _write_spliced(blocks, footer, path, metadata, rows, types)
            except _SpliceFailed as exc:  # nothing written: the caller encodes it all
                from grfguard.errors import GrfguardWarning

                warnings.warn(GrfguardWarning(
                    f"copying the log's columns from {source} into {path} failed "
                    f"({exc}); every column is encoded again instead"), stacklevel=2)
                return None
        else:
            _write_blocks(_Blocks(mon, k, log, max(1, min(rows, n))), path, metadata, rows)
    except pa.ArrowException as exc:  # pragma: no cover - pyarrow wraps some OS errors
        raise OSError(errno.EIO, str(exc)) from None
    return n


def _write_blocks(blocks: _Blocks, path: str | Path, metadata: dict, rows: int) -> None:
    """The output block by block, one row group per block."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from grfguard.io.logio import parquet_options
    from grfguard.io.safe import atomic_path

    n = len(blocks.log)
    first = blocks.block(0, min(n, rows))
    schema = pa.schema([pa.field(c, a.type) for c, a in first.items()], metadata=metadata)
    opts = parquet_options(schema)
    opts.pop("row_group_size")
    with atomic_path(Path(path), what="log") as tmp:
        with pq.ParquetWriter(tmp, schema, **opts) as writer:
            writer.write_table(_table(first, schema))
            del first
            for a in range(rows, n, rows):
                writer.write_table(_table(blocks.block(a, min(n, a + rows)), schema))


def _splice_source(source: str | Path, log: Any, km: Any, k: Any
                   ) -> tuple[Any, dict[str, Any], list[str]] | None:
    """What to copy from ``source``: its parsed footer, the columns to copy with their
    Arrow types, and the log's columns in the file's order (those ``log`` was read
    without included); None when nothing is copied (not a plain Parquet file, other
    rows, no such column; a column ``log`` lacks that cannot be copied)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from grfguard.io.splice import ParquetFooter, same_leaf_type

    try:
        footer = ParquetFooter(source)
        ok = footer.plain() and footer.num_rows == len(log) and all(footer.rows_per_group())
        file_types = {f.name: f.type for f in pq.read_schema(source)} if ok else {}
    except (OSError, ValueError, pa.ArrowException):
        return None
    if not ok:
        return None
    log = log.copy(deep=False)
    log.attrs = {}  # column access would deep-copy the metadata every time
    new = {name for name, _, _ in km.output_rows(k)}
    leaves = footer.leaves
    missing = [c for c in leaves if c not in log.columns]
    if missing and ([c for c in leaves if c in log.columns] != list(log.columns)
                    or any(c in new or file_types.get(c) != pa.float64() for c in missing)):
        return None
    types = {c: pa.from_numpy_dtype(log[c].dtype) for c in log.columns
             if c in file_types and c not in new and _copyable(log[c])}
    types.update((c, pa.float64()) for c in missing)
    if not types:
        return None
    template = _template(list(types), types, {})  # the pages must read as the output says
    same = {c for c in types if same_leaf_type(footer.element(c), template.element(c))}
    if any(c not in same for c in missing):
        return None
    return footer, {c: t for c, t in types.items() if c in same}, (leaves if missing
                                                                    else list(log.columns))


def copy_only_columns(path: str | Path) -> list[str]:
    """Columns of the Parquet log ``path`` that ``grfguard run`` need not read: the
    ground truth of a simulated log (``true_*``: never an input of the monitor) as
    64-bit floats in a plain Parquet file written by grfguard (whose writers store no
    NaN, only nulls: copied unread, they read back as the frame path writes them), for
    :func:`write_run` to copy (``partial=True``). Empty for anything else (a described
    robot's log, another writer's file, no such column)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from grfguard.io.logio import METADATA_KEY
    from grfguard.io.splice import ParquetFooter

    try:
        if not ParquetFooter(path).plain():
            return []
        schema = pq.read_schema(path)
        meta = json.loads((schema.metadata or {}).get(METADATA_KEY, b"null"))
    except (OSError, ValueError, pa.ArrowException):
        return []
    if not isinstance(meta, dict) or ("robot_name" in meta and "sensing" in meta):
        return []
    return [f.name for f in schema if f.name.startswith("true_") and f.type == pa.float64()]


def restore_columns(log: Any, path: str | Path, names: list[str]) -> Any:
    """``log`` (read from ``path`` without the columns ``names``) with them read and put
    back in the file's order (metadata kept); a DataFrame."""
    import pandas as pd
    import pyarrow.parquet as pq

    from grfguard.io.columns import as_frame
    from grfguard.io.logio import _read_parquet
    from grfguard.io.schema import TIME

    log = as_frame(log)
    names = [c for c in names if c not in log.columns]
    if not names:
        return log
    extra = _read_parquet(Path(path), names, copy=False)[0].drop(columns=[TIME])
    file_order = pq.read_schema(path).names
    out = pd.concat([log, extra], axis=1)
    out = out[[c for c in file_order if c in out.columns]
              + [c for c in out.columns if c not in file_order]]
    out.attrs = dict(log.attrs)
    return out


def _copyable(col: Any) -> bool:
    """A log column written as the file holds it: numpy numbers or booleans (a column
    read with nulls is float or object) and, for floats, no NaN (written as null)."""
    dtype = getattr(col, "dtype", None)
    if not isinstance(dtype, np.dtype) or dtype.kind not in "biuf":
        return False
    if dtype.kind == "f":
        a = np.asarray(col)
        return not (a.size and np.isnan(a.min()))
    return True


def _write_spliced(blocks: _Blocks, footer: Any, path: str | Path, metadata: dict,
                   rows: int, types: dict[str, Any]) -> None:
    """The output with the columns ``blocks.raw`` copied from the file of ``footer`` and
    the others encoded by pyarrow, row group by row group of that file (each group's
    blocks held until it is written): :class:`grfguard.io.splice.Splicer`."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from grfguard.io.logio import parquet_options
    from grfguard.io.safe import atomic_path
    from grfguard.io.splice import Splicer, start_writeback

    raw = [c for c in blocks.order if c in blocks.raw]
    blocks.dictionary_text = True  # stored as dictionary pages, typed large_string below
    with atomic_path(Path(path), what="log") as tmp, open(tmp, "wb", buffering=0) as fh:
        sp = Splicer(fh, footer)
        writer = schema = None
        try:
            a = 0
            for g, m in enumerate(footer.rows_per_group()):
                # the group's copied chunks first: the disk writes them while the
                # monitor runs (see Splicer.copy_group), not while the output is synced
                sp.copy_group(g, raw)
                keep = np.empty((blocks.n_float, m))  # the group's float columns, held
                parts = [blocks.block(s, min(a + m, s + rows), keep=keep[:, s - a:])
                         for s in range(a, a + m, rows)]
                if writer is None:
                    schema = pa.schema([pa.field(c, x.type) for c, x in parts[0].items()])
                    opts = parquet_options(schema)
                    opts.pop("row_group_size")
                    writer = pq.ParquetWriter(sp.sink, schema, **opts)
                table = pa.Table.from_arrays(
                    [pa.chunked_array([p[c] for p in parts], f.type)
                     for c, f in zip(schema.names, schema, strict=True)], schema=schema)
                del parts
                written = sp.pos
                writer.write_table(table, row_group_size=m)
                start_writeback(fh, written)
                del table
                a += m
            sp.sink.hold()
            writer.close()
        finally:  # (on failure: the writer closed into memory, not into the dropped file)
            sp.close()
            if writer is not None and sp.sink.held is None:
                sp.sink.hold()
                with contextlib.suppress(Exception):
                    writer.close()
        types = {**types, **{f.name: (f.type.value_type if pa.types.is_dictionary(f.type)
                                      else f.type) for f in schema}}
        try:
            sp.finish(_template(blocks.order, types, metadata), blocks.order)
        except ValueError as exc:
            raise _SpliceFailed(str(exc)) from None
        fh.flush()
        _check_spliced(tmp, len(blocks.log), blocks.order, raw)


class _SpliceFailed(Exception):
    """The spliced output could not be composed or failed its read-back check."""


def _check_spliced(path: Path, n: int, order: list[str], raw: list[str]) -> None:
    """Read the spliced file ``path`` back with pyarrow before it replaces the output:
    its footer, ``n`` rows, the columns ``order``, and the first and the last copied
    column (of ``raw``, in file order: chunks are placed one after the other, so a
    misplaced one moves the last) of its first and last row group decoded: a chunk
    copied to the wrong place fails here, not in the user's next read (about 10 ms on
    a 10-minute log; decoding every copied column would take 0.5 s). Raises
    :class:`_SpliceFailed`."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        with open(path, "rb") as fh:
            pf = pq.ParquetFile(fh)
            md = pf.metadata
            if md.num_rows != n or pf.schema_arrow.names != order:
                raise _SpliceFailed(f"read back: {md.num_rows} rows of "
                                    f"{len(pf.schema_arrow.names)} columns, expected {n} "
                                    f"of {len(order)}")
            for g in sorted({0, md.num_row_groups - 1}) if raw else ():
                got = pf.read_row_group(g, columns=sorted({raw[0], raw[-1]}),
                                        use_threads=False).num_rows
                if got != md.row_group(g).num_rows:
                    raise _SpliceFailed(f"read back: row group {g} has {got} rows")
    except (OSError, ValueError, pa.ArrowException) as exc:
        raise _SpliceFailed(f"read back: {exc}") from None


def _template(order: list[str], types: dict[str, Any], metadata: dict) -> Any:
    """The parsed footer of an empty Parquet file with the columns ``order`` of the
    Arrow ``types`` and the schema ``metadata``, written with the output's options."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from grfguard.io.logio import parquet_options
    from grfguard.io.splice import ParquetFooter

    full = pa.schema([pa.field(c, types[c]) for c in order], metadata=metadata)
    sink = pa.BufferOutputStream()
    opts = parquet_options(full)
    opts.pop("row_group_size")
    pq.ParquetWriter(sink, full, **opts).close()
    return ParquetFooter(data=sink.getvalue().to_pybytes())


def _table(cols: dict[str, Any], schema: Any) -> Any:
    """The block as a table of ``schema`` (its types checked, never cast)."""
    import pyarrow as pa

    return pa.Table.from_arrays(list(cols.values()), schema=schema)


def _arrow(values: Any) -> Any:
    """A pandas column (or array) as the Arrow array ``from_pandas`` makes of it: numpy
    float64, integers and booleans without a copy of the values (NaN becomes null),
    anything else converted by pyarrow as ``from_pandas`` converts it."""
    import pyarrow as pa

    from grfguard.io.arrowcols import float_array, number_array

    if isinstance(values, pa.Array):  # (built from codes: grfguard.io.codes.codes_to_arrow)
        return values
    dtype = getattr(values, "dtype", None)
    if isinstance(dtype, np.dtype) and dtype.kind in "biuf":
        a = np.asarray(values)
        if dtype == np.float64:
            return float_array(a)
        if dtype.kind in "biu":
            return number_array(a)
    return pa.array(values, from_pandas=True)


class _Blocks:
    """The compiled monitor over ``log`` block by block (in row order: the monitor's state
    carries over); :meth:`block` returns the output row group of rows ``a:b`` as named
    Arrow arrays (the log's columns, then the monitor's)."""

    def __init__(self, mon: Any, k: Any, log: Any, rows: int, raw: set | None = None,
                 columns: list[str] | None = None) -> None:
        from grfguard import compiled_monitor as km

        log = log.copy(deep=False)
        log.attrs = {}  # column access would deep-copy the metadata every time
        self.km, self.mon, self.k, self.log = km, mon, k, log
        self.new = [name for name, _, _ in km.output_rows(k)]
        self.src = [(km._column(log, c) if c in log.columns else None) for c in k.in_cols]
        # the log's own columns (those the monitor does not replace), converted once
        self.raw = raw or set()  # (columns the caller writes itself: not in the blocks)
        self.keep = {c: _arrow(log[c]) for c in log.columns
                     if c not in self.new and c not in self.raw}
        cols = list(log.columns) if columns is None else columns  # (the file's, if given)
        self.order = [*cols, *(c for c in self.new if c not in cols)]
        self.bufs = km.chunk_buffers(k, min(_CHUNK, rows))
        self.Y = np.empty((len(k.out_cols), rows))  # each output column contiguous
        self.n_float = sum(typ == "float" for _, typ, _ in km.output_rows(k))
        self.EX = np.empty((rows, km.N_EX))
        #: Fault kinds and system states as Arrow dictionary arrays over the fixed names
        #: (for a writer that stores ``large_string`` as their type: :func:`_write_spliced`)
        self.dictionary_text = False

    def block(self, a: int, b: int, keep: np.ndarray | None = None) -> dict[str, Any]:
        """Rows ``a:b``. The float columns are views of the reused block buffer, or
        with ``keep`` (``n_float`` rows of at least ``b - a`` columns) of copies into
        ``keep``'s rows (they then outlive the next block)."""
        from grfguard.io.arrowcols import bool_array, float_array
        from grfguard.io.codes import codes_to_arrow, codes_to_dictionary
        from grfguard.io.columns import as_frame

        km, k = self.km, self.k
        text = codes_to_dictionary if self.dictionary_text else codes_to_arrow
        m = b - a
        Y = self.Y[:, :m].T  # rows x columns, each column contiguous
        EX = self.EX[:m]
        km.run_rows(k, self.src, a, b, self.bufs, Y, EX)
        new: dict[str, Any] = {}
        i = 0
        for name, typ, j in km.output_rows(k):
            if typ == "float":  # (the other types are converted into new memory)
                if keep is not None:
                    keep[i, :m] = Y[:, j]
                    i += 1
                new[name] = float_array(Y[:, j] if keep is None else keep[i - 1, :m])
            elif typ == "flag":
                new[name] = bool_array(Y[:, j] != 0.0)
            elif typ == "kind":
                new[name] = text(Y[:, j], km.KIND_NAMES)
            elif typ == "mismatch_reason":
                new[name] = km._mismatch_reasons(Y[:, j:], k.vib_config,
                                                 to=codes_to_arrow)
            elif typ == "state":
                new[name] = text(Y[:, j], km.SYSTEM_STATES)
            else:  # "reason" (a row with its own text: the input guard's, on a frame)
                part = as_frame(self.log.iloc[a:b]) if (EX[:, 0] != 0.0).any() else None
                new[name] = _arrow(km._reasons(self.mon, part, Y[:, j].astype(np.int64),
                                               self.src[0][a:b], EX, to=codes_to_arrow))
        return {c: (new[c] if c in new else self.keep[c].slice(a, m)) for c in self.order
                if c not in self.raw}
