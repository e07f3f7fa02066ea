"""Reading and writing logs: Parquet with JSON metadata, CSV on input and output.

A log is a :class:`pandas.DataFrame` with one row per sample (the contract in
:mod:`grfguard.io.schema`) and its metadata (robot, gait, seed, version, ...) in
``df.attrs``. In Parquet the metadata is stored as JSON under the schema key
``grfguard``; in CSV as a first comment line ``# grfguard: {...}``.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import LogFormatError
from grfguard.io.schema import REQUIRED_INPUT_COLUMNS, TIME

__all__ = ["read_log", "write_log", "load_log", "validate_log", "to_jsonable", "METADATA_KEY"]

#: Parquet schema metadata key holding the JSON metadata.
METADATA_KEY = b"grfguard"
_CSV_PREFIX = "# grfguard:"


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
    """Write ``df`` (with ``df.attrs`` as metadata) to ``path``.

    Args:
        df: The log.
        path: Destination; ``.csv`` writes CSV, anything else Parquet (zstd).

    Returns:
        The path written.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = json.dumps(to_jsonable(dict(df.attrs)), sort_keys=True)
    if path.suffix.lower() == ".csv":
        with path.open("w", newline="") as fh:
            fh.write(f"{_CSV_PREFIX} {meta}\n")
            df.to_csv(fh, index=False, float_format="%.17g")
        return path
    plain = df.copy(deep=False)
    plain.attrs = {}  # metadata goes in our own key below, not through pandas
    table = pa.Table.from_pandas(plain, preserve_index=False)
    schema_meta = dict(table.schema.metadata or {})
    schema_meta.pop(b"pandas", None)  # attrs live in our own key, not pandas' blob
    schema_meta[METADATA_KEY] = meta.encode()
    table = table.replace_schema_metadata(schema_meta)
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table, tmp, compression="zstd")
    tmp.replace(path)  # never leave a half-written log behind
    return path


def read_log(
    path: str | Path,
    required: Iterable[str] | None = None,
    columns: Iterable[str] | None = None,
) -> pd.DataFrame:
    """Read a Parquet or CSV log and validate it.

    Args:
        path: A ``.parquet`` or ``.csv`` file.
        required: Columns that must be present (default: only ``time``).
        columns: Read only these columns (Parquet only; ``time`` is always read).

    Returns:
        The log, metadata in ``.attrs``.

    Raises:
        LogFormatError: The file is missing, unreadable or does not follow the contract.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    if not path.exists():
        raise LogFormatError(f"log file {path} does not exist")
    if path.suffix.lower() == ".csv":
        df, meta = _read_csv(path)
    else:
        try:
            cols = None if columns is None else list(dict.fromkeys([TIME, *columns]))
            table = pq.read_table(path, columns=cols)
        except (pa.ArrowInvalid, OSError) as exc:
            raise LogFormatError(
                f"{path} is not a readable Parquet file ({exc}); re-create it with "
                "`grfguard simulate` or convert your data to the log contract"
            ) from exc
        except KeyError as exc:
            raise LogFormatError(f"{path}: requested column {exc} is not in the file") from exc
        raw = (table.schema.metadata or {}).get(METADATA_KEY)
        try:
            meta = json.loads(raw) if raw else {}
        except json.JSONDecodeError as exc:
            raise LogFormatError(
                f"{path}: the grfguard metadata is not valid JSON ({exc})"
            ) from exc
        df = table.to_pandas()
    df.attrs.update(meta)
    df.attrs.setdefault("source", str(path))
    validate_log(df, required=required, where=str(path))
    return df


def _read_csv(path: Path) -> tuple[pd.DataFrame, dict[str, Any]]:
    meta: dict[str, Any] = {}
    with path.open() as fh:
        first = fh.readline()
    skip = 0
    if first.startswith(_CSV_PREFIX):
        skip = 1
        try:
            meta = json.loads(first[len(_CSV_PREFIX) :])
        except json.JSONDecodeError as exc:
            raise LogFormatError(f"{path}: line 1 metadata is not valid JSON ({exc})") from exc
    try:
        df = pd.read_csv(path, skiprows=skip)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise LogFormatError(f"{path} is not a readable CSV log ({exc})") from exc
    return df, meta


def validate_log(
    df: pd.DataFrame, required: Iterable[str] | None = None, where: str = "log"
) -> None:
    """Check ``df`` against the contract; raise :class:`LogFormatError` saying what to fix.

    Checks: the ``time`` column exists, is numeric, finite and strictly increasing; every
    ``required`` column is present and numeric. NaN in sensor columns is allowed (it is
    data: a dropout) and handled by the monitor.
    """
    if TIME not in df.columns:
        raise LogFormatError(
            f"{where}: missing column 'time' [s]; every log needs a strictly increasing time column"
        )
    req = list(required) if required is not None else []
    missing = [c for c in req if c not in df.columns]
    if missing:
        raise LogFormatError(
            f"{where}: missing column(s) {missing}; the log contract (DESIGN.md, "
            "grfguard.io.schema) requires them. Rename your columns or add them."
        )
    for c in [TIME, *req]:
        if not pd.api.types.is_numeric_dtype(df[c]) and not pd.api.types.is_bool_dtype(df[c]):
            raise LogFormatError(
                f"{where}: column {c!r} must be numeric, found dtype {df[c].dtype}"
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
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise LogFormatError(
            f"{where}: time is not strictly increasing at row {i} "
            f"(time[{i - 1}] = {t[i - 1]!r} s, time[{i}] = {t[i]!r} s); sort the log and "
            "drop duplicate samples"
        )


def load_log(path: str | Path) -> pd.DataFrame:
    """Read a log (Parquet or CSV) for the virtual sensor and monitor.

    Checks that the input columns of the log contract are present (``time``, IMU,
    joint encoders, force sensors).
    """
    from grfguard.io.robot_schema import is_described_log, load_robot_log

    df = read_log(path)
    if is_described_log(df):  # Talos, G1, ...: columns from the robot description
        return load_robot_log(path)
    validate_log(df, required=REQUIRED_INPUT_COLUMNS, where=str(path))
    return df
