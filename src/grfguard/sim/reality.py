"""Reality gap: simulate a robot that differs from the description written into its log.

A real robot never matches its model. :class:`RealityGap` lists the differences
(issue 10): the *physics* runs with the true robot (total mass, trunk CoM offset, link
mass distribution, sensor positions), the *sensors* read through the true mounting and
calibration (IMU mounting rotation, gyro and accelerometer biases, accelerometer
vibration, encoder offsets, load-cell gains and zeros), while the log's
``attrs["robot"]`` keeps the nominal description the estimator uses. The resolved gap
(every random draw) goes to ``attrs["reality"]`` as *truth only*: no estimator or
detector reads it, tests and benchmarks compare against it.

Conventions: the actual IMU frame I is the model's IMU (trunk) frame B rotated by
``R_BI = Rz(yaw) Ry(pitch) Rx(roll)`` of ``imu_mount_rpy_deg``; the IMU reports
``R_WI = R_WB R_BI``, ``acc_I = R_BI^T acc_B + b_acc`` and ``gyro_I = R_BI^T gyro_B +
b_gyro``. A load cell reads ``gain * f_true + zero`` (plus the usual noise); an encoder
reads ``q_true + offset``.

Accelerometer vibration: band-limited noise whose band RMS follow the real iCub walk
of issue 10 (:data:`ICUB_VIBRATION_BANDS`, vertical axis; ASSUMED: half of it on x and
y), with an envelope that is 3x stronger for 0.15 s after each planned touchdown
(ASSUMED shape), normalized so the band RMS over the walk match the table times
``acc_vibration``.

Gap files are TOML (``[reality]`` table or top-level keys); examples in
``grfguard/data/reality/*.toml``.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from grfguard._validate import check_number
from grfguard.errors import ConfigError
from grfguard.model.robot import JOINT_NAMES, SENSOR_NAMES, RobotConfig

__all__ = [
    "CONTROLLERS",
    "ICUB_VIBRATION_BANDS",
    "RealityGap",
    "imu_mount_rotation",
    "load_reality",
    "reality_file",
    "REALITY_FILES",
]

#: (low [Hz], high [Hz], RMS [m/s^2]) of the vertical accelerometer disturbance on a real
#: iCub walk (issue 10: IMU specific force times mass minus measured total force).
ICUB_VIBRATION_BANDS: tuple[tuple[float, float, float], ...] = (
    (0.2, 2.0, 0.16),
    (2.0, 5.0, 0.27),
    (5.0, 10.0, 0.51),
    (10.0, 20.0, 1.22),
    (20.0, 50.0, 0.67),
)
#: Gap files shipped with grfguard (``grfguard/data/reality/<name>.toml``).
REALITY_FILES = (
    "mass_plus5", "mass_minus5", "com_x", "com_y", "imu_roll", "imu_pitch", "gyro_bias",
    "acc_bias", "vibration", "encoders", "gains", "zeros", "all",
)

#: Values of :attr:`RealityGap.controller`.
CONTROLLERS = ("open_loop", "balanced")

_VEC3 = ("trunk_com_offset_m", "imu_mount_rpy_deg", "gyro_bias_rad_s", "acc_bias_m_s2")


def _vec3(name: str, v: Any) -> tuple[float, float, float]:
    try:
        out = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        out = ()
    if len(out) != 3 or not all(np.isfinite(out)):
        raise ConfigError(f"reality.{name} = {v!r} must be a list of 3 finite numbers")
    return out  # type: ignore[return-value]


def imu_mount_rotation(rpy_deg: Any) -> np.ndarray:
    """``R_BI = Rz(yaw) Ry(pitch) Rx(roll)`` of roll, pitch, yaw in [deg], (3, 3)."""
    from grfguard.model.kinematics import rot_x, rot_y, rot_z

    r, p, y = np.radians(np.asarray(rpy_deg, dtype=float))
    return rot_z(y) @ rot_y(p) @ rot_x(r)


@dataclass(frozen=True)
class RealityGap:
    """How the simulated robot differs from the description in its log.

    Random entries (encoder offsets, load-cell gains and zeros, sensor position errors)
    are drawn uniformly in ``[-x, +x]`` from ``numpy.random.default_rng(seed)``.

    Attributes:
        mass_error: True mass / model mass - 1 (0.05: the robot is 5 % heavier).
        trunk_com_offset_m: True trunk CoM minus the model's, trunk frame, [m] (x, y, z).
        trunk_mass_fraction_delta: Mass fraction moved from the legs to the trunk
            (link mass distribution), e.g. 0.02.
        imu_mount_rpy_deg: IMU mounting rotation (roll, pitch, yaw) in [deg].
        gyro_bias_rad_s: Gyro bias in the IMU frame in [rad/s].
        acc_bias_m_s2: Accelerometer bias in the IMU frame in [m/s^2].
        acc_vibration: Scale of the iCub vibration spectrum (1 = as measured, 0 = off).
        encoder_offset_deg: Bound of the per-joint encoder offsets in [deg].
        load_cell_gain_error: Bound of each load cell's relative gain error (0.05 = 5 %).
        load_cell_zero_n: Bound of each load cell's zero error in [N].
        sensor_position_error_m: Bound of each sensor's x and y position error in [m].
        seed: Seed of the random draws.
        controller: How the robot's walking controller treats its body (not a gap of
            the description: what the physics does with it). ``"open_loop"``: the walk
            is planned on the description and rolled out as planned, so a true body
            that differs (mass, trunk CoM, mass distribution) walks with its centres of
            pressure where that error puts them (a trunk CoM 3 cm off: about 2.4 cm off
            the soles' centres). ``"balanced"``: the walk is planned on the true body, so
            its CoM follows the planned path over the planned ZMP, as a robot whose
            balance controller has converged (or was tuned on the hardware) walks; the
            log's description stays the nominal one. The sensor gaps act the same way
            under both.
    """

    mass_error: float = 0.0
    trunk_com_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    trunk_mass_fraction_delta: float = 0.0
    imu_mount_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gyro_bias_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    acc_bias_m_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    acc_vibration: float = 0.0
    encoder_offset_deg: float = 0.0
    load_cell_gain_error: float = 0.0
    load_cell_zero_n: float = 0.0
    sensor_position_error_m: float = 0.0
    seed: int = 0
    controller: str = "open_loop"

    def __post_init__(self) -> None:
        o = "reality"
        if self.controller not in CONTROLLERS:
            raise ConfigError(
                f"reality.controller = {self.controller!r} must be one of "
                f"{', '.join(repr(c) for c in CONTROLLERS)}"
            )
        check_number(o, "mass_error", self.mass_error, -0.5, 0.5, "")
        check_number(o, "trunk_mass_fraction_delta", self.trunk_mass_fraction_delta,
                     -0.2, 0.2, "")
        check_number(o, "acc_vibration", self.acc_vibration, 0.0, 10.0, "")
        check_number(o, "encoder_offset_deg", self.encoder_offset_deg, 0.0, 10.0, "deg")
        check_number(o, "load_cell_gain_error", self.load_cell_gain_error, 0.0, 0.5, "")
        check_number(o, "load_cell_zero_n", self.load_cell_zero_n, 0.0, 500.0, "N")
        check_number(o, "sensor_position_error_m", self.sensor_position_error_m,
                     0.0, 0.02, "m")
        for name in _VEC3:
            object.__setattr__(self, name, _vec3(name, getattr(self, name)))
        if any(abs(v) > 10.0 for v in self.imu_mount_rpy_deg):
            raise ConfigError(
                f"reality.imu_mount_rpy_deg = {self.imu_mount_rpy_deg} must stay within "
                "+-10 deg per axis"
            )
        if any(abs(v) > 0.2 for v in self.trunk_com_offset_m):
            raise ConfigError(
                f"reality.trunk_com_offset_m = {self.trunk_com_offset_m} must stay within "
                "+-0.2 m per axis"
            )
        if not isinstance(self.seed, int) or isinstance(self.seed, bool):
            raise ConfigError(f"reality.seed = {self.seed!r} must be an integer")

    # ------------------------------------------------------------------ round trip
    def to_dict(self) -> dict[str, Any]:
        """Plain dict (lists for vectors) for TOML and log metadata."""
        d = dataclasses.asdict(self)
        for name in _VEC3:
            d[name] = list(d[name])
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RealityGap:
        """Build from a dict (a ``reality`` sub-table is accepted); unknown keys raise."""
        if "reality" in data and isinstance(data["reality"], dict):
            data = data["reality"]
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known - {"description"})
        if unknown:
            raise ConfigError(f"unknown reality key(s) {unknown}; known keys: {sorted(known)}")
        return cls(**{k: v for k, v in data.items() if k != "description"})

    @classmethod
    def from_toml(cls, path: str | Path) -> RealityGap:
        """Read a gap file (``[reality]`` table or top-level keys)."""
        p = Path(path)
        if not p.exists():
            raise ConfigError(
                f"reality file {p} does not exist; shipped examples: "
                f"{', '.join(REALITY_FILES)} (grfguard.sim.reality.reality_file(name))"
            )
        try:
            data = tomllib.loads(p.read_text())
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{p} is not valid TOML: {exc}") from exc
        return cls.from_dict(data)

    @property
    def is_exact(self) -> bool:
        """True when the gap changes nothing."""
        return self == RealityGap(seed=self.seed, controller=self.controller)

    # ------------------------------------------------------------------ draws
    def resolve(self) -> dict[str, Any]:
        """Every concrete value of the gap (the truth written to ``attrs["reality"]``)."""
        rng = np.random.default_rng(self.seed)
        n_s, n_j = len(SENSOR_NAMES), len(JOINT_NAMES)
        enc = rng.uniform(-1, 1, n_j) * np.radians(self.encoder_offset_deg)
        gain = 1.0 + rng.uniform(-1, 1, n_s) * self.load_cell_gain_error
        zero = rng.uniform(-1, 1, n_s) * self.load_cell_zero_n
        pos = rng.uniform(-1, 1, (n_s, 2)) * self.sensor_position_error_m
        return {
            **self.to_dict(),
            "encoder_offset_rad": {j: float(v) for j, v in zip(JOINT_NAMES, enc, strict=True)},
            "load_cell_gain": {s: float(v) for s, v in zip(SENSOR_NAMES, gain, strict=True)},
            "load_cell_zero_n": {s: float(v) for s, v in zip(SENSOR_NAMES, zero, strict=True)},
            "sensor_position_error_m": {
                s: [float(v[0]), float(v[1])] for s, v in zip(SENSOR_NAMES, pos, strict=True)
            },
        }

    # ------------------------------------------------------------------ physics
    def planned_robot(self, robot: RobotConfig) -> RobotConfig:
        """The body the walk is planned on: the description (``controller =
        "open_loop"``) or the true body (``"balanced"``)."""
        return self.true_robot(robot) if self.controller == "balanced" else robot

    def true_robot(self, robot: RobotConfig) -> RobotConfig:
        """The robot the physics simulates (mass, mass distribution, trunk CoM)."""
        d = self.trunk_mass_fraction_delta
        legs = 1.0 - robot.trunk_mass_fraction
        scale = (legs - d) / legs
        dx, dy, dz = self.trunk_com_offset_m
        return dataclasses.replace(
            robot,
            mass=robot.mass * (1.0 + self.mass_error),
            trunk_mass_fraction=robot.trunk_mass_fraction + d,
            thigh_mass_fraction=robot.thigh_mass_fraction * scale,
            shank_mass_fraction=robot.shank_mass_fraction * scale,
            foot_mass_fraction=robot.foot_mass_fraction * scale,
            trunk_com_x=robot.trunk_com_x + dx,
            trunk_com_y=robot.trunk_com_y + dy,
            trunk_com_height=robot.trunk_com_height + dz,
        )

    def perturb_model(self, model: Any) -> None:
        """Move each sensor's contact sphere and touch site by its position error
        (in place on a ``mujoco.MjModel``)."""
        import mujoco

        if self.sensor_position_error_m == 0.0:
            return
        err = self.resolve()["sensor_position_error_m"]
        for s in SENSOR_NAMES:
            dx, dy = err[s]
            g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{s}_contact")
            i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
            for arr, idx in ((model.geom_pos, g), (model.site_pos, i)):
                if idx >= 0:
                    arr[idx, 0] += dx
                    arr[idx, 1] += dy

    # ------------------------------------------------------------------ sensors
    def apply_to_columns(
        self, cols: dict[str, np.ndarray], contact_ref: np.ndarray, sample_rate: float
    ) -> dict[str, np.ndarray]:
        """Pass the simulated sensor columns through the true mounting and calibration.

        Args:
            cols: Log columns (modified in place and returned).
            contact_ref: (T, 2) planned contact of the right and left foot (0/1).
            sample_rate: Samples per second [Hz].
        """
        from grfguard.model.kinematics import quat_to_rotation, rotation_to_quat

        truth = self.resolve()
        R_BI = imu_mount_rotation(self.imu_mount_rpy_deg)
        acc = np.column_stack([cols[f"imu_acc_{a}"] for a in "xyz"]) @ R_BI
        gyro = np.column_stack([cols[f"imu_gyro_{a}"] for a in "xyz"]) @ R_BI
        quat = np.column_stack([cols[f"imu_quat_{a}"] for a in "wxyz"])
        quat = rotation_to_quat(quat_to_rotation(quat) @ R_BI)
        quat = quat * np.where(quat[:, :1] < 0, -1.0, 1.0)
        acc = acc + np.asarray(self.acc_bias_m_s2)
        gyro = gyro + np.asarray(self.gyro_bias_rad_s)
        if self.acc_vibration > 0:
            acc = acc + self.acc_vibration * vibration(
                len(acc), contact_ref, sample_rate, self.seed
            )
        for i, a in enumerate("xyz"):
            cols[f"imu_acc_{a}"] = acc[:, i]
            cols[f"imu_gyro_{a}"] = gyro[:, i]
        for i, a in enumerate("wxyz"):
            cols[f"imu_quat_{a}"] = quat[:, i]
        for j, off in truth["encoder_offset_rad"].items():
            cols[f"q_{j}"] = cols[f"q_{j}"] + off
        for s in SENSOR_NAMES:
            cols[f"force_{s}"] = (
                truth["load_cell_gain"][s] * cols[f"force_{s}"] + truth["load_cell_zero_n"][s]
            )
        return cols


def vibration(
    n: int, contact_ref: np.ndarray, sample_rate: float, seed: int
) -> np.ndarray:
    """Accelerometer vibration (n, 3) [m/s^2] with the iCub band RMS on z (half on x, y),
    3x stronger for 0.15 s after each planned touchdown."""
    from scipy.signal import butter, sosfiltfilt

    rng = np.random.default_rng([seed, 10])
    env = np.ones(n)
    cref = np.asarray(contact_ref, dtype=float).reshape(n, -1)
    td = np.flatnonzero(np.any(np.diff(cref, axis=0) > 0.5, axis=1)) + 1
    t = np.arange(n) / sample_rate
    for k in td:
        m = (t >= t[k]) & (t < t[k] + 0.15)
        env[m] += 2.0 * np.exp(-(t[m] - t[k]) / 0.05)
    env /= np.sqrt(np.mean(env**2))
    out = np.zeros((n, 3))
    nyq = sample_rate / 2
    for lo, hi, rms in ICUB_VIBRATION_BANDS:
        sos = butter(4, [lo / nyq, min(hi, 0.95 * nyq) / nyq], btype="band", output="sos")
        w = sosfiltfilt(sos, rng.normal(size=(n, 3)), axis=0) * env[:, None]
        w /= np.sqrt(np.mean(w**2, axis=0))
        out += w * np.array([0.5 * rms, 0.5 * rms, rms])
    return out


def reality_file(name: str) -> Path:
    """Path of a shipped gap file (``grfguard/data/reality/<name>.toml``)."""
    if name not in REALITY_FILES:
        raise ConfigError(f"unknown reality gap {name!r}; shipped: {', '.join(REALITY_FILES)}")
    return Path(str(resources.files("grfguard") / "data" / "reality" / f"{name}.toml"))


def load_reality(path_or_name: str | Path | None) -> RealityGap | None:
    """A gap from a TOML path or a shipped name; None stays None."""
    if path_or_name is None:
        return None
    if str(path_or_name) in REALITY_FILES:
        return RealityGap.from_toml(reality_file(str(path_or_name)))
    return RealityGap.from_toml(Path(path_or_name))


