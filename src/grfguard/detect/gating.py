"""Contact timeline and test gates of the default detector.

Each test of :mod:`grfguard.detect.residual_tests` is only valid in part of the gait:

- *swing* of foot ``f``: ``gate_liftoff_s`` after its lift-off until
  ``gate_before_touchdown_s`` before its expected touchdown (the last swing duration of
  the foot, else of the other foot); no swing test before a swing duration is known;
- *loaded* (constant-reading test): ``gate_loaded_s`` after the foot's touchdown;
- *single support* (corner and foot-total tests) of foot ``f``: ``gate_touchdown_s``
  after its own touchdown while the other foot is in the valid part of its swing.

Contact comes from the planned contact (``contact_ref_<side>``), else the VFS contact
estimate, else the VFS foot force against a fraction of the weight. The *touchdown
guard* closes the swing gate of a foot for the rest of its swing when two unflagged
sensors are loaded at once late in the swing (an early heel strike).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from grfguard.detect.config import MonitorConfig
from grfguard.detect.tuning import DetectTuning

__all__ = ["WeightEstimate", "ContactTimeline"]

_NAN = float("nan")


class WeightEstimate:
    """Running mean of the VFS total vertical force (the robot's weight) [N]."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """No sample seen."""
        self._sum = 0.0
        self._n = 0

    def update(self, total_right_n: float, total_left_n: float) -> float:
        """Add one sample of both feet's VFS forces [N]; returns the mean (NaN before the
        first finite sample) [N]."""
        if math.isfinite(total_right_n) and math.isfinite(total_left_n):
            self._sum += total_right_n + total_left_n
            self._n += 1
        return self._sum / self._n if self._n else _NAN


class ContactTimeline:
    """Touchdown and lift-off times of both feet, swing durations, gates.

    Args:
        config: Gate durations (``gate_*_s``).
        tuning: Contact level, weight fraction and touchdown-guard constants.
    """

    def __init__(self, config: MonitorConfig, tuning: DetectTuning) -> None:
        self.config = config
        self.tuning = tuning
        self.reset()

    def reset(self) -> None:
        """No contact history."""
        self._c_prev: list[bool | None] = [None, None]
        self.touchdown_s = [_NAN, _NAN]
        self.liftoff_s = [_NAN, _NAN]
        self.swing_duration_s = [_NAN, _NAN]
        self._guard = [False, False]

    def contact(self, f: int, cref: float, cest: float, tot: float, weight: float) -> bool:
        """Contact of foot ``f`` from the planned contact, else the VFS estimate, else the
        VFS foot force ``tot`` [N] against a fraction of the weight [N]."""
        cv = cref if math.isfinite(cref) else cest
        if not math.isfinite(cv):
            cv = 1.0 if (math.isfinite(tot) and math.isfinite(weight)
                         and tot > self.tuning.contact_weight_fraction * weight) else 0.0
        return cv > self.tuning.contact_level

    def _record(self, f: int, t: float, cf: bool) -> None:
        """Record a touchdown (and the swing duration) or a lift-off of foot ``f``."""
        prev = self._c_prev[f]
        if prev is None:  # first sample: the phase started before the log
            self.touchdown_s[f] = t if cf else _NAN
            self.liftoff_s[f] = _NAN if cf else t
        elif cf and not prev:
            if math.isfinite(self.liftoff_s[f]):
                self.swing_duration_s[f] = t - self.liftoff_s[f]
            self.touchdown_s[f] = t
        elif prev and not cf:
            self.liftoff_s[f] = t
            self._guard[f] = False
        self._c_prev[f] = cf

    def expected_swing_s(self, f: int) -> float:
        """Expected swing duration of foot ``f`` (its last, else the other foot's) [s]."""
        d = self.swing_duration_s
        return d[f] if math.isfinite(d[f]) else d[1 - f]

    def _in_valid_swing(self, f: int, t: float) -> bool:
        """Foot ``f`` is between ``gate_liftoff_s`` after lift-off and
        ``gate_before_touchdown_s`` before the expected touchdown (needs a known swing
        duration: heels land up to ~0.1 s early, the touchdown must be predictable)."""
        c = self.config
        since = t - self.liftoff_s[f]
        exp_sw = self.expected_swing_s(f)
        return (math.isfinite(exp_sw) and since >= c.gate_liftoff_s
                and since <= exp_sw - c.gate_before_touchdown_s)

    def step(
        self, t: float, cref: Sequence[float], cest: Sequence[float], tot: Sequence[float],
        weight: float,
    ) -> tuple[list[bool], list[bool], list[bool], list[bool]]:
        """Advance to time ``t`` [s]; returns ``(contact, swing_ok, ss_ok, loaded_ok)``
        per foot (the swing gate before the touchdown guard)."""
        c = self.config
        contact = [self.contact(f, cref[f], cest[f], tot[f], weight) for f in range(2)]
        for f in range(2):
            self._record(f, t, contact[f])
        swing_ok = [False, False]
        ss_ok = [False, False]
        loaded_ok = [False, False]
        for f in range(2):
            o = 1 - f
            if not contact[f] and math.isfinite(self.liftoff_s[f]):
                swing_ok[f] = self._in_valid_swing(f, t)
            if contact[f] and math.isfinite(self.touchdown_s[f]):
                loaded_ok[f] = t - self.touchdown_s[f] >= c.gate_loaded_s
                if not contact[o] and math.isfinite(self.liftoff_s[o]):
                    ss_ok[f] = (t - self.touchdown_s[f] >= c.gate_touchdown_s
                                and self._in_valid_swing_other(f, t))
        return contact, swing_ok, ss_ok, loaded_ok

    def _in_valid_swing_other(self, f: int, t: float) -> bool:
        """The other foot's swing check as seen from foot ``f`` (its expected swing is its
        own last swing, else foot ``f``'s)."""
        c = self.config
        o = 1 - f
        since_o = t - self.liftoff_s[o]
        exp_o = self.expected_swing_s(o)
        return (since_o >= c.gate_liftoff_s and math.isfinite(exp_o)
                and since_o <= exp_o - c.gate_before_touchdown_s)

    def touchdown_guard(
        self, f: int, t: float, readings_n: Sequence[float], flagged: Sequence[bool],
        sigma_n: float,
    ) -> bool:
        """True when the swing test of foot ``f`` must stay closed (early touchdown seen,
        latched until the next lift-off).

        Args:
            f: Foot index.
            t: Time [s].
            readings_n: The foot's four readings [N].
            flagged: Whether each of them is flagged.
            sigma_n: Swing noise of a sensor [N].
        """
        if self._guard[f]:
            return True
        tn = self.tuning
        if t - self.liftoff_s[f] < tn.guard_min_swing_fraction * self.expected_swing_s(f):
            return False  # an early touchdown only happens late in the swing
        hi = 0
        for xi, fl in zip(readings_n, flagged, strict=True):
            if not fl and math.isfinite(xi) and xi > tn.guard_load_sigma * sigma_n:
                hi += 1
        if hi >= tn.guard_min_sensors:
            self._guard[f] = True
            return True
        return False
