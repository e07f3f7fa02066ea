"""The SURALP batch loop stage by stage: copies of a compiled step that return early.

Issue 11 (must-show 2: ``Monitor.run`` >= 1 M samples/s on SURALP). Each variant is a
copy of one compiled step, compiled with a ``return`` inserted before one of its stages,
so that its loop time is the cost of the stages before that point; all variants and the
real loop are timed alternately in one process (best of ``--rounds``), which cancels this
machine's phases. The copies' outputs are wrong past the return: timing only.

* ``--part vfs``: the virtual force sensor's step (``kernels.vfs._step``) in ``vfs_run``
  over the log's (T, 24) inputs (the block kinematics of eight rows run before each
  block, as in the real loop);
* ``--part judge``: the monitor's detector side (``kernels.monitor._judge``) in the
  whole batch loop (``_run_flat``), the sensor side unchanged.

The log: the paper scenario on a 60 s SURALP walk (seed 0; ``bench_compiled_monitor.py``'s
log), default settings. The variants compile into a temporary directory (about a minute
each for the sensor, three for the detector side: ``--part judge`` takes about 25 min)::

    taskset -c 1 .venv/bin/python benchmarks/bench_stage_profile.py --part vfs

Figures: BENCHMARKS.md "Issue 11 status (2026-11-28, session 34)".
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# (marker: a line of the step's source, the return goes before it; label: the stage that
# starts there)
VFS_MARKS = [
    ("    aw, ax, ay, az = _attitude_filter", "attitude filter"),
    ("    front = prm[_P_FRONT_CF] != 0.0", "kinematics: sites, CoM, momentum sums' place"),
    ("    st0, st1 = _stance", "stance"),
    ("    xo = _S_FIXED", "leg odometry"),
    ("        _raw_rates(", "raw rates"),
    ("        if front:\n            _momentum_front(", "momentum rate from the trunk-frame sums"),
    ("        _keep_shared(", "filters and ZMP"),
    ("    _split_outputs(", "corner contact, force split, outputs"),
]
JUDGE_MARKS = [
    ("    if son:\n        sys_resume(", "system layer: resume"),
    ("    bounded, state = _prepare(", "range checks and settling"),
    ("    if son:\n        sys_pre_detect(", "system layer: zeros, swing load, common-mode fit"),
    ("    rec = ws[_W_REC", "detector and recovery"),
    ("    oflag = ws[_W_FLAG", "standing layer"),
    ("    o = 0\n", "output row"),
    ("    yout[o + 32] = state", "system layer: outputs"),
]
_HEADER = ("import {mod} as _M\n"
           "globals().update({{k: v for k, v in vars(_M).items() if not k.startswith('__')}})\n"
           "from grfguard.kernels._jit import njit_nort\n\n")


def _cut(src: str, marks: list[tuple[str, str]], k: int, ret: str) -> str:
    """``src`` with the statement ``ret`` before the marker ``k`` (past the last marker:
    the whole step)."""
    for key, _ in marks:
        if key not in src:
            raise SystemExit(f"the step's source no longer has the line {key.strip()!r}: "
                             "update the markers in benchmarks/bench_stage_profile.py")
    if k >= len(marks):
        return src
    key = marks[k][0]
    indent = key[:len(key) - len(key.lstrip())]
    return src.replace(key, f"{indent}{ret}\n{key}", 1)


def _source(fn, decorator: str) -> str:
    return inspect.getsource(fn.py_func).replace(decorator, "")


def _write_variants(part: str, work: Path) -> list[str]:
    """Variant modules ``<part>0 ..`` in ``work``: the step cut before stage k, and the
    loop calling it; returns their names."""
    from grfguard.kernels import monitor as M
    from grfguard.kernels import vfs as V

    if part == "vfs":
        step = _source(V._step, "@njit_nort\n").replace("def _step(", "def _stepv(")
        loop = (_source(V.vfs_run, "@njit_nort\n").replace("_step(", "_stepv(")
                .replace("def vfs_run", "def runv"))
        marks, mod, deco, ret = VFS_MARKS, "grfguard.kernels.vfs", "@njit_nort\n", "return True"
    else:
        step = (_source(M._judge, '@njit_nort(inline="always")\n')
                .replace("def _judge(", "def _judgev("))
        loop = (_source(M._run_flat, "@njit_nort\n").replace("_judge(", "_judgev(")
                .replace("def _run_flat", "def runv"))
        marks, mod, deco, ret = (JUDGE_MARKS, "grfguard.kernels.monitor",
                                 "@njit_nort(inline='always')\n", "return")
    names = []
    for k in range(len(marks) + 1):
        body = _cut(step, marks, k, ret)
        name = f"{part}{k}"
        (work / f"{name}.py").write_text(_HEADER.format(mod=mod) + deco + body
                                         + "\n\n@njit_nort\n" + loop + "\n")
        names.append(name)
    return names


def _log():
    from grfguard.faults import inject_faults
    from grfguard.model.robot import SURALP
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    walk = simulate(SURALP, GaitConfig(duration=60.0), NoiseConfig(), seed=0)
    return inject_faults(walk, ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5",
                                "r4=offset:-100@5"], seed=0)


def _callers(part: str, log):
    """``(call(loop), real loop)``: a call of a loop (the real one or a variant's) over
    the whole log from a fresh state."""
    from grfguard.compiled_monitor import _column
    from grfguard.detect import Monitor
    from grfguard.kernels import monitor as M
    from grfguard.kernels import vfs as V

    mon = Monitor.for_log(log)
    if part == "vfs":
        X, has_gyro, has_ref = V.log_to_array(log)
        k = V.VFSKernel(mon.vfs, has_gyro=has_gyro, has_ref=has_ref)
        Y = np.empty((len(X), V.N_OUT))

        def call(fn):
            k.reset()
            fn(X, Y, *k.packed_args())

        return call, V.vfs_run
    mon.run(log)
    mk = mon._batch_kernel(log)
    X = np.ascontiguousarray(np.column_stack([
        _column(log, c) if c in log.columns else np.full(len(log), np.nan)
        for c in mk.in_cols]))
    n = len(log)
    Y = np.empty((n, len(mk.out_cols)))
    EX = np.empty((n, M.N_EX))
    fx, fy = M._flat(X), M._flat(Y)

    def call(fn):
        mon._batch_kernel(log)  # a fresh state
        fn(n, fx[0], 0, fx[1], fx[2], fy[0], 0, fy[1], fy[2], EX, mk.F, mk.I, M._EMPTY2,
           True)

    return call, M._run_flat


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--part", choices=("vfs", "judge"), default="vfs")
    ap.add_argument("--rounds", type=int, default=8)
    a = ap.parse_args()
    from grfguard.kernels import warm_up

    warm_up()
    log = _log()
    n = len(log)
    call, real = _callers(a.part, log)
    marks = VFS_MARKS if a.part == "vfs" else JUDGE_MARKS
    with tempfile.TemporaryDirectory(prefix="grfguard-stages-") as tmp:
        work = Path(tmp)
        names = _write_variants(a.part, work)
        sys.path.insert(0, str(work))
        loops = {}
        for name in names:
            t0 = time.time()
            loops[name] = importlib.import_module(name).runv
            call(loops[name])  # compiles
            print(f"{name}: compiled in {time.time() - t0:.0f} s", file=sys.stderr, flush=True)
        loops["real"] = real
        best = dict.fromkeys(loops, float("inf"))
        for _ in range(a.rounds):
            for name, fn in loops.items():
                c0 = time.process_time()
                call(fn)
                best[name] = min(best[name], time.process_time() - c0)
    us = {k: v / n * 1e6 for k, v in best.items()}
    what = "`vfs_run`" if a.part == "vfs" else "the monitor's batch loop (`_run_flat`)"
    print(f"{what} over the paper run ({n:,} samples), best of {a.rounds} alternated "
          f"rounds, CPU time; the real loop {us['real']:.3f} µs/sample\n")
    print("\n".join(_table(us, names, marks, a.part)))


def _table(us: dict[str, float], names: list[str], marks: list[tuple[str, str]],
           part: str) -> list[str]:
    """The markdown rows: each stage's cost (the loop cut after it less the loop cut
    before it) and the loop cut after it [µs/sample]."""
    first = ("the loop, the block kinematics, input checks" if part == "vfs"
             else "the loop, the sensor side")
    rows = ["| stage | costs [µs/sample] | the loop up to it, with it [µs/sample] |",
            "|---|---:|---:|",
            f"| before the first stage ({first}) | {us[names[0]]:.3f} | {us[names[0]]:.3f} |"]
    for k, (_, label) in enumerate(marks):
        rows.append(f"| {label} | {us[names[k + 1]] - us[names[k]]:.3f} | "
                    f"{us[names[k + 1]]:.3f} |")
    return rows

if __name__ == "__main__":
    main()
