"""The virtual force sensor as one compiled step over plain arrays.

:func:`vfs_step` processes one sample: attitude filter, forward kinematics of the MuJoCo
tree (:mod:`grfguard.kernels.fk`; for a tree of hinges and the default sites, the poses
in base axes eight samples at a time, :mod:`grfguard.kernels.front`, rotated by the
attitude per sample), leg odometry, finite-difference rates with the
angular momentum, the Butterworth low-passes (direct form II transposed, as
``scipy.signal.lfilter``), Newton-Euler ZMP, kinematic corner contact, the
sole-compliance prior and the corner QP (:mod:`grfguard.kernels.nnls`), the per-foot
totals and CoPs. :func:`vfs_run` loops the same step over a log in one compiled call, so
streaming and batch are identical by construction. Both are what
:class:`grfguard.estimate.vfs.VirtualForceSensor` (``update`` / ``run``) runs; the numpy
stages they reproduce in the same operation order are ``tests/reference/vfs_stages.py``.

Settings: every :class:`VFSConfig`. The non-default stages (the paper's CoM filter and
split, the pendulum Kalman ZMP, the anchor attitude) are in
:mod:`grfguard.kernels.vfs_paper`, called from the hooks marked ``vfs_paper`` in
``_step``; the rigid QP (``contact_stiffness_per_kg = 0``) is the compliance QP with a
uniform prior.

Array layouts (one row per sample):

* input (:data:`IN_COLUMNS`, 24): ``q_<joint>`` x12 [rad] in ``JOINT_NAMES`` order,
  ``imu_quat_w/x/y/z``, ``imu_gyro_x/y/z`` [rad/s], ``imu_acc_x/y/z`` [m/s^2],
  ``contact_ref_r/l`` (0/1). Columns the log lacks are NaN and switched off by flags.
* output (:data:`OUT_COLUMNS`, 22): ``VFS_OUTPUT_COLUMNS`` of the pure-Python sensor
  (``vfs_r1..vfs_l4`` [N], ``com_est_x/y/z`` [m], ``vfs_total_r/l`` [N],
  ``vfs_cop_r_x/y``, ``vfs_cop_l_x/y`` [m], ``contact_est_r/l``, ``zmp_est_x/y`` [m],
  ``vfs_valid``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from grfguard.errors import LogFormatError
from grfguard.estimate.config import VFSConfig
from grfguard.io.schema import (
    CONTACT_REF,
    FORCE_COLUMNS,
    IMU_ACC,
    IMU_GYRO,
    IMU_QUAT,
    JOINT_COLUMNS,
    ZMP_REF,
)
from grfguard.kernels._jit import fma, njit_nort, view1d, view2d
from grfguard.kernels.fk import (
    TreeModel,
    _mv,
    _q2m,
    fk_bodies_kind,
    fk_site_pos,
    fk_sites,
    subtree_com_of,
)
from grfguard.kernels.front import (
    IW_SLOT,
    N_FRONT_ANGLES,
    front_block,
    front_constants,
    front_trunk,
    front_ws_size,
)
from grfguard.kernels.lanes import LANES
from grfguard.kernels.nnls import prior_qp_warm
from grfguard.kernels.vfs_paper import (  # the non-default settings' stages
    N_XSTATE,
    P_COM_PAPER,
    P_KANC,
    P_SPLIT_PAPER,
    P_ZMP_KF,
    anchor_init,
    anchor_odometry,
    extra_params,
    paper_com,
    paper_split,
    valid_paper_inputs,
    zmp_kalman,
)

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["IN_COLUMNS", "OUT_COLUMNS", "VFSKernel", "vfs_step", "vfs_run", "vfs_batch",
           "vfs_step_shared", "resolve_pending", "same_front_state",
           "twin_shareable"]

#: Input row layout of :func:`vfs_step`.
IN_COLUMNS: tuple[str, ...] = (*JOINT_COLUMNS, *IMU_QUAT, *IMU_GYRO, *IMU_ACC, *CONTACT_REF)
#: Input row layout with the paper's CoM filter: :data:`IN_COLUMNS`, the force sensors
#: ``force_r1..force_l4`` [N] and the planned ZMP ``zmp_ref_x/y`` [m] (NaN: not used).
PAPER_IN_COLUMNS: tuple[str, ...] = (*IN_COLUMNS, *FORCE_COLUMNS, *ZMP_REF)
#: Joints of the input row: the schema's ``JOINT_COLUMNS`` (the leg joints of grfguard's
#: MJCF naming contract, which this compiled sensor reads; robots described by a URDF or
#: MJCF of their own go through :mod:`grfguard.estimate.wrench`, which takes every joint).
_NJ = len(JOINT_COLUMNS)
#: Corner cells: the schema's ``FORCE_COLUMNS`` (four per sole).
_NC = len(FORCE_COLUMNS)
_I_Q = 0
_I_QUAT = _I_Q + _NJ
_I_GYRO = _I_QUAT + len(IMU_QUAT)
_I_ACC = _I_GYRO + len(IMU_GYRO)
_I_REF = _I_ACC + len(IMU_ACC)
N_IN = _I_REF + len(CONTACT_REF)
assert N_IN == len(IN_COLUMNS)
N_OUT = 22

# float parameters (prm)
_P_DT, _P_KATT, _P_CH, _P_G, _P_MASS, _P_KC, _P_SW = 0, 1, 2, 3, 4, 5, 6
_P_USE_ACC, _P_ACC_VERT, _P_USE_L, _P_KIN, _P_HAS_GYRO, _P_HAS_REF = 7, 8, 9, 10, 11, 12
_P_BODY_MASS_SUM, _P_QIT = 13, 14  # q_IT: 14..17
_P_ANCHOR_HOLD = 40  # VFSConfig.anchor_hold (after the vfs_paper block)
_P_TWIST = 41  # VFSConfig.contact_twist
# offsets of the block kinematics' constants in cf / ci (grfguard.kernels.front; 0: off)
_P_FRONT_CF, _P_FRONT_CI = 42, 43
N_PRM = 44  # 18..39: the non-default settings (grfguard.kernels.vfs_paper)
# int parameters (iprm)
_IP_TRUNK, _IP_ROOT, _IP_JOINTS = 0, 1, 2
_IP_IMU = _IP_JOINTS + _NJ
_IP_CORNERS = _IP_IMU + 1
_IP_SOLES = _IP_CORNERS + _NC
N_IPRM = _IP_SOLES + 2
# state layout (fixed part)
_S_N, _S_ATT_INIT, _S_ATT = 0, 1, 2  # att: 2..5
_S_ANCHOR, _S_PWA = 6, 7  # p_W_anchor: 7..9
_S_HI, _S_HC, _S_HN = 10, 19, 28  # histories 3 x 3 each, count
_S_PREVF, _S_PREVL_OK, _S_PREVL = 29, 30, 31  # prev_L: 31..33
_S_LP_OK, _S_FUSE_OK, _S_ACC_OK = 34, 35, 36
_S_LAST, _S_HAS_LAST = 37, 59  # last output 37..58
_S_FIXED = 60
# int scratch (iws): 0..31 contact and solver indices, 32..42 the sites, then the QP's
# starting guess (contact pattern, positive corners)
_IW_WARM = 44


def _state_size(nbr: int, order: int) -> int:
    # then N_XSTATE floats of the non-default settings' stages (vfs_paper)
    return _S_FIXED + 15 * order + 12 * nbr


@njit_nort(inline="always")
def _v2(a, o, n, m):
    """(n, m) C-contiguous view of ``a[o : o + n * m]`` without numpy's reshape call
    (which costs about 20 ns in compiled code)."""
    return view2d(a, o, n, m)


@njit_nort(inline="always")
def _qmul(aw, ax, ay, az, bw, bx, by, bz):
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@njit_nort(inline="always")
def _qexp(x, y, z):
    th = math.sqrt(x * x + y * y + z * z)
    if th < 1e-12:
        return 1.0, 0.5 * x, 0.5 * y, 0.5 * z
    s = math.sin(0.5 * th) / th
    return math.cos(0.5 * th), s * x, s * y, s * z


@njit_nort
def _lfilter_step(b, a, zst, x, y, zi, init):
    """One DF2T step of every channel; ``zst`` (order, nch) state; ``init`` primes it."""
    order = b.shape[0] - 1
    nch = x.shape[0]
    if init:
        for k in range(order):
            for c in range(nch):
                zst[k, c] = zi[k] * x[c]
    if order == 2:  # the default: straight-line code, same operations
        b0, b1, b2, a1, a2 = b[0], b[1], b[2], a[1], a[2]
        for c in range(nch):
            xn = x[c]
            yn = zst[0, c] + b0 * xn
            zst[0, c] = zst[1, c] + xn * b1 - yn * a1
            zst[1, c] = xn * b2 - yn * a2
            y[c] = yn
        return
    for c in range(nch):
        xn = x[c]
        yn = zst[0, c] + b[0] * xn
        for k in range(order - 1):
            zst[k, c] = zst[k + 1, c] + xn * b[k + 1] - yn * a[k + 1]
        zst[order - 1, c] = xn * b[order] - yn * a[order]
        y[c] = yn


@njit_nort
def _sum8(a):
    # numpy's pairwise sum of a contiguous 8-vector
    return ((a[0] + a[1]) + (a[2] + a[3])) + ((a[4] + a[5]) + (a[6] + a[7]))


@njit_nort
def _sum_seq(a, n):
    s = a[0]
    for i in range(1, n):
        s += a[i]
    return s


@njit_nort
def _step(x, y, state, cf, ci, ws, iws):
    """Process one input row ``x`` (:data:`IN_COLUMNS`) into ``y`` (:data:`OUT_COLUMNS`).

    ``state`` is updated in place (only for a valid sample). ``cf``/``ci`` are the
    packed constants built by :class:`VFSKernel` (unpacked here: views cost a few
    additions, while numba passes every array argument of a compiled call as 7 machine
    words, about 240 for the 34 unpacked arrays); ``ws``/``iws`` are float/int scratch.
    Returns True for a valid sample.

    Stages: validity, attitude filter, kinematics, stance, leg odometry, raw rates,
    angular momentum rate (in the trunk's axes from the block's sums when the block
    kinematics cover the tree, :func:`_momentum_front`; else from the world-axes poses),
    filters, ZMP (Newton-Euler), corner contact, compliance prior + QP, outputs.
    """
    prm, iprm, body_inertia, corner_radius, filt_b, filt_a, filt_zi, tree, sites = _unpack(
        cf, ci)
    body_mass = tree[8]
    nb = tree[0].shape[0]
    nq = tree[13].shape[0]
    order = filt_b.shape[1] - 1
    dt = prm[_P_DT]
    g = prm[_P_G]
    if not _valid_sample(x, y, state, prm):
        return False
    (qpos, xpos, xquat, xmat, xipos, ximat, stc, msub, sxp, sxm, qin, raw, main, v3a, v3b,
     v3c, v3d, pk, tmp8, prior8, rel8, forces, lin, cc, qp_x, qp_z, qp_M, qp_rhs, qp_dots,
     tail) = _scratch_views(ws, nq, nb)
    aw, ax, ay, az = _attitude_filter(x, state, prm)
    front = prm[_P_FRONT_CF] != 0.0
    if front:  # the poses from the block (grfguard.kernels.front)
        p_AC0, p_AC1, p_AC2, pst, pstep = _kinematics_front(
            x, state, prm, cf, ci, ws, iws, corner_radius, aw, ax, ay, az, sxp, sxm, pk, order)
    else:
        p_AC0, p_AC1, p_AC2 = _kinematics(x, prm, iprm, tree, sites, corner_radius, aw, ax,
                                          ay, az, qpos, xpos, xquat, xmat, xipos, ximat, stc,
                                          msub, sxp, sxm, qin, pk, tail, view1d(iws, 32, 11))
        pst, pstep = -1, 1
    st0, st1 = _stance(x, prm, pk)
    xo = _S_FIXED + 15 * order + 12 * (nb - 1)  # state of the vfs_paper stages
    if prm[P_KANC] > 0.0:  # vfs_paper: anchor attitude (rotates the frames)
        if state[_S_ANCHOR] < 0:
            _init_anchor(state, pk, sxp, st0, st1)
            anchor_init(state, xo, _S_ANCHOR, sxm)
        pwt0, pwt1, pwt2, ground, p_AC0, p_AC1, p_AC2 = anchor_odometry(
            state, xo, prm, _S_ANCHOR, _S_PWA, pk, sxp, sxm, xipos, ximat, nb, p_AC0, p_AC1,
            p_AC2, st0, st1)
    else:
        pwt0, pwt1, pwt2, ground = _leg_odometry(state, prm, pk, sxp, tmp8, st0, st1)
    com0 = pwt0 + p_AC0
    com1 = pwt1 + p_AC1
    com2 = pwt2 + p_AC2
    if prm[P_COM_PAPER] != 0.0:  # vfs_paper: the paper's LIPM CoM filter
        com0, com1, com2, F0, F1, F2, zmp0, zmp1 = paper_com(
            x, state, xo, prm, pk, pwt0, pwt1, pwt2, com0, com1, com2, ground, aw, ax, ay, az)
    else:
        _raw_rates(state, raw, sxp, pwt0, pwt1, pwt2, p_AC0, p_AC1, p_AC2, dt)
        if front:
            _momentum_front(x, state, raw, ws, pst, pstep, sxm, order, dt)
        else:
            _momentum_rate(state, prm, raw, xipos, ximat, body_mass, body_inertia, lin, cc,
                           nb, order, dt)
        _keep_shared(ws, pwt0, pwt1, pwt2, ground, com0, com1, com2, st0, st1, aw, ax, ay, az)
        F0, F1, F2, zmp0, zmp1 = _rates_to_zmp(x, state, prm, filt_b, filt_a, filt_zi, raw,
                                               main, v3a, v3b, v3c, v3d, aw, ax, ay, az,
                                               order, g, xo, com0, com1, com2, ground)
    _split_outputs(y, state, cf, ws, iws, nq, nb, pwt0, pwt1, pwt2, ground, com0, com1,
                   com2, F0, F1, F2, zmp0, zmp1, st0, st1)
    return True


@njit_nort(inline="always")
def _rates_to_zmp(x, state, prm, filt_b, filt_a, filt_zi, raw, main, v3a, v3b, v3c, v3d, aw,
                  ax, ay, az, order, g, xo, com0, com1, com2, ground):
    """Low-passed raw rates (accelerometer fused) to the total force ``F0, F1, F2`` [N] and
    the Newton-Euler ZMP ``zmp0, zmp1`` [m] (or the pendulum Kalman filter's)."""
    F0, F1, F2, ld0, ld1 = _filters(x, state, prm, filt_b, filt_a, filt_zi, raw, main, v3a,
                                    v3b, v3c, v3d, aw, ax, ay, az, order, g)
    h = com2 - ground
    fz = max(F2, 1.0)
    zmp0 = com0 - (h * F0 + ld1) / fz
    zmp1 = com1 - (h * F1 - ld0) / fz
    if prm[P_ZMP_KF] != 0.0:  # vfs_paper: pendulum Kalman filter ZMP
        zmp0, zmp1 = zmp_kalman(state, xo, prm, com0, com1, com2, ground, F2, ld0, ld1)
    return F0, F1, F2, zmp0, zmp1


@njit_nort
def _split_outputs(y, state, cf, ws, iws, nq, nb, pwt0, pwt1, pwt2, ground, com0, com1, com2,
                   F0, F1, F2, zmp0, zmp1, st0, st1):
    """Corner contact, force split (compliance QP or the paper's) and the output row
    (the scratch views taken here from ``ws``/``iws``: fewer call arguments)."""
    prm = view1d(cf, 0, N_PRM)
    (qpos, xpos, xquat, xmat, xipos, ximat, stc, msub, sxp, sxm, qin, raw, main, v3a, v3b,
     v3c, v3d, pk, tmp8, prior8, rel8, forces, lin, cc, qp_x, qp_z, qp_M, qp_rhs, qp_dots,
     tail) = _scratch_views(ws, nq, nb)
    ctc = view1d(iws, 0, 8)
    if prm[P_SPLIT_PAPER] != 0.0:  # vfs_paper: the paper's split
        paper_split(prm, pk, sxp, sxm, pwt0, pwt1, pwt2, com0, com1, com2, F0, F1, F2, st0,
                    st1, forces, ctc, qp_x, qp_z, view1d(iws, 8, 8), view1d(iws, 16, 8),
                    qp_M, qp_rhs, qp_dots, tail)
    else:
        _corner_contact(prm, pk, tmp8, ctc, pwt0, pwt1, pwt2, ground, st0, st1)
        _force_split(prm, ws, iws, nq, nb, F2, zmp0, zmp1)
    _outputs(y, state, forces, pk, ctc, com0, com1, com2, zmp0, zmp1)


#: Floats at the end of the scratch ``ws`` where a step keeps what a twin sensor of the
#: same robot and attitude reuses (:func:`vfs_step_shared`): trunk position, ground,
#: CoM, stance, attitude.
N_SHARED = 16


@njit_nort(inline="always")
def _shared_slots(ws):
    return view1d(ws, ws.shape[0] - N_SHARED, N_SHARED)


@njit_nort(inline="always")
def _keep_shared(ws, pwt0, pwt1, pwt2, ground, com0, com1, com2, st0, st1, aw, ax, ay, az):
    sh = _shared_slots(ws)
    sh[0], sh[1], sh[2], sh[3] = pwt0, pwt1, pwt2, ground
    sh[4], sh[5], sh[6] = com0, com1, com2
    sh[7] = 1.0 if st0 else 0.0
    sh[8] = 1.0 if st1 else 0.0
    sh[9], sh[10], sh[11], sh[12] = aw, ax, ay, az


@njit_nort(inline="always")
def _valid_sample(x, y, state, prm):
    """Whether row ``x`` is usable (finite joints, attitude and the optional gyro, acc and
    contact reference; non-zero quaternion). If not, ``y`` repeats the last output (NaN
    before the first) with validity 0."""
    ok = True
    for i in range(16):
        if not math.isfinite(x[i]):
            ok = False
    if prm[_P_HAS_GYRO] != 0.0:
        for i in range(_I_GYRO, _I_GYRO + 3):
            if not math.isfinite(x[i]):
                ok = False
    if prm[_P_USE_ACC] != 0.0:
        for i in range(_I_ACC, _I_ACC + 3):
            if not math.isfinite(x[i]):
                ok = False
    if prm[_P_HAS_REF] != 0.0:
        for i in range(_I_REF, _I_REF + 2):
            if not math.isfinite(x[i]):
                ok = False
    if ok and prm[P_COM_PAPER] != 0.0:  # vfs_paper: acc and force sensors too
        ok = valid_paper_inputs(x)
    if ok:
        qw, qx, qy, qz = x[_I_QUAT], x[_I_QUAT + 1], x[_I_QUAT + 2], x[_I_QUAT + 3]
        if math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz) < 1e-6:
            ok = False
    if not ok:
        if state[_S_HAS_LAST] != 0.0:
            for k in range(N_OUT):
                y[k] = state[_S_LAST + k]
        else:
            for k in range(N_OUT):
                y[k] = np.nan
        y[N_OUT - 1] = 0.0
    return ok


@njit_nort(inline="always")
def _scratch_views(ws, nq, nb):
    """Named views into the float scratch ``ws`` (fixed layout); the last one is the
    rest of ``ws`` (solver and FK work space). No allocation, no reshape call."""
    o = 0
    qpos = view1d(ws, o, nq)
    o += nq
    xpos = _v2(ws, o, nb, 3)
    o += 3 * nb
    xquat = _v2(ws, o, nb, 4)
    o += 4 * nb
    xmat = _v2(ws, o, nb, 9)
    o += 9 * nb
    xipos = _v2(ws, o, nb, 3)
    o += 3 * nb
    ximat = _v2(ws, o, nb, 9)
    o += 9 * nb
    stc = _v2(ws, o, nb, 3)
    o += 3 * nb
    msub = view1d(ws, o, nb)
    o += nb
    sxp = _v2(ws, o, 11, 3)
    o += 33
    sxm = _v2(ws, o, 11, 9)
    o += 99
    qin = view1d(ws, o, nq)
    o += nq
    raw = view1d(ws, o, 9)
    o += 9
    main = view1d(ws, o, 9)
    o += 9
    v3a = view1d(ws, o, 3)
    o += 3
    v3b = view1d(ws, o, 3)
    o += 3
    v3c = view1d(ws, o, 3)
    o += 3
    v3d = view1d(ws, o, 3)
    o += 3
    pk = _v2(ws, o, 8, 3)
    o += 24
    tmp8 = view1d(ws, o, 8)
    o += 8
    prior8 = view1d(ws, o, 8)
    o += 8
    rel8 = _v2(ws, o, 8, 2)
    o += 16
    forces = view1d(ws, o, 8)
    o += 8
    lin = view1d(ws, o, 3)
    o += 3
    cc = view1d(ws, o, 3)
    o += 3
    qp_x = view1d(ws, o, 8)
    o += 8
    qp_z = view1d(ws, o, 8)
    o += 8
    qp_M = _v2(ws, o, 11, 8)
    o += 88
    qp_rhs = view1d(ws, o, 11)
    o += 11
    qp_dots = view1d(ws, o, 8)
    o += 8
    return (qpos, xpos, xquat, xmat, xipos, ximat, stc, msub, sxp, sxm, qin, raw, main, v3a,
            v3b, v3c, v3d, pk, tmp8, prior8, rel8, forces, lin, cc, qp_x, qp_z, qp_M, qp_rhs,
            qp_dots, view1d(ws, o, ws.shape[0] - N_SHARED - front_ws_size(nb) - o))


@njit_nort(inline="always")
def _attitude_filter(x, state, prm):
    """Complementary attitude filter (gyro prediction pulled towards the measured
    quaternion by ``katt``); returns and stores the unit attitude (w, x, y, z)."""
    qw, qx, qy, qz = x[_I_QUAT], x[_I_QUAT + 1], x[_I_QUAT + 2], x[_I_QUAT + 3]
    nm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    mw, mx, my, mz = qw / nm, qx / nm, qy / nm, qz / nm
    katt = prm[_P_KATT]
    if state[_S_ATT_INIT] == 0.0 or katt >= 1.0 or prm[_P_HAS_GYRO] == 0.0:
        aw, ax, ay, az = mw, mx, my, mz
    else:
        dt = prm[_P_DT]
        gx = x[_I_GYRO] * dt
        gy = x[_I_GYRO + 1] * dt
        gz = x[_I_GYRO + 2] * dt
        e0, e1, e2, e3 = _qexp(gx, gy, gz)
        pw, px, py, pz = _qmul(state[_S_ATT], state[_S_ATT + 1], state[_S_ATT + 2],
                               state[_S_ATT + 3], e0, e1, e2, e3)
        f0, f1, f2, f3 = _qmul(pw, -px, -py, -pz, mw, mx, my, mz)
        sgn = 2.0 * katt if f0 >= 0 else -2.0 * katt
        e0, e1, e2, e3 = _qexp(sgn * f1, sgn * f2, sgn * f3)
        pw, px, py, pz = _qmul(pw, px, py, pz, e0, e1, e2, e3)
        n2 = math.sqrt(pw * pw + px * px + py * py + pz * pz)
        aw, ax, ay, az = pw / n2, px / n2, py / n2, pz / n2
    state[_S_ATT_INIT] = 1.0
    state[_S_ATT] = aw
    state[_S_ATT + 1] = ax
    state[_S_ATT + 2] = ay
    state[_S_ATT + 3] = az
    return aw, ax, ay, az


@njit_nort(inline="always")
def _kinematics(x, prm, iprm, tree, sites, corner_radius, aw, ax, ay, az, qpos, xpos, xquat,
                xmat, xipos, ximat, stc, msub, sxp, sxm, qin, pk, work, sel):
    """Forward kinematics with the trunk at the origin: bodies, IMU/corner/sole sites,
    corner contact points ``pk`` [m]; returns the trunk-relative CoM (3 floats) [m]."""
    (body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos, body_quat, body_ipos,
     body_iquat, body_mass, jnt_type, jnt_qposadr, jnt_axis, jnt_pos, qpos0, body_order,
     body_kind) = tree
    site_body, site_sameframe, site_pos, site_quat = sites
    tw, tx, ty, tz = _trunk_quat(prm, aw, ax, ay, az)
    for k in range(qpos0.shape[0]):
        qin[k] = qpos0[k]
    r = iprm[_IP_ROOT]
    qin[r] = 0.0
    qin[r + 1] = 0.0
    qin[r + 2] = 0.0
    qin[r + 3] = tw
    qin[r + 4] = tx
    qin[r + 5] = ty
    qin[r + 6] = tz
    for j in range(_NJ):
        qin[iprm[_IP_JOINTS + j]] = x[_I_Q + j]
    # fk_tree's bodies, then the subtree CoM of the trunk only (same bits)
    fk_bodies_kind(qin, body_kind, body_parent, body_jntadr, body_jntnum, body_sameframe,
                   body_pos, body_quat, body_ipos, body_iquat, jnt_type, jnt_qposadr, jnt_axis,
                   jnt_pos, qpos0, body_order, qpos, xpos, xquat, xmat, xipos, ximat)
    sel[0] = iprm[_IP_IMU]
    for k in range(8):
        sel[1 + k] = iprm[_IP_CORNERS + k]
    sel[9] = iprm[_IP_SOLES]
    sel[10] = iprm[_IP_SOLES + 1]
    if prm[P_KANC] > 0.0 or prm[P_SPLIT_PAPER] != 0.0:  # the paper stages use the sole axes
        fk_sites(sel, site_body, site_sameframe, site_pos, site_quat, xpos, xquat, xmat, xipos,
                 ximat, sxp, sxm, work)
    else:
        fk_site_pos(sel, site_body, site_sameframe, site_pos, xpos, xmat, xipos, sxp)
    for k in range(8):
        pk[k, 0] = sxp[1 + k, 0]
        pk[k, 1] = sxp[1 + k, 1]
        pk[k, 2] = sxp[1 + k, 2] - corner_radius[k]
    return subtree_com_of(iprm[_IP_TRUNK], body_parent, body_mass, xipos, stc, msub)


@njit_nort(inline="always")
def _trunk_quat(prm, aw, ax, ay, az):
    """The trunk's attitude: the IMU's ``a`` times ``q_IT``, normalised (mju_normalize4)."""
    qi0, qi1, qi2, qi3 = prm[_P_QIT], prm[_P_QIT + 1], prm[_P_QIT + 2], prm[_P_QIT + 3]
    tw, tx, ty, tz = _qmul(aw, ax, ay, az, qi0, qi1, qi2, qi3)
    nt = math.sqrt(tw * tw + tx * tx + ty * ty + tz * tz)
    if nt < 1e-15:
        tw, tx, ty, tz = 1.0, 0.0, 0.0, 0.0
    elif abs(nt - 1.0) > 1e-15:
        inv = 1.0 / nt
        tw, tx, ty, tz = tw * inv, tx * inv, ty * inv, tz * inv
    return tw, tx, ty, tz


@njit_nort(inline="always")
def _kinematics_front(x, state, prm, cf, ci, ws, iws, corner_radius, aw, ax, ay, az, sxp,
                      sxm, pk, order):
    """:func:`_kinematics` from the block of :mod:`grfguard.kernels.front` (the default
    settings): the sites and the trunk-relative CoM (3 floats) [m], then the offset and
    stride in ``ws`` of the trunk-frame sums of the angular momentum with the previous
    valid sample (offset -1: none); the trunk's rotation (row-major) kept in ``sxm[0]``.
    No body poses in world axes (:func:`_momentum_front` needs none)."""
    tw, tx, ty, tz = _trunk_quat(prm, aw, ax, ay, az)
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = _q2m(tw, tx, ty, tz)
    a = _S_FIXED + 15 * order
    c0, c1, c2, pst, pstep = front_trunk(
        x, view1d(state, a, _NJ), state[_S_PREVF] != 0.0, cf, ci, int(prm[_P_FRONT_CF]),
        int(prm[_P_FRONT_CI]), ci[0], ws, iws, N_SHARED, r0, r1, r2, r3, r4, r5, r6, r7, r8,
        sxp)
    (sxm[0, 0], sxm[0, 1], sxm[0, 2], sxm[0, 3], sxm[0, 4], sxm[0, 5], sxm[0, 6], sxm[0, 7],
     sxm[0, 8]) = r0, r1, r2, r3, r4, r5, r6, r7, r8
    for k in range(8):
        pk[k, 0] = sxp[1 + k, 0]
        pk[k, 1] = sxp[1 + k, 1]
        pk[k, 2] = sxp[1 + k, 2] - corner_radius[k]
    return c0, c1, c2, pst, pstep


@njit_nort(inline="always")
def _stance(x, prm, pk):
    """Stance of the right and left foot: the contact reference if logged, else the
    foot whose lowest corner is within 1 cm of the lowest corner of both."""
    if prm[_P_HAS_REF] != 0.0:
        st0 = x[_I_REF] > 0.5
        st1 = x[_I_REF + 1] > 0.5
    else:
        zr = min(pk[0, 2], pk[1, 2], pk[2, 2], pk[3, 2])
        zl = min(pk[4, 2], pk[5, 2], pk[6, 2], pk[7, 2])
        zmin = min(zr, zl)
        st0 = zr - zmin < 0.01
        st1 = zl - zmin < 0.01
    return st0, st1


@njit_nort(inline="always")
def _leg_odometry(state, prm, pk, sxp, tmp8, st0, st1):
    """Leg odometry (no anchor attitude: the rotation correction is the identity):
    the trunk position in the world (3 floats) [m] and the ground height [m]; the anchor
    foot switches when the other foot is in stance and flat (or the anchor lifts); with
    ``anchor_hold`` only when the other is flat and the anchor is not (or it lifts): a
    flat double support then keeps its anchor instead of alternating every sample."""
    if state[_S_ANCHOR] < 0:
        _init_anchor(state, pk, sxp, st0, st1)
    a_ = int(state[_S_ANCHOR])
    pwt0 = state[_S_PWA] - sxp[9 + a_, 0]
    pwt1 = state[_S_PWA + 1] - sxp[9 + a_, 1]
    pwt2 = state[_S_PWA + 2] - sxp[9 + a_, 2]
    for k in range(8):
        tmp8[k] = pwt2 + pk[k, 2]
    ground = min(tmp8[4 * a_], tmp8[4 * a_ + 1], tmp8[4 * a_ + 2], tmp8[4 * a_ + 3])
    ob = 1 - a_
    flat = (max(tmp8[4 * ob], tmp8[4 * ob + 1], tmp8[4 * ob + 2], tmp8[4 * ob + 3]) - ground
            < prm[_P_CH])
    st_a = st0 if a_ == 0 else st1
    st_o = st1 if a_ == 0 else st0
    if flat and prm[_P_ANCHOR_HOLD] != 0.0:  # anchor_hold: the flat anchor stays
        flat = (max(tmp8[4 * a_], tmp8[4 * a_ + 1], tmp8[4 * a_ + 2], tmp8[4 * a_ + 3])
                - ground >= prm[_P_CH])
    if st_o and (flat or not st_a):
        state[_S_ANCHOR] = ob
        state[_S_PWA] = pwt0 + sxp[9 + ob, 0]
        state[_S_PWA + 1] = pwt1 + sxp[9 + ob, 1]
        state[_S_PWA + 2] = pwt2 + sxp[9 + ob, 2]
    return pwt0, pwt1, pwt2, ground


@njit_nort
def _init_anchor(state, pk, sxp, st0, st1):
    """First anchor foot (the single stance foot, else the lower one) and its world
    position: the feet's midpoint (or the stance foot) at the origin, the sole on z = 0."""
    if st0 and not st1:
        anc = 0
    elif st1 and not st0:
        anc = 1
    else:
        zr = min(pk[0, 2], pk[1, 2], pk[2, 2], pk[3, 2])
        zl = min(pk[4, 2], pk[5, 2], pk[6, 2], pk[7, 2])
        anc = 1 if zl < zr - 1e-4 else 0
    if st0 and st1:
        mid0 = (sxp[9, 0] + sxp[10, 0]) / 2
        mid1 = (sxp[9, 1] + sxp[10, 1]) / 2
    else:
        f = 0 if st0 else (1 if st1 else anc)
        mid0 = sxp[9 + f, 0] / 1
        mid1 = sxp[9 + f, 1] / 1
    z0 = min(pk[4 * anc, 2], pk[4 * anc + 1, 2], pk[4 * anc + 2, 2], pk[4 * anc + 3, 2])
    state[_S_PWA] = -mid0 + sxp[9 + anc, 0]
    state[_S_PWA + 1] = -mid1 + sxp[9 + anc, 1]
    state[_S_PWA + 2] = -z0 + sxp[9 + anc, 2]
    state[_S_ANCHOR] = anc


@njit_nort(inline="always")
def _raw_rates(state, raw, sxp, pwt0, pwt1, pwt2, p_AC0, p_AC1, p_AC2, dt):
    """Second differences over the last three samples of the IMU-relative CoM
    (``raw[0:3]``) and the IMU's world position (``raw[6:9]``) [m/s^2]; ``raw`` zeroed."""
    for k in range(9):
        raw[k] = 0.0
    hn = int(state[_S_HN])
    if hn == 3:
        for k in range(6):
            state[_S_HI + k] = state[_S_HI + 3 + k]
            state[_S_HC + k] = state[_S_HC + 3 + k]
        hn = 2
    state[_S_HI + 3 * hn] = pwt0 + sxp[0, 0]
    state[_S_HI + 3 * hn + 1] = pwt1 + sxp[0, 1]
    state[_S_HI + 3 * hn + 2] = pwt2 + sxp[0, 2]
    state[_S_HC + 3 * hn] = p_AC0 - sxp[0, 0]
    state[_S_HC + 3 * hn + 1] = p_AC1 - sxp[0, 1]
    state[_S_HC + 3 * hn + 2] = p_AC2 - sxp[0, 2]
    hn += 1
    state[_S_HN] = hn
    if hn == 3:
        for k in range(3):
            for off, h in ((0, _S_HC), (6, _S_HI)):
                v1 = (state[h + 6 + k] - state[h + 3 + k]) / dt
                v0 = (state[h + 3 + k] - state[h + k]) / dt
                raw[off + k] = (v1 - v0) / dt


@njit_nort(inline="always")
def _momentum_rate(state, prm, raw, xipos, ximat, body_mass, body_inertia, lin, cc, nb,
                   order, dt):
    """Rate of the angular momentum about the CoM (``raw[3:6]``) [N m] from this and the
    previous body poses (kept in ``state``)."""
    nbr = nb - 1
    pb = _v2(state, _S_FIXED + 15 * order, nbr, 3)
    pr = _v2(state, _S_FIXED + 15 * order + 3 * nbr, nbr, 9)
    if state[_S_PREVF] != 0.0:
        msum = prm[_P_BODY_MASS_SUM]
        for k in range(3):
            s = xipos[1, k] * body_mass[1]
            for i in range(2, nb):
                s += xipos[i, k] * body_mass[i]
            cc[k] = s / msum
        L0, L1, L2 = _angular_momentum(xipos, ximat, body_mass, body_inertia, pb, pr, lin, cc,
                                       nbr, dt)
        _rate_of(state, raw, L0, L1, L2, dt)
    for i in range(nbr):
        for k in range(3):
            pb[i, k] = xipos[i + 1, k]
        for k in range(9):
            pr[i, k] = ximat[i + 1, k]
    state[_S_PREVF] = 1.0


@njit_nort(inline="always")
def _rate_of(state, raw, L0, L1, L2, dt):
    """The momentum rate ``raw[3:6]`` [N m] from the angular momentum ``L`` now and the
    one kept in ``state`` (if any); ``L`` kept for the next sample."""
    if state[_S_PREVL_OK] != 0.0:
        raw[3] = (L0 - state[_S_PREVL]) / dt
        raw[4] = (L1 - state[_S_PREVL + 1]) / dt
        raw[5] = (L2 - state[_S_PREVL + 2]) / dt
    state[_S_PREVL] = L0
    state[_S_PREVL + 1] = L1
    state[_S_PREVL + 2] = L2
    state[_S_PREVL_OK] = 1.0


@njit_nort(inline="always")
def _momentum_front(x, state, raw, ws, pst, pstep, sxm, order, dt):
    """:func:`_momentum_rate` from the trunk-frame sums at ``ws[pst]`` (stride ``pstep``;
    :func:`grfguard.kernels.front.front_trunk`, -1: no previous sample) and the trunk's
    rotation now (``sxm[0]``) and before (kept in ``state`` with the joint angles of this
    sample: the previous poses are the block's)."""
    a = _S_FIXED + 15 * order
    if pst >= 0:
        q = view1d(state, a + _NJ, 9)
        r = sxm[0]
        # D = Q^T Q' (row-major)
        D = (r[0] * q[0] + r[3] * q[3] + r[6] * q[6], r[0] * q[1] + r[3] * q[4] + r[6] * q[7],
             r[0] * q[2] + r[3] * q[5] + r[6] * q[8], r[1] * q[0] + r[4] * q[3] + r[7] * q[6],
             r[1] * q[1] + r[4] * q[4] + r[7] * q[7], r[1] * q[2] + r[4] * q[5] + r[7] * q[8],
             r[2] * q[0] + r[5] * q[3] + r[8] * q[6], r[2] * q[1] + r[5] * q[4] + r[8] * q[7],
             r[2] * q[2] + r[5] * q[5] + r[8] * q[8])
        M = (ws[pst + 3 * pstep], ws[pst + 4 * pstep], ws[pst + 5 * pstep],
             ws[pst + 6 * pstep], ws[pst + 7 * pstep], ws[pst + 8 * pstep],
             ws[pst + 9 * pstep], ws[pst + 10 * pstep], ws[pst + 11 * pstep])
        # e(M D^T): (M D^T)_bc = sum_l M_bl D_cl
        n12 = M[3] * D[6] + M[4] * D[7] + M[5] * D[8]
        n21 = M[6] * D[3] + M[7] * D[4] + M[8] * D[5]
        n20 = M[6] * D[0] + M[7] * D[1] + M[8] * D[2]
        n02 = M[0] * D[6] + M[1] * D[7] + M[2] * D[8]
        n01 = M[0] * D[3] + M[1] * D[4] + M[2] * D[5]
        n10 = M[3] * D[0] + M[4] * D[1] + M[5] * D[2]
        s0 = _kd(ws, pst + 12 * pstep, pstep, D)
        s1 = _kd(ws, pst + 21 * pstep, pstep, D)
        s2 = _kd(ws, pst + 30 * pstep, pstep, D)
        v0 = s0 / (2.0 * dt) - (n12 - n21) / dt
        v1 = s1 / (2.0 * dt) - (n20 - n02) / dt
        v2 = s2 / (2.0 * dt) - (n01 - n10) / dt
        L0, L1, L2 = _mv(r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], v0, v1, v2)
        _rate_of(state, raw, L0, L1, L2, dt)
    for k in range(_NJ):
        state[a + k] = x[_I_Q + k]
    for k in range(9):
        state[a + _NJ + k] = sxm[0, k]
    state[_S_PREVF] = 1.0


@njit_nort(inline="always")
def _kd(ws, o, step, D):
    """``sum_(c, l) K[a, c, l] D_cl`` of one row ``a`` of ``K`` at ``ws[o]``."""
    s = ws[o] * D[0]
    for k in range(1, 9):
        s += ws[o + k * step] * D[k]
    return s


@njit_nort(inline="always")
def _angular_momentum(xipos, ximat, body_mass, body_inertia, pb, pr, lin, cc, nbr, dt):
    """Angular momentum about the CoM ``cc`` (3 floats) [N m s]: the bodies' linear
    momenta (finite differences of their CoMs ``pb`` -> ``xipos``) plus their spin
    (finite differences of their orientations ``pr`` -> ``ximat``)."""
    for k in range(3):
        lin[k] = 0.0
    L0 = 0.0
    L1 = 0.0
    L2 = 0.0
    for i in range(nbr):
        bi = i + 1
        m_i = body_mass[bi]
        r0 = xipos[bi, 0] - cc[0]
        r1 = xipos[bi, 1] - cc[1]
        r2 = xipos[bi, 2] - cc[2]
        w0 = (xipos[bi, 0] - pb[i, 0]) / dt
        w1 = (xipos[bi, 1] - pb[i, 1]) / dt
        w2 = (xipos[bi, 2] - pb[i, 2]) / dt
        c0 = (r1 * w2 - r2 * w1) * m_i
        c1 = (r2 * w0 - r0 * w2) * m_i
        c2 = (r0 * w1 - r1 * w0) * m_i
        if i == 0:
            lin[0], lin[1], lin[2] = c0, c1, c2
        else:
            lin[0] += c0
            lin[1] += c1
            lin[2] += c2
        R = ximat[bi]
        P = pr[i]
        # dR = R P^T as numpy's stacked matmul computes it (fused multiply-adds)
        d01 = fma(R[2], P[5], fma(R[1], P[4], R[0] * P[3]))
        d02 = fma(R[2], P[8], fma(R[1], P[7], R[0] * P[6]))
        d10 = fma(R[5], P[2], fma(R[4], P[1], R[3] * P[0]))
        d12 = fma(R[5], P[8], fma(R[4], P[7], R[3] * P[6]))
        d20 = fma(R[8], P[2], fma(R[7], P[1], R[6] * P[0]))
        d21 = fma(R[8], P[5], fma(R[7], P[4], R[6] * P[3]))
        om0 = (d21 - d12) / (2.0 * dt)
        om1 = (d02 - d20) / (2.0 * dt)
        om2 = (d10 - d01) / (2.0 * dt)
        # w_B = R^T w, scaled by the inertia, rotated back
        wb0 = (R[0] * om0 + R[3] * om1 + R[6] * om2) * body_inertia[i, 0]
        wb1 = (R[1] * om0 + R[4] * om1 + R[7] * om2) * body_inertia[i, 1]
        wb2 = (R[2] * om0 + R[5] * om1 + R[8] * om2) * body_inertia[i, 2]
        # (einsum's summation order: first + last, then the middle term)
        t0 = (R[0] * wb0 + R[2] * wb2) + R[1] * wb1
        t1 = (R[3] * wb0 + R[5] * wb2) + R[4] * wb1
        t2 = (R[6] * wb0 + R[8] * wb2) + R[7] * wb1
        if i == 0:
            L0, L1, L2 = t0, t1, t2
        else:
            L0 += t0
            L1 += t1
            L2 += t2
    return lin[0] + L0, lin[1] + L1, lin[2] + L2


@njit_nort(inline="always")
def _filters(x, state, prm, filt_b, filt_a, filt_zi, raw, main, v3a, v3b, v3c, v3d, aw, ax,
             ay, az, order, g):
    """Low-pass the raw rates and (if used) fuse the accelerometer; returns the total
    force ``F0, F1, F2`` [N] and the angular momentum rate ``ld0, ld1`` [N m]."""
    zo = _S_FIXED
    zlp = _v2(state, zo, order, 9)
    zfu = _v2(state, zo + 9 * order, order, 3)
    zac = _v2(state, zo + 12 * order, order, 3)
    _lfilter_step(filt_b[0], filt_a[0], zlp, raw, main, filt_zi[0], state[_S_LP_OK] == 0.0)
    state[_S_LP_OK] = 1.0
    if prm[_P_USE_ACC] != 0.0:
        _world_acc(v3a, x, aw, ax, ay, az, g)
        for k in range(3):
            v3b[k] = raw[6 + k] - v3a[k]
        _lfilter_step(filt_b[2], filt_a[2], zac, v3a, v3c, filt_zi[2], state[_S_ACC_OK] == 0.0)
        _lfilter_step(filt_b[1], filt_a[1], zfu, v3b, v3d, filt_zi[1],
                      state[_S_FUSE_OK] == 0.0)
        state[_S_ACC_OK] = 1.0
        state[_S_FUSE_OK] = 1.0
        cdd0 = (v3c[0] + v3d[0]) + main[0]
        cdd1 = (v3c[1] + v3d[1]) + main[1]
        cdd2 = (v3c[2] + v3d[2]) + main[2]
        if prm[_P_ACC_VERT] == 0.0:
            cdd2 = main[2] + main[8]
    else:
        cdd0 = main[0] + main[6]
        cdd1 = main[1] + main[7]
        cdd2 = main[2] + main[8]
    if prm[_P_USE_L] != 0.0:
        ld0, ld1 = main[3], main[4]
    else:
        ld0, ld1 = 0.0, 0.0
    mass = prm[_P_MASS]
    return mass * (cdd0 + 0.0), mass * (cdd1 + 0.0), mass * (cdd2 + g), ld0, ld1


@njit_nort(inline="always")
def _world_acc(out, x, aw, ax, ay, az, g):
    """acc_W = R(q_att) acc - g e_z [m/s^2] (R from the normalised attitude, numpy's
    formula) into ``out``."""
    n3 = math.sqrt(aw * aw + ax * ax + ay * ay + az * az)
    w_, x_, y_, z_ = aw / n3, ax / n3, ay / n3, az / n3
    r00 = 1 - 2 * (y_ * y_ + z_ * z_)
    r01 = 2 * (x_ * y_ - w_ * z_)
    r02 = 2 * (x_ * z_ + w_ * y_)
    r10 = 2 * (x_ * y_ + w_ * z_)
    r11 = 1 - 2 * (x_ * x_ + z_ * z_)
    r12 = 2 * (y_ * z_ - w_ * x_)
    r20 = 2 * (x_ * z_ - w_ * y_)
    r21 = 2 * (y_ * z_ + w_ * x_)
    r22 = 1 - 2 * (x_ * x_ + y_ * y_)
    a0, a1, a2 = x[_I_ACC], x[_I_ACC + 1], x[_I_ACC + 2]
    # (einsum's summation order: first + last, then the middle term)
    out[0] = ((r00 * a0 + r02 * a2) + r01 * a1) - 0.0
    out[1] = ((r10 * a0 + r12 * a2) + r11 * a1) - 0.0
    out[2] = ((r20 * a0 + r22 * a2) + r21 * a1) - g


@njit_nort(inline="always")
def _corner_contact(prm, pk, tmp8, ctc, pwt0, pwt1, pwt2, ground, st0, st1):
    """Move the corners ``pk`` to the world, ``tmp8`` = their height above ground [m];
    ``ctc`` (0/1) = corners in contact (the stance foot's corners, or with the kinematic
    test the corners below the contact height and the lowest corner of a stance foot)."""
    ch = prm[_P_CH]
    for k in range(8):
        pk[k, 0] = pwt0 + pk[k, 0]
        pk[k, 1] = pwt1 + pk[k, 1]
        pk[k, 2] = pwt2 + pk[k, 2]
        tmp8[k] = pk[k, 2] - ground
    hr = min(tmp8[0], tmp8[1], tmp8[2], tmp8[3])
    hl = min(tmp8[4], tmp8[5], tmp8[6], tmp8[7])
    s0, s1 = st0, st1
    if not (s0 or s1):
        if hl < hr:
            s1 = True
        else:
            s0 = True
    kin = prm[_P_KIN] != 0.0
    for k in range(8):
        foot = s0 if k < 4 else s1
        if not kin:
            ctc[k] = 1 if foot else 0
        else:
            hm = hr if k < 4 else hl
            low = tmp8[k] < ch
            ctc[k] = 1 if (low or (foot and not (hm < ch) and tmp8[k] == hm)) else 0


@njit_nort
def _force_split(prm, ws, iws, nq, nb, F2, zmp0, zmp1):
    """Compliance prior + QP: the corner forces ``forces`` [N] (0 off contact, NaN if an
    input is not finite) summing to ``F2`` with their CoP at the ZMP (the scratch views
    of ``ws``/``iws`` as :func:`_split_outputs`'). The int scratch's warm slots (2 ints):
    the contact pattern and the positive corners of the last solve, the QP's starting
    guess (:func:`grfguard.kernels.nnls.prior_qp_warm`; the bits do not depend on it)."""
    (qpos, xpos, xquat, xmat, xipos, ximat, stc, msub, sxp, sxm, qin, raw, main, v3a, v3b,
     v3c, v3d, pk, tmp8, prior8, rel8, forces, lin, cc, qp_x, qp_z, qp_M, qp_rhs, qp_dots,
     work) = _scratch_views(ws, nq, nb)
    ctc = view1d(iws, 0, 8)
    qp_free = view1d(iws, 8, 8)
    qp_isfree = view1d(iws, 16, 8)
    cidx = view1d(iws, 24, 8)
    warm = view1d(iws, _IW_WARM, 2)
    cnt = 0
    for k in range(8):
        cnt += ctc[k]
    safe = max(cnt, 1)
    for k in range(8):
        qp_z[k] = pk[k, 2] if ctc[k] else 0.0
    zbar = _sum8(qp_z) / safe
    kc = prm[_P_KC]
    for k in range(8):
        prior8[k] = (F2 / safe + kc * (zbar - pk[k, 2])) if ctc[k] else 0.0
        rel8[k, 0] = pk[k, 0] - zmp0
        rel8[k, 1] = pk[k, 1] - zmp1
    m = 0
    for k in range(8):
        if ctc[k]:
            cidx[m] = k
            m += 1
    fin = math.isfinite(F2)
    for c in range(m):
        j = cidx[c]
        if not (math.isfinite(rel8[j, 0]) and math.isfinite(rel8[j, 1])
                and math.isfinite(prior8[j])):
            fin = False
    for k in range(8):
        forces[k] = 0.0
    if not fin:
        for k in range(8):
            forces[k] = np.nan
    elif m > 0 and F2 > 0.0:
        # compact copies for the solver
        for c in range(m):
            tmp8[c] = prior8[cidx[c]]
        relc = _v2(work, 0, m, 2)
        for c in range(m):
            relc[c, 0] = rel8[cidx[c], 0]
            relc[c, 1] = rel8[cidx[c], 1]
        _warm_qp(ctc, cidx, m, relc, tmp8, F2, prm[_P_SW], qp_x, qp_z, qp_free, qp_isfree, qp_M,
                 qp_rhs, qp_dots, warm)
        if prm[_P_TWIST] != 0.0 and _twist_prior(prm[_P_TWIST], ctc, cidx, m, qp_x, F2,
                                                 forces, prior8):
            for c in range(m):
                tmp8[c] = prior8[cidx[c]]
            _warm_qp(ctc, cidx, m, relc, tmp8, F2, prm[_P_SW], qp_x, qp_z, qp_free, qp_isfree,
                     qp_M, qp_rhs, qp_dots, warm)
        if m == 8:
            sx = _sum8(qp_x)
        else:
            sx = _sum_seq(qp_x, m)
        if sx > 0:
            f = F2 / sx
            for c in range(m):
                qp_x[c] = qp_x[c] * f
        for c in range(m):
            forces[cidx[c]] = qp_x[c]


@njit_nort
def _twist_prior(kt, ctc, cidx, m, qp_x, F2, forces, prior8):
    """Add the contact twist (``VFSConfig.contact_twist`` ``kt``) of the split ``qp_x``
    (its ``m`` corners ``cidx``, scaled to ``F2``) to the prior ``prior8`` of each sole
    whose four corners are in contact: ``f1 - f2 - f3 + f4 = kt P R / S`` (``S`` its load,
    ``P`` front minus rear, ``R`` left minus right; corners front-left, front-right,
    rear-left, rear-right). The twist is orthogonal to the load and the centre of
    pressure of a rectangle, so the QP keeps it where no corner goes below 0 and clips
    it where one would. ``forces`` is scratch. False when no prior changed."""
    sx = _sum8(qp_x) if m == 8 else _sum_seq(qp_x, m)
    if not sx > 0:
        return False
    f = F2 / sx
    for k in range(8):
        forces[k] = 0.0
    for c in range(m):
        forces[cidx[c]] = qp_x[c] * f
    changed = False
    for o in (0, 4):
        if not (ctc[o] and ctc[o + 1] and ctc[o + 2] and ctc[o + 3]):
            continue
        f1, f2, f3, f4 = forces[o], forces[o + 1], forces[o + 2], forces[o + 3]
        S = f1 + f2 + f3 + f4
        if S > 0.0:
            q = 0.25 * (kt * (f1 + f2 - f3 - f4) * (f1 - f2 + f3 - f4) / S)
            prior8[o] += q
            prior8[o + 1] -= q
            prior8[o + 2] -= q
            prior8[o + 3] += q
            changed = True
    return changed


@njit_nort(inline="always")
def _warm_qp(ctc, cidx, m, relc, prior, F2, sw, qp_x, qp_z, qp_free, qp_isfree, qp_M, qp_rhs,
             qp_dots, warm):
    """:func:`prior_qp_warm` on the ``m`` corners in contact (``cidx``), guessing the
    last solve's positive corners when the contact pattern is the same."""
    pat = 0
    for k in range(8):
        if ctc[k]:
            pat |= 1 << k
    guess = 0
    if warm[0] == pat:
        for c in range(m):
            if (warm[1] >> cidx[c]) & 1:
                guess |= 1 << c
    mask = prior_qp_warm(relc, prior, F2, sw, m, qp_x, qp_z, qp_free, qp_isfree, qp_M, qp_rhs,
                         qp_dots, guess)
    pos = 0
    for c in range(m):
        if (mask >> c) & 1:
            pos |= 1 << cidx[c]
    warm[0] = pat
    warm[1] = pos


@njit_nort(inline="always")
def _outputs(y, state, forces, pk, ctc, com0, com1, com2, zmp0, zmp1):
    """Write the output row ``y`` (:data:`OUT_COLUMNS`) and keep it in ``state``."""
    for k in range(8):
        y[k] = forces[k]
    y[8] = com0
    y[9] = com1
    y[10] = com2
    for side in range(2):
        b = 4 * side
        tot = ((forces[b] + forces[b + 1]) + forces[b + 2]) + forces[b + 3]
        y[11 + side] = tot
        if tot >= 1.0:
            cx = (((forces[b] * pk[b, 0] + forces[b + 1] * pk[b + 1, 0])
                   + forces[b + 2] * pk[b + 2, 0]) + forces[b + 3] * pk[b + 3, 0])
            cy = (((forces[b] * pk[b, 1] + forces[b + 1] * pk[b + 1, 1])
                   + forces[b + 2] * pk[b + 2, 1]) + forces[b + 3] * pk[b + 3, 1])
            y[13 + 2 * side] = cx / tot
            y[14 + 2 * side] = cy / tot
        else:
            y[13 + 2 * side] = np.nan
            y[14 + 2 * side] = np.nan
    y[17] = 1.0 if (ctc[0] or ctc[1] or ctc[2] or ctc[3]) else 0.0
    y[18] = 1.0 if (ctc[4] or ctc[5] or ctc[6] or ctc[7]) else 0.0
    y[19] = zmp0
    y[20] = zmp1
    y[21] = 1.0
    for k in range(N_OUT):
        state[_S_LAST + k] = y[k]
    state[_S_HAS_LAST] = 1.0
    state[_S_N] += 1.0


@njit_nort(inline="always")
def _unpack(cf, ci):
    nb, nj, nq, ns, order = ci[0], ci[1], ci[2], ci[3], ci[4]
    nbr = nb - 1
    o = 0
    prm = view1d(cf, o, N_PRM)
    o += N_PRM
    body_inertia = _v2(cf, o, nbr, 3)
    o += 3 * nbr
    corner_radius = view1d(cf, o, 8)
    o += 8
    filt_b = _v2(cf, o, 3, order + 1)
    o += 3 * (order + 1)
    filt_a = _v2(cf, o, 3, order + 1)
    o += 3 * (order + 1)
    filt_zi = _v2(cf, o, 3, order)
    o += 3 * order
    body_pos = _v2(cf, o, nb, 3)
    o += 3 * nb
    body_quat = _v2(cf, o, nb, 4)
    o += 4 * nb
    body_ipos = _v2(cf, o, nb, 3)
    o += 3 * nb
    body_iquat = _v2(cf, o, nb, 4)
    o += 4 * nb
    body_mass = view1d(cf, o, nb)
    o += nb
    jnt_axis = _v2(cf, o, nj, 3)
    o += 3 * nj
    jnt_pos = _v2(cf, o, nj, 3)
    o += 3 * nj
    qpos0 = view1d(cf, o, nq)
    o += nq
    site_pos = _v2(cf, o, ns, 3)
    o += 3 * ns
    site_quat = _v2(cf, o, ns, 4)
    i = 5
    iprm = view1d(ci, i, N_IPRM)
    i += N_IPRM
    body_parent = view1d(ci, i, nb)
    i += nb
    body_jntadr = view1d(ci, i, nb)
    i += nb
    body_jntnum = view1d(ci, i, nb)
    i += nb
    body_sameframe = view1d(ci, i, nb)
    i += nb
    jnt_type = view1d(ci, i, nj)
    i += nj
    jnt_qposadr = view1d(ci, i, nj)
    i += nj
    site_body = view1d(ci, i, ns)
    i += ns
    site_sameframe = view1d(ci, i, ns)
    i += ns
    body_order = view1d(ci, i, nb - 1)
    i += nb - 1
    body_kind = view1d(ci, i, nb)
    tree = (body_parent, body_jntadr, body_jntnum, body_sameframe, body_pos, body_quat,
            body_ipos, body_iquat, body_mass, jnt_type, jnt_qposadr, jnt_axis, jnt_pos, qpos0,
            body_order, body_kind)
    sites = (site_body, site_sameframe, site_pos, site_quat)
    return prm, iprm, body_inertia, corner_radius, filt_b, filt_a, filt_zi, tree, sites


@njit_nort
def vfs_step(x, y, state, cf, ci, ws, iws):
    """One sample of the compiled virtual force sensor (callable from other ``@njit`` code).

    Stable signature for callers inside compiled code (e.g. a whole-monitor step):

    Args:
        x: (24,) float64 input row, :data:`IN_COLUMNS` order (NaN where absent).
        y: (22,) float64 output row, :data:`OUT_COLUMNS` order (written).
        state: float64 state of one sensor (:attr:`VFSKernel.state`; updated in place).
        cf, ci: float64 / int64 packed constants (:attr:`VFSKernel.cf`, :attr:`VFSKernel.ci`;
            read only; their layout is internal to this module).
        ws, iws: float64 / int64 scratch (:attr:`VFSKernel.ws`, :attr:`VFSKernel.iws`).

    Returns:
        True for a valid sample; False when the row was not usable (``y`` then repeats
        the last output with ``vfs_valid = 0``, NaN before the first valid sample).

    ``VFSKernel.packed_args()`` gives ``(state, cf, ci, ws, iws)``. No allocation, no
    Python objects; the same function runs behind :meth:`VFSKernel.step` (streaming) and
    :func:`vfs_run` (batch), so both agree bit for bit.
    """
    return _step(x, y, state, cf, ci, ws, iws)


@njit_nort
def vfs_run(X, Y, state, cf, ci, ws, iws):
    """:func:`vfs_step` over every row of ``X`` (T, 24) into ``Y`` (T, 22) in one compiled
    loop (the batch path: the same step as streaming); returns the number of valid
    samples. Arguments after ``X, Y`` as in :func:`vfs_step`."""
    n = 0
    T = X.shape[0]
    front = cf[_P_FRONT_CF] != 0.0
    for t0 in range(0, T, LANES):
        nt = min(LANES, T - t0)
        if front:
            front_rows(X, t0, nt, 0, cf, ci, ws, iws)
        for j in range(nt):
            iws[IW_SLOT] = j
            if _step(X[t0 + j], Y[t0 + j], state, cf, ci, ws, iws):
                n += 1
    iws[IW_SLOT] = -1
    return n


@njit_nort(inline="always")
def front_rows(X, t0, nt, c0, cf, ci, ws, iws):
    """Fill the block of :mod:`grfguard.kernels.front` from rows ``t0 .. t0 + nt - 1`` of
    ``X`` (joint angles in columns ``c0 .. c0 + 11``)."""
    qblk = front_qblk(ws, ci)
    for j in range(nt):
        for k in range(_NJ):
            qblk[j, k] = X[t0 + j, c0 + k]
    front_fill(cf, ci, ws, nt)


@njit_nort(inline="always")
def front_qblk(ws, ci):
    """The block's joint angles (``LANES`` x 12): rows to fill before :func:`front_fill`."""
    return view2d(ws, ws.shape[0] - N_SHARED - front_ws_size(ci[0]), LANES, _NJ)


@njit_nort(inline="always")
def front_fill(cf, ci, ws, nt):
    """The block's poses of its first ``nt`` rows (:func:`grfguard.kernels.front.front_block`);
    a sample ``j`` of them is then stepped with ``iws[IW_SLOT] = j``."""
    front_block(cf, ci, int(cf[_P_FRONT_CF]), int(cf[_P_FRONT_CI]), ci[0], ws, N_SHARED, nt)


# ------------------------------------------------------------------ twin sensor
# A twin sensor (the system layer's: same robot, joints and attitude; other filters, no
# accelerometer) shares the front of the step with the main one: attitude, kinematics,
# stance, odometry, raw rates and angular momentum depend only on the row and on this
# part of the state. While the twin's part equals the main's bit for bit
# (:func:`same_front_state`), the twin takes the main's results (:func:`vfs_step_shared`)
# instead of computing them again; the outputs are the same bits by construction.
_S_FRONT_END = _S_PREVL + 3  # state 1 .. _S_FRONT_END: attitude, anchor, histories, L


@njit_nort(inline="always")
def _pose_range(state, nb, order):
    """Start and end of the previous body poses (momentum finite differences) in
    ``state``."""
    a = _S_FIXED + 15 * order
    return a, a + 12 * (nb - 1)


@njit_nort
def same_front_state(mstate, qstate, ci):
    """Whether the twin's state ``qstate`` equals the main's ``mstate`` in every value the
    front of the step reads (NaN counts as different: then no sharing)."""
    for k in range(1, _S_FRONT_END):
        if mstate[k] != qstate[k]:
            return False
    if mstate[_S_PREVF] == 0.0:  # no previous poses are read
        return True
    a, b = _pose_range(mstate, ci[0], ci[4])
    for k in range(a, b):
        if mstate[k] != qstate[k]:
            return False
    return True


#: Floats at the end of a sensor's state: a twin's split inputs kept while its outputs are
#: not needed (:func:`vfs_step_shared` with ``need`` False), flag first.
N_PEND = 40


@njit_nort
def vfs_step_shared(x, y, state, cf, ci, ws, iws, mstate, mws, need):
    """:func:`vfs_step` of a twin sensor on the row the main sensor (state ``mstate``,
    scratch ``mws``) has just processed as a valid sample, taking the main's front of the
    step. Preconditions (the caller's): :func:`twin_shareable` of the two kernels, and
    :func:`same_front_state` held before the main's step. Without ``need`` the stateless
    end of the step (contact, QP, outputs) is deferred: ``y`` is not written and the
    split's inputs are kept until :func:`resolve_pending` (the next output or an invalid
    sample that repeats it). Returns True."""
    prm, iprm, body_inertia, corner_radius, filt_b, filt_a, filt_zi, tree, sites = _unpack(
        cf, ci)
    nb = ci[0]
    nq = ci[2]
    order = filt_b.shape[1] - 1
    (qpos, xpos, xquat, xmat, xipos, ximat, stc, msub, sxp, sxm, qin, raw, main, v3a, v3b,
     v3c, v3d, pk, tmp8, prior8, rel8, forces, lin, cc, qp_x, qp_z, qp_M, qp_rhs, qp_dots,
     tail) = _scratch_views(ws, nq, nb)
    m = _scratch_views(mws, nq, nb)
    msxp, mraw = m[8], m[11]
    for k in range(1, _S_FRONT_END):
        state[k] = mstate[k]
    a, b = _pose_range(mstate, nb, order)
    # copied through views indexed from 0: with ``range(a, b)`` on the arrays themselves
    # numba's negative-index wraparound made LLVM copy with gathers and scatters (AVX-512
    # ``vscatterqpd`` is microcoded on AMD Zen 4, where the monitor loop ran 4 % slower)
    dst, src = view1d(state, a, b - a), view1d(mstate, a, b - a)
    for k in range(b - a):
        dst[k] = src[k]
    for k in range(9):
        raw[k] = mraw[k]
    sh = _shared_slots(mws)
    com0, com1, com2, ground = sh[4], sh[5], sh[6], sh[3]
    xo = _S_FIXED + 15 * order + 12 * (nb - 1)
    F0, F1, F2, zmp0, zmp1 = _rates_to_zmp(x, state, prm, filt_b, filt_a, filt_zi, raw, main,
                                           v3a, v3b, v3c, v3d, sh[9], sh[10], sh[11], sh[12],
                                           order, prm[_P_G], xo, com0, com1, com2, ground)
    pend = view1d(state, state.shape[0] - N_PEND, N_PEND)
    for k in range(8):
        pend[1 + 3 * k] = msxp[1 + k, 0]
        pend[2 + 3 * k] = msxp[1 + k, 1]
        pend[3 + 3 * k] = msxp[1 + k, 2] - corner_radius[k]
    for k in range(9):
        pend[25 + k] = sh[k]  # pwt, ground, com, stance
    pend[34], pend[35], pend[36], pend[37], pend[38] = F0, F1, F2, zmp0, zmp1
    pend[0] = 1.0
    if need:
        resolve_pending(y, state, cf, ci, ws, iws)
    return True


@njit_nort
def resolve_pending(y, state, cf, ci, ws, iws):
    """The deferred end of a twin's step (:func:`vfs_step_shared`), if any, into ``y``
    and the state's last output."""
    pend = view1d(state, state.shape[0] - N_PEND, N_PEND)
    if pend[0] == 0.0:
        return
    pend[0] = 0.0
    (qpos, xpos, xquat, xmat, xipos, ximat, stc, msub, sxp, sxm, qin, raw, main, v3a, v3b,
     v3c, v3d, pk, tmp8, prior8, rel8, forces, lin, cc, qp_x, qp_z, qp_M, qp_rhs, qp_dots,
     tail) = _scratch_views(ws, ci[2], ci[0])
    for k in range(8):
        pk[k, 0] = pend[1 + 3 * k]
        pk[k, 1] = pend[2 + 3 * k]
        pk[k, 2] = pend[3 + 3 * k]
    _split_outputs(y, state, cf, ws, iws, ci[2], ci[0], pend[25], pend[26], pend[27],
                   pend[28], pend[29], pend[30], pend[31], pend[34], pend[35], pend[36],
                   pend[37], pend[38], pend[32] != 0.0, pend[33] != 0.0)


#: The settings a twin may change without changing the front of the step.
_TWIN_FREE_PRM = (_P_USE_ACC, _P_ACC_VERT, _P_TWIST)


def _check_twist_layout(points_F: np.ndarray) -> None:
    """``VFSConfig.contact_twist`` needs the sole corners front-left, front-right,
    rear-left, rear-right (the twist pattern of :func:`_twist_prior`)."""
    from grfguard.errors import ConfigError

    p = np.asarray(points_F, float)
    if p.shape != (4, 2) or not (np.array_equal(np.sign(p[:, 0]), [1, 1, -1, -1])
                                 and np.array_equal(np.sign(p[:, 1]), [1, -1, 1, -1])):
        raise ConfigError(
            "vfs.contact_twist needs four sensors per sole ordered front-left, front-right, "
            f"rear-left, rear-right; this robot's sole sensors are at {p.tolist()} [m]; "
            "set vfs.contact_twist = 0")


def _filter_design(cfg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(b, a, zi)`` stacked for the rate, fusion and accelerometer low-passes of a
    ``VFSConfig`` (the rate low-pass damped and/or with a lead when set)."""
    from grfguard._iir import butter_lowpass, damped_lowpass, lfilter_zi  # no scipy.signal

    bs, as_, zs = [], [], []
    for i, cut in enumerate((cfg.filter_cutoff, cfg.fusion_cutoff, cfg.acc_cutoff)):
        if i == 0 and (cfg.filter_damping is not None or cfg.filter_lead):
            b, a = damped_lowpass(  # the rate low-pass, damped and/or with a lead
                cut, 1.0 / cfg.dt,
                2**-0.5 if cfg.filter_damping is None else cfg.filter_damping,
                cfg.filter_lead or 0.0)
        else:
            b, a = butter_lowpass(cfg.filter_order, cut, 1.0 / cfg.dt)
        b, a = np.asarray(b, float), np.asarray(a, float)
        bs.append(b)
        as_.append(a)
        zs.append(lfilter_zi(b, a))
    return (np.ascontiguousarray(np.stack(bs)), np.ascontiguousarray(np.stack(as_)),
            np.ascontiguousarray(np.stack(zs)))


def twin_shareable(main: VFSKernel, twin: VFSKernel) -> bool:
    """Whether ``twin`` can take ``main``'s front of the step (:func:`vfs_step_shared`):
    the same model, sites, attitude filter and inputs, the default (non-paper) odometry,
    CoM and split, filters of the same order, and a twin valid whenever the main is (it
    does not read the accelerometer unless the main does)."""
    pm, pt = main.prm, twin.prm
    if (pm[P_KANC] > 0.0 or pm[P_COM_PAPER] != 0.0 or pm[P_SPLIT_PAPER] != 0.0
            or main.order != twin.order or pt[_P_USE_ACC] > pm[_P_USE_ACC]):
        return False
    free = np.zeros(N_PRM, bool)
    free[list(_TWIN_FREE_PRM)] = True
    free[18:_P_ANCHOR_HOLD] = True  # the non-default stages (flags checked above)
    if not np.array_equal(pm[~free], pt[~free]) or not np.array_equal(main.ci, twin.ci):
        return False
    if pm[P_KANC] != pt[P_KANC] or pm[P_COM_PAPER] != pt[P_COM_PAPER] or (
            pm[P_SPLIT_PAPER] != pt[P_SPLIT_PAPER]):
        return False
    # the constants after the filters (tree, sites) and before them (inertia, radii)
    o = N_PRM + main.body_inertia.size + main.corner_radius.size
    f = 3 * (main.order + 1) * 2 + 3 * main.order
    return (np.array_equal(main.cf[N_PRM:o], twin.cf[N_PRM:o])
            and np.array_equal(main.cf[o + f:], twin.cf[o + f:])
            and main.ws.size == twin.ws.size)


_ND = np.ndarray
_F8 = np.dtype(np.float64)
_XST = (8,)
_XSH = (N_IN,)
_YSH = (N_OUT,)


class VFSKernel:
    """Constants, state and scratch of the compiled virtual force sensor.

    Args:
        vfs: A :class:`grfguard.estimate.vfs.VirtualForceSensor` (robot, settings and its
            MuJoCo model are taken from it).
        has_gyro: The input carries the gyro (else the logged attitude is used as is).
        has_ref: The input carries the planned contact (else the lowest-foot fallback).
    """

    def __init__(self, vfs, has_gyro: bool = True, has_ref: bool = True) -> None:
        cfg: VFSConfig = vfs.config
        kin = vfs.kin
        self.config = cfg
        # (from the cached summary of the model: a batch run does not import MuJoCo)
        self.tree = kin.tree() if hasattr(kin, "tree") else TreeModel.from_mujoco(kin.model)
        tm = self.tree
        self.tree_arrays = tm.arrays()
        self.site_arrays = (tm.site_body, tm.site_sameframe, tm.site_pos, tm.site_quat)
        prm = np.zeros(N_PRM)
        prm[_P_DT] = cfg.dt
        prm[_P_KATT] = (cfg.dt / (cfg.attitude_time_constant + cfg.dt)
                        if cfg.attitude_time_constant > 0 else 1.0)
        prm[_P_CH] = cfg.contact_height
        prm[_P_G] = vfs.g
        prm[_P_MASS] = vfs.mass
        prm[_P_KC] = vfs.contact_stiffness
        prm[_P_SW] = math.sqrt(cfg.qp_weight)
        prm[_P_USE_ACC] = float(cfg.use_accelerometer)
        prm[_P_ACC_VERT] = float(cfg.accelerometer_vertical)
        prm[_P_USE_L] = float(cfg.use_angular_momentum)
        prm[_P_KIN] = float(cfg.kinematic_contact)
        prm[_P_HAS_GYRO] = float(has_gyro)
        prm[_P_HAS_REF] = float(has_ref)
        prm[_P_BODY_MASS_SUM] = float(kin.body_mass.sum())
        prm[_P_QIT : _P_QIT + 4] = kin._q_IT
        prm[18:_P_ANCHOR_HOLD] = extra_params(cfg, vfs.points_F)
        prm[_P_ANCHOR_HOLD] = float(cfg.anchor_hold)
        prm[_P_TWIST] = cfg.contact_twist
        if cfg.contact_twist != 0.0:
            _check_twist_layout(vfs.points_F)
        self.prm = prm
        #: Input row layout (:data:`IN_COLUMNS`; the paper's CoM filter also reads the
        #: force sensors and the planned ZMP: :data:`PAPER_IN_COLUMNS`).
        self.in_columns = PAPER_IN_COLUMNS if cfg.com_method == "paper" else IN_COLUMNS
        self.n_in = len(self.in_columns)
        ip = np.zeros(N_IPRM, np.int64)
        ip[_IP_TRUNK] = kin.trunk_id
        ip[_IP_ROOT] = kin.root_qadr
        ip[_IP_JOINTS : _IP_JOINTS + _NJ] = kin.joint_qadr
        ip[_IP_IMU] = kin.imu_site
        ip[_IP_CORNERS : _IP_CORNERS + _NC] = kin.corner_sites
        ip[_IP_SOLES : _IP_SOLES + 2] = kin.sole_sites
        self.iprm = ip
        self.body_inertia = np.ascontiguousarray(kin.body_inertia, dtype=float)
        self.corner_radius = np.ascontiguousarray(kin.corner_radius, dtype=float)
        self.filt_b, self.filt_a, self.filt_zi = _filter_design(cfg)
        self.order = cfg.filter_order
        nb = tm.nbody
        self.state = np.zeros(_state_size(nb - 1, self.order) + N_XSTATE + N_PEND)
        header = np.array([nb, tm.jnt_type.shape[0], tm.nq,
                           tm.site_body.shape[0], self.order], np.int64)
        cf = [prm, self.body_inertia.ravel(), self.corner_radius, self.filt_b.ravel(),
              self.filt_a.ravel(), self.filt_zi.ravel(), tm.body_pos.ravel(),
              tm.body_quat.ravel(), tm.body_ipos.ravel(), tm.body_iquat.ravel(), tm.body_mass,
              tm.jnt_axis.ravel(), tm.jnt_pos.ravel(), tm.qpos0, tm.site_pos.ravel(),
              tm.site_quat.ravel()]
        ci = [header, ip, tm.body_parent, tm.body_jntadr, tm.body_jntnum, tm.body_sameframe,
              tm.jnt_type, tm.jnt_qposadr, tm.site_body, tm.site_sameframe, tm.body_order,
              tm.body_kinds()]
        # the poses eight samples at a time (grfguard.kernels.front): the default sites
        # (the paper's anchor attitude and split read the sites' axes: MuJoCo's order)
        front = None if (prm[P_KANC] > 0.0 or prm[P_SPLIT_PAPER] != 0.0) else front_constants(
            tm, ip[_IP_JOINTS:_IP_JOINTS + _NJ], int(ip[_IP_TRUNK]),
            ip[_IP_IMU:_IP_SOLES + 2], self.body_inertia)
        if front is not None:
            prm[_P_FRONT_CF] = sum(a.size for a in cf)
            prm[_P_FRONT_CI] = sum(a.size for a in ci)
            cf.append(front[0])
            ci.append(front[1])
        self.cf = np.ascontiguousarray(np.concatenate(cf), dtype=float)
        self.ci = np.ascontiguousarray(np.concatenate(ci), dtype=np.int64)
        self._entry = None
        nf = front_ws_size(nb)
        self.ws = np.zeros(2 * tm.nq + 32 * nb + 500 + nf)
        # the block's joint angles: none yet (NaN matches no row)
        self.ws[self.ws.size - N_SHARED - nf:][:N_FRONT_ANGLES] = np.nan
        self.iws = np.zeros(64, np.int64)
        self.iws[IW_SLOT] = -1
        self.reset()

    def reset(self) -> None:
        """Forget all state (as ``VirtualForceSensor.reset``)."""
        self.state[:] = 0.0
        self.state[_S_ANCHOR] = -1.0

    def __getstate__(self) -> dict:
        # the cached machine-code entry point is per process: looked up again after a copy
        return {**self.__dict__, "_entry": None}

    def resync(self) -> None:
        """Forget the finite-difference history only (a continuity break: the next two
        samples have no rate); filters, attitude and odometry keep their state (as the
        monitor's resync of ``VirtualForceSensor``)."""
        self.state[_S_HN] = 0.0
        self.state[_S_PREVF] = 0.0
        self.state[_S_PREVL_OK] = 0.0

    def run_segments(self, X: np.ndarray, starts: np.ndarray) -> np.ndarray:
        """Reset, then every row of ``X`` (T, 24) -> (T, 22), resynced (:meth:`resync`)
        before each row index in ``starts``."""
        self.reset()
        X = np.ascontiguousarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != self.n_in:
            raise LogFormatError(
                f"the compiled virtual force sensor takes a (T, {self.n_in}) array in "
                f"in_columns order; got shape {X.shape} (see grfguard.kernels.vfs.log_to_array)"
            )
        n = X.shape[0]
        Y = np.empty((n, N_OUT))
        cuts = sorted({0, n, *(int(i) for i in starts if 0 < int(i) < n)})
        for a, b in zip(cuts[:-1], cuts[1:], strict=True):
            if a > 0:
                self.resync()
            vfs_run(X[a:b], Y[a:b], *self.packed_args())
        return Y

    def packed_args(self) -> tuple:
        """``(state, cf, ci, ws, iws)``: the arguments after ``x, y`` of
        :func:`vfs_step` / ``X, Y`` of :func:`vfs_run`."""
        return (self.state, self.cf, self.ci, self.ws, self.iws)

    def prepare(self) -> None:
        """The streaming step's machine code (the entry point :meth:`step` calls directly)
        loaded from the cache, or compiled, without a step
        (``VirtualForceSensor.for_log(warm=True)``). The state is untouched."""
        import numba

        args = (np.empty(self.n_in), np.empty(N_OUT), self.state, self.cf, self.ci, self.ws,
                self.iws)
        self._entry = vfs_step.compile(tuple(numba.typeof(a) for a in args))

    def step(self, x: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        """One sample: input row (24,) -> output row (22,) (``y`` is filled if given)."""
        if y is None:
            y = np.empty(N_OUT)
        ep = self._entry
        if (ep is not None and x.__class__ is _ND and y.__class__ is _ND
                and x.dtype is _F8 and y.dtype is _F8 and x.strides == _XST
                and y.strides == _XST and x.shape == _XSH and y.shape == _YSH):
            # fast path: float64 C rows of the right length straight into the machine code
            ep(x, y, self.state, self.cf, self.ci, self.ws, self.iws)
            return y
        x = np.ascontiguousarray(x, dtype=float)
        if x.shape != (self.n_in,) or y.shape != (N_OUT,):
            # the compiled code does not check bounds: refuse wrong shapes here
            raise LogFormatError(
                f"the compiled virtual force sensor takes an input row of shape ({self.n_in},)"
                f" in in_columns order and an output row of shape ({N_OUT},); got {x.shape} "
                f"and {y.shape} (see grfguard.kernels.vfs.IN_COLUMNS / OUT_COLUMNS)"
            )
        args = (x, y, self.state, self.cf, self.ci, self.ws, self.iws)
        ep = self._entry
        if ep is not None and y.flags.c_contiguous and y.dtype == np.float64:
            ep(*args)
            return y
        vfs_step(*args)
        if ep is None and y.flags.c_contiguous and y.dtype == np.float64:
            # the compiled entry point for exactly these argument types skips the
            # dispatcher's type resolution (about 1 us per call)
            import numba

            sig = tuple(numba.typeof(a) for a in args)
            cres = vfs_step.overloads.get(sig)
            self._entry = cres.entry_point if cres is not None else None
        return y

    def run(self, X: np.ndarray) -> np.ndarray:
        """Reset, then every row of ``X`` (T, 24) -> (T, 22)."""
        self.reset()
        X = np.ascontiguousarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != self.n_in:
            raise LogFormatError(
                f"the compiled virtual force sensor takes a (T, {self.n_in}) array in "
                f"in_columns order; got shape {X.shape} (see grfguard.kernels.vfs.log_to_array)"
            )
        Y = np.empty((X.shape[0], N_OUT))
        vfs_run(X, Y, *self.packed_args())
        return Y


#: Output columns (same names and order as ``VFS_OUTPUT_COLUMNS``).
def _out_columns() -> tuple[str, ...]:
    from grfguard.estimate.vfs import VFS_OUTPUT_COLUMNS

    return tuple(VFS_OUTPUT_COLUMNS)


OUT_COLUMNS: tuple[str, ...] = _out_columns()


def log_to_array(log: pd.DataFrame | Mapping[str, np.ndarray],
                 columns: tuple[str, ...] = IN_COLUMNS) -> tuple[np.ndarray, bool, bool]:
    """Input array (T, 24) from a log (``columns``: another layout, e.g.
    :data:`PAPER_IN_COLUMNS`), and whether it has the gyro and the planned contact."""
    import pandas as pd

    cols = log.columns if isinstance(log, pd.DataFrame) else list(log)
    n = len(log) if isinstance(log, pd.DataFrame) else len(next(iter(log.values())))
    X = np.full((n, len(columns)), np.nan)
    for i, c in enumerate(columns):
        if c in cols:
            X[:, i] = np.asarray(log[c], dtype=float)
    has_gyro = all(c in cols for c in IMU_GYRO)
    has_ref = all(c in cols for c in CONTACT_REF)
    return X, has_gyro, has_ref


def vfs_batch(log: pd.DataFrame, vfs=None) -> pd.DataFrame:
    """Compiled ``VirtualForceSensor.for_log(log).run(log)``: same columns and index."""
    import pandas as pd

    from grfguard.estimate.vfs import VirtualForceSensor

    if vfs is None:
        vfs = VirtualForceSensor.for_log(log, warm=False)
    vfs.check_columns(log.columns)
    X, has_gyro, has_ref = log_to_array(log)
    k = VFSKernel(vfs, has_gyro=has_gyro, has_ref=has_ref)
    Y = k.run(X)
    return pd.DataFrame(Y, index=log.index, columns=list(OUT_COLUMNS))


def __getattr__(name: str):
    # the compiled sensor is grfguard.estimate.vfs.VirtualForceSensor itself (it runs this
    # kernel whenever the settings are covered); the old name stays importable
    if name == "CompiledVirtualForceSensor":
        from grfguard.estimate.vfs import VirtualForceSensor

        return VirtualForceSensor
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
