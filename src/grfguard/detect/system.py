"""System-level status: blame the model, not the sensors, when all residuals move together.

A model error (mass, attitude, CoM) moves the residuals ``r_i = f_i - v_i`` (measured
minus virtual force) of every loaded sensor in a pattern fixed by the sole geometry; a
sensor fault moves one residual. :class:`CommonModeMonitor` fits the common pattern

    r_i ~ alpha v_i + L_f (beta_x x_i / S_x + beta_y y_i / S_y)

(``x_i, y_i`` the sensor position in its sole frame [m], ``L_f`` the virtual load of
its foot [N], ``S_x = sum x_k^2`` over a sole's four sensors): ``alpha`` is the relative
total-force error (mass or gain scale), taken from the ratio of the summed residuals to
the summed virtual forces; ``beta`` is a CoP shift common to both feet (attitude, CoM)
in [m], fitted given ``alpha``. The fit uses exponentially
weighted least squares with a slow time constant (``time_constant_s``, default 10 s) so
a sudden sensor fault is caught by the per-sensor tests long before the fit could
absorb it, and it freezes while any sensor is flagged. The fitted pattern is returned as
``correction_n`` (add it to the virtual forces before the per-sensor tests) together with
``model_mismatch`` (True when ``|alpha|`` exceeds ``mass_ratio_limit`` or the CoP shift
exceeds ``cop_shift_limit_m``) and a short ``reason``. The correction is zero unless the
status is raised (on an exact model the per-sensor tests see the plain virtual forces).

Wiring (see :class:`SystemAwareMonitor`): per sample, ``v_i + correction_n[i]`` replaces
``v_i`` in the per-sensor detector, and ``model_mismatch`` / ``reason`` go to the output
(``model_mismatch`` column in ``run``, key in ``update()``, a line in the report).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from grfguard._validate import check_number, check_period
from grfguard.errors import ConfigError
from grfguard.model.robot import SENSOR_NAMES, RobotConfig

__all__ = [
    "CommonModeConfig", "CommonModeMonitor", "CommonModeResult", "SwingZeroConfig",
    "SwingZeroLearner", "GyroBiasConfig", "GyroBiasLearner", "ImuTiltLearner",
    "hold_unarmed_tests", "VibrationConfig", "AccVibrationDetector", "swing_load_to_stance",
    "quiet_vfs_config", "hold_standing_release",
]


@dataclass(frozen=True)
class CommonModeConfig:
    """Settings of :class:`CommonModeMonitor`.

    Attributes:
        time_constant_s: Forgetting time constant of the common-mode fit in [s].
        warmup_s: Loaded time before the status may be raised in [s].
        mass_ratio_limit: ``|alpha|`` above which the total force is blamed on the model.
        cop_shift_limit_m: Common CoP shift above which the attitude/CoM is blamed [m].
        max_ratio: Bound of ``|alpha|`` used in the correction.
        max_cop_shift_m: Bound of the CoP shift used in the correction [m].
        min_load_fraction: A foot enters the fit when its virtual load exceeds this
            fraction of the weight.
        outlier_fraction: A sensor whose residual misses the common pattern by more than
            this fraction of the weight and by ``outlier_ratio`` times the median miss is
            left out of the sample (0.0179: 20 N on a 114 kg robot).
        outlier_ratio: See ``outlier_fraction``.
        single_support_only: Learn only from single-support samples (one foot loaded),
            where the per-sensor stance tests run: in double support a CoM error moves
            load between the feet, a pattern the common CoP shift does not describe.
    """

    time_constant_s: float = 10.0
    warmup_s: float = 2.0
    mass_ratio_limit: float = 0.02
    cop_shift_limit_m: float = 0.01
    max_ratio: float = 0.15
    max_cop_shift_m: float = 0.05
    min_load_fraction: float = 0.2
    outlier_fraction: float = 0.01789094396198532
    outlier_ratio: float = 4.0
    single_support_only: bool = True

    def __post_init__(self) -> None:
        o = "common_mode"
        check_number(o, "time_constant_s", self.time_constant_s, 0.1, 3600.0, "s")
        check_number(o, "warmup_s", self.warmup_s, 0.0, 600.0, "s")
        check_number(o, "mass_ratio_limit", self.mass_ratio_limit, 0.0, 1.0, "")
        check_number(o, "cop_shift_limit_m", self.cop_shift_limit_m, 0.0, 0.5, "m")
        check_number(o, "max_ratio", self.max_ratio, 0.0, 1.0, "")
        check_number(o, "max_cop_shift_m", self.max_cop_shift_m, 0.0, 0.5, "m")
        check_number(o, "min_load_fraction", self.min_load_fraction, 0.0, 1.0, "")
        check_number(o, "outlier_fraction", self.outlier_fraction, 0.0, 10.0, "")
        check_number(o, "outlier_ratio", self.outlier_ratio, 1.0, 100.0, "")


@dataclass(frozen=True)
class CommonModeResult:
    """One step of :class:`CommonModeMonitor`.

    Attributes:
        correction_n: (8,) common-mode residual to add to the virtual forces [N].
        model_mismatch: True when the evidence blames the model.
        reason: Short text (empty when no mismatch), e.g. ``total force off by +5.1 %``.
        ratio: Relative total-force error ``alpha``.
        cop_shift_m: (2,) common CoP shift (x, y) in [m].
    """

    correction_n: np.ndarray
    model_mismatch: bool
    reason: str
    ratio: float
    cop_shift_m: np.ndarray


class CommonModeMonitor:
    """Fits the residual pattern common to all loaded sensors (model error).

    Args:
        robot: Robot description (sensor layout, weight).
        dt_s: Sampling period of the log [s] (required, checked: real robots log at
            100 Hz to 1 kHz; the monitor passes its ``config.dt_s``, the log's rate).
        config: Settings.
    """

    def __init__(
        self, robot: RobotConfig, dt_s: float,
        config: CommonModeConfig | None = None,
    ) -> None:
        self.robot = robot
        self.dt_s = check_period("CommonModeMonitor", dt_s)
        self.config = config if config is not None else CommonModeConfig()
        #: ``outlier_fraction`` of this robot's weight [N]
        self.outlier_n = self.config.outlier_fraction * robot.weight
        p = robot.sensor_positions_in_foot()
        self._x = np.concatenate([p[:, 0], p[:, 0]])
        self._y = np.concatenate([p[:, 1], p[:, 1]])
        # CoP shift d moves a corner's share by L (d . p_i) / sum(p^2) (4 corners)
        self._sx = float(np.sum(p[:, 0] ** 2))
        self._sy = float(np.sum(p[:, 1] ** 2))
        self._xl = [float(q) / self._sx for q in self._x]
        self._yl = [float(q) / self._sy for q in self._y]
        self.reset()

    def reset(self) -> None:
        """Forget the fit."""
        self._M = np.zeros((3, 3))
        self._b = np.zeros(3)
        self._theta = np.zeros(3)
        self._sum_r = 0.0
        self._sum_v = 0.0
        self._sr_f = [0.0, 0.0]  # per foot: summed residuals, virtual forces
        self._sv_f = [0.0, 0.0]
        self._mv_f = [[0.0, 0.0], [0.0, 0.0]]  # per foot: sum v L x / S_x, sum v L y / S_y
        self._alpha_f = [0.0, 0.0]
        self._loaded_s = 0.0
        self._armed_s = 0.0

    @property
    def armed(self) -> bool:
        """``warmup_s`` of usable (single-support) samples have been seen, learned from
        or not (the fit freezes while a sensor is flagged; arming goes on)."""
        return self._armed_s >= self.config.warmup_s

    def update(
        self,
        measured: Sequence[float],
        vfs: Sequence[float],
        valid_foot: Sequence[bool] = (True, True),
        frozen: bool = False,
        planned: Sequence[float] | None = None,
    ) -> CommonModeResult:
        """One sample.

        Args:
            measured: (8,) measured forces [N] (NaN allowed: that sensor is skipped).
            vfs: (8,) virtual forces [N].
            valid_foot: Per foot (right, left): the foot is in contact and its virtual
                forces are valid.
            frozen: Do not learn from this sample (e.g. a sensor is flagged).
            planned: Planned contact per foot (right, left); when given, only planned
                single support is learned from (the virtual sensor may put the whole
                load on one foot in planned double support while the other still
                carries some: a wrong total).

        Returns:
            The :class:`CommonModeResult` (never raises on bad numbers).
        """
        m = [float(q) for q in measured]
        v = [float(q) for q in vfs]
        ok, use, phi = self._select(m, v, valid_foot, planned)
        res = [m[i] - v[i] for i in range(8)]
        self._drop_outlier(res, phi, use)
        if any(use) and not frozen:
            self._learn(res, phi, use)
        return self._result(v, ok, phi)

    def _select(
        self, m: list[float], v: list[float], valid_foot: Sequence[bool],
        planned: Sequence[float] | None,
    ) -> tuple[list[bool], list[bool], list[tuple[float, float, float]]]:
        """Finite pairs, sensors usable for the fit, regressors ``(v_i, L x_i / S_x,
        L y_i / S_y)`` per sensor; counts the arming time."""
        c = self.config
        isf = math.isfinite
        ok = [isf(a) and isf(b) for a, b in zip(m, v, strict=True)]
        loads = [math.fsum(q for q in v[4 * f : 4 * f + 4] if isf(q)) for f in range(2)]
        feet = [bool(valid_foot[f]) and loads[f] > c.min_load_fraction * self.robot.weight
                for f in range(2)]
        if c.single_support_only and all(feet):
            feet = [False, False]
        if planned is not None and c.single_support_only and not (
                all(isf(q) for q in planned) and (planned[0] > 0.5) != (planned[1] > 0.5)):
            feet = [False, False]
        use = [feet[i // 4] and ok[i] for i in range(8)]
        if any(use):
            self._armed_s += self.dt_s
        xs, ys = self._xl, self._yl
        phi = [((v[i] if ok[i] else 0.0), loads[i // 4] * xs[i], loads[i // 4] * ys[i])
               for i in range(8)]
        return ok, use, phi

    def _drop_outlier(self, res: list[float], phi: list, use: list[bool]) -> None:
        """A residual that stands out from the others is a sensor's, not the model's:
        leave it out of this sample (in place on ``use``)."""
        c = self.config
        if sum(use) < 3:
            return
        _, b0, c0 = self._theta
        af = self._alpha_f
        e = {i: abs(res[i] - (af[i // 4] * phi[i][0] + b0 * phi[i][1] + c0 * phi[i][2]))
             for i in range(8) if use[i]}
        worst = max(e, key=e.__getitem__)
        if e[worst] > max(self.outlier_n, c.outlier_ratio * float(np.median(list(e.values())))):
            use[worst] = False

    def _learn(self, res: list[float], phi: list, use: list[bool]) -> None:
        """Exponentially weighted sums, then the per-foot ratios and the CoP shift."""
        c = self.config
        isf = math.isfinite
        lam = math.exp(-self.dt_s / c.time_constant_s)
        M, b = self._M, self._b
        M *= lam
        b *= lam
        sr = sv = 0.0
        for f in range(2):
            self._sr_f[f] *= lam
            self._sv_f[f] *= lam
            self._mv_f[f][0] *= lam
            self._mv_f[f][1] *= lam
        for i in range(8):
            if use[i]:
                p0, p1, p2 = phi[i]
                r = res[i]
                M[0, 0] += p0 * p0
                M[0, 1] += p0 * p1
                M[0, 2] += p0 * p2
                M[1, 1] += p1 * p1
                M[1, 2] += p1 * p2
                M[2, 2] += p2 * p2
                b[0] += p0 * r
                b[1] += p1 * r
                b[2] += p2 * r
                sr += r
                sv += p0
                f = i // 4
                self._sr_f[f] += r
                self._sv_f[f] += p0
                self._mv_f[f][0] += p0 * p1
                self._mv_f[f][1] += p0 * p2
        M[1, 0], M[2, 0], M[2, 1] = M[0, 1], M[0, 2], M[1, 2]
        self._sum_r = lam * self._sum_r + sr
        self._sum_v = lam * self._sum_v + sv
        self._loaded_s += self.dt_s
        # alpha from the totals (robust), per foot (each foot's load cells have their
        # own mean gain) once the foot has data; then the common CoP shift given them
        alpha = self._sum_r / self._sum_v if self._sum_v > 0 else 0.0
        sv_min = 0.1 * self._sum_v
        self._alpha_f = [self._sr_f[f] / self._sv_f[f] if self._sv_f[f] > sv_min
                         else alpha for f in range(2)]
        af = self._alpha_f
        reg = 1e-6 * (M[1, 1] + M[2, 2] + 1e-9)
        m11, m12, m22 = M[1, 1] + reg, M[1, 2], M[2, 2] + reg
        r1 = b[1] - af[0] * self._mv_f[0][0] - af[1] * self._mv_f[1][0]
        r2 = b[2] - af[0] * self._mv_f[0][1] - af[1] * self._mv_f[1][1]
        det = m11 * m22 - m12 * m12
        if det > 0 and isf(det):
            self._theta = np.array(
                [alpha, (m22 * r1 - m12 * r2) / det, (m11 * r2 - m12 * r1) / det])

    def _result(self, v: list[float], ok: list[bool], phi: list) -> CommonModeResult:
        """Status, reason and correction from the current fit."""
        c = self.config
        warm = self._loaded_s >= c.warmup_s
        th = self._theta if warm else np.zeros(3)
        ratio = float(np.clip(th[0], -c.max_ratio, c.max_ratio))
        ratio_f = [float(np.clip(q, -c.max_ratio, c.max_ratio)) if warm else 0.0
                   for q in self._alpha_f]
        sx = float(np.clip(th[1], -c.max_cop_shift_m, c.max_cop_shift_m))
        sy = float(np.clip(th[2], -c.max_cop_shift_m, c.max_cop_shift_m))
        shift = np.array([sx, sy])
        reasons = []
        if warm:
            if max(abs(q) for q in ratio_f) > c.mass_ratio_limit:
                if abs(ratio_f[0] - ratio_f[1]) > c.mass_ratio_limit:
                    reasons.append(f"total force off by {100 * ratio_f[0]:+.1f} % (right), "
                                   f"{100 * ratio_f[1]:+.1f} % (left)")
                else:
                    reasons.append(f"total force off by {100 * ratio:+.1f} %")
            if math.hypot(sx, sy) > c.cop_shift_limit_m:
                reasons.append(
                    f"attitude/CoM inconsistent (CoP shifted {100 * sx:+.1f} cm x, "
                    f"{100 * sy:+.1f} cm y)"
                )
        if reasons:
            corr = np.array([
                (ratio_f[i // 4] * v[i] if ok[i] else 0.0) + phi[i][1] * sx + phi[i][2] * sy
                for i in range(8)])
            corr = np.where(np.isfinite(corr), corr, 0.0)
        else:  # no evidence against the model: leave the virtual forces alone
            corr = np.zeros(8)
        return CommonModeResult(corr, bool(reasons), "; ".join(reasons), ratio, shift)


# ------------------------------------------------------------------ load-cell zeros
@dataclass(frozen=True)
class SwingZeroConfig:
    """Settings of :class:`SwingZeroLearner`.

    Attributes:
        settle_s: Swing time skipped after lift-off before the zeros are learned [s].
        learn_s: Swing time (after ``settle_s``) per foot over which the zeros are
            averaged; afterwards they are frozen (a later drift is not absorbed) [s].
        apply_after_s: Learned swing time before a zero is subtracted [s].
        limit_fraction: A swing reading whose running mean is beyond this fraction of the
            weight is a fault (left to the swing test), not a zero: it is not learned
            (0.0179: 20 N on a 114 kg robot).
        deadband_fraction: A learned zero smaller than this fraction of the weight is not
            applied (on a sensor without zero error the monitor sees the plain readings;
            0.00268: 3 N on a 114 kg robot).
        swing_load_fraction: The foot is in swing when its virtual load is below this
            fraction of the weight (and contact is neither planned nor estimated).
        air_fraction: A swing sample is learned from only when the foot's readings say it
            is in the air: the sum of its unflagged readings minus their zeros learned so
            far is within this fraction of the weight. A planned swing is not always in the air
            (a foot that lands before the plan says, as G1's does, reads its heel cells
            during the last 0.1-0.2 s of the swing): those samples would be learned as
            zeros. 0.05: 56 N on SURALP, 16 N on G1.
    """

    settle_s: float = 0.1
    learn_s: float = 1.0
    apply_after_s: float = 0.3
    limit_fraction: float = 0.01789094396198532
    deadband_fraction: float = 0.002683641594297798
    swing_load_fraction: float = 0.02
    air_fraction: float = 0.05

    def __post_init__(self) -> None:
        o = "swing_zero"
        check_number(o, "settle_s", self.settle_s, 0.0, 10.0, "s")
        check_number(o, "learn_s", self.learn_s, 0.0, 600.0, "s")
        check_number(o, "apply_after_s", self.apply_after_s, 0.0, 600.0, "s")
        check_number(o, "limit_fraction", self.limit_fraction, 0.0, 10.0, "")
        check_number(o, "deadband_fraction", self.deadband_fraction, 0.0, 10.0, "")
        check_number(o, "swing_load_fraction", self.swing_load_fraction, 0.0, 1.0, "")
        check_number(o, "air_fraction", self.air_fraction, 0.0, 10.0, "")


class SwingZeroLearner:
    """Learns each load cell's zero from the first swings (a swing foot carries nothing,
    so its readings are the zeros) and returns it for subtraction from the readings.

    Per foot, samples count once the foot has been in swing for ``settle_s``; the zero of
    a sensor is the mean of its first ``learn_s`` of such samples in which the foot's
    readings say it is in the air (their sum, less the zeros learned so far, within
    ``air_fraction`` of the weight; the sensor not flagged and the running mean within
    ``limit_fraction`` of the weight), then frozen. A zero is
    returned once ``apply_after_s`` of swing has been averaged and when it exceeds
    ``deadband_fraction`` of the weight.

    Args:
        robot: Robot description (weight).
        dt_s: Sampling period of the log [s] (required, checked: real robots log at
            100 Hz to 1 kHz; the monitor passes its ``config.dt_s``, the log's rate).
        config: Settings.
    """

    def __init__(
        self, robot: RobotConfig, dt_s: float,
        config: SwingZeroConfig | None = None,
    ) -> None:
        self.robot = robot
        self.dt_s = check_period("SwingZeroLearner", dt_s)
        self.config = config if config is not None else SwingZeroConfig()
        #: ``limit_fraction`` and ``deadband_fraction`` of this robot's weight [N]
        self.limit_n = self.config.limit_fraction * robot.weight
        self.deadband_n = self.config.deadband_fraction * robot.weight
        #: ``air_fraction`` of this robot's weight [N]
        self.air_n = self.config.air_fraction * robot.weight
        self.reset()

    def reset(self) -> None:
        """Forget the zeros."""
        self._sum = np.zeros(8)
        self._n = np.zeros(8)
        self._swing_s = np.zeros(2)
        self._foot_n = np.zeros(2)
        self._cache: np.ndarray | None = None

    def armed(self, foot: int) -> bool:
        """The foot has swung long enough for its zeros to be known (``apply_after_s`` of
        settled swing), whether or not a zero was learned (a reading beyond
        ``limit_fraction`` of the weight is a fault, left to the tests)."""
        return bool(self._foot_n[foot] * self.dt_s >= self.config.apply_after_s)

    @property
    def zeros_n(self) -> np.ndarray:
        """(8,) zeros applied now [N] (0 where not learned or within the deadband)."""
        if self._cache is None:
            self._cache = self._zeros()
        return self._cache

    def _zeros(self) -> np.ndarray:
        c = self.config
        z = np.divide(self._sum, self._n, out=np.zeros(8), where=self._n > 0)
        ready = self._n * self.dt_s >= c.apply_after_s
        return np.where(ready & (np.abs(z) > self.deadband_n) & (np.abs(z) <= self.limit_n),
                        z, 0.0)

    def update(
        self,
        measured: Sequence[float],
        foot_load_n: Sequence[float],
        in_contact: Sequence[bool],
        flagged: Sequence[bool],
    ) -> np.ndarray:
        """One sample; returns :attr:`zeros_n` (never raises on bad numbers).

        Args:
            measured: (8,) raw readings [N] (NaN skipped).
            foot_load_n: Virtual load of each foot (right, left) [N].
            in_contact: Per foot: contact planned or estimated.
            flagged: (8,) the sensor is flagged.
        """
        c = self.config
        m = np.asarray(measured, dtype=float)
        max_n = c.learn_s / self.dt_s
        for f in range(2):
            load = float(foot_load_n[f])
            swing = (not bool(in_contact[f])) and math.isfinite(load) and (
                load < c.swing_load_fraction * self.robot.weight)
            self._swing_s[f] = self._swing_s[f] + self.dt_s if swing else 0.0
            if self._swing_s[f] <= c.settle_s:
                continue
            self._foot_n[f] += 1
            if not self._in_air(m, f, flagged):
                continue
            for i in range(4 * f, 4 * f + 4):
                if flagged[i] or not math.isfinite(m[i]) or self._n[i] >= max_n:
                    continue
                if abs((self._sum[i] + m[i]) / (self._n[i] + 1)) > self.limit_n:
                    continue
                self._sum[i] += m[i]
                self._n[i] += 1
                self._cache = None
        return self.zeros_n

    def _in_air(self, m: np.ndarray, f: int, flagged: Sequence[bool]) -> bool:
        """The readings of foot ``f`` say it carries nothing: the sum of its finite,
        unflagged readings less their zeros learned so far (0 before any) is within
        ``air_fraction`` of the weight (the compiled twin adds in the same order)."""
        s = 0.0
        for i in range(4 * f, 4 * f + 4):
            q = float(m[i])
            if math.isfinite(q) and not flagged[i]:
                n = self._n[i]
                s += q - (float(self._sum[i] / n) if n > 0 else 0.0)
        return abs(s) <= self.air_n


def hold_unarmed_tests(detector, zeros_armed: Sequence[bool], stance_armed: bool) -> None:
    """Arming delay of the per-sensor tests while the model errors are still unknown
    (``common_mode``): call before each detector step. A foot's swing sums are held at
    zero until its load-cell zeros are known (:meth:`SwingZeroLearner.armed`: the left
    foot's first swing starts before its zeros could be learned), its corner and foot-total
    sums until then and until the common-mode fit has seen ``warmup_s`` of single support
    (:attr:`CommonModeMonitor.armed`). Held sums start from zero every sample, so a gross
    fault (one sample beyond the CUSUM threshold plus the slack) still alarms at once."""
    sensors, totals = detector.sensors, detector.totals
    for f in range(2):
        stance = bool(zeros_armed[f]) and bool(stance_armed)
        for i in range(4 * f, 4 * f + 4):
            s = sensors[i]
            if not zeros_armed[f]:
                s.swing_pos = s.swing_neg = 0.0
            if not stance:
                s.corner_pos = s.corner_neg = 0.0
        if not stance:
            totals.g_pos[f] = totals.g_neg[f] = 0.0


def hold_standing_release(stage, zeros_armed: Sequence[bool], stance_armed: bool) -> None:
    """A flag the standing layer (:class:`~grfguard.detect.standing.StandingStage`) holds
    after a stand is released once the sensor's foot and then the other foot have swung:
    the per-sensor tests had their chance. While those tests are held
    (:func:`hold_unarmed_tests`) they had none: call before each detector step to restart
    the count of a foot whose tests are not armed."""
    for f in range(2):
        if not (bool(zeros_armed[f]) and bool(stance_armed)):
            for i in range(4 * f, 4 * f + 4):
                stage._stage[i] = 0


def swing_load_to_stance(
    x: Sequence[float], v: list[float], tot: list[float], cref: Sequence[float],
    weight_n: float, air_fraction: float = 0.05,
) -> bool:
    """Planned single support, the swing foot's readings near zero (it is in the air),
    yet the virtual sensor put load on it: its kinematic contact (corner heights within
    a few mm of the ground) was fooled by encoder offsets or the attitude. The whole
    vertical force is the stance foot's: move it there (stance corners scaled, swing
    foot zero), in place. Returns True when something was moved.

    Args:
        x: (8,) readings [N] (zeros removed).
        v: (8,) virtual corner forces [N] (modified).
        tot: Virtual foot forces (right, left) [N] (modified).
        cref: Planned contact per foot.
        weight_n: Robot weight [N].
        air_fraction: The swing foot is in the air when its readings sum below this
            fraction of the weight.
    """
    if not all(math.isfinite(q) for q in cref):
        return False
    plan = [q > 0.5 for q in cref]
    if plan[0] == plan[1]:
        return False
    st, sw = (0, 1) if plan[0] else (1, 0)
    other, mine = tot[sw], tot[st]
    if not (math.isfinite(other) and math.isfinite(mine)) or other <= 0.0 or mine <= 0.0:
        return False
    xs = [x[i] for i in range(4 * sw, 4 * sw + 4)]
    if not all(math.isfinite(q) for q in xs) or abs(math.fsum(xs)) > air_fraction * weight_n:
        return False
    k = (mine + other) / mine
    for i in range(4 * st, 4 * st + 4):
        v[i] *= k
    for i in range(4 * sw, 4 * sw + 4):
        v[i] = 0.0
    tot[st], tot[sw] = mine + other, 0.0
    return True


# ------------------------------------------------------------------ accelerometer vibration
@dataclass(frozen=True)
class VibrationConfig:
    """Settings of :class:`AccVibrationDetector`.

    Attributes:
        cutoff_hz: Corner of the causal 2nd-order Butterworth high-pass on the horizontal
            accelerometer axes [Hz] (walking accelerations are slower).
        time_constant_s: Time constant of the running mean of the squared high-passed
            acceleration [s].
        limit_m_s2: Horizontal RMS above ``cutoff_hz`` beyond which the accelerometer is
            called vibrating [m/s^2] (simulated walks with 0.05 m/s^2 white noise: at most
            0.17; the iCub spectrum of issue 10: about 1.1).
        start_s: Samples before this time [s] of data never switch (the mean starts at 0).
        corner_sigma_scale: Factor on ``corner_sigma`` once switched: the corner residual
            noise of the virtual sensor without accelerometer relative to the default one
            (thresholds calibrated on two 60 s exact-model walks: 0.0289 / 0.0109 = 2.65;
            ``total_sigma`` and the swing thresholds are unchanged, 0.0038 both).
    """

    cutoff_hz: float = 5.0
    time_constant_s: float = 2.0
    limit_m_s2: float = 0.3
    start_s: float = 0.5
    corner_sigma_scale: float = 2.7

    def __post_init__(self) -> None:
        o = "vibration"
        check_number(o, "cutoff_hz", self.cutoff_hz, 0.1, 1e4, "Hz")
        check_number(o, "time_constant_s", self.time_constant_s, 0.01, 600.0, "s")
        check_number(o, "limit_m_s2", self.limit_m_s2, 0.0, 1e3, "m/s^2")
        check_number(o, "start_s", self.start_s, 0.0, 600.0, "s")
        check_number(o, "corner_sigma_scale", self.corner_sigma_scale, 1.0, 100.0, "")


#: Cut-off of the twin virtual sensor's rate low-pass in [Hz] (``VFSConfig.filter_cutoff``;
#: the default sensor uses 15 Hz with the accelerometer). Chosen by the per-corner threshold
#: calibrated on a 60 s walk with the iCub accelerometer vibration (``sigma * h``, fraction of
#: the weight x samples): 15 Hz 0.826, 12 Hz 0.675, 10 Hz 0.636, 8 Hz 0.661, 6 Hz 0.775,
#: 4 Hz 1.117; accelerometer fused only in a low band instead (1-2 Hz: 0.937, 0.5-4 Hz:
#: 1.532) is worse than none: what the accelerometer adds on a quiet robot is above 8 Hz,
#: where the vibration is largest.
QUIET_FILTER_CUTOFF_HZ = 10.0


def quiet_vfs_config(cfg):
    """Settings of the twin virtual sensor used once the accelerometer vibrates
    (:class:`AccVibrationDetector`): ``cfg`` (a ``VFSConfig``) without the accelerometer
    and with the rate low-pass at :data:`QUIET_FILTER_CUTOFF_HZ` (or ``cfg``'s own
    cut-off when lower). The one place that decides it (the Python and the compiled
    monitor, and the self-calibration's monitor config, follow it)."""
    import dataclasses

    return dataclasses.replace(cfg, use_accelerometer=False,
                               filter_cutoff=min(cfg.filter_cutoff, QUIET_FILTER_CUTOFF_HZ))


class AccVibrationDetector:
    """Tells when the accelerometer shakes too much for the virtual sensor to use it (the
    horizontal CoM acceleration above 1 Hz comes from it; at the iCub's 1.5 m/s^2 the
    corner forces are off by about 200 N RMS). Latches: once on, stays on until
    :meth:`reset`. The same per-sample arithmetic serves :meth:`update` and :meth:`run`.

    Args:
        dt_s: Sampling period of the log [s] (required, checked: real robots log at
            100 Hz to 1 kHz; the monitor passes its ``config.dt_s``, the log's rate).
        config: Settings.
    """

    def __init__(self, dt_s: float, config: VibrationConfig | None = None) -> None:
        from grfguard._iir import butter_highpass  # scipy.signal's, without importing it

        self.dt_s = check_period("AccVibrationDetector", dt_s)
        self.config = config if config is not None else VibrationConfig()
        c = self.config
        wn = min(0.95, 2.0 * c.cutoff_hz * self.dt_s)
        b, a = butter_highpass(2, wn)
        self._b = [float(q) for q in b]
        self._a = [float(q) for q in a]
        self._lam = math.exp(-self.dt_s / c.time_constant_s)
        self.reset()

    def reset(self) -> None:
        """Forget everything (switch off)."""
        self._z = [[0.0, 0.0], [0.0, 0.0]]  # DF2T states per axis
        self._ms = 0.0
        self._t = 0.0
        self.on = False
        self.rms_m_s2 = 0.0

    def update(self, acc_x: float, acc_y: float) -> bool:
        """One sample of the horizontal accelerometer axes [m/s^2]; returns :attr:`on`
        (never raises; non-finite samples are skipped)."""
        if self.on:
            return True
        if not (math.isfinite(acc_x) and math.isfinite(acc_y)):
            return False
        b0, b1, b2 = self._b
        _, a1, a2 = self._a
        e = 0.0
        for j, u in enumerate((acc_x, acc_y)):
            z = self._z[j]
            y = b0 * u + z[0]
            z[0] = b1 * u - a1 * y + z[1]
            z[1] = b2 * u - a2 * y
            e += y * y
        self._ms = self._lam * self._ms + (1.0 - self._lam) * e
        self._t += self.dt_s
        self.rms_m_s2 = math.sqrt(self._ms)
        if self._t >= self.config.start_s and self.rms_m_s2 > self.config.limit_m_s2:
            self.on = True
        return self.on

    def run(self, acc_x: Sequence[float], acc_y: Sequence[float]) -> int:
        """Reset, then feed whole columns; returns the first index switched on
        (``len`` when never). Leaves the detector in its final state."""
        self.reset()
        for k, (ax, ay) in enumerate(zip(acc_x, acc_y, strict=True)):
            if self.update(float(ax), float(ay)):
                return k
        return len(acc_x)


# ------------------------------------------------------------------ gyro bias
@dataclass(frozen=True)
class GyroBiasConfig:
    """Settings of :class:`GyroBiasLearner`.

    Attributes:
        learn_s: Standing time over which the gyro readings are averaged, then frozen [s].
        apply_after_s: Averaged standing time before the bias is subtracted [s].
        still_rad_s: A sample counts only when every gyro axis is below this [rad/s].
        deadband_rad_s: A bias smaller than this on every axis is not applied (on an
            unbiased gyro the virtual sensor sees the plain readings) [rad/s].
    """

    learn_s: float = 1.5
    apply_after_s: float = 0.5
    still_rad_s: float = 0.1
    deadband_rad_s: float = 0.01

    def __post_init__(self) -> None:
        o = "gyro_bias"
        check_number(o, "learn_s", self.learn_s, 0.0, 600.0, "s")
        check_number(o, "apply_after_s", self.apply_after_s, 0.0, 600.0, "s")
        check_number(o, "still_rad_s", self.still_rad_s, 0.0, 10.0, "rad/s")
        check_number(o, "deadband_rad_s", self.deadband_rad_s, 0.0, 10.0, "rad/s")


class GyroBiasLearner:
    """Learns the gyro bias while the robot stands still (both feet planned in contact,
    the ZMP reference at rest, the gyro quiet): the body does not rotate, so the mean
    reading is the bias. The first ``learn_s`` of such samples are averaged, then the
    bias is frozen; it is returned (for subtraction from the gyro readings before the
    virtual sensor) once ``apply_after_s`` has been averaged and when it exceeds
    ``deadband_rad_s`` on some axis.

    Args:
        dt_s: Sampling period of the log [s] (required, checked: real robots log at
            100 Hz to 1 kHz; the monitor passes its ``config.dt_s``, the log's rate).
        config: Settings.
    """

    def __init__(self, dt_s: float, config: GyroBiasConfig | None = None) -> None:
        self.dt_s = check_period("GyroBiasLearner", dt_s)
        self.config = config if config is not None else GyroBiasConfig()
        self.reset()

    def reset(self) -> None:
        """Forget the bias."""
        self._sum = [0.0, 0.0, 0.0]
        self._n = 0
        self._zmp_prev = (math.nan, math.nan)
        self.still = False

    @property
    def bias_rad_s(self) -> tuple[float, float, float]:
        """The bias applied now [rad/s] (zeros before ``apply_after_s`` or within the
        deadband)."""
        c = self.config
        if self._n == 0 or self._n * self.dt_s < c.apply_after_s:
            return (0.0, 0.0, 0.0)
        b = tuple(q / self._n for q in self._sum)
        if max(abs(q) for q in b) <= c.deadband_rad_s:
            return (0.0, 0.0, 0.0)
        return b  # type: ignore[return-value]

    def update(
        self, gyro: Sequence[float], contact_ref: Sequence[float], zmp_ref: Sequence[float],
    ) -> tuple[float, float, float]:
        """One sample; returns :attr:`bias_rad_s` (never raises on bad numbers).

        Args:
            gyro: (3,) gyro reading [rad/s].
            contact_ref: Planned contact per foot (0/1, NaN unknown).
            zmp_ref: Planned ZMP (x, y) [m] (NaN when the log has none).
        """
        c = self.config
        zr = (float(zmp_ref[0]), float(zmp_ref[1]))
        rest = not any(
            math.isfinite(a) and math.isfinite(b) and abs(a - b) > 1e-6
            for a, b in zip(zr, self._zmp_prev, strict=True)
        )
        self._zmp_prev = zr
        g = [float(q) for q in gyro]
        still = (
            rest and all(math.isfinite(q) and q > 0.5 for q in contact_ref)
            and all(math.isfinite(q) and abs(q) < c.still_rad_s for q in g)
        )
        self.still = bool(still)
        if still and self._n * self.dt_s < c.learn_s:
            self._sum = [a + b for a, b in zip(self._sum, g, strict=True)]
            self._n += 1
        return self.bias_rad_s


# ------------------------------------------------------------------ IMU mounting tilt
class ImuTiltLearner:
    """Learns the IMU mounting tilt (roll, pitch) while the robot stands still: both soles
    are flat on the ground then, so the sole normals the leg kinematics give from the IMU
    attitude, mean over both feet and every ``every_n``-th standing sample of the first
    ``learn_s``, are tilted by the mounting error. Returns the rotation ``C`` (IMU frame
    as reported -> IMU frame as described) once ``apply_after_s`` has been averaged and the
    tilt exceeds ``deadband_deg``; apply it as ``R_WI <- R_WI C^T``, ``acc <- C acc``,
    ``gyro <- C gyro``.

    Args:
        kin: :class:`grfguard.estimate.kinematic.KinematicModel` of the robot.
        dt_s: Sampling period of the log [s] (required, checked: real robots log at
            100 Hz to 1 kHz; the monitor passes its ``config.dt_s``, the log's rate).
    """

    def __init__(self, kin, dt_s: float, learn_s: float = 1.5,
                 apply_after_s: float = 0.5, deadband_deg: float = 0.3,
                 every_n: int = 10) -> None:
        self.kin = kin
        self.dt_s = check_period("ImuTiltLearner", dt_s)
        self.learn_s = float(learn_s)
        self.apply_after_s = float(apply_after_s)
        self.deadband_deg = float(deadband_deg)
        self.every_n = int(every_n)
        self.reset()

    def reset(self) -> None:
        """Forget the tilt."""
        self._z = np.zeros(3)
        self._n = 0
        self._k = 0
        self._C = np.eye(3)

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) correction ``C`` applied now (identity when none)."""
        return self._C

    def tilt_deg(self) -> tuple[float, float]:
        """Learned (roll, pitch) of the mounting in [deg]."""
        if self._n == 0:
            return (0.0, 0.0)
        z = self._z / np.linalg.norm(self._z)
        return (float(np.degrees(-z[1])), float(np.degrees(z[0])))

    def update(self, q_rad: np.ndarray, quat_wxyz: np.ndarray, still: bool) -> np.ndarray:
        """One sample; returns :attr:`rotation` (never raises on bad numbers)."""
        if still and self._n * self.every_n * self.dt_s < self.learn_s:
            self._k += 1
            if self._k % self.every_n == 0 and np.all(np.isfinite(q_rad)) and np.all(
                    np.isfinite(quat_wxyz)):
                try:
                    fr = self.kin.forward(np.asarray(q_rad, float), np.asarray(quat_wxyz, float))
                    zs = fr.R_WS[:, :, 2].mean(axis=0)
                except Exception:  # noqa: BLE001 - a bad sample is skipped
                    zs = None
                if zs is not None and np.all(np.isfinite(zs)):
                    self._z += zs
                    self._n += 1
                    if self._n * self.every_n * self.dt_s >= self.apply_after_s:
                        C = self._solve()
                        if C is not None:
                            self._C = C
        return self._C

    def _solve(self) -> np.ndarray | None:
        z = self._z / np.linalg.norm(self._z)
        ang = math.acos(float(np.clip(z[2], -1.0, 1.0)))
        if math.degrees(ang) <= self.deadband_deg:
            return None
        # R maps e_z to z (minimal rotation): the mounting rotation up to yaw, C = R
        axis = np.cross([0.0, 0.0, 1.0], z)
        axis = axis / np.linalg.norm(axis)
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        R = np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K
        return R


# ---------------------------------------------------------------------------- wiring
class SystemAwareMonitor:
    """The per-sensor :class:`~grfguard.detect.Monitor` with the system-level status and
    the standing detector plugged in, without changing the Monitor.

    Per sample: the virtual sensor runs; :class:`CommonModeMonitor` fits the residual
    pattern common to all sensors and its ``correction_n`` is added to the virtual forces
    (``vfs_<s>`` and ``vfs_total_<side>``) before the inner Monitor (built with
    ``vfs=None``, i.e. on precomputed virtual forces) runs its per-sensor tests; the fit
    freezes while any sensor is flagged. :class:`~grfguard.detect.standing.StandingDetector`
    runs on the corrected residuals and its flags are OR-ed into ``flag_<s>``.

    Outputs: everything the Monitor returns plus ``model_mismatch`` (bool),
    ``model_mismatch_reason`` (text) and ``standing_flag_<s>``.

    How to wire this into the Monitor itself (for the lead): in ``Monitor._step`` (or the
    pipeline's residual stage), right after the virtual forces ``v`` of the sample are
    known and before the residuals are formed, add::

        cm = self._common.update(x, v, valid_foot, frozen=any(self._flags))
        v = [vi + ci for vi, ci in zip(v, cm.correction_n)]
        st_flags, st_kinds = self._standing.update(x, v, cref[0] > 0.5 and cref[1] > 0.5)

    then OR ``st_flags`` into the sensor flags and put ``cm.model_mismatch`` /
    ``cm.reason`` into the output row; create both objects in ``reset()``.

    Args:
        config: Monitor settings.
        robot: Robot description (None: from the log in :meth:`for_log`).
        vfs: A ``VirtualForceSensor``, or None when the rows carry ``vfs_*`` columns.
        common: Settings of the common-mode fit.
        standing: Settings of the standing detector.
    """

    def __init__(
        self,
        config=None,
        robot: RobotConfig | None = None,
        vfs=None,
        common: CommonModeConfig | None = None,
        standing=None,
    ) -> None:
        from grfguard.detect.monitor import Monitor, MonitorConfig
        from grfguard.detect.standing import StandingDetector

        self.config = config if config is not None else MonitorConfig()
        self.vfs = vfs
        if robot is None:
            robot = getattr(vfs, "robot", None)
        if robot is None:
            raise ConfigError("SystemAwareMonitor: no robot description; pass robot= (a "
                              "grfguard.model.robot.RobotConfig, e.g. from "
                              "grfguard.model.robot.load_robot) or a virtual sensor")
        self.inner = Monitor(self.config, vfs=None, robot=robot)
        self.common = CommonModeMonitor(robot, self.config.dt_s, common)
        self.standing = StandingDetector(self.config.dt_s, standing, weight_n=robot.weight)
        self._last_flags = [False] * len(SENSOR_NAMES)
        self._zmp_prev = (math.nan, math.nan)

    @classmethod
    def for_log(cls, log, config=None, **kwargs) -> SystemAwareMonitor:
        """Robot and virtual sensor from the log (as :meth:`Monitor.for_log`)."""
        from grfguard.calib.selfcal import robot_of
        from grfguard.detect.monitor import Monitor

        base = Monitor.for_log(log, config)
        return cls(base.config, robot_of(log), base.vfs, **kwargs)

    def reset(self) -> None:
        """Forget everything."""
        if self.vfs is not None:
            self.vfs.reset()
        self.inner.reset()
        self.common.reset()
        self.standing.reset()
        self._last_flags = [False] * len(SENSOR_NAMES)
        self._zmp_prev = (math.nan, math.nan)

    def _process(self, row: dict, vout: dict) -> dict:
        from grfguard.model.robot import SIDES

        src = vout if self.vfs is not None else row

        def f(d, k):
            try:
                return float(d.get(k, math.nan))
            except (TypeError, ValueError):
                return math.nan

        x = [f(row, f"force_{s}") for s in SENSOR_NAMES]
        v = [f(src, f"vfs_{s}") for s in SENSOR_NAMES]
        cref = [f(row, f"contact_ref_{s}") for s in SIDES]
        cest = [f(src, f"contact_est_{s}") for s in SIDES]
        valid = [
            (ce > 0.5) if math.isfinite(ce) else (cr > 0.5)
            for ce, cr in zip(cest, cref, strict=True)
        ]
        cm = self.common.update(x, v, valid, frozen=any(self._last_flags))
        vc = [vi + float(ci) for vi, ci in zip(v, cm.correction_n, strict=True)]
        # standing: both feet planned in contact and the ZMP reference at rest
        zr = (f(row, "zmp_ref_x"), f(row, "zmp_ref_y"))
        still = not any(
            math.isfinite(a) and math.isfinite(b) and abs(a - b) > 1e-6
            for a, b in zip(zr, self._zmp_prev, strict=True)
        )
        self._zmp_prev = zr
        ds = still and all(math.isfinite(c) and c > 0.5 for c in cref)
        st_flags, st_kinds = self.standing.update(x, vc, ds)
        inner_row = dict(row)
        inner_row.update(src)
        for s, val in zip(SENSOR_NAMES, vc, strict=True):
            inner_row[f"vfs_{s}"] = val
        for si, side in enumerate(SIDES):
            inner_row[f"vfs_total_{side}"] = float(np.nansum(vc[4 * si : 4 * si + 4]))
        out = dict(vout)
        out.update(self.inner.update(inner_row))
        for i, s in enumerate(SENSOR_NAMES):
            out[f"standing_flag_{s}"] = bool(st_flags[i])
            if st_flags[i] and not out.get(f"flag_{s}", False):
                out[f"flag_{s}"] = True
                out[f"kind_{s}"] = st_kinds[i]
        self._last_flags = [bool(out.get(f"flag_{s}", False)) for s in SENSOR_NAMES]
        out["model_mismatch"] = cm.model_mismatch
        out["model_mismatch_reason"] = cm.reason
        return out

    def update(self, row) -> dict:
        """Process one sample (never raises on a bad sample)."""
        vout = {}
        if self.vfs is not None:
            try:
                vout = self.vfs.update(row)
            except Exception:  # noqa: BLE001 - a bad sample must never raise
                vout = {}
        return self._process(dict(row), vout)

    def run(self, log):
        """Reset, then process the whole log; ``log`` plus the output columns."""
        import pandas as pd

        self.reset()
        vdf = self.vfs.run(log) if self.vfs is not None else None
        if self.vfs is not None:
            self.vfs.reset()
        recs = log.to_dict("records")
        vrecs = vdf.to_dict("records") if vdf is not None else [{}] * len(recs)
        rows = [self._process(r, vr) for r, vr in zip(recs, vrecs, strict=True)]
        res = pd.DataFrame(rows, index=log.index)
        out = log.copy()
        for c in res.columns:
            out[c] = res[c].to_numpy()
        out.attrs = {**log.attrs, "monitor": self.inner.describe()}
        return out
