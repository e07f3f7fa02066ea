"""A per-channel monitor for force channels that are not corner load cells (ankle F/T).

The default :class:`~grfguard.detect.detector.Detector` watches the eight corner cells of
two soles (its tests use the foot balance across four corners). A six-axis force/torque
sensor at each ankle gives twelve channels ``ft_<r|l>_<fx, fy, fz, tx, ty, tz>``, each
with its own virtual estimate ``vfs_<r|l>_<axis>``
(:func:`grfguard.estimate.described.with_described_vfs`). Each channel is watched on
its own (batch, zero look-ahead except the planned contact timeline):

1. **residual** ``r = x - v`` (reading minus virtual channel), normalised by the
   channel's fault-free scale ``sigma`` (:func:`calibrate_channels`), tested where the
   virtual channel is accurate: the foot in single support or in swing, ``guard_s``
   away from every planned contact change (in double support the split of the load
   between the feet is only a model);
2. **constant reading**: the same value for ``const_s`` seconds while the foot is
   loaded or the test valid (a healthy sensor's noise never repeats) -> ``frozen``
   (also when the CUSUM flagged the channel first, at the jump to the frozen value);
3. **two-sided CUSUM** (:func:`~grfguard.detect.blocks.cusum_step`) with allowance
   ``kappa`` [σ] and threshold ``h`` [σ·samples]; the onset is where the alarming sum
   last left zero;
4. **kind**: from the onset on, the residual on valid samples is fitted by three
   one-parameter models, offset ``b``, drift ``a (t - t0)``, gain ``(g - 1) v``; the
   least squared error wins (re-fitted at every sample while flagged);
5. **recovery**: ``recovered = x - fault`` for offset, drift and gain (the fitted fault
   taken out: valid in double support too), the virtual channel for frozen.

A flag stays raised to the end of the log (no clearing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from grfguard.detect.blocks import cusum_step, excursion_peaks, robust_scale, threshold_for_rate
from grfguard.errors import ConfigError, LogFormatError

__all__ = ["ChannelConfig", "ChannelMonitor", "calibrate_channels", "channel_valid_mask"]

_KINDS = ("offset", "drift", "gain")


@dataclass(frozen=True)
class ChannelConfig:
    """Settings of :class:`ChannelMonitor`.

    Attributes:
        sigma: Fault-free residual scales per channel, ``(stance, swing)``
            (``ft_r_fz`` -> [N], ``ft_r_tx`` -> [N m]): the virtual channel's model error
            in stance is larger than the sensor noise that dominates in swing.
        h: CUSUM threshold [σ·samples] (one for every channel).
        kappa: CUSUM allowance [σ].
        guard_s: Tests pause this long around every planned contact change [s].
        const_s: A loaded channel reading the same value this long is frozen [s].
        source: Where the numbers come from.
    """

    sigma: dict[str, tuple[float, float]]
    h: float = 30.0
    kappa: float = 2.0
    guard_s: float = 0.15
    const_s: float = 0.03
    source: str = "builtin"

    def __post_init__(self) -> None:
        bad = {k: v for k, v in self.sigma.items()
               if len(v) != 2 or not all(q > 0 and math.isfinite(q) for q in v)}
        if bad:
            raise ConfigError(f"channel sigma must be finite and > 0, got {bad}")
        if not (self.h > 0 and self.kappa >= 0 and self.guard_s >= 0 and self.const_s > 0):
            raise ConfigError("channel h > 0, kappa >= 0, guard_s >= 0, const_s > 0 [s] needed")


    def to_toml(self) -> str:
        """TOML text of a ``[channels]`` table and a ``[channels.sigma]`` table."""
        lines = ["[channels]", f"h = {self.h!r}", f"kappa = {self.kappa!r}",
                 f"guard_s = {self.guard_s!r}", f"const_s = {self.const_s!r}",
                 f"source = {self.source!r}".replace("'", '"'), "", "[channels.sigma]"]
        lines += [f"{k} = [{v[0]!r}, {v[1]!r}]" for k, v in self.sigma.items()]
        return "\n".join(lines) + "\n"

    @classmethod
    def from_toml_text(cls, text: str, where: str = "channel config") -> ChannelConfig:
        """Parse :meth:`to_toml` output.

        Raises:
            ConfigError: Not TOML, or a missing/unknown key (named).
        """
        import tomllib

        try:
            doc = tomllib.loads(text)["channels"]
            sigma = {k: (float(v[0]), float(v[1])) for k, v in doc.pop("sigma").items()}
            return cls(sigma=sigma, **doc)
        except (tomllib.TOMLDecodeError, KeyError, TypeError, IndexError) as exc:
            raise ConfigError(f"{where}: expected a [channels] table with h, kappa, guard_s, "
                              f"const_s, source and [channels.sigma] ch = [stance, swing]: "
                              f"{exc}") from exc


def _side(ch: str) -> int:
    return 0 if ch.startswith("ft_r_") else 1


def channel_valid_mask(log: pd.DataFrame, guard_s: float) -> np.ndarray:
    """(T, 2) bool: per foot (right, left), single support or swing, ``guard_s`` away from
    every planned contact change (``contact_est_<side>``, else ``contact_ref_<side>``)."""
    t = log["time"].to_numpy(float)
    cols = []
    for s in ("r", "l"):
        c = f"contact_est_{s}" if f"contact_est_{s}" in log else f"contact_ref_{s}"
        if c not in log:
            raise LogFormatError(f"channel monitor: the log has no contact_est_{s} or "
                                 f"contact_ref_{s} column (0/1 planned contact)")
        cols.append(log[c].to_numpy(float) > 0.5)
    c = np.column_stack(cols)
    double = c[:, 0] & c[:, 1]
    change = np.zeros(t.size, bool)
    change[1:] = np.any(c[1:] != c[:-1], axis=1)
    tc = t[change]
    if tc.size:
        j = np.searchsorted(tc, t)
        prev = np.where(j > 0, t - tc[np.maximum(j - 1, 0)], np.inf)
        nxt = np.where(j < tc.size, tc[np.minimum(j, tc.size - 1)] - t, np.inf)
        near = (prev < guard_s) | (nxt < guard_s)
    else:
        near = np.zeros(t.size, bool)
    ok = ~double & ~near
    return np.column_stack([ok, ok])


def _loaded(log: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """Planned stance per foot (right, left): ``contact_est``, else ``contact_ref``."""
    out = []
    for s in ("r", "l"):
        c = f"contact_est_{s}" if f"contact_est_{s}" in log else f"contact_ref_{s}"
        out.append(log[c].to_numpy(float) > 0.5)
    return out[0], out[1]


def _channels(log: pd.DataFrame) -> list[str]:
    chans = [c for c in log.columns if c.startswith("ft_") and f"vfs_{c[3:]}" in log]
    if not chans:
        raise LogFormatError("channel monitor: no ft_<side>_<axis> column with its "
                             "vfs_<side>_<axis> virtual channel (see with_described_vfs)")
    return chans


def calibrate_channels(logs: list[pd.DataFrame], rate_per_hour: float = 0.1,
                       safety: float = 1.5, base: ChannelConfig | None = None) -> ChannelConfig:
    """Residual scales and CUSUM threshold from fault-free logs with virtual channels.

    ``sigma`` per channel is the robust scale of ``x - v`` on valid samples, in stance and
    in swing; ``h`` from
    the exponential tail of the fault-free CUSUM excursion peaks
    (:func:`~grfguard.detect.blocks.threshold_for_rate`), the rate split over the
    channels, never below ``safety`` x the largest peak nor ``base.h``.
    """
    if not logs:
        raise ConfigError("calibrate_channels needs at least one fault-free log")
    chans = _channels(logs[0])
    guard = base.guard_s if base is not None else ChannelConfig({}).guard_s
    kappa = base.kappa if base is not None else ChannelConfig({}).kappa
    res: dict[str, list[np.ndarray]] = {c: [] for c in chans}
    masks: dict[str, list[np.ndarray]] = {c: [] for c in chans}
    stance: dict[str, list[np.ndarray]] = {c: [] for c in chans}
    hours = 0.0
    for log in logs:
        ok = channel_valid_mask(log, guard)
        ld = _loaded(log)
        t = log["time"].to_numpy(float)
        hours += (t[-1] - t[0]) / 3600.0
        for c in chans:
            res[c].append(log[c].to_numpy(float) - log[f"vfs_{c[3:]}"].to_numpy(float))
            masks[c].append(ok[:, _side(c)])
            stance[c].append(ld[_side(c)])
    sigma = {}
    for c in chans:
        r, m, st = (np.concatenate(a) for a in (res[c], masks[c], stance[c]))
        sigma[c] = (float(robust_scale(r, m & st)), float(robust_scale(r, m & ~st)))
    peaks = []
    for c in chans:
        for r, m, st in zip(res[c], masks[c], stance[c], strict=True):
            gp = gn = 0.0
            stat = np.zeros(r.size)
            for k in np.flatnonzero(m & np.isfinite(r)):
                gp, gn = cusum_step(gp, gn, r[k] / sigma[c][0 if st[k] else 1], kappa)
                stat[k] = max(gp, gn)
            peaks.append(excursion_peaks(stat))
    floor = base.h if base is not None else ChannelConfig({}).h
    h = threshold_for_rate(np.concatenate(peaks), hours * len(chans),
                           rate_per_hour / len(chans), safety, floor=floor)
    cfg = base if base is not None else ChannelConfig(sigma)
    return replace(cfg, sigma=sigma, h=h,
                   source=f"calibrated on {len(logs)} fault-free log(s), {hours * 60:.1f} min")


class ChannelMonitor:
    """Per-channel detection, kind and recovery over a log (module docstring).

    Args:
        config: Scales and thresholds (:func:`calibrate_channels`).

    Example:
        >>> cfg = calibrate_channels([with_described_vfs(clean_walk)])
        >>> out = ChannelMonitor(cfg).run(with_described_vfs(faulty_walk))
        >>> out["flag_ft_r_fz"], out["kind_ft_r_fz"], out["recovered_ft_r_fz"]
    """

    def __init__(self, config: ChannelConfig) -> None:
        self.config = config

    def run(self, log: pd.DataFrame) -> pd.DataFrame:
        """``log`` plus ``flag_<ch>``, ``kind_<ch>``, ``fault_est_<ch>``, ``recovered_<ch>``
        and ``onset_est_<ch>`` [s] for every F/T channel ``<ch>`` (``ft_r_fz``, ...).

        Raises:
            LogFormatError: No F/T channel with its virtual channel, no contact column,
                or a channel without a calibrated scale.
        """
        cfg = self.config
        chans = _channels(log)
        missing = [c for c in chans if c not in cfg.sigma]
        if missing:
            raise LogFormatError(f"channel monitor: no calibrated sigma for {missing}; "
                                 "run calibrate_channels on fault-free logs of this robot")
        t = log["time"].to_numpy(float)
        ok = channel_valid_mask(log, cfg.guard_s)
        dt = float(np.median(np.diff(t)))
        loaded = _loaded(log)
        out = log.copy()
        for c in chans:
            x = log[c].to_numpy(float)
            v = log[f"vfs_{c[3:]}"].to_numpy(float)
            ld = loaded[_side(c)]
            sig = np.where(ld, cfg.sigma[c][0], cfg.sigma[c][1])
            cols = self._channel(t, x, v, ok[:, _side(c)], ld, sig,
                                 max(2, int(round(cfg.const_s / dt))))
            for k, arr in cols.items():
                out[f"{k}_{c}"] = arr
        out.attrs = {**log.attrs, "channel_monitor": {"h": cfg.h, "kappa": cfg.kappa,
                                                      "source": cfg.source}}
        return out

    def _channel(self, t: np.ndarray, x: np.ndarray, v: np.ndarray, ok: np.ndarray,
                 loaded: np.ndarray, sigma: np.ndarray, n_const: int) -> dict[str, Any]:
        cfg = self.config
        n = t.size
        flag = np.zeros(n, bool)
        kind = np.full(n, "none", dtype=object)
        fault = np.zeros(n)
        gp = gn = 0.0
        start = None  # index where the current CUSUM excursion left zero
        onset = None
        frozen = False
        run = 1
        sums = np.zeros(6)  # Σr, Σ1, Στr, Σττ, Σvr, Σvv on valid samples since onset
        srr = 0.0
        est = (0.0, 0.0, 1.0)
        for k in range(n):
            if k > 0 and x[k] == x[k - 1] and math.isfinite(x[k]):
                run += 1
            else:
                run = 1
            r = x[k] - v[k]
            if onset is not None and not frozen and run >= n_const:
                frozen = True  # flagged by the CUSUM first (a jump to the frozen value)
            if onset is None:
                if (loaded[k] or ok[k]) and run >= n_const:
                    onset, frozen = k - run + 1, True
                elif ok[k] and math.isfinite(r):
                    if gp == 0.0 and gn == 0.0:
                        start = k
                    gp, gn = cusum_step(gp, gn, r / sigma[k], cfg.kappa)
                    if max(gp, gn) > cfg.h:
                        onset = start if start is not None else k
                        for j in range(onset, k + 1):  # the evidence so far
                            if ok[j] and math.isfinite(x[j] - v[j]):
                                tau = t[j] - t[onset]
                                rj = x[j] - v[j]
                                sums += (rj, 1.0, tau * rj, tau * tau, v[j] * rj, v[j] * v[j])
                                srr += rj * rj
                if onset is None:
                    continue
            elif not frozen and ok[k] and math.isfinite(r):
                tau = t[k] - t[onset]
                sums += (r, 1.0, tau * r, tau * tau, v[k] * r, v[k] * v[k])
                srr += r * r
            flag[k] = True
            if frozen:
                kind[k] = "frozen"
                fault[k] = x[k] - v[k]
                continue
            kind[k], est = _best_fit(sums, srr)
            b, a, g = est
            tau = t[k] - t[onset]
            fault[k] = {"offset": b, "drift": a * tau,
                        "gain": (g - 1.0) / g * x[k] if g != 0 else 0.0}[kind[k]]
        recovered = np.where(kind == "frozen", v, x - fault)
        onset_t = np.full(n, np.nan)
        if onset is not None:
            onset_t[flag] = t[onset]
        return {"flag": flag, "kind": kind, "fault_est": fault, "recovered": recovered,
                "onset_est": onset_t}


def _best_fit(s: np.ndarray, srr: float) -> tuple[str, tuple[float, float, float]]:
    """Kind with the least squared error among offset, drift and gain fits, and the fitted
    ``(b, a, g)``."""
    sr, n, str_, stt, svr, svv = s
    b = sr / n if n > 0 else 0.0
    a = str_ / stt if stt > 0 else 0.0
    g1 = svr / svv if svv > 0 else 0.0
    sse = {"offset": srr - b * sr, "drift": srr - a * str_, "gain": srr - g1 * svr}
    k = min(_KINDS, key=lambda q: sse[q])
    return k, (b, a, 1.0 + g1)
