"""The whole default monitor as one compiled step: input guard, time guard, continuity,
virtual force sensor, detector, recovery and the output guard.

:func:`monitor_step_packed` is :meth:`grfguard.pipeline.Monitor.update` (method
``default``, no diagnostics) on one row of plain floats, in the same order:

1. input guard (:class:`~grfguard.guard.InputGuard`): values outside their physical range
   (per-column limits ``lims``) and an IMU quaternion whose norm is not 1 become NaN;
2. time guard and continuity (:class:`~grfguard.guard.TimeGuard`,
   :class:`~grfguard.guard.Continuity`): monotone clock, break detection, resync of the
   virtual sensor's rates, settling;
3. the compiled virtual force sensor (:func:`grfguard.kernels.vfs.vfs_step`) or the
   row's precomputed ``vfs_*`` values;
4. the detector and the recovery (:func:`grfguard.kernels.detect.detect_step`);
5. the output guard: an implausible reading's flag is reported as ``spikes``, the
   recovered force kept within the plausible range.

Steps 1-3 are the sample's sensor side (:func:`_sense`), 4-5 its detector side
(:func:`_judge`, after the system layer's corrections); they share state only through the
sample's record. The batch loop (:func:`monitor_run_packed`, :func:`_run_flat`) runs the
sensor side of :data:`PASS_ROWS` rows, then their detector sides: the same compiled
functions on the same values, in an order that changes no result, so streaming and batch
are identical by construction.

Row layouts (:func:`input_columns`, :func:`output_columns`):

* input, virtual sensor inside (33): ``time`` [s], ``force_r1..force_l4`` [N], then
  :data:`grfguard.kernels.vfs.IN_COLUMNS` (joint angles, IMU, planned contact);
* input, precomputed virtual sensor (46): ``time``, ``force_*`` (8), ``contact_ref_r/l``,
  ``vfs_r1..vfs_l4`` [N], ``vfs_total_r/l`` [N], ``contact_est_r/l``, ``vfs_valid``, then
  the estimator inputs the input guard checks (``imu_acc_*``, ``imu_gyro_*``,
  ``imu_quat_*``, ``q_<joint>``; only checked, for the ``system_reason``; NaN if absent);
* output: the 22 :data:`~grfguard.kernels.vfs.OUT_COLUMNS` (virtual sensor inside only),
  then ``flag_<s>`` (0/1) x8, ``kind_<s>`` (a code of
  :data:`~grfguard.kernels.detect.KIND_NAMES`) x8, ``eta_<s>`` [N] x8, ``recovered_<s>``
  [N] x8 and ``system_state`` (a code of :data:`grfguard.guard.SYSTEM_STATES`).
"""

from __future__ import annotations

import math
import operator
from typing import Any

import numpy as np

from grfguard.guard import ESTIMATOR_INPUTS
from grfguard.io.schema import CONTACT_REF, FORCE_COLUMNS, IMU_QUAT, TIME, ZMP_REF
from grfguard.kernels._jit import njit_nort
from grfguard.kernels.detect import (
    FLAG,
    G_PREV_INVALID,
    G_RESET_CLOCK,
    G_STARTED,
    K_SPIKES,
    KIND,
    N_GS,
    P_DT,
    P_FHI,
    P_FLO,
    P_GAPLIM,
    P_SETTLE,
    P_VLO,
    SPIKE,
    ST_GAP,
    ST_INVALID,
    ST_OK,
    ST_SETTLING,
    detect_step,
    new_state,
    reset_state,
    time_guard_step,
)
from grfguard.kernels.front import IW_SLOT
from grfguard.kernels.lanes import LANES
from grfguard.kernels.standing import N_SD, standing_params, standing_reset, standing_step
from grfguard.kernels.system import (
    N_KEEP,
    N_SYSS,
    sys_keep,
    sys_output,
    sys_pre_detect,
    sys_pre_vfs,
    sys_resume,
    sys_twin,
    sys_twin_prepare,
    system_reset,
)
from grfguard.kernels.system import OUT_COLUMNS as SYS_COLUMNS
from grfguard.kernels.vfs import (
    _P_FRONT_CF,
    _S_HN,
    _S_PREVF,
    _S_PREVL_OK,
    IN_COLUMNS,
    OUT_COLUMNS,
    VFSKernel,
    front_fill,
    front_qblk,
    twin_shareable,
    vfs_step,
)
from grfguard.model.robot import SENSOR_NAMES, SIDES

__all__ = ["input_columns", "output_columns", "MonitorKernel", "warm_monitor",
           "monitor_step_packed", "monitor_run_packed", "split_block"]

#: Precomputed virtual-sensor columns of the input row (without a sensor inside).
PRE_VFS_COLUMNS: tuple[str, ...] = (
    *CONTACT_REF, *(f"vfs_{s}" for s in SENSOR_NAMES), "vfs_total_r", "vfs_total_l",
    *(f"contact_est_{s}" for s in SIDES), "vfs_valid",
)
_NV = len(OUT_COLUMNS)
_O_TOT = OUT_COLUMNS.index("vfs_total_r")
_O_CEST = OUT_COLUMNS.index("contact_est_r")
_O_VALID = OUT_COLUMNS.index("vfs_valid")
_I_VFS = 9  # the virtual sensor's input row: xc[_I_VFS : _I_VFS + 24]
_I_REF_VFS = _I_VFS + IN_COLUMNS.index("contact_ref_r")
# What the sensor side of a sample (:func:`_sense`) hands to its detector side
# (:func:`_judge`), besides the cleaned row ``xc`` and the sensor's outputs ``vy``: the
# virtual forces, totals, contacts (estimated, planned), validity, clock, time-guard
# state, break, vibration switch (on, switched now), the raw readings, what the system
# layer keeps back (:func:`~grfguard.kernels.system.sys_keep`).
_R_V, _R_TOT, _R_CEST, _R_CREF = 0, 8, 10, 12
_R_VALID, _R_CLOCK, _R_ST, _R_RESET, _R_ON, _R_NOW, _R_RAW, _R_SYS = (
    14, 15, 16, 17, 18, 19, 20, 28)
N_R = _R_SYS + N_KEEP
# scratch (ws) layout of the detector side: detector scratch 0..71, then own slots
_W_REC, _W_ETA, _W_FLAG, _W_KIND = 72, 80, 88, 96
N_WS = 104
#: Rows per pass of the batch loop (:func:`_run_flat`): the sensor side of this many
#: samples, then their detector side.
PASS_ROWS = 64
# monitor parameters (mp)
_M_MODE, _M_REJECT, _M_QTOL, _M_QIDX = 0, 1, 2, 3
# per-sample extras (ex): rejected, jump, valid, bounded
N_EX = 4


def input_columns(with_vfs: bool, with_system: bool = False) -> tuple[str, ...]:
    """Input row layout of :func:`monitor_step_packed` (with the virtual sensor inside or not;
    with the system layer: ``zmp_ref_x/y`` appended)."""
    extra = ZMP_REF if with_system else ()
    if with_vfs:
        return (TIME, *FORCE_COLUMNS, *IN_COLUMNS, *extra)
    return (TIME, *FORCE_COLUMNS, *PRE_VFS_COLUMNS, *ESTIMATOR_INPUTS, *extra)


def output_columns(with_vfs: bool, with_system: bool = False) -> tuple[str, ...]:
    """Output row layout of :func:`monitor_step_packed` (with the system layer:
    :data:`grfguard.kernels.system.OUT_COLUMNS` appended)."""
    det = (*(f"flag_{s}" for s in SENSOR_NAMES), *(f"kind_{s}" for s in SENSOR_NAMES),
           *(f"eta_{s}" for s in SENSOR_NAMES), *(f"recovered_{s}" for s in SENSOR_NAMES),
           "system_state", *(SYS_COLUMNS if with_system else ()))
    return (*OUT_COLUMNS, *det) if with_vfs else det


@njit_nort(inline="always")
def _input_guard(xin, xc, mp, lims):
    """``InputGuard.clean_row``: ``xc`` = ``xin`` with implausible values NaN; True when
    something was rejected."""
    bad = 0
    for j in range(xin.shape[0]):  # branch-free (most columns are in range)
        q = xin[j]
        out = not math.isnan(q) and not (lims[0, j] <= q and q <= lims[1, j])
        xc[j] = math.nan if out else q
        bad += 1 if out else 0
    rejected = bad != 0
    qi = int(mp[_M_QIDX])
    if mp[_M_REJECT] != 0.0 and qi >= 0:
        nrm = math.sqrt(0.0 + xin[qi] * xin[qi] + xin[qi + 1] * xin[qi + 1]
                        + xin[qi + 2] * xin[qi + 2] + xin[qi + 3] * xin[qi + 3])
        if math.isfinite(nrm) and abs(nrm - 1.0) > mp[_M_QTOL]:
            for j in range(4):
                xc[qi + j] = math.nan
            rejected = True
    return rejected


@njit_nort(inline="always")
def _estimate(xin, xc, mode, v, tot, cest, cref, vstate, cf, ci, vws, viws, vy):
    """The virtual sensor's outputs of the sample (compiled VFS, resynced after a break
    by the caller, or the row's precomputed columns); returns ``valid``
    (``Monitor._valid``)."""
    if mode == 1.0:
        vfs_step(xc[9:9 + 24], vy, vstate, cf, ci, vws, viws)
        for i in range(8):
            v[i] = vy[i]
        for f in range(2):
            tot[f] = vy[_O_TOT + f]
            cest[f] = vy[_O_CEST + f]
            cref[f] = xin[_I_REF_VFS + f]
        return vy[_O_VALID] == 1.0
    for i in range(8):
        v[i] = xc[11 + i]
    fin = True
    for f in range(2):
        cref[f] = xin[9 + f]
        tot[f] = xc[19 + f]
        cest[f] = xc[21 + f]
        fin = fin and math.isfinite(tot[f])
    for i in range(8):
        fin = fin and math.isfinite(v[i])
    flag = xc[23]
    return (flag == 1.0) if math.isfinite(flag) else fin


@njit_nort(inline="always")
def _prepare(gs, prm, clock, st, reset, valid, v, tot, cest):
    """``Monitor._prepare``: range check of the virtual forces (corners from ``P_VLO``,
    foot totals from ``2 P_FLO``), ``Continuity.after`` (its ``prev_invalid``: set by
    :func:`_sense`), unusable virtual outputs set to NaN; returns ``(bounded, state
    code)``."""
    lo = prm[P_FLO]
    hi = prm[P_FHI]
    vlo = prm[P_VLO]
    bounded = True
    for i in range(8):
        if not (math.isnan(v[i]) or (vlo <= v[i] and v[i] <= hi)):
            bounded = False
    for f in range(2):
        if not (math.isnan(tot[f]) or (2 * lo <= tot[f] and tot[f] <= 2 * hi)):
            bounded = False
    if reset:
        gs[G_RESET_CLOCK] = clock
    if valid:
        rc = gs[G_RESET_CLOCK]
        use = not (math.isfinite(rc) and clock - rc < prm[P_SETTLE] - 1e-12)
    else:
        use = False
    use = use and bounded
    if not use:
        for i in range(8):
            v[i] = math.nan
        for f in range(2):
            tot[f] = math.nan
            cest[f] = math.nan
    if st != ST_OK:
        return bounded, st
    if not (valid and bounded):
        return bounded, ST_INVALID
    if not use:
        return bounded, ST_SETTLING
    return bounded, ST_OK


@njit_nort(inline="always")
def _finish(raw, yout, o, ss, prm, oflag, okind, eta, rec):
    """``Monitor._finish``: an implausible reading (``raw``: the row's forces) flagged is
    reported as ``spikes``, the recovered force kept within the plausible range; writes
    the detector columns."""
    lo = prm[P_FLO]
    hi = prm[P_FHI]
    for i in range(8):
        s = ss[i]
        flagged = oflag[i] != 0.0
        xr = raw[i]
        if not math.isnan(xr) and not (lo <= xr and xr <= hi):
            s[SPIKE] = 1.0
        elif not flagged:
            s[SPIKE] = 0.0
        yout[o + i] = 1.0 if flagged else 0.0
        yout[o + 8 + i] = K_SPIKES if (s[SPIKE] != 0.0 and flagged) else okind[i]
        yout[o + 16 + i] = eta[i]
        r = rec[i]
        if not math.isnan(r):
            r = min(max(r, lo), hi)
        yout[o + 24 + i] = r


@njit_nort(inline="always")
def _sense(xin, ex, mp, lims, gs, prm, vstate, cf, ci, vws, viws, xc, vy, r, sy):
    """The sensor side of a sample: input guard, the system layer's IMU corrections,
    time guard and continuity, the virtual sensor (and the twin); what the detector side
    needs goes into ``xc``, ``vy`` and the record ``r`` (:data:`N_R`).

    It reads no state the detector side writes, and that side reads none it writes
    except through ``xc``, ``vy`` and ``r`` (the system layer's through
    :func:`~grfguard.kernels.system.sys_keep`): the batch loop runs this side for
    :data:`PASS_ROWS` samples, then their detector sides, with the bits of
    :func:`monitor_step_packed`, sample after sample."""
    mode = mp[_M_MODE]
    rejected = _input_guard(xin, xc, mp, lims)
    sysp, syss, qstate, qcf, qci, qws, qiws, qy = sy  # ---- system layer (kernels/system.py)
    son = sysp[0] != 0.0
    if son:
        sys_pre_vfs(sysp, syss, xc, cf, ci, vws, viws)
    clock, st, jump = time_guard_step(gs, xin[0], prm[P_DT], prm[P_GAPLIM])
    # Continuity.before
    reset = gs[G_STARTED] != 0.0 and (st == ST_GAP or gs[G_PREV_INVALID] != 0.0)
    gs[G_STARTED] = 1.0
    v = r[_R_V:_R_V + 8]
    tot = r[_R_TOT:_R_TOT + 2]
    cest = r[_R_CEST:_R_CEST + 2]
    cref = r[_R_CREF:_R_CREF + 2]
    if mode == 1.0 and reset:  # Monitor._vfs_resync
        vstate[_S_HN] = 0.0
        vstate[_S_PREVF] = 0.0
        vstate[_S_PREVL_OK] = 0.0
    share = son and mode == 1.0 and sys_twin_prepare(sysp, syss, reset, vstate, qstate, ci)
    valid = _estimate(xin, xc, mode, v, tot, cest, cref, vstate, cf, ci, vws, viws, vy)
    on = now = False
    if son:
        valid, on, now = sys_twin(sysp, syss, xc, share, valid, vy, qy, qstate, qcf, qci,
                                  qws, qiws, vstate, vws, v, tot, cest, _O_TOT, _O_CEST,
                                  _O_VALID)
        sys_keep(syss, r[_R_SYS:_R_SYS + N_KEEP])
    gs[G_PREV_INVALID] = 0.0 if valid else 1.0  # Continuity.after
    r[_R_VALID] = 1.0 if valid else 0.0
    r[_R_CLOCK] = clock
    r[_R_ST] = st
    r[_R_RESET] = 1.0 if reset else 0.0
    r[_R_ON] = 1.0 if on else 0.0
    r[_R_NOW] = 1.0 if now else 0.0
    for i in range(8):
        r[_R_RAW + i] = xin[1 + i]
    ex[0] = 1.0 if rejected else 0.0
    ex[1] = jump


@njit_nort(inline="always")
def _judge(yout, ex, mp, ss, gs, prm, sd, sp, ws, sy, xc, vy, r):
    """The detector side of a sample (after its :func:`_sense`): range checks and
    settling, the system layer's corrections, detector, recovery, standing layer and the
    output guard, into ``yout``."""
    sysp, syss = sy[0], sy[1]
    son = sysp[0] != 0.0
    v = r[_R_V:_R_V + 8]
    tot = r[_R_TOT:_R_TOT + 2]
    cest = r[_R_CEST:_R_CEST + 2]
    cref = r[_R_CREF:_R_CREF + 2]
    valid = r[_R_VALID] != 0.0
    clock = r[_R_CLOCK]
    st = int(r[_R_ST])
    if son:
        sys_resume(sysp, syss, prm, r[_R_SYS:_R_SYS + N_KEEP], r[_R_ON] != 0.0,
                   r[_R_NOW] != 0.0)
    bounded, state = _prepare(gs, prm, clock, st, r[_R_RESET] != 0.0, valid, v, tot, cest)
    if son:
        sys_pre_detect(sysp, syss, ss, gs, xc[1:9], v, tot, cref, cest, sd)
    rec = ws[_W_REC:_W_REC + 8]
    eta = ws[_W_ETA:_W_ETA + 8]
    detect_step(ss, gs, prm, clock, xc[1:9], v, tot, cref, cest, st == ST_GAP, rec, eta, ws)
    oflag = ws[_W_FLAG:_W_FLAG + 8]
    okind = ws[_W_KIND:_W_KIND + 8]
    for i in range(8):
        oflag[i] = ss[i, FLAG]
        okind[i] = ss[i, KIND]
    if sp[0] != 0.0:
        standing_step(sd, sp, xc[1:9], v, tot, cref, cest, oflag, okind, eta, rec)
    o = 0
    if mp[_M_MODE] == 1.0:
        for j in range(_NV):
            yout[j] = vy[j]
        o = _NV
    _finish(r[_R_RAW:_R_RAW + 8], yout, o, ss, prm, oflag, okind, eta, rec)
    yout[o + 32] = state
    if son:
        sys_output(sysp, syss, yout, o + 33)
    ex[2] = 1.0 if valid else 0.0
    ex[3] = 1.0 if bounded else 0.0


class MonitorKernel:
    """State, parameters and scratch of :func:`monitor_step_packed` for one monitor.

    Args:
        prm: Detector parameters (:func:`grfguard.kernels.detect.detect_params`).
        inputs: The monitor's :class:`~grfguard.guard.InputGuard` (physical ranges).
        vfs_kernel: The compiled virtual sensor (None: the rows carry ``vfs_*``).
    """

    def __init__(self, prm: np.ndarray, inputs: Any, vfs_kernel: VFSKernel | None,
                 standing: Any = None, system: Any = None) -> None:
        self.with_vfs = vfs_kernel is not None
        self.sp = standing_params(standing, float(prm[P_DT]))
        self.sd = np.zeros(N_SD)
        standing_reset(self.sd)
        # system layer (kernels/system.py): (monitor, has_gyro, twin VFS kernel or None)
        self.with_system = system is not None
        self.in_cols = input_columns(self.with_vfs, self.with_system)
        # a row's inputs (grfguard.compiled_monitor.update_dict)
        self.row_get = operator.itemgetter(*self.in_cols)
        self.out_cols = output_columns(self.with_vfs, self.with_system)
        self._system_arrays(system, vfs_kernel)
        self.prm = np.ascontiguousarray(prm, dtype=float)
        self.ss, self.gs = new_state()
        n_in = len(self.in_cols)
        lims = np.empty((2, n_in))
        lims[0] = -np.inf
        lims[1] = np.inf
        reject = inputs.config.reject_implausible
        checked = set(self.in_cols) - {TIME, *CONTACT_REF, "vfs_total_r", "vfs_total_l",
                                       "contact_est_r", "contact_est_l", "vfs_valid"}
        if reject:
            for j, c in enumerate(self.in_cols):
                if c not in checked:
                    continue
                lim = inputs.inputs._lim(c) or inputs.forces._lim(c)
                if lim is not None:
                    lims[0, j], lims[1, j] = lim[0], lim[1]
        self.lims = lims
        qidx = self.in_cols.index(IMU_QUAT[0]) if IMU_QUAT[0] in self.in_cols else -1
        self.mp = np.array([1.0 if self.with_vfs else 0.0, 1.0 if reject else 0.0,
                            inputs.inputs.ranges.quat_norm_tol, float(qidx)])
        self.vfs_kernel = vfs_kernel
        if vfs_kernel is None:
            self._vargs = (np.zeros(N_GS), np.zeros(1), np.zeros(1, np.int64), np.zeros(1),
                           np.zeros(1, np.int64))
        self.ws = np.zeros(N_WS)
        self.ex = np.zeros(N_EX)
        self.xbuf = np.zeros(n_in)
        self.ybuf = np.zeros(len(self.out_cols))
        self.xrow = np.zeros(n_in)  # the batch loop's row buffers (monitor_run_packed)
        self.yrow = np.zeros(len(self.out_cols))
        # the batch loop's sample records: cleaned row, sensor outputs, record (_sense)
        self.passrows = np.zeros((PASS_ROWS, n_in + _NV + N_R))
        self.sin = (n_in,)
        self.sout = (len(self.out_cols),)
        self._pack()
        system_reset(self.sysp, self.syss, self.prm, self.qstate)

    def _system_arrays(self, system: Any, vfs_kernel: VFSKernel | None) -> None:
        """The system layer's parameters, state and twin virtual sensor (placeholders when
        the layer is off); the twin takes the main sensor's front of the step when
        :func:`~grfguard.kernels.vfs.twin_shareable`."""
        from grfguard.kernels.system import Y_SHARE, system_params

        self.quiet_kernel = None
        self.vib_config = None
        self.sysp, self.syss = np.zeros(1), np.zeros(N_SYSS)
        if system is not None:
            mon, has_gyro, qk = system
            self.sysp = system_params(mon, self.in_cols, has_gyro)
            self.quiet_kernel = qk
            self.vib_config = mon.vibration.config if mon.vibration is not None else None
        qk = self.quiet_kernel
        if qk is None:
            self.qstate, self.qcf, self.qws = np.zeros(1), np.zeros(1), np.zeros(1)
            self.qci, self.qiws = np.zeros(1, np.int64), np.zeros(1, np.int64)
        else:
            self.qstate, self.qcf, self.qws, self.qci, self.qiws = (
                qk.state, qk.cf, qk.ws, qk.ci, qk.iws)
            if vfs_kernel is not None and self.sysp.size > Y_SHARE:
                self.sysp[Y_SHARE] = 1.0 if twin_shareable(vfs_kernel, qk) else 0.0
        self.qy = np.zeros(_NV)

    # Every array of the step lives in two buffers (floats F, ints I) so that a call from
    # Python converts four arguments, not eighteen (about 2 us less per sample).
    _F_PARTS = ("ex", "mp", "lims", "ss", "gs", "prm", "sd", "sp", "vstate", "cf", "vws",
                "ws", "sysp", "syss", "qstate", "qcf", "qws", "qy", "xrow", "yrow", "passrows")

    def _parts(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        vstate, cf, ci, vws, viws = self.vfs_args()
        named = {"vstate": vstate, "cf": cf, "vws": vws}
        return ([named[n] if n in named else getattr(self, n) for n in self._F_PARTS],
                [ci, viws, self.qci, self.qiws])

    def _pack(self) -> None:
        fparts, iparts = self._parts()
        head = np.zeros(2 * len(fparts) + 1 + 2 * len(iparts), np.int64)
        o = 0
        for j, a in enumerate(fparts):
            head[2 * j], head[2 * j + 1] = o, a.size
            o += a.size
        h = 2 * len(fparts)
        head[h] = len(self.in_cols)
        o = head.size
        for j, a in enumerate(iparts):
            head[h + 1 + 2 * j], head[h + 2 + 2 * j] = o, a.size
            o += a.size
        self.F = np.concatenate([np.asarray(a, float).ravel() for a in fparts])
        self.I = np.concatenate([head, *[np.asarray(a, np.int64).ravel() for a in iparts]])
        self._relink()

    def _relink(self) -> None:
        """Point every state array (this kernel's and the virtual sensor's) into F and I."""
        h = self.I
        views = {}
        for j, n in enumerate(self._F_PARTS):
            views[n] = self.F[h[2 * j]:h[2 * j] + h[2 * j + 1]]
        views["lims"] = views["lims"].reshape(2, len(self.in_cols))
        views["ss"] = views["ss"].reshape(self.ss.shape)
        views["passrows"] = views["passrows"].reshape(PASS_ROWS, -1)
        for n in ("ex", "mp", "lims", "ss", "gs", "prm", "sd", "sp", "ws", "sysp", "syss",
                  "qstate", "qcf", "qws", "qy", "xrow", "yrow", "passrows"):
            setattr(self, n, views[n])
        k = 2 * len(self._F_PARTS) + 1
        ci = self.I[h[k]:h[k] + h[k + 1]]
        viws = self.I[h[k + 2]:h[k + 2] + h[k + 3]]
        self.qci = self.I[h[k + 4]:h[k + 4] + h[k + 5]]
        self.qiws = self.I[h[k + 6]:h[k + 6] + h[k + 7]]
        qk = getattr(self, "quiet_kernel", None)
        if qk is not None:
            qk.state, qk.cf, qk.ws, qk.ci, qk.iws = (self.qstate, self.qcf, self.qws,
                                                     self.qci, self.qiws)
            qk._entry = None
        vk = self.vfs_kernel
        if vk is not None:
            vk.state, vk.cf, vk.ws, vk.ci, vk.iws = (views["vstate"], views["cf"],
                                                     views["vws"], ci, viws)
            vk._entry = None
        self._entry = None

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_entry": None}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.row_get = operator.itemgetter(*self.in_cols)  # (also for older pickles)
        self._relink()  # a pickled view is a copy: share the buffers again

    def reset(self) -> None:
        """A new monitor's state (the virtual sensor's too)."""
        reset_state(self.ss, self.gs)
        standing_reset(self.sd)
        if self.vfs_kernel is not None:
            self.vfs_kernel.reset()
        system_reset(self.sysp, self.syss, self.prm, self.qstate)

    def vfs_args(self) -> tuple:
        if self.vfs_kernel is not None:
            return self.vfs_kernel.packed_args()
        return self._vargs

    def prepare(self) -> None:
        """The streaming step's machine code (its entry point, which :meth:`step` calls
        directly) loaded from the cache, or compiled, without a step: ``Monitor.for_log``
        calls it, so that the first streamed sample costs what the others do. The state is
        untouched."""
        import numba

        args = (np.empty(len(self.in_cols)), np.empty(len(self.out_cols)), self.F, self.I)
        self._entry = monitor_step_packed.compile(tuple(numba.typeof(a) for a in args))

    def step(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """One row (contiguous float64 arrays of the documented lengths)."""
        ep = self._entry
        if ep is not None:
            ep(x, y, self.F, self.I)
            return y
        monitor_step_packed(x, y, self.F, self.I)
        import numba

        sig = tuple(numba.typeof(a) for a in (x, y, self.F, self.I))
        cres = monitor_step_packed.overloads.get(sig)
        self._entry = cres.entry_point if cres is not None else None
        return y

    def run(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every row of ``X`` (T, n_in) from the current state: ``(Y, EX)``."""
        n = X.shape[0]
        Y = np.empty((n, len(self.out_cols)))
        EX = np.empty((n, N_EX))
        monitor_run_packed(np.asarray(X, dtype=float), Y, EX, self.F, self.I)
        return Y, EX


_NF = len(MonitorKernel._F_PARTS)
_HI = 2 * _NF  # header: (offset, size) per float part, n_in, (offset, size) per int part
# each float part's place in the header
(_I_EX, _I_MP, _I_LIMS, _I_SS, _I_GS, _I_PRM, _I_SD, _I_SP, _I_VSTATE, _I_CF, _I_VWS, _I_WS,
 _I_SYSP, _I_SYSS, _I_QSTATE, _I_QCF, _I_QWS, _I_QY, _I_XROW, _I_YROW, _I_PASS) = (
    2 * j for j in range(_NF))


@njit_nort(inline="always")
def _part(F, I, h):
    """The float part whose (offset, size) is at ``I[h]``."""
    return F[I[h]:I[h] + I[h + 1]]


@njit_nort
def _unpack(F, I):
    n_in = I[_HI]
    ss = _part(F, I, _I_SS)
    sy = (_part(F, I, _I_SYSP), _part(F, I, _I_SYSS), _part(F, I, _I_QSTATE),
          _part(F, I, _I_QCF), I[I[_HI + 5]:I[_HI + 5] + I[_HI + 6]], _part(F, I, _I_QWS),
          I[I[_HI + 7]:I[_HI + 7] + I[_HI + 8]], _part(F, I, _I_QY))
    ci = I[I[_HI + 1]:I[_HI + 1] + I[_HI + 2]]
    viws = I[I[_HI + 3]:I[_HI + 3] + I[_HI + 4]]
    return (_part(F, I, _I_EX), _part(F, I, _I_MP), _part(F, I, _I_LIMS).reshape((2, n_in)),
            ss.reshape((8, ss.shape[0] // 8)), _part(F, I, _I_GS), _part(F, I, _I_PRM),
            _part(F, I, _I_SD), _part(F, I, _I_SP), _part(F, I, _I_VSTATE),
            _part(F, I, _I_CF), ci, _part(F, I, _I_VWS), viws, _part(F, I, _I_WS), sy)


@njit_nort
def monitor_step_packed(x, y, F, I):
    """One row ``x`` (:func:`input_columns`) into ``y`` (:func:`output_columns`): its
    sensor side (:func:`_sense`), then its detector side (:func:`_judge`). Every array
    of the step lives in the two buffers of :class:`MonitorKernel` (``F`` floats, ``I``
    ints with the layout header): ``ex`` receives ``(rejected, jump [s], valid,
    bounded)`` of the sample (what the Python side needs for the ``system_reason``
    text); ``mp``: mode (1 = virtual sensor inside), reject implausible, quaternion norm
    tolerance, quaternion column (-1: none); ``lims`` (2, n_in): physical range per input
    column (+-inf: not checked); ``ss``/``gs``/``prm``: detector state and parameters;
    ``sd``/``sp``: the standing layer's (:mod:`grfguard.kernels.standing`; ``sp[0] = 0``:
    off); ``vstate``/``cf``/``ci``/``vws``/``viws``: the virtual sensor's
    (:class:`~grfguard.kernels.vfs.VFSKernel`); ``ws`` (:data:`N_WS`): the detector side's
    scratch; the system layer's ``(sysp, syss, qstate, qcf, qci, qws, qiws, qy)``
    (:mod:`grfguard.kernels.system`; ``sysp[0] = 0``: off); ``passrows``: the samples'
    records (:func:`_sense` to :func:`_judge`).

    It is the batch loop (:func:`_run_flat`) over one row, so streaming and batch run
    one compiled copy of the step (the block kinematics off: the row is posed alone)."""
    ex = _part(F, I, _I_EX).reshape((1, I[_I_EX + 1]))
    zero = I[0] - I[0]  # run-time values, not literals: the batch loop's own signature
    one = zero + 1
    _run_flat(one, x, zero, x.shape[0], one, y, zero, y.shape[0], one, ex, F, I, ex,
              zero != 0)


@njit_nort
def _run_flat(n, Xf, xo, xrs, xcs, Yf, yo, yrs, ycs, EX, F, I, yblk, lanes):
    """:func:`monitor_step_packed` over ``n`` rows read from and written to flat buffers:
    input value ``(k, j)`` at ``Xf[xo + k xrs + j xcs]``, output ``(k, j)`` at
    ``Yf[yo + k yrs + j ycs]`` (any memory order: no copy of the chunk before or after),
    the extras into ``EX[k]``. The rows go in passes of :data:`PASS_ROWS`: the sensor
    side of each (:func:`_sense`, its row read through the kernel's row buffer), then the
    detector side of each (:func:`_judge`); the same bits as :func:`monitor_step_packed`
    row after row, with each side's code and data hot in the cache for a whole pass
    (SURALP: about 10 % less CPU time than whole steps). The rows are written in place
    when the output's rows are contiguous; otherwise a block of ``yblk.shape[0]`` rows is written
    into ``yblk`` and then copied out column by column when the columns are the far-apart
    dimension (a column-major ``Y``, as ``Monitor.run``'s: whole cache lines per column
    instead of one value per column and row; about 10 % less CPU time for
    ``Monitor.run``), row by row otherwise. ``lanes``: the virtual sensor poses
    :data:`LANES` rows at a time (:mod:`grfguard.kernels.front`; off: each row alone,
    the same bits)."""
    ex, mp, lims, ss, gs, prm, sd, sp, vstate, cf, ci, vws, viws, ws, sy = _unpack(F, I)
    m = I[_I_YROW + 1]  # output columns (the size of the row buffer ``yrow``)
    P = _part(F, I, _I_PASS)
    direct = ycs == 1  # rows contiguous: written in place
    nbk = max(1, n) if direct else yblk.shape[0]
    front = lanes and mp[_M_MODE] == 1.0 and cf[_P_FRONT_CF] != 0.0
    xrow = _part(F, I, _I_XROW)
    w = P.shape[0] // PASS_ROWS  # one record: cleaned row, sensor outputs, N_R
    n_in = I[_HI]
    for k0 in range(0, n, nbk):
        r = min(nbk, n - k0)
        for p0 in range(k0, k0 + r, PASS_ROWS):
            p1 = min(p0 + PASS_ROWS, k0 + r)
            _sense_rows(p0, p1, n, Xf, xo, xrs, xcs, EX, xrow, P, front, mp, lims, gs, prm,
                        vstate, cf, ci, vws, viws, sy)
            for k in range(p0, p1):
                if direct:
                    b = yo + k * yrs
                    yout = Yf[b:b + m]
                else:
                    yout = yblk[k - k0]
                q = P[(k - p0) * w:(k - p0 + 1) * w]
                _judge(yout, EX[k], mp, ss, gs, prm, sd, sp, ws, sy, q[:n_in],
                       q[n_in:n_in + _NV], q[n_in + _NV:])
        if not direct:
            _copy_out(yblk, r, m, Yf, yo + k0 * yrs, yrs, ycs)
    if front:
        viws[IW_SLOT] = -1


@njit_nort(inline="always")
def _sense_rows(p0, p1, n, Xf, xo, xrs, xcs, EX, xrow, P, front, mp, lims, gs, prm, vstate,
                cf, ci, vws, viws, sy):
    """The sensor side (:func:`_sense`) of rows ``p0 .. p1 - 1``, each read through the
    row buffer ``xrow``, into the records ``P`` (the front of the virtual sensor's step,
    its poses, :data:`LANES` rows at a time); the kernel's arrays as :func:`_unpack`
    gives them."""
    n_in = xrow.shape[0]
    w = P.shape[0] // PASS_ROWS
    for k in range(p0, p1):
        if front:  # the virtual sensor's poses, LANES rows at a time
            j = k % LANES
            if j == 0:
                _front_rows_flat(Xf, xo + k * xrs, xrs, xcs, min(LANES, n - k), cf, ci, vws)
            viws[IW_SLOT] = j
        b = xo + k * xrs
        for j in range(n_in):
            xrow[j] = Xf[b + j * xcs]
        q = P[(k - p0) * w:(k - p0 + 1) * w]
        _sense(xrow, EX[k], mp, lims, gs, prm, vstate, cf, ci, vws, viws, q[:n_in],
               q[n_in:n_in + _NV], q[n_in + _NV:], sy)


@njit_nort(inline="always")
def _copy_out(yblk, r, m, Yf, b0, yrs, ycs):
    """The first ``r`` rows of the block ``yblk`` to the output from ``Yf[b0]``, column
    by column when the columns are the far-apart dimension, else row by row."""
    if ycs > yrs:
        for j in range(m):
            b = b0 + j * ycs
            for kk in range(r):
                Yf[b + kk * yrs] = yblk[kk, j]
    else:
        for kk in range(r):
            b = b0 + kk * yrs
            for j in range(m):
                Yf[b + j * ycs] = yblk[kk, j]


@njit_nort(inline="always")
def _front_rows_flat(Xf, b, xrs, xcs, nt, cf, ci, vws):
    """The virtual sensor's block (:func:`grfguard.kernels.vfs.front_fill`) from ``nt``
    rows of the flat input starting at ``Xf[b]`` (its joint angles: the VFS input's first
    12 columns, at column :data:`_I_VFS` of the monitor's row)."""
    qblk = front_qblk(vws, ci)
    for j in range(nt):
        for c in range(12):
            qblk[j, c] = Xf[b + j * xrs + (_I_VFS + c) * xcs]
    front_fill(cf, ci, vws, nt)


def _flat(A: np.ndarray) -> tuple[np.ndarray, int, int] | None:
    """A 2-D float64 array as ``(flat, row stride, column stride)``: a 1-D view over its
    memory from its first element (strides in elements); None when that is not possible
    (negative or odd strides, read-only memory, other dtype)."""
    if A.dtype != np.float64 or A.ndim != 2 or not A.flags.writeable or A.size == 0:
        return None
    s0, s1 = A.strides
    if s0 < 0 or s1 < 0 or s0 % 8 or s1 % 8:
        return None
    r, c = s0 // 8, s1 // 8
    span = (A.shape[0] - 1) * r + (A.shape[1] - 1) * c + 1
    return np.lib.stride_tricks.as_strided(A, shape=(span,), strides=(8,)), r, c


_EMPTY = np.zeros(1)
_EMPTY2 = np.zeros((1, 1))
#: Rows per output block of :func:`_run_flat`.
OUT_BLOCK = 1024


def monitor_run_packed(X: np.ndarray, Y: np.ndarray, EX: np.ndarray, F: np.ndarray,
                       I: np.ndarray) -> None:
    """:func:`monitor_step_packed` over every row of ``X`` (rows x inputs) into ``Y``
    (rows x outputs) and ``EX`` (rows x :data:`N_EX`), each float64 in any memory order
    (the batch path: one compiled loop, :func:`_run_flat`, whatever the layouts; no rows:
    the loop is only loaded)."""
    n = X.shape[0]
    if n == 0:
        _run_flat(0, _EMPTY, 0, 0, 0, _EMPTY, 0, 0, 0, np.zeros((1, N_EX)), F, I,
                  np.zeros((1, Y.shape[1])), True)
        return
    fx = _flat(X)
    if fx is None:
        fx = _flat(np.array(X, dtype=float))
    fy = _flat(Y)
    Yw = Y if fy is not None else np.empty(Y.shape)
    if fy is None:
        fy = _flat(Yw)
    EXw = EX if (EX.dtype == np.float64 and EX.flags.c_contiguous and EX.flags.writeable) \
        else np.empty(EX.shape)
    blk = _EMPTY2 if fy[2] == 1 else np.empty((min(n, OUT_BLOCK), Y.shape[1]))
    _run_flat(n, fx[0], 0, fx[1], fx[2], fy[0], 0, fy[1], fy[2], EXw, F, I, blk, True)
    if Yw is not Y:
        Y[...] = Yw
    if EXw is not EX:
        EX[...] = EXw


@njit_nort
def split_block(Y, a, fidx, F, bidx, B, cidx, C):
    """Rows ``0 .. m - 1`` of the loop's block ``Y`` (rows x outputs) into columns
    ``a .. a + m - 1`` of the output rows: ``F[i] = Y[:, fidx[i]]``, ``B[i] = Y[:,
    bidx[i]] != 0`` and ``C[i] = Y[:, cidx[i]]`` as integers (codes: whole numbers, the
    same as numpy's ``astype``); one pass, no temporaries."""
    m = Y.shape[0]
    for i in range(fidx.size):
        j = fidx[i]
        for r in range(m):
            F[i, a + r] = Y[r, j]
    for i in range(bidx.size):
        j = bidx[i]
        for r in range(m):
            B[i, a + r] = Y[r, j] != 0.0
    for i in range(cidx.size):
        j = cidx[i]
        for r in range(m):
            C[i, a + r] = int(Y[r, j])


def warm_monitor() -> None:
    """Compile or load :func:`monitor_step_packed` and :func:`monitor_run_packed` (both
    layouts)."""
    from grfguard.detect.config import MonitorConfig
    from grfguard.estimate.vfs import VirtualForceSensor
    from grfguard.guard import InputGuard
    from grfguard.kernels.detect import detect_params
    from grfguard.model.robot import RobotConfig

    # No log here: the kernels compile for the argument types, so the reference robot and
    # the config's period serve (a monitor built for a log passes the log's rate).
    cfg = MonitorConfig()
    prm = detect_params(cfg)
    robot = RobotConfig()
    guard = InputGuard(robot)
    from grfguard.detect.standing import StandingStage

    for vk in (None, VFSKernel(VirtualForceSensor(robot))):
        k = MonitorKernel(prm, guard, vk, StandingStage(cfg.dt_s, weight_n=robot.weight))
        x = np.full(len(k.in_cols), math.nan)
        k.step(x, np.empty(len(k.out_cols)))
        k.run(x[None, :])
        idx = np.zeros(1, np.int64)  # split_block as grfguard.compiled_monitor calls it
        split_block(np.zeros((1, len(k.out_cols))), 0, idx, np.empty((1, 1)), idx,
                    np.empty((1, 1), dtype=bool), idx, np.empty((1, 1), dtype=np.int64))
