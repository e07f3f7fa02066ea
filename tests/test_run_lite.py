"""``grfguard run`` without pandas and MuJoCo (issue 11): the log read as numpy columns
(:class:`grfguard.io.columns.LogColumns`), the Arrow columns built from buffers
(:mod:`grfguard.io.arrowcols`) and the command's imports."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from grfguard.io.arrowcols import (
    bool_array,
    float_array,
    number_array,
    numpy_column,
)
from grfguard.io.codes import codes_to_arrow, codes_to_dictionary
from grfguard.io.columns import LogColumns, as_frame
from grfguard.io.logio import read_log, write_log


@pytest.fixture(scope="module")
def walk_file(default_walk, tmp_path_factory):
    path = tmp_path_factory.mktemp("lite") / "walk.parquet"
    write_log(default_walk.iloc[:3000].reset_index(drop=True), path)
    return path


def test_numpy_columns_equal_the_frame(walk_file) -> None:
    """The numpy-column read holds the same values, dtypes and metadata as the frame;
    its frame (``as_frame``) is the frame read (the ground truth ``true_*``, with nulls,
    is what ``grfguard run`` does not read)."""
    cols = [c for c in pq.read_schema(walk_file).names if not c.startswith("true_")]
    ref = read_log(walk_file, copy=False, columns=cols)
    lite = read_log(walk_file, copy=False, frame=False, columns=cols)
    assert isinstance(lite, LogColumns) and lite.columns == list(ref.columns)
    assert lite.attrs == ref.attrs and len(lite) == len(ref)
    for c in ref.columns:
        assert lite[c].dtype == ref[c].dtype
        assert np.array_equal(lite[c].to_numpy(float).view(np.int64),
                              ref[c].to_numpy(float).view(np.int64)), c
    pd.testing.assert_frame_equal(as_frame(lite), ref, check_exact=True)
    sub = lite[["time", "force_r1"]].iloc[::7]
    assert np.array_equal(sub.to_numpy(float), ref[["time", "force_r1"]].iloc[::7].to_numpy())
    # copy=True, or a column with nulls (true_cop_*): a DataFrame, as always
    assert isinstance(read_log(walk_file, frame=False, columns=cols), pd.DataFrame)
    assert isinstance(read_log(walk_file, copy=False, frame=False), pd.DataFrame)


def test_text_or_null_columns_read_as_a_frame(walk_file, tmp_path) -> None:
    df = read_log(walk_file)
    df["note"] = "x"
    p = tmp_path / "text.parquet"
    write_log(df, p)
    assert isinstance(read_log(p, copy=False, frame=False), pd.DataFrame)
    df = read_log(walk_file)
    df.loc[5, "force_r1"] = np.nan  # written as null
    write_log(df, p)
    assert isinstance(read_log(p, copy=False, frame=False), pd.DataFrame)


def test_arrow_arrays_from_buffers_equal_pa_array() -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(size=1001)
    assert float_array(a).equals(pa.array(a))
    a[[0, 17, 1000]] = np.nan
    got = float_array(a)
    got.validate(full=True)
    assert got.equals(pa.array(a, mask=np.isnan(a))) and got.null_count == 3
    b = rng.random(1003) < 0.3
    assert bool_array(b).equals(pa.array(b))
    for x in (b, np.arange(9, dtype=np.int32), np.arange(5, dtype=np.uint8)):
        assert number_array(x).equals(pa.array(x))
    names = ("ok", "", "drölf", "settling")
    for codes in (rng.integers(0, 4, 2000), np.full(50, 2), np.full(3, 1), np.zeros(0, int)):
        s = codes_to_arrow(codes.astype(float), names)
        s.validate(full=True)
        assert s.equals(pa.array([names[int(c)] for c in codes], type=pa.large_string()))
        d = codes_to_dictionary(codes.astype(float), names)
        d.validate(full=True)
        assert d.dictionary_decode().equals(s) and d.dictionary.equals(
            pa.array(names, type=pa.large_string()))
    with pytest.raises(IndexError):
        codes_to_dictionary(np.array([4]), names)
    with pytest.raises(IndexError):
        codes_to_arrow(np.array([4]), names)
    with pytest.raises(ValueError):
        codes_to_arrow(np.array([np.nan]), names)


def test_numpy_column_of_chunks_and_slices() -> None:
    x = np.arange(20.0)
    ch = pa.chunked_array([pa.array(x[:7]), pa.array(x[7:]).slice(3)])
    assert np.array_equal(numpy_column(ch), ch.to_numpy())
    bits = pa.chunked_array([pa.array(np.arange(13) % 3 == 0).slice(2), pa.array([True])])
    assert np.array_equal(numpy_column(bits), bits.to_numpy())
    assert numpy_column(pa.chunked_array([pa.array([1.0, None])])) is None
    assert numpy_column(pa.chunked_array([pa.array(["a"])])) is None


def test_run_imports_neither_pandas_nor_mujoco(walk_file, tmp_path) -> None:
    """``grfguard run`` on a Parquet log: the same file as the frame path, without
    importing pandas or MuJoCo."""
    out = tmp_path / "out.parquet"
    code = (
        "import sys\n"
        "from pathlib import Path\n"
        "from grfguard.cli import run_log\n"
        f"run_log(Path({str(walk_file)!r}), Path({str(out)!r}))\n"
        "print('pandas' in sys.modules, 'mujoco' in sys.modules)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=1200)
    assert res.stdout.split() == ["False", "False"]
    from grfguard.pipeline import Monitor

    log = read_log(walk_file)
    ref = tmp_path / "ref.parquet"
    write_log(Monitor.for_log(log).run(log), ref)
    a, b = pq.read_table(out), pq.read_table(ref)
    assert a.schema.equals(b.schema) and a.schema.metadata == b.schema.metadata
    for c in b.column_names:
        assert a[c].combine_chunks().equals(b[c].combine_chunks()), c
