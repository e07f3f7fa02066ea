"""Shared pieces of the benchmark scripts (run them from the repository root)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

from grfguard.model.robot import RobotConfig

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS_MD = ROOT / "BENCHMARKS.md"

#: The "other size" robot of the foundation issue: 60 kg, 0.20 x 0.12 m feet, shorter legs.
SMALL = RobotConfig(
    name="small", mass=60.0, foot_length=0.20, foot_width=0.12, upper_leg_length=0.22,
    lower_leg_length=0.21, sole_to_ankle=0.09, hip_width=0.16,
)


def reference_us(repeat: int = 5) -> float:
    """A plain reference timed in the same run as a benchmark: ``np.sort`` of 10^6
    random floats, best of ``repeat`` [µs]. A figure divided by it holds on a machine
    whose speed varies (another load, the host's clock)."""
    import numpy as np

    x = np.random.default_rng(0).random(1_000_000)
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        np.sort(x)
        best = min(best, time.perf_counter() - t0)
    return best * 1e6


def fresh_float(code: str, *args: str, prefix: list[str] | None = None) -> float:
    """Run ``code`` (Python printing a number last) with ``args`` in a fresh interpreter
    under ``prefix`` (e.g. ``taskset -c 1``) and return that number; ``_common`` is
    importable there."""
    res = subprocess.run([*(prefix or []), sys.executable, "-c",
                          "import sys; sys.path.insert(0, sys.argv[1]); " + code,
                          str(Path(__file__).parent), *args],
                         capture_output=True, text=True, check=True)
    return float(res.stdout.strip().splitlines()[-1])


def fresh_touch_ms(mb: int = 48, prefix: list[str] | None = None) -> float:
    """Time to allocate and first touch ``mb`` MB in a fresh process (``np.empty`` and
    ``fill``) [ms], run under ``prefix``. On a virtual machine the first touch of memory
    moves with the host (8 ms and 231 ms for 48 MB minutes apart on the session-30 host),
    and ``Monitor.run`` / ``grfguard run`` write their outputs into fresh memory: a
    figure of theirs holds only next to this one."""
    return fresh_float("import time; import numpy as np; n = int(sys.argv[2]) * 131072; "
                       "t = time.perf_counter(); a = np.empty(n); a.fill(0.0); "
                       "print((time.perf_counter() - t) * 1e3)", str(mb), prefix=prefix)


def alarm_episodes(out) -> int:
    """Alarm episodes (rising edges of each sensor's flag, a flag raised at the first
    sample counting as one) in a monitor output over the eight sole sensors."""
    import numpy as np

    from grfguard.model.robot import SENSOR_NAMES

    fl = out[[f"flag_{s}" for s in SENSOR_NAMES]].to_numpy(bool)
    return int(np.sum(fl[1:] & ~fl[:-1]) + np.sum(fl[0]))


def update_section(section: str, body: str, path: Path = BENCHMARKS_MD) -> None:
    """Replace (or append) only ``section`` (a ``## ...`` heading) of ``path``.

    ``body`` may or may not start with the heading itself.
    """
    body = body.strip()
    if body.startswith(section):
        body = body[len(section):].strip()
    text = path.read_text() if path.exists() else "# grfguard benchmarks\n"
    block = f"{section}\n\n{body}\n"
    pattern = re.compile(rf"^{re.escape(section)}\n.*?(?=^## |\Z)", re.S | re.M)
    if pattern.search(text):
        text = pattern.sub(lambda _m: block + "\n", text, count=1)
    else:
        text = text.rstrip("\n") + "\n\n" + block
    path.write_text(text.rstrip("\n") + "\n")


class RunClock:
    """Wall time, CPU time and load average from the start of a benchmark run."""

    def __init__(self) -> None:
        self.t0, self.c0, self.load0 = time.time(), self._cpu(), os.getloadavg()[0]

    @staticmethod
    def _cpu() -> float:
        """CPU seconds of this process and of its finished children (worker pools,
        subprocesses)."""
        import resource

        ru = resource.getrusage(resource.RUSAGE_CHILDREN)
        return time.process_time() + ru.ru_utime + ru.ru_stime

    def line(self) -> str:
        """The closing ``Runtime ...`` sentence of a section."""
        return (f"Runtime {time.time() - self.t0:.0f} s wall, "
                f"{self._cpu() - self.c0:.0f} s CPU (load average {self.load0:.1f} at "
                f"the start, {os.getloadavg()[0]:.1f} at the end), measured "
                f"{time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC.")


def finish_section(section: str, lines: list[str], clock: RunClock, write: bool) -> str:
    """``lines`` and the clock's ``Runtime`` sentence as one text: printed, and written
    into ``section`` of BENCHMARKS.md when ``write``. Returns the text."""
    text = "\n".join([*lines, "", clock.line(), ""])
    print(text)
    if write:
        update_section(section, text)
    return text


def renamed_copy(src: Path, name: str, work: Path) -> None:
    """``src/grfguard`` copied to ``work/name`` with every import renamed (once)."""
    dst = work / name
    if dst.exists():
        return
    shutil.copytree(src / "grfguard", dst, ignore=shutil.ignore_patterns("__pycache__"))
    pat = [(re.compile(r"\bgrfguard\."), f"{name}."),
           (re.compile(r"from grfguard import"), f"from {name} import"),
           (re.compile(r"import grfguard\b"), f"import {name}"),
           (re.compile(r"\"grfguard\""), f"\"{name}\"")]
    for f in dst.rglob("*.py"):
        text = f.read_text()
        for p, r in pat:
            text = p.sub(r, text)
        f.write_text(text)


def cpu_name() -> str:
    """The CPU as LLVM names it (the numba kernels are compiled for it), e.g. znver4: the
    figures of different hosts are not comparable, even as ratios to the reference."""
    try:
        import llvmlite.binding as ll

        return ll.get_host_cpu_name()
    except Exception:  # pragma: no cover - llvmlite comes with numba
        return "CPU unknown"
