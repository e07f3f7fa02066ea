"""The Python side of the compiled monitor (:mod:`grfguard.kernels.monitor`): the dict
call behind ``Monitor.update`` (:func:`update_dict`), the batch frame behind
``Monitor.run`` (:func:`run_frame`), the output columns and their texts.

It lives outside the kernel modules on purpose: numba's on-disk cache of a module (and
grfguard's stamps, :mod:`grfguard.kernels._jit`) is dropped at any edit of that module's
file, and the monitor's compiled loop takes minutes to build again. An edit here
recompiles nothing.
"""

from __future__ import annotations

import math
import operator
import struct
from typing import TYPE_CHECKING, Any

import numpy as np

from grfguard.guard import SYSTEM_STATES
from grfguard.io.codes import codes_to_str, strings_to_str
from grfguard.kernels.detect import KIND_NAMES, ST_OK
from grfguard.kernels.monitor import (
    _NV,
    N_EX,
    MonitorKernel,
    monitor_run_packed,
    split_block,
)
from grfguard.kernels.system import reason_text
from grfguard.kernels.vfs import OUT_COLUMNS
from grfguard.model.robot import SENSOR_NAMES

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["update_dict", "run_frame", "run_blocks", "run_rows", "chunk_buffers",
           "output_rows", "dict_to_row"]

_FLAG_COLS = tuple(f"flag_{s}" for s in SENSOR_NAMES)
_KIND_COLS = tuple(f"kind_{s}" for s in SENSOR_NAMES)
_REC_COLS = tuple(f"recovered_{s}" for s in SENSOR_NAMES)
_ETA_COLS = tuple(f"eta_{s}" for s in SENSOR_NAMES)


def _reason(state: str, t_raw: float, jump: float, valid: bool, reason: str) -> str:
    """The ``system_reason`` text of one sample (as ``Monitor._prepare``)."""
    if state in ("time_gap", "time_backwards", "time_constant", "time_missing"):
        return (f"time stamp {t_raw:.6g} s: step {jump:+.6g} s" if math.isfinite(jump)
                else "time stamp missing") + (f"; {reason}" if reason else "")
    if state == "input_invalid":
        return reason or ("estimator inputs missing or not finite" if not valid
                          else "virtual forces outside the physical range")
    if state == "settling":
        return reason or "virtual sensor settling after a break"
    return reason


def _fill_row(x: np.ndarray, vals: Any) -> bool:
    """``x`` = the values ``vals`` as floats; True when one is None or cannot be a float
    (NaN then; the input guard names it)."""
    try:  # numbers, booleans, numpy scalars: packed into x's memory (no None, no text)
        _pack(x.shape[0])(x, 0, *vals)
        return False
    except (struct.error, TypeError, ValueError, OverflowError):
        pass
    odd = False
    try:
        x[:] = vals  # one conversion in C (numbers, numeric text, booleans)
        try:  # None -> NaN in that conversion, an error for float(): look for it only
            plain = not math.isnan(sum(vals))  # when a value is NaN, None or text
        except TypeError:
            plain = False
        if not plain:
            for j in np.flatnonzero(np.isnan(x)):
                if vals[j] is None:
                    odd = True
    except (TypeError, ValueError, OverflowError):
        for j, v in enumerate(vals):
            try:
                x[j] = float(v)
            except (TypeError, ValueError, OverflowError):
                x[j] = math.nan
                odd = True
    return odd


_PACKERS: dict[int, Any] = {}


def _pack(n: int) -> Any:
    """``struct.Struct(f"{n}d").pack_into`` (kept per row length)."""
    f = _PACKERS.get(n)
    if f is None:
        f = _PACKERS[n] = struct.Struct(f"{n}d").pack_into
    return f


def update_dict(mon: Any, k: MonitorKernel, row: Any) -> dict[str, Any]:
    """``Monitor.update`` through the compiled step: the same dict (keys in the same
    order) as the pure-Python stages."""
    x = k.xbuf
    try:  # every input column in the row (the usual case): one lookup in C
        vals = k.row_get(row)
    except (KeyError, TypeError):
        vals = [row.get(c, math.nan) for c in k.in_cols]
    odd = _fill_row(x, vals)
    y = k.step(x, k.ybuf).tolist()
    ex = k.ex
    out: dict[str, Any] = {}
    o = 0
    if k.with_vfs:
        out = dict(zip(OUT_COLUMNS, y[:_NV], strict=True))
        o = _NV
    pair = [None] * 16  # flag_<s>, kind_<s> by sensor; then recovered_<s>, eta_<s>
    pair[0::2] = map(operator.ne, y[o:o + 8], _ZEROS8)
    pair[1::2] = map(KIND_NAMES.__getitem__, map(int, y[o + 8:o + 16]))
    out.update(zip(_FLAG_KIND_COLS, pair, strict=True))
    pair[0::2] = y[o + 24:o + 32]
    pair[1::2] = y[o + 16:o + 24]
    out.update(zip(_REC_ETA_COLS, pair, strict=True))
    if k.with_system:
        out["model_mismatch"] = y[o + 33] != 0.0
        out["model_mismatch_reason"] = reason_text(y[o + 33:], k.vib_config)
    state = SYSTEM_STATES[int(y[o + 32])]
    reason = ""
    if ex[0] != 0.0 or odd:
        reason = mon.inputs.clean_row(row)[1]
    out["system_state"] = state
    out["system_reason"] = (reason if state == "ok" else
                            _reason(state, x[0], float(ex[1]), ex[2] != 0.0, reason))
    return out


_ZEROS8 = (0.0,) * 8
_FLAG_KIND_COLS = tuple(c for i in range(8) for c in (_FLAG_COLS[i], _KIND_COLS[i]))
_REC_ETA_COLS = tuple(c for i in range(8) for c in (_REC_COLS[i], _ETA_COLS[i]))


def _column(log: pd.DataFrame, c: str) -> np.ndarray:
    """Column ``c`` of ``log`` (a DataFrame, or a mapping of numpy arrays) as floats
    (text that is no number: NaN)."""
    col = log[c]
    try:
        return col.to_numpy(dtype=float) if hasattr(col, "to_numpy") else np.asarray(
            col, dtype=float)
    except (TypeError, ValueError):
        import pandas as pd

        return pd.to_numeric(pd.Series(col), errors="coerce").to_numpy(dtype=float)


#: Rows per block of ``Monitor.run`` (:func:`run_frame`): the input chunk and the output
#: block, both reused, stay in the core's L2 cache (1024 rows x 77 outputs: 616 kB).
RUN_BLOCK = 1 << 10


def run_frame(mon: Any, k: MonitorKernel, log: pd.DataFrame, chunk: int = RUN_BLOCK
              ) -> pd.DataFrame:
    """``Monitor.run`` through the compiled loop (the monitor is reset): ``log`` plus
    the same output columns as the pure-Python stages (``attrs`` left to the caller).

    The loop writes blocks of ``chunk`` rows into one reused row-major block; each block
    is then split into the returned columns (:class:`_FrameColumns`). Only those get
    fresh memory (SURALP's default monitor: about 420 bytes per row instead of 650 for
    all of the loop's outputs), and the loop writes its rows whole into memory already
    in the cache."""
    from grfguard._memory import small_pages
    from grfguard.pipeline import _with_columns

    with small_pages():  # every array here is fresh memory written once
        log = log.copy(deep=False)
        log.attrs = {}  # column access would deep-copy the metadata every time
        src = [(_column(log, c) if c in log.columns else None) for c in k.in_cols]
        cols, EX = run_blocks(k, src, len(log), chunk)
        return _with_columns(log, cols.columns(mon, log, src[0], EX), copy=False)


def run_blocks(k: MonitorKernel, src: list[Any], n: int, chunk: int = RUN_BLOCK
               ) -> tuple[_FrameColumns, np.ndarray]:
    """The compiled loop over the ``n`` rows of the input columns ``src`` (as in
    :func:`run_rows`) in blocks of ``chunk`` rows, each split into the returned columns:
    those columns (:class:`_FrameColumns`) and the per-sample extras (``n`` x
    :data:`N_EX`)."""
    bufs = chunk_buffers(k, min(chunk, n))
    rows = max(1, bufs[0].shape[1])
    block = np.empty((rows, len(k.out_cols)))
    cols = _FrameColumns(k, n)
    EX = np.empty((n, N_EX))
    for a in range(0, n, rows):
        b = min(n, a + rows)
        run_rows(k, src, a, b, bufs, block[:b - a], EX[a:b])
        cols.take(block[:b - a], a, b)
    return cols, EX


class _FrameColumns:
    """The output columns of :func:`run_frame`, filled block by block: the float columns
    (each contiguous), the flags, the codes of the fault kinds and the system state, and
    the system columns of the rows with a model mismatch (the only rows whose
    ``model_mismatch_reason`` is not empty)."""

    def __init__(self, k: MonitorKernel, n: int) -> None:
        self.k, self.n = k, n
        self.rows = output_rows(k)
        by = {t: [j for _, typ, j in self.rows if typ == t] for t in ("float", "flag")}
        self.fidx, self.bidx = np.array(by["float"], int), np.array(by["flag"], int)
        self.cidx = np.array([j for _, typ, j in self.rows if typ in ("kind", "state")], int)
        self.F = np.empty((self.fidx.size, n))
        self.B = np.empty((self.bidx.size, n), dtype=bool)
        self.C = np.empty((self.cidx.size, n), dtype=np.int64)
        self.sys_j = next((j for _, typ, j in self.rows if typ == "mismatch_reason"), None)
        self.sys_rows: list[np.ndarray] = []
        self.sys_vals: list[np.ndarray] = []

    def take(self, Y: np.ndarray, a: int, b: int) -> None:
        """Rows ``a:b`` from the loop's block ``Y`` (rows x outputs)."""
        split_block(Y, a, self.fidx, self.F, self.bidx, self.B, self.cidx, self.C)
        if self.sys_j is not None:
            r = np.flatnonzero(Y[:, self.sys_j] != 0.0)
            if r.size:
                self.sys_rows.append(r + a)
                self.sys_vals.append(Y[r, self.sys_j:])

    def columns(self, mon: Any, log: pd.DataFrame, t_raw: np.ndarray, EX: np.ndarray
                ) -> dict[str, Any]:
        """The columns by name, in ``Monitor.run``'s order."""
        floats, flags, codes = iter(self.F), iter(self.B), iter(self.C)
        state = self.C[-1]  # the system state: the last code column (output_rows)
        new: dict[str, Any] = {}
        for name, typ, _ in self.rows:
            if typ == "float":
                new[name] = next(floats)
            elif typ == "flag":
                new[name] = next(flags)
            elif typ == "kind":
                new[name] = codes_to_str(next(codes), KIND_NAMES)
            elif typ == "mismatch_reason":
                new[name] = _mismatch_reasons_of(self.n, self.sys_rows, self.sys_vals,
                                                 self.k.vib_config)
            elif typ == "state":
                new[name] = codes_to_str(next(codes), SYSTEM_STATES)
            else:  # "reason"
                new[name] = _reasons(mon, log, state, t_raw, EX)
        return new


def chunk_buffers(k: MonitorKernel, rows: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Buffers of ``rows`` rows for :func:`run_rows`: the input chunk, one input column
    per row (each filled by one contiguous copy), and output and extra chunks used only
    when the caller's ``Y`` / ``EX`` cannot be written in place (one set per run: fresh
    arrays would be page-faulted memory every chunk).

    The input chunk's rows are padded to an odd number of cache lines: the compiled loop
    reads one value of every column per sample, and with a power-of-two row length
    (4096 floats: 32 kB apart) all of them would fall in the same L1 cache set (3-4 %
    of the SURALP loop, ``benchmarks/bench_run_layouts.py``)."""
    lines = -(-max(rows, 1) // 8)
    lines += 1 - lines % 2
    XT = np.empty((len(k.in_cols), 8 * lines))[:, :rows]
    return (XT, np.empty((rows, len(k.out_cols))), np.empty((rows, N_EX)))


def run_rows(k: MonitorKernel, src: list[Any], a: int, b: int,
             bufs: tuple[np.ndarray, np.ndarray, np.ndarray], Y: np.ndarray,
             EX: np.ndarray) -> None:
    """The compiled loop over rows ``a:b`` of the input columns ``src`` (None: a column
    the log lacks, NaN) in chunks of the buffers' length, into rows ``0:b - a`` of ``Y``
    (rows x output columns, any memory order) and ``EX``. The compiled loop writes ``Y``
    and ``EX`` in place (a column-major ``Y`` too) and reads the input chunk column by
    column: no transposing copy on either side."""
    XT = bufs[0]
    rows = max(1, XT.shape[1])
    for s in range(a, b, rows):
        e = min(b, s + rows)
        xb = XT[:, : e - s]
        for j, arr in enumerate(src):
            xb[j] = arr[s:e] if arr is not None else math.nan
        monitor_run_packed(xb.T, Y[s - a:e - a], EX[s - a:e - a], k.F, k.I)


def output_rows(k: MonitorKernel) -> list[tuple[str, str, int]]:
    """The monitor's output columns in ``Monitor.run``'s order, each as (name, type,
    index of its column of the kernel output). Types: ``float`` (the value), ``flag``
    (value != 0), ``kind`` (a :data:`KIND_NAMES` code), ``mismatch_reason`` (the text
    of the system columns from that index on), ``state`` (a :data:`SYSTEM_STATES` code)
    and ``reason`` (``system_reason``, from the state codes at that index)."""
    out: list[tuple[str, str, int]] = []
    o = 0
    if k.with_vfs:
        out += [(c, "float", j) for j, c in enumerate(OUT_COLUMNS)]
        o = _NV
    for i in range(8):
        out += [(_FLAG_COLS[i], "flag", o + i), (_KIND_COLS[i], "kind", o + 8 + i)]
    for i in range(8):
        out += [(_REC_COLS[i], "float", o + 24 + i), (_ETA_COLS[i], "float", o + 16 + i)]
    if k.with_system:
        out += [("model_mismatch", "flag", o + 33),
                ("model_mismatch_reason", "mismatch_reason", o + 33)]
    return [*out, ("system_state", "state", o + 32), ("system_reason", "reason", o + 32)]


def _mismatch_reasons(S: np.ndarray, vib_config: Any, to: Any = None) -> Any:
    """``model_mismatch_reason`` of every row of the system columns ``S`` (one text per
    distinct row, the column built from codes: no string object per row) as ``to(codes,
    names)`` gives it (default :func:`~grfguard.io.codes.codes_to_str`: a pandas string
    array; :func:`~grfguard.io.codes.codes_to_arrow`: Arrow, no pandas)."""
    rows = np.flatnonzero(S[:, 0] != 0.0)
    return _mismatch_reasons_of(S.shape[0], [rows], [S[rows]], vib_config, to)


def _mismatch_reasons_of(n: int, rows: list[np.ndarray], vals: list[np.ndarray],
                         vib_config: Any, to: Any = None) -> Any:
    """:func:`_mismatch_reasons` of ``n`` rows given only those with a mismatch: their
    indices (``rows``, in parts) and system columns (``vals``, the same parts); the
    other rows' text is empty."""
    idx = np.zeros(n, dtype=np.int64)
    names = [""]
    memo: dict[bytes, int] = {}
    for part, S in zip(rows, vals, strict=True):
        for r, row in zip(part.tolist(), S, strict=True):
            key = row.tobytes()
            j = memo.get(key)
            if j is None:
                j = memo[key] = len(names)
                names.append(reason_text(row.tolist(), vib_config))
            idx[r] = j
    return (codes_to_str if to is None else to)(idx, names)


def _reasons(mon: Any, log: pd.DataFrame, codes: np.ndarray, t_raw: np.ndarray,
             EX: np.ndarray, to: Any = None) -> Any:
    """The ``system_reason`` column: empty where the state is ``ok``, text built only
    for the other rows (no string object per row); built from codes by ``to`` as in
    :func:`_mismatch_reasons` (rows with their own text, ``EX[:, 0]``: a pandas string
    array of ``log``'s rows, read only then)."""
    to = codes_to_str if to is None else to
    n = len(codes)
    base: list[str] | None = None
    if (EX[:, 0] != 0.0).any():
        base = mon.inputs.clean_frame(log)[1]
    rows = np.flatnonzero(codes != ST_OK)
    if base is None and rows.size == 0:
        return to(np.zeros(n, dtype=np.int64), ("",))
    texts = [_reason(SYSTEM_STATES[codes[r]], float(t_raw[r]), float(EX[r, 1]),
                     EX[r, 2] != 0.0, base[r] if base is not None else "") for r in rows]
    if base is None:  # names: "" and each text; codes point at them
        idx = np.zeros(n, dtype=np.int64)
        idx[rows] = np.arange(1, rows.size + 1)
        return to(idx, ("", *texts))
    reasons = np.array(base, dtype=object)
    reasons[rows] = texts
    return strings_to_str(reasons)


def dict_to_row(out: dict[str, Any], columns: tuple[str, ...]) -> np.ndarray:
    """A ``Monitor.update`` dict as an output row in ``columns`` order (kinds and the
    system state as their codes)."""
    y = np.empty(len(columns))
    for j, c in enumerate(columns):
        val = out.get(c, math.nan)
        if c.startswith("kind_"):
            y[j] = KIND_NAMES.index(val) if val in KIND_NAMES else math.nan
        elif c == "system_state":
            y[j] = SYSTEM_STATES.index(val) if val in SYSTEM_STATES else math.nan
        else:
            y[j] = float(val)
    return y


