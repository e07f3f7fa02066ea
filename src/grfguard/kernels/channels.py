"""Compiled per-channel monitor of ankle F/T channels (:mod:`grfguard.detect.channels`).

One step function, :func:`channels_sample`, advances the causal test gate and every
channel by one sample (CUSUM, constant-reading test, kind fit, recovery, flag clearing);
:func:`channels_run` is the same step looped over a log, and the streaming
:meth:`grfguard.detect.channels.ChannelMonitor.update` calls :func:`channels_sample` on a
one-sample block, so both paths give the same outputs by construction. The arithmetic is
the former Python path's, operation for operation (``tests/reference/channels.py``; the
outputs are bit-identical).

Array layouts (``nch`` channels, ``n`` samples):

* ``X``, ``V``: (n, nch) readings and virtual channels (one sample a row); ``side``:
  (nch,) 0 right, 1 left; ``sigma``: (nch, 2) scales (stance, swing).
* ``prm``: (``N_PRM``,) settings, indices ``P_*`` (``n_const``, ``n_clear``: the
  constant-reading and clearing lengths in samples, ``inf`` before the rate is known;
  ``dt0``: the period, 0 when unknown).
* State: ``fst`` (nch, ``N_F``) floats, ``ist`` (nch, ``N_I``) ints, ``exc`` (nch, cap,
  3) the current fault-free CUSUM excursion ``(t, r, v)`` (the onset evidence, at most
  ``max_exc + 1`` entries), ``gate`` (``N_GATE``,) the contact history.
* Outputs (n, nch): ``flag`` bool, ``kind`` int8 (:data:`KIND_NAMES`), ``fault``,
  ``rec``, ``onset`` float64.
"""

from __future__ import annotations

import math

import numpy as np

from grfguard.kernels._jit import njit_nort

__all__ = ["KIND_NAMES", "N_F", "N_GATE", "N_I", "N_PRM", "channels_run", "channels_sample",
           "gate_run", "gate_step", "new_state", "warm"]

#: Output codes of ``kind`` -> names.
KIND_NAMES = ("none", "offset", "drift", "gain", "frozen")
K_NONE, K_OFFSET, K_DRIFT, K_GAIN, K_FROZEN = 0, 1, 2, 3, 4

# float state per channel
F_GP, F_GN, F_LAST_X, F_ONSET, F_ALARM, F_S0, F_SRR = 0, 1, 2, 3, 4, 5, 11
N_F = 12
# int state per channel
I_RUN, I_FLAG, I_FROZEN, I_KIND, I_QUIET, I_EXC = 0, 1, 2, 3, 4, 5
N_I = 6
# gate: has a previous state, previous state (2 r + l), phase start, last duration of
# each state, whether it was seen
G_HAS, G_PREV, G_START, G_LAST, G_SEEN = 0, 1, 2, 3, 7
N_GATE = 11
# settings
P_KAPPA, P_H, P_CLEAR_S, P_FRAC, P_GUARD, P_NCONST, P_NCLEAR, P_DT0, P_MAXEXC = range(9)
N_PRM = 9


def new_state(nch: int, cap: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fresh ``(fst, ist, exc, gate)`` for ``nch`` channels and an excursion buffer of
    ``cap`` samples per channel (as the former ``_Channel.reset`` and
    ``ContactPhases.reset``)."""
    fst = np.zeros((nch, N_F))
    fst[:, F_LAST_X] = np.nan
    fst[:, F_ONSET] = np.nan
    fst[:, F_ALARM] = np.nan
    gate = np.zeros(N_GATE)
    gate[G_START] = np.nan
    # the excursion buffer is only read below its length: left uninitialised (a batch
    # over a long log asks for megabytes)
    return fst, np.zeros((nch, N_I), np.int64), np.empty((nch, max(cap, 1), 3)), gate


@njit_nort(inline="always")
def gate_step(gate, t, right, left, guard):
    """One sample of the causal contact gate (the former ``ContactPhases.step``): whether
    the channel tests are valid at ``t``."""
    s = 2 * int(right) + int(left)
    if gate[G_HAS] == 0.0:
        gate[G_HAS] = 1.0
        gate[G_PREV] = s
    elif s != int(gate[G_PREV]):
        prev = int(gate[G_PREV])
        if math.isfinite(gate[G_START]):
            gate[G_LAST + prev] = t - gate[G_START]
            gate[G_SEEN + prev] = 1.0
        gate[G_START] = t
        gate[G_PREV] = s
    if s == 3 or not math.isfinite(gate[G_START]):
        return False
    mirror = 2 * int(left) + int(right)
    if gate[G_SEEN + s] != 0.0:
        exp = gate[G_LAST + s]
    elif gate[G_SEEN + mirror] != 0.0:
        exp = gate[G_LAST + mirror]
    else:
        exp = math.nan
    since = t - gate[G_START]
    return math.isfinite(exp) and guard <= since and since <= exp - guard


@njit_nort
def gate_run(gate, t, right, left, guard, ok):
    """:func:`gate_step` over a log into ``ok`` (n,) bool."""
    for k in range(t.size):
        ok[k] = gate_step(gate, t[k], right[k], left[k], guard)


@njit_nort(inline="always")
def _cusum(fst, c, z, kappa):
    gp = fst[c, F_GP] + z - kappa
    gn = fst[c, F_GN] - z - kappa
    fst[c, F_GP] = gp if gp > 0.0 else 0.0
    fst[c, F_GN] = gn if gn > 0.0 else 0.0


@njit_nort(inline="always")
def _add(fst, c, t, r, v):
    """One valid sample into the fit sums (the former ``_Channel.add``)."""
    tau = t - fst[c, F_ONSET]
    fst[c, F_S0] += r
    fst[c, F_S0 + 1] += 1.0
    fst[c, F_S0 + 2] += tau * r
    fst[c, F_S0 + 3] += tau * tau
    fst[c, F_S0 + 4] += v * r
    fst[c, F_S0 + 5] += v * v
    fst[c, F_SRR] += r * r


@njit_nort(inline="always")
def _clear_flag(fst, ist, c):
    ist[c, I_FLAG] = 0
    ist[c, I_FROZEN] = 0
    fst[c, F_ONSET] = math.nan
    fst[c, F_ALARM] = math.nan
    ist[c, I_KIND] = K_NONE
    ist[c, I_QUIET] = 0
    for j in range(6):
        fst[c, F_S0 + j] = 0.0
    fst[c, F_SRR] = 0.0


@njit_nort(inline="always")
def _unflagged_cusum(fst, ist, exc, c, t, r, v, sig, prm):
    """CUSUM on a valid sample of an unflagged channel, keeping the excursion since the
    sum last left zero; raises the flag with the excursion as its first evidence."""
    if fst[c, F_GP] == 0.0 and fst[c, F_GN] == 0.0:
        ist[c, I_EXC] = 0
    m = ist[c, I_EXC]
    exc[c, m, 0] = t
    exc[c, m, 1] = r
    exc[c, m, 2] = v
    m += 1
    ist[c, I_EXC] = m
    _cusum(fst, c, r / sig, prm[P_KAPPA])
    if max(fst[c, F_GP], fst[c, F_GN]) > prm[P_H]:
        ist[c, I_FLAG] = 1
        fst[c, F_ALARM] = t
        fst[c, F_ONSET] = exc[c, 0, 0]
        for j in range(m):  # the evidence so far
            _add(fst, c, exc[c, j, 0], exc[c, j, 1], exc[c, j, 2])
        ist[c, I_EXC] = 0
        fst[c, F_GP] = 0.0
        fst[c, F_GN] = 0.0
    elif m > int(prm[P_MAXEXC]):
        half = m // 2
        for j in range(m - half):
            exc[c, j, 0] = exc[c, j + half, 0]
            exc[c, j, 1] = exc[c, j + half, 1]
            exc[c, j, 2] = exc[c, j + half, 2]
        ist[c, I_EXC] = m - half


@njit_nort(inline="always")
def _flagged(fst, ist, c, t, r, v, sig, ok, loaded, const, valid, prm):
    """A flagged channel: frozen test, CUSUM and quiet count; True when the flag clears."""
    kappa = prm[P_KAPPA]
    frozen = ist[c, I_FROZEN] != 0
    if const:
        if not frozen:  # flagged by the CUSUM first (a jump to the frozen value)
            ist[c, I_FROZEN] = 1
            frozen = True
        if loaded or ok:
            fst[c, F_ALARM] = t
    elif frozen and (loaded or ok) and ist[c, I_RUN] == 1:
        ist[c, I_QUIET] += 1  # the reading varies again
    if valid:
        if not frozen:
            _add(fst, c, t, r, v)
        _cusum(fst, c, r / sig, kappa)
        if max(fst[c, F_GP], fst[c, F_GN]) > prm[P_H]:
            if not frozen:
                fst[c, F_ALARM] = t
                ist[c, I_QUIET] = 0
            fst[c, F_GP] = 0.0
            fst[c, F_GN] = 0.0
        elif (not frozen and abs(r / sig) < kappa
              and (loaded or ist[c, I_KIND] != K_GAIN)):
            ist[c, I_QUIET] += 1  # a gain fault only shows under load: quiet in stance
    if (t - fst[c, F_ALARM] >= prm[P_CLEAR_S]
            and ist[c, I_QUIET] >= prm[P_NCLEAR] * prm[P_FRAC]):
        _clear_flag(fst, ist, c)
        fst[c, F_GP] = 0.0
        fst[c, F_GN] = 0.0
        ist[c, I_EXC] = 0
        return True
    return False


@njit_nort(inline="always")
def _best_fit(fst, c):
    """Kind with the least squared error among offset, drift and gain, and ``(b, a, g)``
    (ties: the first of offset, drift, gain, as Python's ``min``)."""
    sr, n, str_ = fst[c, F_S0], fst[c, F_S0 + 1], fst[c, F_S0 + 2]
    stt, svr, svv = fst[c, F_S0 + 3], fst[c, F_S0 + 4], fst[c, F_S0 + 5]
    srr = fst[c, F_SRR]
    b = sr / n if n > 0 else 0.0
    a = str_ / stt if stt > 0 else 0.0
    g1 = svr / svv if svv > 0 else 0.0
    kind, best = K_OFFSET, srr - b * sr
    e = srr - a * str_
    if e < best:
        kind, best = K_DRIFT, e
    if srr - g1 * svr < best:
        kind = K_GAIN
    return kind, b, a, 1.0 + g1


@njit_nort(inline="always")
def _channel(fst, ist, exc, c, t, x, v, ok, loaded, sig, prm):
    """One channel, one sample: ``(flag, kind, fault, recovered, onset)``."""
    if math.isfinite(x) and x == fst[c, F_LAST_X]:
        ist[c, I_RUN] += 1
    else:
        ist[c, I_RUN] = 1 if math.isfinite(x) else 0
    fst[c, F_LAST_X] = x
    r = x - v
    valid = ok and math.isfinite(r)
    const = ist[c, I_RUN] >= prm[P_NCONST]
    if ist[c, I_FLAG] == 0:
        if (loaded or ok) and const:
            ist[c, I_FLAG] = 1
            ist[c, I_FROZEN] = 1
            fst[c, F_ALARM] = t
            fst[c, F_ONSET] = t - (ist[c, I_RUN] - 1) * prm[P_DT0]
            fst[c, F_GP] = 0.0
            fst[c, F_GN] = 0.0
            ist[c, I_EXC] = 0
        elif valid:
            _unflagged_cusum(fst, ist, exc, c, t, r, v, sig, prm)
        if ist[c, I_FLAG] == 0:
            return False, K_NONE, 0.0, x, math.nan
    elif _flagged(fst, ist, c, t, r, v, sig, ok, loaded, const, valid, prm):
        return False, K_NONE, 0.0, x, math.nan
    if ist[c, I_FROZEN] != 0:
        return True, K_FROZEN, r, v, fst[c, F_ONSET]
    kind, b, a, g = _best_fit(fst, c)
    ist[c, I_KIND] = kind
    if kind == K_OFFSET:
        fault = b
    elif kind == K_DRIFT:
        fault = a * (t - fst[c, F_ONSET])
    else:
        fault = (g - 1.0) / g * x if g != 0 else 0.0
    return True, kind, fault, x - fault, fst[c, F_ONSET]


@njit_nort(inline="always")
def channels_sample(k, t, right, left, X, V, side, sigma, prm, fst, ist, exc, gate,
                    flag, kind, fault, rec, onset):
    """Sample (row) ``k`` of ``X``, ``V`` at time ``t`` with the planned contact of both
    feet: the gate and every channel advanced, outputs written to row ``k``. Returns the
    longest excursion kept (samples), for the caller's buffer."""
    ok = gate_step(gate, t, right, left, prm[P_GUARD])
    longest = 0
    for c in range(X.shape[1]):
        loaded = right if side[c] == 0 else left
        sig = sigma[c, 0] if loaded else sigma[c, 1]
        f, kd, fe, rc, on = _channel(fst, ist, exc, c, t, X[k, c], V[k, c], ok, loaded,
                                     sig, prm)
        flag[k, c] = f
        kind[k, c] = kd
        fault[k, c] = fe
        rec[k, c] = rc
        onset[k, c] = on
        longest = max(longest, ist[c, I_EXC])
    return longest


@njit_nort
def channels_run(t, right, left, X, V, side, sigma, prm, fst, ist, exc, gate,
                 flag, kind, fault, rec, onset):
    """:func:`channels_sample` over every sample of a log (``exc`` must hold
    ``min(n, max_exc + 1)`` samples per channel)."""
    for k in range(t.size):
        channels_sample(k, t[k], right[k], left[k], X, V, side, sigma, prm, fst, ist, exc,
                        gate, flag, kind, fault, rec, onset)


def warm() -> None:
    """Compile (or load) the kernels on a tiny input."""
    fst, ist, exc, gate = new_state(1, 2)
    t = np.array([0.0, 0.001])
    c = np.ones(2, np.bool_)
    X = np.ones((2, 1))
    outs = (np.zeros((2, 1), np.bool_), np.zeros((2, 1), np.int8), np.zeros((2, 1)),
            np.zeros((2, 1)), np.zeros((2, 1)))
    prm = np.ones(N_PRM)
    # ChannelMonitor.run writes column-major outputs (a 2 x 2 transpose is F-contiguous
    # only; numba would type a single column as C-contiguous)
    channels_run(t, c, c, X, X, np.zeros(1, np.int64), np.ones((1, 2)), prm, fst, ist, exc,
                 gate, *(np.zeros((2, 2), a.dtype).T for a in outs))
    channels_sample(0, 0.0, True, False, X, X, np.zeros(1, np.int64), np.ones((1, 2)), prm,
                    fst, ist, exc, gate, *outs)
    gate_run(gate, t, c, c, 0.1, np.zeros(2, np.bool_))
