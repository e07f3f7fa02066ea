"""Fault detection while the robot stands still in double support.

While walking, each foot is unloaded once per step and the per-sensor tests re-learn
their zero; standing, no foot is ever unloaded and the internal force between the feet
is not observable, so those tests wait for walking to resume. Standing is quasi-static,
though: the residual ``d_i = f_i - v_i`` of a healthy sensor stays where it was when the
stand began (the virtual sensor's split of the load between the feet may be off, but it
stays off by the same amount while nothing moves). :class:`StandingDetector` learns each
residual's baseline over ``baseline_s`` after ``settle_s`` of double support, then flags
a sensor whose low-passed residual leaves the baseline by more than
``threshold_fraction`` of the robot's weight (15 N on SURALP) for ``persist_s`` while
the other sensors' deviations stay small (``isolation_ratio``): a common shift of all
residuals is a model or posture change, not a sensor fault. A stand ends when a foot
lifts or when the virtual force of a foot moves by more than ``max_shift_fraction`` of
the weight from its value at the baseline (the robot shifts its weight: the split error
changes). Kinds are ``offset`` (the deviation appeared within ``drift_rise_s``) or
``drift``; a gain fault is an offset while the load stands still (``(g - 1)·load`` is
constant) and is reported as one.

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
from typing import Any, NamedTuple

import numpy as np

from grfguard._validate import check_number, check_period
from grfguard.model.robot import SENSOR_NAMES

__all__ = ["StandEnd", "StandingConfig", "StandingDetector", "StandingStage"]

# The schema's corner cells ``r1..r4, l1..l4``: four load cells per sole (the corner-cell
# sensing of a robot TOML). This layer works on them by design; robots with ankle
# force/torque sensors go through ``detect/channels.py``, which takes any channel list.
_N = len(SENSOR_NAMES)
_MID = _N // 2 - 1  # with one sensor left out, the median of the others is order[_MID(+1)]
_NAN = float("nan")
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
        threshold_fraction: Deviation from the baseline that flags a sensor, as a fraction
            of the robot's weight (0.0134182...: 15 N on SURALP's 114 kg, 4.4 N on G1's
            33.3 kg) [-].
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
    threshold_fraction: float = 0.013418207971488991  # x 1117.884 N = 15.0 N exactly
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
        check_number(o, "threshold_fraction", self.threshold_fraction, 0.0, 10.0, "")
        check_number(o, "persist_s", self.persist_s, 0.0, 10.0, "s")
        check_number(o, "isolation_ratio", self.isolation_ratio, 1.0, 100.0, "")
        check_number(o, "drift_rise_s", self.drift_rise_s, 0.0, 60.0, "s")
        check_number(o, "max_shift_fraction", self.max_shift_fraction, 0.0, 10.0, "")
        check_number(o, "clear_s", self.clear_s, 0.0, 3600.0, "s")
        check_number(o, "hold_filter_s", self.hold_filter_s, 0.0, 60.0, "s")


class StandEnd(NamedTuple):
    """What a stand with flagged sensors left behind when it ended (per sensor, (8,)).

    Attributes:
        flags: Flagged at the end.
        kinds: Their kinds.
        eta_n: Deviations from the baselines [N].
        baseline_n: Residual baselines of the stand [N].
        level_n: Low-passed readings [N].
    """

    flags: tuple[bool, ...]
    kinds: tuple[str, ...]
    eta_n: tuple[float, ...]
    baseline_n: tuple[float, ...]
    level_n: tuple[float, ...]


class StandingDetector:
    """Per-sensor detection of additive faults during a double-support stand.

    Plain floats per sample (eight sensors: small numpy arrays would cost more than the
    arithmetic). ``flags`` ((8,) bool array), ``kinds`` and ``eta_n`` ((8,) [N]) are the
    current verdicts; ``ended`` is the :class:`StandEnd` of the last stand that ended
    with flagged sensors (None otherwise; the caller may clear it).

    Args:
        dt_s: Sampling period of the log [s] (required: real robots log at 100 Hz to 1 kHz;
            the monitor passes its ``config.dt_s``, the log's rate).
        config: Settings.
        weight_n: The robot's weight m g [N] (required: the threshold is a fraction of it).

    Raises:
        ConfigError: If ``dt_s`` is not a positive number of seconds or ``weight_n`` not a
            positive weight.
    """

    def __init__(self, dt_s: float, config: StandingConfig | None = None, *,
                 weight_n: float) -> None:
        self.dt_s = check_period("standing", dt_s)
        self.config = config if config is not None else StandingConfig()
        check_number("standing", "weight_n", weight_n, 1e-3, 1e7, "N")
        #: ``threshold_fraction`` of this robot's weight [N]
        self.threshold_n = self.config.threshold_fraction * float(weight_n)
        self._a = (1.0 if self.config.filter_s <= 0
                   else 1.0 - math.exp(-self.dt_s / self.config.filter_s))
        self.ended: StandEnd | None = None
        self.reset()

    def reset(self) -> None:
        """Forget the stand (and ``ended``)."""
        self._new_stand()
        self._t = 0.0
        self.ended = None

    def _new_stand(self) -> None:
        """End the current stand (``ended`` records its flags, if any)."""
        if getattr(self, "_any", False):
            self.ended = StandEnd(tuple(self._flags), tuple(self.kinds), tuple(self._eta),
                                  tuple(self._base or [_NAN] * _N), tuple(self._xlp))
        self._ds_s = 0.0
        self._base_sum = [0.0] * _N
        self._base_n = 0
        self._base: list[float] | None = None
        self._tot_sum = [0.0, 0.0]
        self._tot_n = 0
        self._tot_base: list[float] | None = None
        self._lp = [_NAN] * _N
        self._xlp = [_NAN] * _N
        self._over_s = [0.0] * _N
        self._quiet_s = [0.0] * _N
        self._half_t = [_NAN] * _N
        self._flags = [False] * _N
        self._eta = [0.0] * _N
        self._any = False
        self.flags = np.zeros(_N, dtype=bool)
        self.kinds = ["none"] * _N

    @property
    def eta_n(self) -> np.ndarray:
        """(8,) deviation of each flagged sensor from its baseline [N] (0 when not flagged)."""
        return np.array(self._eta)

    @property
    def baseline_n(self) -> np.ndarray:
        """(8,) residual baselines of the stand [N] (NaN before they are learnt)."""
        return np.array(self._base if self._base is not None else [_NAN] * _N)

    @property
    def level_n(self) -> np.ndarray:
        """(8,) low-passed readings [N] (NaN outside a stand)."""
        return np.array(self._xlp)

    @property
    def standing(self) -> bool:
        """True once the baselines are learnt and the stand goes on."""
        return self._base is not None

    def _shifted(self, totals: Sequence[float] | None) -> bool:
        """The feet's virtual forces moved away from their baseline values (a weight
        shift); learns those values while the residual baselines are learnt."""
        if totals is None or len(totals) != 2:
            return False
        t0, t1 = float(totals[0]), float(totals[1])
        if not (math.isfinite(t0) and math.isfinite(t1)):
            return False
        if self._base is None:
            self._tot_sum[0] += t0
            self._tot_sum[1] += t1
            self._tot_n += 1
            return False
        tb = self._tot_base
        if tb is None:
            return False
        lim = self.config.max_shift_fraction * abs(tb[0] + tb[1])
        return abs(t0 - tb[0]) > lim or abs(t1 - tb[1]) > lim

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
        dt = self.dt_s
        self._t += dt
        if not double_support:
            if self._ds_s > 0:
                self._new_stand()
            return self.flags, self.kinds
        try:
            xm = [float(q) for q in measured]
            d = [a - float(b) for a, b in zip(xm, vfs, strict=True)]
        except (TypeError, ValueError):
            return self.flags, self.kinds
        if len(d) != _N:
            return self.flags, self.kinds
        if self._base is not None and self._shifted(totals):
            self._new_stand()  # a new stand begins now
        self._ds_s += dt
        a = self._a
        lp, xl = self._lp, self._xlp
        fin_all = True
        for i in range(_N):
            di = d[i]
            if not math.isfinite(di):
                fin_all = False
            elif lp[i] != lp[i]:  # first finite sample
                lp[i] = di
                xl[i] = xm[i]
            else:
                lp[i] += a * (di - lp[i])
                xl[i] += a * (xm[i] - xl[i])
        if self._ds_s < c.settle_s:
            return self.flags, self.kinds
        if self._base is None:
            if fin_all:
                bs = self._base_sum
                for i in range(_N):
                    bs[i] += d[i]
                self._base_n += 1
                self._shifted(totals)
            if self._base_n * dt >= c.baseline_s:
                self._base = [q / self._base_n for q in self._base_sum]
                if self._tot_n:
                    self._tot_base = [q / self._tot_n for q in self._tot_sum]
            return self.flags, self.kinds
        self._monitor(lp)
        return self.flags, self.kinds

    def _monitor(self, lp: list[float]) -> None:
        """Deviations from the baselines, flags, kinds, clearing (one sample)."""
        c = self.config
        dt, t, thr = self.dt_s, self._t, self.threshold_n
        base = self._base
        assert base is not None
        dev_s = [q - b if q == q else 0.0 for q, b in zip(lp, base, strict=True)]
        dev = [abs(q) for q in dev_s]
        order = sorted(dev)
        o3, o4 = order[_MID], order[_MID + 1]  # the median of the other _N - 1 is one of these
        flags, half_t = self._flags, self._half_t
        changed = False
        for i in range(_N):
            di = dev[i]
            if not flags[i]:
                if di > 0.5 * thr:
                    if half_t[i] != half_t[i]:
                        half_t[i] = t
                elif di < 0.25 * thr:
                    half_t[i] = _NAN
                med = o4 if di <= o3 else o3
                if di > thr and di > c.isolation_ratio * med:
                    self._over_s[i] += dt
                    if self._over_s[i] >= c.persist_s:
                        flags[i] = True
                        self.kinds[i] = ("drift" if t - half_t[i] > c.drift_rise_s
                                         else "offset")
                        self._quiet_s[i] = 0.0
                        changed = True
                else:
                    self._over_s[i] = 0.0
            else:
                self._over_s[i] = 0.0
                self._quiet_s[i] = self._quiet_s[i] + dt if di < 0.5 * thr else 0.0
                if self._quiet_s[i] >= c.clear_s:  # the fault went away
                    flags[i] = False
                    self.kinds[i] = "none"
                    self._quiet_s[i] = 0.0
                    half_t[i] = _NAN
                    self._eta[i] = 0.0
                    changed = True
            if flags[i]:
                self._eta[i] = dev_s[i]
        if changed:
            self.flags = np.array(flags, dtype=bool)
            self._any = any(flags)


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
    once it is the detector's threshold closer (in swing a gain reads zero, an offset ``eta``),
    and the kind becomes ``gain``.

    Args:
        dt_s: Sampling period of the log [s] (required, checked).
            :class:`~grfguard.detect.Monitor` passes its ``config.dt_s`` (the log's rate,
            from ``Monitor.for_log``).
        config: Settings of the standing detector.
        weight_n: The robot's weight m g [N] (the monitor passes its robot's).

    Raises:
        ConfigError: If ``dt_s`` is not a positive number of seconds or ``weight_n`` not a
            positive weight.
    """

    def __init__(self, dt_s: float, config: StandingConfig | None = None, *,
                 weight_n: float) -> None:
        self.detector = StandingDetector(dt_s, config, weight_n=weight_n)
        tau = self.detector.config.hold_filter_s
        self._a_hold = 1.0 if tau <= 0 else 1.0 - math.exp(-self.detector.dt_s / tau)
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
        self._any_held = False
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
            if self._e_off[i] - self._e_gain[i] > self.detector.threshold_n:
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
        det.update(x, v, contact[0] and contact[1], tot)
        done = self._swings(contact)
        end = det.ended
        if end is not None:  # a stand with flagged sensors ended: hold them
            det.ended = None
            self._hold(end)
        flags = det._flags
        if not (det._any or self._any_held):
            return
        for i in range(_N):
            if not (flags[i] or self.held[i]):
                continue
            if out.get(_FLAG_COLS[i], False):  # the per-sensor detector has its own verdict
                self.held[i] = False
                continue
            xi = float(x[i])
            if flags[i]:
                self.held[i] = False
                kind, eta = det.kinds[i], det._eta[i]
            else:
                f = i // 4
                if self._stage[i] == 0 and done[f]:
                    self._stage[i] = 1
                elif self._stage[i] == 1 and done[1 - f]:
                    self.held[i] = False
                    continue
                kind, eta = self._held(i, xi, float(v[i]))
            out[_FLAG_COLS[i]] = True
            out[_KIND_COLS[i]] = kind
            out[_ETA_COLS[i]] = eta
            out[_REC_COLS[i]] = xi - eta if math.isfinite(xi) else _NAN
        self._any_held = any(self.held)

    def _hold(self, end: StandEnd) -> None:
        """Hold the flags of a stand that ended."""
        thr = self.detector.threshold_n
        for i in range(_N):
            if not end.flags[i]:
                continue
            self.held[i] = True
            self.held_kind[i] = end.kinds[i]
            eta, level, base = end.eta_n[i], end.level_n[i], end.baseline_n[i]
            self.held_eta[i] = eta
            load = level - eta
            self.held_gain[i] = level / load if load > thr else _NAN
            self.held_ref[i] = base if math.isfinite(base) else 0.0
            self._e_off[i] = self._e_gain[i] = 0.0
            self._stage[i] = 0
        self._any_held = any(self.held)
