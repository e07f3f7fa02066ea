"""Where the all-gaps robot's centres of pressure sit, and the contact twist they cause
(issue 10: why the per-corner threshold grows without the leg-to-trunk mass shift).

The robots of ``bench_selfcal_gaps.py`` (every gap of ``grfguard/data/reality/all.toml``,
or every gap but one) walk the calibration data (poses, then 28 steps; seed 1). From the
simulation's truth columns, over planned single support of the walk (every true corner
force over 20 N): each stance sole's mean centre of pressure relative to the sole centre,
the RMS of its twist ``T = f1 - f2 - f3 + f4`` and the mean of ``P R / S`` (``P`` front
minus rear, ``R`` left minus right, ``S`` the sole's load), which drives that twist on
MuJoCo's soft contact (BENCHMARKS.md "Model self-calibration: contact twist"). The seed
draws sensor noise only: the physics, hence this table, is the same for every seed. The
last robot is the first walking balanced: its walk planned on its true body.

Usage: ``.venv/bin/python benchmarks/bench_twist_cop.py``
"""

from __future__ import annotations

import dataclasses

import numpy as np

from grfguard.model.robot import SIDES
from grfguard.sim import GaitConfig, simulate
from grfguard.sim.reality import load_reality

WALK_FROM_S = 31.0  # the calibration poses end at 30.3 s


def sole_stats(log, side: str) -> tuple[float, float, float, float]:
    """Mean CoP x, y [cm] from the sole centre, twist RMS [N], mean P R / S [N]."""
    other = "l" if side == "r" else "r"
    f = np.column_stack([log[f"true_force_{side}{k}"].to_numpy() for k in range(1, 5)])
    ss = ((log["time"].to_numpy() > WALK_FROM_S)
          & (log[f"contact_ref_{side}"].to_numpy() > 0.5)
          & (log[f"contact_ref_{other}"].to_numpy() < 0.5) & (f > 20.0).all(axis=1))
    f = f[ss]
    S = f.sum(axis=1)
    P = f[:, 0] + f[:, 1] - f[:, 2] - f[:, 3]
    R = f[:, 0] + f[:, 2] - f[:, 1] - f[:, 3]
    T = f[:, 0] - f[:, 1] - f[:, 2] + f[:, 3]
    cx = (log[f"true_cop_{side}_x"] - log[f"true_sole_{side}_x"]).to_numpy()[ss]
    cy = (log[f"true_cop_{side}_y"] - log[f"true_sole_{side}_y"]).to_numpy()[ss]
    return (100 * float(np.mean(cx)), 100 * float(np.mean(cy)),
            float(np.sqrt(np.mean(T**2))), float(np.mean(P * R / S)))


def main() -> None:
    gap = load_reality("all")
    robots = {
        "every gap": gap,
        "every gap but `trunk_mass_fraction_delta`":
            dataclasses.replace(gap, trunk_mass_fraction_delta=0.0),
        "every gap but `trunk_com_offset_m`":
            dataclasses.replace(gap, trunk_com_offset_m=(0.0, 0.0, 0.0)),
        "every gap, walking balanced (`controller = \"balanced\"`)":
            dataclasses.replace(gap, controller="balanced"),
    }
    print("| robot | sole | CoP x [cm] | CoP y [cm] | twist RMS [N] | mean P R / S [N] |")
    print("|---|---|---|---|---|---|")
    for name, g in robots.items():
        log = simulate(gait=GaitConfig(duration=60.0, calibration_poses=True), seed=1, reality=g)
        for side in SIDES:
            cx, cy, t_rms, drive = sole_stats(log, side)
            print(f"| {name} | {side} | {cx:+.2f} | {cy:+.2f} | {t_rms:.1f} | {drive:+.1f} |")


if __name__ == "__main__":
    main()
