"""MuJoCo model (MJCF) of a 12-DOF biped built from a :class:`RobotConfig`.

Frames: world W (x forward, y left, z up, ground plane z = 0); trunk/pelvis body B
(origin midway between the two hip joints, axes = trunk axes); per leg the body chain
hip_yaw_link -> hip_roll_link -> thigh -> shank -> ankle_pitch_link -> foot, every
joint at its body's origin; sole frame F of each foot (origin at the sole centre, on
the sole plane, axes = foot axes).

Naming contract (everyone relies on it):

* bodies ``trunk`` (free joint ``root``), ``{s}_hip_yaw_link``, ``{s}_hip_roll_link``,
  ``{s}_thigh``, ``{s}_shank``, ``{s}_ankle_pitch_link``, ``{s}_foot`` for s in (r, l);
* hinge joints named as :data:`~grfguard.model.robot.JOINT_NAMES`, axes hip_yaw z,
  hip_roll x, hip_pitch y, knee y, ankle_pitch y, ankle_roll x; zero angles = straight
  leg, foot flat and pointing forward;
* sites ``imu`` (trunk origin), ``{s}_sole`` (sole centre, foot axes) and ``{s}{k}``
  (k = 1..4, centre of corner contact sphere k, radius 2 x contact radius so that it
  encloses the sphere's single contact);
* geoms ``{s}{k}_contact``: the only robot geoms that collide (spheres of radius
  ``robot.contact_radius`` whose bottom touches the sole plane);
* sensors ``touch_{s}{k}``, ``imu_acc`` (accelerometer), ``imu_gyro`` (gyro),
  ``imu_quat`` (framequat of the imu site in world), ``jointpos_<joint>``, plus truth
  sensors ``truth_imu_linvel`` (world-frame velocity of the imu site),
  ``truth_com_pos``, ``truth_com_vel`` (trunk subtree = whole robot),
  ``truth_base_pos``, ``truth_base_quat``, ``truth_sole_{s}_pos``,
  ``truth_sole_{s}_quat`` and ``truth_corner_{s}{k}_pos``;
* position actuators named as the joints.

Caveat: MuJoCo's ``accelerometer`` (``imu_acc``) is computed from the explicit ``qacc``
of ``mj_forward``; with ``implicitfast`` and stiff servo damping the velocity actually
changes by a different amount, and the sensor is off by ~0.3 m/s^2 RMS. The simulation
log (:func:`grfguard.sim.simulate`) therefore computes the accelerometer from the IMU
site's velocity (``truth_imu_linvel``) instead.

Scaling: gains and armature are given for SURALP (114 kg, hip-to-sole 0.674 m) and
scaled with the robot so another size walks without hand tuning: ``kp`` with the
gravity torque scale ``m g L``, armature with ``m L^2`` (so the servo bandwidth scales
like the pendulum frequency ``sqrt(g / L)``), ``kv = 0.025 s * kp``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

from grfguard.errors import ConfigError
from grfguard.model.robot import JOINTS_PER_LEG, SIDES, RobotConfig

if TYPE_CHECKING:
    import mujoco

__all__ = [
    "BodySpec",
    "body_layout",
    "actuator_gains",
    "joint_armature",
    "build_mjcf",
    "build_model",
    "KV_OVER_KP",
    "CORNER_SITE_RADIUS_FACTOR",
]

#: Reference robot scale (SURALP): mass [kg] and hip-to-sole length [m].
_REF_MASS = 114.0
_REF_LEG = 0.28 + 0.27 + 0.124
#: Position gains for SURALP in [N m / rad] (DESIGN.md, "Simulation facts").
_REF_KP = {
    "hip_yaw": 3.0e4,
    "hip_roll": 3.0e4,
    "hip_pitch": 3.0e4,
    "knee": 3.0e4,
    "ankle_pitch": 1.0e4,
    "ankle_roll": 1.0e4,
}
#: Ratio kv / kp of every position actuator in [s].
KV_OVER_KP = 0.025
#: Touch-site radius as a multiple of the contact sphere radius.
CORNER_SITE_RADIUS_FACTOR = 2.0

_AXES = {
    "hip_yaw": (0.0, 0.0, 1.0),
    "hip_roll": (1.0, 0.0, 0.0),
    "hip_pitch": (0.0, 1.0, 0.0),
    "knee": (0.0, 1.0, 0.0),
    "ankle_pitch": (0.0, 1.0, 0.0),
    "ankle_roll": (1.0, 0.0, 0.0),
}


@dataclass(frozen=True)
class BodySpec:
    """One rigid body of the biped, the single source of truth for MJCF and FK.

    Attributes:
        name: Body name (naming contract).
        parent: Parent body name (``trunk`` has parent ``world``).
        pos_in_parent: Body origin in the parent frame in [m], shape (3,).
        joint: Name of the hinge joint at the body origin (None for the trunk).
        axis: Joint axis in the body frame, shape (3,).
        mass: Body mass in [kg].
        com_in_body: Centre of mass in the body frame in [m], shape (3,).
        inertia_diag: Principal inertia about the CoM, body axes, in [kg m^2].
    """

    name: str
    parent: str
    pos_in_parent: tuple[float, float, float]
    joint: str | None
    axis: tuple[float, float, float]
    mass: float
    com_in_body: tuple[float, float, float]
    inertia_diag: tuple[float, float, float]


def _rod_inertia(mass: float, length: float, radius: float) -> tuple[float, float, float]:
    ixx = mass * (3.0 * radius**2 + length**2) / 12.0
    return (ixx, ixx, 0.5 * mass * radius**2)


def _box_inertia(mass: float, sx: float, sy: float, sz: float) -> tuple[float, float, float]:
    return (
        mass * (sy**2 + sz**2) / 12.0,
        mass * (sx**2 + sz**2) / 12.0,
        mass * (sx**2 + sy**2) / 12.0,
    )


def _sphere_inertia(mass: float, radius: float) -> tuple[float, float, float]:
    i = 0.4 * mass * radius**2
    return (i, i, i)


def _limb_radius(robot: RobotConfig) -> float:
    """Visual/inertial radius of thigh and shank in [m]."""
    return 0.08 * robot.leg_length


def _trunk_width(robot: RobotConfig) -> float:
    return robot.hip_width + robot.foot_width


@functools.lru_cache(maxsize=32)
def body_layout(robot: RobotConfig) -> tuple[BodySpec, ...]:
    """All bodies of the biped, parents before children (trunk, right leg, left leg).

    Masses add up to ``robot.mass`` exactly. The small links between the hip axes and
    at the ankle take 5 % of the thigh mass each (hip yaw, hip roll) and 10 % of the
    shank mass (ankle pitch link); the rest stays in thigh and shank.

    Args:
        robot: The robot description.

    Returns:
        Tuple of :class:`BodySpec`, ordered parents first.
    """
    m = robot.mass
    l1, l2, h = robot.upper_leg_length, robot.lower_leg_length, robot.sole_to_ankle
    r_limb = _limb_radius(robot)
    r_small = 0.05 * robot.leg_length
    m_thigh = m * robot.thigh_mass_fraction
    m_shank = m * robot.shank_mass_fraction
    m_foot = m * robot.foot_mass_fraction
    m_trunk = m * robot.trunk_mass_fraction
    specs = [
        BodySpec(
            name="trunk",
            parent="world",
            pos_in_parent=(0.0, 0.0, robot.leg_length),
            joint=None,
            axis=(0.0, 0.0, 0.0),
            mass=m_trunk,
            com_in_body=(robot.trunk_com_x, robot.trunk_com_y, robot.trunk_com_height),
            inertia_diag=_box_inertia(
                m_trunk, robot.trunk_depth, _trunk_width(robot), robot.trunk_height
            ),
        )
    ]
    ax = robot.ankle_offset_x
    for side in SIDES:
        y = robot.hip_width / 2 if side == "l" else -robot.hip_width / 2
        chain = [
            ("hip_yaw_link", "trunk", (0.0, y, 0.0), "hip_yaw", 0.05 * m_thigh,
             (0.0, 0.0, 0.0), _sphere_inertia(0.05 * m_thigh, r_small)),
            ("hip_roll_link", "hip_yaw_link", (0.0, 0.0, 0.0), "hip_roll", 0.05 * m_thigh,
             (0.0, 0.0, 0.0), _sphere_inertia(0.05 * m_thigh, r_small)),
            ("thigh", "hip_roll_link", (0.0, 0.0, 0.0), "hip_pitch", 0.9 * m_thigh,
             (0.0, 0.0, -l1 / 2), _rod_inertia(0.9 * m_thigh, l1, r_limb)),
            ("shank", "thigh", (0.0, 0.0, -l1), "knee", 0.9 * m_shank,
             (0.0, 0.0, -l2 / 2), _rod_inertia(0.9 * m_shank, l2, 0.8 * r_limb)),
            ("ankle_pitch_link", "shank", (0.0, 0.0, -l2), "ankle_pitch", 0.1 * m_shank,
             (0.0, 0.0, 0.0), _sphere_inertia(0.1 * m_shank, r_small)),
            ("foot", "ankle_pitch_link", (0.0, 0.0, 0.0), "ankle_roll", m_foot,
             (-ax, 0.0, -h / 2),
             _box_inertia(m_foot, robot.foot_length, robot.foot_width, h)),
        ]
        for name, parent, pos, joint, mass, com, inertia in chain:
            pname = parent if parent == "trunk" else f"{side}_{parent}"
            specs.append(
                BodySpec(
                    name=f"{side}_{name}",
                    parent=pname,
                    pos_in_parent=tuple(float(v) for v in pos),
                    joint=f"{side}_{joint}",
                    axis=_AXES[joint],
                    mass=float(mass),
                    com_in_body=tuple(float(v) for v in com),
                    inertia_diag=tuple(float(v) for v in inertia),
                )
            )
    return tuple(specs)


def _scale(robot: RobotConfig) -> tuple[float, float]:
    """(torque scale, inertia scale) of ``robot`` relative to SURALP."""
    return (
        robot.mass * robot.leg_length / (_REF_MASS * _REF_LEG),
        robot.mass * robot.leg_length**2 / (_REF_MASS * _REF_LEG**2),
    )


def actuator_gains(robot: RobotConfig) -> dict[str, tuple[float, float]]:
    """Position-servo gains of every joint, scaled to the robot.

    Args:
        robot: The robot description.

    Returns:
        Mapping joint name -> (kp [N m/rad], kv [N m s/rad]); kv = 0.025 s * kp.
    """
    torque_scale, _ = _scale(robot)
    out = {}
    for side in SIDES:
        for j in JOINTS_PER_LEG:
            kp = _REF_KP[j] * torque_scale
            out[f"{side}_{j}"] = (kp, KV_OVER_KP * kp)
    return out


def joint_armature(robot: RobotConfig) -> float:
    """Armature of every leg joint in [kg m^2].

    ``robot.armature`` is the value for a SURALP-sized robot (114 kg, 0.674 m legs); it
    is scaled by ``m L^2`` relative to SURALP.
    """
    _, inertia_scale = _scale(robot)
    return robot.armature * inertia_scale


def _f(v: float) -> str:
    return repr(float(v))


def _v(vals) -> str:
    return " ".join(_f(v) for v in vals)


def build_mjcf(robot: RobotConfig) -> str:
    """MJCF text of ``robot`` on a flat ground plane (naming contract in the module doc).

    Options: timestep 1 ms, ``implicitfast`` integrator, gravity ``robot.gravity``,
    default contact ``solref``/``solimp``, pyramidal friction cones (mu = 1).

    Args:
        robot: The robot description.

    Returns:
        The MJCF XML as a string.

    Raises:
        ConfigError: If ``robot`` is not a :class:`RobotConfig`.
    """
    if not isinstance(robot, RobotConfig):
        raise ConfigError(
            f"build_mjcf expects a grfguard RobotConfig, got {type(robot).__name__}; "
            "build one with RobotConfig(...) or load_robot(path)"
        )
    specs = body_layout(robot)
    children: dict[str, list[BodySpec]] = {}
    for s in specs:
        children.setdefault(s.parent, []).append(s)
    armature = joint_armature(robot)
    gains = actuator_gains(robot)
    joints = [s.joint for s in specs if s.joint is not None]
    actuators = [
        f'    <position name="{j}" joint="{j}" kp="{_f(gains[j][0])}" kv="{_f(gains[j][1])}"/>'
        for j in joints
    ]
    ground = 4.0 + 2.0 * robot.leg_length
    lines = [
        f'<mujoco model="{robot.name}">',
        '  <compiler angle="radian" autolimits="true"/>',
        f'  <option timestep="0.001" integrator="implicitfast" '
        f'gravity="0 0 {_f(-robot.gravity)}"/>',
        "  <worldbody>",
        f'    <geom name="ground" type="plane" size="{_f(50 * ground)} {_f(ground)} 0.1" '
        'contype="0" conaffinity="1" rgba="0.8 0.8 0.8 1"/>',
        '    <light pos="0 0 3" dir="0 0 -1" directional="true"/>',
        *_body_xml(robot, specs[0], 2, children, armature),
        "  </worldbody>",
        "  <actuator>",
        *actuators,
        "  </actuator>",
        "  <sensor>",
        *_sensors_xml(joints),
        "  </sensor>",
        "</mujoco>",
    ]
    return "\n".join(lines) + "\n"


def _geoms_xml(robot: RobotConfig, spec: BodySpec, ind: str) -> list[str]:
    """Geoms and sites of one body (trunk box + IMU site, limb capsules, foot box with
    the sole site and the four contact spheres and corner sites), indented by ``ind``."""
    r_limb = _limb_radius(robot)
    rc = robot.contact_radius
    h = robot.sole_to_ankle
    ax = robot.ankle_offset_x
    vis = 'contype="0" conaffinity="0" group="1" mass="0"'
    base = spec.name.split("_", 1)[-1] if spec.name != "trunk" else "trunk"
    if base == "trunk":
        size = (robot.trunk_depth / 2, _trunk_width(robot) / 2, robot.trunk_height / 2)
        return [
            f'{ind}<geom name="trunk_geom" type="box" size="{_v(size)}" '
            f'pos="0 0 {_f(robot.trunk_com_height)}" rgba="0.6 0.6 0.7 1" {vis}/>',
            f'{ind}<site name="imu" pos="0 0 0" size="0.01"/>',
        ]
    if base == "thigh":
        return [
            f'{ind}<geom type="capsule" fromto="0 0 0 0 0 {_f(-robot.upper_leg_length)}" '
            f'size="{_f(r_limb)}" rgba="0.7 0.5 0.3 1" {vis}/>'
        ]
    if base == "shank":
        return [
            f'{ind}<geom type="capsule" fromto="0 0 0 0 0 {_f(-robot.lower_leg_length)}" '
            f'size="{_f(0.8 * r_limb)}" rgba="0.7 0.5 0.3 1" {vis}/>'
        ]
    if base != "foot":
        return []
    corners = robot.sensor_positions_in_foot()
    side = spec.name[0]
    out = [
        f'{ind}<geom type="box" '
        f'size="{_v((robot.foot_length / 2, robot.foot_width / 2, h / 2 - rc))}" '
        f'pos="{_v((-ax, 0.0, -h / 2 + rc))}" rgba="0.3 0.3 0.3 0.6" {vis}/>',
        f'{ind}<site name="{side}_sole" pos="{_v((-ax, 0.0, -h))}" size="0.005"/>',
    ]
    for k in range(4):
        p = (-ax + corners[k, 0], corners[k, 1], -h + rc)
        out.append(
            f'{ind}<geom name="{side}{k + 1}_contact" type="sphere" size="{_f(rc)}" '
            f'pos="{_v(p)}" contype="1" conaffinity="0" condim="3" mass="0" '
            f'rgba="0.9 0.1 0.1 1"/>'
        )
        out.append(
            f'{ind}<site name="{side}{k + 1}" type="sphere" '
            f'size="{_f(CORNER_SITE_RADIUS_FACTOR * rc)}" pos="{_v(p)}"/>'
        )
    return out


def _body_xml(robot: RobotConfig, spec: BodySpec, depth: int,
              children: dict[str, list[BodySpec]], armature: float) -> list[str]:
    """``<body>`` element of ``spec`` and, recursively, of its children."""
    ind = "  " * depth
    lines = [f'{ind}<body name="{spec.name}" pos="{_v(spec.pos_in_parent)}">']
    if spec.joint is None:
        lines.append(f'{ind}  <freejoint name="root"/>')
    else:
        lines.append(
            f'{ind}  <joint name="{spec.joint}" type="hinge" axis="{_v(spec.axis)}" '
            f'armature="{_f(armature)}"/>'
        )
    lines.append(
        f'{ind}  <inertial pos="{_v(spec.com_in_body)}" mass="{_f(spec.mass)}" '
        f'diaginertia="{_v(spec.inertia_diag)}"/>'
    )
    lines.extend(_geoms_xml(robot, spec, ind + "  "))
    for child in children.get(spec.name, []):
        lines.extend(_body_xml(robot, child, depth + 1, children, armature))
    lines.append(f"{ind}</body>")
    return lines


def _sensors_xml(joints: list[str]) -> list[str]:
    """``<sensor>`` entries: measured (touch, IMU, encoders), then truth."""
    sensors = []
    for side in SIDES:
        for k in range(1, 5):
            sensors.append(f'    <touch name="touch_{side}{k}" site="{side}{k}"/>')
    sensors += [
        '    <accelerometer name="imu_acc" site="imu"/>',
        '    <gyro name="imu_gyro" site="imu"/>',
        '    <framequat name="imu_quat" objtype="site" objname="imu"/>',
    ]
    sensors += [f'    <jointpos name="jointpos_{j}" joint="{j}"/>' for j in joints]
    sensors += [
        '    <framelinvel name="truth_imu_linvel" objtype="site" objname="imu"/>',
        '    <subtreecom name="truth_com_pos" body="trunk"/>',
        '    <subtreelinvel name="truth_com_vel" body="trunk"/>',
        '    <framepos name="truth_base_pos" objtype="xbody" objname="trunk"/>',
        '    <framequat name="truth_base_quat" objtype="xbody" objname="trunk"/>',
    ]
    for side in SIDES:
        sensors += [
            f'    <framepos name="truth_sole_{side}_pos" objtype="site" objname="{side}_sole"/>',
            f'    <framequat name="truth_sole_{side}_quat" objtype="site" objname="{side}_sole"/>',
        ]
    for side in SIDES:
        for k in range(1, 5):
            sensors.append(
                f'    <framepos name="truth_corner_{side}{k}_pos" objtype="site" '
                f'objname="{side}{k}"/>'
            )
    return sensors


@functools.lru_cache(maxsize=16)
def build_model(robot: RobotConfig) -> mujoco.MjModel:
    """Compiled MuJoCo model of ``robot`` (cached on the frozen config).

    The returned model is shared by every caller with an equal config: do not mutate
    it (``copy.copy(model)`` first if you must).

    Args:
        robot: The robot description.

    Returns:
        The compiled ``mujoco.MjModel``.
    """
    import mujoco  # lazy: only the MuJoCo model needs it

    xml = build_mjcf(robot)
    try:
        return mujoco.MjModel.from_xml_string(xml)
    except ValueError as exc:  # pragma: no cover - our own XML
        raise ConfigError(f"MuJoCo rejected the model of robot {robot.name!r}: {exc}") from exc
