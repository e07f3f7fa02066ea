"""``grfguard run``'s memory policy (grfguard._memory): set by the console script only,
freed memory kept for reuse, and the output unchanged by it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from grfguard.io.logio import write_log

CHECK = r"""
import pyarrow as pa
from numpy._core.multiarray import _set_madvise_hugepage
def hint():
    v = _set_madvise_hugepage(True)
    _set_madvise_hugepage(v)
    return v
before = pa.default_memory_pool().backend_name
hint_before = hint()
import grfguard.cli, grfguard.io.logio  # importing changes nothing
from grfguard import _memory
assert pa.default_memory_pool().backend_name == before, "import changed the pool"
assert hint() == hint_before, "import changed numpy's huge-page hint"
assert not _memory.freed_memory_kept()
import gc
assert gc.isenabled()
_memory.batch_process()
assert hint() is False, "batch_process left numpy's huge-page hint on"
assert not gc.isenabled()
assert _memory.keep_freed_memory() is True  # (again: nothing more)
assert _memory.freed_memory_kept()
assert pa.default_memory_pool().backend_name == "system", pa.default_memory_pool()
print("ok", before)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_keep_freed_memory_only_when_asked() -> None:
    res = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("ok")


def test_console_script_output_equals_in_process_run(tmp_path, clean_walk) -> None:
    """The console script (:func:`grfguard._memory.batch_process` on) writes the bytes
    the in-process ``run_log`` (off) writes: the same columns, values, footer; the log
    runs as two spliced blocks (``SPLICE_BLOCK_ROWS``) in both."""
    import grfguard.cli as cli

    log = tmp_path / "walk.parquet"
    write_log(clean_walk.iloc[:20_000], log)
    inproc = tmp_path / "a.parquet"
    cli.run_log(log, inproc)
    exe = Path(sys.executable).parent / "grfguard"
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "grfguard.cli"]
    script = tmp_path / "b.parquet"
    res = subprocess.run([*cmd, "run", str(log), "-o", str(script)], capture_output=True,
                         text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    a, b = pq.read_table(inproc), pq.read_table(script)
    assert a.schema.equals(b.schema, check_metadata=True)
    assert a.num_rows == b.num_rows == 20_000
    assert [c for c in a.column_names if not a[c].equals(b[c])] == []
    assert inproc.read_bytes() == script.read_bytes()


def _thp_eligible(a) -> bool | None:
    """Whether the kernel may back ``a``'s memory with huge pages (``THPeligible`` of the
    mapping holding its middle in /proc/self/smaps: numpy hints only the part aligned to
    huge pages, a mapping of its own), None where that is not known."""
    try:
        text = Path("/proc/self/smaps").read_text()
    except OSError:
        return None
    addr = a.__array_interface__["data"][0] + a.nbytes // 2
    inside = False
    for line in text.splitlines():
        head = line.split()[0] if line else ""
        if "-" in head and ":" not in head:
            lo, hi = (int(v, 16) for v in head.split("-"))
            inside = lo <= addr < hi
        elif inside and line.startswith("THPeligible:"):
            return line.split()[1] == "1"
    return None


def test_small_pages_scopes_numpys_huge_page_hint() -> None:
    """Inside ``small_pages`` numpy gives its arrays no huge-page hint (where Linux only
    backs hinted memory with huge pages, the array's mapping is not eligible), and
    numpy's setting is back afterwards, also after an exception."""
    import numpy as np
    from numpy._core.multiarray import _set_madvise_hugepage

    from grfguard._memory import small_pages

    def setting() -> bool:
        v = _set_madvise_hugepage(True)
        _set_madvise_hugepage(v)
        return v

    before = setting()
    with small_pages():
        assert setting() is False
        inside = np.ones(8 << 20)  # 64 MB: its own mapping
    assert setting() is before
    with pytest.raises(RuntimeError), small_pages():
        raise RuntimeError("boom")
    assert setting() is before
    outside = np.ones(8 << 20)
    mode = Path("/sys/kernel/mm/transparent_hugepage/enabled")
    if before and mode.is_file() and "[madvise]" in mode.read_text():
        assert _thp_eligible(inside) is False
        assert _thp_eligible(outside) is True


def test_run_described_allocates_without_the_huge_page_hint(monkeypatch) -> None:
    """``run_described`` (like ``Monitor.run``) does its work inside ``small_pages``: on
    a host where fresh huge pages are slow to touch its first run in a process stalled
    (a 60 s Talos log: 0.107-0.241 s with the hint, 0.119-0.136 s without); numpy's
    setting is back afterwards."""
    from numpy._core.multiarray import _set_madvise_hugepage

    from grfguard.estimate import described

    def setting() -> bool:
        v = _set_madvise_hugepage(True)
        _set_madvise_hugepage(v)
        return v

    seen = []
    monkeypatch.setattr(described, "_run_described",
                        lambda *args: seen.append((setting(), args)) or "out")
    before = setting()
    assert described.run_described("log", track=False) == "out"
    assert seen == [(False, ("log", None, None, None, False))]
    assert setting() is before
