"""The default detector and the recovery as one compiled step over plain arrays.

:func:`detect_step` is :meth:`grfguard.detect.detector.Detector.step` followed by
:meth:`grfguard.recover.recovery.Recovery.step` on one sample, in the same operation
order (``math.fsum`` included, as :func:`_fsum`), so flags, kinds, onsets and states are
identical and the floats equal to the last bits on the tested walks
(``tests/test_kernels_detect.py`` checks it on the paper scenario, fault-free walks and
the nine fault kinds; a change of the Python detector must be mirrored here).
:func:`detect_run` loops the same step over a log.

State, all ``float64`` (integers and booleans stored exactly):

* ``ss`` (8, :data:`N_SS`): per sensor, the fields of
  :class:`~grfguard.detect.sensor_state.SensorState` (its two fits flattened), the
  recovery memory (hand-over weight, last output, last two readings, low-pass) and the
  pipeline's spike latch; ``source`` and ``kind`` as codes (:data:`SOURCE_NAMES`,
  :data:`KIND_NAMES`);
* ``gs`` (:data:`N_GS`): clock, weight mean, contact timeline, foot-total sums and votes,
  and the time guard and continuity of :mod:`grfguard.guard`.

Parameters ``prm`` (:data:`N_PRM`) are built by :func:`detect_params` from the frozen
configs (:class:`~grfguard.detect.config.MonitorConfig`,
:class:`~grfguard.detect.tuning.DetectTuning`,
:class:`~grfguard.recover.recovery.RecoverTuning`, :class:`~grfguard.guard.GuardConfig`).
"""

from __future__ import annotations

import math

import numpy as np

from grfguard.kernels._jit import njit, njit_nort

__all__ = [
    "KIND_NAMES", "SOURCE_NAMES", "N_SS", "N_GS", "N_PRM", "detect_params", "detect_step",
    "detect_run", "new_state", "reset_state", "time_guard_run", "DetectKernel",
]

_NAN = math.nan

#: ``SensorState.source`` codes.
SOURCE_NAMES = ("", "nan", "const", "swing", "corner", "total")
SRC_NONE, SRC_NAN, SRC_CONST, SRC_SWING, SRC_CORNER, SRC_TOTAL = range(6)
#: ``SensorState.kind`` codes (the ``kind_<s>`` output).
KIND_NAMES = ("none", "dropout", "saturation", "frozen", "stuck", "spikes", "noise", "drift",
              "offset", "gain", "unknown")
(K_NONE, K_DROPOUT, K_SATURATION, K_FROZEN, K_STUCK, K_SPIKES, K_NOISE, K_DRIFT, K_OFFSET,
 K_GAIN, K_UNKNOWN) = range(11)

# ---------------------------------------------------------------- per-sensor state (ss)
(LAST, REP, SWP, SWN, CP, CN, FLAG, SRC, KIND, FT, LA, QV, ETA, GAIN, CV, VAR, CR,
 FN, FST, FSX, FSTT, FSTX, FSXX, FOUT,
 SN, SL, SR, SLL, SLR, SRR, SETA,
 HW, LREC, X1, X2, LP, SPIKE, PAIRS, CHANCE, RUNP, RUNR) = range(41)
N_SS = 41
# ---------------------------------------------------------------- global state (gs)
G_LAST_T, G_WSUM, G_WN = 0, 1, 2
G_CPREV, G_TD, G_LO, G_SWD, G_GUARD = 3, 5, 7, 9, 11  # two each (right, left)
G_GPOS, G_GNEG, G_VOTES = 13, 15, 17  # votes: 17 + 4 f + j
G_STAMP, G_CLOCK = 25, 26  # time guard
G_PREV_INVALID, G_RESET_CLOCK, G_STARTED = 27, 28, 29  # continuity
N_GS = 30
# ---------------------------------------------------------------- parameters (prm)
(P_DT, P_GLIFT, P_GBTD, P_GTD, P_GLOADED, P_CLEAR,
 P_SIG, P_SWK, P_SWH, P_TOTSIG, P_TOTK, P_TOTH, P_CORSIG, P_CORK, P_CORH, P_CONSTN,
 P_CLEVEL, P_CWFRAC, P_GMINSW, P_GLOADSIG, P_GMINSENS, P_OUTSIG, P_FITMIN_N, P_STFITMIN_N,
 P_DRFITMIN_N, P_DRSLOPE, P_DRSLOPESE, P_DRTVAR, P_SPKMINOUT, P_SPKMAXFRAC, P_SPKMAXSCAT,
 P_NOISESCAT, P_GAINCHG, P_GAINMIN, P_STETA, P_ROUNDTOL, P_CLRDROP, P_HOLD_SAT,
 P_CLRCONSTFRAC, P_CLRSPK, P_CLRVALID, P_NCLEAR, P_NCLEAR_SAT,
 P_AFAST, P_ALP, P_RGAINMIN, P_BLEND,
 P_FLO, P_FHI, P_SETTLE, P_GAPLIM, P_CHANCE, P_VLO) = range(53)
N_PRM = 53
#: Scratch floats :func:`detect_step` needs.
N_WS_DETECT = 72

#: System-state codes of :mod:`grfguard.guard` (``SYSTEM_STATES`` order).
ST_OK, ST_GAP, ST_BACK, ST_CONST, ST_MISSING, ST_INVALID, ST_SETTLING = range(7)


def detect_params(config, tuning=None, recover_tuning=None, guard=None,
                  force_range=(-math.inf, math.inf), vfs_force_lo=None) -> np.ndarray:
    """The parameter array of :func:`detect_step` from the frozen configs.

    Args:
        config: :class:`~grfguard.detect.config.MonitorConfig`.
        tuning: :class:`~grfguard.detect.tuning.DetectTuning` (default one if None).
        recover_tuning: :class:`~grfguard.recover.recovery.RecoverTuning`.
        guard: :class:`~grfguard.guard.GuardConfig`.
        force_range: Plausible force range of one sensor's reading ``(lo, hi)`` [N].
        vfs_force_lo: Lowest plausible virtual corner force [N]
            (:attr:`grfguard.guard.InputGuard.vfs_force_lo`; None: ``force_range[0]``).
    """
    from grfguard.detect.tuning import DetectTuning
    from grfguard.guard import GuardConfig
    from grfguard.recover.recovery import RecoverTuning

    tn = tuning if tuning is not None else DetectTuning()
    rt = recover_tuning if recover_tuning is not None else RecoverTuning()
    gd = guard if guard is not None else GuardConfig()
    c, th = config, config.thresholds
    dt = c.dt_s
    p = np.zeros(N_PRM)
    p[P_DT] = dt
    p[P_GLIFT], p[P_GBTD] = c.gate_liftoff_s, c.gate_before_touchdown_s
    p[P_GTD], p[P_GLOADED], p[P_CLEAR] = c.gate_touchdown_s, c.gate_loaded_s, c.clear_s
    p[P_SIG], p[P_SWK], p[P_SWH] = th.sigma_swing_n, th.swing_kappa, th.swing_h
    p[P_TOTSIG], p[P_TOTK], p[P_TOTH] = th.total_sigma, th.total_kappa, th.total_h
    p[P_CORSIG], p[P_CORK], p[P_CORH] = th.corner_sigma, th.corner_kappa, th.corner_h
    p[P_CONSTN] = tn.const_samples(th.const_s, dt)
    p[P_CHANCE] = min(0.5, th.false_alarm_rate_per_hour * c.dt_s / 3600.0 / 8)
    p[P_CLEVEL], p[P_CWFRAC] = tn.contact_level, tn.contact_weight_fraction
    p[P_GMINSW], p[P_GLOADSIG] = tn.guard_min_swing_fraction, tn.guard_load_sigma
    p[P_GMINSENS], p[P_OUTSIG] = tn.guard_min_sensors, tn.outlier_sigma
    p[P_FITMIN_N] = tn.samples(tn.fit_min_s, dt)
    p[P_STFITMIN_N] = tn.samples(tn.stance_fit_min_s, dt)
    p[P_DRFITMIN_N] = tn.samples(tn.drift_fit_min_s, dt)
    p[P_DRSLOPE], p[P_DRSLOPESE] = tn.drift_min_slope_n_per_s, tn.drift_min_slope_se
    p[P_DRTVAR] = tn.drift_min_time_var_s2
    p[P_SPKMINOUT], p[P_SPKMAXFRAC] = tn.spikes_min_outliers, tn.spikes_max_outlier_fraction
    p[P_SPKMAXSCAT], p[P_NOISESCAT] = tn.spikes_max_scatter_sigma, tn.noise_min_scatter_sigma
    p[P_GAINCHG], p[P_GAINMIN] = tn.gain_min_change, tn.gain_min
    p[P_STETA], p[P_ROUNDTOL] = tn.stance_eta_factor, tn.round_value_tol_n
    p[P_CLRDROP] = tn.clear_dropout_fraction
    hold_sat = c.clear_s * tn.clear_saturation_factor
    p[P_HOLD_SAT] = hold_sat
    p[P_CLRCONSTFRAC], p[P_CLRSPK] = tn.clear_const_valid_fraction, tn.clear_spikes_valid_factor
    p[P_CLRVALID] = tn.clear_valid_fraction
    p[P_NCLEAR] = tn.samples(c.clear_s * 1.0, dt)
    p[P_NCLEAR_SAT] = tn.samples(hold_sat, dt)
    p[P_AFAST] = min(1.0, dt / rt.fast_drop_tau_s)
    p[P_ALP] = min(1.0, dt / rt.noise_lowpass_tau_s)
    p[P_RGAINMIN] = rt.gain_min
    p[P_BLEND] = min(1.0, dt / c.blend_s) if c.blend_s > 0 else 1.0
    p[P_FLO], p[P_FHI] = float(force_range[0]), float(force_range[1])
    p[P_VLO] = float(force_range[0] if vfs_force_lo is None else vfs_force_lo)
    p[P_SETTLE] = gd.settle_s
    p[P_GAPLIM] = max(gd.gap_s, gd.gap_periods * dt)
    return p


@njit_nort
def _clear(s):
    """``SensorState.clear`` of one row of ``ss``."""
    s[FLAG] = 0.0
    s[SRC] = SRC_NONE
    s[KIND] = K_NONE
    s[FT] = _NAN
    s[LA] = _NAN
    s[QV] = 0.0
    s[ETA] = 0.0
    s[CV] = _NAN
    s[VAR] = 0.0
    s[CR] = 0.0
    s[GAIN] = _NAN
    for k in range(FN, FOUT + 1):
        s[k] = 0.0
    for k in range(SN, SRR + 1):
        s[k] = 0.0
    s[SETA] = _NAN


@njit_nort
def reset_state(ss, gs):
    """Everything back to the state of a new monitor (detector, recovery, guards)."""
    for i in range(ss.shape[0]):
        s = ss[i]
        s[LAST] = _NAN
        s[REP] = 0.0
        s[SWP] = s[SWN] = s[CP] = s[CN] = 0.0
        _clear(s)
        s[HW] = 0.0
        s[LREC] = 0.0
        s[X1] = s[X2] = s[LP] = _NAN
        s[SPIKE] = 0.0
        s[PAIRS] = 0.0
        s[CHANCE] = 0.0
        s[RUNP] = 0.0
        s[RUNR] = 0.0
    gs[:] = 0.0
    gs[G_LAST_T] = _NAN
    _reset_timeline(gs)
    gs[G_STAMP] = _NAN
    gs[G_CLOCK] = _NAN
    gs[G_RESET_CLOCK] = _NAN


@njit_nort
def _reset_timeline(gs):
    """``ContactTimeline.reset``."""
    for f in range(2):
        gs[G_CPREV + f] = -1.0
        gs[G_TD + f] = _NAN
        gs[G_LO + f] = _NAN
        gs[G_SWD + f] = _NAN
        gs[G_GUARD + f] = 0.0


def new_state() -> tuple[np.ndarray, np.ndarray]:
    """Fresh ``(ss, gs)``."""
    ss = np.zeros((8, N_SS))
    gs = np.zeros(N_GS)
    reset_state(ss, gs)
    return ss, gs


# ---------------------------------------------------------------- exact sums
@njit_nort(inline="always")
def _fsum(vals, n, part):
    """``math.fsum(vals[:n])`` for finite values; ``part`` is scratch of at least ``n``
    floats.

    Fast path: the running sum ``s`` with the exact error of every addition (TwoSum),
    the errors summed the same way; when no error of that second sum is lost, ``s + c``
    equals the exact sum and one rounding of it is the correctly rounded sum, which is
    what ``math.fsum`` returns. Otherwise (errors of very different magnitudes, a zero
    result, not finite) :func:`_fsum_exact`."""
    if n < 2:
        return _fsum_exact(vals, n, part)
    s = vals[0]
    c = 0.0
    lost = 0.0
    for k in range(1, n):
        x = vals[k]
        t = s + x
        bp = t - s
        e = (s - (t - bp)) + (x - bp)
        s = t
        u = c + e
        bq = u - c
        lost += abs((c - (u - bq)) + (e - bq))
        c = u
    r = s + c
    if lost != 0.0 or r == 0.0 or not math.isfinite(r):
        return _fsum_exact(vals, n, part)
    return r


@njit_nort
def _fsum_exact(vals, n, part):
    """``math.fsum(vals[:n])`` (Shewchuk's algorithm with CPython's final rounding) for
    finite values; ``part`` is scratch of at least ``n`` floats."""
    m = 0
    for k in range(n):
        x = vals[k]
        i = 0
        for j in range(m):
            y = part[j]
            if abs(x) < abs(y):
                x, y = y, x
            hi = x + y
            lo = y - (hi - x)
            if lo != 0.0:
                part[i] = lo
                i += 1
            x = hi
        m = i
        part[m] = x
        m += 1
    hi = 0.0
    if m > 0:
        m -= 1
        hi = part[m]
        lo = 0.0
        while m > 0:
            x = hi
            m -= 1
            y = part[m]
            hi = x + y
            yr = hi - x
            lo = y - yr
            if lo != 0.0:
                break
        if m > 0 and ((lo < 0.0 and part[m - 1] < 0.0) or (lo > 0.0 and part[m - 1] > 0.0)):
            y = lo * 2.0
            x = hi + y
            yr = x - hi
            if y == yr:
                hi = x
    return hi


# ---------------------------------------------------------------- gates
@njit_nort(inline="always")
def _expected_swing(gs, f):
    d = gs[G_SWD + f]
    return d if math.isfinite(d) else gs[G_SWD + 1 - f]


@njit_nort(inline="always")
def _in_valid_swing(gs, prm, f, t):
    since = t - gs[G_LO + f]
    exp_sw = _expected_swing(gs, f)
    return (math.isfinite(exp_sw) and since >= prm[P_GLIFT]
            and since <= exp_sw - prm[P_GBTD])


@njit_nort(inline="always")
def _timeline(gs, prm, t, cref, cest, tot, weight, swing_ok, ss_ok, loaded_ok, contact):
    """``ContactTimeline.step``: gates per foot (before the touchdown guard)."""
    for f in range(2):
        cv = cref[f] if math.isfinite(cref[f]) else cest[f]
        if not math.isfinite(cv):
            cv = 1.0 if (math.isfinite(tot[f]) and math.isfinite(weight)
                         and tot[f] > prm[P_CWFRAC] * weight) else 0.0
        contact[f] = 1.0 if cv > prm[P_CLEVEL] else 0.0
    for f in range(2):
        cf = contact[f] != 0.0
        prev = gs[G_CPREV + f]
        if prev < 0.0:
            gs[G_TD + f] = t if cf else _NAN
            gs[G_LO + f] = _NAN if cf else t
        elif cf and prev == 0.0:
            if math.isfinite(gs[G_LO + f]):
                gs[G_SWD + f] = t - gs[G_LO + f]
            gs[G_TD + f] = t
        elif prev == 1.0 and not cf:
            gs[G_LO + f] = t
            gs[G_GUARD + f] = 0.0
        gs[G_CPREV + f] = 1.0 if cf else 0.0
    for f in range(2):
        o = 1 - f
        swing_ok[f] = 0.0
        ss_ok[f] = 0.0
        loaded_ok[f] = 0.0
        if contact[f] == 0.0 and math.isfinite(gs[G_LO + f]):
            swing_ok[f] = 1.0 if _in_valid_swing(gs, prm, f, t) else 0.0
        if contact[f] != 0.0 and math.isfinite(gs[G_TD + f]):
            loaded_ok[f] = 1.0 if t - gs[G_TD + f] >= prm[P_GLOADED] else 0.0
            if contact[o] == 0.0 and math.isfinite(gs[G_LO + o]):
                ss_ok[f] = 1.0 if (t - gs[G_TD + f] >= prm[P_GTD]
                                   and _in_valid_swing(gs, prm, o, t)) else 0.0


@njit_nort(inline="always")
def _touchdown_guard(gs, prm, ss, f, t, x):
    """``ContactTimeline.touchdown_guard`` of foot ``f``."""
    if gs[G_GUARD + f] != 0.0:
        return True
    if t - gs[G_LO + f] < prm[P_GMINSW] * _expected_swing(gs, f):
        return False
    hi = 0
    lim = prm[P_GLOADSIG] * prm[P_SIG]
    for i in range(4 * f, 4 * f + 4):
        if ss[i, FLAG] == 0.0 and math.isfinite(x[i]) and x[i] > lim:
            hi += 1
    if hi >= prm[P_GMINSENS]:
        gs[G_GUARD + f] = 1.0
        return True
    return False


# ---------------------------------------------------------------- fits
@njit_nort(inline="always")
def _swing_fit(s):
    """``SwingFit.fit``: (a, b, sd, se)."""
    n = s[FN]
    if n == 0:
        return _NAN, _NAN, _NAN, _NAN
    mx = s[FSX] / n
    mt = s[FST] / n
    ctt = s[FSTT] - n * mt * mt
    ctx = s[FSTX] - n * mt * mx
    cxx = s[FSXX] - n * mx * mx
    if n < 3 or ctt <= 1e-12:
        return mx, 0.0, math.sqrt(max(cxx, 0.0) / max(n - 1.0, 1.0)), _NAN
    b = ctx / ctt
    a = mx - b * mt
    rss = max(cxx - b * ctx, 0.0)
    sd = math.sqrt(rss / (n - 2.0))
    return a, b, sd, sd / math.sqrt(ctt)


@njit_nort(inline="always")
def _swing_add(s, tau, x):
    s[FN] += 1.0
    s[FST] += tau
    s[FSX] += x
    s[FSTT] += tau * tau
    s[FSTX] += tau * x
    s[FSXX] += x * x


@njit_nort(inline="always")
def _stance_add(s, res, load, factor):
    """``StanceFit.add``."""
    if not (math.isfinite(res) and math.isfinite(load)):
        return
    s[SN] += 1.0
    s[SL] += load
    s[SR] += res
    s[SLL] += load * load
    s[SLR] += load * res
    s[SRR] += res * res
    e = s[SETA]
    s[SETA] = res if math.isnan(e) else e + (res - e) * factor


@njit_nort(inline="always")
def _add_swing_sample(s, prm, t, x):
    """``classify.add_swing_sample``."""
    sigma = prm[P_SIG]
    tau = t - s[FT]
    if s[FN] >= prm[P_FITMIN_N]:
        a, b, sd, _ = _swing_fit(s)
        pred = a + b * tau
        scale = max(sd, sigma) if math.isfinite(sd) else sigma
        gate = prm[P_OUTSIG]
        if abs(x - pred) > gate * scale and abs(x - pred) > gate * sigma:
            s[FOUT] += 1.0
            return
    _swing_add(s, tau, x)


# ---------------------------------------------------------------- tests
@njit_nort(inline="always")
def _cusum2(a, ip, ineg, z, kappa):
    """Two-sided CUSUM step on ``a[ip]`` / ``a[ineg]`` (allowance ``kappa``, both clipped
    at 0); returns the larger of the two statistics."""
    gp = a[ip] + z - kappa
    gn = a[ineg] - z - kappa
    a[ip] = gp if gp > 0.0 else 0.0
    a[ineg] = gn if gn > 0.0 else 0.0
    return max(a[ip], a[ineg])


@njit_nort(inline="always")
def _is_comp(s):
    """``residual_tests.compensated``."""
    k = s[KIND]
    return s[FLAG] != 0.0 and (k == K_OFFSET or k == K_DRIFT) and s[SRC] == SRC_SWING


@njit_nort(inline="always")
def _sensor_tests(s, prm, t, xi, vi, tot_f, weight, swing_ok, ss_ok, loaded_ok, infoless):
    """``Detector._sensor_tests``: the alarm source code of one sensor."""
    if not math.isfinite(xi):
        s[REP] = 0.0
        s[LAST] = _NAN
        return SRC_NAN
    flagged = s[FLAG] != 0.0
    # constant reading (residual_tests.constant_test)
    prev = s[LAST]
    same = xi == prev
    if same:
        s[REP] += 1.0
    else:
        if not flagged:  # a run that ended unflagged: its repeats were chance repeats
            s[PAIRS] += s[RUNP]
            s[CHANCE] += s[RUNR]
        s[RUNP] = 0.0
        s[RUNR] = 0.0
        s[REP] = 0.0
        if flagged and s[SRC] == SRC_CONST:
            s[VAR] = 1.0
    if loaded_ok and math.isfinite(prev):  # chance repeats: loaded readings only
        s[RUNP] += 1.0
        s[RUNR] += 1.0 if same else 0.0
    s[LAST] = xi
    alarm = SRC_NONE
    if s[REP] + 1.0 >= prm[P_CONSTN] and loaded_ok:
        chance = False
        mc = prm[P_CHANCE]
        if mc > 0.0:
            p = (s[CHANCE] + 1.0) / (s[PAIRS] + 2.0)
            chance = p < 1.0 and s[REP] * math.log(p) > math.log(mc)
        if not chance:
            if flagged and s[SRC] == SRC_CONST and s[VAR] != 0.0 and xi == s[CV]:
                s[CR] += 1.0
                s[VAR] = 0.0
            alarm = SRC_CONST
    if swing_ok:
        z = xi / prm[P_SIG]
        stat = _cusum2(s, SWP, SWN, z, prm[P_SWK])
        if stat > prm[P_SWH]:
            s[SWP] = s[SWN] = 0.0
            if alarm == SRC_NONE:
                alarm = SRC_SWING
        if s[FLAG] != 0.0 and s[SRC] == SRC_SWING:
            s[QV] += 1.0
            _add_swing_sample(s, prm, t, xi)
    if ss_ok and math.isfinite(weight) and weight > 0 and math.isfinite(vi):
        comp = _is_comp(s)
        corr = xi - (s[ETA] if comp else 0.0)
        r = (corr - vi) / weight
        z = r / prm[P_CORSIG]
        stat = _cusum2(s, CP, CN, z, prm[P_CORK])
        if stat > prm[P_CORH]:
            s[CP] = s[CN] = 0.0
            if not comp and alarm == SRC_NONE:
                alarm = SRC_CORNER
        if s[FLAG] != 0.0 and (s[SRC] == SRC_CORNER or s[SRC] == SRC_TOTAL):
            if s[SRC] == SRC_CORNER and abs(z) < prm[P_CORK]:
                s[QV] += 1.0
            if infoless or not math.isfinite(tot_f):
                _stance_add(s, xi - vi, vi, prm[P_STETA])
    return alarm


@njit_nort(inline="always")
def _foot_total(ss, gs, prm, f, x, v, tot_f, weight, alarms, corr, tmp, part):
    """``Detector._foot_total`` of foot ``f`` (gate open)."""
    for j in range(4):
        s = ss[4 * f + j]
        k = s[KIND]
        if s[FLAG] != 0.0 and not (s[SRC] == SRC_SWING and (k == K_OFFSET or k == K_DRIFT)) \
                and not (s[SRC] == SRC_TOTAL or s[SRC] == SRC_CORNER):
            return
    for j in range(4):
        s = ss[4 * f + j]
        xi = x[4 * f + j]
        corr[j] = xi - s[ETA] if _is_comp(s) else xi
        if not math.isfinite(corr[j]):
            return
    r = (_fsum(corr, 4, part) - tot_f) / weight
    z = r / prm[P_TOTSIG]
    kap = prm[P_TOTK]
    stat = _cusum2(gs, G_GPOS + f, G_GNEG + f, z, kap)
    sgn = 1.0 if z > 0 else -1.0
    vo = G_VOTES + 4 * f
    if abs(z) > kap:
        for j in range(4):
            if math.isfinite(v[4 * f + j]):
                gs[vo + j] += sgn * (corr[j] - v[4 * f + j])
    if gs[G_GPOS + f] == 0.0 and gs[G_GNEG + f] == 0.0:
        for j in range(4):
            gs[vo + j] = 0.0
    for j in range(4):
        s = ss[4 * f + j]
        if s[FLAG] != 0.0 and (s[SRC] == SRC_TOTAL or s[SRC] == SRC_CORNER):
            s[QV] = s[QV] + 1.0 if abs(z) < kap else 0.0
    for j in range(4):
        s = ss[4 * f + j]
        if not (s[FLAG] != 0.0 and (s[SRC] == SRC_TOTAL or s[SRC] == SRC_CORNER)):
            continue
        ok = True
        for k in range(4):
            if k != j:
                o = ss[4 * f + k]
                if o[FLAG] != 0.0 and not (o[KIND] == K_OFFSET or o[KIND] == K_DRIFT):
                    ok = False
        if ok:
            n = 0
            for k in range(4):
                if k != j:
                    tmp[n] = corr[k]
                    n += 1
            load = tot_f - _fsum(tmp, 3, part)
            _stance_add(s, x[4 * f + j] - load, load, prm[P_STETA])
    if stat > prm[P_TOTH]:
        # FootTotalTest.isolate
        gs[G_GPOS + f] = gs[G_GNEG + f] = 0.0
        already = False
        for j in range(4):
            s = ss[4 * f + j]
            if s[FLAG] != 0.0 and (s[SRC] == SRC_TOTAL or s[SRC] == SRC_CORNER):
                already = True
                if alarms[4 * f + j] == SRC_NONE:
                    alarms[4 * f + j] = SRC_TOTAL
        if not already:
            best = -1
            bv = 0.0
            for j in range(4):
                if ss[4 * f + j, FLAG] == 0.0:
                    vj = gs[vo + j]
                    if best < 0 or vj >= bv:
                        best = j
                        bv = vj
            if best >= 0 and alarms[4 * f + best] == SRC_NONE:
                alarms[4 * f + best] = SRC_TOTAL
        for j in range(4):
            gs[vo + j] = 0.0


# ---------------------------------------------------------------- flag machine
@njit_nort(inline="always")
def _prio(src):
    if src == SRC_NAN:
        return 4
    if src == SRC_CONST:
        return 3
    if src == SRC_SWING:
        return 2
    if src == SRC_CORNER or src == SRC_TOTAL:
        return 1
    return 0


@njit_nort(inline="always")
def _apply_alarm(s, a, t, x):
    """``Detector._apply_alarm``."""
    if s[FLAG] == 0.0:
        _clear(s)
        s[FLAG] = 1.0
        s[FT] = t
        s[SRC] = a
        if a == SRC_CONST:
            s[CV] = x
    elif _prio(a) > _prio(int(s[SRC])):
        s[SRC] = a
        if a == SRC_CONST:
            s[CV] = x
            s[VAR] = 0.0
            s[CR] = 0.0
    s[QV] = 0.0
    s[LA] = t


@njit_nort(inline="always")
def _maybe_clear(s, prm, t, x, loaded):
    """``classify.maybe_clear``."""
    last = s[LA]
    src = s[SRC]
    clear_s = prm[P_CLEAR]
    if src == SRC_NAN:
        if math.isfinite(x) and t - last >= clear_s * prm[P_CLRDROP]:
            _clear(s)
    elif src == SRC_CONST:
        sat = s[KIND] == K_SATURATION
        hold = prm[P_HOLD_SAT] if sat else clear_s * 1.0
        nh = prm[P_NCLEAR_SAT] if sat else prm[P_NCLEAR]
        if loaded and s[REP] == 0.0:
            s[QV] += 1.0
        if s[QV] >= nh * prm[P_CLRCONSTFRAC] and t - last >= hold:
            _clear(s)
    else:
        k = prm[P_CLRSPK] if s[KIND] == K_SPIKES else prm[P_CLRVALID]
        if s[QV] >= prm[P_NCLEAR] * k and t - last >= clear_s:
            _clear(s)
    if s[FLAG] == 0.0:
        s[SWP] = s[SWN] = s[CP] = s[CN] = 0.0


@njit_nort(inline="always")
def _classify(s, prm, t, x):
    """``classify.classify`` of a flagged sensor."""
    src = s[SRC]
    sigma = prm[P_SIG]
    if src == SRC_NAN:
        s[KIND] = K_DROPOUT
        s[ETA] = _NAN
    elif src == SRC_CONST:
        v = s[CV]
        if s[CR] >= 1.0:
            s[KIND] = K_SATURATION
        elif math.isfinite(v) and abs(v - np.rint(v)) < prm[P_ROUNDTOL]:
            s[KIND] = K_FROZEN
        else:
            s[KIND] = K_STUCK
    elif src == SRC_SWING:
        n = s[FN]
        nout = s[FOUT]
        n_tot = n + nout
        a, b, sd, se = _swing_fit(s)
        if n == 0:
            s[KIND] = K_OFFSET
            s[ETA] = x if s[ETA] == 0.0 else s[ETA]
            return
        if (nout >= prm[P_SPKMINOUT] and nout < prm[P_SPKMAXFRAC] * n_tot
                and (not math.isfinite(sd) or sd < prm[P_SPKMAXSCAT] * sigma)):
            s[KIND] = K_SPIKES
            s[ETA] = 0.0
        elif math.isfinite(sd) and sd > prm[P_NOISESCAT] * sigma and n >= prm[P_FITMIN_N]:
            s[KIND] = K_NOISE
            s[ETA] = 0.0
        elif (n >= prm[P_DRFITMIN_N] and math.isfinite(se) and abs(b) > prm[P_DRSLOPE]
              and abs(b) > prm[P_DRSLOPESE] * se
              and s[FSTT] / n - (s[FST] / n) * (s[FST] / n) > prm[P_DRTVAR]):
            s[KIND] = K_DRIFT
            s[ETA] = a + b * (t - s[FT])
        else:
            s[KIND] = K_OFFSET
            s[ETA] = s[FSX] / n
    else:
        if s[SN] >= prm[P_STFITMIN_N]:
            sse_const = s[SRR] - s[SR] * s[SR] / s[SN]
            g0 = s[SLR] / s[SLL] if s[SLL] > 0 else 0.0
            sse_gain = s[SRR] - g0 * s[SLR]
            if abs(g0) > prm[P_GAINCHG] and sse_gain < sse_const and 1.0 + g0 > prm[P_GAINMIN]:
                s[KIND] = K_GAIN
                s[ETA] = _NAN
                s[GAIN] = 1.0 + g0
                return
            s[KIND] = K_OFFSET
            s[ETA] = s[SETA]
            return
        s[KIND] = K_UNKNOWN
        s[ETA] = s[SETA] if math.isfinite(s[SETA]) else _NAN


# ---------------------------------------------------------------- recovery
@njit_nort(inline="always")
def _corrected(ss, prm, x, corrected, info, tmp):
    """``Recovery._corrected``: per sensor the corrected reading [N] and whether the
    reading carries information (1/0)."""
    a_lp = prm[P_ALP]
    for i in range(8):
        s = ss[i]
        xi = x[i]
        if math.isfinite(xi):
            lp = s[LP]
            s[LP] = xi if math.isnan(lp) else lp + (xi - lp) * a_lp
        fl = s[FLAG] != 0.0
        k = s[KIND]
        corrected[i] = _NAN
        info[i] = 1.0
        if fl and (k == K_OFFSET or k == K_DRIFT) and math.isfinite(s[ETA]):
            corrected[i] = xi - s[ETA]
        elif fl and k == K_GAIN and s[GAIN] > prm[P_RGAINMIN]:
            corrected[i] = xi / s[GAIN]
        elif fl and k == K_NOISE and math.isfinite(s[LP]):
            corrected[i] = s[LP]
        elif fl and k == K_SPIKES:
            a0, a1, a2 = xi, s[X1], s[X2]
            m = 0
            for q in (a0, a1, a2):
                if math.isfinite(q):
                    tmp[m] = q
                    m += 1
            if m == 0:
                corrected[i] = _NAN
            elif m == 1:
                corrected[i] = tmp[0]
            elif m == 2:
                corrected[i] = max(tmp[0], tmp[1])  # sorted(trip)[1]
            else:
                lo, hi = min(tmp[0], tmp[1]), max(tmp[0], tmp[1])
                corrected[i] = max(lo, min(hi, tmp[2]))
        elif fl:
            info[i] = 0.0
        else:
            corrected[i] = xi
        s[X2] = s[X1]
        s[X1] = xi
        if fl and k == K_SATURATION and math.isfinite(xi) and xi != s[CV]:
            corrected[i] = xi
            info[i] = 1.0


@njit_nort(inline="always")
def _recover(ss, prm, x, v, tot, rec, eta, corrected, info, part, tmp):
    """``Recovery.step``: ``rec`` and ``eta`` of every sensor."""
    _corrected(ss, prm, x, corrected, info, tmp)
    total = tot[0] + tot[1]
    n_lack = 0
    n_known = 0
    for j in range(8):
        if info[j] == 0.0:
            n_lack += 1
        elif math.isfinite(corrected[j]):
            tmp[n_known] = corrected[j]
            n_known += 1
    # the exact sum of the known readings only when a sensor without information needs
    # the rest of the total (``known`` is read nowhere else)
    known = _fsum(tmp, n_known, part) if n_lack > 0 and math.isfinite(total) else 0.0
    a_fast = prm[P_AFAST]
    for i in range(8):
        s = ss[i]
        xi = x[i]
        fl = s[FLAG] != 0.0
        if not fl and s[HW] == 0.0 and math.isfinite(xi):
            s[LREC] = xi
            rec[i] = xi
            eta[i] = 0.0
            continue
        if info[i] == 0.0 and math.isfinite(total):
            rest = total - known
            if n_lack > 1:
                sv = 0.0
                for j in range(8):
                    if info[j] == 0.0:
                        sv += max(v[j], 0.0) if math.isfinite(v[j]) else 0.0
                if sv > 0:
                    share = (max(v[i], 0.0) if math.isfinite(v[i]) else 0.0) / sv
                else:
                    share = 1.0 / n_lack
                rest *= share
            repl = max(rest, 0.0)
        else:
            repl = max(v[i], 0.0) if math.isfinite(v[i]) else 0.0
        # HandOver.update
        target = 1.0 if fl else 0.0
        alpha = a_fast if (fl and info[i] == 0.0) else prm[P_BLEND]
        w = s[HW] + (target - s[HW]) * alpha
        if abs(target - w) < 1e-6:
            w = target
        s[HW] = w
        rec_fault = corrected[i] if info[i] != 0.0 and math.isfinite(corrected[i]) else repl
        if fl and s[KIND] == K_SATURATION and info[i] == 0.0:
            rec_fault = max(rec_fault, s[CV])
        # HandOver.mix
        if not math.isfinite(rec_fault):
            rec_fault = s[LREC]
        if not math.isfinite(xi):
            r = rec_fault
        elif w <= 1e-12:
            r = xi
        else:
            r = (1.0 - w) * xi + w * rec_fault
        if not math.isfinite(r):
            r = s[LREC]
        s[LREC] = r
        rec[i] = r
        k = s[KIND]
        if fl:
            eta[i] = s[ETA] if (k == K_OFFSET or k == K_DRIFT) else xi - r
        else:
            eta[i] = 0.0


# ---------------------------------------------------------------- one sample
@njit_nort
def detect_step(ss, gs, prm, t, x, v, tot, cref, cest, gap, rec, eta, ws):
    """Detector (``Detector.step``) and recovery (``Recovery.step``) on one sample.

    Args:
        ss, gs: State (updated in place).
        prm: Parameters (:func:`detect_params`).
        t: Time [s] (NaN continues the clock).
        x: Measured forces (8,) [N] (NaN = no reading).
        v: VFS corner forces (8,) [N].
        tot: VFS force per foot (2,) [N].
        cref, cest: Planned and estimated contact per foot (2,).
        gap: A time gap before this sample (the contact timeline restarts).
        rec, eta: Outputs (8,): recovered force and fault estimate [N].
        ws: Float scratch of at least :data:`N_WS_DETECT`.
    """
    if gap:
        _reset_timeline(gs)
    if not math.isfinite(t):
        lt = gs[G_LAST_T]
        t = lt + prm[P_DT] if math.isfinite(lt) else 0.0
    gs[G_LAST_T] = t
    t0, t1 = tot[0], tot[1]
    if math.isfinite(t0) and math.isfinite(t1):
        gs[G_WSUM] += t0 + t1
        gs[G_WN] += 1.0
    weight = gs[G_WSUM] / gs[G_WN] if gs[G_WN] != 0.0 else _NAN
    # gates and flags as 0/1 floats in the scratch (no allocation per sample)
    swing_ok = ws[0:2]
    ss_ok = ws[2:4]
    loaded_ok = ws[4:6]
    contact = ws[6:8]
    _timeline(gs, prm, t, cref, cest, tot, weight, swing_ok, ss_ok, loaded_ok, contact)
    for f in range(2):
        if swing_ok[f] != 0.0 and _touchdown_guard(gs, prm, ss, f, t, x):
            swing_ok[f] = 0.0
    infoless = ws[48:50]
    infoless[0] = infoless[1] = 0.0
    for i in range(8):
        if ss[i, FLAG] != 0.0 and (ss[i, SRC] == SRC_NAN or ss[i, SRC] == SRC_CONST):
            infoless[i // 4] = 1.0
    alarms = ws[50:58]
    for i in range(8):
        f = i // 4
        alarms[i] = _sensor_tests(ss[i], prm, t, x[i], v[i], tot[f], weight,
                                  swing_ok[f] != 0.0, ss_ok[f] != 0.0, loaded_ok[f] != 0.0,
                                  infoless[f] != 0.0)
    for f in range(2):
        if ss_ok[f] and math.isfinite(tot[f]) and math.isfinite(weight) and weight > 0:
            _foot_total(ss, gs, prm, f, x, v, tot[f], weight, alarms, ws[8:12], ws[12:16],
                        ws[16:32])
    for i in range(8):
        s = ss[i]
        if alarms[i] != SRC_NONE:
            _apply_alarm(s, int(alarms[i]), t, x[i])
        elif s[FLAG] != 0.0:
            _maybe_clear(s, prm, t, x[i], loaded_ok[i // 4] != 0.0)
        if s[FLAG] != 0.0:
            _classify(s, prm, t, x[i])
    corrected = ws[32:40]
    info = ws[58:66]
    _recover(ss, prm, x, v, tot, rec, eta, corrected, info, ws[16:32], ws[40:48])


@njit
def detect_run(ss, gs, prm, t, x, v, tot, cref, cest, gap, rec, eta, flag, kind):
    """:func:`detect_step` over every row (``t`` (T,), ``x``/``v`` (T, 8), ``tot``/``cref``/
    ``cest`` (T, 2), ``gap`` (T,) bool) into ``rec``/``eta``/``flag``/``kind`` (T, 8)."""
    ws = np.zeros(N_WS_DETECT)
    for k in range(t.shape[0]):
        detect_step(ss, gs, prm, t[k], x[k], v[k], tot[k], cref[k], cest[k], gap[k], rec[k],
                    eta[k], ws)
        for i in range(8):
            flag[k, i] = ss[i, FLAG] != 0.0
            kind[k, i] = int(ss[i, KIND])


@njit_nort
def time_guard_step(gs, t, dt, gap_limit):
    """``TimeGuard.step``: ``(clock, state code, jump)``."""
    last = gs[G_STAMP]
    cl = gs[G_CLOCK]
    if not math.isfinite(t):
        st = ST_MISSING
        jp = math.nan
        c = cl + dt if math.isfinite(cl) else 0.0
    else:
        gs[G_STAMP] = t
        if not math.isfinite(last):
            st = ST_OK
            jp = math.nan
            c = t if (not math.isfinite(cl) or t > cl) else cl + dt
        else:
            jp = t - last
            if jp > gap_limit:
                st = ST_GAP
            elif jp < 0.0:
                st = ST_BACK
            elif jp == 0.0:
                st = ST_CONST
            else:
                st = ST_OK
            c = t if t > cl else cl + dt
    gs[G_CLOCK] = c
    return c, st, jp


@njit_nort
def time_guard_run(t, dt, gap_limit, gs, clock, state, jump):
    """``TimeGuard.step`` over every stamp of ``t`` (state kept in ``gs``): the monotone
    clock, the state code (:data:`ST_OK` ...) and the step from the last finite stamp."""
    for k in range(t.shape[0]):
        clock[k], state[k], jump[k] = time_guard_step(gs, t[k], dt, gap_limit)


class DetectKernel:
    """State and parameters of the compiled detector + recovery of one monitor.

    Args:
        prm: :func:`detect_params`.
    """

    def __init__(self, prm: np.ndarray) -> None:
        self.prm = np.ascontiguousarray(prm, dtype=float)
        self.ss, self.gs = new_state()
        self.ws = np.zeros(N_WS_DETECT)

    def reset(self) -> None:
        """Back to a new monitor's state."""
        reset_state(self.ss, self.gs)

    def run(self, t: np.ndarray, x: np.ndarray, v: np.ndarray, tot: np.ndarray,
            cref: np.ndarray, cest: np.ndarray, gap: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every row from the current state: ``(flag bool, kind code, eta, rec)``, each
        (T, 8)."""
        n = len(t)
        rec = np.empty((n, 8))
        eta = np.empty((n, 8))
        flag = np.empty((n, 8), np.bool_)
        kind = np.empty((n, 8), np.int64)
        c = np.ascontiguousarray
        detect_run(self.ss, self.gs, self.prm, c(t, dtype=float), c(x, dtype=float),
                   c(v, dtype=float), c(tot, dtype=float), c(cref, dtype=float),
                   c(cest, dtype=float), c(gap, dtype=np.bool_), rec, eta, flag, kind)
        return flag, kind, eta, rec
