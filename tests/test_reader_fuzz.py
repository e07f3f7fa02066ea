"""Property tests of the log readers: random corruptions of valid Parquet and CSV logs
(truncation, flipped, inserted or deleted bytes, random files) either read as a valid
log or raise grfguard's own :class:`~grfguard.errors.GrfguardError`, never anything else."""

from __future__ import annotations

import warnings
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from grfguard.errors import GrfguardError
from grfguard.io.logio import load_log, read_log, validate_log, write_log
from grfguard.model.robot import SURALP
from grfguard.sim import GaitConfig, simulate

FUZZ = settings(max_examples=120, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])


@pytest.fixture(scope="module")
def originals(tmp_path_factory) -> dict[str, bytes]:
    """0.3 s of a real simulated walk, written by grfguard as Parquet and CSV."""
    d = tmp_path_factory.mktemp("fuzz")
    full = simulate(SURALP, GaitConfig(duration=2.0), seed=3)
    df = full.iloc[1000:1300].reset_index(drop=True)
    df.attrs = dict(full.attrs)
    out = {}
    for suffix in (".parquet", ".csv"):
        p = write_log(df, d / f"walk{suffix}")
        out[suffix] = p.read_bytes()
    return out


def _read_or_clean_error(path: Path) -> None:
    for reader in (read_log, load_log):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                df = reader(path)
            except GrfguardError as exc:
                assert str(exc), "an error must say what is wrong"
                assert "\n" not in str(exc).strip(), "one line"
                continue
        assert isinstance(df, pd.DataFrame)
        validate_log(df)  # whatever reads must follow the contract


@st.composite
def corruption(draw, data: bytes) -> bytes:
    kind = draw(st.sampled_from(["truncate", "flip", "insert", "delete", "splice"]))
    n = len(data)
    if kind == "truncate":
        return data[: draw(st.integers(0, n - 1))]
    if kind == "flip":
        out = bytearray(data)
        for _ in range(draw(st.integers(1, 8))):
            i = draw(st.integers(0, n - 1))
            out[i] = draw(st.integers(0, 255))
        return bytes(out)
    if kind == "insert":
        i = draw(st.integers(0, n))
        return data[:i] + draw(st.binary(min_size=1, max_size=64)) + data[i:]
    if kind == "delete":
        i = draw(st.integers(0, n - 1))
        return data[:i] + data[i + draw(st.integers(1, 256)):]
    i, j = sorted(draw(st.lists(st.integers(0, n), min_size=2, max_size=2)))
    return data[:i] + data[j:]


@pytest.mark.parametrize("suffix", [".parquet", ".csv"])
@FUZZ
@given(data=st.data())
def test_corrupted_logs_raise_only_grfguard_errors(originals, tmp_path, suffix, data) -> None:
    blob = data.draw(corruption(originals[suffix]))
    p = tmp_path / f"x{suffix}"
    p.write_bytes(blob)
    _read_or_clean_error(p)


@pytest.mark.parametrize("suffix", [".parquet", ".csv", ".txt"])
@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(blob=st.binary(max_size=2048))
def test_random_files_raise_only_grfguard_errors(tmp_path, suffix, blob) -> None:
    p = tmp_path / f"r{suffix}"
    p.write_bytes(blob)
    _read_or_clean_error(p)


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=st.text(alphabet=st.sampled_from(list("0123456789.,-e\n#: {}[]\"time,nan")),
                    max_size=400))
def test_csv_like_text_raises_only_grfguard_errors(tmp_path, text) -> None:
    p = tmp_path / "t.csv"
    p.write_text(text)
    _read_or_clean_error(p)


def test_uncorrupted_files_still_read(originals, tmp_path) -> None:
    """The fuzz baseline: the originals read back exactly."""
    frames = []
    for suffix, blob in originals.items():
        p = tmp_path / f"ok{suffix}"
        p.write_bytes(blob)
        frames.append(load_log(p))
    pd.testing.assert_frame_equal(frames[0], frames[1], check_dtype=False)
    assert frames[0].attrs["robot"] == frames[1].attrs["robot"]
