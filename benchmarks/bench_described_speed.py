"""Described robots (Talos: ankle F/T, G1: corner cells): batch speed of the virtual foot
wrenches and of the whole described monitor, stage by stage (issue 11, must-show 2:
>= 300 k samples/s on a 30-joint robot, kinematics included).

For each robot, on a noisy simulated walk (default noise, seed 1) at 1 kHz:

* ``estimate_wrenches`` split into its stages (exclusive CPU time of the module's stage
  functions: Savitzky-Golay filters, first kinematics pass, stance weights, attitude,
  base motion, inverse dynamics, the rest);
* the monitor stage alone on the log with its virtual channels (Talos:
  ``ChannelMonitor.run``; G1: the corner monitor with tracking, ``run_described`` on a
  log that already has its ``vfs_*`` columns);
* ``run_described`` whole (virtual wrenches, then the monitor).

``--before-src DIR``: the same measurements with the package sources of ``DIR`` (e.g. a
``git archive`` of the previous commit; run in a subprocess with ``PYTHONPATH=DIR/src``),
in the same session, and the largest difference between its ``run_described`` outputs
and this tree's. Also measured here: the per-sample MuJoCo reference of the wrenches
(``estimate_wrenches(compiled=False)``) and the pure-Python channel monitor
(``tests/reference/channels.py``), with their output differences.

Figures are process CPU time (``time.process_time``), the best of ``--repeats`` runs;
samples/s = samples / CPU seconds; the load average is stated. Kernels are compiled (or
loaded from the cache) before timing.

Updates the ``## Described robots: compiled inverse dynamics (issue 11)`` section of
BENCHMARKS.md (keeps the section's earlier tables under "Earlier runs").

Usage: ``.venv/bin/python benchmarks/bench_described_speed.py [--duration 20]
[--repeats 3] [--ref-repeats 1] [--before-src DIR] [--no-write]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core

import argparse  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

import grfguard.estimate.wrench as wrench  # noqa: E402
from grfguard.estimate.described import run_described, with_described_vfs  # noqa: E402
from grfguard.model.description import load_description  # noqa: E402
from grfguard.model.loader import load_model  # noqa: E402
from grfguard.sim.config import NoiseConfig  # noqa: E402
from grfguard.sim.wholebody import scaled_gait, simulate_robot  # noqa: E402

SECTION = "## Described robots: compiled inverse dynamics (issue 11)"
HERE = Path(__file__).resolve().parent
_COMPILED = wrench.estimate_wrenches

#: Stage functions of :mod:`grfguard.estimate.wrench` timed (exclusive time; a missing
#: name is skipped, so the script also times older sources).
STAGES = {
    "Savitzky-Golay filters": ("_deriv", "_derivs", "_deriv_many", "_smooth_long"),
    "first kinematics (`frames_batch`)": ("_body_frames_compiled", "_frames_omega_compiled"),
    "stance weights": ("_stance_weights",),
    "attitude (leveled)": ("_attitude",),
    "base motion (w/o filters)": ("_base_motion",),
    "inverse dynamics (`wrench_batch`)": ("_inverse_dynamics_compiled",),
}


#: Analysis written with the figures (by hand; re-runs keep it).
NOTES = """
What changed (session 31, 2026-11-28; "before" = `git archive 30d999c`, the session's
start plus the demo's figure message): Talos: `ChannelMonitor.run`'s compiled loop
writes column-major outputs, which the frame takes without a copy, and its kind columns
come from `grfguard.io.codes` (alternated in one process: 0.477 -> 0.379 µs/sample). G1:
`track_recovered` no longer deep-copies the whole frame and, on every column access, its
metadata (0.58 -> 0.10 µs/sample), and `Monitor.run` writes its outputs block by block.
The wrench stages' code did not change: their before/after differences here (Talos'
Savitzky-Golay filters 0.79 -> 0.50) are the machine between the two processes. Outputs
bit-identical (last column: 0).

Target (issue 11, must-show 2, second half: batch >= 300 k samples/s on a 30-joint robot,
kinematics included): see "Issue 11 status" for the verdict over the session; this run's
figure is the `run_described` row for Talos.
"""


class _Timers:
    """Exclusive CPU time of wrapped module functions (nested wrapped calls excluded)."""

    def __init__(self, module, names: dict[str, tuple[str, ...]]) -> None:
        self.module, self.acc, self.stack, self.saved = module, {}, [], {}
        for stage, fns in names.items():
            self.acc[stage] = 0.0
            for fn in fns:
                if hasattr(module, fn):
                    self.saved[fn] = getattr(module, fn)
                    setattr(module, fn, self._wrap(stage, self.saved[fn]))

    def _wrap(self, stage, f):
        def g(*a, **k):
            c0 = time.process_time()
            self.stack.append(0.0)
            try:
                return f(*a, **k)
            finally:
                inner = self.stack.pop()
                dt = time.process_time() - c0
                self.acc[stage] += dt - inner
                if self.stack:
                    self.stack[-1] += dt
        return g

    def restore(self) -> None:
        for fn, f in self.saved.items():
            setattr(self.module, fn, f)


def _cpu(fn, repeats: int):
    best, out = float("inf"), None
    for _ in range(repeats):
        c0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - c0)
    return best, out


def _wrench_stages(df, r, repeats: int) -> dict[str, float]:
    """Best whole ``estimate_wrenches`` of ``repeats`` and its stages' exclusive times."""
    best: dict[str, float] = {"`estimate_wrenches`, whole": float("inf")}
    for _ in range(repeats):
        tm = _Timers(wrench, STAGES)
        try:
            c0 = time.process_time()
            wrench.estimate_wrenches(df, r)
            tot = time.process_time() - c0
        finally:
            tm.restore()
        if tot < best["`estimate_wrenches`, whole"]:
            best = {**tm.acc, "rest of `estimate_wrenches`": tot - sum(tm.acc.values()),
                    "`estimate_wrenches`, whole": tot}
    return best


def _channel_monitor(name: str):
    from importlib import resources

    from grfguard.detect.channels import ChannelConfig, ChannelMonitor

    f = resources.files("grfguard") / "data" / f"{name}_channels.toml"
    return ChannelMonitor(ChannelConfig.from_toml_text(f.read_text()))


def measure(name: str, duration: float, repeats: int, dump: str | None) -> dict:
    """Stage times of this interpreter's package on ``name``'s walk."""
    r = load_model(load_description(name))
    df = simulate_robot(r, scaled_gait(r, duration=duration), NoiseConfig(), seed=1)
    _COMPILED(df.iloc[:500], r)  # compile / load the kernels
    run_described(df.iloc[:2000], robot=r)
    res = _wrench_stages(df, r, repeats)
    log = with_described_vfs(df, r)
    if r.description.sensing == "ft":
        cm = _channel_monitor(name)
        res["channel monitor (`ChannelMonitor.run`)"] = _cpu(lambda: cm.run(log), repeats)[0]
    else:
        res["corner monitor + tracking"] = _cpu(lambda: run_described(log, robot=r),
                                                repeats)[0]
    t_all, out = _cpu(lambda: run_described(df, robot=r), repeats)
    res["`run_described`, whole"] = t_all
    if dump:
        out.to_pickle(dump)
    return {"n": len(df), "joints": len(r.joint_names), "bodies": r.model.nbody - 1,
            "stages": res}


def _max_diff(a: pd.DataFrame, b: pd.DataFrame) -> str:
    """Largest difference of the float columns [N, N m, s]; other columns compared
    for equality."""
    d, other = 0.0, 0
    for c in a.columns:
        if c not in b.columns:
            continue
        x, y = a[c].to_numpy(), b[c].to_numpy()
        if a[c].dtype.kind == "f":
            both = np.isnan(x) & np.isnan(y)
            if (np.isnan(x) != np.isnan(y)).any():
                return "NaN pattern differs in " + c
            d = max(d, float(np.max(np.abs(x[~both] - y[~both]), initial=0.0)))
        else:
            other += int((x != y).sum())
    return f"{d:.1e}" + ("" if other == 0 else f" ({other} flags/kinds differ)")


def references(name: str, duration: float, ref_repeats: int) -> list[str]:
    """The MuJoCo reference of the wrenches and the Python channel monitor, timed."""
    sys.path.insert(0, str(HERE.parent / "tests"))
    from reference.channels import PyChannelMonitor

    r = load_model(load_description(name))
    df = simulate_robot(r, scaled_gait(r, duration=duration), NoiseConfig(), seed=1)
    n = len(df)
    lines = []
    new = _COMPILED(df, r)
    old_t, old = _cpu(lambda: _COMPILED(df, r, compiled=False), ref_repeats)
    d = max(float(np.abs(new.ground - old.ground).max()),
            *(float(np.abs(new.sensor[k] - old.sensor[k]).max()) for k in new.sensor))
    lines.append(f"{name}: per-sample MuJoCo `estimate_wrenches(compiled=False)` "
                 f"{1e6 * old_t / n:.1f} µs/sample ({n / old_t / 1e3:.1f} k samples/s), "
                 f"largest difference to the compiled wrenches {d:.1e} N, N m")
    if r.description.sensing == "ft":
        log = with_described_vfs(df, r)
        cm = _channel_monitor(name)
        py = PyChannelMonitor(cm.config)
        py_t, py_out = _cpu(lambda: py.run(log), ref_repeats)
        lines.append(f"{name}: pure-Python channel monitor (tests/reference/channels.py) "
                     f"{1e6 * py_t / n:.1f} µs/sample ({n / py_t / 1e3:.1f} k samples/s), "
                     f"largest difference to the compiled one {_max_diff(cm.run(log), py_out)}")
    return lines


def _before(src: str, duration: float, repeats: int, tmp: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(Path(src).resolve() / "src")}
    out = subprocess.run([sys.executable, __file__, "--json-out", f"{tmp}/before.json",
                          "--dump-dir", tmp, "--duration", str(duration), "--repeats",
                          str(repeats)], env=env, check=True, capture_output=True, text=True)
    print(out.stderr[-2000:], file=sys.stderr)
    return json.loads(Path(f"{tmp}/before.json").read_text())


def _table(after: dict, before: dict | None, diffs: dict[str, str]) -> str:
    head = ("| robot | stage | samples | before: µs/sample (CPU) | after: µs/sample (CPU) | "
            "before: samples/s | after: samples/s | speed-up | max output difference "
            "(before vs after) |\n|---|---|---|---|---|---|---|---|---|")
    rows = [head]
    for name, a in after.items():
        n = a["n"]
        for stage, t in a["stages"].items():
            b = before[name]["stages"].get(stage) if before else None
            rows.append("| " + " | ".join([
                f"{name} ({a['joints']} joints, {a['bodies']} bodies)", stage, str(n),
                f"{1e6 * b / n:.2f}" if b else "-", f"{1e6 * t / n:.2f}",
                f"{n / b / 1e3:.0f} k" if b else "-", f"{n / t / 1e3:.0f} k",
                f"{b / t:.1f}x" if b else "-",
                diffs.get(name, "-") if stage.startswith("`run_described`") else ""]) + " |")
    return "\n".join(rows)


def _args(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0, help="walk length [s]")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--ref-repeats", type=int, default=1)
    ap.add_argument("--before-src", default=None, help="package sources to time as 'before'")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--json-out", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--dump-dir", default=None, help=argparse.SUPPRESS)
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> None:
    a = _args(argv)
    robots = ("talos", "g1")
    if a.json_out:  # the 'before' subprocess
        res = {nm: measure(nm, a.duration, a.repeats, f"{a.dump_dir}/{nm}.pkl")
               for nm in robots}
        Path(a.json_out).write_text(json.dumps(res))
        return
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        before = _before(a.before_src, a.duration, a.repeats, tmp) if a.before_src else None
        after = {nm: measure(nm, a.duration, a.repeats, f"{tmp}/{nm}.after.pkl")
                 for nm in robots}
        diffs = {nm: _max_diff(pd.read_pickle(f"{tmp}/{nm}.after.pkl"),
                               pd.read_pickle(f"{tmp}/{nm}.pkl")) for nm in robots} \
            if before else {}
    refs = [ln for nm in robots for ln in references(nm, a.duration, a.ref_repeats)] \
        if a.ref_repeats > 0 else []
    load1 = os.getloadavg()[0]
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    cmd = "taskset -c 1 .venv/bin/python benchmarks/bench_described_speed.py " + " ".join(
        sys.argv[1:] if argv is None else argv)
    body = (
        f"Command: `{cmd.strip()}` ({now}; {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}; load average {load0:.1f} -> {load1:.1f} on the "
        f"shared 2-core machine: CPU times are the figures). Noisy {a.duration:g} s walks "
        f"at 1 kHz (seed 1). Best CPU time of {a.repeats} runs; stage rows are exclusive "
        "times of `grfguard.estimate.wrench`'s stage functions in the best whole run. "
        + ("\"Before\": the sources of `" + a.before_src + "` timed in a subprocess of the "
           "same run; \"after\": this tree." if before else "") + "\n\n"
        + _table(after, before, diffs) + "\n\n" + "\n".join(f"- {ln}" for ln in refs) + "\n"
        + NOTES)
    print(body)
    if not a.no_write:
        _write(body)


def _write(body: str) -> None:
    """The new figures first, the section's previous text under "Earlier runs"."""
    import re

    from _common import BENCHMARKS_MD, update_section

    m = re.search(rf"^{re.escape(SECTION)}\n(.*?)(?=^## |\Z)", BENCHMARKS_MD.read_text(),
                  re.S | re.M)
    prev = m.group(1).strip() if m else ""
    mark = "### Earlier runs"
    latest, _, older = prev.partition(mark)
    earlier = (latest.strip() + "\n\n" + older.strip()).strip()
    update_section(SECTION, body + (f"\n{mark}\n\n{earlier}\n" if earlier else ""))


if __name__ == "__main__":
    main()
