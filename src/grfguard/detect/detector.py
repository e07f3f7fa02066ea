"""The default detector: one sample through gates, tests, isolation and the flag machine.

Per sample (:meth:`Detector.step`):

1. time and weight (running mean of the VFS total force) [N];
2. gates (:class:`~grfguard.detect.gating.ContactTimeline`): contact, swing, loaded,
   single support, touchdown guard;
3. per-sensor tests (:mod:`grfguard.detect.residual_tests`): NaN reading (dropout at
   once), constant reading, swing CUSUM, corner CUSUM; evidence for the kind
   (:mod:`grfguard.detect.classify`);
4. foot-total test per foot with isolation votes;
5. flag state machine: an alarm flags the sensor (or upgrades the source of its flag
   by priority ``nan > const > swing > corner = total``); a flagged sensor without
   alarm may clear; the kind and size of every flagged sensor are re-estimated.

The detector only reads the VFS outputs; recovery is a separate stage
(:mod:`grfguard.recover`) that reads :attr:`Detector.sensors`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

from grfguard.detect.classify import add_swing_sample, classify, maybe_clear
from grfguard.detect.config import MonitorConfig
from grfguard.detect.gating import ContactTimeline, WeightEstimate
from grfguard.detect.residual_tests import (
    FootTotalTest,
    constant_test,
    corner_test,
    swing_test,
)
from grfguard.detect.sensor_state import SensorState
from grfguard.detect.tuning import DetectTuning
from grfguard.io.schema import TIME, flag_col, force_col, kind_col, vfs_col
from grfguard.model.robot import SENSOR_NAMES, SIDES

__all__ = ["Detector", "DetectorInputs", "DetectorStep", "VFS_TOTAL_COLUMNS"]

_N = len(SENSOR_NAMES)
_NAN = float("nan")
_FLAG_COLS = tuple(flag_col(s) for s in SENSOR_NAMES)
_KIND_COLS = tuple(kind_col(s) for s in SENSOR_NAMES)
#: Which test wins when a flagged sensor alarms again (higher = more specific).
_PRIORITY = {"nan": 4, "const": 3, "swing": 2, "corner": 1, "total": 1}
#: Flags from these tests leave the reading without information.
_INFOLESS_SOURCES = ("nan", "const")


class DetectorStep(NamedTuple):
    """Output of :meth:`Detector.step`.

    Attributes:
        columns: ``flag_<s>`` and ``kind_<s>`` of every sensor.
        diagnostics: Test statistics ``stat_*``, residuals ``res_*`` and gates
            (empty unless ``config.diagnostics``).
    """

    columns: dict[str, Any]
    diagnostics: dict[str, Any]


class _Seen:
    """What the tests saw at one sample (diagnostics)."""

    def __init__(self) -> None:
        self.stat_swing = [_NAN] * _N
        self.stat_corner = [_NAN] * _N
        self.res_swing = [_NAN] * _N
        self.res_corner = [_NAN] * _N
        self.stat_total = [_NAN, _NAN]
        self.res_total = [_NAN, _NAN]


class Detector:
    """Streaming default detector (one sample per :meth:`step`; plain floats).

    Args:
        config: Thresholds, gates, clearing time, sampling period.
        tuning: Design constants (default :class:`DetectTuning`).
    """

    def __init__(self, config: MonitorConfig, tuning: DetectTuning | None = None) -> None:
        self.config = config
        self.tuning = tuning if tuning is not None else DetectTuning()
        self.timeline = ContactTimeline(config, self.tuning)
        self.weight = WeightEstimate()
        self.totals = FootTotalTest()
        #: Identical readings of a loaded sensor that mean frozen (``const_s`` at ``dt_s``).
        self.const_samples = self.tuning.const_samples(config.thresholds.const_s, config.dt_s)
        #: Largest chance per sample and sensor that a healthy (quantised) sensor's
        #: reading repeats as long as a frozen one: the calibrated false-alarm rate.
        self.const_chance = min(
            0.5, config.thresholds.false_alarm_rate_per_hour * config.dt_s / 3600.0 / _N)
        self.reset()

    def reset(self) -> None:
        """Forget everything (flags, sums, contact timeline, weight)."""
        self.timeline.reset()
        self.weight.reset()
        self.totals.reset()
        self.sensors = [SensorState() for _ in range(_N)]
        self._last_t = _NAN
        self._sink = _Seen()  # written, never read, when diagnostics are off

    def _time(self, t: float) -> float:
        """A NaN time continues the clock by one period."""
        if not math.isfinite(t):
            t = self._last_t + self.config.dt_s if math.isfinite(self._last_t) else 0.0
        self._last_t = t
        return t

    def _gates(
        self, t: float, x: Sequence[float], tot: Sequence[float], cref: Sequence[float],
        cest: Sequence[float], weight: float,
    ) -> tuple[list[bool], list[bool], list[bool]]:
        """``(swing_ok, ss_ok, loaded_ok)`` per foot, the touchdown guard applied."""
        _, swing_ok, ss_ok, loaded_ok = self.timeline.step(t, cref, cest, tot, weight)
        sig = self.config.thresholds.sigma_swing_n
        for f in range(2):
            if swing_ok[f]:
                idx = range(4 * f, 4 * f + 4)
                if self.timeline.touchdown_guard(
                    f, t, [x[i] for i in idx], [self.sensors[i].flag for i in idx], sig
                ):
                    swing_ok[f] = False
        return swing_ok, ss_ok, loaded_ok

    def _sensor_tests(
        self, i: int, t: float, xi: float, vi: float, tot_f: float, weight: float,
        swing_ok: bool, ss_ok: bool, loaded_ok: bool, infoless_foot: bool, seen: _Seen,
    ) -> str:
        """Constant, swing and corner tests of sensor ``i``; returns its alarm source."""
        th = self.config.thresholds
        s = self.sensors[i]
        if not math.isfinite(xi):
            s.repeats = 0
            s.last_reading_n = _NAN
            return "nan"
        const = constant_test(s, xi, loaded_ok, self.const_samples, self.const_chance)
        alarm = "const" if const else ""
        if swing_ok:
            seen.res_swing[i] = xi
            hit, seen.stat_swing[i] = swing_test(s, xi, th)
            if hit and not alarm:
                alarm = "swing"
            if s.flag and s.source == "swing":
                s.quiet_valid += 1
                add_swing_sample(s, t, xi, th.sigma_swing_n, self.tuning, self.config.dt_s)
        if ss_ok and math.isfinite(weight) and weight > 0 and math.isfinite(vi):
            hit, seen.stat_corner[i], seen.res_corner[i], z = corner_test(s, xi, vi, weight, th)
            if hit and not alarm:
                alarm = "corner"
            if s.flag and s.source in ("corner", "total"):
                if s.source == "corner" and abs(z) < th.corner_kappa:
                    s.quiet_valid += 1
                if infoless_foot or not math.isfinite(tot_f):
                    s.stance.add(xi - vi, vi, self.tuning.stance_eta_factor)
        return alarm

    def _foot_total(
        self, f: int, x: Sequence[float], v: Sequence[float], tot_f: float, weight: float,
        alarms: list[str], seen: _Seen,
    ) -> None:
        """Foot-total test of foot ``f`` (gate already open): statistics, health evidence
        and stance fits of its stance-flagged sensors, isolation on alarm."""
        th = self.config.thresholds
        idx = range(4 * f, 4 * f + 4)
        sens = [self.sensors[i] for i in idx]
        if not FootTotalTest.usable(sens):
            return
        corr = FootTotalTest.corrected(sens, [x[i] for i in idx])
        if not all(math.isfinite(q) for q in corr):
            return
        vf = [v[i] for i in idx]
        stance_flagged = [s.flag and s.source in ("total", "corner") for s in sens]
        seen.res_total[f], z, seen.stat_total[f] = self.totals.step(f, corr, vf, tot_f, weight, th)
        for s, sf in zip(sens, stance_flagged, strict=True):
            if sf:  # health evidence: a quiet residual
                s.quiet_valid = s.quiet_valid + 1 if abs(z) < th.total_kappa else 0
        for j, s in enumerate(sens):
            # stance fit of a stance-flagged sensor: residual vs load by the foot balance
            # (the other corners healthy or corrected)
            if stance_flagged[j] and all(
                (not o.flag) or o.kind in ("offset", "drift") for k, o in enumerate(sens) if k != j
            ):
                load = tot_f - math.fsum(corr[k] for k in range(4) if k != j)
                s.stance.add(x[4 * f + j] - load, load, self.tuning.stance_eta_factor)
        if seen.stat_total[f] > th.total_h:
            for j in self.totals.isolate(f, sens):
                if not alarms[4 * f + j]:
                    alarms[4 * f + j] = "total"

    def _apply_alarm(self, s: SensorState, a: str, t: float, x_n: float) -> None:
        """Flag ``s`` (or upgrade the source of its flag) for alarm ``a`` at ``t``."""
        if not s.flag:
            s.clear()
            s.flag = True
            s.flag_time_s = t
            s.source = a
            if a == "const":
                s.const_value_n = x_n
        elif _PRIORITY[a] > _PRIORITY.get(s.source, 0):
            s.source = a
            if a == "const":
                s.const_value_n = x_n
                s.varied = False
                s.const_returns = 0
        s.quiet_valid = 0
        s.last_alarm_s = t

    def step(
        self, t: float, x: Sequence[float], v: Sequence[float], tot: Sequence[float],
        cref: Sequence[float], cest: Sequence[float],
    ) -> DetectorStep:
        """One sample.

        Args:
            t: Time [s] (NaN continues the clock).
            x: Measured forces ``N_meas`` of the 8 sensors [N] (NaN = no reading).
            v: VFS corner forces ``N̂`` [N].
            tot: VFS vertical force of each foot (right, left) [N].
            cref: Planned contact per foot (0/1, NaN when unknown).
            cest: VFS contact estimate per foot (0/1, NaN when unknown).

        Returns:
            :class:`DetectorStep`.
        """
        t = self._time(t)
        weight = self.weight.update(tot[0], tot[1])
        swing_ok, ss_ok, loaded_ok = self._gates(t, x, tot, cref, cest, weight)
        sens = self.sensors
        infoless = [any(sens[i].flag and sens[i].source in _INFOLESS_SOURCES
                        for i in range(4 * f, 4 * f + 4)) for f in range(2)]
        seen = _Seen() if self.config.diagnostics else self._sink
        alarms = [
            self._sensor_tests(i, t, x[i], v[i], tot[i // 4], weight, swing_ok[i // 4],
                               ss_ok[i // 4], loaded_ok[i // 4], infoless[i // 4], seen)
            for i in range(_N)
        ]
        for f in range(2):
            if ss_ok[f] and math.isfinite(tot[f]) and math.isfinite(weight) and weight > 0:
                self._foot_total(f, x, v, tot[f], weight, alarms, seen)
        cols: dict[str, Any] = {}
        for i in range(_N):
            s = sens[i]
            if alarms[i]:
                self._apply_alarm(s, alarms[i], t, x[i])
            elif s.flag:
                maybe_clear(s, t, x[i], loaded_ok[i // 4], self.config, self.tuning)
            if s.flag:
                classify(s, t, x[i], self.config.thresholds.sigma_swing_n, self.tuning,
                         self.config.dt_s)
            cols[_FLAG_COLS[i]] = s.flag
            cols[_KIND_COLS[i]] = s.kind
        diag = self._diagnostics(seen, swing_ok, ss_ok) if self.config.diagnostics else {}
        return DetectorStep(cols, diag)

    @staticmethod
    def _diagnostics(seen: _Seen, swing_ok: list[bool], ss_ok: list[bool]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for i, name in enumerate(SENSOR_NAMES):
            out[f"stat_swing_{name}"] = seen.stat_swing[i]
            out[f"stat_corner_{name}"] = seen.stat_corner[i]
            out[f"res_swing_{name}"] = seen.res_swing[i]
            out[f"res_corner_{name}"] = seen.res_corner[i]
        for f, side in enumerate(SIDES):
            out[f"stat_total_{side}"] = seen.stat_total[f]
            out[f"res_total_{side}"] = seen.res_total[f]
            out[f"swing_ok_{side}"] = swing_ok[f]
            out[f"ss_ok_{side}"] = ss_ok[f]
        return out


#: VFS foot-force columns (right, left).
VFS_TOTAL_COLUMNS = tuple(f"vfs_total_{s}" for s in SIDES)


class DetectorInputs(NamedTuple):
    """Columns a detector reads from a log, as lists of floats (NaN where missing).

    Attributes:
        t: Time (T,) [s].
        x: Measured forces, 8 lists of T [N].
        v: VFS corner forces, 8 lists of T [N].
        tot: VFS force per foot, 2 lists of T [N].
        cref: Planned contact per foot, 2 lists of T.
        cest: VFS contact estimate per foot, 2 lists of T.
    """

    t: list[float]
    x: list[list[float]]
    v: list[list[float]]
    tot: list[list[float]]
    cref: list[list[float]]
    cest: list[list[float]]

    @classmethod
    def from_frames(cls, log: Any, vfs: Any) -> DetectorInputs:
        """From the log (time, forces, planned contact) and the frame with the VFS
        outputs (``vfs_<s>``, ``vfs_total_<side>``, ``contact_est_<side>``; may be the log)."""
        n = len(log)

        def col(frame: Any, name: str) -> list[float]:
            if name in frame.columns:
                return frame[name].to_numpy(dtype=float).tolist()
            return [_NAN] * n

        return cls(
            t=col(log, TIME),
            x=[col(log, force_col(s)) for s in SENSOR_NAMES],
            v=[col(vfs, vfs_col(s)) for s in SENSOR_NAMES],
            tot=[col(vfs, c) for c in VFS_TOTAL_COLUMNS],
            cref=[col(log, f"contact_ref_{s}") for s in SIDES],
            cest=[col(vfs, f"contact_est_{s}") for s in SIDES],
        )

    def sample(self, k: int) -> tuple[float, list[float], list[float], list[float],
                                      list[float], list[float]]:
        """Sample ``k`` as the arguments of :meth:`Detector.step`."""
        return (
            self.t[k],
            [c[k] for c in self.x],
            [c[k] for c in self.v],
            [self.tot[0][k], self.tot[1][k]],
            [self.cref[0][k], self.cref[1][k]],
            [self.cest[0][k], self.cest[1][k]],
        )
