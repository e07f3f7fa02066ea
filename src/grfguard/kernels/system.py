"""The system-level ("common-mode") layer of :mod:`grfguard.detect.system` as compiled steps.

Mirrors, on flat arrays and in the same operation order, what
:meth:`grfguard.pipeline.Monitor.update` does with ``common_mode`` on:

* before the virtual sensor (:func:`sys_pre_vfs`): the gyro bias learned while standing
  (:class:`~grfguard.detect.system.GyroBiasLearner`) is subtracted, the IMU mounting tilt
  learned from the sole normals (:class:`~grfguard.detect.system.ImuTiltLearner`, forward
  kinematics of :mod:`grfguard.kernels.vfs`) rotated out of the IMU readings;
* after the virtual sensor (:func:`sys_twin`): the twin virtual sensor without the
  accelerometer (settings :func:`~grfguard.detect.system.quiet_vfs_config`) runs beside
  the main one; once :class:`~grfguard.detect.system.AccVibrationDetector` latches, its
  outputs replace the main ones;
* between the sample's sensor side and its detector side (:func:`sys_keep`,
  :func:`sys_resume`; the batch loop runs the sensor side of several samples first): the
  layer's values the detector side reads are kept with the sample; once the vibration
  switch is on, the corner threshold is widened (and the fits settle again when it
  switches);
* before the detector (:func:`sys_pre_detect`): the load-cell zeros
  (:class:`~grfguard.detect.system.SwingZeroLearner`) are removed from the readings, a
  fooled swing foot's load moved to the stance foot
  (:func:`~grfguard.detect.system.swing_load_to_stance`), the common-mode fit
  (:class:`~grfguard.detect.system.CommonModeMonitor`) corrects the virtual forces and the
  unarmed tests are held (:func:`~grfguard.detect.system.hold_unarmed_tests`, and with
  them the release of the standing layer's held flags,
  :func:`~grfguard.detect.system.hold_standing_release`);
* after the detector (:func:`sys_output`): ``model_mismatch`` and the numbers of its
  reason (:data:`OUT_COLUMNS`; :func:`reason_text` builds the text).

Parameters ``sysp`` (:data:`N_SYSP`, :func:`system_params`; ``sysp[0] = 0``: layer off) and
state ``syss`` (:data:`N_SYSS`). ``tests/test_kernels_system.py`` checks the compiled
monitor against the Python stages.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from grfguard.kernels._jit import njit_nort as njit
from grfguard.kernels._jit import view1d
from grfguard.kernels.detect import CN, CP, FLAG, G_GNEG, G_GPOS, P_CORSIG, SWN, SWP, _fsum
from grfguard.kernels.fk import fk_sites
from grfguard.kernels.standing import _STAGE as SD_STAGE
from grfguard.kernels.standing import _det_reset, sort8
from grfguard.kernels.vfs import (
    _NJ,
    _S_ANCHOR,
    _S_HN,
    _S_N,
    _S_PREVF,
    _S_PREVL_OK,
    _kinematics,
    _scratch_views,
    _unpack,
    resolve_pending,
    same_front_state,
    vfs_step,
    vfs_step_shared,
)
from grfguard.model.robot import SENSOR_NAMES

__all__ = ["N_SYSP", "N_SYSS", "OUT_COLUMNS", "system_params", "system_reset",
           "sys_pre_vfs", "sys_twin_prepare", "sys_twin", "sys_keep", "sys_resume",
           "sys_pre_detect", "sys_output", "reason_text"]

# ------------------------------------------------------------------ parameters (sysp)
(Y_ON, Y_DT, Y_W) = range(3)
Y_XL, Y_YL = 3, 11
(Y_CM_LAM, Y_CM_WARM, Y_CM_MASS, Y_CM_COP, Y_CM_MAXR, Y_CM_MAXC, Y_CM_MINLOAD, Y_CM_OUTN,
 Y_CM_OUTR, Y_CM_SSO) = range(19, 29)
Y_Z_SETTLE, Y_Z_MAXN, Y_Z_APPLY, Y_Z_LIMIT, Y_Z_DEAD, Y_Z_SWFRAC = range(29, 35)
Y_G_ON, Y_G_LEARN, Y_G_APPLY, Y_G_STILL, Y_G_DEAD = range(35, 40)
Y_T_ON, Y_T_LEARN, Y_T_APPLY, Y_T_DEAD, Y_T_EVERY = range(40, 45)
Y_V_ON, Y_V_B0, Y_V_B1, Y_V_B2, Y_V_A1, Y_V_A2, Y_V_LAM, Y_V_LIMIT, Y_V_START = range(45, 54)
Y_CORSIG, Y_CORSIG_Q = 54, 55
Y_I_GYRO, Y_I_CREF, Y_I_ZMP, Y_I_Q, Y_I_QUAT, Y_I_ACC = range(56, 62)
Y_SHARE = 62  # 1: the twin may take the main sensor's front of the step (twin_shareable)
Y_Z_AIR = 63  # SwingZeroLearner.air_n [N]
N_SYSP = 64
# ------------------------------------------------------------------ state (syss)
S_M11, S_M12, S_M22, S_B1, S_B2 = range(5)
S_TH, S_SUMR, S_SUMV, S_SRF, S_SVF, S_MVF, S_AF, S_LOADED, S_ARMED = 5, 8, 9, 10, 12, 14, 18, 20, 21
S_ZSUM, S_ZN, S_SWS, S_FOOTN = 22, 30, 38, 40
S_GSUM, S_GN, S_GZP, S_GSTILL = 42, 45, 46, 48
S_TZ, S_TN, S_TK, S_TC, S_TSET, S_TNOW, S_TSEEN, S_TSETTLE = 49, 52, 53, 54, 63, 64, 66, 68
S_VZ, S_VMS, S_VT, S_VON, S_VRMS = 69, 73, 74, 75, 76
S_BIAS = 77
S_CMCODE, S_RATIO, S_RF, S_SX, S_SY = 80, 81, 82, 84, 85
S_RES, S_PHI, S_USE, S_OK, S_E, S_PART, S_CORR, S_ZERO = 86, 94, 118, 126, 134, 142, 158, 166
# the twin's front state is a copy of the main's (a shared step, then the two sensors'
# output counters at that time; sys_twin_prepare then skips the comparison)
S_SYNC, S_SYNC_N, S_SYNC_QN = 174, 175, 176
N_SYSS = 180
#: Codes of the common-mode reason (bits of ``mm_code``).
CM_TOTAL, CM_TOTAL_FEET, CM_COP = 1, 2, 4

#: Output columns of the layer (appended after ``system_state``).
OUT_COLUMNS: tuple[str, ...] = (
    "model_mismatch", "mm_code", "mm_ratio", "mm_ratio_r", "mm_ratio_l", "mm_cop_shift_x",
    "mm_cop_shift_y", "mm_gyro_bias_x", "mm_gyro_bias_y", "mm_gyro_bias_z", "mm_vibration",
    "mm_vibration_rms", "mm_tilt_roll", "mm_tilt_pitch", *(f"mm_zero_{s}" for s in SENSOR_NAMES),
)
N_OUT = len(OUT_COLUMNS)


def system_params(mon: Any, in_cols: tuple[str, ...], has_gyro: bool = True) -> np.ndarray:
    """``sysp`` from a :class:`~grfguard.pipeline.Monitor` with ``common_mode`` on (zeros:
    off) and the kernel's input layout (``has_gyro``: the log carries the gyro)."""
    p = np.zeros(N_SYSP)
    cm = mon.common
    if cm is None:
        return p
    from grfguard.io.schema import CONTACT_REF, IMU_ACC, IMU_GYRO, IMU_QUAT, JOINT_COLUMNS, ZMP_REF

    c = cm.config
    dt = mon.config.dt_s
    p[Y_ON], p[Y_DT], p[Y_W] = 1.0, dt, mon.robot.weight
    p[Y_XL:Y_XL + 8] = cm._xl
    p[Y_YL:Y_YL + 8] = cm._yl
    p[Y_CM_LAM] = math.exp(-cm.dt_s / c.time_constant_s)
    p[Y_CM_WARM], p[Y_CM_MASS], p[Y_CM_COP] = c.warmup_s, c.mass_ratio_limit, c.cop_shift_limit_m
    p[Y_CM_MAXR], p[Y_CM_MAXC] = c.max_ratio, c.max_cop_shift_m
    p[Y_CM_MINLOAD], p[Y_CM_OUTN], p[Y_CM_OUTR] = c.min_load_fraction, cm.outlier_n, c.outlier_ratio
    p[Y_CM_SSO] = float(c.single_support_only)
    z = mon.zeros.config
    p[Y_Z_SETTLE], p[Y_Z_APPLY] = z.settle_s, z.apply_after_s
    p[Y_Z_MAXN] = z.learn_s / mon.zeros.dt_s
    p[Y_Z_LIMIT], p[Y_Z_DEAD] = mon.zeros.limit_n, mon.zeros.deadband_n
    p[Y_Z_SWFRAC] = z.swing_load_fraction
    p[Y_Z_AIR] = mon.zeros.air_n
    g = mon.gyro_bias.config

    def idx(col: str) -> float:
        return float(in_cols.index(col)) if col in in_cols else -1.0

    p[Y_G_ON] = 1.0 if has_gyro and all(cc in in_cols for cc in IMU_GYRO) else 0.0
    p[Y_G_LEARN], p[Y_G_APPLY], p[Y_G_STILL], p[Y_G_DEAD] = (
        g.learn_s, g.apply_after_s, g.still_rad_s, g.deadband_rad_s)
    t = mon.tilt
    if t is not None:
        p[Y_T_ON] = 1.0
        p[Y_T_LEARN], p[Y_T_APPLY], p[Y_T_DEAD] = t.learn_s, t.apply_after_s, t.deadband_deg
        p[Y_T_EVERY] = t.every_n
    v = mon.vibration
    p[Y_CORSIG] = mon.config.thresholds.corner_sigma
    p[Y_CORSIG_Q] = p[Y_CORSIG]
    if v is not None:
        p[Y_V_ON] = 1.0
        p[Y_V_B0], p[Y_V_B1], p[Y_V_B2] = v._b
        p[Y_V_A1], p[Y_V_A2] = v._a[1], v._a[2]
        p[Y_V_LAM], p[Y_V_LIMIT], p[Y_V_START] = v._lam, v.config.limit_m_s2, v.config.start_s
        p[Y_CORSIG_Q] = mon._quiet_config.thresholds.corner_sigma
    p[Y_I_GYRO], p[Y_I_CREF], p[Y_I_ZMP] = idx(IMU_GYRO[0]), idx(CONTACT_REF[0]), idx(ZMP_REF[0])
    p[Y_I_Q], p[Y_I_QUAT], p[Y_I_ACC] = idx(JOINT_COLUMNS[0]), idx(IMU_QUAT[0]), idx(IMU_ACC[0])
    return p


# ------------------------------------------------------------------ reset
@njit(inline="always")
def _cm_reset(ys):
    """``CommonModeMonitor.reset``."""
    for k in range(S_ZSUM):
        ys[k] = 0.0


@njit
def system_reset(yp, ys, prm, qstate):
    """A new monitor's layer state; the twin virtual sensor reset, the corner threshold
    back to its own value."""
    for k in range(N_SYSS):
        ys[k] = 0.0
    ys[S_GZP] = math.nan
    ys[S_GZP + 1] = math.nan
    for k in range(9):
        ys[S_TC + k] = 0.0
    ys[S_TC] = ys[S_TC + 4] = ys[S_TC + 8] = 1.0
    if yp[Y_ON] != 0.0:
        prm[P_CORSIG] = yp[Y_CORSIG]
    _vfs_reset(qstate)


@njit
def _vfs_reset(state):
    """``VFSKernel.reset`` (nothing for the one-float placeholder of a monitor without a
    twin sensor: the anchor's slot would lie past its end)."""
    for k in range(state.shape[0]):
        state[k] = 0.0
    if state.shape[0] > _S_ANCHOR:
        state[_S_ANCHOR] = -1.0


# ------------------------------------------------------------------ before the VFS
@njit(inline="always")
def _gyro_bias(yp, ys, xc):
    """``GyroBiasLearner.update``: learns, writes the bias applied now to ``ys[S_BIAS:]``."""
    ig = int(yp[Y_I_GYRO])
    ir = int(yp[Y_I_CREF])
    iz = int(yp[Y_I_ZMP])
    z0 = xc[iz] if iz >= 0 else math.nan
    z1 = xc[iz + 1] if iz >= 0 else math.nan
    p0 = ys[S_GZP]
    p1 = ys[S_GZP + 1]
    rest = not ((math.isfinite(z0) and math.isfinite(p0) and abs(z0 - p0) > 1e-6)
                or (math.isfinite(z1) and math.isfinite(p1) and abs(z1 - p1) > 1e-6))
    ys[S_GZP] = z0
    ys[S_GZP + 1] = z1
    c0 = xc[ir] if ir >= 0 else math.nan
    c1 = xc[ir + 1] if ir >= 0 else math.nan
    still = rest and math.isfinite(c0) and c0 > 0.5 and math.isfinite(c1) and c1 > 0.5
    for j in range(3):
        q = xc[ig + j]
        still = still and math.isfinite(q) and abs(q) < yp[Y_G_STILL]
    ys[S_GSTILL] = 1.0 if still else 0.0
    dt = yp[Y_DT]
    if still and ys[S_GN] * dt < yp[Y_G_LEARN]:
        for j in range(3):
            ys[S_GSUM + j] = ys[S_GSUM + j] + xc[ig + j]
        ys[S_GN] += 1.0
    n = ys[S_GN]
    for j in range(3):
        ys[S_BIAS + j] = 0.0
    if n == 0.0 or n * dt < yp[Y_G_APPLY]:
        return
    big = 0.0
    for j in range(3):
        big = max(big, abs(ys[S_GSUM + j] / n))
    if big <= yp[Y_G_DEAD]:
        return
    for j in range(3):
        ys[S_BIAS + j] = ys[S_GSUM + j] / n


@njit(inline="always")
def _tilt_solve(ys):
    """``ImuTiltLearner._solve`` into ``ys[S_TC:]`` (False: within the deadband)."""
    a, b, c = ys[S_TZ], ys[S_TZ + 1], ys[S_TZ + 2]
    nrm = math.sqrt(a * a + b * b + c * c)
    z0, z1, z2 = a / nrm, b / nrm, c / nrm
    ang = math.acos(min(max(z2, -1.0), 1.0))
    return ang, z0, z1


@njit(inline="always")
def _tilt(yp, ys, xc, dt, cf, ci, vws, viws):
    """``ImuTiltLearner.update`` (the sole normals from the compiled forward kinematics)."""
    every = yp[Y_T_EVERY]
    if not (ys[S_GSTILL] != 0.0 and ys[S_TN] * every * dt < yp[Y_T_LEARN]):
        return
    ys[S_TK] += 1.0
    if ys[S_TK] % every != 0.0:
        return
    iq = int(yp[Y_I_Q])
    iw = int(yp[Y_I_QUAT])
    for j in range(_NJ):
        if not math.isfinite(xc[iq + j]):
            return
    for j in range(4):
        if not math.isfinite(xc[iw + j]):
            return
    x = xc[iq:iq + 24]
    prm, iprm, body_inertia, corner_radius, filt_b, filt_a, filt_zi, tree, sites = _unpack(cf, ci)
    nb = tree[0].shape[0]
    nq = tree[13].shape[0]
    (qpos, xpos, xquat, xmat, xipos, ximat, stc, msub, sxp, sxm, qin, raw, main, v3a, v3b,
     v3c, v3d, pk, tmp8, prior8, rel8, forces, lin, cc, qp_x, qp_z, qp_M, qp_rhs, qp_dots,
     tail) = _scratch_views(vws, nq, nb)
    _kinematics(x, prm, iprm, tree, sites, corner_radius, xc[iw], xc[iw + 1], xc[iw + 2],
                xc[iw + 3], qpos, xpos, xquat, xmat, xipos, ximat, stc, msub, sxp, sxm, qin,
                pk, tail, view1d(viws, 32, 11))
    # the sole axes (the sensor's kinematics compute them only for the paper stages)
    site_body, site_sameframe, site_pos, site_quat = sites
    fk_sites(view1d(viws, 32, 11), site_body, site_sameframe, site_pos, site_quat, xpos, xquat,
             xmat, xipos, ximat, sxp, sxm, tail)
    zs0 = (sxm[9, 2] + sxm[10, 2]) / 2.0
    zs1 = (sxm[9, 5] + sxm[10, 5]) / 2.0
    zs2 = (sxm[9, 8] + sxm[10, 8]) / 2.0
    if not (math.isfinite(zs0) and math.isfinite(zs1) and math.isfinite(zs2)):
        return
    ys[S_TZ] += zs0
    ys[S_TZ + 1] += zs1
    ys[S_TZ + 2] += zs2
    ys[S_TN] += 1.0
    if ys[S_TN] * every * dt < yp[Y_T_APPLY]:
        return
    ang, z0, z1 = _tilt_solve(ys)
    if math.degrees(ang) <= yp[Y_T_DEAD]:
        return
    # axis = e_z x z, normalised; R = I + sin K + (1 - cos) K K
    a0, a1 = -z1, z0
    na = math.sqrt(a0 * a0 + a1 * a1)
    a0, a1 = a0 / na, a1 / na
    s, c1 = math.sin(ang), 1.0 - math.cos(ang)
    # K = [[0, 0, a1], [0, 0, -a0], [-a1, a0, 0]]; K K = [[-a1^2, a0 a1, 0],
    # [a0 a1, -a0^2, 0], [0, 0, -(a0^2 + a1^2)]]
    C = ys[S_TC:S_TC + 9]
    C[0] = 1.0 + c1 * (-a1 * a1)
    C[1] = c1 * (a0 * a1)
    C[2] = s * a1
    C[3] = c1 * (a0 * a1)
    C[4] = 1.0 + c1 * (-a0 * a0)
    C[5] = s * (-a0)
    C[6] = s * (-a1)
    C[7] = s * a0
    C[8] = 1.0 + c1 * (-(a0 * a0 + a1 * a1))
    ys[S_TSET] = 1.0


@njit(inline="always")
def _rotate_imu(yp, ys, xc):
    """``pipeline._rotate_imu``: the IMU readings in the described IMU frame."""
    C = ys[S_TC:S_TC + 9]
    iw = int(yp[Y_I_QUAT])
    w, x, y, z = xc[iw], xc[iw + 1], xc[iw + 2], xc[iw + 3]
    if math.isfinite(w) and math.isfinite(x) and math.isfinite(y) and math.isfinite(z):
        n = math.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / n, x / n, y / n, z / n
        r00 = 1 - 2 * (y * y + z * z)
        r01 = 2 * (x * y - w * z)
        r02 = 2 * (x * z + w * y)
        r10 = 2 * (x * y + w * z)
        r11 = 1 - 2 * (x * x + z * z)
        r12 = 2 * (y * z - w * x)
        r20 = 2 * (x * z - w * y)
        r21 = 2 * (y * z + w * x)
        r22 = 1 - 2 * (x * x + y * y)
        # M = R C^T
        m00 = r00 * C[0] + r01 * C[1] + r02 * C[2]
        m01 = r00 * C[3] + r01 * C[4] + r02 * C[5]
        m02 = r00 * C[6] + r01 * C[7] + r02 * C[8]
        m10 = r10 * C[0] + r11 * C[1] + r12 * C[2]
        m11 = r10 * C[3] + r11 * C[4] + r12 * C[5]
        m12 = r10 * C[6] + r11 * C[7] + r12 * C[8]
        m20 = r20 * C[0] + r21 * C[1] + r22 * C[2]
        m21 = r20 * C[3] + r21 * C[4] + r22 * C[5]
        m22 = r20 * C[6] + r21 * C[7] + r22 * C[8]
        qw = 0.5 * math.sqrt(max(0.0, 1 + m00 + m11 + m22))
        qx = math.copysign(0.5 * math.sqrt(max(0.0, 1 + m00 - m11 - m22)), m21 - m12)
        qy = math.copysign(0.5 * math.sqrt(max(0.0, 1 - m00 + m11 - m22)), m02 - m20)
        qz = math.copysign(0.5 * math.sqrt(max(0.0, 1 - m00 - m11 + m22)), m10 - m01)
        n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        sg = -1.0 if qw / n < 0 else 1.0
        xc[iw] = qw / n * sg
        xc[iw + 1] = qx / n * sg
        xc[iw + 2] = qy / n * sg
        xc[iw + 3] = qz / n * sg
    for base in (int(yp[Y_I_ACC]), int(yp[Y_I_GYRO])):
        a0, a1, a2 = xc[base], xc[base + 1], xc[base + 2]
        xc[base] = C[0] * a0 + C[1] * a1 + C[2] * a2
        xc[base + 1] = C[3] * a0 + C[4] * a1 + C[5] * a2
        xc[base + 2] = C[6] * a0 + C[7] * a1 + C[8] * a2


@njit(inline="always")
def sys_pre_vfs(yp, ys, xc, cf, ci, vws, viws):
    """Gyro bias and IMU tilt learned and removed from the cleaned row ``xc`` (in place;
    ``Monitor._unbias_row``)."""
    for j in range(3):
        ys[S_BIAS + j] = 0.0
    if yp[Y_G_ON] == 0.0:
        return
    _gyro_bias(yp, ys, xc)
    ig = int(yp[Y_I_GYRO])
    for j in range(3):
        if ys[S_BIAS + j] != 0.0:
            xc[ig + j] = xc[ig + j] - ys[S_BIAS + j]
    if yp[Y_T_ON] == 0.0:
        return
    _tilt(yp, ys, xc, yp[Y_DT], cf, ci, vws, viws)
    if ys[S_TSET] != 0.0:
        a, b, c = ys[S_TZ], ys[S_TZ + 1], ys[S_TZ + 2]
        nrm = math.sqrt(a * a + b * b + c * c)
        ys[S_TNOW] = math.degrees(-(b / nrm))
        ys[S_TNOW + 1] = math.degrees(a / nrm)
        _rotate_imu(yp, ys, xc)
    else:
        ys[S_TNOW] = 0.0
        ys[S_TNOW + 1] = 0.0


# ------------------------------------------------------------------ vibration, twin VFS
@njit(inline="always")
def _vibration(yp, ys, ax, ay):
    """``AccVibrationDetector.update``; returns ``(on, switched on at this sample)``
    (the switch's effect on the fits, ``Monitor._vibration_on``, is the detector side's:
    :func:`sys_resume`)."""
    if ys[S_VON] != 0.0:
        return True, False
    if not (math.isfinite(ax) and math.isfinite(ay)):
        return False, False
    b0, b1, b2, a1, a2 = yp[Y_V_B0], yp[Y_V_B1], yp[Y_V_B2], yp[Y_V_A1], yp[Y_V_A2]
    e = 0.0
    for j in range(2):
        u = ax if j == 0 else ay
        z0 = ys[S_VZ + 2 * j]
        z1 = ys[S_VZ + 2 * j + 1]
        y = b0 * u + z0
        ys[S_VZ + 2 * j] = b1 * u - a1 * y + z1
        ys[S_VZ + 2 * j + 1] = b2 * u - a2 * y
        e += y * y
    lam = yp[Y_V_LAM]
    ys[S_VMS] = lam * ys[S_VMS] + (1.0 - lam) * e
    ys[S_VT] += yp[Y_DT]
    ys[S_VRMS] = math.sqrt(ys[S_VMS])
    if ys[S_VT] >= yp[Y_V_START] and ys[S_VRMS] > yp[Y_V_LIMIT]:
        ys[S_VON] = 1.0
        return True, True
    return False, False


@njit(inline="always")
def sys_twin_prepare(yp, ys, reset, vstate, qstate, ci):
    """Before the main sensor's step (after its resync): the twin resynced at a break as
    the main (finite differences only: it keeps its filters, attitude, odometry and last
    output, ``VFSKernel.resync``); True when the twin may take the main's front of the
    step this sample (layer on, ``Y_SHARE``, and the twin's front state equal to the
    main's). After a shared step the twin's front state is a copy of the main's: while
    neither sensor's output counter moved since (no step outside this monitor), the
    comparison is skipped (both resyncs above set the same values)."""
    if yp[Y_V_ON] == 0.0:
        return False
    if reset:
        qstate[_S_HN] = 0.0
        qstate[_S_PREVF] = 0.0
        qstate[_S_PREVL_OK] = 0.0
    if yp[Y_SHARE] == 0.0:
        return False
    if (ys[S_SYNC] != 0.0 and vstate[_S_N] == ys[S_SYNC_N]
            and qstate[_S_N] == ys[S_SYNC_QN]):
        return True
    return same_front_state(vstate, qstate, ci)


@njit(inline="always")
def sys_twin(yp, ys, xc, share, valid, vy, qy, qstate, qcf, qci, qws, qiws, vstate, vws, v,
             tot, cest, o_tot, o_cest, o_valid):
    """The twin virtual sensor without the accelerometer (reset at a break by
    :func:`sys_twin_prepare`; with ``share`` and a valid main sample it takes the main's
    front of the step, state ``vstate`` / scratch ``vws``), the vibration switch; once on,
    the twin's outputs replace ``vy``, ``v``, ``tot``, ``cest`` (before that the twin's
    outputs are not computed, only its filters run; the corner threshold is widened by
    :func:`sys_resume`).
    Returns the sample's ``(valid, on, switched on now)``; the last two go to
    :func:`sys_resume` (the detector's side of the switch)."""
    if yp[Y_V_ON] == 0.0:
        return valid, False, False
    ia = int(yp[Y_I_ACC])
    on, now = _vibration(yp, ys, xc[ia], xc[ia + 1])  # (reads neither sensor)
    if share and valid:  # the twin's outputs computed only when used
        vfs_step_shared(xc[9:9 + 24], qy, qstate, qcf, qci, qws, qiws, vstate, vws, on)
        ys[S_SYNC] = 1.0
        ys[S_SYNC_N] = vstate[_S_N]
        ys[S_SYNC_QN] = qstate[_S_N]
    else:
        ys[S_SYNC] = 0.0
        resolve_pending(qy, qstate, qcf, qci, qws, qiws)
        vfs_step(xc[9:9 + 24], qy, qstate, qcf, qci, qws, qiws)
    if not on:
        return valid, False, False
    for j in range(qy.shape[0]):
        vy[j] = qy[j]
    for i in range(8):
        v[i] = qy[i]
    for f in range(2):
        tot[f] = qy[o_tot + f]
        cest[f] = qy[o_cest + f]
    return qy[o_valid] == 1.0, True, now


#: Floats of :func:`sys_keep`: what the sensor side of a sample leaves in the layer's
#: state for its detector side (tilt now, gyro bias, vibration on and RMS).
N_KEEP = 7


@njit(inline="always")
def sys_keep(ys, r):
    """After the sensor side of a sample (:func:`sys_pre_vfs`, :func:`sys_twin`): the
    state its detector side reads (:func:`sys_pre_detect`, :func:`sys_output`) into
    ``r`` (:data:`N_KEEP` floats), so that the sensor side of later samples may run
    before it (the batch loop's two passes)."""
    r[0] = ys[S_TNOW]
    r[1] = ys[S_TNOW + 1]
    for j in range(3):
        r[2 + j] = ys[S_BIAS + j]
    r[5] = ys[S_VON]
    r[6] = ys[S_VRMS]


@njit(inline="always")
def sys_resume(yp, ys, prm, r, on, now):
    """Before the detector side of a sample: the state :func:`sys_keep` kept back, and
    the vibration switch's effect on the detector (``on``: the corner threshold widened;
    ``now``, switched on at this sample: the fits settle again,
    ``Monitor._vibration_on``). Only the detector side writes these."""
    ys[S_TNOW] = r[0]
    ys[S_TNOW + 1] = r[1]
    for j in range(3):
        ys[S_BIAS + j] = r[2 + j]
    ys[S_VON] = r[5]
    ys[S_VRMS] = r[6]
    if now:
        ys[S_TSETTLE] = 1.0
    if on:
        prm[P_CORSIG] = yp[Y_CORSIG_Q]


# ------------------------------------------------------------------ before the detector
@njit(inline="always")
def _zeros_update(yp, ys, ss, x, tot, cref, cest):
    """``SwingZeroLearner.update``; the zeros applied now into ``ys[S_ZERO:]``."""
    dt = yp[Y_DT]
    max_n = yp[Y_Z_MAXN]
    for f in range(2):
        load = tot[f]
        contact = (cref[f] > 0.5) or (cest[f] > 0.5)
        swing = (not contact) and math.isfinite(load) and (load < yp[Y_Z_SWFRAC] * yp[Y_W])
        ys[S_SWS + f] = ys[S_SWS + f] + dt if swing else 0.0
        if ys[S_SWS + f] <= yp[Y_Z_SETTLE]:
            continue
        ys[S_FOOTN + f] += 1.0
        # SwingZeroLearner._in_air: the readings less the zeros so far sum to ~0
        s = 0.0
        for i in range(4 * f, 4 * f + 4):
            if math.isfinite(x[i]) and ss[i, FLAG] == 0.0:
                n = ys[S_ZN + i]
                s += x[i] - (ys[S_ZSUM + i] / n if n > 0 else 0.0)
        if not abs(s) <= yp[Y_Z_AIR]:
            continue
        for i in range(4 * f, 4 * f + 4):
            m = x[i]
            n = ys[S_ZN + i]
            if ss[i, FLAG] != 0.0 or not math.isfinite(m) or n >= max_n:
                continue
            if abs((ys[S_ZSUM + i] + m) / (n + 1)) > yp[Y_Z_LIMIT]:
                continue
            ys[S_ZSUM + i] += m
            ys[S_ZN + i] = n + 1
    for i in range(8):
        n = ys[S_ZN + i]
        z = ys[S_ZSUM + i] / n if n > 0 else 0.0
        ready = n * dt >= yp[Y_Z_APPLY]
        ys[S_ZERO + i] = z if (ready and abs(z) > yp[Y_Z_DEAD] and abs(z) <= yp[Y_Z_LIMIT]) else 0.0


@njit(inline="always")
def _swing_to_stance(x, v, tot, cref, weight, part):
    """``swing_load_to_stance`` (in place)."""
    if not (math.isfinite(cref[0]) and math.isfinite(cref[1])):
        return
    p0 = cref[0] > 0.5
    p1 = cref[1] > 0.5
    if p0 == p1:
        return
    st, sw = (0, 1) if p0 else (1, 0)
    other, mine = tot[sw], tot[st]
    if not (math.isfinite(other) and math.isfinite(mine)) or other <= 0.0 or mine <= 0.0:
        return
    for i in range(4):
        if not math.isfinite(x[4 * sw + i]):
            return
        part[8 + i] = x[4 * sw + i]
    if abs(_fsum(part[8:12], 4, part)) > 0.05 * weight:
        return
    k = (mine + other) / mine
    for i in range(4 * st, 4 * st + 4):
        v[i] *= k
    for i in range(4 * sw, 4 * sw + 4):
        v[i] = 0.0
    tot[st] = mine + other
    tot[sw] = 0.0


@njit(inline="always")
def _median(e, use, tmp):
    """``np.median`` of ``e`` where ``use`` (at least one; the values not NaN): the used
    values sorted in ``tmp`` (:func:`~grfguard.kernels.standing.sort8`, the others +inf
    behind them)."""
    n = 0
    for i in range(8):
        u = use[i] != 0.0
        tmp[i] = e[i] if u else math.inf
        n += 1 if u else 0
    sort8(tmp)
    if n % 2 == 1:
        return tmp[n // 2]
    return (tmp[n // 2 - 1] + tmp[n // 2]) / 2.0


@njit(inline="always")
def _cm_update(yp, ys, m, v, valid0, valid1, frozen, planned, part):
    """``CommonModeMonitor.update`` (its result in ``ys[S_CMCODE:]`` and
    ``ys[S_CORR:]``)."""
    res, phi, use, ok, e = (ys[S_RES:S_RES + 8], ys[S_PHI:S_PHI + 24], ys[S_USE:S_USE + 8],
                            ys[S_OK:S_OK + 8], ys[S_E:S_E + 8])
    # _select
    for i in range(8):
        ok[i] = 1.0 if (math.isfinite(m[i]) and math.isfinite(v[i])) else 0.0
    loads = (0.0, 0.0)
    l0 = l1 = 0.0
    for f in range(2):
        n = 0
        for i in range(4 * f, 4 * f + 4):
            if math.isfinite(v[i]):
                part[8 + n] = v[i]
                n += 1
        s = _fsum(part[8:8 + n], n, part) if n > 0 else 0.0
        if f == 0:
            l0 = s
        else:
            l1 = s
    loads = (l0, l1)
    lim = yp[Y_CM_MINLOAD] * yp[Y_W]
    f0 = valid0 and l0 > lim
    f1 = valid1 and l1 > lim
    sso = yp[Y_CM_SSO] != 0.0
    if sso and f0 and f1:
        f0 = f1 = False
    if sso and not (math.isfinite(planned[0]) and math.isfinite(planned[1])
                    and (planned[0] > 0.5) != (planned[1] > 0.5)):
        f0 = f1 = False
    nuse = 0
    for i in range(8):
        ft = f0 if i < 4 else f1
        use[i] = 1.0 if (ft and ok[i] != 0.0) else 0.0
        nuse += 1 if use[i] != 0.0 else 0
    if nuse > 0:
        ys[S_ARMED] += yp[Y_DT]
    for i in range(8):
        ld = loads[i // 4]
        phi[3 * i] = v[i] if ok[i] != 0.0 else 0.0
        phi[3 * i + 1] = ld * yp[Y_XL + i]
        phi[3 * i + 2] = ld * yp[Y_YL + i]
        res[i] = m[i] - v[i]
    # _drop_outlier (only the fit reads ``use`` after it: nothing to drop while frozen)
    if nuse >= 3 and not frozen:
        b0, c0 = ys[S_TH + 1], ys[S_TH + 2]
        worst = -1
        ew = 0.0
        for i in range(8):
            if use[i] != 0.0:
                e[i] = abs(res[i] - (ys[S_AF + i // 4] * phi[3 * i] + b0 * phi[3 * i + 1]
                                     + c0 * phi[3 * i + 2]))
                take = (worst < 0) | (e[i] > ew)  # selects: no branch on the residuals
                worst = i if take else worst
                ew = e[i] if take else ew
        med = _median(e, use, part)
        if e[worst] > max(yp[Y_CM_OUTN], yp[Y_CM_OUTR] * med):
            use[worst] = 0.0
            nuse -= 1
    if nuse > 0 and not frozen:
        _cm_learn(yp, ys, res, phi, use)
    _cm_result(yp, ys, v, ok, phi)


@njit(inline="always")
def _cm_learn(yp, ys, res, phi, use):
    """``CommonModeMonitor._learn``."""
    lam = yp[Y_CM_LAM]
    for k in (S_M11, S_M12, S_M22, S_B1, S_B2):
        ys[k] *= lam
    sr = 0.0
    sv = 0.0
    for f in range(2):
        ys[S_SRF + f] *= lam
        ys[S_SVF + f] *= lam
        ys[S_MVF + 2 * f] *= lam
        ys[S_MVF + 2 * f + 1] *= lam
    for i in range(8):
        if use[i] != 0.0:
            p0, p1, p2 = phi[3 * i], phi[3 * i + 1], phi[3 * i + 2]
            r = res[i]
            ys[S_M11] += p1 * p1
            ys[S_M12] += p1 * p2
            ys[S_M22] += p2 * p2
            ys[S_B1] += p1 * r
            ys[S_B2] += p2 * r
            sr += r
            sv += p0
            f = i // 4
            ys[S_SRF + f] += r
            ys[S_SVF + f] += p0
            ys[S_MVF + 2 * f] += p0 * p1
            ys[S_MVF + 2 * f + 1] += p0 * p2
    ys[S_SUMR] = lam * ys[S_SUMR] + sr
    ys[S_SUMV] = lam * ys[S_SUMV] + sv
    ys[S_LOADED] += yp[Y_DT]
    alpha = ys[S_SUMR] / ys[S_SUMV] if ys[S_SUMV] > 0 else 0.0
    sv_min = 0.1 * ys[S_SUMV]
    for f in range(2):
        ys[S_AF + f] = ys[S_SRF + f] / ys[S_SVF + f] if ys[S_SVF + f] > sv_min else alpha
    a0, a1 = ys[S_AF], ys[S_AF + 1]
    reg = 1e-6 * (ys[S_M11] + ys[S_M22] + 1e-9)
    m11, m12, m22 = ys[S_M11] + reg, ys[S_M12], ys[S_M22] + reg
    r1 = ys[S_B1] - a0 * ys[S_MVF] - a1 * ys[S_MVF + 2]
    r2 = ys[S_B2] - a0 * ys[S_MVF + 1] - a1 * ys[S_MVF + 3]
    det = m11 * m22 - m12 * m12
    if det > 0 and math.isfinite(det):
        ys[S_TH] = alpha
        ys[S_TH + 1] = (m22 * r1 - m12 * r2) / det
        ys[S_TH + 2] = (m11 * r2 - m12 * r1) / det


@njit(inline="always")
def _clip(q, lim):
    return min(max(q, -lim), lim)


@njit(inline="always")
def _cm_result(yp, ys, v, ok, phi):
    """``CommonModeMonitor._result``: code, ratios, CoP shift, correction."""
    warm = ys[S_LOADED] >= yp[Y_CM_WARM]
    mr, mc = yp[Y_CM_MAXR], yp[Y_CM_MAXC]
    th0 = ys[S_TH] if warm else 0.0
    th1 = ys[S_TH + 1] if warm else 0.0
    th2 = ys[S_TH + 2] if warm else 0.0
    ratio = _clip(th0, mr)
    rf0 = _clip(ys[S_AF], mr) if warm else 0.0
    rf1 = _clip(ys[S_AF + 1], mr) if warm else 0.0
    sx = _clip(th1, mc)
    sy = _clip(th2, mc)
    code = 0
    if warm:
        if max(abs(rf0), abs(rf1)) > yp[Y_CM_MASS]:
            code |= CM_TOTAL_FEET if abs(rf0 - rf1) > yp[Y_CM_MASS] else CM_TOTAL
        if math.hypot(sx, sy) > yp[Y_CM_COP]:
            code |= CM_COP
    ys[S_CMCODE] = code
    ys[S_RATIO] = ratio
    ys[S_RF] = rf0
    ys[S_RF + 1] = rf1
    ys[S_SX] = sx
    ys[S_SY] = sy
    for i in range(8):
        c = 0.0
        if code != 0:
            rf = rf0 if i < 4 else rf1
            c = ((rf * v[i] if ok[i] != 0.0 else 0.0) + phi[3 * i + 1] * sx
                 + phi[3 * i + 2] * sy)
            if not math.isfinite(c):
                c = 0.0
        ys[S_CORR + i] = c


@njit(inline="always")
def sys_pre_detect(yp, ys, ss, gs, x, v, tot, cref, cest, sd):
    """``Monitor._detect`` with ``common_mode`` up to the detector step: ``x`` (zeros
    removed), ``v`` and ``tot`` (moved and corrected) edited in place, the unarmed tests'
    sums held in ``ss`` / ``gs``."""
    part = ys[S_PART:S_PART + 14]
    allfin = True
    for i in range(8):
        allfin = allfin and math.isfinite(v[i])
    va0 = (cest[0] > 0.5) if math.isfinite(cest[0]) else (cref[0] > 0.5)
    va1 = (cest[1] > 0.5) if math.isfinite(cest[1]) else (cref[1] > 0.5)
    if not allfin:
        va0 = va1 = False
    frozen = False
    for i in range(8):
        frozen = frozen or ss[i, FLAG] != 0.0
    _zeros_update(yp, ys, ss, x, tot, cref, cest)
    for i in range(8):
        x[i] = x[i] - ys[S_ZERO + i]
    _swing_to_stance(x, v, tot, cref, yp[Y_W], part)
    if ys[S_TNOW] != ys[S_TSEEN] or ys[S_TNOW + 1] != ys[S_TSEEN + 1]:
        ys[S_TSEEN] = ys[S_TNOW]
        ys[S_TSEEN + 1] = ys[S_TNOW + 1]
        ys[S_TSETTLE] = 1.0
    if ys[S_TSETTLE] > 0.0:
        ys[S_TSETTLE] -= yp[Y_DT]
        _cm_reset(ys)
        _det_reset(sd)  # the standing detector's baseline too
    _cm_update(yp, ys, x, v, va0, va1, frozen, cref, part)
    if ys[S_CMCODE] != 0.0:
        for i in range(8):
            v[i] = v[i] + ys[S_CORR + i]
        for f in range(2):
            for i in range(4):
                part[8 + i] = ys[S_CORR + 4 * f + i]
            tot[f] = tot[f] + _fsum(part[8:12], 4, part)
    armed = ys[S_ARMED] >= yp[Y_CM_WARM]
    dt = yp[Y_DT]
    for f in range(2):
        za = ys[S_FOOTN + f] * dt >= yp[Y_Z_APPLY]
        stance = za and armed
        for i in range(4 * f, 4 * f + 4):
            if not za:
                ss[i, SWP] = 0.0
                ss[i, SWN] = 0.0
            if not stance:
                ss[i, CP] = 0.0
                ss[i, CN] = 0.0
        if not stance:
            gs[G_GPOS + f] = 0.0
            gs[G_GNEG + f] = 0.0
            for i in range(4 * f, 4 * f + 4):  # hold_standing_release
                sd[SD_STAGE + i] = 0.0


@njit(inline="always")
def sys_output(yp, ys, y, o):
    """``model_mismatch`` and the numbers of its reason into ``y[o:o + N_OUT]``."""
    any_zero = False
    for i in range(8):
        y[o + 14 + i] = ys[S_ZERO + i]
        any_zero = any_zero or ys[S_ZERO + i] != 0.0
    bias = ys[S_BIAS] != 0.0 or ys[S_BIAS + 1] != 0.0 or ys[S_BIAS + 2] != 0.0
    tilt = ys[S_TNOW] != 0.0 or ys[S_TNOW + 1] != 0.0
    vib = ys[S_VON] != 0.0
    mm = ys[S_CMCODE] != 0.0 or bias or tilt or vib or any_zero
    y[o] = 1.0 if mm else 0.0
    y[o + 1] = ys[S_CMCODE]
    y[o + 2] = ys[S_RATIO]
    y[o + 3] = ys[S_RF]
    y[o + 4] = ys[S_RF + 1]
    y[o + 5] = ys[S_SX]
    y[o + 6] = ys[S_SY]
    for j in range(3):
        y[o + 7 + j] = ys[S_BIAS + j]
    y[o + 10] = 1.0 if vib else 0.0
    y[o + 11] = ys[S_VRMS]
    y[o + 12] = ys[S_TNOW]
    y[o + 13] = ys[S_TNOW + 1]


# ------------------------------------------------------------------ reason text
def reason_text(row: Any, vib_cfg: Any = None) -> str:
    """``model_mismatch_reason`` of one output row (``row`` indexable by position
    relative to ``model_mismatch``; the same text as ``Monitor._detect``)."""
    if not row[0]:
        return ""
    reasons = []
    code = int(row[1])
    if code & (CM_TOTAL | CM_TOTAL_FEET):
        if code & CM_TOTAL_FEET:
            reasons.append(f"total force off by {100 * row[3]:+.1f} % (right), "
                           f"{100 * row[4]:+.1f} % (left)")
        else:
            reasons.append(f"total force off by {100 * row[2]:+.1f} %")
    if code & CM_COP:
        reasons.append(f"attitude/CoM inconsistent (CoP shifted {100 * row[5]:+.1f} cm x, "
                       f"{100 * row[6]:+.1f} cm y)")
    if row[7] != 0.0 or row[8] != 0.0 or row[9] != 0.0:
        reasons.append(f"gyro bias ({row[7]:+.3f}, {row[8]:+.3f}, {row[9]:+.3f}) rad/s removed")
    if row[10] and vib_cfg is not None:
        reasons.append(
            f"accelerometer vibration (RMS {row[11]:.1f} m/s^2 above "
            f"{vib_cfg.cutoff_hz:g} Hz): virtual sensor without it, corner "
            f"threshold x{vib_cfg.corner_sigma_scale:g}")
    if row[12] != 0.0 or row[13] != 0.0:
        reasons.append(f"IMU mounting tilt (roll {row[12]:+.1f}, pitch {row[13]:+.1f}) deg removed")
    zs = [float(q) for q in row[14:22]]
    if any(zs):
        reasons.append("load-cell zeros removed (" + ", ".join(
            f"{n} {q:+.0f} N" for n, q in zip(SENSOR_NAMES, zs, strict=True) if q != 0.0) + ")")
    return "; ".join(reasons)
