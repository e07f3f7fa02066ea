"""Text columns from integer codes, without a Python string per row.

The compiled monitor returns the fault kind of each sensor and the system state as
integer codes (indices into :data:`grfguard.kernels.detect.KIND_NAMES` and
:data:`grfguard.guard.SYSTEM_STATES`). :func:`codes_to_str` turns a code array into the
column of names ``Monitor.run`` returns (pandas' default ``str`` dtype, the same values
and dtype as a column built from Python strings) through Arrow: a 600 000-row column
takes milliseconds instead of the 600 000 string objects and pandas' type inference.
:func:`codes_to_categorical` gives a :class:`pandas.Categorical` instead (the names as
categories, in code order) for callers that want the codes kept.

This is the one place where codes become names: the monitor's batch output
(:mod:`grfguard.compiled_monitor`) and any other writer of ``kind_<s>`` /
``system_state`` columns go through it.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["codes_to_str", "codes_to_categorical", "strings_to_str", "codes_to_arrow",
           "codes_to_dictionary"]


#: Rows from which :func:`_take` imports ``pyarrow.compute`` for a column of several codes.
_PC_IMPORT_ROWS = 1 << 18


def _index(codes: Any, n_names: int) -> np.ndarray:
    idx = np.asarray(codes)
    if idx.dtype.kind == "f":
        if not np.isfinite(idx).all():
            raise ValueError("codes must be finite")
        idx = idx.astype(np.int64)
    elif idx.dtype.kind not in "iu":
        raise TypeError(f"codes must be integers, got dtype {idx.dtype}")
    if idx.size and (idx.min() < 0 or idx.max() >= n_names):
        raise IndexError(f"codes must be in [0, {n_names}), got {idx.min()}..{idx.max()}")
    return idx


def codes_to_str(codes: Any, names: Sequence[str]) -> Any:
    """``names[codes]`` as a pandas string array (the dtype pandas infers for a column
    of Python strings).

    Args:
        codes: Integer codes (or floats holding integers), shape (n,).
        names: The name of each code.

    Raises:
        IndexError: A code is outside ``[0, len(names))``.
    """
    import pandas as pd
    import pyarrow as pa

    idx = _index(codes, len(names))
    dtype = _str_dtype()
    if getattr(dtype, "storage", None) != "pyarrow":  # pandas without Arrow strings
        return pd.array(np.asarray(list(names), dtype=object)[idx], dtype=dtype)
    return pd.arrays.ArrowStringArray(pa.chunked_array([_take(idx, names)]), dtype=dtype)


def codes_to_arrow(codes: Any, names: Sequence[str]) -> Any:
    """``names[codes]`` as an Arrow ``large_string`` array (the type pandas' ``str``
    columns are written with), without pandas; codes as in :func:`codes_to_str`."""
    return _take(_index(codes, len(names)), names)


def codes_to_dictionary(codes: Any, names: tuple[str, ...]) -> Any:
    """``names[codes]`` as an Arrow dictionary array (int32 indices into ``names`` as
    ``large_string``), without pandas; codes as in :func:`codes_to_str`. A Parquet writer
    stores it as dictionary pages without looking at a string per row; read back under
    a ``large_string`` schema it is the column :func:`codes_to_arrow` gives."""
    import pyarrow as pa

    idx = _index(codes, len(names)).astype(np.int32)
    indices = pa.Array.from_buffers(pa.int32(), idx.size, [None, pa.py_buffer(idx)])
    return pa.DictionaryArray.from_arrays(indices, _names_array(names))


@functools.lru_cache(maxsize=16)
def _names_array(names: tuple[str, ...]) -> Any:
    """``names`` as one Arrow ``large_string`` array, shared by every column and block
    built from them (one dictionary for a whole Parquet column chunk)."""
    return _gather(np.arange(len(names), dtype=np.int64), names, len(names) == 1)


def _take(idx: np.ndarray, names: Sequence[str]) -> Any:
    """``names[idx]`` (valid int64 codes) as an Arrow ``large_string`` array. A column of
    several codes is Arrow's ``take`` on the names (about ten times faster than
    :func:`_gather`'s byte gather) once ``pyarrow.compute`` is loaded (pandas loads it) or
    the column is long enough to pay for its import (about 40 ms)."""
    n = idx.size
    one = bool(n) and idx[0] == idx.min() == idx.max()
    if one or ("pyarrow.compute" not in sys.modules and n < _PC_IMPORT_ROWS):
        return _gather(idx, names, one)
    import pyarrow as pa
    import pyarrow.compute as pc

    ind = np.ascontiguousarray(idx, dtype=np.int64)
    return pc.take(_names_array(tuple(names)),
                   pa.Array.from_buffers(pa.int64(), n, [None, pa.py_buffer(ind)]))


def _gather(idx: np.ndarray, names: Sequence[str], one: bool) -> Any:
    """:func:`_take` built from its buffers (no ``pa.array``: pyarrow would import pandas
    for it). A column of one code (``one``: a fault kind that stays ``none``) repeats its
    text directly."""
    import pyarrow as pa

    n = idx.size
    enc = [str(s).encode("utf-8") for s in names]
    lens = np.array([len(e) for e in enc], dtype=np.int64)
    if one:
        offsets = np.arange(n + 1, dtype=np.int64) * lens[idx[0]]
        data = enc[int(idx[0])] * n
    else:
        starts = np.concatenate([[0], np.cumsum(lens)])
        row_len = lens[idx]
        offsets = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(row_len, out=offsets[1:])
        blob = np.frombuffer(b"".join(enc) or b"\0", dtype=np.uint8)
        src = np.repeat(starts[idx] - offsets[:-1], row_len) + np.arange(int(offsets[-1]))
        data = blob[src].tobytes()
    return pa.Array.from_buffers(pa.large_string(), n,
                                 [None, pa.py_buffer(offsets), pa.py_buffer(data)])


def strings_to_str(values: Any) -> Any:
    """A sequence of Python strings as the same pandas string array as
    :func:`codes_to_str` (the few rows that carry their own text, such as
    ``system_reason``); a missing value (None) stays missing."""
    import pandas as pd

    return pd.array(np.asarray(values, dtype=object), dtype=_str_dtype())


def codes_to_categorical(codes: Any, names: Sequence[str]) -> pd.Categorical:
    """``names[codes]`` as a :class:`pandas.Categorical` with ``names`` as categories
    (the codes are kept, no strings are built)."""
    import pandas as pd

    idx = _index(codes, len(names))
    return pd.Categorical.from_codes(idx, categories=list(names))


@functools.cache
def _str_dtype() -> Any:
    """The dtype pandas gives a column of Python strings (``str`` in pandas 3)."""
    import pandas as pd

    return pd.Series(np.array([""], dtype=object)).dtype
