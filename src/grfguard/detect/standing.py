"""Fault detection while the robot stands still in double support.

While walking, each foot is unloaded once per step and the per-sensor tests re-learn
their zero; standing, no foot is ever unloaded and the internal force between the feet
is not observable, so those tests wait for walking to resume. Standing is quasi-static,
though: the residual ``d_i = f_i - v_i`` of a healthy sensor stays where it was when
the stand began (the virtual sensor's split of the load between the feet may be off,
but it stays off by the same amount while nothing moves). :class:`StandingDetector`
learns each residual's baseline over ``baseline_s`` after ``settle_s`` of double
support, then flags a sensor whose low-passed residual leaves the baseline by more than
``threshold_n`` for ``persist_s`` while the other sensors' deviations stay small
(``isolation_ratio``): a common shift of all residuals is a model or posture change, not
a sensor fault. A stand ends when a foot lifts or when the virtual force of a foot moves
by more than ``max_shift_fraction`` of the weight from its value at the baseline (the
robot shifts its weight: the split error changes). Kinds are ``offset`` (the deviation
appeared within ``drift_rise_s``) or ``drift``; a gain fault is an offset while the
load stands still (``(g - 1)·load`` is constant) and is reported as one.

:class:`StandingStage` is the layer of the default :class:`~grfguard.detect.Monitor`:
it runs after the per-sensor detector and recovery, flags what the detector has not
flagged, writes ``eta_<s>`` (the deviation from the baseline) and ``recovered_<s>``
(reading minus deviation) and, after the stand, holds its flag until the per-sensor
tests have had their chance (the sensor's foot has swung, then the other foot has
swung) or until the detector flags the sensor itself.
"""

from __future__ import annotations

import math
from collections.abc import MutableMapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from grfguard._validate import check_number
from grfguard.model.robot import SENSOR_NAMES

__all__ = ["StandingConfig", "StandingDetector", "StandingStage"]

_N = 8
_FLAG_COLS = tuple(f"flag_{s}" for s in SENSOR_NAMES)
_KIND_COLS = tuple(f"kind_{s}" for s in SENSOR_NAMES)
_ETA_COLS = tuple(f"eta_{s}" for s in SENSOR_NAMES)
_REC_COLS = tuple(f"recovered_{s}" for s in SENSOR_NAMES)


@dataclass(frozen=True)
class StandingConfig:
    """Settings of :class:`StandingDetector`.

    Attributes:
        settle_s: Double support needed before a stand counts as standing [s].
        baseline_s: Averaging window of the residual baselines [s].
        filter_s: Time constant of the residual low-pass [s].
        threshold_n: Deviation from the baseline that flags a sensor [N].
        persist_s: Time the deviation must persist [s].
        isolation_ratio: The flagged deviation must exceed this multiple of the median
            deviation of the other sensors.
        drift_rise_s: A deviation that took longer than this from half to full
            threshold is a drift [s].
        max_shift_fraction: The stand ends when a foot's virtual vertical force moves
            by more than this fraction of the weight from its value at the baseline
            (a weight shift) [-].
        clear_s: A flagged sensor whose deviation stays below half the threshold this
            long is cleared (the fault went away during the stand) [s].
        hold_filter_s: Time constant over which, after the stand, the offset and the
            gain explanation of a held flag are compared [s].
    """

    settle_s: float = 0.6
    baseline_s: float = 0.3
    filter_s: float = 0.02
    threshold_n: float = 15.0
    persist_s: float = 0.04
    isolation_ratio: float = 3.0
    drift_rise_s: float = 0.2
    max_shift_fraction: float = 0.03
    clear_s: float = 1.0
    hold_filter_s: float = 0.05

    def __post_init__(self) -> None:
        o = "standing"
        check_number(o, "settle_s", self.settle_s, 0.0, 60.0, "s")
        check_number(o, "baseline_s", self.baseline_s, 0.001, 60.0, "s")
        check_number(o, "filter_s", self.filter_s, 0.0, 10.0, "s")
        check_number(o, "threshold_n", self.threshold_n, 0.0, 1e5, "N")
        check_number(o, "persist_s", self.persist_s, 0.0, 10.0, "s")
        check_number(o, "isolation_ratio", self.isolation_ratio, 1.0, 100.0, "")
        check_number(o, "drift_rise_s", self.drift_rise_s, 0.0, 60.0, "s")
        check_number(o, "max_shift_fraction", self.max_shift_fraction, 0.0, 10.0, "")
        check_number(o, "clear_s", self.clear_s, 0.0, 3600.0, "s")
        check_number(o, "hold_filter_s", self.hold_filter_s, 0.0, 60.0, "s")


class StandingDetector:
    """Per-sensor detection of additive faults during a double-support stand.

    Args:
        dt_s: Sampling period in [s].
        config: Settings.
    """

    def __init__(self, dt_s: float = 0.001, config: StandingConfig | None = None) -> None:
        self.dt_s = float(dt_s)
        self.config = config if config is not None else StandingConfig()
        self._a = (1.0 if self.config.filter_s <= 0
                   else 1.0 - math.exp(-self.dt_s / self.config.filter_s))
        self.reset()

    def reset(self) -> None:
        """Forget the stand."""
        self._ds_s = 0.0
        self._base_sum = np.zeros(_N)
        self._base_n = 0
        self._base: np.ndarray | None = None
        self._tot_sum = np.zeros(2)
        self._tot_n = 0
        self._tot_base: np.ndarray | None = None
        self._lp = np.full(_N, np.nan)
        self._xlp = np.full(_N, np.nan)
        self._over_s = np.zeros(_N)
        self._quiet_s = np.zeros(_N)
        self._half_t = np.full(_N, np.nan)
        self._t = 0.0
        self.flags = np.zeros(_N, dtype=bool)
        self.kinds = ["none"] * _N
        self.eta_n = np.zeros(_N)

    @property
    def baseline_n(self) -> np.ndarray:
        """(8,) residual baselines of the stand [N] (NaN before they are learnt)."""
        return self._base.copy() if self._base is not None else np.full(_N, np.nan)

    @property
    def level_n(self) -> np.ndarray:
        """(8,) low-passed readings [N] (NaN outside a stand)."""
        return self._xlp.copy()

    @property
    def standing(self) -> bool:
        """True once the baselines are learnt and the stand goes on."""
        return self._base is not None

    def _shifted(self, totals: Sequence[float] | None) -> bool:
        """The feet's virtual forces moved away from their baseline values (a weight
        shift); learns those values while the residual baselines are learnt."""
        if totals is None:
            return False
        tot = np.asarray(totals, dtype=float)
        if tot.shape != (2,) or not np.isfinite(tot).all():
            return False
        if self._base is None:
            self._tot_sum += tot
            self._tot_n += 1
            return False
        if self._tot_base is None:
            return False
        lim = self.config.max_shift_fraction * abs(float(self._tot_base.sum()))
        return bool(np.abs(tot - self._tot_base).max() > lim)

    def update(
        self,
        measured: Sequence[float],
        vfs: Sequence[float],
        double_support: bool,
        totals: Sequence[float] | None = None,
    ) -> tuple[np.ndarray, list[str]]:
        """One sample.

        Args:
            measured: (8,) measured forces [N].
            vfs: (8,) virtual forces [N].
            double_support: Both feet planned (or estimated) in contact.
            totals: (2,) virtual vertical force of each foot (right, left) [N]; when
                given, a weight shift larger than ``max_shift_fraction`` of the weight
                ends the stand.

        Returns:
            ``(flags (8,) bool, kinds)``; never raises on bad numbers.
        """
        c = self.config
        self._t += self.dt_s
        if not double_support:
            if self._ds_s > 0:
                self.reset()
            return self.flags, self.kinds
        d = np.asarray(measured, dtype=float) - np.asarray(vfs, dtype=float)
        if d.shape != (_N,):
            return self.flags, self.kinds
        if self._base is not None and self._shifted(totals):
            self.reset()  # a new stand begins now
        self._ds_s += self.dt_s
        fin = np.isfinite(d)
        first = ~np.isfinite(self._lp) & fin
        self._lp[first] = d[first]
        upd = fin & ~first
        self._lp[upd] += self._a * (d[upd] - self._lp[upd])
        xm = np.asarray(measured, dtype=float)
        self._xlp[first] = xm[first]
        self._xlp[upd] += self._a * (xm[upd] - self._xlp[upd])
        if self._ds_s < c.settle_s:
            return self.flags, self.kinds
        if self._base is None:
            if fin.all():
                self._base_sum += d
                self._base_n += 1
                self._shifted(totals)
            if self._base_n * self.dt_s >= c.baseline_s:
                self._base = self._base_sum / self._base_n
                if self._tot_n:
                    self._tot_base = self._tot_sum / self._tot_n
            return self.flags, self.kinds
        dev_s = np.where(np.isfinite(self._lp), self._lp - self._base, 0.0)
        dev = np.abs(dev_s)
        # median of the other seven deviations: the 4th or 5th smallest of all eight
        order = np.sort(dev)
        med_others = np.where(dev <= order[3], order[4], order[3])
        half = (dev > 0.5 * c.threshold_n) & ~np.isfinite(self._half_t)
        self._half_t[half] = self._t
        self._half_t[(dev < 0.25 * c.threshold_n) & ~self.flags] = np.nan
        over = (dev > c.threshold_n) & (dev > c.isolation_ratio * med_others) & ~self.flags
        self._over_s = np.where(over, self._over_s + self.dt_s, 0.0)
        new = np.flatnonzero((self._over_s >= c.persist_s) & ~self.flags)
        for i in new:
            self.flags[i] = True
            rise = self._t - self._half_t[i]
            self.kinds[i] = "drift" if rise > c.drift_rise_s else "offset"
        quiet = self.flags & (dev < 0.5 * c.threshold_n)
        self._quiet_s = np.where(quiet, self._quiet_s + self.dt_s, 0.0)
        gone = self.flags & (self._quiet_s >= c.clear_s)
        if gone.any():
            self.flags[gone] = False
            for i in np.flatnonzero(gone):
                self.kinds[i] = "none"
            self._quiet_s[gone] = 0.0
            self._half_t[gone] = np.nan
        self.eta_n = np.where(self.flags, dev_s, 0.0)
        return self.flags, self.kinds


def _contact(cref: float, cest: float) -> bool:
    """Contact from the planned contact, else the estimated one (NaN: no contact)."""
    c = cref if math.isfinite(cref) else cest
    return math.isfinite(c) and c > 0.5


class StandingStage:
    """The standing layer of the default monitor (runs after detector and recovery).

    Per sample it feeds :class:`StandingDetector` (double support: both feet in contact,
    planned else estimated; the virtual foot forces for the weight-shift check) and
    edits the output row of the detector: a sensor the standing detector flags and the
    detector has not is flagged with the standing kind, ``eta_<s>`` = its deviation from
    the baseline [N] and ``recovered_<s>`` = reading − ``eta``. When the stand ends the
    flag is held until the detector flags the sensor or until the sensor's foot has
    completed a swing and then the other foot has (the per-sensor swing and
    single-support tests had their chance and saw nothing). While held, two explanations
    of the standing deviation ``eta`` compete, as the load now changes: an offset
    (``recovered = reading − eta``) and a gain ``g = level / (level − eta)`` (``level``
    the reading at the end of the stand; ``recovered = reading / g``); the one closer to
    the virtual sensor (plus the stand's baseline residual) over ``hold_filter_s`` wins
    once it is ``threshold_n`` closer (in swing a gain reads zero, an offset ``eta``),
    and the kind becomes ``gain``.

    Args:
        dt_s: Sampling period [s].
        config: Settings of the standing detector.
    """

    def __init__(self, dt_s: float = 0.001, config: StandingConfig | None = None) -> None:
        self.detector = StandingDetector(dt_s, config)
        tau = self.detector.config.hold_filter_s
        self._a_hold = 1.0 if tau <= 0 else 1.0 - math.exp(-float(dt_s) / tau)
        self.reset()

    def reset(self) -> None:
        """Forget the stand and the held flags."""
        self.detector.reset()
        self.held = [False] * _N
        self.held_kind = ["none"] * _N
        self.held_eta = [0.0] * _N
        self.held_gain = [math.nan] * _N
        self.held_ref = [0.0] * _N  # baseline residual of the stand [N]
        self._e_off = [0.0] * _N
        self._e_gain = [0.0] * _N
        self._stage = [0] * _N  # 0: wait own swing, 1: wait other swing after it
        self._prev = [True, True]
        self._lifted = [False, False]

    def _swings(self, contact: Sequence[bool]) -> list[bool]:
        """Per foot: a swing ended (touchdown after a lift-off) at this sample."""
        done = [False, False]
        for f in range(2):
            if self._prev[f] and not contact[f]:
                self._lifted[f] = True
            elif contact[f] and not self._prev[f] and self._lifted[f]:
                done[f] = True
                self._lifted[f] = False
            self._prev[f] = contact[f]
        return done

    def _held(self, i: int, xi: float, vi: float) -> tuple[str, float]:
        """Kind and ``eta`` [N] of held sensor ``i`` at reading ``xi``, virtual force
        ``vi`` [N]: offset or gain, whichever explains the reading better."""
        eta, g = self.held_eta[i], self.held_gain[i]
        if self.held_kind[i] == "gain":
            return "gain", xi - xi / g if math.isfinite(xi) else eta
        if (math.isfinite(g) and g > 0 and self.held_kind[i] == "offset"
                and math.isfinite(xi) and math.isfinite(vi)):
            ref = vi + self.held_ref[i]
            a = self._a_hold
            self._e_off[i] += a * (abs(xi - eta - ref) - self._e_off[i])
            self._e_gain[i] += a * (abs(xi / g - ref) - self._e_gain[i])
            if self._e_off[i] - self._e_gain[i] > self.detector.config.threshold_n:
                self.held_kind[i] = "gain"
                return "gain", xi - xi / g
        return self.held_kind[i], eta

    def step(
        self, x: Sequence[float], v: Sequence[float], tot: Sequence[float],
        cref: Sequence[float], cest: Sequence[float], out: MutableMapping[str, Any],
    ) -> None:
        """One sample; edits ``out`` (the detector's and recovery's row) in place.

        Args:
            x: Measured forces (8,) [N].
            v: Virtual corner forces (8,) [N] (NaN when not usable).
            tot: Virtual vertical force of each foot (right, left) [N].
            cref: Planned contact per foot (0/1, NaN when unknown).
            cest: Estimated contact per foot (0/1, NaN when unknown).
            out: Row with ``flag_<s>``, ``kind_<s>``, ``eta_<s>``, ``recovered_<s>``.
        """
        contact = [_contact(cref[f], cest[f]) for f in range(2)]
        det = self.detector
        was = det.flags.copy()
        kinds_before = list(det.kinds)
        eta_before = det.eta_n.copy()
        base_before = det.baseline_n
        level_before = det.level_n
        flags, kinds = det.update(x, v, contact[0] and contact[1], tot)
        done = self._swings(contact)
        for i in range(_N):
            if was[i] and not det.standing and not flags[i]:  # the stand ended: hold
                self.held[i] = True
                self.held_kind[i] = kinds_before[i]
                self.held_eta[i] = float(eta_before[i])
                load = float(level_before[i] - eta_before[i])
                self.held_gain[i] = (float(level_before[i]) / load
                                     if load > det.config.threshold_n else math.nan)
                self.held_ref[i] = float(base_before[i]) if math.isfinite(
                    base_before[i]) else 0.0
                self._e_off[i] = self._e_gain[i] = 0.0
                self._stage[i] = 0
        for i in range(_N):
            flagged = bool(out.get(_FLAG_COLS[i], False))
            if flagged:  # the per-sensor detector has its own verdict
                self.held[i] = False
                continue
            f = i // 4
            if self.held[i] and not flags[i]:
                if self._stage[i] == 0 and done[f]:
                    self._stage[i] = 1
                elif self._stage[i] == 1 and done[1 - f]:
                    self.held[i] = False
                    continue
            if flags[i]:
                self.held[i] = False
                kind, eta = kinds[i], float(det.eta_n[i])
            elif self.held[i]:
                kind, eta = self._held(i, float(x[i]), float(v[i]))
            else:
                continue
            out[_FLAG_COLS[i]] = True
            out[_KIND_COLS[i]] = kind
            out[_ETA_COLS[i]] = eta
            xi = float(x[i])
            out[_REC_COLS[i]] = xi - eta if math.isfinite(xi) else float("nan")
