"""Physical plausibility of log values: what a working sensor can report on this robot.

A finite value can still be impossible: a foot sensor reading 1e30 N, an IMU reading
1e30 m/s^2 or a gyro 1e3 rad/s. Such values must be treated like NaN (a fault, not data)
before they reach an estimator, and a recovered force must never leave the physical range.

Ranges per column family (:class:`PlausibleRanges`, from :func:`ranges_for`):

* ``force_<s>`` [N]: ``[-force_min_weights, force_max_weights] x m g`` per sensor. One
  sensor carries at most the whole weight plus the dynamic load of a step (about 1.5 m g);
  the default upper bound 3 m g leaves margin. Small negative readings are noise or
  offset (tension on a load cell): down to -0.25 m g is allowed.
* ``imu_acc_*`` [m/s^2]: ``|a| <= acc_max`` (default 16 g, a common full scale; a walking
  trunk stays within 2-3 g).
* ``imu_gyro_*`` [rad/s]: ``|w| <= gyro_max`` (default 35 rad/s = 2000 deg/s full scale;
  walking stays below 3 rad/s).
* ``imu_quat_*``: each component in ``[-1.05, 1.05]`` (per sample, the norm must be within
  ``quat_norm_tol`` of 1: see :meth:`PlausibilityChecker.check_sample`).
* ``q_<joint>`` [rad]: within the joint's limits (``joint_limits``; by default
  ``[-pi, pi]`` for every joint, since a leg joint never turns half a revolution: an
  angle in degrees is caught here).

Usage, per sample (streaming) or vectorized (batch)::

    checker = PlausibilityChecker(robot)
    bad = checker.check_sample(row)          # {column: reason} of implausible values
    mask, reasons = checker.check_frame(df)  # bool DataFrame (True = implausible), reasons

    rec = clamp_recovered(values, robot)     # recovered force kept within range
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from grfguard._lazy import lazy_module
from grfguard._validate import check_number

pd = lazy_module("pandas")  # (imported when first used: not by `grfguard run`)

__all__ = [
    "PlausibleRanges",
    "PlausibilityChecker",
    "ranges_for",
    "force_range",
    "clamp_recovered",
    "check_log",
    "LogIssue",
    "G",
]

#: Standard gravity [m/s^2] used to express the IMU range in g.
G = 9.80665


@dataclass(frozen=True)
class PlausibleRanges:
    """Physical limits of the logged channels of one robot.

    Attributes:
        weight_n: Robot weight m g [N].
        force_min_weights: Lowest plausible sensor force, in weights (negative) [-].
        force_max_weights: Highest plausible sensor force, in weights [-].
        virtual_min_weights: Lowest plausible virtual corner force (``vfs_<s>``), in
            weights (negative) [-]. A load cell's reading cannot go far below zero, but the
            virtual sensor's split of a foot's (F_z, M_x, M_y) over four corners can: about
            -F_z / 4 at a corner opposite a CoP near the sole's edge (G1's minimum-norm
            split); hence a range of its own, as wide as the upper bound.
        acc_max: Largest plausible |IMU acceleration| per axis [m/s^2].
        gyro_max: Largest plausible |IMU angular rate| per axis [rad/s].
        quat_norm_tol: Largest plausible | |q| - 1 | of the IMU quaternion [-].
        joint_limits: Joint name (without ``q_``) -> (min, max) [rad]; joints not listed
            use ``default_joint_limit``.
        default_joint_limit: (min, max) of any other joint [rad].
    """

    weight_n: float
    force_min_weights: float = 0.25
    force_max_weights: float = 3.0
    virtual_min_weights: float = 3.0
    acc_max: float = 16.0 * G
    gyro_max: float = 35.0
    quat_norm_tol: float = 0.1
    joint_limits: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    default_joint_limit: tuple[float, float] = (-math.pi, math.pi)

    def __post_init__(self) -> None:
        check_number("plausibility", "weight_n", self.weight_n, 1.0, 1e6, "N")
        check_number("plausibility", "force_min_weights", self.force_min_weights, 0.0, 10.0, "")
        check_number("plausibility", "force_max_weights", self.force_max_weights, 0.5, 100.0, "")
        check_number("plausibility", "virtual_min_weights", self.virtual_min_weights, 0.0,
                     100.0, "")
        check_number("plausibility", "acc_max", self.acc_max, G, 1e4, "m/s^2")
        check_number("plausibility", "gyro_max", self.gyro_max, 1.0, 1e3, "rad/s")
        check_number("plausibility", "quat_norm_tol", self.quat_norm_tol, 1e-6, 1.0, "")

    @property
    def force_lo(self) -> float:
        """Lowest plausible sensor force [N]."""
        return -self.force_min_weights * self.weight_n

    @property
    def force_hi(self) -> float:
        """Highest plausible sensor force [N]."""
        return self.force_max_weights * self.weight_n

    @property
    def vfs_force_lo(self) -> float:
        """Lowest plausible virtual corner force (``vfs_<s>``) [N]."""
        return -self.virtual_min_weights * self.weight_n

    def limits(self, column: str) -> tuple[float, float, str] | None:
        """(lo, hi, unit) of ``column``, or None when the column has no physical range."""
        if column.startswith("vfs_") and not column.startswith(
            ("vfs_total", "vfs_cop", "vfs_valid")
        ):
            return self.vfs_force_lo, self.force_hi, "N"
        if column.startswith(("force_", "recovered_")):
            return self.force_lo, self.force_hi, "N"
        if column.startswith("imu_acc_"):
            return -self.acc_max, self.acc_max, "m/s^2"
        if column.startswith("imu_gyro_"):
            return -self.gyro_max, self.gyro_max, "rad/s"
        if column.startswith("imu_quat_"):
            return -1.0 - self.quat_norm_tol / 2, 1.0 + self.quat_norm_tol / 2, ""
        if column.startswith("q_"):
            lo, hi = self.joint_limits.get(column[2:], self.default_joint_limit)
            return float(lo), float(hi), "rad"
        return None


def ranges_for(robot: Any, **overrides: Any) -> PlausibleRanges:
    """The :class:`PlausibleRanges` of ``robot`` (a :class:`RobotConfig` or anything with a
    ``weight`` [N] or ``mass`` [kg]); joint limits from ``robot.joint_limits`` when the
    model provides them. ``overrides`` replace single fields."""
    if isinstance(robot, PlausibleRanges):
        return robot
    weight = getattr(robot, "weight", None)
    if weight is None:
        weight = float(robot.mass) * G
    kw: dict[str, Any] = {"weight_n": float(weight)}
    limits = getattr(robot, "joint_limits", None)
    if callable(limits):
        limits = limits()
    if isinstance(limits, Mapping):
        kw["joint_limits"] = dict(limits)
    kw.update(overrides)
    return PlausibleRanges(**kw)


def force_range(robot: Any) -> tuple[float, float]:
    """(lo, hi) plausible force of one sole sensor of ``robot`` [N]."""
    r = ranges_for(robot)
    return r.force_lo, r.force_hi


def _reason(column: str, value: float, lim: tuple[float, float, str]) -> str:
    lo, hi, unit = lim
    u = f" {unit}" if unit else ""
    if not math.isfinite(value):
        return f"{column} = {value} is not finite"
    side = "above" if value > hi else "below"
    return f"{column} = {value:.6g}{u} is {side} the physical range [{lo:.6g}, {hi:.6g}]{u}"


class PlausibilityChecker:
    """Checks log values against the physical ranges of one robot.

    Args:
        robot: A :class:`~grfguard.model.robot.RobotConfig` (or :class:`PlausibleRanges`).
        columns: Columns to check (default: every column with a physical range).
        **overrides: Fields of :class:`PlausibleRanges` to change.

    NaN is *missing*, not implausible: it is left to the caller (the monitor already
    handles dropouts); +-inf is implausible.
    """

    def __init__(self, robot: Any, columns: Iterable[str] | None = None,
                 **overrides: Any) -> None:
        self.ranges = ranges_for(robot, **overrides)
        self._columns = None if columns is None else tuple(columns)
        self._cache: dict[str, tuple[float, float, str] | None] = {}

    def _lim(self, column: str) -> tuple[float, float, str] | None:
        try:
            return self._cache[column]
        except KeyError:
            lim = self.ranges.limits(column)
            self._cache[column] = lim
            return lim

    def check_value(self, column: str, value: Any) -> str | None:
        """Reason why ``value`` of ``column`` is implausible, or None (plausible, NaN, or
        a column without range). Never raises: a value that is not a number is reported."""
        lim = self._lim(column)
        if lim is None:
            return None
        try:
            v = float(value)
        except (TypeError, ValueError, OverflowError):
            return f"{column} = {value!r} is not a number"
        if math.isnan(v):
            return None
        if not (lim[0] <= v <= lim[1]):
            return _reason(column, v, lim)
        return None

    def check_sample(self, sample: Mapping[str, Any]) -> dict[str, str]:
        """Implausible values of one sample: ``{column: reason}`` (empty when all are fine).

        Also checks the IMU quaternion's norm when all four components are present. O(number
        of columns), no allocation when everything is plausible except the empty dict.
        """
        bad: dict[str, str] = {}
        cols = self._columns if self._columns is not None else sample.keys()
        for c in cols:
            if c in sample:
                r = self.check_value(c, sample[c])
                if r is not None:
                    bad[c] = r
        q = [sample.get(f"imu_quat_{a}") for a in "wxyz"]
        if all(isinstance(x, (int, float)) for x in q):
            n = math.sqrt(sum(float(x) * float(x) for x in q))  # type: ignore[arg-type]
            if math.isfinite(n) and abs(n - 1.0) > self.ranges.quat_norm_tol:
                for a in "wxyz":
                    bad.setdefault(f"imu_quat_{a}", f"IMU quaternion norm {n:.4g} is not 1 "
                                   f"(within {self.ranges.quat_norm_tol})")
        return bad

    def check_frame(self, df: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, str]]:
        """Vectorized check of a whole log.

        Returns:
            ``mask``: bool DataFrame over the checked columns, True where the value is
            implausible (+-inf or outside the range; NaN is False), and ``reasons``:
            column -> the reason of its first implausible row (``"... at row N ..."``).
        """
        cols = [c for c in (self._columns or df.columns) if c in df.columns
                and self._lim(c) is not None]
        masks: dict[str, np.ndarray] = {}
        reasons: dict[str, str] = {}
        for c in cols:
            lo, hi, unit = self._lim(c)  # type: ignore[misc]
            v = pd.to_numeric(df[c], errors="coerce").to_numpy(dtype=float)
            with np.errstate(invalid="ignore"):
                m = (v < lo) | (v > hi)
            masks[c] = m
            if m.any():
                i = int(np.argmax(m))
                reasons[c] = (f"{_reason(c, float(v[i]), (lo, hi, unit))} at row {i} "
                              f"({int(m.sum())} row(s) in all)")
        qcols = [f"imu_quat_{a}" for a in "wxyz"]
        if all(c in df.columns for c in qcols) and (self._columns is None
                                                   or set(qcols) <= set(self._columns)):
            q = np.column_stack([pd.to_numeric(df[c], errors="coerce").to_numpy(float)
                                 for c in qcols])
            with np.errstate(invalid="ignore"):
                n = np.sqrt((q * q).sum(axis=1))
                mq = np.isfinite(n) & (np.abs(n - 1.0) > self.ranges.quat_norm_tol)
            if mq.any():
                i = int(np.argmax(mq))
                for c in qcols:
                    masks[c] = masks.get(c, np.zeros(len(df), bool)) | mq
                    reasons.setdefault(c, f"IMU quaternion norm {n[i]:.4g} is not 1 at row {i}")
        mask = pd.DataFrame(masks, index=df.index, columns=list(masks))
        return mask, reasons


def clamp_recovered(values: Any, robot: Any, nan: float | None = None) -> Any:
    """``values`` (recovered sensor forces [N]) clipped to the plausible force range of
    ``robot``; +inf becomes the upper bound and -inf the lower one.

    Args:
        values: A float, a numpy array or a pandas Series/DataFrame of forces [N].
        robot: A :class:`RobotConfig` or :class:`PlausibleRanges`.
        nan: Value replacing NaN (default: NaN is kept, meaning "no estimate").

    Returns:
        The same kind of object, every finite value within ``force_range(robot)``.
    """
    lo, hi = force_range(robot)
    if not isinstance(values, (float, int, np.ndarray)) and isinstance(
            values, (pd.Series, pd.DataFrame)):
        out = values.astype(float).clip(lower=lo, upper=hi)
        return out if nan is None else out.fillna(nan)
    if np.ndim(values) == 0:
        v = float(values)
        if math.isnan(v):
            return v if nan is None else float(nan)
        return min(max(v, lo), hi)
    arr = np.clip(np.asarray(values, dtype=float), lo, hi)
    if nan is not None:
        arr = np.where(np.isnan(arr), nan, arr)
    return arr


# --------------------------------------------------------------------- whole-log checks
#: Force-sum to weight ratios of common unit mistakes (the sum is in N when this is 1).
_FORCE_UNITS = (("kN", 1e-3), ("kgf", 1.0 / G), ("lbf", 0.224809), ("daN", 0.1))


#: Rows used by :func:`check_log` at most (evenly spaced).
_CHECK_ROWS = 100_000
#: Column prefixes :func:`check_log` reads.
_CHECKED = ("force_", "imu_acc_", "q_", "imu_quat_")


def _numeric(frame: pd.DataFrame) -> np.ndarray:
    """``frame`` as a float array, text that is not a number as NaN."""
    if all((isinstance(t, np.dtype) and t.kind in "biuf") or pd.api.types.is_numeric_dtype(t)
           for t in frame.dtypes):
        return frame.to_numpy(dtype=float)
    return frame.apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)


@dataclass(frozen=True)
class LogIssue:
    """A whole-log plausibility finding: ``error`` (the log cannot be right) or ``warning``."""

    severity: str
    column: str
    message: str


def check_log(df: pd.DataFrame, robot: Any) -> list[LogIssue]:
    """Unit and wiring mistakes visible in a whole log, checked against ``robot``.

    * forces in kN, kgf, lbf or daN: the median of the summed sensor forces is compared
      with the weight m g (error near one of these units' ratios or below 0.2 or above 5
      weights, warning otherwise outside 0.6-1.6: a robot partly held by a harness);
    * acceleration in g, or with gravity removed: the median |imu_acc| must be near g;
    * joint angles in degrees: a joint beyond its limits (default +-pi) in >= 1 % of rows;
    * IMU quaternion: not unit norm (error), or a 180 deg yaw that x-y-z-w order gives
      (warning);
    * a force sensor on the wrong foot: loaded while its own foot's three other sensors
      read nothing and unloaded while the other foot is in the air.

    Rows with NaN are ignored; isolated glitches are left to the monitor. Returns the
    findings (empty when the log looks right).
    """
    r = ranges_for(robot)
    if len(df) > _CHECK_ROWS:  # statistics of the whole log: evenly spaced rows suffice
        used = [c for c in df.columns if c.startswith(_CHECKED)]  # (not the other columns)
        df = df[used].iloc[:: len(df) // _CHECK_ROWS]
    return [*_check_forces(df, r.weight_n), *_check_acc(df), *_check_joints(df, r),
            *_check_quat(df, r)]


def _check_forces(df: pd.DataFrame, w: float) -> list[LogIssue]:
    """Force units (median summed force vs the weight ``w`` [N]) and wrong-foot wiring."""
    out: list[LogIssue] = []
    fcols = [c for c in df.columns if c.startswith("force_")]
    if fcols:
        f = df[fcols].pipe(_numeric)
        ok = np.isfinite(f).all(axis=1)
        if ok.sum() >= 10:
            ratio = float(np.median(f[ok].sum(axis=1))) / w
            if not 0.6 <= ratio <= 1.6:
                guess = min(_FORCE_UNITS, key=lambda u: abs(math.log(max(ratio, 1e-12) / u[1])))
                near = abs(math.log(max(ratio, 1e-12) / guess[1])) < 0.25
                hint = (f"they look like {guess[0]}: multiply by {1 / guess[1]:.6g} to get N"
                        if near else "check the units (N) and the robot's mass (--robot)")
                sev = "error" if (near or ratio < 0.2 or ratio > 5.0) else "warning"
                out.append(LogIssue(sev, "force_*", (
                    f"the force sensors sum to {ratio * w:.4g} on average (median), but the "
                    f"robot weighs {w:.4g} N ({ratio:.3g} weights); {hint}")))
        if all(f"force_{s}{k}" in df.columns for s in "rl" for k in range(1, 5)):
            out.extend(_wrong_foot(df, w))
    return out


def _check_acc(df: pd.DataFrame) -> list[LogIssue]:
    """Acceleration in g, or with gravity removed (median |imu_acc| vs g)."""
    out: list[LogIssue] = []
    acols = [f"imu_acc_{a}" for a in "xyz"]
    if all(c in df.columns for c in acols):
        a = df[acols].pipe(_numeric)
        n = np.linalg.norm(a[np.isfinite(a).all(axis=1)], axis=1)
        if n.size >= 10:
            med = float(np.median(n))
            if 0.5 <= med <= 2.0:
                out.append(LogIssue("error", "imu_acc_*", (
                    f"the median |imu_acc| is {med:.3g}: the acceleration looks like g; "
                    f"multiply by {G} to get m/s^2")))
            elif not 5.0 <= med <= 20.0:
                out.append(LogIssue("error", "imu_acc_*", (
                    f"the median |imu_acc| is {med:.3g} m/s^2, expected about {G} (the "
                    "accelerometer's specific force, gravity included); check the units and "
                    "that gravity was not removed")))
    return out


def _check_joints(df: pd.DataFrame, r: PlausibleRanges) -> list[LogIssue]:
    """Joint angles beyond their limits in >= 1 % of the rows (degrees?)."""
    out: list[LogIssue] = []
    for c in [c for c in df.columns if c.startswith("q_")]:
        lim = r.limits(c)
        v = _numeric(df[[c]])[:, 0]
        v = v[np.isfinite(v)]
        if lim is None or v.size < 10:
            continue
        frac = float(np.mean((v < lim[0]) | (v > lim[1])))
        if frac >= 0.01:
            out.append(LogIssue("error", c, (
                f"{c} is outside its limits [{lim[0]:.4g}, {lim[1]:.4g}] rad in "
                f"{100 * frac:.3g} % of the rows (max |{c}| = {np.abs(v).max():.4g}); "
                "degrees? convert the joint angles to rad")))
    return out


def _check_quat(df: pd.DataFrame, r: PlausibleRanges) -> list[LogIssue]:
    """IMU quaternion not of unit norm, or a 180 deg yaw (x-y-z-w order)."""
    out: list[LogIssue] = []
    qcols = [f"imu_quat_{a}" for a in "wxyz"]
    if all(c in df.columns for c in qcols):
        q = df[qcols].pipe(_numeric)
        q = q[np.isfinite(q).all(axis=1)]
        if len(q) >= 10:
            norm = float(np.median(np.linalg.norm(q, axis=1)))
            if abs(norm - 1.0) > r.quat_norm_tol:
                out.append(LogIssue("error", "imu_quat_*", (
                    f"the IMU quaternion's median norm is {norm:.4g}, not 1; give a unit "
                    "quaternion (imu_quat_w, _x, _y, _z)")))
            elif (np.median(np.abs(q[:, 0])) < 0.2 and np.median(np.abs(q[:, 3])) > 0.9):
                out.append(LogIssue("warning", "imu_quat_*", (
                    "the IMU quaternion is a 180 deg yaw for most of the log (imu_quat_w ~ 0, "
                    "imu_quat_z ~ 1): if your IMU writes x-y-z-w, reorder the columns to "
                    "w-x-y-z")))
    return out

def _wrong_foot(df: pd.DataFrame, weight: float) -> list[LogIssue]:
    out = []
    f = {s: _numeric(df[[f"force_{s}{k}" for k in range(1, 5)]]) for s in "rl"}
    # a foot swings when at least three of its four sensors read ~0 (one may be misplaced)
    air = {s: (np.abs(f[s]) < 0.01 * weight).sum(axis=1) >= 3 for s in "rl"}
    for side, other in (("r", "l"), ("l", "r")):
        if air[side].sum() < 20 or air[other].sum() < 20:
            continue
        for k in range(4):
            v = f[side][:, k]
            in_own_air = float(np.nanmean(v[air[side]]))
            in_other_air = float(np.nanmean(np.abs(v[air[other]])))
            if in_own_air > 0.1 * weight and in_other_air < 0.02 * weight:
                col = f"force_{side}{k + 1}"
                out.append(LogIssue("error", col, (
                    f"{col} carries {in_own_air:.4g} N on average while foot '{side}' is in "
                    f"the air (its other sensors read ~0) and ~0 while foot '{other}' is: it "
                    f"looks like a sensor of foot '{other}'; check the column mapping")))
    return out
