"""Robot description: the frozen, validated parameters of a biped.

Frames: world W (x forward, y left, z up); foot/sole frame F of each foot, origin at
the centre of the sole (on the ground plane when the foot is flat), axes aligned
with the foot (x forward, y left, z up).

The default is SURALP as given in the paper (Table I). Values the paper does not give
are assumed and documented on each field (``ASSUMED``).
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from grfguard._validate import check_number
from grfguard.errors import ConfigError

__all__ = [
    "RobotConfig",
    "SIDES",
    "JOINTS_PER_LEG",
    "JOINT_NAMES",
    "SENSOR_NAMES",
    "sensor_names",
    "load_robot",
    "SURALP",
]

#: Leg sides, right first.
SIDES: tuple[str, str] = ("r", "l")
#: Joint names of one leg, from the hip down.
JOINTS_PER_LEG: tuple[str, ...] = (
    "hip_yaw",
    "hip_roll",
    "hip_pitch",
    "knee",
    "ankle_pitch",
    "ankle_roll",
)
#: All 12 joint names, right leg first (``r_hip_yaw`` ... ``l_ankle_roll``).
JOINT_NAMES: tuple[str, ...] = tuple(f"{s}_{j}" for s in SIDES for j in JOINTS_PER_LEG)


def sensor_names(n_per_foot: int = 4) -> tuple[str, ...]:
    """Sensor names ``r1..rN, l1..lN`` for ``n_per_foot`` sensors per foot."""
    return tuple(f"{s}{k}" for s in SIDES for k in range(1, n_per_foot + 1))


#: The eight sole sensors of the default layout.
SENSOR_NAMES: tuple[str, ...] = sensor_names(4)


def _check_range(name: str, value: float, lo: float, hi: float, unit: str) -> None:
    check_number("robot", name, value, lo, hi, unit,
                 "edit the robot TOML (see `grfguard robot show`)")


@dataclass(frozen=True)
class RobotConfig:
    """Parameters of a 12-DOF biped with four force sensors per sole.

    All lengths in [m], masses in [kg]. Construct with keyword arguments or
    :meth:`from_toml`; invalid values raise :class:`~grfguard.errors.ConfigError`.
    """

    #: Robot name, written to log metadata.
    name: str = "suralp"
    #: Total mass in [kg] (paper, Table I).
    mass: float = 114.0
    #: Hip-pitch to knee distance in [m] (paper).
    upper_leg_length: float = 0.28
    #: Knee to ankle distance in [m] (paper).
    lower_leg_length: float = 0.27
    #: Ankle joint height above the sole in [m] (paper).
    sole_to_ankle: float = 0.124
    #: Sole length (x) in [m] (paper).
    foot_length: float = 0.24
    #: Sole width (y) in [m] (paper).
    foot_width: float = 0.15
    #: Lateral distance between the two hip joints in [m]. ASSUMED: 0.20 m, which
    #: leaves a 5 cm gap between 15 cm wide feet walking straight.
    hip_width: float = 0.20
    #: Ankle joint position along the sole x axis, from the sole centre, in [m].
    #: ASSUMED: 0 (ankle above the sole centre; the paper does not say).
    ankle_offset_x: float = 0.0
    #: Fraction of the mass in the trunk (with arms and head). ASSUMED: 0.70, so each
    #: leg carries 15 % (the swing leg inertia the paper neglects).
    trunk_mass_fraction: float = 0.70
    #: Fraction of the mass in each thigh. ASSUMED.
    thigh_mass_fraction: float = 0.07
    #: Fraction of the mass in each shank. ASSUMED.
    shank_mass_fraction: float = 0.05
    #: Fraction of the mass in each foot. ASSUMED.
    foot_mass_fraction: float = 0.03
    #: Height of the trunk's CoM above the hip joints in [m]. ASSUMED.
    trunk_com_height: float = 0.20
    #: Forward offset of the trunk's CoM from the hip midpoint in [m] (0: centred).
    trunk_com_x: float = 0.0
    #: Leftward offset of the trunk's CoM from the hip midpoint in [m] (0: centred).
    trunk_com_y: float = 0.0
    #: Trunk box height in [m] (inertia only). ASSUMED.
    trunk_height: float = 0.45
    #: Trunk box depth (x) in [m] (inertia only). ASSUMED.
    trunk_depth: float = 0.25
    #: Distance of each force sensor centre from the sole edge in [m]. ASSUMED: 1 cm.
    sensor_inset: float = 0.01
    #: Radius of the collision sphere at each sensor in [m] (DESIGN.md: ~5 mm).
    contact_radius: float = 0.005
    #: Joint armature in [kg m^2] for a SURALP-sized robot (DESIGN.md: 0.3); the MJCF
    #: scales it by m L^2 relative to SURALP (hip-to-sole length L).
    armature: float = 0.3
    #: Extra keys kept verbatim (for forward compatibility of TOML files).
    extra: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ConfigError(f"robot.name must be a non-empty string, got {self.name!r}")
        _check_range("mass", self.mass, 1.0, 1000.0, "kg")
        _check_range("upper_leg_length", self.upper_leg_length, 0.05, 2.0, "m")
        _check_range("lower_leg_length", self.lower_leg_length, 0.05, 2.0, "m")
        _check_range("sole_to_ankle", self.sole_to_ankle, 0.02, 0.5, "m")
        _check_range("foot_length", self.foot_length, 0.05, 1.0, "m")
        _check_range("foot_width", self.foot_width, 0.03, 0.6, "m")
        _check_range("hip_width", self.hip_width, 0.03, 1.0, "m")
        _check_range(
            "ankle_offset_x", self.ankle_offset_x, -self.foot_length / 2, self.foot_length / 2, "m"
        )
        for frac in (
            "trunk_mass_fraction",
            "thigh_mass_fraction",
            "shank_mass_fraction",
            "foot_mass_fraction",
        ):
            _check_range(frac, getattr(self, frac), 0.001, 0.99, "")
        total = self.trunk_mass_fraction + 2 * (
            self.thigh_mass_fraction + self.shank_mass_fraction + self.foot_mass_fraction
        )
        if abs(total - 1.0) > 1e-6:
            raise ConfigError(
                f"robot mass fractions add up to {total:.6f}, not 1: "
                "trunk + 2 * (thigh + shank + foot) must equal 1"
            )
        _check_range("trunk_com_height", self.trunk_com_height, 0.0, 2.0, "m")
        _check_range("trunk_com_x", self.trunk_com_x, -0.5, 0.5, "m")
        _check_range("trunk_com_y", self.trunk_com_y, -0.5, 0.5, "m")
        _check_range("trunk_height", self.trunk_height, 0.05, 3.0, "m")
        _check_range("trunk_depth", self.trunk_depth, 0.02, 2.0, "m")
        _check_range("contact_radius", self.contact_radius, 0.0005, 0.05, "m")
        max_inset = min(self.foot_length, self.foot_width) / 2 - 1e-3
        _check_range("sensor_inset", self.sensor_inset, 0.0, max_inset, "m")
        _check_range("armature", self.armature, 0.0, 100.0, "kg m^2")
        if self.hip_width <= self.foot_width:
            raise ConfigError(
                f"robot.hip_width = {self.hip_width} m must exceed robot.foot_width = "
                f"{self.foot_width} m, or the feet would overlap when walking straight"
            )

    # ------------------------------------------------------------------ geometry
    @property
    def leg_length(self) -> float:
        """Hip to sole distance with a straight leg in [m]."""
        return self.upper_leg_length + self.lower_leg_length + self.sole_to_ankle

    @property
    def gravity(self) -> float:
        """Gravity acceleration in [m/s^2] (the paper's value)."""
        return 9.806

    @property
    def weight(self) -> float:
        """m g in [N]."""
        return self.mass * self.gravity

    def sensor_positions_in_foot(self) -> np.ndarray:
        """(4, 2) sensor centres ``p_FS`` in the sole frame in [m].

        Order: 1 front-left, 2 front-right, 3 rear-left, 4 rear-right.
        """
        hx = self.foot_length / 2 - self.sensor_inset
        hy = self.foot_width / 2 - self.sensor_inset
        return np.array([[hx, hy], [hx, -hy], [-hx, hy], [-hx, -hy]], dtype=float)

    # ---------------------------------------------------------------- TOML round trip
    def to_dict(self) -> dict[str, Any]:
        """Plain dict of the parameters (``extra`` merged in)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "extra"}
        d.update(self.extra)
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RobotConfig:
        """Build from a dict; unknown keys are rejected with the list of known ones."""
        if "robot" in data and isinstance(data["robot"], dict):
            data = data["robot"]
        known = {f.name for f in dataclasses.fields(cls) if f.name != "extra"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(
                f"unknown robot key(s) {unknown}; known keys: {sorted(known)}"
            )
        return cls(**data)

    def to_toml(self) -> str:
        """TOML text with one commented line per parameter (``[robot]`` table)."""
        docs = _field_docs()
        lines = ["# grfguard robot description; lengths in m, masses in kg", "[robot]"]
        for key, value in self.to_dict().items():
            if key in docs:
                lines.append(f"# {docs[key]}")
            lines.append(f"{key} = {_toml_value(value)}")
        return "\n".join(lines) + "\n"

    @classmethod
    def from_toml(cls, text_or_path: str | Path) -> RobotConfig:
        """Parse TOML text or a ``.toml`` file path.

        Strict: the file must exist and be UTF-8 TOML text; the parameters are in a
        ``[robot]`` table (or at the top level); a key that is not a parameter is an error.
        Parameters left out take SURALP's values, with a
        :class:`~grfguard.errors.GrfguardWarning` listing them (a silent SURALP value in
        another robot's description gives wrong forces).
        """
        p = Path(text_or_path) if not str(text_or_path).lstrip().startswith(("[", "#")) else None
        if p is not None and (p.suffix == ".toml" or p.exists()):
            where = str(p)
            if not p.exists():
                raise ConfigError(f"robot file {p} does not exist")
            if p.is_dir():
                raise ConfigError(f"robot file {p} is a directory; give the robot .toml file")
            try:
                text = p.read_bytes().decode("utf-8")
            except UnicodeDecodeError:
                raise ConfigError(
                    f"robot file {p} is not a text file (not UTF-8); give a robot TOML "
                    "(`grfguard robot show` prints one)"
                ) from None
            except OSError as exc:
                raise ConfigError(f"robot file {p} cannot be read ({exc.strerror})") from None
        else:
            text = str(text_or_path)
            where = "<string>"
        if "\x00" in text:
            raise ConfigError(f"{where} is a binary file, not a robot TOML")
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{where} is not valid TOML: {exc}") from None
        if "robot" in data:
            if not isinstance(data["robot"], dict):
                raise ConfigError(
                    f"{where}: key 'robot' must be a [robot] table of parameters, got "
                    f"{data['robot']!r}; write '[robot]' then one 'name = value' line each"
                )
            others = sorted(set(data) - {"robot"})
            if others:
                raise ConfigError(
                    f"{where}: key(s) {others} are outside the [robot] table; move them into "
                    "it (or remove them)"
                )
            data = data["robot"]
        try:
            robot = cls.from_dict(data)
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        except TypeError as exc:
            raise ConfigError(f"{where}: bad robot parameters ({exc})") from None
        known = [f.name for f in dataclasses.fields(cls) if f.name != "extra"]
        missing = [k for k in known if k not in data]
        if missing:
            import warnings

            from grfguard.errors import GrfguardWarning

            warnings.warn(
                f"{where}: robot key(s) {missing} not given; SURALP's values are used "
                "(`grfguard robot show` lists them); add them to the [robot] table",
                GrfguardWarning,
                stacklevel=2,
            )
        return robot


def _toml_value(v: Any) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def _field_docs() -> dict[str, str]:
    """First sentence of each field's ``#:`` comment, read from this file's source."""
    import inspect

    src = inspect.getsource(RobotConfig).splitlines()
    docs: dict[str, str] = {}
    pending: list[str] = []
    for line in src:
        s = line.strip()
        if s.startswith("#:"):
            pending.append(s[2:].strip())
        elif s.startswith("#") and pending:
            pending.append(s[1:].strip())
        elif ":" in s and pending and not s.startswith(("def", "@", '"')):
            docs[s.split(":")[0].strip()] = " ".join(pending)
            pending = []
        else:
            pending = []
    return docs


def load_robot(path: str | Path | None) -> RobotConfig:
    """The robot in ``path`` (TOML), or SURALP when ``path`` is None."""
    return SURALP if path is None else RobotConfig.from_toml(Path(path))


#: The paper's robot.
SURALP = RobotConfig()
