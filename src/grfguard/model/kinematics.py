"""Closed-form leg inverse kinematics and vectorized forward kinematics.

Notation (Drake-style monograms): ``p_WB`` position of frame B in world W [m], ``R_WB``
rotation of B in W (maps B coordinates to W). Frames: world W, trunk/pelvis B (the
``trunk`` body frame, origin midway between the hip joints), sole S of a foot (the
``{s}_sole`` site: sole centre on the sole plane, foot axes).

Every function is vectorized over time: positions have shape (T, 3), rotations
(T, 3, 3), joint angles (T, 6) for one leg or (T, 12) for both legs in
:data:`~grfguard.model.robot.JOINT_NAMES` order. A single pose (3,) / (3, 3) is
broadcast.

The geometry comes from :func:`grfguard.model.mjcf.body_layout`, the same table the
MJCF is built from, so FK here equals MuJoCo's ``mj_kinematics`` to rounding.
"""

from __future__ import annotations

import numpy as np

from grfguard.errors import ConfigError
from grfguard.model.mjcf import body_layout
from grfguard.model.robot import SIDES, RobotConfig
from grfguard.rotations import axis_index, rot_x, rot_y, rot_z, rotation_to_quat
from grfguard.rotations import quat_to_matrix as quat_to_rotation
from grfguard.rotations import rot_axis as _rot_axis

__all__ = [
    "rot_x",
    "rot_y",
    "rot_z",
    "rotation_to_quat",
    "quat_to_rotation",
    "leg_ik",
    "leg_fk",
    "body_poses",
    "center_of_mass",
]


def _check_side(side: str) -> None:
    if side not in SIDES:
        raise ConfigError(f"side must be one of {SIDES}, got {side!r}")


def _as_traj(p: np.ndarray, R: np.ndarray, n: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(p, dtype=float)
    R = np.asarray(R, dtype=float)
    p = p[None] if p.ndim == 1 else p
    R = R[None] if R.ndim == 2 else R
    t = max(p.shape[0], R.shape[0], n or 1)
    return np.broadcast_to(p, (t, 3)), np.broadcast_to(R, (t, 3, 3))


def _is_identity(R: np.ndarray) -> bool:
    """True for one (3, 3) rotation that is the identity (no negative zero): a product
    with it gives the other factor's values (the vectorized paths skip it)."""
    R = np.asarray(R)
    return R.shape == (3, 3) and bool(np.array_equal(R, _EYE)) and not np.signbit(R).any()


_EYE = np.eye(3)


def _hip_offset_in_pelvis(robot: RobotConfig, side: str) -> np.ndarray:
    return np.array([0.0, robot.hip_width / 2 if side == "l" else -robot.hip_width / 2, 0.0])


def _ankle_in_sole(robot: RobotConfig) -> np.ndarray:
    return np.array([robot.ankle_offset_x, 0.0, robot.sole_to_ankle])


def leg_ik(
    robot: RobotConfig,
    side: str,
    p_WB: np.ndarray,
    R_WB: np.ndarray,
    p_WS: np.ndarray,
    R_WS: np.ndarray,
) -> np.ndarray:
    """Closed-form 6-DOF leg IK (Kajita et al.'s analytic solution, knee bent forward).

    The three hip axes intersect at the hip joint and the two ankle axes at the ankle,
    so with ``r = R_WS^T (p_WH - p_WA)`` (hip seen from the ankle, sole axes),
    ``C = |r|``, thigh ``A`` and shank ``B``:

    ``knee = acos((C^2 - A^2 - B^2) / (2AB))``,
    ``ankle_roll = atan2(r_y, r_z)``,
    ``ankle_pitch = -atan2(r_x, sign(r_z) sqrt(r_y^2 + r_z^2)) - asin(A sin(knee) / C)``,
    and ``Rz(yaw) Rx(roll) Ry(pitch) = R_WB^T R_WS Rx(-ankle_roll) Ry(-(knee + ankle_pitch))``.

    Unreachable targets (``C > A + B``) are clipped to a straight knee.

    Args:
        robot: The robot description.
        side: ``"r"`` or ``"l"``.
        p_WB: Pelvis (trunk body) position in world [m], (T, 3) or (3,).
        R_WB: Pelvis orientation in world, (T, 3, 3) or (3, 3).
        p_WS: Sole-centre position in world [m], (T, 3) or (3,).
        R_WS: Sole orientation in world, (T, 3, 3) or (3, 3).

    Returns:
        Joint angles [rad], (T, 6): hip_yaw, hip_roll, hip_pitch, knee, ankle_pitch,
        ankle_roll.
    """
    _check_side(side)
    # an upright pelvis or a flat sole (the pattern generator's usual case): the products
    # with the identity are left out (same values: BENCHMARKS.md "Simulation speed: the
    # pattern generator")
    upright, flat = _is_identity(R_WB), _is_identity(R_WS)
    p_WB, R_WB = _as_traj(p_WB, R_WB)
    p_WS, R_WS = _as_traj(p_WS, R_WS, p_WB.shape[0])
    p_WB, R_WB = _as_traj(p_WB, R_WB, p_WS.shape[0])
    a, b = robot.upper_leg_length, robot.lower_leg_length
    hip, ankle = _hip_offset_in_pelvis(robot, side), _ankle_in_sole(robot)
    p_WH = p_WB + (hip if upright else R_WB @ hip)
    p_WA = p_WS + (ankle if flat else R_WS @ ankle)
    r = p_WH - p_WA if flat else np.einsum("tji,tj->ti", R_WS, p_WH - p_WA)
    c = np.linalg.norm(r, axis=1)
    cos_knee = np.clip((c**2 - a**2 - b**2) / (2 * a * b), -1.0, 1.0)
    knee = np.arccos(cos_knee)
    c_eff = np.minimum(c, a + b)
    q_a = np.arcsin(np.clip(a * np.sin(knee) / c_eff, -1.0, 1.0))
    ankle_roll = np.arctan2(r[:, 1], r[:, 2])
    ankle_roll = np.where(ankle_roll > np.pi / 2, ankle_roll - np.pi, ankle_roll)
    ankle_roll = np.where(ankle_roll < -np.pi / 2, ankle_roll + np.pi, ankle_roll)
    ankle_pitch = (
        -np.arctan2(r[:, 0], np.sign(r[:, 2]) * np.sqrt(r[:, 1] ** 2 + r[:, 2] ** 2)) - q_a
    )
    if upright and flat:
        r01, r11, r20, r21, r22 = _hip_entries(-ankle_roll, -(knee + ankle_pitch))
    else:
        R = (
            np.swapaxes(R_WB, 1, 2)
            @ R_WS
            @ rot_x(-ankle_roll)
            @ rot_y(-(knee + ankle_pitch))
        )
        r01, r11, r20, r21, r22 = R[:, 0, 1], R[:, 1, 1], R[:, 2, 0], R[:, 2, 1], R[:, 2, 2]
    yaw = np.arctan2(-r01, r11)
    cz, sz = np.cos(yaw), np.sin(yaw)
    roll = np.arctan2(r21, -r01 * sz + r11 * cz)
    pitch = np.arctan2(-r20, r22)
    return np.stack([yaw, roll, pitch, knee, ankle_pitch, ankle_roll], axis=1)


def _hip_entries(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, ...]:
    """Entries (0, 1), (1, 1), (2, 0), (2, 1), (2, 2) of ``rot_x(a) @ rot_y(b)`` for
    ``|a| <= pi / 2``, ``|b| < pi / 2``, with the matrix product's bits: each entry of
    that product has at most one non-zero term, so it is that term, or +0 where the
    terms are zeros (``x + 0.0`` turns -0 into +0 and changes nothing else)."""
    ca, sa = np.cos(a), np.sin(a)
    cb, sb = np.cos(b), np.sin(b)
    return np.zeros_like(ca), ca, ca * -sb + 0.0, sa + 0.0, ca * cb


def leg_fk(
    robot: RobotConfig,
    side: str,
    p_WB: np.ndarray,
    R_WB: np.ndarray,
    q_leg: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Sole pose of one leg from the pelvis pose and its 6 joint angles.

    Args:
        robot: The robot description.
        side: ``"r"`` or ``"l"``.
        p_WB: Pelvis position in world [m], (T, 3) or (3,).
        R_WB: Pelvis orientation in world, (T, 3, 3) or (3, 3).
        q_leg: Joint angles [rad], (T, 6) or (6,), order as :func:`leg_ik`.

    Returns:
        ``(p_WS, R_WS)``: sole-centre position (T, 3) [m] and orientation (T, 3, 3).
    """
    _check_side(side)
    q = np.atleast_2d(np.asarray(q_leg, dtype=float))
    p_WB, R_WB = _as_traj(p_WB, R_WB, q.shape[0])
    a, b = robot.upper_leg_length, robot.lower_leg_length
    p = p_WB + R_WB @ _hip_offset_in_pelvis(robot, side)
    R = R_WB @ rot_z(q[:, 0]) @ rot_x(q[:, 1]) @ rot_y(q[:, 2])
    p = p + R @ np.array([0.0, 0.0, -a])
    R = R @ rot_y(q[:, 3])
    p = p + R @ np.array([0.0, 0.0, -b])
    R = R @ rot_y(q[:, 4]) @ rot_x(q[:, 5])
    p = p - R @ _ankle_in_sole(robot)
    return p, R


def body_poses(
    robot: RobotConfig, p_WB: np.ndarray, R_WB: np.ndarray, q: np.ndarray
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """World pose of every body (MuJoCo ``xpos``/``xmat`` equivalent), vectorized.

    Args:
        robot: The robot description.
        p_WB: Trunk position in world [m], (T, 3) or (3,).
        R_WB: Trunk orientation in world, (T, 3, 3) or (3, 3).
        q: Joint angles [rad], (T, 12) or (12,), JOINT_NAMES order.

    Returns:
        Mapping body name -> (position (T, 3) [m], rotation (T, 3, 3)).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if q.shape[1] != 12:
        raise ConfigError(f"q must have 12 columns (JOINT_NAMES order), got shape {q.shape}")
    one_R = np.ndim(R_WB) == 2
    p_WB, R_WB = _as_traj(p_WB, R_WB, q.shape[0])
    if one_R and _use_compiled(q.shape[0]):
        return _compiled_poses(robot, p_WB, R_WB, q)[0]
    return _numpy_poses(robot, p_WB, R_WB, q)


def _numpy_poses(
    robot: RobotConfig, p_WB: np.ndarray, R_WB: np.ndarray, q: np.ndarray
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """:func:`body_poses` by stacked numpy products (``p_WB``, ``R_WB`` as
    :func:`_as_traj` gives them)."""
    from grfguard.model.robot import JOINT_NAMES

    col = {j: i for i, j in enumerate(JOINT_NAMES)}
    poses: dict[str, tuple[np.ndarray, np.ndarray]] = {"trunk": (p_WB, R_WB)}
    for spec in body_layout(robot)[1:]:
        pp, Rp = poses[spec.parent]
        p = pp + Rp @ np.asarray(spec.pos_in_parent)
        R = Rp @ _rot_axis(spec.axis, q[:, col[spec.joint]])
        poses[spec.name] = (p, R)
    return poses


def _numpy_com(robot: RobotConfig, poses: dict[str, tuple[np.ndarray, np.ndarray]]
               ) -> np.ndarray:
    """:func:`center_of_mass` of numpy's poses."""
    total = 0.0
    acc = 0.0
    for spec in body_layout(robot):
        p, R = poses[spec.name]
        acc = acc + spec.mass * (p + R @ np.asarray(spec.com_in_body))
        total += spec.mass
    return acc / total


#: Trajectories of at least this many samples (with one trunk orientation) take the
#: compiled path (:mod:`grfguard.kernels.chain`, same values to the bit); shorter ones
#: numpy's (numba's import and cache load cost more than they save there).
_COMPILED_MIN_SAMPLES = 256

#: Whether the compiled path gives numpy's bits on this machine (None: not probed yet).
_COMPILED_SAME_BITS: bool | None = None


def _use_compiled(n: int) -> bool:
    """True for ``n`` samples when the compiled path is both worth it and exact here.

    The kernels do numpy's arithmetic in numpy's order as this machine's numpy does it
    (fused multiply-adds in its BLAS products). Another CPU or BLAS may multiply
    otherwise; then the simulation would still run, but its plans would differ from
    numpy's in the last bits. So the first call compares the two paths once on a random
    trajectory of the reference robot (a few ms) and keeps numpy's where they differ."""
    global _COMPILED_SAME_BITS
    if n < _COMPILED_MIN_SAMPLES:
        return False
    if _COMPILED_SAME_BITS is None:
        _COMPILED_SAME_BITS = _probe_same_bits()
    return _COMPILED_SAME_BITS


def _probe_same_bits() -> bool:
    rng = np.random.default_rng(0)
    n = _COMPILED_MIN_SAMPLES
    robot = RobotConfig()
    q = rng.normal(0.0, 0.5, (n, 12))
    for p_WB, R_WB in ((rng.normal(0.0, 0.3, (n, 3)), np.eye(3)),
                       (rng.normal(0.0, 0.3, 3), rot_z(0.3) @ rot_x(-0.2))):
        p, R = _as_traj(p_WB, R_WB, n)
        fast, p0, R0, P, Rs = _compiled_poses(robot, p, R, q)
        slow = _numpy_poses(robot, p, R, q)
        if not all(np.array_equal(fast[k][i], slow[k][i]) for k in slow for i in (0, 1)):
            return False
        if not np.array_equal(_compiled_com(robot, p0, R0, P, Rs), _numpy_com(robot, slow)):
            return False
    return True


def _compiled_poses(
    robot: RobotConfig, p_WB: np.ndarray, R_WB: np.ndarray, q: np.ndarray
) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], np.ndarray, np.ndarray, np.ndarray,
           np.ndarray]:
    """:func:`body_poses` for one trunk orientation, compiled: the poses, the root's
    position (T, 3) and orientation (3, 3), and the arrays ``P`` (nb, T, 3) and ``R``
    (nb, T, 3, 3) the poses view (body 0's rows unused)."""
    from grfguard.kernels.chain import chain_poses
    from grfguard.model.robot import JOINT_NAMES

    specs = body_layout(robot)
    names = [sp.name for sp in specs]
    col = {j: i for i, j in enumerate(JOINT_NAMES)}
    n, nb = q.shape[0], len(specs)
    C, S = np.ones((nb, n)), np.zeros((nb, n))
    for b, sp in enumerate(specs[1:], 1):
        a = q[:, col[sp.joint]]  # the column view numpy's path takes cos / sin of
        C[b], S[b] = np.cos(a), np.sin(a)
    # writable copies: one compiled signature (broadcast inputs are read-only views)
    p0 = np.array(p_WB, dtype=float, order="C")
    R0 = np.array(R_WB[0], dtype=float, order="C")
    P, R = np.empty((nb, n, 3)), np.empty((nb, n, 3, 3))
    chain_poses(
        p0, R0, np.array([0] + [names.index(sp.parent) for sp in specs[1:]], dtype=np.int64),
        np.array([(0.0, 0.0, 0.0)] + [sp.pos_in_parent for sp in specs[1:]], dtype=float),
        np.array([0] + [axis_index(sp.axis) for sp in specs[1:]], dtype=np.int64),
        C, S, P, R,
    )
    poses = {"trunk": (p_WB, R_WB)}
    poses.update((sp.name, (P[b], R[b])) for b, sp in enumerate(specs) if b)
    return poses, p0, R0, P, R


def center_of_mass(
    robot: RobotConfig, p_WB: np.ndarray, R_WB: np.ndarray, q: np.ndarray
) -> np.ndarray:
    """Whole-body centre of mass in world [m], (T, 3) (MuJoCo ``subtree_com[trunk]``).

    Args:
        robot: The robot description.
        p_WB: Trunk position in world [m], (T, 3) or (3,).
        R_WB: Trunk orientation in world, (T, 3, 3) or (3, 3).
        q: Joint angles [rad], (T, 12) or (12,), JOINT_NAMES order.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if np.ndim(R_WB) == 2 and q.shape[1] == 12 and _use_compiled(q.shape[0]):
        p_WB, R_WB = _as_traj(p_WB, R_WB, q.shape[0])
        _, p0, R0, P, R = _compiled_poses(robot, p_WB, R_WB, q)
        return _compiled_com(robot, p0, R0, P, R)
    return _numpy_com(robot, body_poses(robot, p_WB, R_WB, q))


def _compiled_com(robot: RobotConfig, p0: np.ndarray, R0: np.ndarray, P: np.ndarray,
                  R: np.ndarray) -> np.ndarray:
    """:func:`center_of_mass` of :func:`_compiled_poses`'s arrays."""
    from grfguard.kernels.chain import chain_com

    specs = body_layout(robot)
    out = np.empty((P.shape[1], 3))
    chain_com(p0, R0, np.array([sp.mass for sp in specs]),
              np.array([sp.com_in_body for sp in specs], dtype=float), P, R, out)
    return out
