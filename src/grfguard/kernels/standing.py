"""The standing layer (:class:`grfguard.detect.standing.StandingStage`) as a compiled step.

:func:`standing_step` mirrors ``StandingStage.step`` (and the
:class:`~grfguard.detect.standing.StandingDetector` inside it) on plain arrays, in the
same operation order; it edits the detector's per-sensor output (flag, kind code, eta,
recovered) in place. ``tests/test_kernels_detect.py`` checks the compiled monitor
against the Python stages with the layer on.

State ``sd`` (:data:`N_SD` floats) and parameters ``sp`` (:data:`N_SP`, from
:func:`standing_params`).
"""

from __future__ import annotations

import math

import numpy as np

from grfguard.kernels._jit import njit_nort

__all__ = ["N_SD", "N_SP", "standing_params", "standing_reset", "standing_step"]

_K_NONE, _K_DRIFT, _K_OFFSET = 0, 7, 8  # codes of grfguard.kernels.detect.KIND_NAMES
# state
(_DS, _BASE_N, _BASE_SET, _TOT_N, _TOTB_SET, _T) = range(6)
_BASE_SUM, _BASE, _TOT_SUM, _TOT_BASE, _LP, _OVER, _QUIET, _HALF = (
    6, 14, 22, 24, 26, 34, 42, 50)
_FLAGS, _KINDS, _ETA, _HELD, _HELD_KIND, _HELD_ETA, _STAGE = 58, 66, 74, 82, 90, 98, 106
_PREV, _LIFTED = 114, 116
_WAS, _KB, _EB, _DEV, _DEVS, _SORT, _D = 118, 126, 134, 142, 150, 158, 166  # scratch
_XLP, _HELD_GAIN, _HELD_REF, _E_OFF, _E_GAIN = 174, 182, 190, 198, 206
_BB, _LB = 214, 222  # scratch: baseline and level before the sample
N_SD = 230
# parameters
(_S_ON, _S_DT, _S_A, _S_SETTLE, _S_BASELINE, _S_THR, _S_PERSIST, _S_ISO, _S_RISE, _S_SHIFT,
 _S_CLEAR, _S_AHOLD) = range(12)
N_SP = 12
_K_GAIN = 9


def standing_params(stage, dt_s: float) -> np.ndarray:
    """Parameters of :func:`standing_step` from a ``StandingStage`` (None: layer off)."""
    p = np.zeros(N_SP)
    if stage is None:
        return p
    det = stage.detector
    c = det.config
    p[_S_ON] = 1.0
    p[_S_DT] = det.dt_s
    p[_S_A] = det._a
    p[_S_SETTLE], p[_S_BASELINE], p[_S_THR] = c.settle_s, c.baseline_s, det.threshold_n
    p[_S_PERSIST], p[_S_ISO], p[_S_RISE] = c.persist_s, c.isolation_ratio, c.drift_rise_s
    p[_S_SHIFT], p[_S_CLEAR] = c.max_shift_fraction, c.clear_s
    p[_S_AHOLD] = stage._a_hold
    return p


@njit_nort
def _det_reset(sd):
    """``StandingDetector.reset``."""
    for k in range(_DS, _T + 1):
        sd[k] = 0.0
    for i in range(8):
        sd[_BASE_SUM + i] = 0.0
        sd[_BASE + i] = 0.0
        sd[_LP + i] = math.nan
        sd[_XLP + i] = math.nan
        sd[_OVER + i] = 0.0
        sd[_QUIET + i] = 0.0
        sd[_HALF + i] = math.nan
        sd[_FLAGS + i] = 0.0
        sd[_KINDS + i] = _K_NONE
        sd[_ETA + i] = 0.0
    for f in range(2):
        sd[_TOT_SUM + f] = 0.0
        sd[_TOT_BASE + f] = 0.0


@njit_nort
def standing_reset(sd):
    """``StandingStage.reset``."""
    _det_reset(sd)
    for i in range(8):
        sd[_HELD + i] = 0.0
        sd[_HELD_KIND + i] = _K_NONE
        sd[_HELD_ETA + i] = 0.0
        sd[_HELD_GAIN + i] = math.nan
        sd[_HELD_REF + i] = 0.0
        sd[_E_OFF + i] = 0.0
        sd[_E_GAIN + i] = 0.0
        sd[_STAGE + i] = 0.0
    for f in range(2):
        sd[_PREV + f] = 1.0
        sd[_LIFTED + f] = 0.0


@njit_nort
def _shifted(sd, sp, tot):
    """``StandingDetector._shifted``."""
    if not (math.isfinite(tot[0]) and math.isfinite(tot[1])):
        return False
    if sd[_BASE_SET] == 0.0:
        sd[_TOT_SUM] += tot[0]
        sd[_TOT_SUM + 1] += tot[1]
        sd[_TOT_N] += 1.0
        return False
    if sd[_TOTB_SET] == 0.0:
        return False
    lim = sp[_S_SHIFT] * abs(sd[_TOT_BASE] + sd[_TOT_BASE + 1])
    return max(abs(tot[0] - sd[_TOT_BASE]), abs(tot[1] - sd[_TOT_BASE + 1])) > lim


@njit_nort(inline="always")
def _cx(a, i, j):
    """Compare-exchange ``a[i] <= a[j]`` without a branch (selects)."""
    p, q = a[i], a[j]
    lt = q < p
    a[i] = q if lt else p
    a[j] = p if lt else q


@njit_nort
def sort8(a):
    """Sort ``a`` (8,) of values that are not NaN in place (numba's ``sort`` needs its
    runtime, which these per-sample kernels do without): Batcher's 19 compare-exchanges
    (optimal for 8 values) in straight-line selects. Sorted values are the same whatever
    the method; the insertion sort before it branched on the data, and those branches
    were mispredicted (``tests/test_kernels_system.py`` checks every 0/1 input)."""
    _cx(a, 0, 1)
    _cx(a, 2, 3)
    _cx(a, 4, 5)
    _cx(a, 6, 7)
    _cx(a, 0, 2)
    _cx(a, 1, 3)
    _cx(a, 4, 6)
    _cx(a, 5, 7)
    _cx(a, 1, 2)
    _cx(a, 5, 6)
    _cx(a, 0, 4)
    _cx(a, 3, 7)
    _cx(a, 1, 5)
    _cx(a, 2, 6)
    _cx(a, 1, 4)
    _cx(a, 3, 6)
    _cx(a, 2, 4)
    _cx(a, 3, 5)
    _cx(a, 3, 4)


@njit_nort
def _det_update(sd, sp, x, v, ds, tot):
    """``StandingDetector.update`` (flags, kinds, eta in ``sd``)."""
    dt = sp[_S_DT]
    sd[_T] += dt
    if not ds:
        if sd[_DS] > 0:
            _det_reset(sd)
        return
    d = sd[_D:_D + 8]
    for i in range(8):
        d[i] = x[i] - v[i]
    if sd[_BASE_SET] != 0.0 and _shifted(sd, sp, tot):
        _det_reset(sd)
    sd[_DS] += dt
    a = sp[_S_A]
    allfin = True
    for i in range(8):
        fin = math.isfinite(d[i])
        allfin = allfin and fin
        lp = sd[_LP + i]
        if not math.isfinite(lp) and fin:
            sd[_LP + i] = d[i]
            sd[_XLP + i] = x[i]
        elif fin:
            sd[_LP + i] = lp + a * (d[i] - lp)
            sd[_XLP + i] += a * (x[i] - sd[_XLP + i])
    if sd[_DS] < sp[_S_SETTLE]:
        return
    if sd[_BASE_SET] == 0.0:
        if allfin:
            for i in range(8):
                sd[_BASE_SUM + i] += d[i]
            sd[_BASE_N] += 1.0
            _shifted(sd, sp, tot)
        if sd[_BASE_N] * dt >= sp[_S_BASELINE]:
            for i in range(8):
                sd[_BASE + i] = sd[_BASE_SUM + i] / sd[_BASE_N]
            sd[_BASE_SET] = 1.0
            if sd[_TOT_N] != 0.0:
                for f in range(2):
                    sd[_TOT_BASE + f] = sd[_TOT_SUM + f] / sd[_TOT_N]
                sd[_TOTB_SET] = 1.0
        return
    thr = sp[_S_THR]
    dev_s = sd[_DEVS:_DEVS + 8]
    dev = sd[_DEV:_DEV + 8]
    srt = sd[_SORT:_SORT + 8]
    for i in range(8):
        lp = sd[_LP + i]
        dev_s[i] = lp - sd[_BASE + i] if math.isfinite(lp) else 0.0
        dev[i] = abs(dev_s[i])
        srt[i] = dev[i]
    sort8(srt)
    o3, o4 = srt[3], srt[4]
    t = sd[_T]
    for i in range(8):
        flagged = sd[_FLAGS + i] != 0.0
        med = o4 if dev[i] <= o3 else o3
        if dev[i] > 0.5 * thr and not math.isfinite(sd[_HALF + i]):
            sd[_HALF + i] = t
        if dev[i] < 0.25 * thr and not flagged:
            sd[_HALF + i] = math.nan
        over = dev[i] > thr and dev[i] > sp[_S_ISO] * med and not flagged
        sd[_OVER + i] = sd[_OVER + i] + dt if over else 0.0
    for i in range(8):
        if sd[_OVER + i] >= sp[_S_PERSIST] and sd[_FLAGS + i] == 0.0:
            sd[_FLAGS + i] = 1.0
            rise = t - sd[_HALF + i]
            sd[_KINDS + i] = _K_DRIFT if rise > sp[_S_RISE] else _K_OFFSET
    for i in range(8):
        flagged = sd[_FLAGS + i] != 0.0
        quiet = flagged and dev[i] < 0.5 * thr
        sd[_QUIET + i] = sd[_QUIET + i] + dt if quiet else 0.0
        if flagged and sd[_QUIET + i] >= sp[_S_CLEAR]:
            sd[_FLAGS + i] = 0.0
            sd[_KINDS + i] = _K_NONE
            sd[_QUIET + i] = 0.0
            sd[_HALF + i] = math.nan
    for i in range(8):
        sd[_ETA + i] = dev_s[i] if sd[_FLAGS + i] != 0.0 else 0.0


@njit_nort
def _contact(cref, cest):
    c = cref if math.isfinite(cref) else cest
    return math.isfinite(c) and c > 0.5


@njit_nort
def _held(sd, sp, i, xi, vi):
    """``StandingStage._held``: kind code and eta [N] of a held sensor (offset or gain,
    whichever explains the reading better)."""
    eta = sd[_HELD_ETA + i]
    g = sd[_HELD_GAIN + i]
    if sd[_HELD_KIND + i] == _K_GAIN:
        return float(_K_GAIN), (xi - xi / g if math.isfinite(xi) else eta)
    if (math.isfinite(g) and g > 0 and sd[_HELD_KIND + i] == _K_OFFSET
            and math.isfinite(xi) and math.isfinite(vi)):
        ref = vi + sd[_HELD_REF + i]
        a = sp[_S_AHOLD]
        sd[_E_OFF + i] += a * (abs(xi - eta - ref) - sd[_E_OFF + i])
        sd[_E_GAIN + i] += a * (abs(xi / g - ref) - sd[_E_GAIN + i])
        if sd[_E_OFF + i] - sd[_E_GAIN + i] > sp[_S_THR]:
            sd[_HELD_KIND + i] = _K_GAIN
            return float(_K_GAIN), xi - xi / g
    return sd[_HELD_KIND + i], eta


@njit_nort
def standing_step(sd, sp, x, v, tot, cref, cest, oflag, okind, oeta, orec):
    """``StandingStage.step``: edits the output flag/kind code/eta/recovered (8,) of the
    detector and recovery in place."""
    c0 = _contact(cref[0], cest[0])
    c1 = _contact(cref[1], cest[1])
    for i in range(8):
        sd[_WAS + i] = sd[_FLAGS + i]
        sd[_KB + i] = sd[_KINDS + i]
        sd[_EB + i] = sd[_ETA + i]
        sd[_BB + i] = sd[_BASE + i] if sd[_BASE_SET] != 0.0 else math.nan
        sd[_LB + i] = sd[_XLP + i]
    _det_update(sd, sp, x, v, c0 and c1, tot)
    done0 = False
    done1 = False
    for f in range(2):
        cf = c0 if f == 0 else c1
        prev = sd[_PREV + f] != 0.0
        dn = False
        if prev and not cf:
            sd[_LIFTED + f] = 1.0
        elif cf and not prev and sd[_LIFTED + f] != 0.0:
            dn = True
            sd[_LIFTED + f] = 0.0
        sd[_PREV + f] = 1.0 if cf else 0.0
        if f == 0:
            done0 = dn
        else:
            done1 = dn
    standing = sd[_BASE_SET] != 0.0
    for i in range(8):
        if sd[_WAS + i] != 0.0 and not standing and sd[_FLAGS + i] == 0.0:
            sd[_HELD + i] = 1.0
            sd[_HELD_KIND + i] = sd[_KB + i]
            sd[_HELD_ETA + i] = sd[_EB + i]
            load = sd[_LB + i] - sd[_EB + i]
            sd[_HELD_GAIN + i] = sd[_LB + i] / load if load > sp[_S_THR] else math.nan
            sd[_HELD_REF + i] = sd[_BB + i] if math.isfinite(sd[_BB + i]) else 0.0
            sd[_E_OFF + i] = 0.0
            sd[_E_GAIN + i] = 0.0
            sd[_STAGE + i] = 0.0
    for i in range(8):
        if oflag[i] != 0.0:
            sd[_HELD + i] = 0.0
            continue
        f = i // 4
        own = done0 if f == 0 else done1
        other = done1 if f == 0 else done0
        fl = sd[_FLAGS + i] != 0.0
        if sd[_HELD + i] != 0.0 and not fl:
            if sd[_STAGE + i] == 0.0 and own:
                sd[_STAGE + i] = 1.0
            elif sd[_STAGE + i] == 1.0 and other:
                sd[_HELD + i] = 0.0
                continue
        if fl:
            sd[_HELD + i] = 0.0
            kind = sd[_KINDS + i]
            eta = sd[_ETA + i]
        elif sd[_HELD + i] != 0.0:
            kind, eta = _held(sd, sp, i, x[i], v[i])
        else:
            continue
        oflag[i] = 1.0
        okind[i] = kind
        oeta[i] = eta
        xi = x[i]
        orec[i] = xi - eta if math.isfinite(xi) else math.nan
