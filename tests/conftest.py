"""Shared, cached simulated walks (session fixtures) for every test module.

Each fixture runs :func:`grfguard.sim.simulate` once per test session and returns the
log-contract DataFrame (``df.attrs`` carries robot, gait, noise, seed, ...). Treat the
returned frames as read-only (``df.copy()`` before modifying them).

Fixtures (duration; gait = step length, period, double support; noise; robot):

* ``default_walk``: 60 s; 0.12 m, 1.0 s, 20 %; default noise, seed 0; SURALP.
* ``clean_walk``: 20 s; 0.12 m, 1.0 s, 20 %; ``NoiseConfig.none()``; SURALP.
* ``fast_gait_walk``: 30 s; 0.15 m, 0.8 s, 20 %; default noise, seed 0; SURALP.
* ``slow_gait_walk``: 30 s; 0.08 m, 1.2 s, 20 %; default noise, seed 0; SURALP.
* ``small_robot_walk``: 30 s; 0.12 m, 1.0 s, 20 %; default noise, seed 0; ``small_robot``.

``small_robot`` is a 60 kg robot (foot 0.20 x 0.12 m, legs 0.22/0.21 m, sole-ankle
0.09 m, hip width 0.16 m) that walks with no hand tuning. Each walk costs about 1-3 s.
"""

from __future__ import annotations

import pandas as pd
import pytest

from grfguard.model.robot import SURALP, RobotConfig
from grfguard.sim import GaitConfig, NoiseConfig, simulate

SMALL_ROBOT = RobotConfig(
    name="small",
    mass=60.0,
    foot_length=0.20,
    foot_width=0.12,
    upper_leg_length=0.22,
    lower_leg_length=0.21,
    sole_to_ankle=0.09,
    hip_width=0.16,
)


def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile (fresh checkout: about 1.5-2 minutes, once) or load (about 1 s) the
    numba kernels before any test: ``Monitor.for_log`` runs them by default, and
    subprocesses, Dask workers or pytest-xdist workers would otherwise compile them each,
    at the same time."""
    if hasattr(session.config, "workerinput"):  # an xdist worker: the controller did it
        return
    from grfguard.kernels import warm_up

    warm_up()


@pytest.fixture(scope="session")
def small_robot() -> RobotConfig:
    """The 60 kg test robot of ``small_robot_walk``."""
    return SMALL_ROBOT


@pytest.fixture(scope="session")
def default_walk() -> pd.DataFrame:
    """60 s SURALP walk, default gait (0.12 m, 1.0 s, 20 % DS), default noise, seed 0."""
    return simulate(SURALP, GaitConfig(duration=60.0), NoiseConfig(), seed=0)


@pytest.fixture(scope="session")
def clean_walk() -> pd.DataFrame:
    """20 s SURALP walk, default gait, no noise (measured force == true force)."""
    return simulate(SURALP, GaitConfig(duration=20.0), NoiseConfig.none(), seed=0)


@pytest.fixture(scope="session")
def fast_gait_walk() -> pd.DataFrame:
    """30 s SURALP walk with 0.15 m steps every 0.8 s, default noise, seed 0."""
    return simulate(
        SURALP, GaitConfig(step_length=0.15, step_period=0.8, duration=30.0), NoiseConfig(), 0
    )


@pytest.fixture(scope="session")
def slow_gait_walk() -> pd.DataFrame:
    """30 s SURALP walk with 0.08 m steps every 1.2 s, default noise, seed 0."""
    return simulate(
        SURALP, GaitConfig(step_length=0.08, step_period=1.2, duration=30.0), NoiseConfig(), 0
    )


@pytest.fixture(scope="session")
def small_robot_walk(small_robot: RobotConfig) -> pd.DataFrame:
    """30 s walk of the 60 kg ``small_robot``, default gait and noise, seed 0."""
    return simulate(small_robot, GaitConfig(duration=30.0), NoiseConfig(), seed=0)


@pytest.fixture(scope="module")
def talos():
    """PAL Talos loaded from its URDF (example-robot-data), once per test module."""
    from grfguard.model.description import load_description
    from grfguard.model.loader import load_model

    return load_model(load_description("talos"))


@pytest.fixture(scope="module")
def g1():
    """Unitree G1 loaded from its URDF (example-robot-data), once per test module."""
    from grfguard.model.description import load_description
    from grfguard.model.loader import load_model

    return load_model(load_description("g1"))
