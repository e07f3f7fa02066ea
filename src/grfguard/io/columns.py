"""A log as plain numpy columns: the part of a :class:`pandas.DataFrame` that ``grfguard
run`` reads, without importing pandas (about 0.2-0.35 s of the command's start-up, issue
11).

:func:`grfguard.io.logio.read_log` returns a :class:`LogColumns` with ``frame=False``
when every column it reads is a number or boolean column without nulls (anything else:
the DataFrame, as always). The readers on ``grfguard run``'s path (the log checks, the
unit checks, :meth:`grfguard.pipeline.Monitor.for_log`, the block writer
:func:`grfguard.io.runwriter.write_run`) use only what is here: ``columns``, ``attrs``,
``len``, ``in``, ``log[name]`` (a numpy array with ``to_numpy``), ``log[[names]]``,
``iloc[slice]``, ``dtypes``, ``pipe``, ``to_numpy`` and ``copy``. Anything else converts
it with :meth:`LogColumns.to_pandas` (the same frame ``read_log`` returns).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

__all__ = ["LogColumns", "Column", "as_frame"]


class Column(np.ndarray):
    """A column of :class:`LogColumns`: a numpy array (no copy) with the
    ``Series.to_numpy`` of pandas."""

    def to_numpy(self, dtype: Any = None, copy: bool = False) -> np.ndarray:
        """The values as a plain numpy array (of ``dtype``; a copy with ``copy``)."""
        a = np.asarray(self, dtype=dtype)
        return a.copy() if copy and np.shares_memory(a, self) else a


class LogColumns:
    """Named numpy columns of one length, with metadata in ``attrs``.

    Args:
        data: Column name -> 1-D numpy array (numbers or booleans), all of one length.
        attrs: The log's metadata (kept as given: not copied).
    """

    def __init__(self, data: dict[str, np.ndarray], attrs: dict | None = None) -> None:
        self._data = data
        self.attrs: dict = {} if attrs is None else attrs
        self.columns = list(data)
        self._n = len(next(iter(data.values()))) if data else 0

    def __len__(self) -> int:
        return self._n

    def __contains__(self, name: object) -> bool:
        return name in self._data

    def __getitem__(self, key: str | Iterable[str]) -> Any:
        if isinstance(key, str):
            return self._data[key].view(Column)
        return LogColumns({c: self._data[c] for c in key}, self.attrs)

    @property
    def dtypes(self) -> list[np.dtype]:
        return [a.dtype for a in self._data.values()]

    @property
    def iloc(self) -> _Rows:
        """Rows by a slice: ``log.iloc[a:b:k]`` (views)."""
        return _Rows(self)

    def pipe(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        return fn(self, *args, **kwargs)

    def to_numpy(self, dtype: Any = None) -> np.ndarray:
        """(rows, columns) array of every column."""
        out = np.empty((self._n, len(self.columns)), dtype=dtype if dtype is not None
                       else np.result_type(*self.dtypes) if self.columns else float)
        for j, a in enumerate(self._data.values()):
            out[:, j] = a
        return out

    def copy(self, deep: bool = True) -> LogColumns:
        """A copy (``deep=False``: the same arrays, its own column list and metadata)."""
        data = {c: (a.copy() if deep else a) for c, a in self._data.items()}
        return LogColumns(data, dict(self.attrs))

    def to_pandas(self) -> Any:
        """The :class:`pandas.DataFrame` of these columns (no copy of the values), with
        ``attrs``: what :func:`grfguard.io.logio.read_log` returns otherwise."""
        import pandas as pd

        df = pd.DataFrame(self._data, copy=False)
        df.attrs.update(self.attrs)
        return df


class _Rows:
    def __init__(self, log: LogColumns) -> None:
        self._log = log

    def __getitem__(self, rows: slice) -> LogColumns:
        if not isinstance(rows, slice):
            raise TypeError("LogColumns.iloc takes a slice of rows")
        return LogColumns({c: a[rows] for c, a in self._log._data.items()}, self._log.attrs)


def as_frame(log: Any) -> Any:
    """``log`` as a :class:`pandas.DataFrame` (a :class:`LogColumns` converted, anything
    else as it is)."""
    return log.to_pandas() if isinstance(log, LogColumns) else log
