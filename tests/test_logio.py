"""Log I/O: Parquet/CSV round trip with metadata, clear errors on bad files."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from grfguard.errors import LogFormatError
from grfguard.io.logio import load_log, read_log, write_log
from grfguard.io.schema import REQUIRED_INPUT_COLUMNS


def _log(n: int = 50) -> pd.DataFrame:
    rng = np.random.default_rng(3)
    df = pd.DataFrame({c: rng.normal(size=n) for c in REQUIRED_INPUT_COLUMNS})
    df["time"] = np.arange(n) * 1e-3
    df["fault_kind_r1"] = "none"
    df.attrs.update({"robot": {"name": "suralp", "mass": 114.0}, "seed": np.int64(4)})
    return df


@pytest.mark.parametrize("suffix", [".parquet", ".csv"])
def test_round_trip_keeps_data_and_metadata(tmp_path, suffix: str) -> None:
    df = _log()
    p = write_log(df, tmp_path / f"log{suffix}")
    back = load_log(p)
    pd.testing.assert_frame_equal(back, df, check_dtype=False, check_exact=suffix == ".parquet")
    assert back.attrs["robot"]["mass"] == 114.0 and back.attrs["seed"] == 4


def test_missing_column_is_named(tmp_path) -> None:
    p = write_log(_log().drop(columns=["force_r3", "q_l_knee"]), tmp_path / "x.parquet")
    with pytest.raises(LogFormatError, match=r"force_r3.*q_l_knee|q_l_knee.*force_r3"):
        load_log(p)


def test_time_jump_backwards_names_the_row(tmp_path) -> None:
    df = _log()
    df.loc[17, "time"] = df.loc[15, "time"]
    p = write_log(df, tmp_path / "x.parquet")
    with pytest.raises(LogFormatError, match="row 17"):
        read_log(p)


def test_nan_time_is_rejected(tmp_path) -> None:
    df = _log()
    df.loc[3, "time"] = np.nan
    with pytest.raises(LogFormatError, match="row 3"):
        read_log(write_log(df, tmp_path / "x.csv"))


def test_corrupted_file_is_reported(tmp_path) -> None:
    p = write_log(_log(), tmp_path / "x.parquet")
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(LogFormatError, match="not a readable Parquet"):
        read_log(p)


def test_missing_file(tmp_path) -> None:
    with pytest.raises(LogFormatError, match="does not exist"):
        read_log(tmp_path / "nope.parquet")


def test_nan_sensor_values_are_data_not_errors(tmp_path) -> None:
    df = _log()
    df.loc[5, "force_r2"] = np.nan
    back = load_log(write_log(df, tmp_path / "x.parquet"))
    assert np.isnan(back.loc[5, "force_r2"])
