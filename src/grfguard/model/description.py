"""A robot = its model file (URDF or MJCF) + a short TOML: :class:`RobotDescription`.

The TOML names what the model file cannot say: which bodies are the feet, where the
sole is, how each foot's force is sensed (four corner load cells or a six-axis
force/torque sensor), where the IMU is, and optionally the measured total mass.
The format is documented in the README ("Robot descriptions") and in the shipped
files ``grfguard/robots/*.toml``.

Frames: a pose ``pos`` [m] / ``rpy`` [rad] (roll-pitch-yaw, fixed axes x-y-z, as in
URDF) is given in the frame of the named body of the model. The sole frame F of a
foot has its origin at the centre of the sole rectangle, on the sole plane, x
forward, z up (out of the sole).

Errors name the file, the key and what was expected
(:class:`~grfguard.errors.ConfigError`); the checks against the model itself (body
names, a sole below the ankle) are made by :func:`grfguard.model.loader.load_model`.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from grfguard.errors import ConfigError

__all__ = [
    "SIDES",
    "Pose",
    "FootDescription",
    "RobotDescription",
    "load_description",
    "shipped_robots",
    "corner_sensor_names",
    "ft_channels",
    "FT_AXES",
]

#: Feet, right first (log columns use ``r`` / ``l``).
SIDES: tuple[str, str] = ("r", "l")
#: The six channels of an F/T sensor: forces [N] then torques [N m].
FT_AXES: tuple[str, ...] = ("fx", "fy", "fz", "tx", "ty", "tz")
_SENSING = ("corners", "ft")


def corner_sensor_names() -> tuple[str, ...]:
    """``r1..r4, l1..l4``: 1 front-left, 2 front-right, 3 rear-left, 4 rear-right."""
    return tuple(f"{s}{k}" for s in SIDES for k in range(1, 5))


def ft_channels(side: str | None = None) -> tuple[str, ...]:
    """F/T channel names ``r_fx .. r_tz, l_fx .. l_tz`` (or one side's six)."""
    sides = SIDES if side is None else (side,)
    return tuple(f"{s}_{a}" for s in sides for a in FT_AXES)


@dataclass(frozen=True)
class Pose:
    """A pose in a body frame: position [m] and roll-pitch-yaw [rad] (fixed x-y-z)."""

    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def rotation(self) -> np.ndarray:
        """Rotation matrix ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (3, 3)."""
        r, p, y = self.rpy
        cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                                  math.cos(y), math.sin(y))
        return np.array([
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ])

    def quat(self) -> np.ndarray:
        """Quaternion (w, x, y, z) of :meth:`rotation`."""
        r, p, y = (0.5 * v for v in self.rpy)
        cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                                  math.cos(y), math.sin(y))
        return np.array([
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ])


@dataclass(frozen=True)
class FootDescription:
    """One foot.

    Attributes:
        body: The foot body of the model (the last body of the leg chain).
        sole: Pose of the sole frame F in ``body`` (origin at the sole centre, on the
            sole plane, z out of the sole).
        length: Sole length (x) [m].
        width: Sole width (y) [m].
        corner_inset: Distance of each corner load cell from the sole edges [m]
            (``corners`` sensing).
        ft: Pose of the F/T sensor frame in ``body`` (``ft`` sensing): it measures the
            wrench between ``body`` (and everything below it) and its parent.
    """

    body: str
    sole: Pose
    length: float
    width: float
    corner_inset: float = 0.005
    ft: Pose | None = None

    def corners_in_sole(self) -> np.ndarray:
        """(4, 2) corner load-cell positions in the sole frame [m] (order of
        :func:`corner_sensor_names`)."""
        hx = self.length / 2 - self.corner_inset
        hy = self.width / 2 - self.corner_inset
        return np.array([[hx, hy], [hx, -hy], [-hx, hy], [-hx, -hy]], dtype=float)


@dataclass(frozen=True)
class RobotDescription:
    """A humanoid = model file + feet, force sensing, IMU (see the module docstring).

    Attributes:
        name: Robot name (log metadata, scenario id ``<name>-walk-v1``).
        model: Path of the URDF or MJCF file (resolved).
        sensing: ``corners`` (four load cells per sole, columns ``force_r1..l4``) or
            ``ft`` (a six-axis sensor per ankle, columns ``ft_<r|l>_<fx..tz>``).
        feet: Right and left :class:`FootDescription`.
        imu_body: Body carrying the IMU.
        imu: IMU pose in ``imu_body``.
        base_body: The floating base (root body; None = the model's first body).
        mass: Measured total mass [kg]; None keeps the model's masses, otherwise
            every body's mass and inertia are scaled to match it.
        nominal: Joint angles [rad] of the nominal posture (joints not named: 0); the
            upper body is held there while walking.
        source: The TOML file the description was read from (messages).
    """

    name: str
    model: Path
    sensing: str
    feet: tuple[FootDescription, FootDescription]
    imu_body: str
    imu: Pose = Pose()
    base_body: str | None = None
    mass: float | None = None
    nominal: dict[str, float] = field(default_factory=dict)
    source: str = "<dict>"

    def foot(self, side: str) -> FootDescription:
        """The foot of ``side`` (``r`` or ``l``)."""
        return self.feet[SIDES.index(side)]

    @property
    def force_channels(self) -> tuple[str, ...]:
        """Names of the force channels of the log (``force_<name>`` / ``ft_<name>``)."""
        return corner_sensor_names() if self.sensing == "corners" else ft_channels()

    @property
    def force_columns(self) -> tuple[str, ...]:
        """Measured force columns of a log of this robot."""
        prefix = "force_" if self.sensing == "corners" else "ft_"
        return tuple(prefix + c for c in self.force_channels)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict (log metadata)."""
        def pose(p: Pose | None) -> Any:
            return None if p is None else {"pos": list(p.pos), "rpy": list(p.rpy)}

        return {
            "name": self.name,
            "model": str(self.model),
            "sensing": self.sensing,
            "imu": {"body": self.imu_body, **pose(self.imu)},
            "base_body": self.base_body,
            "mass": self.mass,
            "nominal": dict(self.nominal),
            "feet": {
                s: {"body": f.body, "sole": pose(f.sole), "length": f.length,
                    "width": f.width, "corner_inset": f.corner_inset, "ft": pose(f.ft)}
                for s, f in zip(SIDES, self.feet, strict=True)
            },
        }


# ------------------------------------------------------------------------ parsing
class _Reader:
    """Reads typed values from a TOML table, errors naming the file and the key."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, expected: str, got: Any) -> ConfigError:
        return ConfigError(f"{self.source}: key '{key}' must be {expected}, got {got!r}")

    def table(self, data: dict[str, Any], key: str, required: bool = True) -> dict[str, Any]:
        v = data.get(key.rsplit(".", 1)[-1])
        if v is None and not required:
            return {}
        if not isinstance(v, dict):
            raise self.fail(key, "a table", v) if v is not None else ConfigError(
                f"{self.source}: missing table [{key}]")
        return v

    def string(self, data: dict[str, Any], key: str, required: bool = True) -> str | None:
        v = data.get(key.rsplit(".", 1)[-1])
        if v is None and not required:
            return None
        if not isinstance(v, str) or not v:
            if v is None:
                raise ConfigError(f"{self.source}: missing key '{key}' (a string)")
            raise self.fail(key, "a non-empty string", v)
        return v

    def number(self, data: dict[str, Any], key: str, lo: float, hi: float, unit: str,
               default: float | None = None) -> float | None:
        v = data.get(key.rsplit(".", 1)[-1], default)
        if v is None:
            if default is None and key.rsplit(".", 1)[-1] in data:
                raise self.fail(key, f"a number in [{lo}, {hi}] {unit}", v)
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
            math.isfinite(v) and lo <= v <= hi
        ):
            raise self.fail(key, f"a number in [{lo}, {hi}] {unit}", v)
        return float(v)

    def vec3(self, data: dict[str, Any], key: str, default=(0.0, 0.0, 0.0)) -> tuple:
        v = data.get(key.rsplit(".", 1)[-1], default)
        ok = (isinstance(v, (list, tuple)) and len(v) == 3 and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
            for x in v))
        if not ok:
            raise self.fail(key, "a list of three numbers", v)
        return tuple(float(x) for x in v)

    def pose(self, data: dict[str, Any], key: str) -> Pose:
        return Pose(self.vec3(data, f"{key}.pos"), self.vec3(data, f"{key}.rpy"))

    def unknown(self, data: dict[str, Any], key: str, known: set[str]) -> None:
        extra = sorted(set(data) - known)
        if extra:
            where = f"[{key}]" if key else "the top level"
            raise ConfigError(
                f"{self.source}: unknown key(s) {extra} in {where}; known: {sorted(known)}")


def _resolve_model(spec: str, base: Path, source: str) -> Path:
    """``example-robot-data:<path>``, ``grfguard:suralp`` or a path relative to the TOML's
    folder."""
    prefix = "example-robot-data:"
    if spec.startswith("grfguard:"):
        if spec != "grfguard:suralp":
            raise ConfigError(f"{source}: key 'model' = {spec!r}: the only built-in model is "
                              "'grfguard:suralp'")
        return Path(spec)  # generated MJCF (grfguard.model.mjcf), no file
    if spec.startswith(prefix):
        import importlib.metadata as md

        try:
            dist = md.distribution("example-robot-data")
        except md.PackageNotFoundError:
            raise ConfigError(
                f"{source}: key 'model' = {spec!r} needs the example-robot-data package; "
                "install it with `pip install 'grfguard[robots]'`") from None
        path = Path(str(dist.locate_file(
            "cmeel.prefix/share/example-robot-data/robots"))) / spec[len(prefix):]
    else:
        path = Path(spec)
        if not path.is_absolute():
            path = base / path
    if not path.exists():
        raise ConfigError(f"{source}: key 'model' = {spec!r}: file {path} does not exist")
    if path.suffix.lower() not in (".urdf", ".xml", ".mjcf"):
        raise ConfigError(
            f"{source}: key 'model' = {spec!r} must be a URDF (.urdf) or MJCF (.xml) file")
    return path


def _foot(r: _Reader, data: dict[str, Any], key: str, sensing: str) -> FootDescription:
    r.unknown(data, key, {"body", "sole", "length", "width", "corner_inset", "ft"})
    sole = r.table(data, f"{key}.sole", required=False)
    r.unknown(sole, f"{key}.sole", {"pos", "rpy"})
    ft = None
    if sensing == "ft":
        ft_t = r.table(data, f"{key}.ft")
        r.unknown(ft_t, f"{key}.ft", {"pos", "rpy"})
        ft = r.pose(ft_t, f"{key}.ft")
    length = r.number(data, f"{key}.length", 0.02, 1.0, "m")
    width = r.number(data, f"{key}.width", 0.01, 1.0, "m")
    if length is None or width is None:
        raise ConfigError(f"{r.source}: [{key}] needs 'length' and 'width' of the sole [m]")
    inset = r.number(data, f"{key}.corner_inset", 0.0, 0.1, "m", default=0.005)
    if 2 * inset >= min(length, width):
        raise r.fail(f"{key}.corner_inset", f"less than half the sole width ({width / 2} m)",
                     inset)
    return FootDescription(
        body=r.string(data, f"{key}.body"),
        sole=r.pose(sole, f"{key}.sole"),
        length=length,
        width=width,
        corner_inset=inset,
        ft=ft,
    )


def description_from_dict(data: dict[str, Any], source: str = "<dict>",
                          base: Path | None = None) -> RobotDescription:
    """Build a :class:`RobotDescription` from parsed TOML (see the module docstring).

    Raises:
        ConfigError: naming ``source``, the key and what was expected.
    """
    r = _Reader(source)
    r.unknown(data, "", {"name", "model", "sensing", "mass", "base_body", "imu", "feet",
                         "nominal"})
    sensing = r.string(data, "sensing")
    if sensing not in _SENSING:
        raise r.fail("sensing", f"one of {list(_SENSING)}", sensing)
    model = _resolve_model(r.string(data, "model"), base or Path.cwd(), source)
    imu = r.table(data, "imu")
    r.unknown(imu, "imu", {"body", "pos", "rpy"})
    feet_t = r.table(data, "feet")
    r.unknown(feet_t, "feet", {"r", "l"})
    feet = tuple(
        _foot(r, r.table(feet_t, f"feet.{s}"), f"feet.{s}", sensing) for s in SIDES
    )
    nominal = r.table(data, "nominal", required=False)
    for k, v in nominal.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise r.fail(f"nominal.{k}", "a joint angle in rad", v)
    name = r.string(data, "name")
    return RobotDescription(
        name=name,
        model=model,
        sensing=sensing,
        feet=feet,  # type: ignore[arg-type]
        imu_body=r.string(imu, "imu.body"),
        imu=r.pose(imu, "imu"),
        base_body=r.string(data, "base_body", required=False),
        mass=r.number(data, "mass", 1.0, 1000.0, "kg"),
        nominal={k: float(v) for k, v in nominal.items()},
        source=source,
    )


def shipped_robots() -> tuple[str, ...]:
    """Names of the robot descriptions shipped in ``grfguard/robots``."""
    files = resources.files("grfguard") / "robots"
    return tuple(sorted(p.name[:-5] for p in files.iterdir() if p.name.endswith(".toml")))


def load_description(name_or_path: str | Path) -> RobotDescription:
    """Read a robot description: a shipped name (``talos``, ``g1``) or a TOML path.

    Raises:
        ConfigError: Unknown name, unreadable TOML, or a bad key (file, key and what was
            expected in the message).
    """
    text = str(name_or_path)
    shipped = shipped_robots()
    if text in shipped:
        res = resources.files("grfguard") / "robots" / f"{text}.toml"
        with resources.as_file(res) as p:
            path = Path(p)
    else:
        path = Path(text)
        if not path.exists():
            raise ConfigError(
                f"robot {text!r} is neither a shipped robot ({', '.join(shipped)}) nor an "
                "existing TOML file")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from exc
    return description_from_dict(data, source=str(path), base=path.parent)
