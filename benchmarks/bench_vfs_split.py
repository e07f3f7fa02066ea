"""The SURALP virtual sensor's step in two passes over a block of rows (issue 11).

Is the batch loop held back by its code's size (the instruction cache) rather than its
arithmetic? The step (``kernels.vfs._step``, default settings) is split in two at its
middle: pass A (validity, attitude filter, poses, stance, leg odometry, raw rates,
momentum rate) runs over a block of rows, keeping per row what pass B needs (raw rates,
corner points, trunk position, ground, CoM, stance, attitude: 47 floats); pass B
(filters, ZMP, corner contact, force split, outputs) then runs over the same rows. The
state each pass writes is read only by itself (pass B repeats the last output of an
invalid row), so the outputs equal ``vfs_run``'s bit for bit, which the script checks.
Each pass's code is about half of the step's, and stays hot for a whole block.

Both loops, a copy of ``vfs_run`` compiled beside them, and ``vfs_run`` itself are timed
alternately in one process over the paper run (best of ``--rounds``, CPU time)::

    taskset -c 1 .venv/bin/python benchmarks/bench_vfs_split.py [--blocks 8,16,32,64]

``--asm`` also compiles uncached copies and counts the machine instructions of each
function of the loops (numba's ``inspect_asm``). Figures: BENCHMARKS.md "Issue 11 status
(2026-11-28, session 36)".
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

#: The two passes and the loops (the step's default path: the front's poses, no paper
#: stages). ``{deco}`` is grfguard's cached decorator or, for ``--asm``, an uncached one.
MODULE = '''
import grfguard.kernels.vfs as _M
globals().update({{k: v for k, v in vars(_M).items() if not k.startswith("__")}})
{deco}

NREC = 47


@njit_nort(inline="always")
def _pass_a(x, y, state, cf, ci, ws, iws, rec):
    prm, iprm, body_inertia, corner_radius, filt_b, filt_a, filt_zi, tree, sites = _unpack(
        cf, ci)
    nb = tree[0].shape[0]
    nq = tree[13].shape[0]
    order = filt_b.shape[1] - 1
    dt = prm[_P_DT]
    if not _valid_sample(x, y, state, prm):
        rec[0] = 0.0
        return
    rec[0] = 1.0
    (qpos, xpos, xquat, xmat, xipos, ximat, stc, msub, sxp, sxm, qin, raw, main, v3a, v3b,
     v3c, v3d, pk, tmp8, prior8, rel8, forces, lin, cc, qp_x, qp_z, qp_M, qp_rhs, qp_dots,
     tail) = _scratch_views(ws, nq, nb)
    aw, ax, ay, az = _attitude_filter(x, state, prm)
    p0, p1, p2 = _kinematics_front(x, prm, iprm, tree, cf, ci, ws, iws, corner_radius, aw,
                                   ax, ay, az, xipos, ximat, stc, msub, sxp, pk)
    st0, st1 = _stance(x, prm, pk)
    pwt0, pwt1, pwt2, ground = _leg_odometry(state, prm, pk, sxp, tmp8, st0, st1)
    com0, com1, com2 = pwt0 + p0, pwt1 + p1, pwt2 + p2
    _raw_rates(state, raw, sxp, pwt0, pwt1, pwt2, p0, p1, p2, dt)
    _momentum_rate(state, prm, raw, xipos, ximat, tree[8], body_inertia, lin, cc, nb, order,
                   dt)
    _keep_shared(ws, pwt0, pwt1, pwt2, ground, com0, com1, com2, st0, st1, aw, ax, ay, az)
    for k in range(9):
        rec[1 + k] = raw[k]
    for k in range(8):
        for c in range(3):
            rec[10 + 3 * k + c] = pk[k, c]
    rec[34], rec[35], rec[36], rec[37] = pwt0, pwt1, pwt2, ground
    rec[38], rec[39], rec[40] = com0, com1, com2
    rec[41] = 1.0 if st0 else 0.0
    rec[42] = 1.0 if st1 else 0.0
    rec[43], rec[44], rec[45], rec[46] = aw, ax, ay, az


@njit_nort(inline="always")
def _pass_b(x, y, state, cf, ci, ws, iws, rec):
    prm, iprm, body_inertia, corner_radius, filt_b, filt_a, filt_zi, tree, sites = _unpack(
        cf, ci)
    nb = tree[0].shape[0]
    nq = tree[13].shape[0]
    order = filt_b.shape[1] - 1
    if rec[0] == 0.0:
        _valid_sample(x, y, state, prm)  # the last output is pass B's
        return False
    (qpos, xpos, xquat, xmat, xipos, ximat, stc, msub, sxp, sxm, qin, raw, main, v3a, v3b,
     v3c, v3d, pk, tmp8, prior8, rel8, forces, lin, cc, qp_x, qp_z, qp_M, qp_rhs, qp_dots,
     tail) = _scratch_views(ws, nq, nb)
    for k in range(9):
        raw[k] = rec[1 + k]
    for k in range(8):
        for c in range(3):
            pk[k, c] = rec[10 + 3 * k + c]
    xo = _S_FIXED + 15 * order + 12 * (nb - 1)
    F0, F1, F2, zmp0, zmp1 = _rates_to_zmp(x, state, prm, filt_b, filt_a, filt_zi, raw, main,
                                           v3a, v3b, v3c, v3d, rec[43], rec[44], rec[45],
                                           rec[46], order, prm[_P_G], xo, rec[38], rec[39],
                                           rec[40], rec[37])
    _split_outputs(y, state, cf, ws, iws, nq, nb, rec[34], rec[35], rec[36], rec[37],
                   rec[38], rec[39], rec[40], F0, F1, F2, zmp0, zmp1, rec[41] != 0.0,
                   rec[42] != 0.0)
    return True


@njit_nort
def run_split(X, Y, state, cf, ci, ws, iws, R, blk):
    n = 0
    T = X.shape[0]
    for b0 in range(0, T, blk):
        b1 = min(b0 + blk, T)
        for t in range(b0, b1):
            j = t % LANES
            if j == 0:
                front_rows(X, t, min(LANES, T - t), 0, cf, ci, ws, iws)
            iws[IW_SLOT] = j
            _pass_a(X[t], Y[t], state, cf, ci, ws, iws, R[t - b0])
        for t in range(b0, b1):
            if _pass_b(X[t], Y[t], state, cf, ci, ws, iws, R[t - b0]):
                n += 1
    iws[IW_SLOT] = -1
    return n


@njit_nort
def run_copy(X, Y, state, cf, ci, ws, iws):
    n = 0
    T = X.shape[0]
    for t0 in range(0, T, LANES):
        nt = min(LANES, T - t0)
        front_rows(X, t0, nt, 0, cf, ci, ws, iws)
        for j in range(nt):
            iws[IW_SLOT] = j
            if _step(X[t0 + j], Y[t0 + j], state, cf, ci, ws, iws):
                n += 1
    iws[IW_SLOT] = -1
    return n
'''
CACHED = "from grfguard.kernels._jit import njit_nort"
UNCACHED = '''import numba


def njit_nort(f=None, **kw):
    def deco(g):
        return numba.njit(g, nogil=True, error_model="numpy", _nrt=False, **kw)
    return deco if f is None else deco(f)
'''


def _instructions(fn) -> dict[str, int]:
    """Machine instructions per function in ``fn``'s assembly (its first signature)."""
    asm = next(iter(fn.inspect_asm().values()))
    out: dict[str, int] = {}
    cur = None
    for line in asm.splitlines():
        m = re.match(r"^([\w.$]+):", line)
        if m and not m.group(1).startswith(".L"):
            cur = m.group(1)
            out.setdefault(cur, 0)
        elif cur and line.startswith("\t") and not line.startswith("\t."):
            out[cur] += 1
    return out


def _short(name: str) -> str:
    """``grfguard.kernels.vfs._step`` from a mangled numba symbol (``_ZN8grfguard..``)."""
    words, rest = [], name[3:]
    while (m := re.match(r"(\d+)", rest)):
        k = int(m.group(1))
        words.append(rest[len(m.group(1)):len(m.group(1)) + k])
        rest = rest[len(m.group(1)) + k:]
    return ".".join(words) if words else name


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--blocks", default="8,16,32,64")
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--asm", action="store_true")
    a = ap.parse_args()
    blocks = [int(b) for b in a.blocks.split(",")]
    from bench_stage_profile import _log

    from grfguard.detect import Monitor
    from grfguard.kernels import vfs as V
    from grfguard.kernels import warm_up

    warm_up()
    log = _log()
    mon = Monitor.for_log(log)
    X, has_gyro, has_ref = V.log_to_array(log)
    k = V.VFSKernel(mon.vfs, has_gyro=has_gyro, has_ref=has_ref)
    T = len(X)
    Y = {name: np.empty((T, V.N_OUT)) for name in ("real", "copy", "split")}
    with tempfile.TemporaryDirectory(prefix="grfguard-split-") as tmp:
        for name, deco in (("vsplit", CACHED), ("vsplit_asm", UNCACHED)):
            (Path(tmp) / f"{name}.py").write_text(MODULE.format(deco=deco))
        sys.path.insert(0, tmp)
        S = importlib.import_module("vsplit")
        R = np.zeros((max(blocks), S.NREC))  # the rows' records between the passes
        loops = {"`vfs_run`": lambda: V.vfs_run(X, Y["real"], *k.packed_args()),
                 "a compiled copy of `vfs_run`": lambda: S.run_copy(X, Y["copy"],
                                                                    *k.packed_args())}
        for b in blocks:
            loops[f"two passes, blocks of {b} rows"] = (
                lambda b=b: S.run_split(X, Y["split"], *k.packed_args(), R, b))
        t0 = time.time()
        for name, fn in loops.items():
            k.reset()
            fn()
            if name != "`vfs_run`":
                got = Y["copy"] if "copy" in name else Y["split"]
                if not np.array_equal(got.view(np.int64), Y["real"].view(np.int64)):
                    raise SystemExit(f"{name}: outputs differ from vfs_run's; the passes in "
                                     "this script no longer mirror kernels.vfs._step")
        print(f"compiled and checked in {time.time() - t0:.0f} s (outputs equal bit for "
              "bit)", file=sys.stderr)
        best = dict.fromkeys(loops, float("inf"))
        for _ in range(a.rounds):
            for name, fn in loops.items():
                k.reset()
                c0 = time.process_time()
                fn()
                best[name] = min(best[name], time.process_time() - c0)
        print(f"The paper run ({T:,} samples), best of {a.rounds} alternated rounds, CPU "
              "time\n\n| loop | µs/sample |\n|---|---:|")
        for name, s in best.items():
            print(f"| {name} | {s / T * 1e6:.3f} |")
        if a.asm:
            U = importlib.import_module("vsplit_asm")
            U.run_copy(X[:8], Y["copy"][:8], *k.packed_args())
            U.run_split(X[:8], Y["split"][:8], *k.packed_args(), R, blocks[0])
            print("\n| loop | machine instructions | the largest functions |\n|---|---:|---|")
            for fn in (U.run_copy, U.run_split):
                ins = _instructions(fn)
                top = sorted(ins.items(), key=lambda t: -t[1])[:4]
                print(f"| `{fn.__name__}` | {sum(ins.values()):,} | "
                      + ", ".join(f"{_short(n)} {c:,}" for n, c in top) + " |")
    k.reset()


if __name__ == "__main__":
    main()
