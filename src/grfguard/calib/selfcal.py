"""Model self-calibration: identify corrections to the robot description from fault-free data.

Uses only the redundancy of fault-free walking (no simulation truth):

* **Load-cell zeros** ``z_i``: a swing foot carries nothing, so its load cells read
  their zero: ``z_i = median(f_i)`` over swing samples (planned swing, 60 ms away from
  lift-off and touchdown).
* **Gyro bias** ``b_g`` (IMU frame): mean of ``gyro - omega_quat`` where ``omega_quat``
  is the body rate implied by the orientation over 0.5 s windows.
* **Accelerometer bias** ``b_a`` (IMU frame): the robot starts and ends at rest, so the
  mean specific force is gravity: ``b_a = mean(acc - R_WI^T g e_z)``.
* **IMU mounting** ``R_BI`` (roll, pitch; yaw is not observable from gravity): when both
  feet stand flat (double support, both feet loaded), the sole normal computed by leg
  kinematics in the trunk frame, ``z_B``, is vertical, so the gravity direction the IMU
  reports, ``g_I = R_WI^T e_z``, satisfies ``g_I = R_BI^T z_B``. Least squares over the
  small rotation, iterated to convergence (Gauss-Newton); then jointly with the 12
  encoder offsets (which tilt the kinematic sole too) under a prior, the two soles at the
  same height separating them. Of the offsets only each leg's net sole tilt is applied,
  on its ankle (``APPLY_ENCODER_OFFSETS``).
* **Load-cell gains and mass**: the eight corrected load cells carry the whole body,
  ``sum_i (f_i - z_i) / k_i = m (g + a_z)``, with ``a_z`` the vertical acceleration of
  the trunk (corrected IMU). Linear least squares in ``w_i = 1 / (k_i m)`` over 20 ms
  averages; the moving centre of pressure makes the eight ``w_i`` identifiable. Without a
  measured mass only the products ``k_i m`` are known: the gains are normalized to mean 1
  and the mass becomes the weight the load cells see; with ``measured_mass_kg``,
  ``k_i = 1 / (w_i m)``. A flat sole's load is planar, so a walk leaves each sole's twist
  of gains (corners 1, 4 against 2, 3) to a ridge; data with calibration poses
  (``GaitConfig.calibration_poses``: a sole standing on one corner) pin it: standing-still
  samples (:func:`_still`, encoders only) are then exact rows (``a_z = 0``), see
  :func:`_posed_static_rows`, and posed soles are left out of the flat-sole fits
  (:func:`_soles_parallel`).
* **Contact twist** ``kappa``: a loaded flat sole's load is not planar on a contact whose
  stiffness grows with penetration: ``f1 - f2 - f3 + f4 = kappa P R / S`` (``S`` the
  sole's load, ``P`` front minus rear, ``R`` left minus right corners), large when the
  centre of pressure sits off the sole's centre in both axes (a trunk CoM a few cm off:
  20-50 N), which the virtual sensor's planar split misses. Least squares over single
  support samples with all four corrected cells loaded (:func:`_fit_contact_twist`),
  written into the calibration file; the corrected monitor does not apply it yet
  (``APPLY_CONTACT_TWIST``).
* **Trunk CoM** (horizontal): the time average of the ZMP equals that of the CoM
  (the mean horizontal acceleration of a walk from rest to rest is zero), so the mean of
  ``CoP - CoM_model`` (corrected forces and attitude, trunk-yaw frame) is
  ``(m_trunk / m) d_xy``.

The corrections are written as a ``[model_corrections]`` TOML table (values and 1-sigma
uncertainties) and applied to a log by :func:`apply_corrections` before the estimator
sees it.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import ConfigError, LogFormatError
from grfguard.io.schema import CONTACT_REF, FORCE_COLUMNS, IMU_ACC, IMU_GYRO, IMU_QUAT
from grfguard.model.kinematics import (
    center_of_mass,
    leg_fk,
    quat_to_rotation,
    rotation_to_quat,
)
from grfguard.model.robot import JOINT_NAMES, SENSOR_NAMES, SIDES, RobotConfig

__all__ = [
    "ModelCorrections",
    "estimate_corrections",
    "apply_corrections",
    "corrected_config",
    "accelerometer_vibration_rms",
    "robot_of",
]

_EDGE_S = 0.06  # margin around contact transitions [s]
#: Relative ridge weight pulling the load-cell gains toward a common value (only
#: directions the walk does not excite are affected).
GAIN_RIDGE = 0.01
#: The same with a quiet accelerometer (a_z measured: the fit is well conditioned).
GAIN_RIDGE_QUIET = 1e-4
#: Low-pass cut-off of the whole-body balance fit of the gains in [Hz].
GAIN_FIT_CUTOFF_HZ = 10.0
#: The same with a vibrating accelerometer (leg odometry instead; accurate below ~2 Hz).
GAIN_FIT_CUTOFF_VIBRATING_HZ = 2.0
#: Rocking of a loaded sole about the flat ground (contact compliance) [rad].
FLAT_SOLE_SIGMA_RAD = math.radians(0.2)
#: Height difference of two loaded soles on flat ground (contact compliance) [m].
FLAT_HEIGHT_SIGMA_M = 0.5e-3
#: Prior (1 sigma) of each encoder offset [rad] (ASSUMED: a calibrated robot's encoders
#: are within a degree).
ENCODER_PRIOR_RAD = math.radians(0.5)
#: Apply the fitted encoder offsets joint by joint (True) or only each leg's net sole tilt,
#: folded into its ankle pitch and roll (False). The offsets are fitted jointly with the
#: IMU mounting to separate the two (both tilt the kinematic sole), but individually they
#: are poorly determined (all-gaps robot: 0.47 deg RMS error against 0.28 deg for none).
#: Measured on it (seed 1): joint by joint, per-corner threshold 3.38x the exact model's;
#: none applied, 2.45x (seeds 1-3) but the soles' kinematic tilt left in flags healthy
#: sensors on other gaits (0.18 m steps: 80 episodes); the net tilt on the ankles, 2.41x
#: and no flag on those walks.
APPLY_ENCODER_OFFSETS = False
#: Largest deviation of the two soles' relative tilt from its median that counts as both
#: soles flat [deg] (walks: within 0.2 deg; a posed sole: 2 deg).
SOLE_TILT_TOL_DEG = 0.5
#: Margin around a posed sole (relative tilt over twice ``SOLE_TILT_TOL_DEG``) excluded
#: from the flat-sole fits [s] (the ramp into and out of the pose).
SOLE_POSE_MARGIN_S = 0.6
#: Standing still (:func:`_still`): joint speed below [rad/s] over blocks of [s], for at
#: least [s], trimmed at both ends by [s].
STILL_JOINT_SPEED = 0.01
STILL_BLOCK_S = 0.05
STILL_MIN_S = 0.3
STILL_TRIM_S = 0.1
#: A still foot whose load is this non-planar (twist over load) stands on a corner or an
#: edge; corner poses of at least POSED_MIN_S [s] per foot enable the static rows.
POSED_TWIST_RATIO = 0.5
POSED_MIN_S = 1.0
#: Weight of a standing-still row of the gain fit against a walking one. A still row's
#: reference (m g) is exact and its noise (8 cells x 2 N over 50 ms: ~0.8 N) independent
#: from row to row; a walking row's reference is the odometry's, ~1 N off in the 2 Hz
#: band and correlated over ~25 rows (10 ms apart): inverse-variance weighting gives ~40;
#: measured (all-gaps robot, seed 1) 10: 0.27 %, 100: 0.23 %, 1000: 0.21 %, still rows
#: only: 0.36 % (gains relative to each other, ridge 0 - 0.001).
STATIC_ROW_WEIGHT = 100.0
#: Accelerometer RMS above 10 Hz [m/s^2] up to which it is used in the gain fit.
ACC_QUIET_RMS = 0.2
#: Contact twist fit (:func:`_fit_contact_twist`): least corrected load of each of the
#: four cells of the stance sole (fraction of the weight) and least number of samples.
TWIST_MIN_CELL_LOAD = 0.02
TWIST_MIN_SAMPLES = 500
#: Give the fitted contact twist to the corrected monitor's accelerometer-free sensor
#: (:func:`corrected_config`, ``VFSConfig.contact_twist``). Measured on the all-gaps
#: robot (BENCHMARKS.md "Model self-calibration: contact twist"): it takes the sole's
#: twist error in flat single support from 46 to 28 N RMS and the calibrated per-corner
#: threshold from 2.02x to 1.76x the exact model's, but the lower threshold then flags
#: healthy sensors on 4 of the 10 minutes of other walks (5 episodes; seed 11: r2 at heel
#: lift, where the error left is the centre of pressure's lag, not the twist: the same
#: alarm with the planar sensor at that threshold, none with the twist at the old one).
#: So off until the thresholds hold that margin.
APPLY_CONTACT_TWIST = False


def _rpy_to_R(rpy_rad: np.ndarray) -> np.ndarray:
    from grfguard.model.kinematics import rot_x, rot_y, rot_z

    r, p, y = rpy_rad
    return rot_z(y) @ rot_y(p) @ rot_x(r)


def _R_to_rpy(R: np.ndarray) -> np.ndarray:
    pitch = math.asin(max(-1.0, min(1.0, -R[2, 0])))
    roll = math.atan2(R[2, 1], R[2, 2])
    yaw = math.atan2(R[1, 0], R[0, 0])
    return np.array([roll, pitch, yaw])


@dataclass(frozen=True)
class ModelCorrections:
    """Corrections to the robot description and the sensors' calibration.

    Attributes:
        mass_kg: Corrected total mass in [kg] (the weight the load cells see / g when
            no measured mass was given), None to keep the model's.
        trunk_com_x_m: Trunk CoM forward offset in [m] (replaces the model's).
        trunk_com_y_m: Trunk CoM leftward offset in [m].
        imu_mount_rpy_deg: IMU mounting rotation ``R_BI`` (roll, pitch, yaw) in [deg].
        gyro_bias_rad_s: Gyro bias in the IMU frame in [rad/s].
        acc_bias_m_s2: Accelerometer bias in the IMU frame in [m/s^2].
        load_cell_gain: Gain of each load cell (sensor name -> gain).
        load_cell_zero_n: Zero of each load cell in [N].
        sigma: 1-sigma uncertainty of each entry (same keys, flattened).
        measured_mass: True when ``mass_kg`` is a given measured mass.
        acc_vibration_rms_m_s2: Vertical accelerometer RMS above 10 Hz seen in the
            calibration data [m/s^2] (impact vibration; white noise alone is ~0.05).
        use_accelerometer: Whether the virtual sensor should fuse the accelerometer
            (False when it vibrates above ``ACC_QUIET_RMS``: its shaking would reach the
            per-corner forces; leg odometry alone, low-passed at 10 Hz, is then the better
            estimate, see :func:`grfguard.detect.system.quiet_vfs_config`).
        encoder_offset_deg: Offset of each joint encoder (joint name -> [deg]; the
            reading minus the true angle). From :func:`estimate_corrections` only each
            leg's net sole tilt, on the ankle pitch and roll (``APPLY_ENCODER_OFFSETS``:
            individually the offsets are too poorly determined to apply).
        twin_filter_cutoff_hz: Cut-off of the accelerometer-free virtual sensor's rate
            low-pass [Hz] chosen on the calibration data
            (:func:`grfguard.calib.twin_filter.choose_twin_filter`); None: the default
            quiet twin's (:func:`grfguard.detect.system.quiet_vfs_config`). Used only
            when ``use_accelerometer`` is False.
        twin_filter_damping: Damping ratio of that low-pass (``VFSConfig.filter_damping``);
            None: the Butterworth.
        contact_twist: Twist of a loaded flat sole's load, ``f1 - f2 - f3 + f4 =
            kappa P R / S`` (:func:`_fit_contact_twist`), for the accelerometer-free
            virtual sensor (``VFSConfig.contact_twist``; applied by
            :func:`corrected_config` only with ``APPLY_CONTACT_TWIST``); None: not
            fitted (files written before it).
    """

    mass_kg: float | None = None
    trunk_com_x_m: float = 0.0
    trunk_com_y_m: float = 0.0
    imu_mount_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gyro_bias_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    acc_bias_m_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    load_cell_gain: dict[str, float] = field(
        default_factory=lambda: {s: 1.0 for s in SENSOR_NAMES}
    )
    load_cell_zero_n: dict[str, float] = field(
        default_factory=lambda: {s: 0.0 for s in SENSOR_NAMES}
    )
    sigma: dict[str, float] = field(default_factory=dict, compare=False)
    measured_mass: bool = False
    acc_vibration_rms_m_s2: float = 0.0
    use_accelerometer: bool = True
    encoder_offset_deg: dict[str, float] = field(
        default_factory=lambda: {j: 0.0 for j in JOINT_NAMES}
    )
    twin_filter_cutoff_hz: float | None = None
    twin_filter_damping: float | None = None
    contact_twist: float | None = None

    def __post_init__(self) -> None:
        from grfguard._validate import check_number

        fix = "recalibrate with `grfguard calibrate --model` or remove the key"
        if self.twin_filter_cutoff_hz is not None:
            check_number("model_corrections", "twin_filter_cutoff_hz",
                         self.twin_filter_cutoff_hz, 0.5, 100.0, "Hz", fix)
        if self.twin_filter_damping is not None:
            check_number("model_corrections", "twin_filter_damping",
                         self.twin_filter_damping, 0.2, 2.0, "", fix)
        if self.contact_twist is not None:
            check_number("model_corrections", "contact_twist", self.contact_twist,
                         -5.0, 5.0, "", fix)
        for name in ("imu_mount_rpy_deg", "gyro_bias_rad_s", "acc_bias_m_s2"):
            v = tuple(float(x) for x in getattr(self, name))
            if len(v) != 3 or not all(math.isfinite(x) for x in v):
                raise ConfigError(f"model_corrections.{name} = {v} must be 3 finite numbers")
            object.__setattr__(self, name, v)
        for name, keys in (("load_cell_gain", SENSOR_NAMES),
                           ("load_cell_zero_n", SENSOR_NAMES),
                           ("encoder_offset_deg", JOINT_NAMES)):
            d = getattr(self, name)
            missing = [s for s in keys if s not in d]
            if missing:
                raise ConfigError(f"model_corrections.{name} lacks sensor(s) {missing}")
        bad = {s: g for s, g in self.load_cell_gain.items() if not 0.2 < float(g) < 5.0}
        if bad:
            raise ConfigError(
                f"model_corrections.load_cell_gain {bad} outside (0.2, 5); recalibrate on "
                "fault-free data"
            )
        if self.mass_kg is not None and not 1.0 <= float(self.mass_kg) <= 1000.0:
            raise ConfigError(f"model_corrections.mass_kg = {self.mass_kg} outside [1, 1000] kg")

    # ------------------------------------------------------------------ TOML
    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        for k in ("imu_mount_rpy_deg", "gyro_bias_rad_s", "acc_bias_m_s2"):
            d[k] = list(d[k])
        for k in ("mass_kg", "twin_filter_cutoff_hz", "twin_filter_damping", "contact_twist"):
            if d[k] is None:  # TOML has no null: a missing key is None
                del d[k]
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ModelCorrections:
        if "model_corrections" in data and isinstance(data["model_corrections"], dict):
            data = data["model_corrections"]
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(
                f"unknown model_corrections key(s) {unknown}; known keys: {sorted(known)}"
            )
        return cls(**data)

    def to_toml(self) -> str:
        """A ``[model_corrections]`` table (append to a thresholds file)."""
        d = self.to_dict()
        lines = [
            "# model corrections from `grfguard calibrate --model` (grfguard.calib.selfcal);",
            "# sigma holds 1-sigma uncertainties",
            "[model_corrections]",
        ]
        for k, v in d.items():
            if isinstance(v, dict):
                continue
            if isinstance(v, bool):
                lines.append(f"{k} = {'true' if v else 'false'}")
            elif isinstance(v, list):
                lines.append(f"{k} = [{', '.join(repr(float(x)) for x in v)}]")
            else:
                lines.append(f"{k} = {float(v)!r}")
        for k in ("load_cell_gain", "load_cell_zero_n", "encoder_offset_deg", "sigma"):
            lines.append(f"[model_corrections.{k}]")
            lines += [f'"{s}" = {float(v)!r}' for s, v in d[k].items()]
        return "\n".join(lines) + "\n"

    @classmethod
    def from_toml(cls, path: str | Path) -> ModelCorrections | None:
        """The ``[model_corrections]`` table of a TOML file, None when it has none."""
        p = Path(path)
        try:
            data = tomllib.loads(p.read_text())
        except (OSError, tomllib.TOMLDecodeError) as exc:
            raise ConfigError(f"cannot read model corrections from {p}: {exc}") from exc
        if "model_corrections" not in data:
            return None
        return cls.from_dict(data["model_corrections"])

    def summary(self) -> str:
        """One line for reports and the CLI."""
        g = np.array([self.load_cell_gain[s] for s in SENSOR_NAMES])
        z = np.array([self.load_cell_zero_n[s] for s in SENSOR_NAMES])
        m = "model" if self.mass_kg is None else f"{self.mass_kg:.2f} kg"
        r = self.imu_mount_rpy_deg
        return (
            f"mass {m}, trunk CoM ({100 * self.trunk_com_x_m:+.1f}, "
            f"{100 * self.trunk_com_y_m:+.1f}) cm, IMU mount roll {r[0]:+.2f} deg pitch "
            f"{r[1]:+.2f} deg, gyro bias {np.round(self.gyro_bias_rad_s, 4).tolist()} rad/s, "
            f"gains {g.min():.3f}-{g.max():.3f}, zeros {z.min():+.1f}..{z.max():+.1f} N, "
            f"encoder offsets up to {max(map(abs, self.encoder_offset_deg.values())):.2f} "
            "deg, "
            f"accelerometer vibration {self.acc_vibration_rms_m_s2:.2f} m/s^2 RMS > 10 Hz"
            + ("" if self.use_accelerometer else " (left out of the virtual sensor"
               + self._twin_filter_text() + ")")
        )

    def _twin_filter_text(self) -> str:
        """The accelerometer-free sensor's rate low-pass and contact twist, for :meth:`summary`."""
        tw = "" if self.contact_twist is None else f"; contact twist {self.contact_twist:.2f}"
        if self.twin_filter_cutoff_hz is None and self.twin_filter_damping is None:
            return tw
        z = self.twin_filter_damping
        cut = self.twin_filter_cutoff_hz
        return (f"; rate low-pass {'default' if cut is None else f'{cut:g} Hz'}, "
                + ("Butterworth" if z is None else f"damping {z:g}") + tw)


# ---------------------------------------------------------------------- helpers
def robot_of(log: pd.DataFrame, robot: Any = None) -> RobotConfig:
    """The robot of a log: ``robot`` when given, else its metadata (``attrs["robot"]``, or
    a described robot's ``robot_name``: its own mass and sole), through
    :func:`grfguard.estimate.described.log_robot`, the resolver
    :meth:`~grfguard.pipeline.Monitor.for_log` uses. Never a stand-in.

    Raises:
        LogFormatError: The log has no robot metadata (how to give one in the message).
    """
    from grfguard.estimate.described import log_robot

    return log_robot(log, robot, where="grfguard.calib.robot_of")


def _leg_model_robot(log: pd.DataFrame) -> RobotConfig:
    """The ``RobotConfig`` robot of a log for the self-calibration, which fits its
    12-joint leg model (``q_<joint>`` of :data:`~grfguard.model.robot.JOINT_NAMES`).

    Raises:
        LogFormatError: The log has no robot metadata, or names a robot described by its
            model file (Talos, G1, a user TOML), whose legs this fit does not model.
    """
    from grfguard.estimate.described import is_described

    attrs = getattr(log, "attrs", {}) or {}
    name = attrs.get("robot_name")
    if name is None and isinstance(attrs.get("robot"), str):
        name = None if attrs["robot"].lstrip().startswith("{") else attrs["robot"]
    if is_described(log) or name is not None:
        raise LogFormatError(
            f"estimate_corrections: the log's robot {name!r} is described by its model "
            "file (URDF/MJCF); the model self-calibration fits the 12-joint leg model of a "
            "RobotConfig robot (grfguard robot show) only. Calibrate this robot's "
            "thresholds without --model (grfguard calibrate LOGS -o FILE)")
    return robot_of(log)


def _arr(log: pd.DataFrame, cols: Sequence[str]) -> np.ndarray:
    missing = [c for c in cols if c not in log.columns]
    if missing:
        raise LogFormatError(
            f"self-calibration needs column(s) {missing}; see grfguard.io.schema"
        )
    return log[list(cols)].to_numpy(dtype=float)


def _away_from_edges(c: np.ndarray, dt: float) -> np.ndarray:
    """Mask of samples at least ``_EDGE_S`` away from any change of ``c`` (T, k)."""
    ch = np.any(np.diff(c, axis=0) != 0, axis=1)
    idx = np.flatnonzero(ch)
    bad = np.zeros(len(c), dtype=bool)
    w = int(round(_EDGE_S / dt))
    for i in idx:
        bad[max(0, i - w) : i + w + 2] = True
    return ~bad


def _blocks(x: np.ndarray, n: int) -> np.ndarray:
    m = (len(x) // n) * n
    return x[:m].reshape(-1, n, *x.shape[1:]).mean(axis=1)


@dataclass
class _LogData:
    dt: float
    quat: np.ndarray
    acc: np.ndarray
    gyro: np.ndarray
    q: np.ndarray
    f: np.ndarray
    cref: np.ndarray


def _load(log: pd.DataFrame) -> _LogData:
    t = _arr(log, ["time"])[:, 0]
    if len(t) < 1000:
        raise LogFormatError(
            f"self-calibration needs at least 1000 samples of fault-free walking, got {len(t)}"
        )
    dt = float(np.median(np.diff(t)))
    return _LogData(
        dt,
        _arr(log, IMU_QUAT),
        _arr(log, IMU_ACC),
        _arr(log, IMU_GYRO),
        _arr(log, [f"q_{j}" for j in JOINT_NAMES]),
        _arr(log, FORCE_COLUMNS),
        _arr(log, CONTACT_REF),
    )


# ---------------------------------------------------------------------- estimation
def estimate_corrections(
    logs: pd.DataFrame | Sequence[pd.DataFrame],
    measured_mass_kg: float | None = None,
) -> ModelCorrections:
    """Identify model and sensor corrections from fault-free logs of one robot.

    The stages run in order: load-cell zeros (:func:`_fit_zeros`), gyro bias
    (:func:`_fit_gyro_bias`), accelerometer bias (:func:`_fit_acc_bias`), IMU mounting
    (:func:`_fit_imu_mount`), then twice gains and mass (:func:`_fit_gains`) and the
    trunk CoM (:func:`_fit_trunk_com`), then the contact twist
    (:func:`_fit_contact_twist`).

    Args:
        logs: One or more fault-free logs (log contract; ``contact_ref_*`` needed) of the
            same robot; about one minute of walking with standing at start and end.
        measured_mass_kg: The robot's weighed mass in [kg], if known (fixes the gains'
            common scale); None: gains normalized to mean 1 and the mass becomes the
            weight the load cells see.

    Returns:
        The :class:`ModelCorrections` with 1-sigma uncertainties in ``sigma``.

    Raises:
        LogFormatError: If a required column is missing or a log is too short.
    """
    frames = [logs] if isinstance(logs, pd.DataFrame) else list(logs)
    if not frames:
        raise LogFormatError("estimate_corrections needs at least one fault-free log")
    robot = _leg_model_robot(frames[0])
    data = [_load(df) for df in frames]
    sigma: dict[str, float] = {}
    zero = _fit_zeros(data, sigma)
    b_g = _fit_gyro_bias(data, sigma)
    b_a = _fit_acc_bias(data, robot.gravity, sigma)
    R_BI = _fit_imu_mount(data, robot, zero, sigma)
    R_BI, enc = _fit_mount_and_encoders(data, robot, zero, R_BI, sigma)
    if not APPLY_ENCODER_OFFSETS:
        enc = _tilt_on_ankles(enc)
    data = [dataclasses.replace(d, q=d.q - enc) for d in data]
    vib = max(accelerometer_vibration_rms(d.acc, d.dt) for d in data)

    def build(mass: float, gains: np.ndarray, d_com: np.ndarray) -> ModelCorrections:
        return ModelCorrections(
            mass_kg=mass,
            trunk_com_x_m=float(robot.trunk_com_x + d_com[0]),
            trunk_com_y_m=float(robot.trunk_com_y + d_com[1]),
            imu_mount_rpy_deg=tuple(float(v) for v in np.degrees(_R_to_rpy(R_BI))),
            gyro_bias_rad_s=tuple(float(v) for v in b_g),
            acc_bias_m_s2=tuple(float(v) for v in b_a),
            load_cell_gain={s: float(v) for s, v in zip(SENSOR_NAMES, gains, strict=True)},
            load_cell_zero_n={s: float(v) for s, v in zip(SENSOR_NAMES, zero, strict=True)},
            sigma=sigma,
            measured_mass=measured_mass_kg is not None,
            acc_vibration_rms_m_s2=vib,
            use_accelerometer=vib < ACC_QUIET_RMS,
            encoder_offset_deg={j: float(math.degrees(v))
                                for j, v in zip(JOINT_NAMES, enc, strict=True)},
        )

    # gains/mass and trunk CoM twice: the second pass computes the relative CoM motion
    # with the corrected trunk CoM; a vibrating accelerometer: a third pass with the
    # vertical acceleration of the leg odometry on the corrected logs
    odo = None
    mass, gains, d_com = robot.mass, np.ones(8), np.zeros(2)
    for k in range(2 if vib < ACC_QUIET_RMS else 3):
        if k == 2:
            first = build(mass, gains, d_com)
            odo = [_odometry_vertical_acc(f, first) for f in frames]
        rob_fit = robot if k == 0 else dataclasses.replace(
            robot, trunk_com_x=robot.trunk_com_x + float(d_com[0]),
            trunk_com_y=robot.trunk_com_y + float(d_com[1]))
        mass, gains = _fit_gains(data, rob_fit, zero, b_a, R_BI, measured_mass_kg, sigma, odo)
        d_com = _fit_trunk_com(data, robot, mass, gains, zero, R_BI, sigma)
    twist = _fit_contact_twist(data, robot, zero, gains, sigma)
    return dataclasses.replace(build(mass, gains, d_com), contact_twist=twist)


def _fit_contact_twist(data: list, robot: RobotConfig, zero: np.ndarray, gains: np.ndarray,
                       sigma: dict[str, float]) -> float | None:
    """Stage 7: the contact twist ``kappa`` (:class:`ModelCorrections`): least squares of
    ``T = f1 - f2 - f3 + f4`` on ``u = P R / S`` over planned single support samples
    (away from contact changes) whose four corrected cells each carry more than
    ``TWIST_MIN_CELL_LOAD`` of the weight (the sole flat on the ground), both soles.
    None with fewer than ``TWIST_MIN_SAMPLES`` of them."""
    T, u = [], []
    for d in data:
        fc = (d.f - zero) / gains
        edge = _away_from_edges(d.cref, d.dt)
        for si in range(2):
            f = fc[:, 4 * si : 4 * si + 4]
            m = ((d.cref[:, si] > 0.5) & (d.cref[:, 1 - si] < 0.5) & edge
                 & (f.min(axis=1) > TWIST_MIN_CELL_LOAD * robot.weight))
            f1, f2, f3, f4 = f[m].T
            T.append(f1 - f2 - f3 + f4)
            u.append((f1 + f2 - f3 - f4) * (f1 - f2 + f3 - f4) / (f1 + f2 + f3 + f4))
    T_all, u_all = np.concatenate(T), np.concatenate(u)
    if len(T_all) < TWIST_MIN_SAMPLES or not np.any(u_all):
        return None
    kappa = float(u_all @ T_all / (u_all @ u_all))
    res = T_all - kappa * u_all
    n_eff = max(1.0, len(res) * data[0].dt / 0.05)
    sigma["contact_twist"] = float(np.std(res) / (math.sqrt(n_eff) * np.sqrt(np.mean(u_all**2))))
    return kappa


def _fit_zeros(data: list, sigma: dict[str, float]) -> np.ndarray:
    """Stage 1: load-cell zeros [N] (8,) as the median of each swing foot's readings."""
    zero = np.zeros(8)
    for si in range(2):
        vals = []
        for d in data:
            m = (d.cref[:, si] < 0.5) & _away_from_edges(d.cref, d.dt)
            vals.append(d.f[m, 4 * si : 4 * si + 4])
        v = np.concatenate(vals)
        if len(v) < 50:
            raise LogFormatError("self-calibration found no swing phase: walk, not stand")
        zero[4 * si : 4 * si + 4] = np.median(v, axis=0)
        for k in range(4):
            sigma[f"zero_{SENSOR_NAMES[4 * si + k]}"] = float(
                1.2533 * np.std(v[:, k]) / math.sqrt(max(1.0, len(v) * data[0].dt / 0.02))
            )
    return zero


def _fit_gyro_bias(data: list, sigma: dict[str, float]) -> np.ndarray:
    """Stage 2: gyro bias [rad/s] (3,) from the orientation's rate over 0.5 s windows."""
    diffs = []
    for d in data:
        n = int(round(0.5 / d.dt))
        R = quat_to_rotation(d.quat)
        for k0 in range(0, len(R) - n, n):
            dR = R[k0].T @ R[k0 + n]
            ang = _so3_log(dR) / (n * d.dt)
            diffs.append(d.gyro[k0 : k0 + n].mean(axis=0) - ang)
    diffs = np.array(diffs)
    sigma["gyro_bias"] = float(np.std(diffs) / math.sqrt(len(diffs)))
    return np.median(diffs, axis=0)


def _fit_acc_bias(data: list, g: float, sigma: dict[str, float]) -> np.ndarray:
    """Stage 3: accelerometer bias [m/s^2] (3,): mean specific force = gravity."""
    ab = []
    for d in data:
        R = quat_to_rotation(d.quat)
        ab.append(d.acc - g * R[:, 2, :])  # R^T e_z = third row of R
    ab = np.concatenate(ab)
    sigma["acc_bias"] = float(np.std(ab) / math.sqrt(len(ab) * data[0].dt / 0.1))
    return ab.mean(axis=0)


def _loaded_double_support(d, zero: np.ndarray, robot: RobotConfig) -> np.ndarray:
    """Samples of one log in planned double support, away from contact changes, with both
    feet carrying more than 15 % of the weight (zero-corrected readings); (T,) bool."""
    fz = d.f - zero
    load = np.column_stack([fz[:, :4].sum(1), fz[:, 4:].sum(1)])
    m = ((d.cref.min(axis=1) > 0.5)
         & _away_from_edges(d.cref, d.dt)
         & (load.min(axis=1) > 0.15 * robot.weight))
    return m & _soles_parallel(d, robot, m)


def _soles_parallel(d, robot: RobotConfig, m: np.ndarray) -> np.ndarray:
    """(T,) bool: samples of ``m`` whose two soles are parallel: the relative tilt (leg
    kinematics only, roll and pitch of ``R_BS,r^T R_BS,l``) within ``SOLE_TILT_TOL_DEG``
    of its median over ``m``, and no sample within ``SOLE_POSE_MARGIN_S`` tilted by more
    than twice that. Excludes a foot posed on an edge or a corner, with the ramps into
    and out of the pose (``GaitConfig.calibration_poses``), from the flat-sole fits; on a
    walk the relative tilt is constant (encoder offsets) within 0.2 deg: nothing is
    excluded."""
    idx = np.flatnonzero(m)
    if not len(idx):
        return np.zeros(len(m), dtype=bool)
    _, Rr = leg_fk(robot, "r", np.zeros(3), np.eye(3), d.q[:, :6])
    _, Rl = leg_fk(robot, "l", np.zeros(3), np.eye(3), d.q[:, 6:])
    R_rel = np.swapaxes(Rr, 1, 2) @ Rl
    tilt = np.column_stack([R_rel[:, 2, 1], -R_rel[:, 2, 0]])
    dev = np.abs(tilt - np.median(tilt[idx], axis=0)).max(axis=1)
    tol = math.radians(SOLE_TILT_TOL_DEG)
    posed = (dev > 2 * tol).astype(float)
    w = int(round(SOLE_POSE_MARGIN_S / d.dt))
    near = np.convolve(posed, np.ones(2 * w + 1), mode="same") > 0
    return m & (dev < tol) & ~near


def _fit_imu_mount(data: list, robot: RobotConfig, zero: np.ndarray,
                   sigma: dict[str, float]) -> np.ndarray:
    """Stage 4: IMU mounting rotation ``R_BI`` (3, 3) from flat soles in double support."""
    zB, gI = [], []
    for d in data:
        m = _loaded_double_support(d, zero, robot)
        if not m.any():
            continue
        R_WI = quat_to_rotation(d.quat[m])
        for si, s in enumerate(SIDES):
            _, R_BS = leg_fk(robot, s, np.zeros(3), np.eye(3), d.q[m, 6 * si : 6 * si + 6])
            zB.append(R_BS[:, :, 2])
            gI.append(R_WI[:, 2, :])
    if not zB:
        raise LogFormatError("self-calibration found no double support with both feet loaded")
    zB_all, gI_all = np.concatenate(zB), np.concatenate(gI)
    R_BI = np.eye(3)
    for _ in range(5):
        pred = zB_all @ R_BI  # R_BI^T z per row
        r = (gI_all - pred).reshape(-1)
        # d(R_BI^T z)/d theta for R_BI <- R_BI (I + [theta]x): -[theta]x R_BI^T z = [p]x theta
        J = np.zeros((len(pred), 3, 2))
        J[:, 0, 1], J[:, 1, 0] = -pred[:, 2], pred[:, 2]
        J[:, 2, 0], J[:, 2, 1] = -pred[:, 1], pred[:, 0]
        J = J.reshape(-1, 2)
        th, *_ = np.linalg.lstsq(J, r, rcond=None)
        R_BI = R_BI @ _rpy_to_R(np.array([th[0], th[1], 0.0]))
        if np.max(np.abs(th)) < 1e-9:
            break
    res = gI_all - zB_all @ R_BI
    n_eff = max(1.0, len(res) * data[0].dt / 0.2)
    sigma["imu_mount_deg"] = float(np.degrees(np.std(res[:, :2]) / math.sqrt(n_eff)))
    return R_BI


def _double_support_samples(data: list, robot: RobotConfig, zero: np.ndarray,
                            every_s: float = 0.02) -> list[tuple[_LogData, np.ndarray]]:
    """Per log, the indices of double-support samples with both feet loaded (> 15 % of
    the weight each), away from contact changes, every ``every_s`` [s]."""
    out = []
    for d in data:
        m = _loaded_double_support(d, zero, robot)
        idx = np.flatnonzero(m)[:: max(1, int(round(every_s / d.dt)))]
        if len(idx):
            out.append((d, idx))
    return out


def _flat_feet_residuals(params: np.ndarray, samples: list, robot: RobotConfig,
                         R0: np.ndarray) -> np.ndarray:
    """Residuals of the flat-ground constraints in double support for ``params`` =
    (mount roll, mount pitch [rad] on top of ``R0``, 12 encoder offsets [rad]): both sole
    normals vertical (world x, y components, over ``FLAT_SOLE_SIGMA_RAD``) and both soles
    at the same height (over ``FLAT_HEIGHT_SIGMA_M``), then the offsets over
    ``ENCODER_PRIOR_RAD`` (their prior)."""
    R_BI = R0 @ _rpy_to_R(np.array([params[0], params[1], 0.0]))
    off = params[2:]
    res = []
    for d, idx in samples:
        R_WB = quat_to_rotation(d.quat[idx]) @ R_BI.T
        q = d.q[idx] - off
        pr, Rr = leg_fk(robot, "r", np.zeros(3), R_WB, q[:, :6])
        pl, Rl = leg_fk(robot, "l", np.zeros(3), R_WB, q[:, 6:])
        res += [Rr[:, :2, 2].ravel() / FLAT_SOLE_SIGMA_RAD,
                Rl[:, :2, 2].ravel() / FLAT_SOLE_SIGMA_RAD,
                (pl[:, 2] - pr[:, 2]) / FLAT_HEIGHT_SIGMA_M]
    res.append(off / ENCODER_PRIOR_RAD)
    return np.concatenate(res)


def _tilt_on_ankles(enc: np.ndarray) -> np.ndarray:
    """Encoder offsets [rad] (12,) with each leg's net sole tilt of ``enc`` on its ankle:
    ankle pitch = hip pitch + knee + ankle pitch offsets, ankle roll = hip roll + ankle
    roll offsets (parallel axes for a flat foot under an upright trunk), the rest zero."""
    out = np.zeros_like(enc)
    for o in (0, 6):  # JOINT_NAMES: hip yaw, hip roll, hip pitch, knee, ankle pitch, roll
        out[o + 4] = enc[o + 2] + enc[o + 3] + enc[o + 4]
        out[o + 5] = enc[o + 1] + enc[o + 5]
    return out


def _fit_mount_and_encoders(data: list, robot: RobotConfig, zero: np.ndarray,
                            R0: np.ndarray, sigma: dict[str, float]
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Stage 4b: IMU mounting ``R_BI`` (3, 3) and encoder offsets [rad] (12,) jointly.

    The sole normals alone fix only the mounting plus the legs' summed joint offsets (an
    encoder offset tilts the kinematic sole like a mounting error does); that both soles
    stand at the same height on flat ground (mm over the 0.2 m between the feet) separates
    them. Gauss-Newton from ``R0`` with a prior of ``ENCODER_PRIOR_RAD`` on each offset.
    """
    samples = _double_support_samples(data, robot, zero)
    p = np.zeros(14)
    for _ in range(3):
        r0 = _flat_feet_residuals(p, samples, robot, R0)
        J = np.empty((len(r0), 14))
        for k in range(14):
            dp = np.zeros(14)
            dp[k] = 1e-6
            J[:, k] = (_flat_feet_residuals(p + dp, samples, robot, R0) - r0) / 1e-6
        step, *_ = np.linalg.lstsq(J, -r0, rcond=None)
        p = p + step
        if np.max(np.abs(step)) < 1e-8:
            break
    cov = np.linalg.inv(J.T @ J)
    sigma["imu_mount_deg"] = float(np.degrees(math.sqrt(max(cov[0, 0], cov[1, 1]))))
    sigma["encoder_offset_deg"] = float(np.degrees(math.sqrt(np.max(np.diag(cov)[2:]))))
    return R0 @ _rpy_to_R(np.array([p[0], p[1], 0.0])), p[2:]


def accelerometer_vibration_rms(acc: np.ndarray, dt: float) -> float:
    """RMS of the vertical (IMU z) specific force above 10 Hz [m/s^2] of (T, 3) ``acc``
    (the shaking at the foot impacts; a quiet IMU reads only its white noise there)."""
    from scipy.signal import butter, sosfiltfilt

    nyq = 0.5 / dt
    hf = sosfiltfilt(butter(4, min(10.0 / nyq, 0.9), "highpass", output="sos"), acc[:, 2])
    return float(np.sqrt(np.mean(hf**2)))


def _odometry_vertical_acc(log: pd.DataFrame, corr: ModelCorrections | None) -> np.ndarray:
    """``g + a_z`` [m/s^2] (T,) of the CoM from the virtual sensor's leg odometry (the
    accelerometer unused): its total vertical force over the model mass, on ``log`` with
    the first-pass corrections applied."""
    from grfguard.estimate.vfs import VFSConfig, VirtualForceSensor

    lc = apply_corrections(log, corr)
    out = VirtualForceSensor.for_log(lc, VFSConfig(use_accelerometer=False),
                                     warm=False).run(lc)
    return (out["vfs_total_r"].to_numpy(float) + out["vfs_total_l"].to_numpy(float)) / (
        robot_of(lc).mass
    )


def _gain_fit_rows(data: list, rob_fit: RobotConfig, zero: np.ndarray, b_a: np.ndarray,
                   R_BI: np.ndarray, odo: list | None = None
                   ) -> tuple[np.ndarray, np.ndarray, bool]:
    """Rows ``A`` (loads [N]) and ``y`` (vertical CoM acceleration + g [m/s^2]) of the
    whole-body balance, and whether the accelerometer was quiet.

    Quiet accelerometer: the vertical CoM acceleration is the trunk's (accelerometer,
    world z) plus the CoM's relative to the trunk (kinematics); both sides low-passed at
    GAIN_FIT_CUTOFF_HZ. An accelerometer that shakes at the impacts (RMS above 10 Hz >
    ACC_QUIET_RMS) would bias and swamp the fit: then ``y`` is the virtual sensor's leg
    odometry (``odo``, :func:`_odometry_vertical_acc`) and both sides are low-passed at
    GAIN_FIT_CUTOFF_VIBRATING_HZ, where the odometry is accurate; without ``odo``,
    ``a_z = 0`` over 0.1 s blocks (first pass).
    """
    from scipy.signal import butter, savgol_filter, sosfiltfilt

    g = rob_fit.gravity
    A, y = [], []
    quiet = all(accelerometer_vibration_rms(d.acc, d.dt) < ACC_QUIET_RMS for d in data)
    for k, d in enumerate(data):
        nyq = 0.5 / d.dt
        step = max(1, int(round(0.01 / d.dt)))
        if quiet:
            acc_B = (d.acc - b_a) @ R_BI.T  # R_BI (acc - b)
            R_WB = quat_to_rotation(d.quat) @ R_BI.T
            a_trunk = np.einsum("tj,tj->t", R_WB[:, 2, :], acc_B) - g
            rel = center_of_mass(rob_fit, np.zeros(3), R_WB, d.q)[:, 2]
            win = 2 * int(round(0.025 / d.dt)) + 1
            a_rel = savgol_filter(rel, win, 3, deriv=2, delta=d.dt)
            sos = butter(4, min(GAIN_FIT_CUTOFF_HZ / nyq, 0.9), output="sos")
            A.append(sosfiltfilt(sos, d.f - zero, axis=0)[::step])
            y.append(sosfiltfilt(sos, g + a_trunk + a_rel)[::step])
        elif odo is not None:
            sos = butter(4, min(GAIN_FIT_CUTOFF_VIBRATING_HZ / nyq, 0.9), output="sos")
            cut = int(round(1.0 / d.dt))  # the filters' start-up
            A.append(sosfiltfilt(sos, d.f - zero, axis=0)[cut:-cut:step])
            y.append(sosfiltfilt(sos, odo[k] * g / rob_fit.gravity)[cut:-cut:step])
        else:
            n = max(1, int(round(0.1 / d.dt)))
            A.append(_blocks(d.f - zero, n))
            y.append(np.full(len(A[-1]), g))
    return np.concatenate(A), np.concatenate(y), bool(quiet)


def _fit_gains(data: list, rob_fit: RobotConfig, zero: np.ndarray, b_a: np.ndarray,
               R_BI: np.ndarray, measured_mass_kg: float | None,
               sigma: dict[str, float], odo: list | None = None) -> tuple[float, np.ndarray]:
    """Stage 5: mass [kg] and load-cell gains (8,) from the whole-body balance."""
    A_all, y_all, quiet = _gain_fit_rows(data, rob_fit, zero, b_a, R_BI, odo)
    A_st = _posed_static_rows(data, zero, rob_fit.weight)
    if A_st is not None:  # standing still: the load cells carry m g exactly
        k = math.sqrt(STATIC_ROW_WEIGHT)
        A_all = np.vstack([A_all, k * A_st])
        y_all = np.concatenate([y_all, np.full(len(A_st), k * rob_fit.gravity)])
    w0 = float(np.linalg.lstsq(A_all.sum(axis=1, keepdims=True), y_all, rcond=None)[0][0])
    # ridge toward equal gains for load patterns the walk does not excite (twist of a
    # sole); corner poses excite them: then only the small ridge
    ridge = GAIN_RIDGE_QUIET if (quiet or A_st is not None) else GAIN_RIDGE
    reg = ridge * float((A_all**2).sum()) / 8.0
    M = A_all.T @ A_all + reg * np.eye(8)
    w = np.linalg.solve(M, A_all.T @ y_all + reg * w0)
    res = y_all - A_all @ w
    cov = np.linalg.inv(M) * float(np.var(res))
    km = 1.0 / w  # gain_i * mass
    mass = float(measured_mass_kg) if measured_mass_kg is not None else float(np.mean(km))
    gains = km / mass
    for i, s in enumerate(SENSOR_NAMES):
        sigma[f"gain_{s}"] = float(math.sqrt(max(cov[i, i], 0.0)) * km[i] ** 2 / mass)
    var_km = np.clip(np.diag(cov), 0.0, None) * km**4
    sigma["mass_kg"] = float(math.sqrt(var_km.sum()) / 8.0)
    return mass, gains


def _still(d) -> np.ndarray:
    """(T,) bool: both feet planned in contact and every joint still (speed over
    ``STILL_BLOCK_S`` below ``STILL_JOINT_SPEED``) for at least ``STILL_MIN_S``, less
    ``STILL_TRIM_S`` at both ends (encoders only: the robot stands still)."""
    n = max(1, int(round(STILL_BLOCK_S / d.dt)))
    speed = np.full(len(d.q), np.inf)
    if len(d.q) > n:
        speed[n // 2: n // 2 + len(d.q) - n] = np.abs(d.q[n:] - d.q[:-n]).max(axis=1) / (n * d.dt)
    m = np.r_[False, (speed < STILL_JOINT_SPEED) & (d.cref.min(axis=1) > 0.5), False]
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    out = np.zeros(len(d.q), dtype=bool)
    trim = int(round(STILL_TRIM_S / d.dt))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if (b - a) * d.dt >= STILL_MIN_S:
            out[a + trim: b - trim] = True
    return out


def _posed_static_rows(data: list, zero: np.ndarray, weight: float) -> np.ndarray | None:
    """Loads [N] (n, 8) of the standing-still ``STILL_BLOCK_S`` blocks, when the logs
    hold corner poses (``GaitConfig.calibration_poses``): each foot at least
    ``POSED_MIN_S`` standing still with a non-planar load (``|f1 - f2 - f3 + f4|`` over
    ``POSED_TWIST_RATIO`` of its load, the load over 5 % of ``weight`` [N]). A flat sole
    carries a planar load (ratio near 0); only these rows show a sole's twist of gains.
    None without such poses (a walk: the gain fit keeps its ridge)."""
    blocks, posed = [], np.zeros(2)
    for d in data:
        n = max(1, int(round(STILL_BLOCK_S / d.dt)))
        still = _still(d)
        idx = np.flatnonzero(still[: len(still) // n * n].reshape(-1, n).all(axis=1))
        if not len(idx):
            continue
        fz = _blocks(d.f - zero, n)[idx]
        for i in range(2):
            f = fz[:, 4 * i: 4 * i + 4]
            load = f.sum(axis=1)
            tw = np.abs(f[:, 0] - f[:, 1] - f[:, 2] + f[:, 3])
            ok = (load > 0.05 * weight) & (tw > POSED_TWIST_RATIO * load)
            posed[i] += ok.sum() * n * d.dt
        blocks.append(fz)
    if not blocks or posed.min() < POSED_MIN_S:
        return None
    return np.concatenate(blocks)


def _fit_trunk_com(data: list, robot: RobotConfig, mass: float, gains: np.ndarray,
                   zero: np.ndarray, R_BI: np.ndarray, sigma: dict[str, float]) -> np.ndarray:
    """Stage 6: trunk CoM correction [m] (2,) from mean(CoP - CoM)."""
    rob_c = dataclasses.replace(robot, mass=mass)
    diffs_xy = []
    p_F = robot.sensor_positions_in_foot()
    for d in data:
        fz = (d.f - zero) / gains
        R_WB = quat_to_rotation(d.quat) @ R_BI.T
        # yaw-free trunk frame: remove the trunk's heading
        yaw = np.arctan2(R_WB[:, 1, 0], R_WB[:, 0, 0])
        c, s_ = np.cos(-yaw), np.sin(-yaw)
        Rz = np.zeros_like(R_WB)
        Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1] = c, -s_, s_, c
        Rz[:, 2, 2] = 1.0
        R_H = Rz @ R_WB
        com = center_of_mass(rob_c, np.zeros(3), R_H, d.q)
        num = np.zeros((len(fz), 2))
        for si, sd in enumerate(SIDES):
            p_S, R_S = leg_fk(rob_c, sd, np.zeros(3), R_H, d.q[:, 6 * si : 6 * si + 6])
            for k in range(4):
                pk = p_S + R_S @ np.array([p_F[k, 0], p_F[k, 1], 0.0])
                num += fz[:, 4 * si + k, None] * pk[:, :2]
        tot = fz.sum(axis=1)
        ok = tot > 0.5 * rob_c.weight
        cop = num[ok] / tot[ok, None]
        diffs_xy.append(cop - com[ok, :2])
    dxy = np.concatenate(diffs_xy)
    frac = robot.trunk_mass_fraction
    sigma["trunk_com_m"] = float(
        np.std(dxy) / frac / math.sqrt(max(1.0, len(dxy) * data[0].dt / 1.0))
    )
    return dxy.mean(axis=0) / frac


def _so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix [rad]."""
    c = max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0))
    th = math.acos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if th < 1e-9:
        return v / 2.0
    return v * th / (2.0 * math.sin(th))


# ---------------------------------------------------------------------- application
def apply_corrections(log: pd.DataFrame, corr: ModelCorrections | None) -> pd.DataFrame:
    """A copy of ``log`` with the corrections applied before the estimator sees it.

    IMU columns are rotated into the model's trunk frame after removing the biases
    (``acc_B = R_BI (acc - b_a)``, ``gyro_B = R_BI (gyro - b_g)``, ``R_WB = R_WI R_BI^T``),
    forces become ``(f - z_i) / k_i``, joint angles ``q - offset``, and ``attrs["robot"]``
    gets the corrected mass and trunk CoM. ``attrs["model_corrections"]`` records what was
    applied. None returns ``log`` unchanged.
    """
    if corr is None:
        return log
    out = log.copy()
    R_BI = _rpy_to_R(np.radians(corr.imu_mount_rpy_deg))
    if all(c in out.columns for c in IMU_ACC):
        acc = (out[list(IMU_ACC)].to_numpy(float) - np.asarray(corr.acc_bias_m_s2)) @ R_BI.T
        out[list(IMU_ACC)] = acc
    if all(c in out.columns for c in IMU_GYRO):
        gy = (out[list(IMU_GYRO)].to_numpy(float) - np.asarray(corr.gyro_bias_rad_s)) @ R_BI.T
        out[list(IMU_GYRO)] = gy
    if all(c in out.columns for c in IMU_QUAT):
        q = out[list(IMU_QUAT)].to_numpy(float)
        ok = np.all(np.isfinite(q), axis=1) & (np.linalg.norm(q, axis=1) > 0)
        qn = q.copy()
        if ok.any():
            qc = rotation_to_quat(quat_to_rotation(q[ok]) @ R_BI.T)
            qn[ok] = qc * np.where(qc[:, :1] < 0, -1.0, 1.0)
        out[list(IMU_QUAT)] = qn
    for j, off in corr.encoder_offset_deg.items():
        c = f"q_{j}"
        if c in out.columns and off != 0.0:
            out[c] = out[c].to_numpy(float) - math.radians(off)
    for s in SENSOR_NAMES:
        c = f"force_{s}"
        if c in out.columns:
            out[c] = (out[c].to_numpy(float) - corr.load_cell_zero_n[s]) / corr.load_cell_gain[s]
    robot = robot_of(log)
    changes: dict[str, Any] = {"trunk_com_x": corr.trunk_com_x_m, "trunk_com_y": corr.trunk_com_y_m}
    if corr.mass_kg is not None:
        changes["mass"] = float(corr.mass_kg)
    out.attrs = {
        **log.attrs,
        "robot": dataclasses.replace(robot, **changes).to_dict(),
        "model_corrections": corr.to_dict(),
    }
    return out


def corrected_config(config: Any, corr: ModelCorrections | None) -> Any:
    """``config`` (a :class:`~grfguard.detect.MonitorConfig`, None for the default) with
    the virtual sensor settings the corrections call for: when the accelerometer vibrated
    in the calibration data (``corr.use_accelerometer`` False), the monitor's quiet twin
    (:func:`grfguard.detect.system.quiet_vfs_config`: no accelerometer, rate low-pass at
    10 Hz, or the cut-off and damping chosen on the calibration data,
    ``corr.twin_filter_cutoff_hz`` / ``corr.twin_filter_damping``; with the fitted
    contact twist ``corr.contact_twist`` when ``APPLY_CONTACT_TWIST``) from the start.
    Unchanged when ``corr`` is None or the accelerometer was quiet."""
    from grfguard.detect import MonitorConfig
    from grfguard.detect.system import quiet_vfs_config
    from grfguard.estimate.vfs import VFSConfig

    cfg = config if config is not None else MonitorConfig()
    if corr is None or corr.use_accelerometer:
        return cfg
    vfs = cfg.vfs if cfg.vfs is not None else VFSConfig()
    if vfs.com_method != "multibody":  # the paper's LIPM filter: nothing to switch
        return cfg
    quiet = quiet_vfs_config(vfs)
    if APPLY_CONTACT_TWIST and corr.contact_twist is not None:
        quiet = quiet.replace(contact_twist=float(corr.contact_twist))
    if corr.twin_filter_cutoff_hz is not None or corr.twin_filter_damping is not None:
        cut = corr.twin_filter_cutoff_hz
        quiet = quiet.replace(filter_cutoff=quiet.filter_cutoff if cut is None else cut,
                              filter_damping=corr.twin_filter_damping)
    return cfg.replace(vfs=quiet)
