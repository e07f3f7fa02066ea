r"""Reference (tests and benchmarks only; formerly ``grfguard.estimate.legs``): leg force
split, centre of pressure and contact-point forces in numpy, compiled in
:func:`grfguard.kernels.vfs._corner_contact` / ``_force_split`` and
:func:`grfguard.kernels.vfs_paper.paper_split`.

Two methods, both on arrays over time (leading axis ``T``) and usable on one sample:

* ``qp`` (default, physically consistent). The corners in contact ``K`` come from the
  kinematic corner heights, with the planned stance as a fallback (never from the
  monitored sensors). One QP over all of them, in world coordinates relative to the ZMP ``p``:

  .. math::

      \min_N \Big\lVert \sum_{k \in K} N_k (r_k - p) \Big\rVert^2 + w \lVert N \rVert^2
      \quad \text{s.t.} \quad N \ge 0,\; \sum_k N_k = F_z,\; N_k = 0 \; (k \notin K).

  In single support this is "everything on the stance foot, CoP = ZMP clipped to the
  sole" (for a rectangle the least-squares projection is the clip); in double support
  it is one rigid body on equal springs with only the total force and moment known
  (DESIGN.md: per-foot splits by ZMP position were poor). A heel-first landing keeps the
  lifted toe corners out of ``K``.

* ``paper`` (eq. 6-12, read literally). ``alpha = c_y / c_y,max`` clipped to ``[-1, 1]``
  (eq. 7, 9), ``F_L = (1 + alpha)/2 F``, ``F_R = (1 - alpha)/2 F`` with the gravity the
  paper leaves out (``F = m (c_dd + g e_z)``); single support puts everything on the stance
  foot. Moments ``M_i = f_i x F_i`` with ``f_i`` the foot origin from the CoM (eq. 10),
  ``d_i = [-M_y/F_z, M_x/F_z]`` (eq. 11), ``CoP_i = d_i - f_i`` (eq. 12), which reduces to
  ``CoP_i = -f_z F_xy / F_z = h F_xy / F_z``: the CoM-to-foot offset drops out (the
  documented error of the paper; DESIGN.md item 3). The CoP is clipped to the sensor
  rectangle and distributed per foot with the paper's ``W``.
"""

from __future__ import annotations

import numpy as np

from reference.corner_split import qp_split

__all__ = [
    "corner_contact",
    "split_qp",
    "paper_alpha",
    "paper_leg_forces",
    "paper_cop_literal",
    "world_to_foot_xy",
    "split_paper_feet",
    "split_with_prior",
]


def corner_contact(
    corner_height_m: np.ndarray,
    stance: np.ndarray,
    contact_height_m: float,
    kinematic: bool = True,
) -> np.ndarray:
    """Corners taken to be in contact.

    With ``kinematic`` a corner touches when it is within ``contact_height_m`` of the
    ground, whatever the plan says: feet land early or late and heel first (DESIGN.md),
    and the plan is wrong in those windows. A planned-stance foot with no corner that low
    keeps its lowest corner (the plan says it is down; a slightly wrong height must not
    leave the robot floating). Without ``kinematic`` every corner of a planned-stance foot
    touches (the paper). If no foot is planned in stance, the lowest foot counts as planned.

    Args:
        corner_height_m: (..., 8) height of each corner above the ground [m].
        stance: (..., 2) planned stance (right, left), bool.
        contact_height_m: Threshold [m].
        kinematic: Use the heights.

    Returns:
        (..., 8) bool.
    """
    h = np.asarray(corner_height_m, float)
    st = np.asarray(stance, bool)
    feet_h = h.reshape(h.shape[:-1] + (2, 4))
    none = ~st.any(axis=-1, keepdims=True)
    lower = np.argmin(feet_h.min(axis=-1), axis=-1)
    st = st | (none & (np.arange(2) == lower[..., None]))
    foot = np.repeat(st, 4, axis=-1)
    if not kinematic:
        return foot
    low = h < contact_height_m
    lowest = (feet_h == feet_h.min(axis=-1, keepdims=True)).reshape(h.shape)
    any_low = np.repeat(feet_h.min(axis=-1) < contact_height_m, 4, axis=-1)
    return low | (foot & ~any_low & lowest)


def split_qp(
    corners_xy_W: np.ndarray,
    contact: np.ndarray,
    zmp_W: np.ndarray,
    total_force_n: np.ndarray,
    weight: float,
) -> np.ndarray:
    """Corner forces from the total vertical force and the ZMP, batch.

    Args:
        corners_xy_W: (T, 8, 2) corner contact points in world [m].
        contact: (T, 8) corners in contact (bool).
        zmp_W: (T, 2) ZMP in world [m].
        total_force_n: (T,) total vertical ground force [N].
        weight: QP weight ``w`` [m^2].

    Returns:
        (T, 8) forces [N] (``NaN`` where the input was not finite).
    """
    rel = corners_xy_W - zmp_W[:, None, :]
    ok = np.asarray(contact, bool)
    # the uniform prior F_z / n is the rigid QP's |N|^2 on the constraint sum N = F_z
    prior = np.asarray(total_force_n, float)[:, None] / np.maximum(ok.sum(axis=1), 1)[:, None]
    return qp_split(rel, np.broadcast_to(prior, ok.shape), total_force_n, weight, ok)


def paper_alpha(com_y_rel_m: np.ndarray, cy_max_m: np.ndarray | float) -> np.ndarray:
    """Paper eq. 7 and 9: ``alpha = c_y / c_y,max`` clipped to [-1, 1].

    Args:
        com_y_rel_m: lateral CoM relative to the mid-point of the feet [m] (left positive).
        cy_max_m: lateral CoM excursion that puts all the load on one foot [m].
    """
    return np.clip(np.asarray(com_y_rel_m) / np.maximum(cy_max_m, 1e-6), -1.0, 1.0)


def paper_leg_forces(force_W: np.ndarray, alpha: np.ndarray, stance: np.ndarray) -> np.ndarray:
    """Paper eq. 6 (with gravity): leg forces of the right and left foot.

    Args:
        force_W: (T, 3) total ground force ``m (c_dd + g e_z)`` [N].
        alpha: (T,) eq. 7 ratio.
        stance: (T, 2) planned stance (right, left).

    Returns:
        (T, 2, 3) forces on the right and left foot [N]; single support puts everything on
        the stance foot, no stance (flight) gives zeros.
    """
    st = np.asarray(stance, bool)
    a = np.asarray(alpha, float)
    frac_r = np.where(st[:, 0] & st[:, 1], 0.5 * (1.0 - a), st[:, 0].astype(float))
    frac_l = np.where(st[:, 0] & st[:, 1], 0.5 * (1.0 + a), st[:, 1].astype(float))
    return np.stack([frac_r[:, None] * force_W, frac_l[:, None] * force_W], axis=1)


def paper_cop_literal(foot_from_com_W: np.ndarray, leg_force_W: np.ndarray) -> np.ndarray:
    """Paper eq. 10-12 read literally: CoP of each foot from its frame origin.

    ``M = f x F``; ``d = [-M_y/F_z, M_x/F_z]``; ``CoP = d - f`` (world axes).

    Args:
        foot_from_com_W: (..., 3) foot frame origin minus CoM [m].
        leg_force_W: (..., 3) leg force [N].

    Returns:
        (..., 2) CoP relative to the foot origin, world axes [m] (``NaN`` -> 0 where the
        foot carries no vertical force).
    """
    M = np.cross(foot_from_com_W, leg_force_W)
    fz = leg_force_W[..., 2]
    safe = np.where(np.abs(fz) > 1e-9, fz, 1.0)
    d = np.stack([-M[..., 1] / safe, M[..., 0] / safe], axis=-1)
    cop = d - foot_from_com_W[..., :2]
    return np.where((np.abs(fz) > 1e-9)[..., None], cop, 0.0)


def world_to_foot_xy(vec_W_xy: np.ndarray, R_WS: np.ndarray) -> np.ndarray:
    """Rotate horizontal world vectors into the sole frame (x, y of ``R_WS^T v``)."""
    v = np.concatenate([vec_W_xy, np.zeros(vec_W_xy.shape[:-1] + (1,))], axis=-1)
    return np.einsum("...ji,...j->...i", R_WS, v)[..., :2]


def split_paper_feet(
    cop_F: np.ndarray,
    foot_force_n: np.ndarray,
    points_F: np.ndarray,
    weight: float,
) -> np.ndarray:
    """Per-foot distribution of the paper: CoP clipped to the sensor rectangle, QP per foot.

    Args:
        cop_F: (T, 2, 2) CoP of (right, left) in each sole frame [m].
        foot_force_n: (T, 2) vertical force of each foot [N].
        points_F: (4, 2) sensor positions in the sole frame [m].
        weight: QP weight (the paper: 0.01) [m^2].

    Returns:
        (T, 8) corner forces [N].
    """
    lo, hi = points_F.min(axis=0), points_F.max(axis=0)
    cop = np.clip(cop_F, lo, hi).reshape(-1, 2)  # (2T, 2): right, left of each sample
    fz = np.asarray(foot_force_n, float).reshape(-1)
    n = points_F.shape[0]
    # |C N - F_z CoP|^2 = |sum N_k (r_k - CoP)|^2 on sum N = F_z; uniform prior = |N|^2
    rel = points_F[None, :, :] - cop[:, None, :]
    forces = qp_split(rel, np.repeat(fz[:, None] / n, n, axis=1), fz, weight)
    return forces.reshape(-1, 8)


def split_with_prior(
    corners_W: np.ndarray,
    contact: np.ndarray,
    zmp_W: np.ndarray,
    total_force_n: np.ndarray,
    weight: float,
    stiffness_n_m: float,
    extra_prior: np.ndarray | None = None,
) -> np.ndarray:
    """Batch over T samples: corners (T, n, 3) in world [m], contact (T, n), ZMP (T, 2) [m],
    total force (T,) [N]; returns (T, n) forces [N]. ``extra_prior`` (T, n) [N] is added
    to the prior (the contact twist)."""
    # vectorized prior (same arithmetic as compliance_prior)
    z = corners_W[:, :, 2]
    cnt = contact.sum(axis=1)
    safe = np.maximum(cnt, 1)
    zbar = np.where(contact, z, 0.0).sum(axis=1) / safe
    prior = np.where(
        contact, (total_force_n / safe)[:, None] + stiffness_n_m * (zbar[:, None] - z), 0.0
    )
    if extra_prior is not None:
        prior = prior + extra_prior
    rel = corners_W[:, :, :2] - zmp_W[:, None, :]
    return qp_split(rel, prior, total_force_n, weight, contact)
