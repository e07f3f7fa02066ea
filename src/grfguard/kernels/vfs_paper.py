"""Compiled stages of the virtual force sensor's non-default settings.

Called from :func:`grfguard.kernels.vfs.vfs_step` (hooks marked ``vfs_paper`` in its
``_step``), over the same plain arrays, so every :class:`~grfguard.estimate.config.VFSConfig`
runs compiled:

* :func:`paper_com` - the paper's CoM estimator (eq. 1-5): LIPM jerk-form Kalman filter per
  horizontal axis, state ``(c, c_d, c_dd)``, process input the measured-ZMP rate,
  measurements the world IMU acceleration and eq. 1 ``p_act = c - z_c/g c_dd``; the ZMP
  disturbance observer low-passes ``p_ref - p_act`` into ``Delta c`` (eq. 4-5);
* :func:`zmp_kalman` - the pendulum Kalman filter with the ZMP as a state
  (``zmp_filter="kalman"``): per axis ``(c, c_d, p)``, ``c_dd = w2 (c - p) + u``,
  measurement the kinematic CoM;
* :func:`anchor_odometry` - leg odometry with the anchor attitude
  (``anchor_attitude_time_constant > 0``): the anchored sole's orientation replaces the IMU
  attitude at high frequency and every frame is rotated by ``R_corr``;
* :func:`paper_split` - the paper's split (eq. 6-12 read literally): alpha rule, literal
  CoP, clipped to the sensor rectangle, one QP per foot with ``W``.

The maths and the reference implementation (pure Python, the one these stages are tested
against to 1e-9 N) are in ``tests/reference/vfs_stages.py``. State layout: :data:`N_XSTATE`
floats after the default sensor's state (offset ``xo``); parameters: the ``prm`` slots
:data:`P_COM_PAPER` ... (:func:`extra_params`).
"""

from __future__ import annotations

import math

import numpy as np

from grfguard.kernels._jit import njit_nort, view2d
from grfguard.kernels.nnls import prior_qp

__all__ = ["N_XPRM", "N_XSTATE", "extra_params", "paper_com", "zmp_kalman",
           "anchor_odometry", "paper_split"]

# ------------------------------------------------------------------ prm slots (after 18)
P_COM_PAPER, P_SPLIT_PAPER, P_ZMP_KF, P_KANC = 18, 19, 20, 21
P_LIPM_H, P_JERK, P_ACC_VAR, P_ZMP_VAR, P_KDOB, P_DOBG, P_CYMAX = 22, 23, 24, 25, 26, 27, 28
P_ZKF_QA, P_ZKF_QZ, P_ZKF_R = 29, 30, 31
P_PF = 32  # sensor positions in the sole frame (4, 2): 32..39
N_XPRM = 22  # slots 18..39
#: Variance of the measured ZMP in the eq. 1 pseudo-measurement [m^2].
ZMP_VAR_M2 = 0.005**2
#: Smallest total force of the force sensors for a measured ZMP [N].
MIN_FOOT_FORCE_N = 1.0

# ------------------------------------------------------------------ state (offset xo)
_X_PC_OK, _X_ZC, _X_PC_X, _X_PC_P, _X_PPREV, _X_DC, _X_PACT_OK, _X_PACT = (
    0, 1, 2, 8, 17, 19, 21, 22)
_X_ZK_OK, _X_ZK_X, _X_ZK_P = 24, 25, 31
_X_RANC = 40  # anchor sole orientation (3, 3): 40..48
_X_WS = 49  # scratch of the Kalman filters: 49..118
N_XSTATE = 119


def extra_params(cfg, points_F: np.ndarray) -> np.ndarray:
    """The ``prm`` slots 18..39 for ``cfg`` (a VFSConfig) and the sensor positions (4, 2)."""
    p = np.zeros(N_XPRM)
    p[P_COM_PAPER - 18] = float(cfg.com_method == "paper")
    p[P_SPLIT_PAPER - 18] = float(cfg.split_method == "paper")
    p[P_ZMP_KF - 18] = float(cfg.zmp_filter == "kalman")
    t = cfg.anchor_attitude_time_constant
    p[P_KANC - 18] = cfg.dt / (t + cfg.dt) if t > 0 else 0.0
    p[P_LIPM_H - 18] = cfg.lipm_height
    p[P_JERK - 18] = cfg.paper_process_noise
    p[P_ACC_VAR - 18] = cfg.paper_measurement_noise
    p[P_ZMP_VAR - 18] = ZMP_VAR_M2
    p[P_KDOB - 18] = cfg.dt / (cfg.paper_dob_time_constant + cfg.dt)
    p[P_DOBG - 18] = cfg.paper_dob_gain
    p[P_CYMAX - 18] = cfg.paper_cy_max
    p[P_ZKF_QA - 18] = cfg.com_acc_psd * cfg.dt
    p[P_ZKF_QZ - 18] = cfg.zmp_rate_psd * cfg.dt
    p[P_ZKF_R - 18] = cfg.com_sigma**2
    p[P_PF - 18 : P_PF - 18 + 8] = np.asarray(points_F, float).reshape(8)
    return p


@njit_nort
def valid_paper_inputs(x) -> bool:
    """The paper's CoM filter also reads the accelerometer (19..21) and the force sensors
    (24..31) of the input row; all must be finite."""
    for i in range(19, 22):
        if not math.isfinite(x[i]):
            return False
    for i in range(24, 32):
        if not math.isfinite(x[i]):
            return False
    return True


# ------------------------------------------------------------------ paper CoM filter
@njit_nort
def paper_com(x, state, xo, prm, pk, pwt0, pwt1, pwt2, com0, com1, com2, ground, aw, ax,
              ay, az):
    """The paper's LIPM Kalman filter + ZMP disturbance observer for one sample.

    ``x``: input row with the force sensors at 24..31 [N] and the planned ZMP at 32..33
    [m]; ``pk``: corners relative to the trunk (8, 3) [m]; ``pwt``: trunk position [m];
    ``com``: kinematic CoM in world [m]; ``aw..az``: filtered attitude.

    Returns:
        ``com0, com1, com2`` [m], total force ``F0, F1, F2`` [N], ZMP ``p0, p1`` [m].
    """
    dt, g, mass = prm[0], prm[3], prm[4]
    if state[xo + _X_PC_OK] == 0.0:
        zc = prm[P_LIPM_H] if prm[P_LIPM_H] > 0 else com2 - ground
        state[xo + _X_ZC] = zc
        P = state[xo + _X_PC_P : xo + _X_PC_P + 9]
        for k in range(9):
            P[k] = 0.0
        P[0], P[4], P[8] = 1e-4, 1e-2, 1.0
        for k in range(4):
            state[xo + _X_PPREV + k] = 0.0  # p_prev, dc
    zc = state[xo + _X_ZC]
    # measured ZMP from the force sensors (eq. 1's p_act)
    f = x[24:32]
    fsum = ((f[0] + f[1]) + (f[2] + f[3])) + ((f[4] + f[5]) + (f[6] + f[7]))
    if fsum > MIN_FOOT_FORCE_N:
        s0 = f[0] * (pwt0 + pk[0, 0])
        s1 = f[0] * (pwt1 + pk[0, 1])
        for k in range(1, 8):
            s0 += f[k] * (pwt0 + pk[k, 0])
            s1 += f[k] * (pwt1 + pk[k, 1])
        pa0, pa1 = s0 / fsum, s1 / fsum
    elif state[xo + _X_PACT_OK] != 0.0:
        pa0, pa1 = state[xo + _X_PACT], state[xo + _X_PACT + 1]
    else:
        pa0, pa1 = com0, com1
    state[xo + _X_PACT_OK] = 1.0
    state[xo + _X_PACT] = pa0
    state[xo + _X_PACT + 1] = pa1
    # IMU acceleration in world, gravity removed (horizontal part)
    n = math.sqrt(aw * aw + ax * ax + ay * ay + az * az)
    w_, x_, y_, z_ = aw / n, ax / n, ay / n, az / n
    a0, a1, a2 = x[19], x[20], x[21]
    acc0 = (1 - 2 * (y_ * y_ + z_ * z_)) * a0 + 2 * (x_ * y_ - w_ * z_) * a1 \
        + 2 * (x_ * z_ + w_ * y_) * a2
    acc1 = 2 * (x_ * y_ + w_ * z_) * a0 + (1 - 2 * (x_ * x_ + z_ * z_)) * a1 \
        + 2 * (y_ * z_ - w_ * x_) * a2
    r0, r1 = x[32], x[33]
    has_ref = math.isfinite(r0) and math.isfinite(r1)
    c_hat0, cdd0, c_hat1, cdd1 = _paper_kf(state, xo, prm, dt, g, zc, pa0, pa1, acc0, acc1,
                                           has_ref, r0, r1)
    return (c_hat0, c_hat1, ground + zc, mass * cdd0, mass * cdd1, mass * g,
            c_hat0 - zc * cdd0 / g, c_hat1 - zc * cdd1 / g)


@njit_nort
def _mm(A, B, out, n, k, m, tb):
    """``out (n, m) = A (n, k) @ B (k, m)`` (``B^T`` when ``tb``: B stored (m, k)); flat
    row-major arrays; sums in index order, as numpy's small matrix products."""
    for i in range(n):
        for j in range(m):
            s = 0.0
            for r in range(k):
                s += A[i * k + r] * (B[j * k + r] if tb else B[r * m + j])
            out[i * m + j] = s


@njit_nort
def _paper_kf(state, xo, prm, t, g, zc, pa0, pa1, acc0, acc1, has_ref, r0, r1):
    """``PaperCoMFilter.update`` (tests/reference): predict with the jerk-form LIPM, correct
    with ``[acc; p_act]``; returns ``c_hat`` and ``c_dd`` per axis."""
    X = state[xo + _X_PC_X : xo + _X_PC_X + 6]  # (3, 2): state per axis in columns
    P = state[xo + _X_PC_P : xo + _X_PC_P + 9]
    ws = state[xo + _X_WS : xo + N_XSTATE]
    A, Q, H, xp, T, Pp, HP, S, PHt, K = (ws[0:9], ws[9:18], ws[18:24], ws[24:30],
                                         ws[30:39], ws[39:48], ws[48:54], ws[54:58],
                                         ws[58:64], ws[64:70])
    if state[xo + _X_PC_OK] == 0.0:
        for k in range(6):
            X[k] = 0.0
        X[0], X[1] = pa0, pa1
        state[xo + _X_PPREV] = pa0
        state[xo + _X_PPREV + 1] = pa1
        state[xo + _X_PC_OK] = 1.0
    pd = ((pa0 - state[xo + _X_PPREV]) / t, (pa1 - state[xo + _X_PPREV + 1]) / t)
    state[xo + _X_PPREV] = pa0
    state[xo + _X_PPREV + 1] = pa1
    w2 = g / zc
    A[0], A[1], A[2], A[3], A[4], A[5], A[6], A[7], A[8] = (
        1.0, t, 0.5 * t * t, 0.0, 1.0, t, 0.0, t * w2, 1.0)
    q = prm[P_JERK]
    Q[0], Q[1], Q[2] = q * (t**5 / 20), q * (t**4 / 8), q * (t**3 / 6)
    Q[3], Q[4], Q[5] = q * (t**4 / 8), q * (t**3 / 3), q * (t**2 / 2)
    Q[6], Q[7], Q[8] = q * (t**3 / 6), q * (t**2 / 2), q * t
    H[0], H[1], H[2], H[3], H[4], H[5] = 0.0, 0.0, 1.0, 1.0, 0.0, -zc / g
    b2 = -t * w2
    # predict
    _mm(A, X, xp, 3, 3, 2, False)
    for c in range(2):
        xp[4 + c] += b2 * pd[c]
    _mm(A, P, T, 3, 3, 3, False)
    _mm(T, A, Pp, 3, 3, 3, True)
    for k in range(9):
        Pp[k] += Q[k]
    # correct
    _mm(H, Pp, HP, 2, 3, 3, False)
    _mm(HP, H, S, 2, 3, 2, True)
    S[0] += prm[P_ACC_VAR]
    S[3] += prm[P_ZMP_VAR]
    det = S[0] * S[3] - S[1] * S[2]
    i00, i01, i10, i11 = S[3] / det, -S[1] / det, -S[2] / det, S[0] / det
    _mm(Pp, H, PHt, 3, 3, 2, True)
    for r in range(3):
        a, b = PHt[2 * r], PHt[2 * r + 1]
        K[2 * r] = a * i00 + b * i10
        K[2 * r + 1] = a * i01 + b * i11
    for c in range(2):
        y0 = (acc0 if c == 0 else acc1) - (xp[4 + c])
        y1 = (pa0 if c == 0 else pa1) - (xp[c] + H[5] * xp[4 + c])
        for r in range(3):
            X[2 * r + c] = xp[2 * r + c] + (K[2 * r] * y0 + K[2 * r + 1] * y1)
    # P = (I - K H) Pp
    for i in range(3):
        for j in range(3):
            m_ij = (1.0 if i == j else 0.0) - (K[2 * i] * H[j] + K[2 * i + 1] * H[3 + j])
            T[3 * i + j] = m_ij
    _mm(T, Pp, P, 3, 3, 3, False)
    dc = state[xo + _X_DC : xo + _X_DC + 2]
    if has_ref:
        kd = prm[P_KDOB]
        dc[0] = dc[0] + kd * ((r0 - pa0) - dc[0])
        dc[1] = dc[1] + kd * ((r1 - pa1) - dc[1])
    gd = prm[P_DOBG]
    return X[0] + gd * dc[0], X[4], X[1] + gd * dc[1], X[5]


# ------------------------------------------------------------------ pendulum ZMP filter
@njit_nort
def zmp_kalman(state, xo, prm, com0, com1, com2, ground, F2, ld0, ld1):
    """``zmp_filter="kalman"``: the ZMP (2 floats) [m] from the kinematic CoM ``com``
    [m], the vertical force ``F2`` [N] and the angular momentum rate ``ld0, ld1`` [N m]."""
    t, mass = prm[0], prm[4]
    h = max(com2 - ground, 1e-3)
    fz = max(F2, 1.0)
    w2 = fz / (mass * h)
    u = (-ld1 / (mass * h), ld0 / (mass * h))
    X = state[xo + _X_ZK_X : xo + _X_ZK_X + 6]  # (3, 2): c, c_d, p per axis
    P = state[xo + _X_ZK_P : xo + _X_ZK_P + 9]
    ws = state[xo + _X_WS : xo + N_XSTATE]
    A, xp, T, Pp = ws[0:9], ws[24:30], ws[30:39], ws[39:48]
    if state[xo + _X_ZK_OK] == 0.0:
        X[0], X[1], X[2], X[3], X[4], X[5] = com0, com1, 0.0, 0.0, com0, com1
        for k in range(9):
            P[k] = 0.0
        P[0], P[4], P[8] = 1e-6, 1e-2, 1e-4
        state[xo + _X_ZK_OK] = 1.0
    A[0], A[1], A[2], A[3], A[4], A[5], A[6], A[7], A[8] = (
        1.0, t, 0.0, w2 * t, 1.0, -w2 * t, 0.0, 0.0, 1.0)
    _mm(A, X, xp, 3, 3, 2, False)
    xp[2] += t * u[0]
    xp[3] += t * u[1]
    _mm(A, P, T, 3, 3, 3, False)
    _mm(T, A, Pp, 3, 3, 3, True)
    Pp[0] += 1e-12
    Pp[4] += prm[P_ZKF_QA]
    Pp[8] += prm[P_ZKF_QZ]
    s = Pp[0] + prm[P_ZKF_R]
    for c in range(2):
        innov = (com0 if c == 0 else com1) - xp[c]
        for r in range(3):
            X[2 * r + c] = xp[2 * r + c] + (Pp[3 * r] / s) * innov
    for r in range(3):
        kr = Pp[3 * r] / s
        for j in range(3):
            P[3 * r + j] = Pp[3 * r + j] - kr * Pp[j]
    return X[4], X[5]


# ------------------------------------------------------------------ anchor attitude
@njit_nort
def anchor_odometry(state, xo, prm, ia, ipa, pk, sxp, sxm, xipos, ximat, nb, c0, c1, c2,
                    st0, st1):
    """Leg odometry with the anchor attitude (``LegOdometry`` with
    ``attitude_time_constant > 0``, tests/reference): ``R_corr = R_WS_anchor R_WS^T``
    rotates every frame in place (corners ``pk``, IMU and sole sites ``sxp``/``sxm``,
    bodies ``xipos``/``ximat``). The anchor foot and its world position are
    ``state[ia]`` and ``state[ipa : ipa + 3]`` (set by the first sample's anchor choice).

    Returns:
        trunk position (3 floats) [m], ground height [m], the rotated trunk-relative CoM
        ``c0, c1, c2`` [m].
    """
    Ra = state[xo + _X_RANC : xo + _X_RANC + 9]
    ws = state[xo + _X_WS : xo + N_XSTATE]
    E, T, Rc = ws[0:9], ws[9:18], ws[18:27]
    a = int(state[ia])
    Rs = sxm[9 + a]
    # err = log(R_anc^T R_WS[a]) (small angle); R_anc <- R_anc exp(k err)
    _mtm(Ra, Rs, T)
    k = prm[P_KANC]
    w0 = k * (0.5 * (T[7] - T[5]))
    w1 = k * (0.5 * (T[2] - T[6]))
    w2 = k * (0.5 * (T[3] - T[1]))
    _so3_exp(w0, w1, w2, E)
    _mm(Ra, E, T, 3, 3, 3, False)
    for i in range(9):
        Ra[i] = T[i]
    _mm(Ra, Rs, Rc, 3, 3, 3, True)  # R_corr = R_anc R_WS[a]^T
    pw0 = state[ipa] - (Rc[0] * sxp[9 + a, 0] + Rc[1] * sxp[9 + a, 1] + Rc[2] * sxp[9 + a, 2])
    pw1 = state[ipa + 1] - (Rc[3] * sxp[9 + a, 0] + Rc[4] * sxp[9 + a, 1]
                            + Rc[5] * sxp[9 + a, 2])
    pw2 = state[ipa + 2] - (Rc[6] * sxp[9 + a, 0] + Rc[7] * sxp[9 + a, 1]
                            + Rc[8] * sxp[9 + a, 2])
    # rotate the frames
    for r in range(8):
        _rotv(Rc, pk, r)
    _rotv(Rc, sxp, 0)
    _rotv(Rc, sxp, 9)
    _rotv(Rc, sxp, 10)
    _rotm(Rc, sxm, 9, T)
    _rotm(Rc, sxm, 10, T)
    for b in range(1, nb):
        _rotv(Rc, xipos, b)
        _rotm(Rc, ximat, b, T)
    rc0 = Rc[0] * c0 + Rc[1] * c1 + Rc[2] * c2
    rc1 = Rc[3] * c0 + Rc[4] * c1 + Rc[5] * c2
    rc2 = Rc[6] * c0 + Rc[7] * c1 + Rc[8] * c2
    ground = min(pk[4 * a, 2], pk[4 * a + 1, 2], pk[4 * a + 2, 2], pk[4 * a + 3, 2]) + pw2
    o = 1 - a
    top = max(pk[4 * o, 2], pk[4 * o + 1, 2], pk[4 * o + 2, 2], pk[4 * o + 3, 2]) + pw2
    st_a = st0 if a == 0 else st1
    st_o = st1 if a == 0 else st0
    if st_o and (top - ground < prm[2] or not st_a):
        state[ia] = o
        state[ipa] = pw0 + sxp[9 + o, 0]
        state[ipa + 1] = pw1 + sxp[9 + o, 1]
        state[ipa + 2] = pw2 + sxp[9 + o, 2]
        for i in range(9):
            Ra[i] = sxm[9 + o, i]  # R_corr R_WS[o] (sxm already rotated)
    return pw0, pw1, pw2, ground, rc0, rc1, rc2


@njit_nort
def anchor_init(state, xo, ia, sxm):
    """First sample: the anchor orientation is the anchor sole's (IMU-based) one."""
    a = int(state[ia])
    for i in range(9):
        state[xo + _X_RANC + i] = sxm[9 + a, i]


@njit_nort
def _mtm(A, B, out):
    """``out = A^T B`` (3 x 3, flat row-major)."""
    for i in range(3):
        for j in range(3):
            out[3 * i + j] = A[i] * B[j] + A[3 + i] * B[3 + j] + A[6 + i] * B[6 + j]


@njit_nort
def _so3_exp(w0, w1, w2, E):
    """Rotation matrix ``exp([w]x)`` (flat) by Rodrigues' formula."""
    th = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    K = (0.0, -w2, w1, w2, 0.0, -w0, -w1, w0, 0.0)
    if th < 1e-9:
        a, b = 1.0, 0.0
    else:
        a, b = math.sin(th) / th, (1 - math.cos(th)) / th**2
    for i in range(3):
        for j in range(3):
            kk = K[3 * i] * K[j] + K[3 * i + 1] * K[3 + j] + K[3 * i + 2] * K[6 + j]
            E[3 * i + j] = (1.0 if i == j else 0.0) + a * K[3 * i + j] + b * kk


@njit_nort
def _rotv(R, v, r):
    """``v[r] <- R v[r]`` for a row of an (n, 3) array."""
    x0, x1, x2 = v[r, 0], v[r, 1], v[r, 2]
    v[r, 0] = R[0] * x0 + R[1] * x1 + R[2] * x2
    v[r, 1] = R[3] * x0 + R[4] * x1 + R[5] * x2
    v[r, 2] = R[6] * x0 + R[7] * x1 + R[8] * x2


@njit_nort
def _rotm(R, m, r, T):
    """``m[r] <- R m[r]`` for a row of an (n, 9) array of flat rotations."""
    _mm(R, m[r], T, 3, 3, 3, False)
    for i in range(9):
        m[r, i] = T[i]


# ------------------------------------------------------------------ paper split
@njit_nort
def paper_split(prm, pk, sxp, sxm, pwt0, pwt1, pwt2, com0, com1, com2, F0, F1, F2, st0, st1,
                forces, ctc, qp_x, qp_z, qp_free, qp_isfree, qp_M, qp_rhs, qp_dots, work):
    """The paper's split (eq. 6-12 read literally) into ``forces`` (8) [N]; ``ctc`` = the
    planned stance per corner; ``pk`` moved to the world."""
    for k in range(8):
        pk[k, 0] = pwt0 + pk[k, 0]
        pk[k, 1] = pwt1 + pk[k, 1]
        pk[k, 2] = pwt2 + pk[k, 2]
        ctc[k] = 1 if (st0 if k < 4 else st1) else 0
    s00, s01, s02 = pwt0 + sxp[9, 0], pwt1 + sxp[9, 1], pwt2 + sxp[9, 2]
    s10, s11, s12 = pwt0 + sxp[10, 0], pwt1 + sxp[10, 1], pwt2 + sxp[10, 2]
    mid0, mid1 = (s00 + s10) / 2.0, (s01 + s11) / 2.0
    heading = math.atan2((sxm[9, 3] + sxm[10, 3]) / 2.0, (sxm[9, 0] + sxm[10, 0]) / 2.0)
    y0, y1 = -math.sin(heading), math.cos(heading)
    cy_rel = (com0 - mid0) * y0 + (com1 - mid1) * y1
    cy_max = prm[P_CYMAX]
    if not cy_max > 0:
        cy_max = 0.5 * abs((s10 - s00) * y0 + (s11 - s01) * y1)
    alpha = min(max(cy_rel / max(cy_max, 1e-6), -1.0), 1.0)
    both = st0 and st1
    for i in range(2):
        if both:
            frac = 0.5 * (1.0 - alpha) if i == 0 else 0.5 * (1.0 + alpha)
        else:
            frac = (1.0 if st0 else 0.0) if i == 0 else (1.0 if st1 else 0.0)
        fx, fy, fz = frac * F0, frac * F1, frac * F2
        f0 = (s00 if i == 0 else s10) - com0
        f1 = (s01 if i == 0 else s11) - com1
        f2 = (s02 if i == 0 else s12) - com2
        _foot_split(prm, sxm[9 + i], 4 * i, f0, f1, f2, fx, fy, fz, forces, qp_x, qp_z, qp_free,
                    qp_isfree, qp_M, qp_rhs, qp_dots, work)


@njit_nort
def _foot_split(prm, R, b, f0, f1, f2, Fx, Fy, Fz, forces, qp_x, qp_z, qp_free, qp_isfree,
                qp_M, qp_rhs, qp_dots, work):
    """One foot of :func:`paper_split`: literal CoP ``d - f`` from ``M = f x F`` (eq. 10-12),
    in the sole frame ``R`` (flat), clipped to the sensor rectangle, QP over the foot's four
    sensors with the uniform prior; corners ``b..b+3`` of ``forces``."""
    if abs(Fz) > 1e-9:
        m0 = f1 * Fz - f2 * Fy
        m1 = f2 * Fx - f0 * Fz
        cw0 = -m1 / Fz - f0
        cw1 = m0 / Fz - f1
    else:
        cw0, cw1 = 0.0, 0.0
    c0 = R[0] * cw0 + R[3] * cw1 + R[6] * 0.0
    c1 = R[1] * cw0 + R[4] * cw1 + R[7] * 0.0
    pf = prm[P_PF : P_PF + 8]
    lo0 = min(pf[0], pf[2], pf[4], pf[6])
    hi0 = max(pf[0], pf[2], pf[4], pf[6])
    lo1 = min(pf[1], pf[3], pf[5], pf[7])
    hi1 = max(pf[1], pf[3], pf[5], pf[7])
    c0 = min(max(c0, lo0), hi0)
    c1 = min(max(c1, lo1), hi1)
    rel = view2d(work, 0, 4, 2)
    fin = math.isfinite(Fz) and math.isfinite(Fz / 4)
    for k in range(4):
        rel[k, 0] = pf[2 * k] - c0
        rel[k, 1] = pf[2 * k + 1] - c1
        qp_z[k] = Fz / 4
        if not (math.isfinite(rel[k, 0]) and math.isfinite(rel[k, 1])):
            fin = False
        forces[b + k] = 0.0
    if not fin:
        for k in range(4):
            forces[b + k] = np.nan
        return
    if Fz <= 0.0:
        return
    for k in range(4):
        work[8 + k] = qp_z[k]
    prior_qp(rel, work[8:12], Fz, prm[6], 4, qp_x, qp_z, qp_free, qp_isfree, qp_M, qp_rhs,
             qp_dots)
    s = ((qp_x[0] + qp_x[1]) + qp_x[2]) + qp_x[3]
    for k in range(4):
        forces[b + k] = qp_x[k] * (Fz / s) if s > 0 else qp_x[k]
