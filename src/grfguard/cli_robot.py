"""``grfguard robot list|show`` and the simulation of described robots (Talos, G1, ...).

``grfguard simulate --robot NAME`` routes here when NAME is a shipped description
(``talos``, ``g1``) or a TOML with a ``model`` key (:mod:`grfguard.model.description`);
SURALP and SURALP-shaped TOMLs keep the original simulation.
"""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path
from typing import Annotated, Any

import typer

from grfguard._term import cli_friendly as _friendly
from grfguard._term import console, out
from grfguard._term import progress as _progress

__all__ = ["robot_app", "is_described_robot", "simulate_described", "decimate_cmd"]

robot_app = typer.Typer(help="Robot descriptions.", no_args_is_help=True)


def is_described_robot(robot: str | Path | None) -> bool:
    """True when ``robot`` names a shipped description or a TOML with a ``model`` key."""
    if robot is None:
        return False
    from grfguard.model.description import shipped_robots

    if str(robot) in shipped_robots():
        return True
    p = Path(robot)
    if p.suffix.lower() != ".toml" or not p.exists():
        return False
    try:
        return "model" in tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError:
        return False


@robot_app.command("list")
@_friendly
def robot_list() -> None:
    """List the shipped robots."""
    from grfguard.model.description import load_description, shipped_robots

    for name in shipped_robots():
        d = load_description(name)
        model = "grfguard's MJCF of the paper's biped" if name == "suralp" else d.model.name
        out.print(f"{name}\t{model}, {d.sensing} sensing", highlight=False)


@robot_app.command("show")
@_friendly
def robot_show(
    name: Annotated[str | None, typer.Argument(help="suralp, talos, g1 or a TOML.")] = None,
    robot: Annotated[Path | None, typer.Option(help="SURALP-shaped robot TOML.")] = None,
) -> None:
    """Print a robot: SURALP's TOML (copy and edit it), or a described robot's summary."""
    if name is not None and is_described_robot(name):
        _show_described(name)
        return
    from grfguard.model.robot import load_robot

    path = robot if robot is not None else (None if name in (None, "suralp") else Path(name))
    sys.stdout.write(load_robot(path).to_toml())


def _show_described(name: str) -> None:
    from grfguard.model.description import load_description
    from grfguard.model.loader import load_model

    d = load_description(name)
    r = load_model(d)
    lines = [
        f"name        {d.name}",
        f"model       {d.model}",
        f"description {d.source}",
        f"mass        {r.mass:.2f} kg",
        f"joints      {len(r.joint_names)}",
        f"leg length  {r.leg_length:.3f} m (hip to sole)",
        f"sensing     {d.sensing}: {', '.join(d.force_columns)}",
        f"imu         body {d.imu_body}, pos {list(d.imu.pos)}",
    ]
    for s, leg, f in zip(("right", "left"), r.leg_joints, d.feet, strict=True):
        lines.append(f"{s:<5} foot  {f.body}, sole {f.length} x {f.width} m at {list(f.sole.pos)}")
        lines.append(f"{s:<5} leg   {', '.join(leg)}")
    lines.append("columns     " + ", ".join(f"q_{j}" for j in r.joint_names))
    out.print("\n".join(lines), highlight=False, soft_wrap=True)


def simulate_described(
    robot: str | Path, output: Path, duration: float, step_length: float | None,
    step_period: float | None, double_support: float | None, seed: int, noise: str,
    rate: float = 1000.0,
) -> Any:
    """Simulate a described robot on its scaled default gait and write the log."""
    from grfguard.errors import ConfigError
    from grfguard.io.logio import write_log
    from grfguard.model.description import load_description
    from grfguard.model.loader import load_model
    from grfguard.sim import NoiseConfig
    from grfguard.sim.wholebody import scaled_gait, simulate_robot

    if noise not in ("default", "none"):
        raise ConfigError(f"--noise must be 'default' or 'none', got {noise!r}")
    r = load_model(load_description(str(robot)))
    gait = scaled_gait(r, duration=duration, step_length=step_length,
                       step_period=step_period, double_support=double_support)
    noise_cfg = NoiseConfig() if noise == "default" else NoiseConfig.none()
    with _progress("simulate") as prog:
        task = prog.add_task("simulate", total=1.0)
        df = simulate_robot(r, gait, noise_cfg, seed=seed, sample_rate=rate,
                            progress=lambda f: prog.update(task, completed=f))
    write_log(df, output)
    console.print(f"wrote {output}: {len(df)} samples, {df['time'].iloc[-1]:.2f} s, "
                  f"robot {r.description.name} ({len(r.joint_names)} joints, {r.mass:.2f} kg)")
    return df


@_friendly
def decimate_cmd(
    log: Annotated[Path, typer.Argument(help="Input log (1 kHz).")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Log to write.")],
    rate: Annotated[float, typer.Option(help="New sample rate [Hz], dividing the log's.")],
) -> None:
    """Keep every k-th sample of a log (e.g. 1 kHz -> 200 Hz or 100 Hz)."""
    from grfguard.io.logio import read_log, write_log
    from grfguard.sim.wholebody import decimate

    df = decimate(read_log(log), rate)
    write_log(df, output)
    console.print(f"wrote {output}: {len(df)} samples at {rate:g} Hz")
