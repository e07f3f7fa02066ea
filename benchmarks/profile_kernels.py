"""Where the compiled SURALP monitor loop spends its time, with Linux ``perf``.

numba's machine code has no symbols ``perf`` can see (it is loaded from numba's on-disk
cache into anonymous memory). This script runs the loop in a child process under ``perf
record``; the child keeps the object code of every kernel library it loads from the cache
(numba's ``CPUCodeLibrary._set_compiled_object``), writes it to ``--work``, and writes a
perf map (``/tmp/perf-<pid>.map``) from each object's symbols (``nm``) and the load
address of one of them. Few symbols survive (the step functions are inlined into one
body), so the report is by address window: for the hottest windows, the library, the
offset, the nearest preceding symbol and the share of all samples; then every AVX-512
gather or scatter instruction that is hot (slow on some CPUs: ``vscatterqpd`` is
microcoded on AMD Zen 4), and the disassembly (``objdump``) of the hottest window. The
setup (simulating the walk, loading the kernels) is in the samples too: the share of the
libraries is printed first. Needs ``perf``, ``nm`` and ``objdump`` (binutils)::

    .venv/bin/python benchmarks/profile_kernels.py [--rounds 30] [--window 256]

``--lines`` compiles the kernels with ``NUMBA_DEBUGINFO=1`` (in a cache of their own beside
``--work``, kept; the first run compiles them first, about 15 min) and adds the samples
by Python function and by source line (``addr2line -i``: the innermost inlined
location). The line tables are approximate in places (numba's inlining); the debug
build runs the loop about 10-40 % slower.

Nothing is written to BENCHMARKS.md (section "SURALP monitor loop: a scatter on Zen 4"
is what it found first).
"""

from __future__ import annotations

import argparse
import ast
import collections
import functools
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve()


def _child(work: Path, rounds: int) -> None:
    """Load the kernels (objects kept), write them and the perf map, run the loop."""
    import numba.core.codegen as cg

    captured: list = []
    orig = cg.CPUCodeLibrary._set_compiled_object

    def keep(self, value):  # every library loaded from the cache passes here
        captured.append((self, value))
        return orig(self, value)

    cg.CPUCodeLibrary._set_compiled_object = keep
    import numpy as np

    from grfguard.detect import Monitor
    from grfguard.model.robot import SURALP
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    walk = simulate(SURALP, GaitConfig(duration=60.0), NoiseConfig(), seed=0)
    mon = Monitor.for_log(walk)
    k = mon._kernel(True, True)
    n = len(walk)
    X = np.ascontiguousarray(np.column_stack([
        walk[c].to_numpy(float) if c in walk else np.full(n, np.nan) for c in k.in_cols]))
    k.reset()
    k.run(X[:100])  # loads the loop
    lines = []
    for i, (lib, obj) in enumerate(captured):
        lines += _map_lines(lib, obj, work / f"lib{i:02d}.o", work / "bases.txt")
    Path(f"/tmp/perf-{os.getpid()}.map").write_text("\n".join(lines) + "\n")
    t = time.process_time()
    for _ in range(rounds):
        k.reset()
        k.run(X)
    us = (time.process_time() - t) / (rounds * n) * 1e6
    print(f"child: {len(captured)} libraries, {len(lines)} symbols; loop {us:.2f} µs/sample",
          flush=True)


def _map_lines(lib, obj: bytes, path: Path, bases: Path) -> list[str]:
    """Perf-map lines of the object ``obj`` of ``lib`` (written to ``path``; its load
    address and name appended to ``bases``)."""
    path.write_bytes(obj)
    nm = subprocess.run(["nm", "--defined-only", "-n", str(path)], capture_output=True,
                        text=True, check=True).stdout
    syms = [p for p in (ln.split() for ln in nm.splitlines()) if len(p) == 3 and p[1] in "tT"]
    heads = subprocess.run(["objdump", "-h", str(path)], capture_output=True, text=True,
                           check=True).stdout
    size = max((int(ln.split()[2], 16) for ln in heads.splitlines() if "text" in ln),
               default=0)
    base = None
    for off, kind, name in syms:
        if kind == "T":
            try:
                addr = lib.get_pointer_to_function(name)
            except Exception:  # noqa: BLE001 - a symbol numba does not export
                addr = 0
            if addr:
                base = addr - int(off, 16)
                break
    if base is None or not size:
        return []
    with bases.open("a") as fh:
        fh.write(f"{base:x} {size:x} {path.name} {lib.name}\n")
    offs = [int(off, 16) for off, _, _ in syms] + [size]
    return [f"{base + offs[i]:x} {offs[i + 1] - offs[i]:x} {syms[i][2]}"
            for i in range(len(syms)) if offs[i + 1] > offs[i]]


def _report(work: Path, data: Path, window: int, top: int, lines: bool = False) -> None:
    ips = subprocess.run(["perf", "script", "-i", str(data), "-F", "ip"], capture_output=True,
                         text=True, check=True).stdout.split()
    libs = []
    for ln in (work / "bases.txt").read_text().splitlines():
        base, size, obj, name = ln.split(maxsplit=3)
        libs.append((int(base, 16), int(size, 16), obj, name))
    total = len(ips)
    per_lib: collections.Counter = collections.Counter()
    per_win: collections.Counter = collections.Counter()
    per_ip: collections.Counter = collections.Counter()
    for text in ips:
        ip = int(text, 16)
        for base, size, obj, _ in libs:
            if base <= ip < base + size:
                per_lib[obj] += 1
                per_win[(obj, (ip - base) // window * window)] += 1
                per_ip[(obj, ip - base)] += 1
                break
    names = {obj: name for _, _, obj, name in libs}
    print(f"{total} samples; in the kernels' code: {100 * sum(per_lib.values()) / total:.1f} %")
    for obj, c in per_lib.most_common():
        print(f"  {names[obj]:28s} {100 * c / total:5.1f} %")
    disasm = {obj: _disassemble(work / obj) for obj in per_lib}
    print(f"\nhottest {window}-byte windows (share of all samples; nearest symbol before):")
    for (obj, off), c in per_win.most_common(top):
        print(f"  {names[obj]:22s} +{off:06x} {100 * c / total:5.2f} %  {_near(disasm[obj], off)}")
    print("\nhot gathers/scatters (samples within 48 bytes):")
    for obj, insns in disasm.items():
        for off, op, _ in insns:
            if "gather" in op or "scatter" in op:
                c = sum(v for (o, a), v in per_ip.items() if o == obj and abs(a - off) < 48)
                if c > total * 0.002:
                    print(f"  {names[obj]:22s} +{off:06x} {op:12s} {100 * c / total:5.2f} %  "
                          f"{_near(insns, off)}")
    if lines:
        _report_lines(work, per_ip, names, total, top)
    if per_win:
        (obj, off), _ = per_win.most_common(1)[0]
        print(f"\ndisassembly of the hottest window ({names[obj]} +{off:06x}):")
        for o, _op, line in disasm[obj]:
            if off <= o < off + window:
                print("  " + line)


def _report_lines(work: Path, per_ip: collections.Counter, names: dict, total: int,
                  top: int) -> None:
    """Samples by source line (innermost inlined location, ``addr2line -i``) and by the
    Python function holding that line (objects compiled with ``NUMBA_DEBUGINFO=1``)."""
    per_line: collections.Counter = collections.Counter()
    per_func: collections.Counter = collections.Counter()
    by_obj: dict = collections.defaultdict(list)
    for (obj, off), c in per_ip.items():
        by_obj[obj].append((off, c))
    for obj, offs in by_obj.items():
        out = subprocess.run(["addr2line", "-i", "-f", "-e", str(work / obj),
                              *[f"{o:x}" for o, _ in offs], "-a"],
                             capture_output=True, text=True, check=True).stdout
        blocks = re.split(r"^0x[0-9a-f]+$", out, flags=re.M)[1:]
        for (_off, c), blk in zip(offs, blocks, strict=True):
            rows = blk.strip().splitlines()
            # (-f: the function's mangled name first, then its innermost inlined line)
            where = (rows[1] if len(rows) > 1 else "?").split(" ")[0]
            per_line[where.split("/src/grfguard/")[-1]] += c
            per_func[_enclosing_def(where)] += c
    print("\nby Python function (the innermost inlined one):")
    for f, c in per_func.most_common(2 * top):
        print(f"  {f:50s} {100 * c / total:5.2f} %")
    print("\nby source line (innermost inlined):")
    for w, c in per_line.most_common(3 * top):
        print(f"  {w:50s} {100 * c / total:5.2f} %")


@functools.cache
def _defs(path: str) -> list[tuple[int, int, str]]:
    """(first line, last line, name) of every function in the source file ``path``."""
    try:
        tree = ast.parse(Path(path).read_text())
    except (OSError, SyntaxError):
        return []
    return [(n.lineno, n.end_lineno or n.lineno, n.name) for n in ast.walk(tree)
            if isinstance(n, ast.FunctionDef)]


def _enclosing_def(where: str) -> str:
    """``file:function`` of the innermost function holding ``where`` (``path:line``)."""
    path, _, line = where.rpartition(":")
    if not line.isdigit():
        return where.split("/")[-1]
    best = None
    for a, b, name in _defs(path):
        if a <= int(line) <= b and (best is None or a > best[0]):
            best = (a, name)
    return f"{path.split('/')[-1]}:{best[1] if best else '?'}"


def _disassemble(path: Path) -> list[tuple[int, str, str]]:
    """(offset, mnemonic, line) of every instruction of ``path``; symbols as offset -1."""
    out = subprocess.run(["objdump", "-d", "--no-show-raw-insn", str(path)],
                         capture_output=True, text=True, check=True).stdout
    rows = []
    for ln in out.splitlines():
        m = re.match(r"^([0-9a-f]+) <(.*)>:", ln)
        if m:
            rows.append((int(m.group(1), 16), "<symbol>", m.group(2)))
            continue
        m = re.match(r"^\s+([0-9a-f]+):\s+(\S+)(.*)", ln)
        if m:
            rows.append((int(m.group(1), 16), m.group(2), f"{m.group(1)}: {m.group(2)}"
                         f"{re.sub(r'<.*>', '', m.group(3))}"))
    return rows


def _near(insns: list[tuple[int, str, str]], off: int) -> str:
    best = None
    for o, op, name in insns:
        if op == "<symbol>" and o <= off:
            best = (o, name)
    if best is None:
        return "?"
    short = re.sub(r"B\d+v\d+B.*", "", best[1])
    return f"{short[-60:]}+0x{off - best[0]:x}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=30, help="loops over the 60 s walk")
    ap.add_argument("--window", type=int, default=256, help="address window [bytes]")
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--work", type=Path, default=Path("/tmp/grfguard-profile"))
    ap.add_argument("--lines", action="store_true",
                    help="compile with NUMBA_DEBUGINFO=1 (own cache beside --work) and "
                    "report samples by Python function and source line")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _child(args.work, args.rounds)
        return
    for tool in ("perf", "nm", "objdump"):
        if shutil.which(tool) is None:
            raise SystemExit(f"{tool} is not installed (Debian: apt-get install "
                             f"{'linux-perf' if tool == 'perf' else 'binutils'})")
    cache = args.work.parent / (args.work.name + "-debugcache")
    shutil.rmtree(args.work, ignore_errors=True)
    args.work.mkdir(parents=True)
    env = {**os.environ, "MUJOCO_GL": "disable"}
    if args.lines:  # line tables in the objects; a cache of their own (kept between runs)
        env.update(NUMBA_DEBUGINFO="1", NUMBA_CACHE_DIR=str(cache))
        if not cache.exists():  # compile first: only objects loaded from the cache are kept
            subprocess.run([sys.executable, str(HERE), "--child", "--rounds", "1", "--work",
                            str(args.work)], check=True, env=env)
    data = args.work / "perf.data"
    prefix = ["taskset", "-c", "1"] if (os.cpu_count() or 1) > 1 and shutil.which(
        "taskset") else []
    subprocess.run(["perf", "record", "-q", "-F", "5000", "-o", str(data), "--", *prefix,
                    sys.executable, str(HERE), "--child", "--rounds", str(args.rounds),
                    "--work", str(args.work)], check=True, env=env)
    _report(args.work, data, args.window, args.top, args.lines)


if __name__ == "__main__":
    main()
