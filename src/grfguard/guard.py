"""Input and continuity guards of the monitor: glitches, gaps and absurd values.

Two small stages that :class:`~grfguard.pipeline.Monitor` runs around the virtual force
sensor (VFS), identically per sample (``update``) and over a whole log (``run``):

* :class:`InputGuard`: values outside the robot's physical range
  (:mod:`grfguard.io.plausibility`: IMU acceleration and rate, quaternion norm, joint
  limits, sole forces, precomputed ``vfs_<s>``, whose lower bound is wider: a virtual
  corner force may be negative) become NaN before any estimator sees them, so a finite
  absurd value (``imu_acc_z = 1e30``) is handled like a dropout instead of poisoning
  filter states. A force sensor's implausible reading becomes a
  NaN reading for the detector (flagged at once) and the pipeline reports it with the
  kind ``spikes``.
* :class:`TimeGuard`: classifies each sample's time stamp (``ok``, ``time_gap``,
  ``time_backwards``, ``time_constant``, ``time_missing``) and gives the detector a
  monotone clock (a stamp that does not move forward continues the clock by one period).

Continuity (:class:`Continuity`): after a time break or after samples the VFS could not
use, the VFS is reset (its finite differences and filters would otherwise see the jump)
and the VFS-based tests wait ``settle_s``; the monitor never tests a sensor against a
held (``vfs_valid = 0``) or settling estimate. These are system-level states (the
``system_state`` output), never a sensor flag by themselves.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from grfguard._validate import check_number
from grfguard.io.plausibility import PlausibilityChecker
from grfguard.io.schema import FORCE_COLUMNS, IMU_ACC, IMU_GYRO, IMU_QUAT, JOINT_COLUMNS
from grfguard.model.robot import SENSOR_NAMES

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "Continuity",
    "GuardConfig",
    "InputGuard",
    "SYSTEM_STATES",
    "TimeGuard",
]

_NAN = float("nan")

#: Values of the ``system_state`` output, most specific first.
SYSTEM_STATES = (
    "ok",
    "time_gap",
    "time_backwards",
    "time_constant",
    "time_missing",
    "input_invalid",
    "settling",
)

#: Estimator inputs checked against their physical range.
ESTIMATOR_INPUTS = (*IMU_ACC, *IMU_GYRO, *IMU_QUAT, *JOINT_COLUMNS)


@dataclass(frozen=True)
class GuardConfig:
    """Settings of the input and continuity guards.

    Attributes:
        gap_s: A time step longer than ``max(gap_s, gap_periods x dt)`` is a gap [s].
        gap_periods: See ``gap_s`` (in sampling periods) [-].
        settle_s: After a continuity break (gap, stamps not moving forward, unusable
            estimator inputs) the VFS is reset and its outputs are not used by the tests
            for this long [s].
        reject_implausible: Treat values outside the physical range as missing.
    """

    gap_s: float = 0.02
    gap_periods: float = 5.0
    settle_s: float = 0.3
    reject_implausible: bool = True

    def __post_init__(self) -> None:
        check_number("guard", "gap_s", self.gap_s, 0.0, 3600.0, "s")
        check_number("guard", "gap_periods", self.gap_periods, 1.0, 1e6, "")
        check_number("guard", "settle_s", self.settle_s, 0.0, 60.0, "s")


class InputGuard:
    """Physical-range check of the estimator inputs and the force readings.

    Args:
        robot: Robot description (weight, joint limits).
        config: Guard settings.
    """

    def __init__(self, robot: Any, config: GuardConfig | None = None) -> None:
        self.config = config if config is not None else GuardConfig()
        self.inputs = PlausibilityChecker(robot, ESTIMATOR_INPUTS)
        vfs_cols = tuple(f"vfs_{s}" for s in SENSOR_NAMES)
        self.forces = PlausibilityChecker(robot, (*FORCE_COLUMNS, *vfs_cols))
        #: plausible range of a force reading (and of a recovered force) [N]
        self.force_lo = self.forces.ranges.force_lo
        self.force_hi = self.forces.ranges.force_hi
        #: lowest plausible virtual corner force ``vfs_<s>`` [N] (wider than a reading's:
        #: :attr:`~grfguard.io.plausibility.PlausibleRanges.virtual_min_weights`)
        self.vfs_force_lo = self.forces.ranges.vfs_force_lo

    def clean_row(self, row: Mapping[str, Any]) -> tuple[Mapping[str, Any], str]:
        """``row`` with implausible estimator inputs and forces set to NaN (the same
        mapping when all is plausible) and the reason (empty when nothing was rejected).
        Never raises."""
        if not self.config.reject_implausible:
            return row, ""
        try:
            bad = self.inputs.check_sample(row)
            bad.update(self.forces.check_sample(row))
        except Exception:  # noqa: BLE001 - a bad sample must never raise
            return row, ""
        if not bad:
            return row, ""
        out = dict(row)
        for c in bad:
            out[c] = _NAN
        return out, "; ".join(bad[c] for c in sorted(bad))

    def clean_frame(self, log: pd.DataFrame) -> tuple[pd.DataFrame, list[str]]:
        """Vectorized :meth:`clean_row` over a log: the cleaned copy (``log`` itself when
        all is plausible) and the reason per row."""
        reasons = [""] * len(log)
        if not self.config.reject_implausible:
            return log, reasons
        masks = []
        for chk in (self.inputs, self.forces):
            m, _ = chk.check_frame(log)
            if m.shape[1]:
                masks.append(m)
        if not masks:
            return log, reasons
        import pandas as pd

        mask = pd.concat(masks, axis=1)
        mask = mask.loc[:, ~mask.columns.duplicated()]
        arr = mask.to_numpy(dtype=bool)
        rows = np.flatnonzero(arr.any(axis=1))
        if rows.size == 0:
            return log, reasons
        out = log.copy()
        cols = list(mask.columns)
        for c in cols:
            m = mask[c].to_numpy(dtype=bool)
            if m.any():
                out[c] = out[c].astype(float).where(~m, np.nan)
        for k in rows:
            row = log.iloc[int(k)]
            bad = {c: self.inputs.check_value(c, row[c]) or self.forces.check_value(c, row[c])
                   for c in cols if arr[k, cols.index(c)]}
            for c in cols:
                if arr[k, cols.index(c)] and not bad.get(c):
                    bad[c] = self._quat_reason(row)
            reasons[int(k)] = "; ".join(str(bad[c]) for c in sorted(bad))
        return out, reasons

    def _quat_reason(self, row: Any) -> str:
        """The reason :meth:`clean_row` gives for a quaternion whose norm is not 1."""
        q = [float(row.get(f"imu_quat_{a}", _NAN)) for a in "wxyz"]
        n = math.sqrt(sum(x * x for x in q))
        return (f"IMU quaternion norm {n:.4g} is not 1 "
                f"(within {self.inputs.ranges.quat_norm_tol})")

    def force_implausible(self, value: float) -> bool:
        """True when a (finite or infinite) force reading is outside the range."""
        return not math.isnan(value) and not (self.force_lo <= value <= self.force_hi)

    def clamp(self, value: float) -> float:
        """``value`` within the plausible force range (NaN stays NaN)."""
        if math.isnan(value):
            return value
        return min(max(value, self.force_lo), self.force_hi)


class TimeGuard:
    """Classifies time stamps and keeps a monotone clock for the detector.

    Args:
        dt_s: Nominal sampling period [s].
        config: Guard settings.
    """

    def __init__(self, dt_s: float, config: GuardConfig | None = None) -> None:
        self.config = config if config is not None else GuardConfig()
        self.dt_s = float(dt_s)
        self.gap_limit_s = max(self.config.gap_s, self.config.gap_periods * self.dt_s)
        self.reset()

    def reset(self) -> None:
        """No sample seen."""
        self._last_stamp = _NAN
        self.clock_s = _NAN

    def step(self, t: float) -> tuple[float, str, float]:
        """One time stamp ``t`` [s] (NaN allowed).

        Returns:
            ``(clock_s, state, jump_s)``: the detector's clock [s] (monotone), the state
            (``ok``, ``time_gap``, ``time_backwards``, ``time_constant``,
            ``time_missing``) and the stamp's step from the last finite stamp [s] (NaN
            at the first sample or when ``t`` is not finite).
        """
        last = self._last_stamp
        if not math.isfinite(t):
            state, jump = "time_missing", _NAN
            clock = self.clock_s + self.dt_s if math.isfinite(self.clock_s) else 0.0
        else:
            self._last_stamp = t
            if not math.isfinite(last):
                state, jump = "ok", _NAN
                clock = t if not math.isfinite(self.clock_s) or t > self.clock_s else (
                    self.clock_s + self.dt_s)
            else:
                jump = t - last
                if jump > self.gap_limit_s:
                    state = "time_gap"
                elif jump < 0.0:
                    state = "time_backwards"
                elif jump == 0.0:
                    state = "time_constant"
                else:
                    state = "ok"
                clock = t if t > self.clock_s else self.clock_s + self.dt_s
        self.clock_s = clock
        return clock, state, jump


class Continuity:
    """When to reset the VFS and how long its outputs must not be used.

    Per sample: :meth:`before` (does the VFS need a reset before this sample?) and,
    once the VFS output is known, :meth:`after` (may the tests use it?). A break is a
    time gap (rows missing) or a sample after one the VFS could not use. Constant,
    backwards or missing stamps are not a break of the data (the VFS runs on its nominal
    period and never reads the stamps): only the detector's clock is kept monotone.

    Args:
        settle_s: Settling time after a reset [s].
    """

    def __init__(self, settle_s: float) -> None:
        self.settle_s = float(settle_s)
        self.reset()

    def reset(self) -> None:
        """No sample seen."""
        self._prev_invalid = False
        self._reset_clock = _NAN
        self._started = False

    def before(self, time_state: str) -> bool:
        """True when the VFS must be reset before this sample."""
        brk = self._started and (time_state == "time_gap" or self._prev_invalid)
        self._started = True
        return brk

    def after(self, clock_s: float, reset: bool, valid: bool) -> bool:
        """Record the sample; True when the tests may use the VFS output."""
        if reset:
            self._reset_clock = clock_s
        self._prev_invalid = not valid
        if not valid:
            return False
        return not (math.isfinite(self._reset_clock)
                    and clock_s - self._reset_clock < self.settle_s - 1e-12)
