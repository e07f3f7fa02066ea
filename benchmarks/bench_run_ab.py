"""``grfguard run`` of two source trees on one log, alternated in fresh processes.

For each of ``--rounds`` rounds and each tree (order alternating), one whole command
(``grfguard run LOG -o OUT`` through ``grfguard.cli.main`` with ``PYTHONPATH`` set to the
tree, CPU time and peak memory from ``os.wait4``) and one phase run (the phase code of
``bench_run_cli.py``: imports, read, checks, set-ups, compiled loop, columns, Parquet
writer, copy). Prints the medians and minima per tree; the outputs of the two trees are
compared column by column, bit for bit. On a shared machine the paired medians are the
figure (single runs move by 10-40 % with the load). Each tree needs its numba cache
(run it once first). Nothing is written to BENCHMARKS.md.

Usage: ``.venv/bin/python benchmarks/bench_run_ab.py LOG BASE_SRC NEW_SRC [--rounds 4]
[--commands-only]`` (``BASE_SRC``: e.g. ``git archive <commit> src | tar -x -C /tmp/base``,
then ``/tmp/base/src``; ``--commands-only``: no phase runs). The commands' wall time,
system CPU time and minor page faults are printed too (the memory policy of
``grfguard._memory`` shows in the last two).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_run_cli import CHECK_CODE, PHASE_CODE

KEYS = ("imports", "read", "checks", "monitor_setup", "kernel_setup", "kernel", "frame",
        "write", "copy", "total", "rest")
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
PREFIX = ["taskset", "-c", "1"] if (os.cpu_count() or 1) > 1 else []


def _command(src: str, log: str, out: str) -> tuple[float, float, float, float, int]:
    """(CPU, peak memory [MB], wall, system CPU [s], minor page faults) of one command."""
    code = f"import sys; sys.argv=['grfguard','run',{log!r},'-o',{out!r}]\n" \
           "from grfguard.cli import main; main()\n"
    t0 = time.perf_counter()
    p = subprocess.Popen([*PREFIX, sys.executable, "-c", code], env=dict(ENV, PYTHONPATH=src),
                         cwd=tempfile.gettempdir(), stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    if status:
        raise SystemExit(p.stderr.read().decode()[-2000:] if p.stderr else "failed")
    return ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024, wall, ru.ru_stime, ru.ru_minflt


def _phases(src: str, log: str, out: str) -> dict[str, float]:
    res = subprocess.run([*PREFIX, sys.executable, "-c", PHASE_CODE, log, out],
                         capture_output=True, text=True, env=dict(ENV, PYTHONPATH=src),
                         cwd=tempfile.gettempdir(), check=True)
    d = json.loads(res.stdout.strip().splitlines()[-1])
    ph: dict[str, float] = {}
    prev = 0.0
    for name, t in d["marks"]:
        ph[name] = t - prev
        prev = t
    run = ph.pop("run_write")
    ph.update(kernel=d["kernel"], write=d["parquet"], copy=d["copy"], total=prev,
              rest=prev - d["kernel"])
    ph["frame"] = run - d["kernel"] - d["parquet"] - d["copy"]
    return ph


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("base")
    ap.add_argument("new")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--commands-only", action="store_true",
                    help="only the whole commands (no phase runs): twice the rounds per "
                    "minute")
    args = ap.parse_args()
    trees = {"base": args.base, "new": args.new}
    cmd: dict[str, list] = {k: [] for k in trees}
    ph: dict[str, list] = {k: [] for k in trees}
    loads = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for name in (["base", "new"] if r % 2 == 0 else ["new", "base"]):
                out = str(Path(tmp) / f"{name}.parquet")
                cmd[name].append(_command(trees[name], args.log, out))
                if not args.commands_only:
                    ph[name].append(_phases(trees[name], args.log, out + ".ph"))
            loads.append(os.getloadavg()[0])
        check = subprocess.run([sys.executable, "-c", CHECK_CODE.replace(
            "write_log(Monitor.for_log(log).run(log), sys.argv[3])  # the frame path", ""),
            args.log, str(Path(tmp) / "base.parquet"), str(Path(tmp) / "new.parquet")],
            capture_output=True, text=True, check=True, env=ENV).stdout.strip()
    for name in trees:
        c = cmd[name]
        med = {i: statistics.median(x[i] for x in c) for i in range(5)}
        print(f"{name}: command CPU median {med[0]:.2f} (min {min(x[0] for x in c):.2f}) s, "
              f"peak memory {max(x[1] for x in c):.0f} MB; wall median {med[2]:.2f} (min "
              f"{min(x[2] for x in c):.2f}, max {max(x[2] for x in c):.2f}) s; system CPU "
              f"median {med[3]:.2f} (min {min(x[3] for x in c):.2f}, max "
              f"{max(x[3] for x in c):.2f}) s; minor page faults median {med[4]:.0f}")
        for how, fn in (("median", statistics.median), ("min", min)) if ph[name] else ():
            print(f"   phases {how}: " + " ".join(
                f"{k}={fn(p[k] for p in ph[name]):.3f}" for k in KEYS))
    print(f"outputs base vs new: {check}")
    print("load averages:", " ".join(f"{x:.1f}" for x in loads))
    print("wall new/base per round:", " ".join(
        f"{n[2] / b[2]:.2f}" for b, n in zip(cmd["base"], cmd["new"], strict=True)))


if __name__ == "__main__":
    main()
