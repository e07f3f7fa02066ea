"""Load a :class:`~grfguard.model.description.RobotDescription` into MuJoCo.

What real model files bring and how it is handled:

* mesh-only geometry: every visual and collision geometry of a URDF is dropped (the
  meshes are not needed for the physics; only the soles touch the ground), a MJCF's
  geoms are made non-colliding;
* a missing floating base: a free joint is added to the base body;
* inertias that break the triangle inequality: ``balanceinertia``;
* fixed links are kept as bodies (``fusestatic = false``) so sole and sensor frames of
  the file stay addressable.

Added to the model (names are the contract of :mod:`grfguard.sim.wholebody`):

* sites ``{s}_sole`` (sole frame), ``imu``, ``{s}_ft`` (F/T sensing) or ``{s}{k}``
  (corner load cells, k = 1..4) for s in (r, l);
* contact geoms: a sole box per foot (F/T sensing) or four spheres of radius 5 mm
  at the corner load cells (corner sensing), the only geoms that collide;
* sensors ``touch_{s}{k}`` or ``force_{s}`` / ``torque_{s}`` (at ``{s}_ft``),
  ``touch_sole_{s}`` (truth: total normal force of a foot), ``imu_gyro``, ``imu_quat``,
  ``truth_imu_linvel``, ``truth_com_pos``, ``truth_com_vel``, ``truth_base_pos``,
  ``truth_base_quat``, ``truth_sole_{s}_pos``, ``truth_sole_{s}_quat``;
* a position actuator per joint, named as the joint (gains from
  :func:`servo_gains`).

Options: timestep 1 ms, ``implicitfast``, pyramidal cones, friction 1.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import mujoco
import numpy as np

from grfguard.errors import ConfigError
from grfguard.model.description import SIDES, RobotDescription

__all__ = ["LoadedRobot", "load_model", "leg_joints", "CONTACT_RADIUS", "SOLE_THICKNESS"]

#: Radius of a corner contact sphere [m].
CONTACT_RADIUS = 0.005
#: Thickness of the sole contact box (F/T sensing) [m].
SOLE_THICKNESS = 0.01
#: Servo stiffness of hips and knees per unit of ``m g L`` [1/rad] (SURALP: 3e4 N m/rad
#: at 114 kg, L = 0.674 m); ankles one third of it.
_KP_LEG = 40.0
#: Ratio kv / kp of every position actuator [s].
KV_OVER_KP = 0.025


@dataclass
class LoadedRobot:
    """A compiled model and what the simulation and the estimator need to know of it.

    Attributes:
        description: The robot description.
        model: The compiled MuJoCo model (free base, sole geoms, sensors, servos).
        joint_names: Every actuated joint, model order (log columns ``q_<name>``).
        leg_joints: Joint names of the right and of the left leg, hip to ankle.
        base_body: The floating base body.
        mass: Total mass [kg].
        leg_length: Hip-to-sole height in the zero posture [m] (scales the gait).
        kp: Position gain of each joint (``joint_names`` order) [N m/rad].
    """

    description: RobotDescription
    model: mujoco.MjModel
    joint_names: tuple[str, ...]
    leg_joints: tuple[tuple[str, ...], tuple[str, ...]]
    base_body: str
    mass: float
    leg_length: float
    kp: np.ndarray

    def qpos_adr(self, names: tuple[str, ...] | list[str]) -> np.ndarray:
        """qpos addresses of joints."""
        return np.array([self.model.jnt_qposadr[self.model.joint(n).id] for n in names])

    def dof_adr(self, names: tuple[str, ...] | list[str]) -> np.ndarray:
        """qvel addresses of joints."""
        return np.array([self.model.jnt_dofadr[self.model.joint(n).id] for n in names])


def _urdf_xml(desc: RobotDescription) -> str:
    try:
        root = ET.parse(desc.model).getroot()
    except ET.ParseError as exc:
        raise ConfigError(f"{desc.model}: not valid XML ({exc})") from exc
    if root.tag != "robot":
        raise ConfigError(f"{desc.model}: a URDF's root element must be <robot>")
    for link in root.findall("link"):
        for tag in ("visual", "collision"):
            for e in link.findall(tag):
                link.remove(e)
    for tag in ("transmission", "gazebo", "mujoco"):
        for e in root.findall(tag):
            root.remove(e)
    # a floating joint to "world" (commented out in some files) is replaced by our own
    for j in root.findall("joint"):
        if j.get("type") == "floating":
            root.remove(j)
    for link in root.findall("link"):
        if link.get("name") == "world":
            root.remove(link)
    mj = ET.SubElement(root, "mujoco")
    c = ET.SubElement(mj, "compiler")
    c.set("fusestatic", "false")
    c.set("balanceinertia", "true")
    c.set("discardvisual", "true")
    c.set("strippath", "true")
    return ET.tostring(root, encoding="unicode")


def _spec(desc: RobotDescription) -> mujoco.MjSpec:
    try:
        if str(desc.model) == "grfguard:suralp":
            from grfguard.model.mjcf import build_mjcf
            from grfguard.model.robot import SURALP

            spec = _clean_mjcf(mujoco.MjSpec.from_string(build_mjcf(SURALP)))
        elif desc.model.suffix.lower() == ".urdf":
            spec = mujoco.MjSpec.from_string(_urdf_xml(desc))
        else:
            spec = _clean_mjcf(mujoco.MjSpec.from_file(str(desc.model)))
            spec.compiler.balanceinertia = True
    except ValueError as exc:
        raise ConfigError(f"{desc.model}: MuJoCo cannot read it ({exc})") from exc
    for g in list(spec.geoms):
        g.contype = 0
        g.conaffinity = 0
    return spec


def _clean_mjcf(spec: mujoco.MjSpec) -> mujoco.MjSpec:
    """An MJCF's own actuators, sensors, sites, world geoms (floor) and geoms named like
    ours (``*_contact``, ``*_sole_box``) are replaced by ours."""
    for group in (spec.actuators, spec.sensors, spec.sites):
        for e in list(group):
            spec.delete(e)
    for g in list(spec.worldbody.geoms):
        spec.delete(g)
    for g in list(spec.geoms):  # names of our contact geoms
        if g.name.endswith(("_contact", "_sole_box")):
            spec.delete(g)
    return spec


def _body(spec: mujoco.MjSpec, name: str, desc: RobotDescription, key: str):
    b = spec.body(name)
    if b is None:
        names = [x.name for x in spec.bodies if x.name != "world"]
        raise ConfigError(
            f"{desc.source}: key '{key}' = {name!r} is not a body of {desc.model.name}; "
            f"bodies: {', '.join(names)}")
    return b


def leg_joints(model: mujoco.MjModel, foot_body: str, base_body: str) -> tuple[str, ...]:
    """Hinge joints on the chain from ``base_body`` down to ``foot_body``, hip first."""
    b = model.body(foot_body).id
    base = model.body(base_body).id
    names: list[str] = []
    while b not in (base, 0):
        for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
                names.append(model.joint(j).name)
        b = int(model.body_parentid[b])
    return tuple(reversed(names))


def servo_gains(model: mujoco.MjModel, joint_names, legs, mass: float, leg_length: float,
                gravity: float) -> np.ndarray:
    """Position gains [N m/rad]: legs ``40 m g L`` (ankles a third), every other joint
    ``40 g m_sub r_sub`` from the mass ``m_sub`` it carries and that mass's lever
    ``r_sub`` (at least 0.1 m), so every servo sags about the same angle."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    kp = np.empty(len(joint_names))
    leg_set = {j: i for leg in legs for i, j in enumerate(leg)}
    mgl = mass * gravity * leg_length
    for n, name in enumerate(joint_names):
        if name in leg_set:
            i = leg_set[name]
            kp[n] = _KP_LEG * mgl * (1.0 if i < len(legs[0]) - 2 else 1.0 / 3.0)
            continue
        jid = model.joint(name).id
        b = int(model.jnt_bodyid[jid])
        m_sub = float(model.body_subtreemass[b])
        r_sub = float(np.linalg.norm(data.subtree_com[b] - data.xanchor[jid]))
        kp[n] = _KP_LEG * gravity * max(m_sub, 0.05) * max(r_sub, 0.1)
    return kp


def load_model(desc: RobotDescription, gravity: float = 9.81) -> LoadedRobot:
    """Compile the robot of ``desc`` with soles, sensors and servos (module docstring).

    Raises:
        ConfigError: A body named in the TOML is not in the model, the model has no
            joints, or a sole is not below its ankle (file, key and value named).
    """
    spec = _spec(desc)
    bodies = [b for b in spec.bodies if b.name != "world"]
    if not bodies:
        raise ConfigError(f"{desc.model}: the model has no bodies")
    base = (_body(spec, desc.base_body, desc, "base_body") if desc.base_body
            else spec.worldbody.first_body())
    if not any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in base.joints):
        if list(base.joints):
            raise ConfigError(
                f"{desc.source}: base body {base.name!r} of {desc.model.name} has joints; "
                "set 'base_body' to the floating base (pelvis)")
        base.add_freejoint(name="root")
    imu_b = _body(spec, desc.imu_body, desc, "imu.body")
    imu_b.add_site(name="imu", pos=desc.imu.pos, quat=desc.imu.quat())
    _add_feet(spec, desc)
    floor = spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE,
                                    size=[0, 0, 1], contype=0, conaffinity=1)
    floor.friction = [1.0, 0.005, 1e-4]
    spec.option.timestep = 0.001
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
    spec.option.gravity = [0.0, 0.0, -gravity]
    try:
        model = spec.compile()
    except ValueError as exc:
        raise ConfigError(f"{desc.model}: MuJoCo cannot compile it ({exc})") from exc

    base_name = base.name
    if desc.mass is not None:
        total = float(model.body_subtreemass[0])
        f = desc.mass / total
        spec_scale = [(b.name, b.mass, b.inertia) for b in spec.bodies if b.name != "world"]
        for name, m, inertia in spec_scale:
            spec.body(name).mass = m * f
            spec.body(name).inertia = np.asarray(inertia) * f
        model = spec.compile()
    joints = tuple(model.joint(j).name for j in range(model.njnt)
                   if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE)
    if not joints:
        raise ConfigError(f"{desc.model}: the model has no hinge joints")
    legs = tuple(leg_joints(model, f.body, base_name) for f in desc.feet)
    leg_len = _check_legs(model, desc, joints, legs, base_name)
    mass = float(model.body_subtreemass[0])
    kp = servo_gains(model, joints, legs, mass, leg_len, gravity)
    model = _add_servos_and_sensors(spec, desc, joints, kp, mass, leg_len)
    return LoadedRobot(desc, model, joints, legs, base_name, mass, leg_len, kp)


def _add_feet(spec: mujoco.MjSpec, desc: RobotDescription) -> None:
    """Sole site, contacts (a sole box for F/T sensing, else four corner spheres with
    their sites) and a truth touch site enclosing the sole, on each foot."""
    for s, foot in zip(SIDES, desc.feet, strict=True):
        fb = _body(spec, foot.body, desc, f"feet.{s}.body")
        q_sole = foot.sole.quat()
        fb.add_site(name=f"{s}_sole", pos=foot.sole.pos, quat=q_sole)
        R = foot.sole.rotation()
        p0 = np.asarray(foot.sole.pos)
        if desc.sensing == "ft":
            fb.add_site(name=f"{s}_ft", pos=foot.ft.pos, quat=foot.ft.quat())
            c = p0 + R @ np.array([0.0, 0.0, SOLE_THICKNESS / 2])
            fb.add_geom(name=f"{s}_sole_box", type=mujoco.mjtGeom.mjGEOM_BOX,
                        size=[foot.length / 2, foot.width / 2, SOLE_THICKNESS / 2],
                        pos=c, quat=q_sole, contype=1, conaffinity=0, friction=[1, 0.005, 1e-4],
                        mass=0)
        else:
            for k, (x, y) in enumerate(foot.corners_in_sole(), start=1):
                c = p0 + R @ np.array([x, y, CONTACT_RADIUS])
                fb.add_geom(name=f"{s}{k}_contact", type=mujoco.mjtGeom.mjGEOM_SPHERE,
                            size=[CONTACT_RADIUS, 0, 0], pos=c, contype=1, conaffinity=0,
                            friction=[1, 0.005, 1e-4], mass=0)
                fb.add_site(name=f"{s}{k}", pos=c, size=[2 * CONTACT_RADIUS, 0, 0])
        # a truth site enclosing the whole sole: total normal force of the foot
        fb.add_site(name=f"{s}_sole_touch", type=mujoco.mjtGeom.mjGEOM_BOX, pos=p0,
                    quat=q_sole, size=[foot.length / 2 + 0.02, foot.width / 2 + 0.02, 0.03])


def _check_legs(model: mujoco.MjModel, desc: RobotDescription, joints: tuple[str, ...],
                legs: tuple[tuple[str, ...], ...], base_name: str) -> float:
    """Check that every leg has 6 hinges, the nominal joints exist and each sole lies
    below its ankle facing up at the zero posture; returns the hip-to-sole length [m].

    Raises:
        ConfigError: On the first violation (file, key and value named).
    """
    for s, leg, f in zip(SIDES, legs, desc.feet, strict=True):
        if len(leg) < 6:
            raise ConfigError(
                f"{desc.source}: feet.{s}.body = {f.body!r} hangs from {base_name!r} by "
                f"{len(leg)} hinge joint(s) {list(leg)}; a walking leg needs 6")
    for n in desc.nominal:
        if n not in joints:
            raise ConfigError(f"{desc.source}: key 'nominal.{n}': no joint {n!r} in "
                              f"{desc.model.name}")
    # geometry at the zero posture: soles must be below their ankles
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    hips = []
    for s, leg, f in zip(SIDES, legs, desc.feet, strict=True):
        sole = data.site(f"{s}_sole")
        ankle = data.xanchor[model.joint(leg[-1]).id]
        hips.append(data.xanchor[model.joint(leg[0]).id].copy())
        if not sole.xpos[2] < ankle[2] - 0.01:
            raise ConfigError(
                f"{desc.source}: key 'feet.{s}.sole.pos' = {list(f.sole.pos)} puts the sole "
                f"{1000 * (sole.xpos[2] - ankle[2]):.0f} mm above the ankle joint "
                f"{leg[-1]!r} (zero posture); the sole must be below the ankle")
        if sole.xmat.reshape(3, 3)[2, 2] < 0.9:
            raise ConfigError(
                f"{desc.source}: key 'feet.{s}.sole.rpy' = {list(f.sole.rpy)}: the sole "
                "frame's z axis must point up (out of the sole) in the zero posture")
    leg_len = float(np.mean([hips[i][2] - data.site(f"{s}_sole").xpos[2]
                             for i, s in enumerate(SIDES)]))
    return leg_len


def _add_servos_and_sensors(spec, desc, joints, kp, mass, leg_len) -> mujoco.MjModel:
    # armature: SURALP's 0.3 kg m^2 scaled by m L^2 (servo bandwidth ~ sqrt(g / L))
    arm = 0.3 * (mass / 114.0) * (leg_len / 0.674) ** 2
    for j, k in zip(joints, kp, strict=True):
        spec.joint(j).armature = arm
        spec.joint(j).damping = [0.0, 0.0, 0.0]
        spec.joint(j).frictionloss = 0.0
        act = spec.add_actuator(name=j, target=j, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=float(k), kv=float(KV_OVER_KP * k))
        act.ctrllimited = 0
        act.forcelimited = 0
    S = mujoco.mjtSensor
    O = mujoco.mjtObj

    def sensor(name, typ, objtype=None, objname=""):
        s = spec.add_sensor(name=name, type=typ)
        if objtype is not None:
            s.objtype = objtype
            s.objname = objname
        return s

    for s in SIDES:
        if desc.sensing == "ft":
            sensor(f"force_{s}", S.mjSENS_FORCE, O.mjOBJ_SITE, f"{s}_ft")
            sensor(f"torque_{s}", S.mjSENS_TORQUE, O.mjOBJ_SITE, f"{s}_ft")
        else:
            for k in range(1, 5):
                sensor(f"touch_{s}{k}", S.mjSENS_TOUCH, O.mjOBJ_SITE, f"{s}{k}")
        sensor(f"touch_sole_{s}", S.mjSENS_TOUCH, O.mjOBJ_SITE, f"{s}_sole_touch")
    sensor("imu_gyro", S.mjSENS_GYRO, O.mjOBJ_SITE, "imu")
    sensor("imu_quat", S.mjSENS_FRAMEQUAT, O.mjOBJ_SITE, "imu")
    sensor("truth_imu_linvel", S.mjSENS_FRAMELINVEL, O.mjOBJ_SITE, "imu")
    base = spec.worldbody.first_body().name if desc.base_body is None else desc.base_body
    sensor("truth_com_pos", S.mjSENS_SUBTREECOM, O.mjOBJ_BODY, base)
    sensor("truth_com_vel", S.mjSENS_SUBTREELINVEL, O.mjOBJ_BODY, base)
    sensor("truth_base_pos", S.mjSENS_FRAMEPOS, O.mjOBJ_XBODY, base)
    sensor("truth_base_quat", S.mjSENS_FRAMEQUAT, O.mjOBJ_XBODY, base)
    for s in SIDES:
        sensor(f"truth_sole_{s}_pos", S.mjSENS_FRAMEPOS, O.mjOBJ_SITE, f"{s}_sole")
        sensor(f"truth_sole_{s}_quat", S.mjSENS_FRAMEQUAT, O.mjOBJ_SITE, f"{s}_sole")
    for j in joints:
        sensor(f"jointpos_{j}", S.mjSENS_JOINTPOS, O.mjOBJ_JOINT, j)
    return spec.compile()
