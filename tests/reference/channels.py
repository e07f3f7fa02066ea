"""Reference (tests and benchmarks only; formerly ``grfguard.detect.channels``'s
per-sample Python path): the per-channel monitor of ankle F/T channels, one Python step per
channel and sample. The compiled kernel (:mod:`grfguard.kernels.channels`, behind
:class:`grfguard.detect.channels.ChannelMonitor`) is held to it, output for output.

``PyContactPhases`` is the former ``ContactPhases`` (the causal test gate);
``PyChannelMonitor`` the former ``ChannelMonitor`` (same constructor, ``run``,
``update``).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from grfguard.detect.blocks import cusum_step
from grfguard.detect.channels import ChannelMonitor, _channels, _contact_columns, _side

_KINDS = ("offset", "drift", "gain")


class PyContactPhases:
    """Causal test gate of the channel monitor from the planned contact (one sample per
    :meth:`step`).

    The tests are valid while the robot is not in double support, ``guard_s`` after the
    last contact change and ``guard_s`` before the expected next one; the expected end of
    a phase is its start plus the last duration of the same phase (the same feet on the
    ground), else of its mirror (the other foot's single support). Before such a phase
    has been seen whole, no test is valid (the first step of a walk).

    Args:
        guard_s: Distance kept from contact changes [s].
    """

    def __init__(self, guard_s: float) -> None:
        self.guard_s = float(guard_s)
        self.reset()

    def reset(self) -> None:
        """No contact history."""
        self._prev: tuple[bool, bool] | None = None
        self._start = math.nan  # start time of the current phase (NaN: before the log)
        self._last: dict[tuple[bool, bool], float] = {}

    def step(self, t: float, right: bool, left: bool) -> bool:
        """Advance to time ``t`` [s] with the planned contact of both feet; returns
        whether the tests are valid at ``t``."""
        state = (bool(right), bool(left))
        if self._prev is None:
            self._prev = state
        elif state != self._prev:
            if math.isfinite(self._start):
                self._last[self._prev] = t - self._start
            self._start = t
            self._prev = state
        if state == (True, True) or not math.isfinite(self._start):
            return False
        exp = self._last.get(state, self._last.get(state[::-1], math.nan))
        since = t - self._start
        return math.isfinite(exp) and self.guard_s <= since <= exp - self.guard_s


class _Channel:
    """Streaming state of one channel (tests, fits, flag)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.gp = self.gn = 0.0
        self.last_x = math.nan
        self.run = 0          # identical readings so far (1 = a new value)
        self.excursion: list[tuple[float, float, float]] = []  # (t, r, v) since the sum left 0
        self.clear_flag()

    def clear_flag(self) -> None:
        self.flag = False
        self.frozen = False
        self.onset_s = math.nan
        self.last_alarm_s = math.nan
        self.kind = "none"  # the kind given at the previous sample
        self.quiet = 0
        self.sums = [0.0] * 6  # Σr, Σ1, Στr, Σττ, Σvr, Σvv on valid samples since the onset
        self.srr = 0.0

    def add(self, t: float, r: float, v: float) -> None:
        tau = t - self.onset_s
        s = self.sums
        s[0] += r
        s[1] += 1.0
        s[2] += tau * r
        s[3] += tau * tau
        s[4] += v * r
        s[5] += v * v
        self.srr += r * r


class PyChannelMonitor(ChannelMonitor):
    """The former pure-Python :class:`~grfguard.detect.channels.ChannelMonitor`: the
    interface (:meth:`update`, the sigma check) is the shipped class's; :meth:`run` loops
    the Python step below over the rows and :meth:`_step` replaces the compiled step."""

    def reset(self) -> None:
        """Forget everything (flags, sums, contact history, channel list)."""
        super().reset()
        self.gate = PyContactPhases(self.config.guard_s)
        self._state: dict[str, _Channel] = {}

    # ------------------------------------------------------------------ batch
    def run(self, log: pd.DataFrame) -> pd.DataFrame:
        """``log`` plus ``flag_<ch>``, ``kind_<ch>``, ``fault_est_<ch>``, ``recovered_<ch>``
        and ``onset_est_<ch>`` [s] for every F/T channel ``<ch>`` (``ft_r_fz``, ...).

        Raises:
            LogFormatError: No F/T channel with its virtual channel, no contact column,
                or a channel without a calibrated scale.
        """
        chans = _channels(log)
        self._check(chans)
        t = log["time"].to_numpy(float)
        cr, cl = _contact_columns(log)
        self.reset()
        self.channels = chans
        if self.dt_s is None and t.size > 1:
            self.dt_s = float(np.median(np.diff(t)))
        xs = [log[c].to_numpy(float).tolist() for c in chans]
        vs = [log[f"vfs_{c[3:]}"].to_numpy(float).tolist() for c in chans]
        n = t.size
        cols = {c: (np.zeros(n, bool), np.full(n, "none", dtype=object), np.zeros(n),
                    np.zeros(n), np.full(n, np.nan)) for c in chans}
        tl, crl, cll = t.tolist(), cr.tolist(), cl.tolist()
        for k in range(n):
            step = self._step(tl[k], crl[k], cll[k], [x[k] for x in xs], [v[k] for v in vs])
            for c, o in zip(chans, step, strict=True):
                a = cols[c]
                a[0][k], a[1][k], a[2][k], a[3][k], a[4][k] = o
        out = log.copy()
        for c in chans:
            for name, arr in zip(("flag", "kind", "fault_est", "recovered", "onset_est"),
                                 cols[c], strict=True):
                out[f"{name}_{c}"] = arr
        out.attrs = {**log.attrs, "channel_monitor": {"h": self.config.h,
                                                      "kappa": self.config.kappa,
                                                      "source": self.config.source}}
        return out

    def _step(self, t: float, cr: bool, cl: bool, xs: list[float],
              vs: list[float]) -> list[tuple[bool, str, float, float, float]]:
        self._t_prev = t
        ok = self.gate.step(t, cr, cl)
        if self.dt_s:
            n_const: float = max(3, int(round(self.config.const_s / self.dt_s)))
            n_clear: float = int(round(self.config.clear_s / self.dt_s))
        else:  # the first sample: no rate yet, so no frozen test and no clearing
            n_const = n_clear = math.inf
        out = []
        assert self.channels is not None
        for c, x, v in zip(self.channels, xs, vs, strict=True):
            st = self._state.get(c)
            if st is None:
                st = self._state[c] = _Channel()
            loaded = cr if _side(c) == 0 else cl
            out.append(self._channel_step(st, c, t, x, v, ok, loaded, n_const, n_clear))
        return out

    def _channel_step(self, st: _Channel, c: str, t: float, x: float, v: float, ok: bool,
                      loaded: bool, n_const: float, n_clear: float,
                      ) -> tuple[bool, str, float, float, float]:
        cfg = self.config
        if math.isfinite(x) and x == st.last_x:
            st.run += 1
        else:
            st.run = 1 if math.isfinite(x) else 0
        st.last_x = x
        r = x - v
        valid = ok and math.isfinite(r)
        sig = cfg.sigma[c][0 if loaded else 1]
        const = st.run >= n_const
        if not st.flag:
            if (loaded or ok) and const:
                st.flag, st.frozen, st.last_alarm_s = True, True, t
                st.onset_s = t - (st.run - 1) * (self.dt_s or 0.0)
                st.gp = st.gn = 0.0
                st.excursion.clear()
            elif valid:
                if st.gp == 0.0 and st.gn == 0.0:
                    st.excursion.clear()
                st.excursion.append((t, r, v))
                st.gp, st.gn = cusum_step(st.gp, st.gn, r / sig, cfg.kappa)
                if max(st.gp, st.gn) > cfg.h:
                    st.flag, st.last_alarm_s = True, t
                    st.onset_s = st.excursion[0][0]
                    for tj, rj, vj in st.excursion:  # the evidence so far
                        st.add(tj, rj, vj)
                    st.excursion.clear()
                    st.gp = st.gn = 0.0
                elif len(st.excursion) > _MAX_EXCURSION:
                    del st.excursion[: len(st.excursion) // 2]
            if not st.flag:
                return False, "none", 0.0, x, math.nan
        else:
            if const:
                if not st.frozen:  # flagged by the CUSUM first (a jump to the frozen value)
                    st.frozen = True
                if loaded or ok:
                    st.last_alarm_s = t
            elif st.frozen and (loaded or ok) and st.run == 1:
                st.quiet += 1  # the reading varies again
            if valid:
                if not st.frozen:
                    st.add(t, r, v)
                st.gp, st.gn = cusum_step(st.gp, st.gn, r / sig, cfg.kappa)
                if max(st.gp, st.gn) > cfg.h:
                    if not st.frozen:
                        st.last_alarm_s, st.quiet = t, 0
                    st.gp = st.gn = 0.0
                elif (not st.frozen and abs(r / sig) < cfg.kappa
                      and (loaded or st.kind != "gain")):
                    st.quiet += 1  # a gain fault only shows under load: quiet in stance
            if (t - st.last_alarm_s >= cfg.clear_s
                    and st.quiet >= n_clear * cfg.clear_valid_fraction):
                st.clear_flag()
                st.gp = st.gn = 0.0
                st.excursion.clear()
                return False, "none", 0.0, x, math.nan
        if st.frozen:
            return True, "frozen", r, v, st.onset_s
        kind, (b, a, g) = _best_fit(st.sums, st.srr)
        st.kind = kind
        fault = {"offset": b, "drift": a * (t - st.onset_s),
                 "gain": (g - 1.0) / g * x if g != 0 else 0.0}[kind]
        return True, kind, fault, x - fault, st.onset_s


#: Longest fault-free CUSUM excursion kept as onset evidence [samples] (a memory bound:
#: 200 s at 1 kHz, 2000 s at 100 Hz; half is dropped when it is reached).
_MAX_EXCURSION = 200_000


def _best_fit(s: list[float], srr: float) -> tuple[str, tuple[float, float, float]]:
    """Kind with the least squared error among offset, drift and gain fits, and the fitted
    ``(b, a, g)``."""
    sr, n, str_, stt, svr, svv = s
    b = sr / n if n > 0 else 0.0
    a = str_ / stt if stt > 0 else 0.0
    g1 = svr / svv if svv > 0 else 0.0
    sse = {"offset": srr - b * sr, "drift": srr - a * str_, "gain": srr - g1 * svr}
    k = min(_KINDS, key=lambda q: sse[q])
    return k, (b, a, 1.0 + g1)
