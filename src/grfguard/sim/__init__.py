"""MuJoCo walking simulation: footsteps, ZMP preview control, leg IK, sensors -> log."""

from __future__ import annotations

from grfguard.sim.config import GaitConfig, NoiseConfig
from grfguard.sim.pattern import WalkPlan, plan_walk
from grfguard.sim.simulate import SCENARIO, simulate

__all__ = ["GaitConfig", "NoiseConfig", "WalkPlan", "plan_walk", "simulate", "SCENARIO"]
