"""numpy columns to Arrow arrays and back without pandas.

pyarrow imports pandas (about 0.2-0.35 s) the first time ``pa.array`` or ``to_numpy``
is called, to check whether its argument is a pandas object. ``grfguard run`` builds its
Arrow columns here from the buffers instead (the same arrays: types, values and nulls
as ``pa.array`` / ``Array.to_numpy`` give them), so it never imports pandas (issue 11).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["float_array", "bool_array", "number_array", "numpy_column"]

#: numpy dtypes of the Arrow number types read as numpy views (:func:`numpy_column`).
_NUMPY_OF = {"double": np.float64, "float": np.float32, "int64": np.int64,
             "int32": np.int32, "int16": np.int16, "int8": np.int8, "uint64": np.uint64,
             "uint32": np.uint32, "uint16": np.uint16, "uint8": np.uint8}


def _valid_bits(valid: np.ndarray) -> Any:
    import pyarrow as pa

    return pa.py_buffer(np.packbits(valid, bitorder="little"))


def float_array(a: np.ndarray) -> Any:
    """Contiguous float64 ``a`` as Arrow (its memory, no copy), NaN as null: what
    ``pa.array(a, mask=np.isnan(a))`` gives (``pa.array(a)`` without NaN). The NaN search
    is one ``min`` (it propagates NaN, at half the cost of ``isnan(a).any()``)."""
    import pyarrow as pa

    a = np.ascontiguousarray(a, dtype=np.float64)
    valid = None
    if a.size and np.isnan(a.min()):
        valid = _valid_bits(~np.isnan(a))
    return pa.Array.from_buffers(pa.float64(), a.size, [valid, pa.py_buffer(a)])


def bool_array(b: np.ndarray) -> Any:
    """Booleans ``b`` as an Arrow boolean array (``pa.array(b)``)."""
    import pyarrow as pa

    b = np.asarray(b, dtype=bool)
    return pa.Array.from_buffers(pa.bool_(), b.size, [None, _valid_bits(b)])


def number_array(a: np.ndarray) -> Any:
    """Integers or booleans ``a`` as Arrow (``pa.array(a)``: the same type)."""
    import pyarrow as pa

    if a.dtype.kind == "b":
        return bool_array(a)
    a = np.ascontiguousarray(a)
    return pa.Array.from_buffers(pa.from_numpy_dtype(a.dtype), a.size,
                                 [None, pa.py_buffer(a)])


def numpy_column(col: Any) -> np.ndarray | None:
    """A chunked Arrow column of numbers without nulls as a numpy array (one chunk:
    a read-only view of its buffer, as ``to_numpy(zero_copy_only=True)``; several: one
    copy), or of booleans without nulls (a copy); None for any other column."""
    t = str(col.type)
    if col.null_count:
        return None
    if t == "bool":
        parts = [np.empty(0, bool)]
        for ch in col.chunks:
            if not len(ch):
                continue
            bits = np.frombuffer(ch.buffers()[1], dtype=np.uint8)
            parts.append(np.unpackbits(bits, bitorder="little", count=ch.offset + len(ch))
                         [ch.offset:].astype(bool))
        return np.concatenate(parts) if len(parts) != 2 else parts[1]
    dtype = _NUMPY_OF.get(t)
    if dtype is None:
        return None
    views = [np.frombuffer(ch.buffers()[1], dtype=dtype, count=len(ch), offset=ch.offset
                           * np.dtype(dtype).itemsize) if len(ch) else np.empty(0, dtype)
             for ch in col.chunks]
    if len(views) == 1:
        return views[0]
    return np.concatenate(views) if views else np.empty(0, dtype)
