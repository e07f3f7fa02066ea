"""The four residual tests of the default detector (one sample each, plain floats).

Each test is a two-sided CUSUM (:func:`~grfguard.detect.blocks.cusum_step`) on a
residual normalised per phase (thresholds in :class:`~grfguard.detect.thresholds.Thresholds`),
evaluated only where its gate is open (:mod:`grfguard.detect.gating`):

- :func:`constant_test`: a loaded sensor whose reading repeats exactly
  ``const_samples`` times (``Thresholds.const_s`` seconds at the log's rate, see
  :meth:`~grfguard.detect.tuning.DetectTuning.const_samples`) is frozen, stuck or
  clipped (a healthy load cell always shows noise; a quantised one repeats by chance,
  so the run must also be longer than its own chance repeats explain, see
  :func:`constant_test`);
- :func:`swing_test`: in swing the true force is zero, so ``z = N_meas / σ_swing``;
- :func:`corner_test`: in clean single support ``r = (N_meas - N̂) / weight`` per corner
  (N̂ the VFS corner force), an additive fault found in swing compensated;
- :class:`FootTotalTest`: in clean single support ``r = (Σ N_meas - F_z,VFS) / weight``
  over the foot; isolated by the signed corner residuals accumulated while the sum
  grows (votes), or charged to the foot's already stance-flagged sensors.

An alarm resets the sums of its CUSUM. Each function returns what it saw; the
detector (:mod:`grfguard.detect.detector`) turns alarms into flags.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from grfguard.detect.blocks import cusum_step
from grfguard.detect.sensor_state import SensorState
from grfguard.detect.thresholds import Thresholds

__all__ = ["ADDITIVE", "constant_test", "swing_test", "corner_test", "FootTotalTest"]

#: Fault kinds corrected by subtracting ``eta``.
ADDITIVE = ("offset", "drift")
_STANCE_SOURCES = ("total", "corner")
_NAN = float("nan")


def constant_test(
    s: SensorState, x_n: float, loaded: bool, const_samples: int, max_chance: float = 0.0
) -> bool:
    """Track exact repetitions of the (finite) reading ``x_n`` [N]; True = alarm (the
    reading repeated ``const_samples`` times on a loaded foot).

    With ``max_chance`` > 0 the run must also be one a healthy sensor makes with at most
    that probability: with ``p`` the sensor's own share of exact repeats among its
    consecutive loaded readings while unflagged (``(repeats + 1) / (pairs + 2)``, the
    run in progress left out; unloaded readings are left out too, a cell clipped at zero
    in swing repeats without telling anything about stance), ``n`` identical readings
    need ``p^(n-1) <= max_chance``. A sensor whose readings never repeat (no
    quantisation) keeps ``p`` near 0 and ``const_samples`` decides; a coarsely quantised
    one at a low rate needs a longer run.
    """
    prev = s.last_reading_n
    same = x_n == prev
    if same:
        s.repeats += 1
    else:
        if not s.flag:  # a run that ended unflagged: its repeats were chance repeats
            s.pairs += s.run_pairs
            s.chance_repeats += s.run_repeats
        s.run_pairs = s.run_repeats = 0
        s.repeats = 0
        if s.flag and s.source == "const":
            s.varied = True
    if loaded and math.isfinite(prev):
        s.run_pairs += 1
        s.run_repeats += same
    s.last_reading_n = x_n
    if s.repeats + 1 >= const_samples and loaded:
        if max_chance > 0.0:
            p = (s.chance_repeats + 1) / (s.pairs + 2)
            if p < 1.0 and s.repeats * math.log(p) > math.log(max_chance):
                return False
        if s.flag and s.source == "const" and s.varied and x_n == s.const_value_n:
            s.const_returns += 1  # the flat top came back: saturation
            s.varied = False
        return True
    return False


def swing_test(s: SensorState, x_n: float, th: Thresholds) -> tuple[bool, float]:
    """Swing CUSUM on ``z = x_n / σ_swing``; returns ``(alarm, statistic [σ·samples])``."""
    z = x_n / th.sigma_swing_n
    s.swing_pos, s.swing_neg = cusum_step(s.swing_pos, s.swing_neg, z, th.swing_kappa)
    stat = max(s.swing_pos, s.swing_neg)
    if stat > th.swing_h:
        s.swing_pos = s.swing_neg = 0.0
        return True, stat
    return False, stat


def compensated(s: SensorState) -> bool:
    """The sensor carries an additive fault found in swing (exactly compensable)."""
    return s.flag and s.kind in ADDITIVE and s.source == "swing"


def corner_test(
    s: SensorState, x_n: float, vfs_n: float, weight_n: float, th: Thresholds
) -> tuple[bool, float, float, float]:
    """Corner CUSUM on ``r = (x - η̂·[compensated] - N̂) / weight``.

    Returns:
        ``(alarm, statistic [σ·samples], r [-], z [σ])``; a compensated sensor never
        alarms (its residual is already explained).
    """
    comp = compensated(s)
    corr = x_n - (s.eta_n if comp else 0.0)
    r = (corr - vfs_n) / weight_n
    z = r / th.corner_sigma
    s.corner_pos, s.corner_neg = cusum_step(s.corner_pos, s.corner_neg, z, th.corner_kappa)
    stat = max(s.corner_pos, s.corner_neg)
    if stat > th.corner_h:
        s.corner_pos = s.corner_neg = 0.0
        return (not comp), stat, r, z
    return False, stat, r, z


class FootTotalTest:
    """Foot-total CUSUM of both feet with isolation votes (index 0 = right, 1 = left)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Sums and votes back to zero."""
        self.g_pos = [0.0, 0.0]
        self.g_neg = [0.0, 0.0]
        self.votes = [[0.0] * 4, [0.0] * 4]

    @staticmethod
    def usable(sensors: Sequence[SensorState]) -> bool:
        """The balance is only meaningful when every flagged sensor of the foot is
        exactly compensated (swing-sized offset/drift) or is one under stance test."""
        return not any(
            s.flag and not (s.source == "swing" and s.kind in ADDITIVE)
            and s.source not in _STANCE_SOURCES
            for s in sensors
        )

    @staticmethod
    def corrected(sensors: Sequence[SensorState], x_n: Sequence[float]) -> list[float]:
        """The foot's readings with the compensable faults removed [N]."""
        return [xi - s.eta_n if compensated(s) else xi for s, xi in zip(sensors, x_n, strict=True)]

    def step(
        self, f: int, corr: Sequence[float], vfs_n: Sequence[float], total_n: float,
        weight_n: float, th: Thresholds,
    ) -> tuple[float, float, float]:
        """One sample of foot ``f``: corrected readings ``corr`` and VFS corners ``vfs_n``
        [N], VFS foot force ``total_n`` [N]; returns ``(r [-], z [σ], statistic)``.
        Votes accumulate ``sign(z)·(corr_j - N̂_j)`` while ``|z| > κ`` and restart when
        both sums are back at zero."""
        r = (math.fsum(corr) - total_n) / weight_n
        z = r / th.total_sigma
        self.g_pos[f], self.g_neg[f] = cusum_step(self.g_pos[f], self.g_neg[f], z, th.total_kappa)
        stat = max(self.g_pos[f], self.g_neg[f])
        sgn = 1.0 if z > 0 else -1.0
        if abs(z) > th.total_kappa:
            for j in range(4):
                if math.isfinite(vfs_n[j]):
                    self.votes[f][j] += sgn * (corr[j] - vfs_n[j])
        if self.g_pos[f] == 0.0 and self.g_neg[f] == 0.0:
            self.votes[f] = [0.0] * 4
        return r, z, stat

    def isolate(self, f: int, sensors: Sequence[SensorState]) -> list[int]:
        """After an alarm of foot ``f``: the foot's sensor indices (0-3) to charge: the
        already stance-flagged ones, else the unflagged one with the largest vote.
        Resets the foot's sums and votes."""
        self.g_pos[f] = self.g_neg[f] = 0.0
        already = [j for j, s in enumerate(sensors) if s.flag and s.source in _STANCE_SOURCES]
        if already:
            out = already
        else:
            cand = [(self.votes[f][j], j) for j, s in enumerate(sensors) if not s.flag]
            out = [max(cand)[1]] if cand else []
        self.votes[f] = [0.0] * 4
        return out
