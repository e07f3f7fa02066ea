"""Recovery stage: the reconstructed force of every sensor from the detector's verdicts.

Reads the per-sensor state of the detector (flag, kind, ``eta_n``, ``gain``, the clipped
value; :class:`~grfguard.detect.sensor_state.SensorState`) and writes ``recovered_<s>``
and ``eta_<s>``. The rules are those of :mod:`grfguard.recover.reconstruct`:

- healthy: the measurement;
- offset/drift: ``N_meas - η̂``; gain: ``N_meas / ĝ``; noise: a low-pass of the reading;
  spikes: the median of the last three readings; saturation: the reading when it is
  off the flat top;
- no information (dropout, frozen, stuck, clipped): the whole-body balance
  ``F_z,VFS(both feet) - Σ known sensors``, shared by the VFS corner forces when several
  sensors lack information (at least the clipped value for a saturated sensor);
- a hand-over (:class:`~grfguard.recover.reconstruct.HandOver`) blends from the
  measurement to the reconstruction and back; an information-less reading is dropped
  fast.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from grfguard.detect.config import MonitorConfig
from grfguard.detect.residual_tests import ADDITIVE
from grfguard.detect.sensor_state import SensorState
from grfguard.errors import ConfigError
from grfguard.io.schema import eta_col, recovered_col
from grfguard.model.robot import SENSOR_NAMES
from grfguard.recover.reconstruct import HandOver

__all__ = ["RecoverTuning", "Recovery"]

_N = len(SENSOR_NAMES)
_NAN = float("nan")
_REC_COLS = tuple(recovered_col(s) for s in SENSOR_NAMES)
_ETA_COLS = tuple(eta_col(s) for s in SENSOR_NAMES)


@dataclass(frozen=True)
class RecoverTuning:
    """Design constants of the recovery.

    Attributes:
        fast_drop_tau_s: Time constant of the hand-over away from a reading without
            information [s] (5 ms: a frozen or lost reading must leave the output fast;
            the corrections blend over ``MonitorConfig.blend_s``).
        noise_lowpass_tau_s: Time constant of the low-pass that cleans a noisy sensor
            [s] (8 ms: removes most of the 25 N noise of the scenarios while keeping
            the touchdown transients).
        gain_min: Estimated gains below this are not divided by [-].
    """

    fast_drop_tau_s: float = 0.005
    noise_lowpass_tau_s: float = 0.008
    gain_min: float = 0.05

    def __post_init__(self) -> None:
        for name in ("fast_drop_tau_s", "noise_lowpass_tau_s", "gain_min"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (v > 0.0):
                raise ConfigError(f"recover tuning {name} = {v!r} must be a number > 0")


class _RecState:
    """Recovery memory of one sensor."""

    __slots__ = ("hand", "last_rec_n", "x1_n", "x2_n", "lowpass_n")

    def __init__(self, blend_s: float, dt_s: float) -> None:
        self.hand = HandOver(blend_s, dt_s)
        self.last_rec_n = 0.0
        self.x1_n = self.x2_n = _NAN  # the previous two readings
        self.lowpass_n = _NAN


class Recovery:
    """Streaming recovery of the 8 sensors (one sample per :meth:`step`).

    Args:
        config: ``dt_s`` and ``blend_s`` (hand-over time constant).
        tuning: Design constants (default :class:`RecoverTuning`).
    """

    def __init__(self, config: MonitorConfig, tuning: RecoverTuning | None = None) -> None:
        self.config = config
        self.tuning = tuning if tuning is not None else RecoverTuning()
        dt = config.dt_s
        self._a_fast = min(1.0, dt / self.tuning.fast_drop_tau_s)
        self._a_lp = min(1.0, dt / self.tuning.noise_lowpass_tau_s)
        self.reset()

    def reset(self) -> None:
        """Back to the measurement, filters empty."""
        self._rec = [_RecState(self.config.blend_s, self.config.dt_s) for _ in range(_N)]

    def _corrected(
        self, sens: Sequence[SensorState], x: Sequence[float]
    ) -> tuple[list[float], list[bool]]:
        """Per sensor: the corrected reading [N] and whether the reading carries
        information."""
        a_lp = self._a_lp
        gain_min = self.tuning.gain_min
        corrected = [_NAN] * _N
        info = [True] * _N
        for i in range(_N):
            s, r, xi = sens[i], self._rec[i], x[i]
            if math.isfinite(xi):
                lp = r.lowpass_n
                r.lowpass_n = xi if math.isnan(lp) else lp + (xi - lp) * a_lp
            if s.flag and s.kind in ADDITIVE and math.isfinite(s.eta_n):
                corrected[i] = xi - s.eta_n
            elif s.flag and s.kind == "gain" and s.gain > gain_min:
                corrected[i] = xi / s.gain
            elif s.flag and s.kind == "noise" and math.isfinite(r.lowpass_n):
                corrected[i] = r.lowpass_n
            elif s.flag and s.kind == "spikes":
                trip = [q for q in (xi, r.x1_n, r.x2_n) if math.isfinite(q)]
                corrected[i] = sorted(trip)[len(trip) // 2] if trip else _NAN
            elif s.flag:
                info[i] = False
            else:
                corrected[i] = xi
            r.x2_n, r.x1_n = r.x1_n, xi
            if s.flag and s.kind == "saturation" and math.isfinite(xi) and xi != s.const_value_n:
                corrected[i] = xi  # off the flat top: the reading is right
                info[i] = True
        return corrected, info

    @staticmethod
    def _balance(
        i: int, v: Sequence[float], total: float, known: float, lacking: Sequence[int]
    ) -> float:
        """Whole-body balance for sensor ``i`` without information: the VFS total force
        minus every known sensor [N] (the total is precise in every phase, unlike the
        per-foot split of the VFS), shared by VFS corner forces among ``lacking``."""
        rest = total - known
        if len(lacking) > 1:
            vs = [max(v[j], 0.0) if math.isfinite(v[j]) else 0.0 for j in lacking]
            share = (max(v[i], 0.0) if math.isfinite(v[i]) else 0.0) / sum(vs) \
                if sum(vs) > 0 else 1.0 / len(lacking)
            rest *= share
        return max(rest, 0.0)

    def step(
        self, sens: Sequence[SensorState], x: Sequence[float], v: Sequence[float],
        tot: Sequence[float], out: dict[str, Any] | None = None,
    ) -> dict[str, Any]:
        """One sample: ``recovered_<s>`` and ``eta_<s>`` of every sensor.

        Args:
            sens: The detector's sensor states after this sample.
            x: Measured forces [N].
            v: VFS corner forces [N].
            tot: VFS vertical force per foot (right, left) [N].
            out: Dict to write into (a new one by default); returned.
        """
        a_fast = self._a_fast
        corrected, info = self._corrected(sens, x)
        total = tot[0] + tot[1]
        lacking = [j for j in range(_N) if not info[j]]
        known = math.fsum(corrected[j] for j in range(_N) if info[j] and
                          math.isfinite(corrected[j]))
        if out is None:
            out = {}
        for i in range(_N):
            s, r, xi = sens[i], self._rec[i], x[i]
            rec_col, eta_c = _REC_COLS[i], _ETA_COLS[i]
            if not s.flag and r.hand.w == 0.0 and math.isfinite(xi):
                # healthy and fully handed back: the measurement itself
                r.last_rec_n = xi
                out[rec_col] = xi
                out[eta_c] = 0.0
                continue
            if not info[i] and math.isfinite(total):
                repl = self._balance(i, v, total, known, lacking)
            else:
                repl = max(v[i], 0.0) if math.isfinite(v[i]) else 0.0
            w = r.hand.update(1.0 if s.flag else 0.0,
                              a_fast if (s.flag and not info[i]) else None)
            rec_fault = corrected[i] if info[i] and math.isfinite(corrected[i]) else repl
            if s.flag and s.kind == "saturation" and not info[i]:
                rec_fault = max(rec_fault, s.const_value_n)  # clipped: the truth is above
            rec = HandOver.mix(w, xi, rec_fault, r.last_rec_n)
            if not math.isfinite(rec):
                rec = r.last_rec_n
            r.last_rec_n = rec
            out[rec_col] = rec
            out[eta_c] = (s.eta_n if s.kind in ADDITIVE else xi - rec) if s.flag else 0.0
        return out
