"""Does a feedback stabiliser converge to what ``RealityGap.controller = "balanced"``
simulates? (issue 10: the all-gaps robot walking balanced; an emulation, not a library
option).

The balanced controller plans the walk on the true body. A real robot instead plans on
its description and corrects online. This script emulates a common correction: an
integral ZMP feedback that estimates the horizontal CoM offset ``c`` from the measured
centre of pressure and shifts the planned motion by it.

- Each ``--chunk`` ms of physics, ``c`` grows by ``--gain`` times the mean error of the
  whole-body centre of pressure (the true corner forces, as the robot's own sole
  sensors would see them) against the planned ZMP, over the samples where both feet are
  planned to stand still (before and after the walk; ``--while-walking``: every sample
  with the feet loaded); the new value is ramped in over the next chunk.
- The joint references are those of the plan made on the description, moved by the
  planner's own first-order response to a trunk CoM offset: ``q(c) = q0 + (dq/dc_x) c_x +
  (dq/dc_y) c_y``, the derivatives from two more plans with the description's trunk CoM
  moved by 1 mm.
- The feed-forward torques stay the description's.

For the all-gaps robot (``grfguard/data/reality/all.toml``; calibration poses + walk,
60 s, seed 1), under the open-loop, balanced and stabilised controllers, the script
prints:

- where each stance sole's centre of pressure sits and the twist the soft contact
  carries (``bench_twist_cop.py``);
- the converged estimate ``c``;
- on ``--seeds``, the per-corner threshold after self-calibration (as ``bench_selfcal.py``
  does: weighed mass, rate low-pass chosen on the data) and its ratio to the exact
  model's on the same seed.

Usage: ``.venv/bin/python benchmarks/bench_stabiliser.py [--seeds 1,4] [--gain 0.05]
[--chunk 100] [--while-walking]``
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import sys
import time
from pathlib import Path

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from grfguard.calib import estimate_corrections
from grfguard.model.mjcf import build_model
from grfguard.model.robot import SENSOR_NAMES, SIDES, SURALP
from grfguard.sim import GaitConfig, simulate
from grfguard.sim.pattern import plan_walk
from grfguard.sim.reality import load_reality

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_selfcal import level, thresholds_of  # noqa: E402
from bench_twist_cop import sole_stats  # noqa: E402

SIM = importlib.import_module("grfguard.sim.simulate")
STEP_M = 0.001  # the trunk CoM moved by this much for the planner's response [m]


class Stabiliser:
    """Integral ZMP feedback on the horizontal CoM offset, for ``run_physics``'s
    signature (the description is ``SURALP``; ``trace`` keeps ``(t, c_x, c_y)``)."""

    def __init__(self, gain: float, chunk: int, standing_only: bool = True) -> None:
        self.gain, self.chunk, self.trace = gain, chunk, []
        self.standing_only = standing_only

    def run_physics(self, robot, plan, progress=None, progress_offset=0.0,
                    progress_scale=1.0, perturb=None):
        nominal = SURALP
        plans = [plan_walk(dataclasses.replace(
            nominal, trunk_com_x=nominal.trunk_com_x + STEP_M * (a == 0),
            trunk_com_y=nominal.trunk_com_y + STEP_M * (a == 1)), plan.gait) for a in (0, 1)]
        model = build_model(robot)
        if perturb is not None:
            import copy

            model = copy.copy(model)
            perturb(model)
        data = mujoco.MjData(model)
        index = SIM._sensor_index(model)
        ctrl0 = SIM._controls(robot, plan, model)
        # the planner's response to the CoM offset, per metre (position references only)
        dctrl = [(SIM._controls(robot, p, model) - ctrl0) / STEP_M for p in plans]
        SIM._start_at_rest(model, data, plan, ctrl0[0])
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        n_t = plan.time.size
        out = np.empty((n_t, model.nsensordata))
        state = np.empty(mujoco.mj_stateSize(model, spec))
        warm = np.zeros(model.nv)
        f_sl = [index[f"touch_{s}"] for s in SENSOR_NAMES]
        p_sl = [index[f"truth_corner_{s}_pos"] for s in SENSOR_NAMES]
        c, c_prev = np.zeros(2), np.zeros(2)
        self.trace = []
        for k0 in range(0, n_t, self.chunk):
            k1 = min(n_t, k0 + self.chunk)
            # the estimate ramps from its last value to its new one over the chunk
            ramp = np.linspace(0.0, 1.0, k1 - k0, endpoint=False)[:, None] + 1.0 / self.chunk
            cc = c_prev + (c - c_prev) * np.minimum(ramp, 1.0)
            c_prev = c.copy()
            ctrl = ctrl0[k0:k1] + dctrl[0][k0:k1] * cc[:, :1] + dctrl[1][k0:k1] * cc[:, 1:]
            mujoco.mj_getState(model, data, state, spec)
            _, sens = mj_rollout.rollout(model, data, initial_state=state[None],
                                         control=ctrl[None], initial_warmstart=warm[None])
            out[k0:k1] = sens[0]
            warm = data.qacc_warmstart.copy()
            f = np.column_stack([out[k0:k1, sl][:, 0] for sl in f_sl])
            p = np.stack([out[k0:k1, sl][:, :2] for sl in p_sl], axis=1)
            tot = f.sum(axis=1)
            ok = tot > 0.5 * 9.81 * robot.mass
            if self.standing_only:  # adapt only while both feet stand still, planned
                ok &= (plan.contact_ref[k0:k1].min(axis=1) > 0) & (
                    (plan.time[k0:k1] < plan.gait.start_time)
                    | (plan.time[k0:k1] > plan.step_times[-1] + plan.gait.step_period))
            if ok.any():
                cop = np.einsum("tk,tka->ta", f[ok], p[ok]) / tot[ok, None]
                c += self.gain * np.mean(cop - plan.zmp_ref[k0:k1][ok], axis=0)
            self.trace.append((float(plan.time[k1 - 1]), float(c[0]), float(c[1])))
        return SIM.PhysicsResult(out, index)


def walk(gap, seed: int, stab: Stabiliser | None):
    """The calibration data (poses, then the walk) of ``gap``'s robot; with ``stab``, its
    physics run by the stabiliser (the plan made on the description)."""
    saved = SIM.run_physics
    if stab is not None:
        SIM.run_physics = stab.run_physics
    try:
        return simulate(gait=GaitConfig(duration=60.0, calibration_poses=True), seed=seed,
                        reality=gap)
    finally:
        SIM.run_physics = saved


def corner_threshold(log) -> float:
    m_true = SURALP.mass * (1 + log.attrs["reality"]["mass_error"])
    th, *_ = thresholds_of(log, estimate_corrections(log, measured_mass_kg=m_true))
    return level(th)[0]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="1,4")
    ap.add_argument("--gain", type=float, default=0.05,
                    help="integral gain per chunk [m of CoM offset per m of CoP error]")
    ap.add_argument("--chunk", type=int, default=100, help="feedback period [ms]")
    ap.add_argument("--while-walking", action="store_true",
                    help="adapt while walking too (default: only while both feet stand "
                         "still, before and after the walk; the estimate is held while "
                         "walking)")
    args = ap.parse_args()
    t0 = time.time()
    gap = load_reality("all")
    robots = {"open loop": (gap, None),
              "balanced": (dataclasses.replace(gap, controller="balanced"), None),
              f"stabilised (gain {args.gain:g} per {args.chunk} ms"
              + (", adapting while walking" if args.while_walking else "") + ")":
                  (gap, Stabiliser(args.gain, args.chunk, not args.while_walking))}
    print("| robot | sole | CoP x [cm] | CoP y [cm] | twist RMS [N] | mean P R / S [N] |")
    print("|---|---|---|---|---|---|")
    for name, (g, stab) in robots.items():
        log = walk(g, 1, stab)
        for side in SIDES:
            cx, cy, t_rms, drive = sole_stats(log, side)
            print(f"| {name} | {side} | {cx:+.2f} | {cy:+.2f} | {t_rms:.1f} | {drive:+.1f} |",
                  flush=True)
        if stab is not None:
            tr = np.array(stab.trace)
            print("stabiliser estimate c [cm] at " + ", ".join(
                f"{t:g} s: ({100 * tr[np.searchsorted(tr[:, 0], t), 1]:+.2f}, "
                f"{100 * tr[np.searchsorted(tr[:, 0], t), 2]:+.2f})"
                for t in (1.0, 5.0, 15.0, 30.0, 45.0, 59.0)), flush=True)
    print("\n| seed | exact model | open loop | balanced | stabilised |")
    print("|---|---|---|---|---|")
    for seed in (int(s) for s in args.seeds.split(",")):
        exact = level(thresholds_of(simulate(gait=GaitConfig(duration=60.0), seed=seed))[0])[0]
        row = [corner_threshold(walk(g, seed, stab)) for g, stab in robots.values()]
        print(f"| {seed} | {exact:.3f} | " + " | ".join(
            f"{v:.3f} ({v / exact:.2f}x)" for v in row) + " |", flush=True)
    print(f"\nruntime {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
