"""The paper's scenario end to end (``grfguard demo`` / ``make demo``).

1. Simulate the default SURALP walk (MuJoCo, default sensor noise).
2. Inject the faults of the paper's section IV at t = 5 s on the right foot:
   ``r1`` frozen at 0, ``r2`` +100 N offset, ``r3`` +15 N/s drift, ``r4`` -100 N offset.
3. Run the monitor on the same input three ways: the paper as published (its virtual
   sensor and observer), the paper's observer on grfguard's virtual sensor, and
   grfguard's default.
4. Evaluate both against the truth, write a metrics table, the analogues of the
   paper's Figures 4-7 and a standalone HTML report.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from grfguard.config import monitor_config
from grfguard.evaluate.frame import evaluate_frame
from grfguard.io.logio import to_jsonable, write_log
from grfguard.io.safe import atomic_write_text

__all__ = ["PAPER_FAULTS", "RUNS", "run_demo", "plot_corner_forces"]

#: The runs compared: name -> (detection method, virtual sensor). ``paper`` is the
#: paper as published; ``paper-observer`` its observer on grfguard's virtual sensor.
RUNS = {
    "paper": ("paper", "paper"),
    "paper-observer": ("paper", "default"),
    "default": ("default", "default"),
}

#: The paper's scenario (section IV), as fault specs.
PAPER_FAULTS = ("r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5", "r4=offset:-100@5")


def run_demo(
    out_dir: str | Path,
    duration: float = 60.0,
    seed: int = 0,
    console: Console | None = None,
    out: Console | None = None,
) -> dict[str, Any]:
    """Run the paper's scenario and write everything to ``out_dir``.

    Args:
        out_dir: Output directory (created).
        duration: Walk duration in [s].
        seed: Seed of the sensor noise.
        console: Where progress goes (stderr).
        out: Where the results table goes (stdout).

    Returns:
        The metrics of both methods.
    """
    console = console or Console(stderr=True)
    out = out or Console()
    if not out.is_terminal:
        out = Console(width=160)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    faulty = _walk_with_faults(out_dir, duration, seed, console)
    runs, results = _run_methods(faulty, out_dir, console)
    console.print("[bold]4/5[/] writing figures and metrics")
    atomic_write_text(out_dir / "metrics.json", json.dumps(to_jsonable(results), indent=2))
    atomic_write_text(out_dir / "metrics.md", _metrics_markdown(results))
    pngs = _write_figures(runs, results, out_dir)
    console.print("[bold]5/5[/] writing the HTML report")
    report = _write_reports(runs, results, out_dir)
    _print_table(results, out)
    console.print("figures: " + ", ".join(f"{n} in {escape(str(d))}" for d, n in pngs.items()))
    out.print(f"report: {escape(str(report.resolve()))}")
    return results


def _walk_with_faults(out_dir: Path, duration: float, seed: int, console: Console) -> Any:
    """Steps 1-2: the simulated walk and its faulty copy (both written to ``out_dir``)."""
    from grfguard.faults import inject_faults, parse_fault_spec
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    console.print(f"[bold]1/5[/] simulating a {duration:g} s SURALP walk (seed {seed})")
    walk = simulate(gait=GaitConfig(duration=duration), noise=NoiseConfig(), seed=seed)
    write_log(walk, out_dir / "walk.parquet")
    fig, _ = plot_corner_forces(walk)
    fig.savefig(out_dir / "corner_forces.png", dpi=120)
    console.print("[bold]2/5[/] injecting the paper's faults: " + ", ".join(PAPER_FAULTS))
    faulty = inject_faults(walk, [parse_fault_spec(s) for s in PAPER_FAULTS], seed=seed)
    write_log(faulty, out_dir / "walk_faulty.parquet")
    return faulty


def _run_methods(
    faulty: Any, out_dir: Path, console: Console
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Step 3: every run of :data:`RUNS` on the faulty walk, and its metrics."""
    from grfguard.detect import Monitor

    runs, results = {}, {}
    for method, (observer, vfs) in RUNS.items():
        console.print(f"[bold]3/5[/] running the monitor: {method}")
        res = Monitor.for_log(faulty, config=monitor_config(method=observer, vfs=vfs)).run(faulty)
        write_log(res, out_dir / f"run_{method}.parquet")
        runs[method] = res
        results[method] = evaluate_frame(res)
    return runs, results


def _sensor_metrics(results: dict[str, Any], method: str) -> Any:
    return results[method].get("detection", {}).get("sensors")


def _write_figures(runs: dict[str, Any], results: dict[str, Any],
                   out_dir: Path) -> dict[Path, int]:
    """PNG figures of the default run (whole walk and 3-9 s) and of the paper's run;
    returns the number written per folder."""
    from grfguard.report.figures import write_png_figures

    metrics = _sensor_metrics(results, "default")
    dirs = {name: out_dir / name for name in ("figures", "figures_zoom", "figures_paper")}
    counts = {dirs["figures"]: len(write_png_figures(runs["default"], dirs["figures"],
                                                     metrics=metrics))}
    # The same figures over six seconds around the onset, where single steps are visible.
    counts[dirs["figures_zoom"]] = len(write_png_figures(
        runs["default"], dirs["figures_zoom"], metrics=metrics, t_range=(3.0, 9.0),
        per_sensor=False))
    counts[dirs["figures_paper"]] = len(write_png_figures(
        runs["paper"], dirs["figures_paper"], metrics=_sensor_metrics(results, "paper")))
    return counts


def _write_reports(runs: dict[str, Any], results: dict[str, Any], out_dir: Path) -> Path:
    """HTML reports of the default and the paper's run; returns the default one's path."""
    from grfguard.report.html import write_html_report

    for method, name, label in (("paper", "report_paper.html", "paper's method"),
                                ("default", "report.html", "default method")):
        path = write_html_report(
            runs[method], out_dir / name, metrics=_sensor_metrics(results, method),
            title=f"grfguard: the paper's scenario ({label})",
        )
    return path


def plot_corner_forces(log: Any, t_max: float = 6.0) -> tuple[Any, Any]:
    """Measured and true force of every corner sensor over the first ``t_max`` seconds.

    Returns:
        ``(fig, axes)``: one row per foot.
    """
    from matplotlib.figure import Figure

    from grfguard.model.robot import SIDES

    sel = log["time"] <= t_max
    t = log["time"][sel]
    fig = Figure(figsize=(10, 6), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    for ax, side in zip(axes, SIDES, strict=True):
        for k, colour in zip(range(1, 5), ("C0", "C1", "C2", "C3"), strict=True):
            s = f"{side}{k}"
            ax.plot(t, log[f"force_{s}"][sel], color=colour, lw=0.6, alpha=0.6,
                    label=f"{s} measured")
            if f"true_force_{s}" in log:
                ax.plot(t, log[f"true_force_{s}"][sel], color=colour, lw=1.2, ls="--",
                        label=f"{s} true")
        ax.set_ylabel(f"{'right' if side == 'r' else 'left'} foot force [N]")
        ax.grid(alpha=0.3)
        ax.legend(ncol=4, fontsize=8, loc="upper right")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle("Sole sensor forces of the simulated walk")
    return fig, axes


_DET_KEYS = (
    ("detected", "detected"),
    ("delay_s", "delay [s]"),
    ("kind_estimated", "kind found"),
    ("kind_correct", "kind ok"),
    ("false_alarms", "false alarms"),
    ("recovery_rmse_n", "recovery RMSE [N]"),
    ("fault_size_error_n", "size error [N]"),
)


def _rows(results: dict[str, Any]) -> list[list[str]]:
    """One row per faulty sensor, plus one per healthy sensor that raised an alarm."""
    rows = []
    for method, res in results.items():
        det = res.get("detection", {}).get("sensors", {})
        for sensor, m in det.items():
            if m.get("faulty") or (m.get("false_alarms") or 0) > 0:
                rows.append([method, sensor, str(m.get("fault_kind", "none"))]
                            + [_fmt(m.get(k)) for k, _ in _DET_KEYS])
        healthy_fa = sum(
            (m.get("false_alarms") or 0) for m in det.values() if not m.get("faulty")
        )
        n_healthy = sum(1 for m in det.values() if not m.get("faulty"))
        rows.append([method, f"{n_healthy} healthy", "none", "-", "-", "-", "-",
                     str(healthy_fa), "-", "-"])
    return rows


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return "nan" if v != v else f"{v:.3g}"
    return str(v)


def _metrics_markdown(results: dict[str, Any]) -> str:
    head = ["method", "sensor", "true kind"] + [label for _, label in _DET_KEYS]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in _rows(results)]
    return "\n".join(lines) + "\n"


def _print_table(results: dict[str, Any], out: Console) -> None:
    table = Table(title="the paper's scenario: detection and recovery")
    for h in ["method", "sensor", "true kind"] + [label for _, label in _DET_KEYS]:
        table.add_column(h, no_wrap=True)
    for r in _rows(results):
        table.add_row(*r)
    out.print(table)
