"""The kinematics of the virtual force sensor eight samples at a time.

The sensor's forward kinematics (:func:`grfguard.kernels.vfs._kinematics`) poses the
robot with the trunk at the origin, rotated by the filtered attitude: a chain of 12
hinges per sample, each waiting on its parent (on SURALP, with the attitude filter,
0.74-0.79 µs per sample in a loop of their own, the whole monitor step about 2.1 µs; in
the step the CPU overlapped part of it with other work, and this module saves about 8 %
of the step). Only the attitude depends on the sensor's state; the joint angles come
from the row alone. So the poses are split:

* **base axes, in blocks** (:func:`front_block`): every body's centre of mass and
  inertial axes and the sensor's sites with the trunk at the origin and unrotated, for
  :data:`~grfguard.kernels.lanes.LANES` samples at once in vector lanes (branch-free
  hinge rotations ``L = B0 + c B1 + s B2`` as :class:`grfguard.kernels.rne.HingeTree`'s;
  a unit axis at the body's origin, every SURALP joint, turns two of the parent's
  columns; sines and cosines by :func:`grfguard.kernels.sincos.sincos_flat`), before
  the samples are stepped;
* **the angular momentum's sums, in blocks** (:func:`_pairs`): the sensor's angular
  momentum about the CoM is a backward difference of two consecutive samples' body poses.
  In world axes it needs every body rotated by the attitude first (on SURALP 0.46 µs per
  sample for the rotation and the differences); in the trunk's axes it is
  ``Q (sum K D / (2 dt) - e(M D^T) / dt)`` with ``D = Q^T Q'`` from the trunk's attitudes
  now and before, and ``M`` (9 floats), ``K`` (27) sums over the bodies of the two
  samples' base-axes poses: joint angles only, so computed in the lanes with the poses
  (each lane against the lane before it, the first against the last row of the block
  before), leaving about 150 operations per sample;
* **per sample** (:func:`front_trunk`): the sites and the CoM rotated by the trunk's
  attitude, and the sums' place for :func:`grfguard.kernels.vfs._momentum_front`
  (:func:`front_pose` rotates every body: for tests and other callers).

A sample's poses are taken from the block only when its joint angles are the block's,
bit for bit, and its sums only when the previous valid sample's angles are also those of
the row before it in the block; else they are computed for it alone, in floats, by the
same functions (each lane's operations are the IEEE operations of the float code, with
no fused multiply-add, so the bits are a lane's). The single poses are kept for the next
sample, so a streamed sample computes its own poses and not its predecessor's. A
streamed sample, a batch sample and a sample whose row was changed after the block was
filled get the same bits: streaming and batch stay identical by construction. Against
the world-axes differences (the pure-Python reference's order) the momentum differs by
rounding (about 3e-13 of its size on random poses); the sensor's forces by up to
about 1e-9 N (``tests/test_kernels_vfs.py``).

Used for trees of one free joint (the trunk, body 1) and one hinge per other body, and
the default settings' sites (positions only: the paper's anchor attitude and split, which
read the sites' axes, keep MuJoCo's order of :mod:`grfguard.kernels.fk`). The poses agree
with MuJoCo's to about 1e-15 m (``tests/test_kernels_front.py``).

Layouts: the constants (:func:`front_constants`) go into the sensor's packed ``cf``/``ci``
at the offsets ``prm[P_FRONT_CF]``, ``prm[P_FRONT_CI]`` (0: not used); the block lives at
the end of the float scratch ``ws`` (:func:`front_ws_size` floats before the shared
slots), its slot in the int scratch (``iws[IW_SLOT]``: the sample's lane, -1 none).
"""

from __future__ import annotations

import math

import numpy as np
from numba.extending import overload, register_jitable

from grfguard.kernels._jit import njit_nort, view1d, view2d
from grfguard.kernels.fk import FREE, HINGE, _mm, _mv, _q2m
from grfguard.kernels.lanes import (
    LANES,
    VecType,
    lane,
    lanes2d,
    lanes_size,
    lanes_start,
    shift_in,
    splat,
    vload,
)
from grfguard.kernels.sincos import SINCOS_MAX, _sincos_one, sincos_flat

__all__ = ["front_constants", "front_ws_size", "front_block", "front_pose", "front_trunk",
           "N_FRONT_SITES", "N_FRONT_ANGLES", "NPAIR", "FB_COLS", "IW_SLOT"]

#: Sites the sensor poses: the IMU, the 8 corners, the 2 soles.
N_FRONT_SITES = 11
#: Joint angles per sample (the schema's leg joints).
N_FRONT_Q = 12
#: Floats per body in the constants: ``L``'s ``B0, B1, B2`` (27), the origin offset's
#: ``u0, u1, u2`` (9), the CoM in body axes (3), the inertial axes in body axes (9).
FB_COLS = 48
#: Row of a block's vector array: a body's CoM (3) and inertial axes (9) in base axes.
_OUT_COLS = 12
#: The int scratch's slot entry (``iws``) of the sample being stepped (-1: none).
IW_SLOT = 48


def _quat_mat(q: np.ndarray) -> np.ndarray:
    """3x3 rotation of a quaternion (w, x, y, z), normalised."""
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def front_constants(tm, joint_qadr: np.ndarray, trunk: int, sites: np.ndarray,
                    body_inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """``(floats, ints)`` of :func:`front_block` for the tree ``tm``
    (:class:`~grfguard.kernels.fk.TreeModel`) whose joint angles ``joint_qadr`` (their
    qpos addresses, in row order) the rows carry, or None when the tree is not a free
    trunk (body ``trunk`` = 1) with one hinge per other body, parents first.

    Floats: per body (``nb`` rows of :data:`FB_COLS`), then the sites' positions in
    their bodies' axes (``N_FRONT_SITES`` x 3), each body's zero angle (``nb``), mass
    (``nb``) and principal inertias (``nb`` x 3, from ``body_inertia`` of bodies 1..),
    then the mass of bodies 1.. (one float).
    Ints: each body's parent (``nb``), its joint's column in the row (-1: held at its
    zero angle), each site's body (:data:`N_FRONT_SITES`), each body's kind (``nb``: the
    axis 0, 1, 2 of a unit hinge at the body's origin with the parent's axes, else -1),
    whether its inertial axes are its own (``nb``: 1, else 0)."""
    nb = int(tm.body_parent.shape[0])
    par, jadr, jnum = tm.body_parent, tm.body_jntadr, tm.body_jntnum
    if (trunk != 1 or nb < 3 or int(jnum[1]) != 1 or int(tm.jnt_type[jadr[1]]) != FREE
            or len(sites) != N_FRONT_SITES or len(joint_qadr) != N_FRONT_Q):
        return None
    if any(int(jnum[i]) != 1 or int(tm.jnt_type[jadr[i]]) != HINGE
           or not 1 <= int(par[i]) < i for i in range(2, nb)):
        return None
    col = {int(a): c for c, a in enumerate(joint_qadr)}
    fb = np.zeros((nb, FB_COLS))
    q0 = np.zeros(nb)
    qcol = np.full(nb, -1, np.int64)
    kind = np.full(nb, -1, np.int64)
    same = np.zeros(nb, np.int64)
    for i in range(1, nb):
        fb[i, 36:39] = tm.body_ipos[i]
        fb[i, 39:48] = _quat_mat(tm.body_iquat[i]).ravel()
        same[i] = int(np.array_equal(tm.body_iquat[i], [1.0, 0.0, 0.0, 0.0]))
        if i == 1:
            continue
        j = int(jadr[i])
        a = np.asarray(tm.jnt_axis[j], float)
        a = a / np.linalg.norm(a)
        jp = np.asarray(tm.jnt_pos[j], float)
        O = _quat_mat(tm.body_quat[i])
        K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
        B0 = O @ np.outer(a, a)
        B1, B2 = O - B0, O @ K
        fb[i, 0:27] = np.concatenate([B0.ravel(), B1.ravel(), B2.ravel()])
        fb[i, 27:36] = np.concatenate([tm.body_pos[i] + O @ jp - B0 @ jp, -B1 @ jp, -B2 @ jp])
        adr = int(tm.jnt_qposadr[j])
        q0[i] = float(tm.qpos0[adr])
        qcol[i] = col.get(adr, -1)
        unit = [k for k in range(3) if np.array_equal(tm.jnt_axis[j], np.eye(3)[k])]
        if (unit and np.array_equal(tm.body_quat[i], [1.0, 0.0, 0.0, 0.0])
                and not np.any(tm.jnt_pos[j])):
            kind[i] = unit[0]
    sb = np.array([int(tm.site_body[s]) for s in sites], np.int64)
    if (sb < 1).any():
        return None
    sp = np.array([tm.site_pos[s] for s in sites], float)
    inertia = np.zeros((nb, 3))
    inertia[1:] = np.asarray(body_inertia, float).reshape(nb - 1, 3)
    mass = np.asarray(tm.body_mass, float)
    floats = np.concatenate([fb.ravel(), sp.ravel(), q0, mass, inertia.ravel(),
                             [float(mass[1:].sum())]])
    ints = np.concatenate([np.asarray(par, np.int64), qcol, sb, kind, same])
    return np.ascontiguousarray(floats), np.ascontiguousarray(ints)


#: Floats of the trunk-frame sums of a sample (:func:`_pairs`): the CoM of bodies 1..
#: (3), ``M`` (3 x 3) and ``K`` (3 x 3 x 3) of the angular momentum.
NPAIR = 39
#: Leading floats of the block that hold joint angles (NaN at the start: no row matches):
#: the block's rows, the row before them, the block's last row (the carry), the row of
#: the kept single poses.
N_FRONT_ANGLES = (LANES + 3) * N_FRONT_Q


@register_jitable
def front_ws_size(nb):
    """Floats of the block at the end of the sensor's scratch: joint angles
    (:data:`N_FRONT_ANGLES`), angles, sines and cosines (3 x ``nb LANES``), the bodies'
    frames, the block's poses, its previous rows' poses and its trunk-frame sums (vector
    arrays), the carry's poses (floats), then one sample's frames, poses and sums and the
    kept single poses (floats: a sample computed alone)."""
    return (N_FRONT_ANGLES + 3 * nb * LANES + lanes_size(nb, 12)
            + lanes_size(nb + N_FRONT_SITES, _OUT_COLS) + lanes_size(nb, _OUT_COLS)
            + lanes_size(1, NPAIR) + _OUT_COLS * nb + 12 * nb
            + 2 * _OUT_COLS * (nb + N_FRONT_SITES) + NPAIR)


@njit_nort(inline="always")
def _views(ws, nb, shared):
    """The block's views into ``ws`` (it ends ``shared`` floats before the end) and the
    offsets of ``obuf`` and ``abuf`` in ``ws``."""
    o = ws.shape[0] - shared - front_ws_size(nb)
    qblk = view2d(ws, o, LANES, N_FRONT_Q)
    o += N_FRONT_ANGLES
    TH = view1d(ws, o, nb * LANES)
    SN = view1d(ws, o + nb * LANES, nb * LANES)
    CS = view1d(ws, o + 2 * nb * LANES, nb * LANES)
    o += 3 * nb * LANES
    rbuf = view1d(ws, o, lanes_size(nb, 12))
    o += lanes_size(nb, 12)
    obuf = view1d(ws, o, lanes_size(nb + N_FRONT_SITES, _OUT_COLS))
    oo = o
    o += lanes_size(nb + N_FRONT_SITES, _OUT_COLS)
    pbuf = view1d(ws, o, lanes_size(nb, _OUT_COLS))
    o += lanes_size(nb, _OUT_COLS)
    abuf = view1d(ws, o, lanes_size(1, NPAIR))
    return qblk, TH, SN, CS, rbuf, obuf, oo, pbuf, abuf, o


@njit_nort(inline="always")
def _angle_rows(ws, nb, shared):
    """The joint angles of the row before the block, of the carry and of the kept single
    poses (each a (1, 12) array)."""
    o = ws.shape[0] - shared - front_ws_size(nb) + LANES * N_FRONT_Q
    return (view2d(ws, o, 1, N_FRONT_Q), view2d(ws, o + N_FRONT_Q, 1, N_FRONT_Q),
            view2d(ws, o + 2 * N_FRONT_Q, 1, N_FRONT_Q))


@njit_nort(inline="always")
def _single_views(ws, nb, shared):
    """One sample's frames ``(nb, 12)``, poses ``(nb + N_FRONT_SITES, 12)``, the kept
    single poses (same shape), the sums (``NPAIR``) and the carry's poses ``(nb, 12)``
    (floats, the last part of the block), and the offsets of the poses and sums in
    ``ws``."""
    ns = nb + N_FRONT_SITES
    o = ws.shape[0] - shared - _OUT_COLS * nb - 12 * nb - 2 * _OUT_COLS * ns - NPAIR
    carry = view2d(ws, o, nb, _OUT_COLS)
    o += _OUT_COLS * nb
    RX = view2d(ws, o, nb, 12)
    po = o + 12 * nb
    OUT = view2d(ws, po, ns, _OUT_COLS)
    KEEP = view2d(ws, po + _OUT_COLS * ns, ns, _OUT_COLS)
    pa = po + 2 * _OUT_COLS * ns
    return RX, OUT, po, KEEP, view2d(ws, pa, 1, NPAIR), pa, carry


@njit_nort(inline="always")
def _consts(cf, ci, fo, io, nb):
    """Views of :func:`front_constants`' arrays in the packed ``cf``/``ci``."""
    FB = view2d(cf, fo, nb, FB_COLS)
    o = fo + nb * FB_COLS
    FS = view2d(cf, o, N_FRONT_SITES, 3)
    o += 3 * N_FRONT_SITES
    Q0 = view1d(cf, o, nb)
    FM = view1d(cf, o + nb, nb)
    FI = view2d(cf, o + 2 * nb, nb, 3)
    msum = cf[o + 5 * nb]
    par = view1d(ci, io, nb)
    qcol = view1d(ci, io + nb, nb)
    sb = view1d(ci, io + 2 * nb, N_FRONT_SITES)
    kind = view1d(ci, io + 2 * nb + N_FRONT_SITES, nb)
    same = view1d(ci, io + 3 * nb + N_FRONT_SITES, nb)
    return FB, FS, Q0, par, qcol, sb, kind, same, FM, FI, msum


@njit_nort(inline="always")
def _pose_body(i, p, c, s, FB, RX):
    """Body ``i``'s rotation ``RX[i, 0:9]`` and origin ``RX[i, 9:12]`` from its parent
    ``p``'s and its hinge's ``cos``, ``sin`` (vectors), in base axes."""
    L = (FB[i, 0] + c * FB[i, 9] + s * FB[i, 18], FB[i, 1] + c * FB[i, 10] + s * FB[i, 19],
         FB[i, 2] + c * FB[i, 11] + s * FB[i, 20], FB[i, 3] + c * FB[i, 12] + s * FB[i, 21],
         FB[i, 4] + c * FB[i, 13] + s * FB[i, 22], FB[i, 5] + c * FB[i, 14] + s * FB[i, 23],
         FB[i, 6] + c * FB[i, 15] + s * FB[i, 24], FB[i, 7] + c * FB[i, 16] + s * FB[i, 25],
         FB[i, 8] + c * FB[i, 17] + s * FB[i, 26])
    u0 = FB[i, 27] + c * FB[i, 30] + s * FB[i, 33]
    u1 = FB[i, 28] + c * FB[i, 31] + s * FB[i, 34]
    u2 = FB[i, 29] + c * FB[i, 32] + s * FB[i, 35]
    d0, d1, d2 = _mv(RX[p, 0], RX[p, 1], RX[p, 2], RX[p, 3], RX[p, 4], RX[p, 5], RX[p, 6],
                     RX[p, 7], RX[p, 8], u0, u1, u2)
    RX[i, 9] = RX[p, 9] + d0
    RX[i, 10] = RX[p, 10] + d1
    RX[i, 11] = RX[p, 11] + d2
    (RX[i, 0], RX[i, 1], RX[i, 2], RX[i, 3], RX[i, 4], RX[i, 5], RX[i, 6], RX[i, 7],
     RX[i, 8]) = _mm(RX[p, 0], RX[p, 1], RX[p, 2], RX[p, 3], RX[p, 4], RX[p, 5], RX[p, 6],
                     RX[p, 7], RX[p, 8], L[0], L[1], L[2], L[3], L[4], L[5], L[6], L[7],
                     L[8])


@njit_nort(inline="always")
def _pose_unit(i, p, k, c, s, FB, RX):
    """:func:`_pose_body` of a body of kind ``k`` (a unit hinge about its axis ``k`` at
    its origin, the parent's axes): two of the parent's columns turned, the origin at
    the offset ``u0`` (the other terms of ``L`` and ``u`` are zeros)."""
    d0, d1, d2 = _mv(RX[p, 0], RX[p, 1], RX[p, 2], RX[p, 3], RX[p, 4], RX[p, 5], RX[p, 6],
                     RX[p, 7], RX[p, 8], FB[i, 27], FB[i, 28], FB[i, 29])
    RX[i, 9] = RX[p, 9] + d0
    RX[i, 10] = RX[p, 10] + d1
    RX[i, 11] = RX[p, 11] + d2
    a = 1 if k == 0 else 0  # Rot_k mixes columns a, b: a' = c a + s b, b' = c b - s a
    b = 2 if k != 2 else 1
    if k == 1:
        a, b = 2, 0
    for r in range(3):
        ra, rb = RX[p, 3 * r + a], RX[p, 3 * r + b]
        RX[i, 3 * r + k] = RX[p, 3 * r + k]
        RX[i, 3 * r + a] = c * ra + s * rb
        RX[i, 3 * r + b] = c * rb - s * ra


@njit_nort(inline="always")
def _body_out(i, same, FB, RX, OUT):
    """Body ``i``'s CoM and inertial axes in base axes into ``OUT[i]`` (``same``: its
    inertial axes are its own)."""
    c0, c1, c2 = _mv(RX[i, 0], RX[i, 1], RX[i, 2], RX[i, 3], RX[i, 4], RX[i, 5], RX[i, 6],
                     RX[i, 7], RX[i, 8], FB[i, 36], FB[i, 37], FB[i, 38])
    OUT[i, 0] = RX[i, 9] + c0
    OUT[i, 1] = RX[i, 10] + c1
    OUT[i, 2] = RX[i, 11] + c2
    if same:
        for k in range(9):
            OUT[i, 3 + k] = RX[i, k]
        return
    for r in range(3):
        a0, a1, a2 = RX[i, 3 * r], RX[i, 3 * r + 1], RX[i, 3 * r + 2]
        for k in range(3):
            OUT[i, 3 + 3 * r + k] = (a0 * FB[i, 39 + k] + a1 * FB[i, 42 + k]
                                     + a2 * FB[i, 45 + k])


@njit_nort
def front_block(cf, ci, fo, io, nb, ws, shared, nt):
    """Poses in base axes of the ``nt`` (1 .. ``LANES``) samples whose joint angles are
    in the block's rows ``qblk[0:nt]`` (rows ``nt..`` are set to the last one's, whose
    lanes they repeat): per body its CoM and inertial axes, per site its position; and
    each sample's trunk-frame sums (:func:`_pairs`) with the row before it: the block's
    previous row, or for the first the last row of the block before (the carry)."""
    FB, FS, Q0, par, qcol, sb, kind, same, FM, FI, msum = _consts(cf, ci, fo, io, nb)
    qblk, TH, SN, CS, rbuf, obuf, oo, pbuf, abuf, ao = _views(ws, nb, shared)
    qbefore, qcarry, qkeep = _angle_rows(ws, nb, shared)
    carry = _single_views(ws, nb, shared)[6]
    for j in range(nt, LANES):
        for k in range(N_FRONT_Q):
            qblk[j, k] = qblk[nt - 1, k]
    for i in range(2, nb):
        c = qcol[i]
        for j in range(LANES):
            TH[(i - 2) * LANES + j] = qblk[j, c] - Q0[i] if c >= 0 else 0.0
    sincos_flat(TH, (nb - 2) * LANES, SN, CS)
    RX = lanes2d(rbuf, nb, 12)
    OUT = lanes2d(obuf, nb + N_FRONT_SITES, _OUT_COLS)
    for k in range(12):
        RX[1, k] = splat(1.0 if (k == 0 or k == 4 or k == 8) else 0.0)
    for i in range(2, nb):
        c, s = vload(CS, (i - 2) * LANES), vload(SN, (i - 2) * LANES)
        if kind[i] >= 0:
            _pose_unit(i, par[i], kind[i], c, s, FB, RX)
        else:
            _pose_body(i, par[i], c, s, FB, RX)
    _outputs(nb, FB, FS, same, sb, RX, OUT)
    # the previous rows' poses: lane 0 the carry, lane j the block's lane j - 1
    PRV = lanes2d(pbuf, nb, _OUT_COLS)
    for i in range(1, nb):
        for k in range(_OUT_COLS):
            v = OUT[i, k]
            PRV[i, k] = shift_in(v, carry[i, k])
            carry[i, k] = lane(v, nt - 1)
    for k in range(N_FRONT_Q):
        qbefore[0, k] = qcarry[0, k]
        qcarry[0, k] = qblk[nt - 1, k]
    _pairs(nb, FM, FI, msum, OUT, PRV, lanes2d(abuf, 1, NPAIR))
    rbuf[0] = rbuf[0]  # (the vector views borrow the buffers)
    obuf[0] = obuf[0]
    pbuf[0] = pbuf[0]
    abuf[0] = abuf[0]


@njit_nort(inline="always")
def _outputs(nb, FB, FS, same, sb, RX, OUT):
    """Every body's CoM and inertial axes (:func:`_body_out`), then the sites'
    positions, from the frames ``RX`` into ``OUT`` (vectors or floats alike)."""
    for i in range(1, nb):
        _body_out(i, same[i] != 0, FB, RX, OUT)
    for s in range(N_FRONT_SITES):
        b = sb[s]
        p0, p1, p2 = _mv(RX[b, 0], RX[b, 1], RX[b, 2], RX[b, 3], RX[b, 4], RX[b, 5],
                         RX[b, 6], RX[b, 7], RX[b, 8], FS[s, 0], FS[s, 1], FS[s, 2])
        OUT[nb + s, 0] = RX[b, 9] + p0
        OUT[nb + s, 1] = RX[b, 10] + p1
        OUT[nb + s, 2] = RX[b, 11] + p2


def _zero(v):  # pragma: no cover (compiled only)
    """A zero of ``v``'s type (a vector or a float)."""


@overload(_zero)
def _ov_zero(v):
    if isinstance(v, VecType):
        return lambda v: splat(0.0)
    return lambda v: 0.0


@njit_nort(inline="always")
def _com(nb, FM, msum, OUT):
    """The CoM of bodies 1.. in base axes from their CoMs ``OUT[i, 0:3]``."""
    c0, c1, c2 = OUT[1, 0] * FM[1], OUT[1, 1] * FM[1], OUT[1, 2] * FM[1]
    for i in range(2, nb):
        c0 += OUT[i, 0] * FM[i]
        c1 += OUT[i, 1] * FM[i]
        c2 += OUT[i, 2] * FM[i]
    return c0 / msum, c1 / msum, c2 / msum


@njit_nort(inline="always")
def _kacc(K, j00, j01, j02, j11, j12, j22, g00, g01, g02, g10, g11, g12, g20, g21, g22):
    """``K`` (27 values, ``K[a, c, l]`` at ``9 a + 3 c + l``) plus one body's terms:
    ``K[a, :, l] -= J[a, :] x G[:, l]`` (``J`` symmetric)."""
    return (K[0] + (j02 * g10 - j01 * g20),
            K[1] + (j02 * g11 - j01 * g21),
            K[2] + (j02 * g12 - j01 * g22),
            K[3] + (j00 * g20 - j02 * g00),
            K[4] + (j00 * g21 - j02 * g01),
            K[5] + (j00 * g22 - j02 * g02),
            K[6] + (j01 * g00 - j00 * g10),
            K[7] + (j01 * g01 - j00 * g11),
            K[8] + (j01 * g02 - j00 * g12),
            K[9] + (j12 * g10 - j11 * g20),
            K[10] + (j12 * g11 - j11 * g21),
            K[11] + (j12 * g12 - j11 * g22),
            K[12] + (j01 * g20 - j12 * g00),
            K[13] + (j01 * g21 - j12 * g01),
            K[14] + (j01 * g22 - j12 * g02),
            K[15] + (j11 * g00 - j01 * g10),
            K[16] + (j11 * g01 - j01 * g11),
            K[17] + (j11 * g02 - j01 * g12),
            K[18] + (j22 * g10 - j12 * g20),
            K[19] + (j22 * g11 - j12 * g21),
            K[20] + (j22 * g12 - j12 * g22),
            K[21] + (j02 * g20 - j22 * g00),
            K[22] + (j02 * g21 - j22 * g01),
            K[23] + (j02 * g22 - j22 * g02),
            K[24] + (j12 * g00 - j02 * g10),
            K[25] + (j12 * g01 - j02 * g11),
            K[26] + (j12 * g02 - j02 * g12))


@njit_nort(inline="always")
def _pairs(nb, FM, FI, msum, OUT, PRV, P):
    """The trunk-frame sums of a sample's angular momentum from its body poses ``OUT``
    and the previous sample's ``PRV`` (base axes; vectors or floats alike) into ``P[0]``:
    the CoM ``c`` (0:3), ``M = sum m (r - c)(r' - c')^T`` (3:12, row-major) and
    ``K[a, c, l] = sum_i sum_d J_ad dv_d/dD_cl`` (12:39, at ``12 + 9 a + 3 c + l``), with
    ``J = E diag(I) E^T`` a body's inertia and ``G = E E'^T`` its rotation step in base
    axes and ``v = vee(G D^T - D G^T)``. For the trunk's attitudes ``Q`` now and ``Q'``
    before and ``D = Q^T Q'`` the angular momentum about the CoM is then
    ``Q (sum K D / (2 dt) - e(M D^T) / dt)`` (``e(N)_a = eps_abc N_bc``), the finite
    differences of the world poses (:func:`grfguard.kernels.vfs._angular_momentum`)."""
    c0, c1, c2 = _com(nb, FM, msum, OUT)
    d0, d1, d2 = _com(nb, FM, msum, PRV)
    P[0, 0], P[0, 1], P[0, 2] = c0, c1, c2
    z = _zero(c0)
    M = (z, z, z, z, z, z, z, z, z)
    K = (z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z)
    for i in range(1, nb):
        m = FM[i]
        u0, u1, u2 = (OUT[i, 0] - c0) * m, (OUT[i, 1] - c1) * m, (OUT[i, 2] - c2) * m
        w0, w1, w2 = PRV[i, 0] - d0, PRV[i, 1] - d1, PRV[i, 2] - d2
        M = (M[0] + u0 * w0, M[1] + u0 * w1, M[2] + u0 * w2, M[3] + u1 * w0, M[4] + u1 * w1,
             M[5] + u1 * w2, M[6] + u2 * w0, M[7] + u2 * w1, M[8] + u2 * w2)
        e00, e01, e02 = OUT[i, 3], OUT[i, 4], OUT[i, 5]
        e10, e11, e12 = OUT[i, 6], OUT[i, 7], OUT[i, 8]
        e20, e21, e22 = OUT[i, 9], OUT[i, 10], OUT[i, 11]
        f00, f01, f02 = PRV[i, 3], PRV[i, 4], PRV[i, 5]
        f10, f11, f12 = PRV[i, 6], PRV[i, 7], PRV[i, 8]
        f20, f21, f22 = PRV[i, 9], PRV[i, 10], PRV[i, 11]
        i0, i1, i2 = FI[i, 0], FI[i, 1], FI[i, 2]
        a00, a01, a02 = e00 * i0, e01 * i1, e02 * i2
        a10, a11, a12 = e10 * i0, e11 * i1, e12 * i2
        a20, a21, a22 = e20 * i0, e21 * i1, e22 * i2
        j00 = a00 * e00 + a01 * e01 + a02 * e02
        j01 = a00 * e10 + a01 * e11 + a02 * e12
        j02 = a00 * e20 + a01 * e21 + a02 * e22
        j11 = a10 * e10 + a11 * e11 + a12 * e12
        j12 = a10 * e20 + a11 * e21 + a12 * e22
        j22 = a20 * e20 + a21 * e21 + a22 * e22
        g00, g10, g20 = _mv(e00, e01, e02, e10, e11, e12, e20, e21, e22, f00, f01, f02)
        g01, g11, g21 = _mv(e00, e01, e02, e10, e11, e12, e20, e21, e22, f10, f11, f12)
        g02, g12, g22 = _mv(e00, e01, e02, e10, e11, e12, e20, e21, e22, f20, f21, f22)
        K = _kacc(K, j00, j01, j02, j11, j12, j22, g00, g01, g02, g10, g11, g12, g20, g21,
                  g22)
    for k in range(9):
        P[0, 3 + k] = M[k]
    for k in range(27):
        P[0, 12 + k] = K[k]


@njit_nort(inline="always")
def _single_at(q, FB, FS, Q0, par, qcol, sb, kind, same, RX, OUT):
    """:func:`front_block`'s poses for the joint angles ``q`` (a row's first 12 values)
    alone in floats into ``OUT`` (each operation the one of a lane: the same bits)."""
    for k in range(12):
        RX[1, k] = 1.0 if (k == 0 or k == 4 or k == 8) else 0.0
    for i in range(2, _nb_of(RX)):
        c = qcol[i]
        th = q[c] - Q0[i] if c >= 0 else 0.0
        s, co = _sincos_one(th)
        if abs(th) > SINCOS_MAX:
            s, co = math.sin(th), math.cos(th)
        if kind[i] >= 0:
            _pose_unit(i, par[i], kind[i], co, s, FB, RX)
        else:
            _pose_body(i, par[i], co, s, FB, RX)
    _outputs(_nb_of(RX), FB, FS, same, sb, RX, OUT)


@njit_nort(inline="always")
def _nb_of(RX):
    """Bodies of a frames array."""
    return RX.shape[0]


@njit_nort(inline="always")
def _single(x, cf, ci, fo, io, nb, ws, shared):
    """:func:`front_block` for the row ``x`` alone in floats (each operation the one of a
    lane: the same bits); returns the offset of its poses in ``ws``."""
    FB, FS, Q0, par, qcol, sb, kind, same, FM, FI, msum = _consts(cf, ci, fo, io, nb)
    RX, OUT, po, KEEP, PA, pa, carry = _single_views(ws, nb, shared)
    _single_at(x, FB, FS, Q0, par, qcol, sb, kind, same, RX, OUT)
    return po


@njit_nort(inline="always")
def _same_angles(x, qblk, j):
    """The row's joint angles ``x[0:12]`` are the block row ``j``'s, bit for bit (a
    signed zero counts; NaN never matches)."""
    for k in range(N_FRONT_Q):
        a, b = x[k], qblk[j, k]
        if not (a == b and (a != 0.0 or math.copysign(1.0, a) == math.copysign(1.0, b))):
            return False
    return True


@njit_nort(inline="always")
def front_pose(x, cf, ci, fo, io, nb, ws, iws, shared, tw, tx, ty, tz, xipos, ximat, sxp):
    """The row ``x``'s body CoMs ``xipos``, inertial axes ``ximat`` (rows 1..) and sites
    ``sxp`` with the trunk at the origin and its attitude the unit quaternion ``t``: from
    the block's lane of the row (``iws[IW_SLOT]``) when its joint angles are the lane's,
    else computed for the row alone (:func:`_single`, the same bits)."""
    qblk, TH, SN, CS, rbuf, obuf, oo, pbuf, abuf, ao = _views(ws, nb, shared)
    j = iws[IW_SLOT]
    if j >= 0 and _same_angles(x, qblk, j):  # pose (r, c) at ws[st + (12 r + c) step]
        st, step = oo + lanes_start(obuf) + j, LANES
    else:
        st, step = _single(x, cf, ci, fo, io, nb, ws, shared), 1
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = _q2m(tw, tx, ty, tz)
    for i in range(1, nb):
        b = st + i * _OUT_COLS * step
        v0, v1, v2 = _mv(r0, r1, r2, r3, r4, r5, r6, r7, r8, ws[b], ws[b + step],
                         ws[b + 2 * step])
        xipos[i, 0], xipos[i, 1], xipos[i, 2] = v0, v1, v2
        for c in range(3):
            m = b + (3 + c) * step
            v0, v1, v2 = _mv(r0, r1, r2, r3, r4, r5, r6, r7, r8, ws[m], ws[m + 3 * step],
                             ws[m + 6 * step])
            ximat[i, c], ximat[i, 3 + c], ximat[i, 6 + c] = v0, v1, v2
    _sites(ws, st, step, nb, r0, r1, r2, r3, r4, r5, r6, r7, r8, sxp)


@njit_nort(inline="always")
def _sites(ws, st, step, nb, r0, r1, r2, r3, r4, r5, r6, r7, r8, sxp):
    """The sites' positions of the poses at ``ws[st]`` (stride ``step``) rotated by the
    row-major ``r`` into ``sxp``."""
    for s in range(N_FRONT_SITES):
        b = st + (nb + s) * _OUT_COLS * step
        v0, v1, v2 = _mv(r0, r1, r2, r3, r4, r5, r6, r7, r8, ws[b], ws[b + step],
                         ws[b + 2 * step])
        sxp[s, 0], sxp[s, 1], sxp[s, 2] = v0, v1, v2


@njit_nort(inline="always")
def front_trunk(x, qprev, has_prev, cf, ci, fo, io, nb, ws, iws, shared, r0, r1, r2, r3, r4,
                r5, r6, r7, r8, sxp):
    """The row ``x``'s sites ``sxp`` with the trunk at the origin and its attitude the
    row-major rotation ``r``, its CoM (3 floats, world axes) and the offset and stride in
    ``ws`` of its trunk-frame sums (:func:`_pairs`) with the previous valid sample, whose
    joint angles are ``qprev`` (-1: ``has_prev`` False, no sums). From the block's lane of
    the row (``iws[IW_SLOT]``) when the lane's angles and the angles before it are the
    rows', else computed for the row alone (the same bits); the single poses are kept for
    the next sample (a streamed sample finds its predecessor's there)."""
    FB, FS, Q0, par, qcol, sb, kind, same, FM, FI, msum = _consts(cf, ci, fo, io, nb)
    qblk, TH, SN, CS, rbuf, obuf, oo, pbuf, abuf, ao = _views(ws, nb, shared)
    qbefore, qcarry, qkeep = _angle_rows(ws, nb, shared)
    RX, OUT, po, KEEP, PA, pa, carry = _single_views(ws, nb, shared)
    j = iws[IW_SLOT]
    lane = j >= 0 and _same_angles(x, qblk, j)
    if lane:
        st, step = oo + lanes_start(obuf) + j, LANES
        pst = ao + lanes_start(abuf) + j
        if has_prev and not (_same_angles(qprev, qblk, j - 1) if j > 0 else
                             _same_angles(qprev, qbefore, 0)):
            lane = False
    else:
        st, step = po, 1
    if not lane:
        pst, pstep = pa, 1
        _single_at(x, FB, FS, Q0, par, qcol, sb, kind, same, RX, OUT)
        if has_prev:
            if not _same_angles(qprev, qkeep, 0):
                _single_at(qprev, FB, FS, Q0, par, qcol, sb, kind, same, RX, KEEP)
            _pairs(nb, FM, FI, msum, OUT, KEEP, PA)
        else:
            c0, c1, c2 = _com(nb, FM, msum, OUT)
            PA[0, 0], PA[0, 1], PA[0, 2] = c0, c1, c2
        for r in range(1, nb):
            for k in range(_OUT_COLS):
                KEEP[r, k] = OUT[r, k]
        for k in range(N_FRONT_Q):
            qkeep[0, k] = x[k]
    else:
        pstep = LANES
    _sites(ws, st, step, nb, r0, r1, r2, r3, r4, r5, r6, r7, r8, sxp)
    c0, c1, c2 = _mv(r0, r1, r2, r3, r4, r5, r6, r7, r8, ws[pst], ws[pst + pstep],
                     ws[pst + 2 * pstep])
    return c0, c1, c2, (pst if has_prev else -1), pstep

