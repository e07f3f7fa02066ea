"""A shipped campaign on the default local Dask cluster: throughput and what it finds.

Runs ``campaigns/paper-onset.toml`` (846 cells: the paper's scenario over onset phase x
fault size x seeds, both methods, plus a threshold-scale sweep and fault-free 60 s
walks) with ``grfguard.campaign.run_campaign`` on a local cluster, writes the report
and the ``## Campaigns on Dask`` section of BENCHMARKS.md: cells per minute, the
smallest fault of each kind detected in 95 % of runs (both methods), false alarms per
hour and the delay-vs-false-alarm curve.

Usage:
    .venv/bin/python benchmarks/bench_campaign.py [--workers 2] [--no-write]
    (results in out/campaigns/<name>/, report in out/campaigns/<name>-report/;
    a rerun reuses the results and recomputes nothing)
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, update_section  # noqa: E402

from grfguard.campaign import ResultStore, load_spec  # noqa: E402
from grfguard.campaign.report import CampaignReport  # noqa: E402
from grfguard.campaign.runner import run_campaign  # noqa: E402

SECTION = "## Campaigns on Dask"


def _f(v: float, fmt: str = "{:.3g}") -> str:
    return "–" if v is None or (isinstance(v, float) and math.isnan(v)) else fmt.format(v)


def _unit(kind: str, v: float) -> str:
    if isinstance(v, float) and math.isnan(v):
        return "not reached"
    return {"offset": f"{v:g} N", "drift": f"{v:g} N/s", "gain": f"×{v:g}",
            "noise": f"σ {v:g} N", "spikes": f"{v:g} N"}.get(kind, f"{v:g}")


def body(spec_path: Path, store: ResultStore, rep: CampaignReport, note: str = "") -> str:
    runs = [r for r in store.runs() if r.get("n_computed", 0) > 0]
    last = runs[-1] if runs else {}
    d = rep.df
    try:
        shown = spec_path.relative_to(ROOT)
    except ValueError:
        shown = spec_path
    name = store.root.name
    lines = [
        f"Command: `.venv/bin/python benchmarks/bench_campaign.py` (= `grfguard campaign run "
        f"{shown} -o out/campaigns/{name}` then `grfguard campaign "
        "report`), default local cluster (single-threaded worker processes on 127.0.0.1) on "
        "this 2-core machine, shared with other jobs.",
        "",
        f"- cells: {len(d)} on {d['walk_id'].nunique()} walks (simulated once each); "
        f"computed in the last run: {last.get('n_computed', 0)} with "
        f"{last.get('workers', '?')} workers in {_f(last.get('compute_s', math.nan), '{:.0f}')} s "
        f"= **{_f(last.get('cells_per_min', math.nan), '{:.0f}')} cells/min**; mean compute per "
        f"cell {d['compute_s'].mean():.2f} s (11 s walks; 60 s for fault-free cells)"
        + (f"; load average {last['load_avg_1min']:.1f} at the end of the run"
           if "load_avg_1min" in last else "") + (f". {note}" if note else ""),
        "",
        "Smallest fault detected in 95 % of runs (threshold scale 1; 12 runs per size = "
        "4 onsets over one stride x 3 seeds; every larger tested size also >= 95 %):",
        "",
        "| kind | default | paper | tested sizes |",
        "|---|---|---|---|",
    ]
    m = rep.min_detectable
    for kind in sorted(m["kind"].unique()):
        row = m[m["kind"] == kind].set_index("method")
        cells = [_unit(kind, float(row.loc[meth, "min_size"])) if meth in row.index else "–"
                 for meth in ("default", "paper")]
        lines.append(f"| {kind} | {cells[0]} | {cells[1]} | {row['tested'].iloc[0]} |")
    lines += [
        "",
        "Delay against false alarms over the threshold scale (faults: r2 +20 N and r3 "
        "+3 N/s, 24 runs per method and scale; false alarms from fault-free 60 s walks, "
        "3 per method and scale, all eight sensors, exact Poisson 95 % interval):",
        "",
        "| method | scale | detection rate | median delay [s] | p90 delay [s] | "
        "false alarms/h | 95 % CI [1/h] |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rep.curve.itertuples(index=False):
        lines.append(
            f"| {r.method} | ×{r.threshold_scale:g} | {r.detection_rate:.0%} | "
            f"{_f(r.delay_median_s, '{:.2f}')} | {_f(r.delay_p90_s, '{:.2f}')} | "
            f"{_f(r.false_alarms_per_hour, '{:.0f}')} | "
            f"[{_f(r.per_hour_lo, '{:.0f}')}, {_f(r.per_hour_hi, '{:.0f}')}] |"
        )
    det = rep.detection
    lines += ["", "Detection rate and median delay [s] per kind and size (scale 1):", "",
              "| kind | size | default rate | default delay | paper rate | paper delay |",
              "|---|---|---|---|---|---|"]
    for (kind, size), g in det.groupby(["kind", "size"], dropna=False, sort=True):
        by = g.set_index("method")

        def cell(col: str, meth: str, fmt: str, by: pd.DataFrame = by) -> str:
            return _f(float(by.loc[meth, col]), fmt) if meth in by.index else "–"

        lines.append(f"| {kind} | {'–' if math.isnan(size) else f'{size:g}'} | "
                     f"{cell('rate', 'default', '{:.0%}')} | "
                     f"{cell('delay_median_s', 'default', '{:.2f}')} | "
                     f"{cell('rate', 'paper', '{:.0%}')} | "
                     f"{cell('delay_median_s', 'paper', '{:.2f}')} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spec", type=Path, default=ROOT / "campaigns" / "paper-onset.toml")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "campaigns")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--note", default="", help="Conditions of the run, for BENCHMARKS.md.")
    args = ap.parse_args()
    spec = load_spec(args.spec)
    results = args.out / spec.name
    summary = run_campaign(spec, results, n_workers=args.workers)
    print(summary, f"{summary.cells_per_min:.0f} cells/min")
    rep = CampaignReport(results)
    print("report:", rep.write(args.out / f"{spec.name}-report"))
    text = body(args.spec.resolve(), ResultStore(results), rep, args.note)
    print(text)
    if not args.no_write:
        update_section(SECTION, text)


if __name__ == "__main__":
    main()
