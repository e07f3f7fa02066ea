"""Bit-for-bit comparison of Arrow columns, shared by the Parquet writer tests."""

from __future__ import annotations

import numpy as np
import pyarrow as pa


def same_bits(a: pa.ChunkedArray, b: pa.ChunkedArray) -> bool:
    """Same type, same nulls, same values (floats compared bit for bit)."""
    x, y = a.combine_chunks(), b.combine_chunks()
    if x.type != y.type or x.null_count != y.null_count:
        return False
    if x.null_count and not x.is_null().equals(y.is_null()):
        return False
    if pa.types.is_floating(x.type):
        xv, yv = x.fill_null(0.0).to_numpy(), y.fill_null(0.0).to_numpy()
        return bool(np.array_equal(xv.view(np.int64), yv.view(np.int64)))
    return x.equals(y)
