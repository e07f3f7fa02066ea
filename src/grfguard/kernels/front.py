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
* **per sample** (:func:`front_pose`): those rotated by the trunk's attitude.

A sample's poses are taken from the block only when its joint angles are the block's,
bit for bit; else they are computed for it alone, in floats, by the same functions
(each lane's operations are the IEEE operations of the float code, with no fused
multiply-add, so the bits are a lane's). A streamed sample, a batch sample and a sample
whose row was changed after the block was filled get the same bits: streaming and batch
stay identical by construction.

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
from numba.extending import register_jitable

from grfguard.kernels._jit import njit_nort, view1d, view2d
from grfguard.kernels.fk import FREE, HINGE, _mm, _mv, _q2m
from grfguard.kernels.lanes import LANES, lanes2d, lanes_size, lanes_start, splat, vload
from grfguard.kernels.sincos import SINCOS_MAX, _sincos_one, sincos_flat

__all__ = ["front_constants", "front_ws_size", "front_block", "front_pose", "N_FRONT_SITES",
           "FB_COLS", "IW_SLOT"]

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


def front_constants(tm, joint_qadr: np.ndarray, trunk: int, sites: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """``(floats, ints)`` of :func:`front_block` for the tree ``tm``
    (:class:`~grfguard.kernels.fk.TreeModel`) whose joint angles ``joint_qadr`` (their
    qpos addresses, in row order) the rows carry, or None when the tree is not a free
    trunk (body ``trunk`` = 1) with one hinge per other body, parents first.

    Floats: per body (``nb`` rows of :data:`FB_COLS`), then the sites' positions in
    their bodies' axes (``N_FRONT_SITES`` x 3), then each body's zero angle (``nb``).
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
    floats = np.concatenate([fb.ravel(), sp.ravel(), q0])
    ints = np.concatenate([np.asarray(par, np.int64), qcol, sb, kind, same])
    return np.ascontiguousarray(floats), np.ascontiguousarray(ints)


@register_jitable
def front_ws_size(nb):
    """Floats of the block at the end of the sensor's scratch: the joint angles
    (``LANES`` x 12), angles, sines and cosines (3 x ``nb LANES``), the bodies' frames
    and the block's poses (vector arrays), then one sample's frames and poses (floats:
    a sample computed alone)."""
    return (LANES * N_FRONT_Q + 3 * nb * LANES + lanes_size(nb, 12)
            + lanes_size(nb + N_FRONT_SITES, _OUT_COLS) + 12 * nb
            + _OUT_COLS * (nb + N_FRONT_SITES))


@njit_nort(inline="always")
def _views(ws, nb, shared):
    """The block's views into ``ws`` (it ends ``shared`` floats before the end) and the
    offset of ``obuf`` in ``ws``."""
    o = ws.shape[0] - shared - front_ws_size(nb)
    qblk = view2d(ws, o, LANES, N_FRONT_Q)
    o += LANES * N_FRONT_Q
    TH = view1d(ws, o, nb * LANES)
    SN = view1d(ws, o + nb * LANES, nb * LANES)
    CS = view1d(ws, o + 2 * nb * LANES, nb * LANES)
    o += 3 * nb * LANES
    rbuf = view1d(ws, o, lanes_size(nb, 12))
    o += lanes_size(nb, 12)
    obuf = view1d(ws, o, lanes_size(nb + N_FRONT_SITES, _OUT_COLS))
    return qblk, TH, SN, CS, rbuf, obuf, o


@njit_nort(inline="always")
def _single_views(ws, nb, shared):
    """One sample's frames ``(nb, 12)`` and poses ``(nb + N_FRONT_SITES, 12)`` (floats,
    the last part of the block) and the offset of the poses in ``ws``."""
    o = ws.shape[0] - shared - 12 * nb - _OUT_COLS * (nb + N_FRONT_SITES)
    po = o + 12 * nb
    return view2d(ws, o, nb, 12), view2d(ws, po, nb + N_FRONT_SITES, _OUT_COLS), po


@njit_nort(inline="always")
def _consts(cf, ci, fo, io, nb):
    """Views of :func:`front_constants`' arrays in the packed ``cf``/``ci``."""
    FB = view2d(cf, fo, nb, FB_COLS)
    FS = view2d(cf, fo + nb * FB_COLS, N_FRONT_SITES, 3)
    Q0 = view1d(cf, fo + nb * FB_COLS + 3 * N_FRONT_SITES, nb)
    par = view1d(ci, io, nb)
    qcol = view1d(ci, io + nb, nb)
    sb = view1d(ci, io + 2 * nb, N_FRONT_SITES)
    kind = view1d(ci, io + 2 * nb + N_FRONT_SITES, nb)
    same = view1d(ci, io + 3 * nb + N_FRONT_SITES, nb)
    return FB, FS, Q0, par, qcol, sb, kind, same


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
    lanes they repeat): per body its CoM and inertial axes, per site its position."""
    FB, FS, Q0, par, qcol, sb, kind, same = _consts(cf, ci, fo, io, nb)
    qblk, TH, SN, CS, rbuf, obuf, oo = _views(ws, nb, shared)
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
    rbuf[0] = rbuf[0]  # (the vector views borrow the buffers)
    obuf[0] = obuf[0]


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


@njit_nort(inline="always")
def _single(x, cf, ci, fo, io, nb, ws, shared):
    """:func:`front_block` for the row ``x`` alone in floats (each operation the one of a
    lane: the same bits); returns the offset of its poses in ``ws``."""
    FB, FS, Q0, par, qcol, sb, kind, same = _consts(cf, ci, fo, io, nb)
    RX, OUT, po = _single_views(ws, nb, shared)
    for k in range(12):
        RX[1, k] = 1.0 if (k == 0 or k == 4 or k == 8) else 0.0
    for i in range(2, nb):
        c = qcol[i]
        th = x[c] - Q0[i] if c >= 0 else 0.0
        s, co = _sincos_one(th)
        if abs(th) > SINCOS_MAX:
            s, co = math.sin(th), math.cos(th)
        if kind[i] >= 0:
            _pose_unit(i, par[i], kind[i], co, s, FB, RX)
        else:
            _pose_body(i, par[i], co, s, FB, RX)
    _outputs(nb, FB, FS, same, sb, RX, OUT)
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
    qblk, TH, SN, CS, rbuf, obuf, oo = _views(ws, nb, shared)
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
    for s in range(N_FRONT_SITES):
        b = st + (nb + s) * _OUT_COLS * step
        v0, v1, v2 = _mv(r0, r1, r2, r3, r4, r5, r6, r7, r8, ws[b], ws[b + step],
                         ws[b + 2 * step])
        sxp[s, 0], sxp[s, 1], sxp[s, 2] = v0, v1, v2
