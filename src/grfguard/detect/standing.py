"""Fault detection while the robot stands still in double support.

While walking, each foot is unloaded once per step and the per-sensor tests re-learn
their zero; standing, no foot is ever unloaded and the internal force between the feet
is not observable, so those tests wait for walking to resume. Standing is quasi-static,
though: the residual ``d_i = f_i - v_i`` of a healthy sensor stays where it was when
the stand began. :class:`StandingDetector` learns each residual's baseline over
``baseline_s`` after ``settle_s`` of double support, then flags a sensor whose low-passed
residual leaves the baseline by more than ``threshold_n`` for ``persist_s`` while the
other sensors' deviations stay small (``isolation_ratio``): a common shift of all
residuals is a model or posture change, not a sensor fault. The flag holds until the
stand ends; kinds are ``offset`` (the deviation appeared within ``drift_rise_s``) or
``drift``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from grfguard._validate import check_number

__all__ = ["StandingConfig", "StandingDetector"]

_N = 8


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
    """

    settle_s: float = 0.6
    baseline_s: float = 0.3
    filter_s: float = 0.02
    threshold_n: float = 15.0
    persist_s: float = 0.04
    isolation_ratio: float = 3.0
    drift_rise_s: float = 0.2

    def __post_init__(self) -> None:
        o = "standing"
        check_number(o, "settle_s", self.settle_s, 0.0, 60.0, "s")
        check_number(o, "baseline_s", self.baseline_s, 0.001, 60.0, "s")
        check_number(o, "filter_s", self.filter_s, 0.0, 10.0, "s")
        check_number(o, "threshold_n", self.threshold_n, 0.0, 1e5, "N")
        check_number(o, "persist_s", self.persist_s, 0.0, 10.0, "s")
        check_number(o, "isolation_ratio", self.isolation_ratio, 1.0, 100.0, "")
        check_number(o, "drift_rise_s", self.drift_rise_s, 0.0, 60.0, "s")


class StandingDetector:
    """Per-sensor detection of additive faults during a double-support stand.

    Args:
        dt_s: Sampling period in [s].
        config: Settings.
    """

    def __init__(self, dt_s: float = 0.001, config: StandingConfig | None = None) -> None:
        self.dt_s = float(dt_s)
        self.config = config if config is not None else StandingConfig()
        self.reset()

    def reset(self) -> None:
        """Forget the stand."""
        self._ds_s = 0.0
        self._base_sum = np.zeros(_N)
        self._base_n = 0
        self._base: np.ndarray | None = None
        self._lp = np.full(_N, np.nan)
        self._over_s = np.zeros(_N)
        self._half_t = np.full(_N, np.nan)
        self._t = 0.0
        self.flags = np.zeros(_N, dtype=bool)
        self.kinds = ["none"] * _N

    @property
    def standing(self) -> bool:
        """True once the baselines are learnt and the stand goes on."""
        return self._base is not None

    def update(
        self,
        measured: Sequence[float],
        vfs: Sequence[float],
        double_support: bool,
    ) -> tuple[np.ndarray, list[str]]:
        """One sample.

        Args:
            measured: (8,) measured forces [N].
            vfs: (8,) virtual forces [N].
            double_support: Both feet planned (or estimated) in contact.

        Returns:
            ``(flags (8,) bool, kinds)``; never raises on bad numbers.
        """
        c = self.config
        self._t += self.dt_s
        if not double_support:
            if self._ds_s > 0:
                self.reset()
            return self.flags, self.kinds
        self._ds_s += self.dt_s
        d = np.asarray(measured, dtype=float) - np.asarray(vfs, dtype=float)
        a = 1.0 if c.filter_s <= 0 else 1.0 - math.exp(-self.dt_s / c.filter_s)
        fin = np.isfinite(d)
        first = ~np.isfinite(self._lp) & fin
        self._lp[first] = d[first]
        upd = fin & ~first
        self._lp[upd] += a * (d[upd] - self._lp[upd])
        if self._ds_s < c.settle_s:
            return self.flags, self.kinds
        if self._base is None:
            if fin.all():
                self._base_sum += d
                self._base_n += 1
            if self._base_n * self.dt_s >= c.baseline_s:
                self._base = self._base_sum / self._base_n
            return self.flags, self.kinds
        dev = np.abs(np.where(np.isfinite(self._lp), self._lp - self._base, 0.0))
        # median of the other seven deviations: the 4th or 5th smallest of all eight
        order = np.sort(dev)
        med_others = np.where(dev <= order[3], order[4], order[3])
        half = (dev > 0.5 * c.threshold_n) & ~np.isfinite(self._half_t)
        self._half_t[half] = self._t
        over = (dev > c.threshold_n) & (dev > c.isolation_ratio * med_others) & ~self.flags
        self._over_s = np.where(over, self._over_s + self.dt_s, 0.0)
        new = np.flatnonzero((self._over_s >= c.persist_s) & ~self.flags)
        for i in new:
            self.flags[i] = True
            rise = self._t - self._half_t[i]
            self.kinds[i] = "drift" if rise > c.drift_rise_s else "offset"
        return self.flags, self.kinds
