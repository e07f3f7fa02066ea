"""``grfguard run``'s I/O (issue 11): the zero-copy Parquet read, the Parquet options of
written logs, the kind/state columns built from integer codes, and the command's output
against the pure-Python monitor on a log with bad samples."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from arrow_compare import same_bits
from grfguard.cli import run_log
from grfguard.detect.monitor import Monitor
from grfguard.faults import inject_faults, parse_fault_spec
from grfguard.guard import SYSTEM_STATES
from grfguard.io.codes import (
    codes_to_arrow,
    codes_to_categorical,
    codes_to_str,
    strings_to_str,
)
from grfguard.io.logio import read_log, write_log
from grfguard.io.runwriter import write_run
from grfguard.kernels.detect import KIND_NAMES
from grfguard.model.robot import SURALP
from grfguard.sim import GaitConfig, NoiseConfig, simulate

pytestmark = pytest.mark.filterwarnings("ignore::grfguard.errors.GrfguardWarning")  # the gap


@pytest.fixture(scope="module")
def bad_walk(tmp_path_factory) -> tuple:
    """A 5 s walk with faults (frozen, offset, dropout, spikes), IMU samples missing, a
    gap of 40 ms and a repeated time stamp dropped: every text column has non-trivial
    values."""
    log = simulate(SURALP, GaitConfig(duration=5.0), NoiseConfig(), seed=11)
    specs = ["r1=frozen:0@1", "r2=offset:100@1.5", "l4=dropout@2-2.3", "l1=spikes:400@3"]
    log = inject_faults(log, [parse_fault_spec(s) for s in specs], seed=1)
    log = log.drop(index=range(3000, 3040)).reset_index(drop=True)  # a time gap
    log.loc[1200:1205, ["imu_acc_x", "imu_gyro_y"]] = np.nan  # estimator inputs missing
    path = tmp_path_factory.mktemp("runio") / "bad.parquet"
    write_log(log, path)
    return path, log


def test_codes_to_str_equals_python_strings() -> None:
    rng = np.random.default_rng(0)
    codes = rng.integers(0, len(KIND_NAMES), 5000)
    ref = pd.Series(np.array(KIND_NAMES, dtype=object)[codes])  # the previous construction
    got = pd.Series(codes_to_str(codes, KIND_NAMES))
    pd.testing.assert_series_equal(got, ref)
    got_f = pd.Series(codes_to_str(codes.astype(float), KIND_NAMES))  # kernel outputs
    pd.testing.assert_series_equal(got_f, ref)
    cat = codes_to_categorical(codes, KIND_NAMES)
    assert list(cat.categories) == list(KIND_NAMES)
    assert np.array_equal(cat.codes, codes)
    assert pd.Series(strings_to_str(ref.to_numpy(dtype=object))).equals(ref)
    with pytest.raises(IndexError):
        codes_to_str(np.array([0, len(SYSTEM_STATES)]), SYSTEM_STATES)
    with pytest.raises(IndexError):
        codes_to_str(np.array([-1]), SYSTEM_STATES)


@pytest.mark.parametrize("code", range(len(KIND_NAMES)))
def test_one_code_columns_equal_python_strings(code) -> None:
    """A column of one code (built from its buffers, not by ``take``), for every name,
    also the empty one, and a column mixing codes: the Arrow array of Python strings."""

    names = (*KIND_NAMES, "", "drölf")
    for codes in (np.full(1000, code), np.full(3, len(names) - 2), np.full(3, len(names) - 1),
                  np.array([code, 0, len(names) - 1]), np.zeros(0, dtype=np.int64)):
        ref = pa.array([names[int(c)] for c in codes], type=pa.large_string())
        got = codes_to_arrow(codes.astype(float), names)
        got.validate(full=True)
        assert got.equals(ref)
        if codes.size:  # (pandas types an empty column of objects as object)
            ref_pd = pd.Series(np.array(names, dtype=object)[codes.astype(np.int64)])
            pd.testing.assert_series_equal(pd.Series(codes_to_str(codes, names)), ref_pd)
    with pytest.raises(IndexError):
        codes_to_arrow(np.full(4, len(names)), names)


def test_take_and_gather_build_the_same_text() -> None:
    """Arrow's ``take`` (a column of several codes, ``pyarrow.compute`` loaded) and the
    byte gather used without it give the same array."""
    import pyarrow.compute  # noqa: F401  (the take path needs it loaded)

    from grfguard.io import codes

    names = (*KIND_NAMES, "", "drölf")
    rng = np.random.default_rng(3)
    idx = rng.integers(0, len(names), 20_000).astype(np.int64)
    taken = codes._take(idx, names)
    gathered = codes._gather(idx, names, False)
    taken.validate(full=True)
    assert taken.type == gathered.type == pa.large_string()
    assert taken.equals(gathered)
    assert taken.to_pylist()[:50] == [names[i] for i in idx[:50]]


_PC_BRANCH = """
import sys
import numpy as np
from grfguard.io import codes
assert "pyarrow.compute" not in sys.modules and "pandas" not in sys.modules
names = ("none", "frozen", "drift")
small = np.arange(1000, dtype=np.int64) % 3
a = codes._take(small, names)
assert "pyarrow.compute" not in sys.modules, "a short column imported pyarrow.compute"
big = np.arange(codes._PC_IMPORT_ROWS, dtype=np.int64) % 3
b = codes._take(big, names)
assert "pyarrow.compute" in sys.modules, "a long column did not take the Arrow path"
assert a.to_pylist() == [names[i] for i in small]
assert b.slice(0, 1000).equals(a) and len(b) == len(big)
assert "pandas" not in sys.modules
"""


def test_take_without_pandas_imports_compute_only_for_long_columns() -> None:
    """Without pandas (``grfguard run``), a short column of several codes stays on the byte
    gather (no ``pyarrow.compute`` import); one of 2^18 rows or more loads it and takes."""
    import subprocess
    import sys

    res = subprocess.run([sys.executable, "-c", _PC_BRANCH], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr


def test_zero_copy_read_equals_the_copying_read(bad_walk) -> None:
    path, _ = bad_walk
    ref = read_log(path)
    fast = read_log(path, copy=False)
    pd.testing.assert_frame_equal(fast, ref, check_exact=True)
    assert fast.attrs == ref.attrs
    ref.loc[0, "force_r1"] = 1.0  # the default read is an ordinary writable frame
    with pytest.raises(ValueError, match="read-only"):  # views of the Arrow buffers
        fast.loc[0, "force_r1"] = 1.0
    assert ref["force_l4"].isna().any()  # the dropout: nulls converted the same way
    with pytest.raises(Exception, match="requested column"):
        read_log(path, columns=["force_r1", "no_such_column"])
    assert list(read_log(path, columns=["force_r1"]).columns) == ["time", "force_r1"]


def test_written_logs_round_trip_with_split_floats(tmp_path) -> None:
    n = 1000
    df = pd.DataFrame({
        "time": np.arange(n) * 1e-3,
        "x": np.where(np.arange(n) % 7 == 0, np.nan, np.sin(np.arange(n))),
        "k": np.arange(n) % 3,
        "b": np.arange(n) % 2 == 0,
        "s": np.array(["a", "bb", ""], dtype=object)[np.arange(n) % 3],
        "f32": np.linspace(0, 1, n, dtype=np.float32),
    })
    df.attrs = {"robot": None, "note": "x"}
    p = write_log(df, tmp_path / "rt.parquet")
    back = read_log(p)
    pd.testing.assert_frame_equal(back, df, check_exact=True)
    meta = pq.ParquetFile(p).metadata.row_group(0)
    enc = {meta.column(i).path_in_schema: meta.column(i).encodings
           for i in range(meta.num_columns)}
    assert "BYTE_STREAM_SPLIT" in enc["x"] and "BYTE_STREAM_SPLIT" in enc["f32"]
    assert "RLE_DICTIONARY" in enc["k"] and "BYTE_STREAM_SPLIT" not in enc["k"]
    assert "RLE_DICTIONARY" not in enc["s"] and "PLAIN" in enc["s"]  # text: plain + zstd
    assert meta.column(0).compression == "ZSTD"
    assert meta.column(0).is_stats_set and not meta.column(1).is_stats_set  # time only


def test_run_output_equals_the_python_monitor(bad_walk, tmp_path) -> None:
    path, _ = bad_walk
    out = tmp_path / "out.parquet"
    marks: list[str] = []
    n = run_log(path, out, phase=marks.append)
    assert marks == ["read", "checks", "monitor_setup", "kernel_setup", "run_write"]
    got = read_log(out)
    assert n == len(got)
    log = read_log(path)
    ref = Monitor.for_log(log, compiled=False).run(log)  # the reference stages
    assert list(got.columns) == list(ref.columns)
    text = [c for c in ref.columns if c.startswith("kind_")] + ["system_state",
                                                                "system_reason"]
    for c in ref.columns:
        assert got[c].dtype == ref[c].dtype, c
        if c in text or not pd.api.types.is_float_dtype(ref[c]) or c in log.columns:
            assert got[c].equals(ref[c]), c
        else:
            np.testing.assert_allclose(got[c].to_numpy(float), ref[c].to_numpy(float),
                                       atol=1e-6, rtol=0, err_msg=c)
    states = set(got["system_state"])
    assert {"ok", "time_gap", "input_invalid"} <= states, states
    assert (got["system_reason"] != "").sum() > 5
    kinds = set().union(*(set(got[c]) for c in got.columns if c.startswith("kind_")))
    assert "frozen" in kinds and len(kinds - {"none"}) >= 2, kinds  # several names


@pytest.mark.parametrize("rows", [1 << 17, 777])
def test_block_writer_equals_the_frame_path(bad_walk, tmp_path, rows) -> None:
    """``write_run`` (the compiled monitor's arrays straight to Parquet, block by block)
    writes the file ``write_log(Monitor.run(log))`` writes: the same schema and metadata,
    every column equal bit for bit (nulls where the frame had NaN), also across blocks
    of 777 rows (the gap, the rejected IMU samples and the faults fall in different
    blocks) and when the log already carries output columns (replaced in place)."""
    path, _ = bad_walk
    log = read_log(path, copy=False)
    again = Monitor.for_log(log).run(log)  # a log that carries the outputs already
    again = again.drop(columns=["system_reason"])
    again.attrs = dict(log.attrs)
    for src in (log, again):
        new, old = tmp_path / "new.parquet", tmp_path / "old.parquet"
        assert write_run(Monitor.for_log(src), src, new, rows=rows) == len(src)
        write_log(Monitor.for_log(src).run(src), old)
        a, b = pq.read_table(new), pq.read_table(old)
        assert a.schema.equals(b.schema, check_metadata=True)
        assert a.column_names == b.column_names and a.num_rows == b.num_rows == len(src)
        bad = [c for c in b.column_names if not same_bits(a[c], b[c])]
        assert not bad, bad
        if rows < len(src):
            assert pq.ParquetFile(new).metadata.num_row_groups == -(-len(src) // rows)
    assert set(b.column("system_state").to_pylist()) >= {"ok", "time_gap", "input_invalid"}
    assert b.column("force_l4").null_count > 0  # the dropout: NaN written as null


def test_block_writer_leaves_the_python_stages_to_the_frame_path(bad_walk, tmp_path) -> None:
    path, _ = bad_walk
    log = read_log(path, copy=False)
    out = tmp_path / "none.parquet"
    assert write_run(Monitor.for_log(log, compiled=False), log, out) is None
    assert not out.exists()
    n = run_log(path, out, compiled=False)  # the frame path of the command
    assert n == len(read_log(out)) == len(log)


def test_console_script_run_ends_cleanly(bad_walk, tmp_path) -> None:
    """The console script ends a completed ``run`` without the interpreter's teardown:
    exit code 0, its message printed, the output complete; an error still exits 2."""
    import subprocess
    import sys
    from pathlib import Path

    path, _ = bad_walk
    out = tmp_path / "cli.parquet"
    exe = Path(sys.executable).parent / "grfguard"
    res = subprocess.run([str(exe), "run", str(path), "-o", str(out)], capture_output=True,
                         text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    said = res.stdout + res.stderr
    assert f"wrote {out}" in said.replace("\n", "") and "samples" in said
    ref = tmp_path / "ref.parquet"
    run_log(path, ref)
    assert pq.read_table(out).equals(pq.read_table(ref))
    bad = subprocess.run([str(exe), "run", str(tmp_path / "missing.parquet"), "-o",
                          str(tmp_path / "x.parquet")], capture_output=True, text=True,
                         timeout=600)
    assert bad.returncode == 2 and "does not exist" in bad.stdout + bad.stderr


def test_for_log_warm_false_leaves_the_kernels_to_their_first_call(bad_walk,
                                                                    monkeypatch) -> None:
    """``grfguard run`` builds its monitor with ``warm=False``: no ``warm_up()`` (every
    streaming kernel), only the loop it runs is loaded, by ``write_run``."""
    import grfguard.kernels as kernels

    path, _ = bad_walk
    log = read_log(path, copy=False)
    calls: list[int] = []
    monkeypatch.setattr(kernels, "warm_up", lambda: calls.append(1) or 0.0)
    cold = Monitor.for_log(log, warm=False)
    assert calls == []
    Monitor.for_log(log)  # the default warms up
    assert calls == [1]
    out = cold.run(log)
    assert len(out) == len(log) and "system_state" in out


def test_run_log_loads_the_kernel_without_scipy_linalg(bad_walk, tmp_path) -> None:
    """The kernels load from numba's cache without its implementation registries
    (grfguard.kernels._jit._lean_cache_class), so without its BLAS check and the
    scipy.linalg package it imports; the paper's observer solves its Riccati equation
    only when used; afterwards scipy.linalg imports as usual and numba's linear algebra
    compiles and works."""
    import subprocess
    import sys

    path, _ = bad_walk
    code = (
        "import sys; from pathlib import Path; import grfguard.cli as cli\n"
        "n = cli.run_log(Path(sys.argv[1]), Path(sys.argv[2]))\n"
        "print(n, 'scipy.linalg' in sys.modules, 'numba.np.arraymath' in sys.modules,\n"
        "      any(m.startswith('scipy.linalg.') for m in sys.modules))\n"
        "import numba, numpy as np, scipy.linalg\n"
        "print(float(scipy.linalg.solve([[2.0]], [4.0])[0]),\n"
        "      hasattr(scipy.linalg, 'cython_blas'),\n"
        "      float(numba.njit(lambda a: np.dot(a, a))(np.ones(3))))\n"
    )
    out = tmp_path / "out.parquet"
    res = subprocess.run([sys.executable, "-c", code, str(path), str(out)],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    first, second = res.stdout.split("\n")[:2]
    assert first.split()[1:] == ["False", "False", "False"], first
    assert second.split() == ["2.0", "True", "3.0"], second
    assert int(first.split()[0]) == len(read_log(out))
