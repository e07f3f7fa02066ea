"""Calibration poses: a standing routine that loads the soles' corners one at a time.

On compliant flat ground a flat sole carries a planar load (``f_i = a + b x_i + c y_i``
over its four corners), so the whole-body balance of a walk cannot tell a sole's *twist*
of the load-cell gains (corners 1 and 4 against 2 and 3) from a correct calibration; it
shows only in partial contacts. This routine (``GaitConfig.calibration_poses``) gives the
self-calibration (:mod:`grfguard.calib.selfcal`) quasi-static partial contacts, where the
reference is exact (nothing accelerates: the load cells carry ``m g``).

Timeline, from :data:`ROUTINE_START_S` of the initial stand: the ZMP moves over
``1 - ROCK_SHARE`` of the way to the left foot; the right sole tilts by
:data:`TILT_DEG` about each of its four corners in turn (the other three corners rise, the
corner stays where it stood), each tilt held :data:`HOLD_S` between smooth ramps of
:data:`RAMP_S`; the ZMP moves to the other side and the left sole does the same; the ZMP
returns between the feet and the walk starts. The rocked foot keeps about
:data:`ROCK_SHARE` of the weight on its one corner. Planned contact (``contact_ref``)
stays 1 for both feet throughout.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "ROUTINE_START_S",
    "ROCK_SHARE",
    "TILT_DEG",
    "HOLD_S",
    "RAMP_S",
    "SHIFT_S",
    "routine_duration",
    "routine_zmp_knots",
    "routine_soles",
]

#: Time of the initial stand at which the routine starts [s].
ROUTINE_START_S = 1.0
#: Share of the weight the planned ZMP leaves on the rocked foot [-].
ROCK_SHARE = 0.3
#: Tilt of the rocked sole about each axis [deg] (the three other corners rise by
#: ``sin(TILT) * (corner spacing)``, a few mm: well above the ground's compression).
TILT_DEG = 2.0
#: Hold of each corner pose [s].
HOLD_S = 1.5
#: Smooth ramp into and out of each corner pose [s].
RAMP_S = 0.8
#: ZMP shift from one side to the other [s] (half of it from / to the middle).
SHIFT_S = 2.0
#: Corner order of each foot (indices into ``sensor_positions_in_foot``: 1 FL, 2 FR,
#: 4 RR, 3 RL).
_CORNER_ORDER = (0, 1, 3, 2)


def _foot_time() -> float:
    return len(_CORNER_ORDER) * (2 * RAMP_S + HOLD_S)


def routine_duration() -> float:
    """Duration of the routine [s] (from :data:`ROUTINE_START_S` to the ZMP back between
    the feet); the walk may start 0.5 s after its end."""
    return SHIFT_S / 2 + _foot_time() + SHIFT_S + _foot_time() + SHIFT_S / 2


def routine_zmp_knots(feet_xy: np.ndarray) -> tuple[list[float], list[np.ndarray]]:
    """Knot times [s] and ZMP positions [m] of the routine, from t = 0 to its end (ZMP
    back at the middle of the feet); ``feet_xy`` (2, 2) = (right, left) footprints."""
    mid = feet_xy.mean(axis=0)
    toward_l = ROCK_SHARE * feet_xy[0] + (1 - ROCK_SHARE) * feet_xy[1]  # right rocks
    toward_r = ROCK_SHARE * feet_xy[1] + (1 - ROCK_SHARE) * feet_xy[0]  # left rocks
    t0, tf = ROUTINE_START_S, _foot_time()
    kt = [0.0, t0, t0 + SHIFT_S / 2]
    kp = [mid, mid, toward_l]
    t1 = kt[-1] + tf
    kt += [t1, t1 + SHIFT_S]
    kp += [toward_l, toward_r]
    t2 = kt[-1] + tf
    kt += [t2, t2 + SHIFT_S / 2]
    kp += [toward_r, mid]
    return kt, kp


def _tilt_profile(t: np.ndarray, t_start: float) -> tuple[np.ndarray, np.ndarray]:
    """Per sample: tilt fraction in [0, 1] and the corner index posed (-1 none) of one
    foot whose corner poses start at ``t_start``."""
    frac = np.zeros(t.size)
    corner = np.full(t.size, -1)
    per = 2 * RAMP_S + HOLD_S
    for n, k in enumerate(_CORNER_ORDER):
        a = t_start + n * per
        m = (t >= a) & (t < a + per)
        tau = t[m] - a
        s = np.clip(np.minimum(tau, per - tau) / RAMP_S, 0.0, 1.0)
        frac[m] = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
        corner[m] = k
    return frac, corner


def routine_soles(t: np.ndarray, corners_xy: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Sole displacement (2, T, 3) [m] and orientation (2, T, 3, 3) of the routine at
    times ``t``; ``corners_xy`` (4, 2) are the corner contact points in the sole frame.

    Corner k at ``c = (x_k, y_k, 0)`` stays put: the sole rotates by ``R = Rx(-sy a)
    Ry(sx a)`` (``sx, sy`` the corner's signs, ``a`` the tilt, so the other corners rise)
    and moves by ``c - R c``. Identity and zero outside the corner poses.
    """
    R = np.broadcast_to(np.eye(3), (2, t.size, 3, 3)).copy()
    dp = np.zeros((2, t.size, 3))
    starts = (ROUTINE_START_S + SHIFT_S / 2,
              ROUTINE_START_S + SHIFT_S / 2 + _foot_time() + SHIFT_S)
    for i, t_start in enumerate(starts):
        frac, corner = _tilt_profile(t, t_start)
        for k in range(len(corners_xy)):
            m = corner == k
            if not m.any():
                continue
            sx, sy = np.sign(corners_xy[k])
            a = math.radians(TILT_DEG) * frac[m]
            ca, sa = np.cos(a), np.sin(a)
            Rx = np.zeros((m.sum(), 3, 3))
            Rx[:, 0, 0] = 1.0
            Rx[:, 1, 1], Rx[:, 1, 2], Rx[:, 2, 1], Rx[:, 2, 2] = ca, sy * sa, -sy * sa, ca
            Ry = np.zeros_like(Rx)
            Ry[:, 1, 1] = 1.0
            Ry[:, 0, 0], Ry[:, 0, 2], Ry[:, 2, 0], Ry[:, 2, 2] = ca, sx * sa, -sx * sa, ca
            Rk = Rx @ Ry
            c = np.array([corners_xy[k, 0], corners_xy[k, 1], 0.0])
            R[i, m] = Rk
            dp[i, m] = c - Rk @ c
    return dp, R
