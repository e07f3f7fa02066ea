"""``grfguard run`` copies the log's unchanged columns from the input Parquet file (column
chunks byte for byte, :mod:`grfguard.io.splice`) instead of encoding them again: the
file read back must be the one the frame path writes (schema, metadata, every column bit
for bit) for logs of every layout, and anything that does not qualify is encoded."""

from __future__ import annotations

import struct

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from arrow_compare import same_bits
from grfguard.detect.monitor import Monitor
from grfguard.io import _thrift
from grfguard.io.logio import read_log, write_log
from grfguard.io.runwriter import write_run
from grfguard.io.splice import ParquetFooter
from grfguard.model.robot import SURALP
from grfguard.sim import GaitConfig, NoiseConfig, simulate

pytestmark = pytest.mark.filterwarnings("ignore::grfguard.errors.GrfguardWarning")


@pytest.fixture(scope="module")
def walk(tmp_path_factory) -> tuple:
    """A 3 s walk (truth columns included) with a few NaN force samples."""
    log = simulate(SURALP, GaitConfig(duration=3.0), NoiseConfig(), seed=5)
    log.loc[700:720, "force_l2"] = np.nan
    path = tmp_path_factory.mktemp("splice") / "walk.parquet"
    write_log(log, path)
    return path, log


def _spliced_equals_frame_path(src, tmp_path, monkeypatch, rows: int = 1 << 17) -> tuple:
    """Run ``write_run`` with ``source=src`` and the frame path on the log read from
    ``src``; assert the two files read back the same; return (copied columns, file)."""
    from grfguard.io import splice

    copied: list[str] = []
    orig = splice.Splicer.copy_group

    def spy(self, g, names):
        copied.extend(names if g == 0 else [])
        return orig(self, g, names)

    monkeypatch.setattr(splice.Splicer, "copy_group", spy)
    log = read_log(src, copy=False)
    new, old = tmp_path / "new.parquet", tmp_path / "old.parquet"
    assert write_run(Monitor.for_log(log), log, new, rows=rows, source=src) == len(log)
    write_log(Monitor.for_log(log).run(log), old)
    a, b = pq.read_table(new), pq.read_table(old)
    assert a.schema.equals(b.schema, check_metadata=True)
    assert a.column_names == b.column_names and a.num_rows == b.num_rows == len(log)
    bad = [c for c in b.column_names if not same_bits(a[c], b[c])]
    assert not bad, bad
    return copied, new


def test_thrift_round_trip_and_errors() -> None:
    fields = {1: (_thrift.I32, -5), 2: (_thrift.BINARY, b"abc"), 3: (_thrift.BOOL_TRUE, True),
              4: (_thrift.BOOL_FALSE, False), 30: (_thrift.I64, 1 << 40),
              31: (_thrift.LIST, (_thrift.I32, list(range(20)))),
              32: (_thrift.STRUCT, {1: (_thrift.I16, 7)}),
              33: (_thrift.LIST, (_thrift.BOOL_TRUE, [1, 2, 1]))}
    raw = _thrift.encode_struct(fields)
    back, end = _thrift.decode_struct(raw)
    assert end == len(raw) and back == fields
    assert _thrift.encode_struct(back) == raw
    with pytest.raises(_thrift.ThriftError):
        _thrift.decode_struct(raw[:-3])


def test_footer_of_a_written_log_round_trips(walk) -> None:
    path, _ = walk
    data = path.read_bytes()
    n = struct.unpack("<I", data[-8:-4])[0]
    footer = ParquetFooter(path)
    assert footer.plain() and footer.num_rows == pq.ParquetFile(path).metadata.num_rows
    assert footer.leaves == pq.ParquetFile(path).schema_arrow.names
    assert _thrift.encode_struct(footer.meta) == data[-8 - n:-8]
    with pytest.raises(ValueError, match="not a Parquet file"):
        ParquetFooter(data=b"PAR1" + b"x" * 20)


def test_run_copies_the_unchanged_columns(walk, tmp_path, monkeypatch) -> None:
    """The log's columns without NaN are copied (the truth and sensor columns), the
    column with NaN (written as null by the frame path) and the monitor's are encoded;
    the file reads back as the frame path's."""
    path, log = walk
    copied, out = _spliced_equals_frame_path(path, tmp_path, monkeypatch)
    assert "force_l2" not in copied  # NaN -> encoded (null) as the frame path does
    assert {"time", "force_r1", "true_force_r1", "imu_quat_w"} <= set(copied)
    assert len(copied) == len(log.columns) - 1
    # fault kinds and system states go in as dictionary pages (one dictionary of the
    # fixed names), read back as the frame path's large_string columns (above)
    meta = pq.ParquetFile(out).metadata.row_group(0)
    enc = {meta.column(i).path_in_schema: meta.column(i).encodings
           for i in range(meta.num_columns)}
    assert all("RLE_DICTIONARY" in enc[c] for c in ("kind_r1", "kind_l4", "system_state"))


def test_run_copies_from_any_layout(walk, tmp_path, monkeypatch) -> None:
    """Inputs written by other writers: several row groups, dictionary pages, page
    indexes and statistics, no compression, a non-nullable column (not copied: its
    pages lack the definition levels of the output's nullable column), 32-bit floats,
    integers and booleans."""
    path, _ = walk
    table = pq.read_table(path)
    n = table.num_rows
    extra = pa.table({"i64": pa.array(np.arange(n) % 5), "b": pa.array(np.arange(n) % 3 == 0),
                      "f32": pa.array(np.linspace(0, 1, n, dtype=np.float32)),
                      "req": pa.array(np.ones(n))})
    for name in extra.column_names:
        table = table.append_column(name, extra[name])
    schema = table.schema.set(table.schema.get_field_index("req"),
                              pa.field("req", pa.float64(), nullable=False))
    table = table.cast(schema)
    src = tmp_path / "other.parquet"
    pq.write_table(table, src, row_group_size=700, compression="none", write_page_index=True,
                   use_dictionary=True, write_statistics=True)
    assert pq.ParquetFile(src).metadata.num_row_groups > 2
    copied, new = _spliced_equals_frame_path(src, tmp_path, monkeypatch, rows=256)
    assert {"i64", "b", "f32", "time", "true_com_x"} <= set(copied)
    assert "req" not in copied
    groups = pq.ParquetFile(src).metadata.num_row_groups
    assert pq.ParquetFile(new).metadata.num_row_groups == groups


def test_run_replaces_output_columns_of_a_rerun_log(walk, tmp_path, monkeypatch) -> None:
    """A log that already carries the monitor's columns: those are replaced (encoded),
    the others copied."""
    path, _ = walk
    log = read_log(path, copy=False)
    again = Monitor.for_log(log).run(log).drop(columns=["system_reason"])
    again.attrs = dict(log.attrs)
    src = tmp_path / "again.parquet"
    write_log(again, src)
    copied, _ = _spliced_equals_frame_path(src, tmp_path, monkeypatch)
    assert not {"flag_r1", "recovered_r1", "eta_l4", "system_state"} & set(copied)
    assert "true_force_r1" in copied


def test_run_log_copies_only_a_log_read_as_it_is(walk, tmp_path) -> None:
    """``run_log`` hands the input file to the writer for a Parquet log read with the
    default time order, not when rows are dropped (``time_order="drop"``)."""
    from grfguard.cli import run_log

    path, log = walk
    dup = log.copy()
    dup.loc[10, "time"] = dup.loc[9, "time"]  # a repeated time stamp: dropped
    src = tmp_path / "dup.parquet"
    write_log(dup, src)
    out = tmp_path / "dup_out.parquet"
    assert run_log(src, out, time_order="drop") == len(log) - 1
    back = pq.read_table(out)
    ref = Monitor.for_log(read_log(src, time_order="drop")).run(
        read_log(src, time_order="drop"))
    assert back.num_rows == len(ref)
    assert np.array_equal(back["time"].to_numpy(), ref["time"].to_numpy())
    out2 = tmp_path / "plain_out.parquet"
    assert run_log(path, out2) == len(log)
    assert pq.read_table(out2)["true_force_r1"].equals(pq.read_table(path)["true_force_r1"])


def test_run_log_copies_the_truth_unread(walk, tmp_path, monkeypatch) -> None:
    """A simulated log's ``true_*`` columns are not read by ``grfguard run`` (the monitor
    never reads them) but copied into the output; when the block writer cannot copy them
    (the paper method runs the Python stages, a CSV output) they are read after all:
    every output has them, equal to the input's."""
    from grfguard.cli import run_log
    from grfguard.io.runwriter import copy_only_columns

    path, log = walk
    truth = [c for c in log.columns if c.startswith("true_") and log[c].dtype == float]
    assert truth and copy_only_columns(path) == truth
    asked: list = []
    import grfguard.io.logio as logio

    real = logio.load_log

    def spy(*a, **k):
        asked.append(k.get("columns"))
        return real(*a, **k)

    monkeypatch.setattr(logio, "load_log", spy)
    src = pq.read_table(path)
    for kw, name in (({}, "a.parquet"), ({"method": "paper"}, "b.parquet"),
                     ({}, "c.csv")):
        out = tmp_path / name
        asked.clear()
        assert run_log(path, out, **kw) == len(log)
        if name.endswith(".csv"):
            assert asked == [None]  # a CSV output: everything read
            back = read_log(out)
            for c in truth:
                assert np.array_equal(back[c].to_numpy(), log[c].to_numpy()), c
            continue
        assert asked and not set(truth) & set(asked[0])  # read without the truth
        back = pq.read_table(out)
        assert back.column_names[:len(src.column_names)] == src.column_names
        for c in truth:
            assert back[c].equals(src[c]), c
    ref = tmp_path / "frame.parquet"
    full = read_log(path, copy=False)
    write_log(Monitor.for_log(full).run(full), ref)
    a, b = pq.read_table(tmp_path / "a.parquet"), pq.read_table(ref)
    assert a.schema.equals(b.schema, check_metadata=True)
    assert not [c for c in b.column_names if not same_bits(a[c], b[c])]


def test_copy_only_columns_refuses_other_files(walk, tmp_path) -> None:
    """Only a plain Parquet log written by grfguard: not a file without grfguard's
    metadata (another writer may store NaN), not a CSV, not a missing file."""
    path, log = walk
    table = pq.read_table(path).replace_schema_metadata(None)
    other = tmp_path / "other.parquet"
    pq.write_table(table, other)
    from grfguard.io.runwriter import copy_only_columns

    assert copy_only_columns(other) == []
    assert copy_only_columns(tmp_path / "missing.parquet") == []
    csv = tmp_path / "x.csv"
    csv.write_text("time\n0\n")
    assert copy_only_columns(csv) == []


def test_corrupted_copy_falls_back_to_encoding(walk, tmp_path, monkeypatch) -> None:
    """A copied chunk whose bytes come out wrong (here: zeros) fails the read-back check
    before the file replaces the output: ``write_run`` writes nothing, warns, and says
    so (None: ``grfguard run`` then encodes every column through the frame path); an
    existing output is left as it was."""
    from grfguard.errors import GrfguardWarning
    from grfguard.io import splice

    src, _ = walk

    def zeros(dst, fh, start, n, what) -> None:
        splice._write_all(dst, memoryview(bytes(n)))

    monkeypatch.setattr(splice, "_copy_range", zeros)
    log = read_log(src, copy=False)
    out = tmp_path / "out.parquet"
    write_log(log.iloc[:10], out)  # an existing output: must be left as it was
    before = out.read_bytes()
    with pytest.warns(GrfguardWarning, match="every column is encoded again"):
        assert write_run(Monitor.for_log(log), log, out, source=src) is None
    assert out.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["out.parquet"]  # no temporary left
