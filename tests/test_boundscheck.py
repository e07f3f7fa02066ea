"""The compiled kernels index no array out of bounds on the paths whose array sizes
differ (``make boundscheck``: ``benchmarks/check_bounds.py``).

The kernels run without bounds checks: an index past an array's end reads or writes
whatever memory is there, silently. This test compiles every kernel once more with
numba's bounds checks (``NUMBA_BOUNDSCHECK=1``, in a cache of its own: the project's
cache is untouched) and drives the SURALP monitor (virtual sensor inside, its columns
precomputed, without the common-mode layer; batch, array and dict streaming), the
virtual sensor alone, the paper method and Talos's described monitor through them; an
out-of-bounds index raises ``IndexError`` and fails the run, naming the call. It takes
about two minutes of CPU (the compilation), the longest test of the suite, in one
worker while the other runs the rest.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "check_bounds.py"


def test_every_kernel_stays_in_bounds() -> None:
    res = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True,
                         timeout=1800)
    out = res.stdout + res.stderr
    assert res.returncode == 0, out[-4000:]
    assert "no index out of bounds" in res.stdout, out[-4000:]
    for path in ("monitor, virtual sensor inside", "virtual sensor alone", "paper method",
                 "Talos described monitor"):
        assert re.search(rf"^  {re.escape(path)}[^\n]*: in bounds", res.stdout, re.M), path
