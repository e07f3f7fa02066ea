"""Reading and writing logs: Parquet with JSON metadata, CSV on input and output.

A log is a :class:`pandas.DataFrame` with one row per sample (the contract in
:mod:`grfguard.io.schema`) and its metadata (robot, gait, seed, version, ...) in
``df.attrs``. In Parquet the metadata is stored as JSON under the schema key
``grfguard``; in CSV as a first comment line ``# grfguard: {...}``.
"""

from __future__ import annotations

import dataclasses
import errno
import json
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from grfguard._lazy import lazy_module
from grfguard.errors import GrfguardWarning, LogFormatError
from grfguard.io.safe import atomic_open, atomic_path
from grfguard.io.schema import REQUIRED_INPUT_COLUMNS, TIME

pd = lazy_module("pandas")  # (imported when first used: not by `grfguard run`)

__all__ = [
    "read_log",
    "write_log",
    "load_log",
    "validate_log",
    "find_time_gaps",
    "to_jsonable",
    "METADATA_KEY",
    "SEGMENT",
    "TIME_ORDERS",
]

#: Parquet schema metadata key holding the JSON metadata.
METADATA_KEY = b"grfguard"
_CSV_PREFIX = "# grfguard:"
#: Key of the row count in a CSV's metadata line (removed on read).
_CSV_ROWS_KEY = "_rows"


def to_jsonable(value: Any) -> Any:
    """``value`` as plain JSON data: mappings, sequences, numpy scalars and arrays and
    dataclasses converted; anything else unknown becomes its ``str``."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return to_jsonable(dataclasses.asdict(value))
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return str(value)


def write_log(df: pd.DataFrame, path: str | Path) -> Path:
    """Write ``df`` (with ``df.attrs`` as metadata) to ``path``, atomically.

    The file is written next to ``path`` under a temporary name, flushed to disk and then
    renamed: an existing ``path`` is either replaced by the complete new log or left
    untouched (disk full, file-size limit, any error), never truncated.

    Args:
        df: The log.
        path: Destination; ``.csv`` writes CSV, anything else Parquet (zstd).

    Returns:
        The path written.

    Raises:
        OutputError: ``path`` is a directory or could not be written (nothing is changed).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    meta_dict = to_jsonable(dict(df.attrs))
    if path.suffix.lower() == ".csv":
        # the row count lets read_log notice a file cut at a line boundary
        meta = json.dumps({**meta_dict, _CSV_ROWS_KEY: len(df)}, sort_keys=True)
        with atomic_open(path, "w", what="log", newline="", encoding="utf-8") as fh:
            fh.write(f"{_CSV_PREFIX} {meta}\n")
            df.to_csv(fh, index=False, float_format="%.17g")
        return path
    meta = json.dumps(meta_dict, sort_keys=True)
    plain = df.copy(deep=False)
    plain.attrs = {}  # metadata goes in our own key below, not through pandas
    table = pa.Table.from_pandas(plain, preserve_index=False)
    schema_meta = dict(table.schema.metadata or {})
    schema_meta.pop(b"pandas", None)  # attrs live in our own key, not pandas' blob
    schema_meta[METADATA_KEY] = meta.encode()
    table = table.replace_schema_metadata(schema_meta)
    with atomic_path(path, what="log") as tmp:
        try:
            pq.write_table(table, tmp, **parquet_options(table.schema))
        except pa.ArrowException as exc:  # pragma: no cover - pyarrow wraps some OS errors
            raise OSError(errno.EIO, str(exc)) from None
    return path


#: Parquet compression of written logs: zstd at its fast level -1. LZ4 (Parquet's LZ4_RAW
#: codec) writes a 10-minute output about 0.4 s faster than zstd level 1 for 2 % more
#: bytes (BENCHMARKS.md "grfguard run end to end (issue 11)"), but LZ4_RAW is a 2021
#: addition to the format that older readers (Spark < 3.3, older DuckDB and fastparquet)
#: cannot open: logs are for any tool. A zstd level is the writer's choice only (the
#: frames are ordinary zstd, read by every zstd decoder): level -1 writes the 10-minute
#: output about 0.1-0.15 s faster than level 1 (byte-stream-split floats: the same size
#: to 0.1 %, the same read time).
PARQUET_COMPRESSION = "zstd"
PARQUET_COMPRESSION_LEVEL = -1
#: Rows per Parquet row group (a 10-minute 1 kHz log is one group).
PARQUET_ROW_GROUP = 1 << 20


def parquet_options(schema: Any) -> dict[str, Any]:
    """``pyarrow.parquet.write_table`` options of grfguard logs for a table ``schema``.

    Floating-point columns are written with the BYTE_STREAM_SPLIT encoding (the bytes of
    each value grouped by significance: noisy sensor data compresses about 20 % better and
    several times faster than with dictionary tries) and no dictionary; text columns
    (``kind_<s>``, ``system_state``, reasons) are written plain: zstd shrinks their few
    repeated words almost as well as a dictionary (a 10-minute output's 11 text columns:
    43 kB instead of 38 kB) in a third less writing and a fifth less reading time;
    every other column (booleans, integer flags) is dictionary encoded. Min/max
    statistics are written for ``time`` only (for readers that select a time range; on
    every column they cost about a tenth of the writing time). Values and types read
    back unchanged.
    """
    import pyarrow as pa

    floats = [f.name for f in schema if pa.types.is_floating(f.type)]
    others = [f.name for f in schema if not (pa.types.is_floating(f.type)
                                             or pa.types.is_string(f.type)
                                             or pa.types.is_large_string(f.type))]
    return {
        "compression": PARQUET_COMPRESSION,
        "compression_level": PARQUET_COMPRESSION_LEVEL,
        "use_dictionary": others,
        "use_byte_stream_split": floats or False,
        "write_statistics": [TIME] if TIME in schema.names else False,
        "row_group_size": PARQUET_ROW_GROUP,
    }


#: Policies for timestamps that do not increase (see :func:`read_log`).
TIME_ORDERS = ("strict", "drop", "split")


def read_log(
    path: str | Path,
    required: Iterable[str] | None = None,
    columns: Iterable[str] | None = None,
    time_order: str = "strict",
    gap_s: float | None = None,
    copy: bool = True,
    frame: bool = True,
) -> pd.DataFrame:
    """Read a Parquet or CSV log and validate it.

    Timestamps are checked on load. Rows whose time does not increase (duplicated,
    constant or backwards time) are an error by default naming the row; ``time_order``
    chooses otherwise:

    * ``"strict"``: raise :class:`LogFormatError` (default);
    * ``"drop"``: drop every row whose time is not after all earlier rows (warning with
      the rows dropped);
    * ``"split"``: keep every row and add an integer ``segment`` column that starts a new
      segment at each such row; time increases within each segment (``grfguard run
      --time-order split`` runs each segment on its own).

    Gaps (a step longer than ``gap_s``, by default ``max(5 x median step, 20 ms)``) are
    kept; each one gives a :class:`~grfguard.errors.GrfguardWarning` naming its row and
    times, and the list ``[row, t_before, t_after]`` is stored in ``df.attrs["time_gaps"]``.

    Args:
        path: A ``.parquet`` or ``.csv`` file.
        required: Columns that must be present (default: only ``time``).
        columns: Read only these columns (Parquet only; ``time`` is always read).
        time_order: ``strict``, ``drop`` or ``split`` (see above).
        gap_s: Smallest time step reported as a gap [s] (default: see above).
        copy: False reads a Parquet log without copying its numeric columns: they are
            read-only numpy views of the file's Arrow buffers (for readers that never
            write into the frame, such as ``grfguard run``; about half the memory and
            time). True (default) gives ordinary writable columns.
        frame: False (with ``copy=False``) returns a Parquet log whose columns are all
            numbers or booleans without nulls as a
            :class:`~grfguard.io.columns.LogColumns` (numpy columns, no pandas import:
            ``grfguard run``); any other log is a DataFrame as always.

    Returns:
        The log, metadata in ``.attrs``.

    Raises:
        LogFormatError: The file is missing, unreadable, truncated, or does not follow the
            contract.
    """
    path = Path(path)
    if time_order not in TIME_ORDERS:
        raise LogFormatError(
            f"time_order must be one of {list(TIME_ORDERS)}, got {time_order!r}"
        )
    if not path.exists():
        raise LogFormatError(f"log file {path} does not exist")
    if not path.is_file():
        raise LogFormatError(f"log file {path} is not a regular file (a directory?); give a "
                             ".parquet or .csv log")
    if path.suffix.lower() == ".csv":
        df, meta = _read_csv(path)
    else:
        df, meta = _read_parquet(path, columns, copy, frame)
    _check_metadata(meta, path)
    df.attrs.update(meta)
    df.attrs.setdefault("source", str(path))
    if TIME in df.columns and time_order != "strict" and len(df):
        from grfguard.io.columns import as_frame

        df = _repair_time(as_frame(df), time_order, str(path))
    validate_log(df, required=required, where=str(path))
    gaps = find_time_gaps(df, gap_s)
    if gaps:
        df.attrs["time_gaps"] = gaps
        _warn_gaps(gaps, str(path))
    return df


def _read_parquet(path: Path, columns: Iterable[str] | None, copy: bool = True,
                  frame: bool = True) -> tuple[pd.DataFrame, Any]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        with pq.ParquetFile(path, memory_map=PARQUET_READ_MMAP) as pf:
            raw = (pf.schema_arrow.metadata or {}).get(METADATA_KEY)
            cols = None if columns is None else list(dict.fromkeys([TIME, *columns]))
            if cols is not None:
                names = set(pf.schema_arrow.names)
                missing = [c for c in cols if c not in names and c != TIME]
                if missing:
                    raise KeyError(missing[0])
                cols = [c for c in cols if c in names]
            table = _read_columns(pf, cols)
        df = _table_to_frame(table, copy, frame)
    except KeyError as exc:
        raise LogFormatError(f"{path}: requested column {exc} is not in the file") from None
    except (pa.ArrowException, OSError, ValueError, TypeError, IndexError) as exc:
        raise LogFormatError(
            f"{path} is not a readable Parquet file ({_short(exc)}); it may be truncated or "
            "not Parquet: re-create it, or convert your data to the log contract "
            "(a .csv file is read as CSV)"
        ) from None
    try:
        meta = json.loads(raw) if raw else {}
    except ValueError as exc:
        raise LogFormatError(
            f"{path}: the grfguard metadata (Parquet key 'grfguard') is not valid JSON "
            f"({_short(exc)}); rewrite the file with grfguard.io.logio.write_log"
        ) from None
    return df, meta


#: Decode Parquet columns on several threads (False: the decoding is cheap once floats
#: are byte-stream split, and threads cost CPU time on a busy or one-core machine).
PARQUET_READ_THREADS = False


#: Read Parquet files through a memory map: the compressed pages are decoded straight
#: from the page cache, without first copying the file into the reader's buffers (about
#: 0.05 s of CPU on a 10-minute log). The decoded columns are fresh memory, never views
#: of the map, and the file is unmapped once read.
PARQUET_READ_MMAP = True


#: Columns decoded per ``ParquetFile.read`` call: the reader's scratch memory
#: (compressed and byte-split copies of the columns) stays a few columns large instead
#: of twice the log (a 10-minute log: 640 MB peak instead of 910 MB).
PARQUET_READ_COLUMNS = 16


def _read_columns(pf: Any, cols: list[str] | None) -> Any:
    """The columns ``cols`` (None: all) of the Parquet file ``pf`` as one Arrow table,
    decoded a few columns at a time; unused reader memory goes back to the system
    (unless :func:`grfguard._memory.keep_freed_memory` is in effect)."""
    import pyarrow as pa

    schema = pf.schema_arrow
    names = list(schema.names) if cols is None else cols
    if len(set(names)) != len(names) or len(names) <= PARQUET_READ_COLUMNS:
        table = pf.read(columns=cols, use_threads=PARQUET_READ_THREADS)
    else:
        k = PARQUET_READ_COLUMNS
        arrays = []
        for i in range(0, len(names), k):
            arrays.extend(pf.read(columns=names[i:i + k], use_threads=PARQUET_READ_THREADS)
                          .columns)
        fields = [schema.field(n) for n in names]
        table = pa.Table.from_arrays(arrays, schema=pa.schema(fields, schema.metadata))
    from grfguard._memory import freed_memory_kept

    if not freed_memory_kept():  # (else the memory is reused by the next phase)
        pa.default_memory_pool().release_unused()
    return table


def _table_to_frame(table: Any, copy: bool, frame: bool = True) -> pd.DataFrame:
    """``table.to_pandas()``; with ``copy=False`` the numeric and boolean columns without
    nulls are read-only numpy views of the Arrow buffers (the same dtypes and values,
    no copy), the other columns converted as ``to_pandas`` does; with ``frame=False``
    too and no other column, a :class:`~grfguard.io.columns.LogColumns` of them."""
    import pyarrow as pa

    if copy or table.schema.pandas_metadata is not None or not table.num_columns:
        return table.to_pandas()
    if not frame and len(set(table.column_names)) == table.num_columns:
        from grfguard.io.arrowcols import numpy_column
        from grfguard.io.columns import LogColumns

        cols = {n: numpy_column(c) for n, c in zip(table.column_names, table.columns,
                                                       strict=True)}
        if all(a is not None for a in cols.values()):  # (no pandas import: pyarrow's
            return LogColumns(cols)                    # to_numpy would make one)
    data: dict[str, Any] = {}
    for name, col in zip(table.column_names, table.columns, strict=True):
        t = col.type
        plain = (pa.types.is_floating(t) or pa.types.is_integer(t)) and col.null_count == 0
        if plain and col.num_chunks == 1:
            data[name] = col.chunk(0).to_numpy(zero_copy_only=True)
        elif plain or (pa.types.is_boolean(t) and col.null_count == 0):
            data[name] = col.to_numpy()  # several chunks, or bit-packed booleans: a copy
        else:  # nulls, strings, timestamps, ...: pandas' own conversion
            data[name] = col.to_pandas()
    if len(data) != table.num_columns:  # duplicated names: pandas decides
        return table.to_pandas()
    return pd.DataFrame(data, copy=False)


def _short(exc: BaseException, n: int = 160) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= n else text[: n - 3] + "..."


def _check_metadata(meta: Any, path: Path) -> None:
    """The metadata must be a JSON object; a ``robot`` entry must describe a valid robot."""
    if not isinstance(meta, dict):
        raise LogFormatError(
            f"{path}: the grfguard metadata must be a JSON object {{...}}, got "
            f"{type(meta).__name__} {_short(repr(meta), 60)}; fix or remove the metadata "
            "(the first '# grfguard:' line of a CSV, the 'grfguard' key of a Parquet file)"
        )
    robot = meta.get("robot")
    if robot is None or isinstance(robot, str):
        return
    if isinstance(robot, dict) and ("model" in robot or "sensing" in meta):
        return  # a described robot (Talos, G1, ...): checked by io.robot_schema
    if not isinstance(robot, dict):
        raise LogFormatError(
            f"{path}: metadata key 'robot' must be a JSON object with the robot "
            f"parameters, got {type(robot).__name__} {_short(repr(robot), 60)}; remove it "
            "and pass the robot with --robot ROBOT.toml"
        )
    if "model" in robot:  # a described robot (Talos, G1, ...): checked by io.robot_schema
        return
    from grfguard.errors import ConfigError
    from grfguard.model.robot import RobotConfig

    try:
        RobotConfig.from_dict(dict(robot))
    except (ConfigError, TypeError) as exc:
        raise LogFormatError(
            f"{path}: metadata key 'robot' is not a valid robot description ({exc}); "
            "remove it and pass the robot with --robot ROBOT.toml"
        ) from None


def _read_csv(path: Path) -> tuple[pd.DataFrame, Any]:
    meta: Any = {}
    try:
        with path.open("rb") as fh:
            first = fh.readline().decode("utf-8")
    except UnicodeDecodeError:
        raise LogFormatError(
            f"{path} is not a text CSV file (line 1 is not UTF-8); is it a Parquet file "
            "with a .csv name? Rename it to .parquet, or export the data as CSV"
        ) from None
    skip = 0
    if first.startswith(_CSV_PREFIX):
        skip = 1
        try:
            meta = json.loads(first[len(_CSV_PREFIX) :])
        except ValueError as exc:
            raise LogFormatError(
                f"{path}: line 1 metadata is not valid JSON ({_short(exc)}); fix the "
                "'# grfguard: {...}' line or delete it"
            ) from None
    try:
        df = pd.read_csv(path, skiprows=skip, encoding="utf-8")
    except pd.errors.EmptyDataError:
        raise LogFormatError(f"{path} has no CSV header or data") from None
    except (ValueError, UnicodeDecodeError, OverflowError, IndexError, TypeError) as exc:
        raise LogFormatError(f"{path} is not a readable CSV log ({_short(exc)})") from None
    rows = meta.pop(_CSV_ROWS_KEY, None) if isinstance(meta, dict) else None
    _check_csv_complete(path, df, rows, written_by_us=skip == 1)
    return df, meta


def _check_csv_complete(path: Path, df: pd.DataFrame, rows: Any, written_by_us: bool) -> None:
    """Refuse a CSV that was cut: a last line with fewer fields than the header, a missing
    final newline in a grfguard CSV, or fewer rows than its metadata says."""
    fix = "the file looks truncated (an interrupted copy or a full disk?); re-export it"
    ncols = len(df.columns)
    size = path.stat().st_size
    with path.open("rb") as fh:
        fh.seek(max(0, size - 65536))
        tail = fh.read()
    if not tail:
        return
    ends_with_newline = tail.endswith((b"\n", b"\r"))
    lines = tail.rstrip(b"\r\n").splitlines()
    last = lines[-1] if lines else b""
    if len(df) and ncols > 1:
        import csv

        try:
            fields = next(csv.reader([last.decode("utf-8", "replace")]))
        except (csv.Error, StopIteration):
            fields = []
        if len(fields) < ncols:
            raise LogFormatError(
                f"{path}: the last row (row {len(df) - 1}) has {len(fields)} of {ncols} "
                f"fields; {fix}"
            )
    if ncols > 1:
        _check_csv_field_counts(path, ncols, len(df), skip=1 if written_by_us else 0, fix=fix)
    if written_by_us and not ends_with_newline:
        raise LogFormatError(f"{path}: the last row (row {len(df) - 1}) is cut short; {fix}")
    if isinstance(rows, int) and not isinstance(rows, bool) and rows != len(df):
        raise LogFormatError(
            f"{path}: has {len(df)} rows but its metadata says {rows}; {fix}"
        )


def _check_csv_field_counts(path: Path, ncols: int, nrows: int, skip: int, fix: str) -> None:
    """Every row must have as many fields as the header (pandas pads a short row with NaN).

    Counts the separators of the whole file in large chunks; only when the count is off
    does it look for the first bad row. Files with quoted fields are left to pandas."""
    commas = 0
    quoted = False
    with path.open("rb") as fh:
        for _ in range(skip):
            fh.readline()
        for chunk in iter(lambda: fh.read(1 << 24), b""):
            commas += chunk.count(b",")
            quoted = quoted or b'"' in chunk
    if quoted or commas == (ncols - 1) * (nrows + 1):
        return
    with path.open("rb") as fh:
        for _ in range(skip + 1):
            fh.readline()
        row = 0
        for line in fh:
            if not line.strip():
                continue
            n = line.count(b",") + 1
            if n != ncols:
                raise LogFormatError(
                    f"{path}: row {row} (line {row + skip + 2}) has {n} of {ncols} fields; "
                    f"{fix if row == nrows - 1 else 'the file is damaged; re-export it'}"
                )
            row += 1


def _repair_time(df: pd.DataFrame, time_order: str, where: str) -> pd.DataFrame:
    t = pd.to_numeric(df[TIME], errors="coerce").to_numpy(dtype=float)
    if not np.isfinite(t).all():
        return df  # validate_log names the row
    if time_order == "drop":
        running = np.maximum.accumulate(t)
        keep = np.ones(len(t), dtype=bool)
        keep[1:] = t[1:] > running[:-1]
        if keep.all():
            return df
        dropped = np.flatnonzero(~keep)
        attrs = dict(df.attrs)
        out = df.loc[keep].reset_index(drop=True)
        out.attrs = attrs
        out.attrs["time_dropped_rows"] = [int(i) for i in dropped[:100]]
        warnings.warn(
            f"{where}: dropped {dropped.size} row(s) whose time does not advance, first at "
            f"row {int(dropped[0])} (t = {t[dropped[0]]:.6g} s)",
            GrfguardWarning,
            stacklevel=3,
        )
        return out
    seg = np.zeros(len(t), dtype=np.int64)
    seg[1:] = np.cumsum(np.diff(t) <= 0)
    if seg[-1] == 0:
        return df
    attrs = dict(df.attrs)
    out = df.copy()
    out[SEGMENT] = seg
    out.attrs = attrs
    starts = np.flatnonzero(np.diff(seg)) + 1
    warnings.warn(
        f"{where}: time does not advance at {starts.size} row(s), first at row "
        f"{int(starts[0])} (t = {t[starts[0] - 1]:.6g} s -> {t[starts[0]]:.6g} s); split into "
        f"{int(seg[-1]) + 1} segments (column 'segment')",
        GrfguardWarning,
        stacklevel=3,
    )
    return out


#: Optional column numbering the time segments of a log read with ``time_order="split"``.
SEGMENT = "segment"
#: A gap is a time step longer than this many median steps (and than :data:`MIN_GAP_S`).
GAP_FACTOR = 5.0
#: Smallest time step reported as a gap by default [s].
MIN_GAP_S = 0.02


def find_time_gaps(df: pd.DataFrame, gap_s: float | None = None) -> list[list[float]]:
    """Gaps in ``df["time"]``: ``[row, t_before, t_after]`` for every step longer than
    ``gap_s`` [s] (default ``max(GAP_FACTOR x median step, MIN_GAP_S)``); ``row`` is the
    first row after the gap. Steps across ``segment`` boundaries are not gaps."""
    if TIME not in df.columns or len(df) < 3:
        return []
    df = without_attrs(df)
    t = df[TIME].to_numpy(dtype=float)
    dt = np.diff(t)
    if SEGMENT in df.columns:
        dt = np.where(np.diff(df[SEGMENT].to_numpy()) != 0, 0.0, dt)
    pos = dt[dt > 0]
    if pos.size == 0:
        return []
    limit = gap_s if gap_s is not None else max(GAP_FACTOR * float(np.median(pos)), MIN_GAP_S)
    idx = np.flatnonzero(dt > limit)
    return [[int(i) + 1, float(t[i]), float(t[i + 1])] for i in idx]


def without_attrs(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` without its metadata (no copy of the data): pandas deep-copies ``attrs``
    on every column access, which costs more than the checks on a long log."""
    if not df.attrs:
        return df
    bare = df.copy(deep=False)
    bare.attrs = {}
    return bare


def _warn_gaps(gaps: list[list[float]], where: str) -> None:
    shown = ", ".join(
        f"{b - a:.3g} s at row {int(r)} (t = {a:.6g} s -> {b:.6g} s)" for r, a, b in gaps[:3]
    )
    more = f" and {len(gaps) - 3} more" if len(gaps) > 3 else ""
    warnings.warn(
        f"{where}: {len(gaps)} time gap(s) in column 'time': {shown}{more}; samples are "
        "missing there (the monitor restarts what needs continuity)",
        GrfguardWarning,
        stacklevel=3,
    )


def validate_log(
    df: pd.DataFrame, required: Iterable[str] | None = None, where: str = "log"
) -> None:
    """Check ``df`` against the contract; raise :class:`LogFormatError` saying what to fix.

    Checks: the ``time`` column exists, is numeric, finite and strictly increasing (within
    each ``segment`` when that column exists); every ``required`` column is present and
    numeric. NaN in sensor columns is allowed (it is data: a dropout) and handled by the
    monitor.
    """
    if TIME not in df.columns:
        raise LogFormatError(
            f"{where}: missing column 'time' [s]; every log needs a strictly increasing time column"
        )
    df = without_attrs(df)
    req = list(required) if required is not None else []
    missing = [c for c in req if c not in df.columns]
    if missing:
        raise LogFormatError(
            f"{where}: missing column(s) {missing}; the log contract (DESIGN.md, "
            "grfguard.io.schema) requires them. Rename your columns or add them."
        )
    for c in [TIME, *req]:
        if not _numeric_column(df[c]):
            raise LogFormatError(
                f"{where}: column {c!r} must be numeric, found dtype {df[c].dtype}"
                + _first_non_number(df[c])
            )
    t = df[TIME].to_numpy(dtype=float)
    if len(t) == 0:
        raise LogFormatError(f"{where}: the log has no rows")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise LogFormatError(
            f"{where}: column 'time' is not finite at row {int(bad[0])} (value {t[bad[0]]}); "
            "drop or repair that row"
        )
    dt = np.diff(t)
    if SEGMENT in df.columns:
        dt = np.where(np.diff(df[SEGMENT].to_numpy(dtype=float)) != 0, 1.0, dt)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        what = "goes backwards" if t[i] < t[i - 1] else "does not advance (repeated value)"
        n_const = 1
        while i + n_const < len(t) and t[i + n_const] == t[i - 1]:
            n_const += 1
        extra = f" for {n_const} rows" if n_const > 1 and t[i] == t[i - 1] else ""
        raise LogFormatError(
            f"{where}: time {what} at row {i}{extra} (time[{i - 1}] = {t[i - 1]!r} s, "
            f"time[{i}] = {t[i]!r} s); sort the log and drop duplicate samples, or read it "
            "with time_order='drop' / 'split' (CLI: --time-order drop|split)"
        )


def _numeric_column(col: Any) -> bool:
    """A column of numbers or booleans (numpy's dtypes decided without pandas)."""
    dtype = getattr(col, "dtype", None)
    if isinstance(dtype, np.dtype) and dtype.kind in "biuf":
        return True
    return bool(pd.api.types.is_numeric_dtype(col) or pd.api.types.is_bool_dtype(col))


def _first_non_number(col: pd.Series) -> str:
    vals = pd.to_numeric(col, errors="coerce")
    bad = np.flatnonzero(vals.isna().to_numpy() & col.notna().to_numpy())
    if bad.size == 0:
        return ""
    return f" (row {int(bad[0])} holds {_short(repr(col.iloc[bad[0]]), 40)})"


def load_log(path: str | Path, time_order: str = "strict", copy: bool = True,
             columns: Iterable[str] | None = None, frame: bool = True) -> pd.DataFrame:
    """Read a log (Parquet or CSV) for the virtual sensor and monitor.

    Checks that the input columns of the log contract are present (``time``, IMU,
    joint encoders, force sensors); timestamps, ``copy`` and ``columns`` (of a Parquet
    file; None: all) and ``frame`` as in :func:`read_log`. A described robot's log is
    read whole (a DataFrame).
    """
    from grfguard.io.robot_schema import is_described_log, load_robot_log

    df = read_log(path, time_order=time_order, copy=copy, columns=columns, frame=frame)
    if is_described_log(df):  # Talos, G1, ...: columns from the robot description
        return load_robot_log(path)
    validate_log(df, required=REQUIRED_INPUT_COLUMNS, where=str(path))
    return df
