"""Frozen, validated configurations of the walking simulation.

:class:`GaitConfig` describes the walk (footsteps, timing, CoM height) and
:class:`NoiseConfig` the sensor imperfections added to the clean MuJoCo signals.
Both round-trip through plain dicts (``to_dict`` / ``from_dict``) for log metadata
and TOML scenario files.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from grfguard._validate import check_number
from grfguard.errors import ConfigError

__all__ = ["GaitConfig", "NoiseConfig"]


def _num(owner: str, name: str, value: Any, lo: float, hi: float, unit: str) -> None:
    check_number(owner, name, value, lo, hi, unit)


def _from_dict(cls, data: dict[str, Any], owner: str):
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(f"unknown {owner} key(s) {unknown}; known keys: {sorted(known)}")
    return cls(**data)


@dataclass(frozen=True)
class GaitConfig:
    """A straight walk on flat ground, planned by ZMP preview control.

    Timeline: stand still for ``start_time``; then steps of ``step_period`` each, a
    double-support phase (``double_support * step_period``, the ZMP moves to the new
    support foot) followed by single support (the other foot swings); the first and
    the last step move the swing foot by one ``step_length``, the others by two (foot
    placements advance by ``step_length``); after the last step the ZMP returns to the
    middle of the feet and the robot stands until ``duration``. ``first_swing`` says
    which foot makes the first step; the default, the right foot, gives the faulty
    foot of the paper's scenario the timing of the prototype in DESIGN.md (onset at
    5 s late in its stance, swing from about 5.2 s).

    Attributes:
        step_length: Forward distance between consecutive footprints in [m].
        step_period: Duration of one step (double + single support) in [s].
        double_support: Fraction of the step period in double support, in (0, 1).
        duration: Total simulated time in [s].
        com_height: Planned (constant) CoM height above the ground in [m]; None picks
            the robot's default (knees bent so the hip-ankle distance is 88 % of the
            leg, :func:`grfguard.sim.pattern.default_com_height`).
        swing_height: Peak sole height of the swing foot in [m]; None means
            6 % of the robot's hip-to-sole length (4 cm for SURALP).
        start_time: Standing time before the first step in [s].
        stop_time: Minimum standing time after the last step in [s].
        preview_dt: Sampling period of the preview controller in [s].
        preview_horizon: Preview horizon in [s].
        com_iterations: Pelvis corrections that make the model CoM follow the plan.
        zmp_passes: Second-stage preview passes that correct the CoM plan so the
            multibody ZMP (swing legs included) follows the reference (0 = cart-table
            plan only).
        torque_feedforward: Add inverse-dynamics torques of the planned motion to the
            position servos (removes the stance-leg sag and the tracking lag of an
            open-loop walk).
        first_swing: The foot that makes the first step, ``r`` or ``l``.
        calibration_poses: Start with the calibration routine of
            :mod:`grfguard.sim.routine` (SURALP-type robots): standing, each sole in turn
            tilted 2 deg onto each of its corners and held 1.5 s while the other foot
            carries most of the weight (30.3 s); ``start_time`` is lengthened to
            cover it. For ``grfguard calibrate --model`` data: the corner poses make
            each sole's load-cell gains identifiable (a walk loads the corners only
            planarly).
    """

    step_length: float = 0.12
    step_period: float = 1.0
    double_support: float = 0.2
    duration: float = 60.0
    com_height: float | None = None
    swing_height: float | None = None
    start_time: float = 1.0
    stop_time: float = 1.0
    preview_dt: float = 0.005
    preview_horizon: float = 1.6
    com_iterations: int = 3
    zmp_passes: int = 1
    torque_feedforward: bool = True
    first_swing: str = "r"
    calibration_poses: bool = False

    def __post_init__(self) -> None:
        o = "gait"
        _num(o, "step_length", self.step_length, 0.0, 1.0, "m")
        _num(o, "step_period", self.step_period, 0.2, 10.0, "s")
        _num(o, "double_support", self.double_support, 0.02, 0.9, "")
        _num(o, "duration", self.duration, 0.1, 36000.0, "s")
        if self.com_height is not None:
            _num(o, "com_height", self.com_height, 0.05, 5.0, "m")
        if self.swing_height is not None:
            _num(o, "swing_height", self.swing_height, 0.0, 1.0, "m")
        _num(o, "start_time", self.start_time, 0.2, 60.0, "s")
        _num(o, "stop_time", self.stop_time, 0.0, 60.0, "s")
        _num(o, "preview_dt", self.preview_dt, 0.001, 0.05, "s")
        _num(o, "preview_horizon", self.preview_horizon, 0.2, 5.0, "s")
        if not isinstance(self.com_iterations, int) or not 0 <= self.com_iterations <= 20:
            raise ConfigError(
                f"gait.com_iterations = {self.com_iterations!r} must be an integer in [0, 20]"
            )
        if not isinstance(self.zmp_passes, int) or not 0 <= self.zmp_passes <= 5:
            raise ConfigError(
                f"gait.zmp_passes = {self.zmp_passes!r} must be an integer in [0, 5]"
            )
        if self.first_swing not in ("r", "l"):
            raise ConfigError(
                f"gait.first_swing = {self.first_swing!r} must be 'r' or 'l' (the foot that "
                "makes the first step)"
            )
        if not isinstance(self.calibration_poses, bool):
            raise ConfigError(
                f"gait.calibration_poses = {self.calibration_poses!r} must be true or false"
            )
        if not isinstance(self.torque_feedforward, bool):
            raise ConfigError(
                f"gait.torque_feedforward = {self.torque_feedforward!r} must be true or false"
            )
        if abs(self.preview_dt / 0.001 - round(self.preview_dt / 0.001)) > 1e-9:
            raise ConfigError(
                f"gait.preview_dt = {self.preview_dt} s must be a multiple of the 1 ms "
                "simulation step"
            )
        if self.duration < self.start_time + self.stop_time:
            raise ConfigError(
                f"gait.duration = {self.duration} s is shorter than start_time + stop_time "
                f"= {self.start_time + self.stop_time} s; lengthen the walk"
            )

    @property
    def n_steps(self) -> int:
        """Number of steps that fit in ``duration`` (0 means standing only)."""
        room = self.duration - self.start_time - self.stop_time - self.double_support_time
        return max(0, int(math.floor(room / self.step_period + 1e-9)))

    @property
    def double_support_time(self) -> float:
        """Double-support time of one step in [s]."""
        return self.double_support * self.step_period

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of the fields (None kept as None)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> GaitConfig:
        """Build from a dict; unknown keys raise :class:`ConfigError`."""
        return _from_dict(cls, data, "gait")


@dataclass(frozen=True)
class NoiseConfig:
    """Sensor imperfections added to the clean simulated signals.

    Every random draw comes from ``numpy.random.default_rng(seed)`` of
    :func:`grfguard.sim.simulate`. Forces are not clipped at zero (a real load cell
    reads noise around zero in swing).

    Attributes:
        force_sigma: White noise of every sole force sensor in [N] (default 2 N).
        acc_sigma: Accelerometer white noise per axis in [m/s^2] (default 0.05).
        acc_bias_sigma: Std of the constant accelerometer bias drawn once per axis in
            [m/s^2] (default 0.02).
        gyro_sigma: Gyro white noise per axis in [rad/s] (default 0.005).
        gyro_bias_sigma: Std of the constant gyro bias per axis in [rad/s]
            (default 0.001).
        attitude_sigma: White small-angle error of the attitude quaternion per axis in
            [rad] (default 0.001).
        attitude_bias_sigma: Std of a constant small-angle attitude error per axis in
            [rad] (default 0.002, about 0.1 deg).
        encoder_counts_per_rev: Encoder resolution; angles are rounded to
            ``2 pi / counts`` [rad]. 0 disables quantization (default 2**17).
    """

    force_sigma: float = 2.0
    acc_sigma: float = 0.05
    acc_bias_sigma: float = 0.02
    gyro_sigma: float = 0.005
    gyro_bias_sigma: float = 0.001
    attitude_sigma: float = 0.001
    attitude_bias_sigma: float = 0.002
    encoder_counts_per_rev: int = 2**17

    def __post_init__(self) -> None:
        o = "noise"
        _num(o, "force_sigma", self.force_sigma, 0.0, 1e4, "N")
        _num(o, "acc_sigma", self.acc_sigma, 0.0, 100.0, "m/s^2")
        _num(o, "acc_bias_sigma", self.acc_bias_sigma, 0.0, 100.0, "m/s^2")
        _num(o, "gyro_sigma", self.gyro_sigma, 0.0, 10.0, "rad/s")
        _num(o, "gyro_bias_sigma", self.gyro_bias_sigma, 0.0, 10.0, "rad/s")
        _num(o, "attitude_sigma", self.attitude_sigma, 0.0, 0.5, "rad")
        _num(o, "attitude_bias_sigma", self.attitude_bias_sigma, 0.0, 0.5, "rad")
        c = self.encoder_counts_per_rev
        if not isinstance(c, int) or isinstance(c, bool) or c < 0:
            raise ConfigError(
                f"noise.encoder_counts_per_rev = {c!r} must be a non-negative integer "
                "(0 disables quantization)"
            )

    @classmethod
    def none(cls) -> NoiseConfig:
        """Clean data: no noise, no bias, no quantization."""
        return cls(
            force_sigma=0.0,
            acc_sigma=0.0,
            acc_bias_sigma=0.0,
            gyro_sigma=0.0,
            gyro_bias_sigma=0.0,
            attitude_sigma=0.0,
            attitude_bias_sigma=0.0,
            encoder_counts_per_rev=0,
        )

    @property
    def is_clean(self) -> bool:
        """True when this adds nothing to the clean signals."""
        return self == NoiseConfig.none()

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of the fields."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> NoiseConfig:
        """Build from a dict; unknown keys raise :class:`ConfigError`."""
        return _from_dict(cls, data, "noise")
