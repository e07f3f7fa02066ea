"""A per-channel monitor for force channels that are not corner load cells (ankle F/T).

The default :class:`~grfguard.detect.detector.Detector` watches the eight corner cells of
two soles (its tests use the foot balance across four corners). A six-axis force/torque
sensor at each ankle gives twelve channels ``ft_<r|l>_<fx, fy, fz, tx, ty, tz>``, each
with its own virtual estimate ``vfs_<r|l>_<axis>``
(:func:`grfguard.estimate.described.with_described_vfs`). Each channel is watched on
its own (causal: no look-ahead):

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
   taken out: valid in double support too), the virtual channel for frozen;
6. **clearing**: the CUSUM keeps running on the raw residual while flagged; the flag
   clears (kind, fits and onset forgotten) after ``clear_s`` without alarm once
   ``clear_valid_fraction`` of ``clear_s`` in valid samples were quiet
   (``|r| / sigma < kappa``) since the last alarm (for a gain fault, which only shows
   under load, valid samples in stance only);
   a frozen flag clears after ``clear_s`` of varying readings, as the corner
   detector's flags do.

:meth:`ChannelMonitor.update` takes one sample (the virtual channels computed ahead, e.g.
by the batch :func:`~grfguard.estimate.described.with_described_vfs`), and
:meth:`ChannelMonitor.run` is the same step over a log. The test gate is causal
(:class:`ContactPhases`: the end of a phase is predicted from the last phase of the same
kind).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from grfguard._lazy import lazy_module
from grfguard.detect.blocks import cusum_step, excursion_peaks, robust_scale, threshold_for_rate
from grfguard.errors import ConfigError, LogFormatError

pd = lazy_module("pandas")  # (imported on first use: `grfguard run` never does)

__all__ = [
    "ChannelConfig", "ChannelMonitor", "ContactPhases", "calibrate_channels",
    "channel_valid_mask",
]



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
        const_s: A loaded channel reading the same value this long is frozen [s] (at
            least 3 identical readings).
        clear_s: A flag clears after this long without alarm [s], once ...
        clear_valid_fraction: ... this fraction of ``clear_s`` (in samples) were valid
            and quiet since the flag (residual within ``kappa``; frozen: the reading
            varied) [-].
        source: Where the numbers come from.
    """

    sigma: dict[str, tuple[float, float]]
    h: float = 30.0
    kappa: float = 2.0
    guard_s: float = 0.15
    const_s: float = 0.03
    clear_s: float = 1.0
    clear_valid_fraction: float = 0.5
    source: str = "builtin"

    def __post_init__(self) -> None:
        bad = {k: v for k, v in self.sigma.items()
               if len(v) != 2 or not all(q > 0 and math.isfinite(q) for q in v)}
        if bad:
            raise ConfigError(f"channel sigma must be finite and > 0, got {bad}")
        if not (self.h > 0 and self.kappa >= 0 and self.guard_s >= 0 and self.const_s > 0
                and self.clear_s > 0 and 0 <= self.clear_valid_fraction <= 1):
            raise ConfigError("channel h > 0, kappa >= 0, guard_s >= 0, const_s > 0 [s], "
                              "clear_s > 0 [s], 0 <= clear_valid_fraction <= 1 needed")


    def to_toml(self) -> str:
        """TOML text of a ``[channels]`` table and a ``[channels.sigma]`` table."""
        lines = ["[channels]", f"h = {self.h!r}", f"kappa = {self.kappa!r}",
                 f"guard_s = {self.guard_s!r}", f"const_s = {self.const_s!r}",
                 f"clear_s = {self.clear_s!r}",
                 f"clear_valid_fraction = {self.clear_valid_fraction!r}",
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


class ContactPhases:
    """Causal test gate of the channel monitor from the planned contact (one sample per
    :meth:`step`).

    The tests are valid while the robot is not in double support, ``guard_s`` after the
    last contact change and ``guard_s`` before the expected next one; the expected end of
    a phase is its start plus the last duration of the same phase (the same feet on the
    ground), else of its mirror (the other foot's single support). Before such a phase
    has been seen whole, no test is valid (the first step of a walk). Compiled
    (:func:`grfguard.kernels.channels.gate_step`).

    Args:
        guard_s: Distance kept from contact changes [s].
    """

    def __init__(self, guard_s: float) -> None:
        self.guard_s = float(guard_s)
        self.reset()

    def reset(self) -> None:
        """No contact history."""
        from grfguard.kernels.channels import new_state

        self._gate = new_state(0, 1)[3]

    def step(self, t: float, right: bool, left: bool) -> bool:
        """Advance to time ``t`` [s] with the planned contact of both feet; returns
        whether the tests are valid at ``t``."""
        from grfguard.kernels.channels import gate_step

        return bool(gate_step(self._gate, float(t), bool(right), bool(left), self.guard_s))

    def run(self, t: np.ndarray, right: np.ndarray, left: np.ndarray) -> np.ndarray:
        """:meth:`step` over arrays (n,): (n,) bool."""
        from grfguard.kernels.channels import gate_run

        ok = np.zeros(len(t), bool)
        gate_run(self._gate, np.ascontiguousarray(t, float), np.ascontiguousarray(right, bool),
                 np.ascontiguousarray(left, bool), self.guard_s, ok)
        return ok


def _contact_columns(log: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """Planned stance per foot (right, left): ``contact_est``, else ``contact_ref``."""
    out = []
    for s in ("r", "l"):
        c = f"contact_est_{s}" if f"contact_est_{s}" in log else f"contact_ref_{s}"
        if c not in log:
            raise LogFormatError(f"channel monitor: the log has no contact_est_{s} or "
                                 f"contact_ref_{s} column (0/1 planned contact)")
        out.append(log[c].to_numpy(float) > 0.5)
    return out[0], out[1]


def channel_valid_mask(log: pd.DataFrame, guard_s: float) -> np.ndarray:
    """(T, 2) bool: per foot (right, left), where the channel tests are valid
    (:class:`ContactPhases` over the log: single support or swing, ``guard_s`` after the
    last planned contact change and before the expected next one)."""
    t = log["time"].to_numpy(float)
    cr, cl = _contact_columns(log)
    ok = ContactPhases(guard_s).run(t, cr, cl)
    return np.column_stack([ok, ok])


_loaded = _contact_columns


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


#: Longest fault-free CUSUM excursion kept as onset evidence [samples] (a memory bound:
#: 200 s at 1 kHz, 2000 s at 100 Hz; half is dropped when it is reached).
_MAX_EXCURSION = 200_000

_OUT_NAMES = ("flag", "kind", "fault_est", "recovered", "onset_est")


class ChannelMonitor:
    """Per-channel detection, kind, recovery and flag clearing (module docstring), batch
    (:meth:`run`) or one sample at a time (:meth:`update`). Both run the same compiled
    step (:func:`grfguard.kernels.channels.channels_sample`; :meth:`run` loops it over
    the log in compiled code), so both give the same outputs.

    Args:
        config: Scales and thresholds (:func:`calibrate_channels`).
        dt_s: Sampling period [s] (for ``const_s`` and ``clear_s`` in samples); None: the
            median time step of the log (:meth:`run`) or the first time step
            (:meth:`update`).

    Example:
        >>> cfg = calibrate_channels([with_described_vfs(clean_walk)])
        >>> out = ChannelMonitor(cfg).run(with_described_vfs(faulty_walk))
        >>> out["flag_ft_r_fz"], out["kind_ft_r_fz"], out["recovered_ft_r_fz"]
        >>> live = ChannelMonitor(cfg, dt_s=0.001)
        >>> row_out = live.update(row)   # dict: time, ft_*, vfs_*, contact_est_* or _ref_*
    """

    def __init__(self, config: ChannelConfig, dt_s: float | None = None) -> None:
        self.config = config
        self._dt_given = dt_s
        self.channels: list[str] | None = None
        self.reset()

    def reset(self) -> None:
        """Forget everything (flags, sums, contact history, channel list)."""
        self.dt_s = self._dt_given
        self._t_prev = math.nan
        self._k: dict[str, Any] | None = None  # compiled state, made for the channels
        self._keys: tuple[list[str], list[str], list[str]] | None = None

    def _kernel_state(self, chans: list[str], cap: int) -> dict[str, Any]:
        """Settings, state and one-sample buffers of the compiled step for ``chans``."""
        from grfguard.kernels.channels import N_PRM, new_state

        cfg = self.config
        fst, ist, exc, gate = new_state(len(chans), cap)
        prm = np.zeros(N_PRM)
        prm[:5] = (cfg.kappa, cfg.h, cfg.clear_s, cfg.clear_valid_fraction, cfg.guard_s)
        prm[8] = _MAX_EXCURSION
        ks = {"side": np.array([_side(c) for c in chans], np.int64),
              "sigma": np.array([cfg.sigma[c] for c in chans], float).reshape(-1, 2),
              "prm": prm, "fst": fst, "ist": ist, "exc": exc, "gate": gate}
        self._set_rate(ks)
        return ks

    def _set_rate(self, ks: dict[str, Any]) -> None:
        """The constant-reading and clearing lengths in samples for the current rate
        (none before the rate is known: no frozen test and no clearing)."""
        prm = ks["prm"]
        if self.dt_s:
            prm[5] = max(3, int(round(self.config.const_s / self.dt_s)))
            prm[6] = int(round(self.config.clear_s / self.dt_s))
            prm[7] = self.dt_s
        else:
            prm[5] = prm[6] = math.inf
            prm[7] = 0.0
        ks["dt"] = self.dt_s

    # ------------------------------------------------------------------ batch
    def run(self, log: pd.DataFrame) -> pd.DataFrame:
        """``log`` plus ``flag_<ch>``, ``kind_<ch>``, ``fault_est_<ch>``, ``recovered_<ch>``
        and ``onset_est_<ch>`` [s] for every F/T channel ``<ch>`` (``ft_r_fz``, ...).

        Raises:
            LogFormatError: No F/T channel with its virtual channel, no contact column,
                or a channel without a calibrated scale.
        """
        from grfguard.io.codes import codes_to_str
        from grfguard.io.logio import without_attrs
        from grfguard.kernels.channels import KIND_NAMES, channels_run

        attrs = log.attrs
        log = without_attrs(log)  # pandas deep-copies the metadata on every access
        chans = _channels(log)
        self._check(chans)
        # a writable copy: pandas hands out read-only views, which numba compiles as a
        # second signature of the kernel (warm() compiles the writable one)
        t = np.array(log["time"].to_numpy(float), dtype=float, order="C")
        cr, cl = _contact_columns(log)
        self.reset()
        self.channels = chans
        if self.dt_s is None and t.size > 1:
            self.dt_s = float(np.median(np.diff(t)))
        n, m = t.size, len(chans)
        # one frame access per block
        X = np.ascontiguousarray(log[chans].to_numpy(float)).reshape(n, m)
        V = np.ascontiguousarray(log[[f"vfs_{c[3:]}" for c in chans]].to_numpy(float)
                                 ).reshape(n, m)
        ks = self._k = self._kernel_state(chans, min(n, _MAX_EXCURSION + 1))
        # every element written; column-major: each output column contiguous, taken by
        # the frame without a copy
        outs = tuple(np.empty((m, n), dt).T for dt in (bool, np.int8, float, float, float))
        channels_run(t, np.ascontiguousarray(cr), np.ascontiguousarray(cl), X, V, ks["side"],
                     ks["sigma"], ks["prm"], ks["fst"], ks["ist"], ks["exc"], ks["gate"],
                     *outs)
        if n:
            self._t_prev = float(t[-1])
        cols = {f"{name}_{c}": (codes_to_str(a[:, j], KIND_NAMES) if name == "kind"
                                else a[:, j])
                for j, c in enumerate(chans) for name, a in zip(_OUT_NAMES, outs, strict=True)}
        if any(k in log.columns for k in cols):
            out = log.copy()
            for k, a in cols.items():
                out[k] = a
        else:
            out = pd.concat([log, pd.DataFrame(cols, index=log.index, copy=False)], axis=1)
        out.attrs = {**attrs, "channel_monitor": {"h": self.config.h,
                                                      "kappa": self.config.kappa,
                                                      "source": self.config.source}}
        return out

    def _check(self, chans: list[str]) -> None:
        missing = [c for c in chans if c not in self.config.sigma]
        if missing:
            raise LogFormatError(f"channel monitor: no calibrated sigma for {missing}; "
                                 "run calibrate_channels on fault-free logs of this robot")

    # -------------------------------------------------------------- streaming
    def update(self, sample: dict[str, Any]) -> dict[str, Any]:
        """One sample (``time``, ``ft_<side>_<axis>``, ``vfs_<side>_<axis>``,
        ``contact_est_<side>`` or ``contact_ref_<side>``); returns ``flag_<ch>``,
        ``kind_<ch>``, ``fault_est_<ch>``, ``recovered_<ch>`` and ``onset_est_<ch>`` of
        every channel. The channels are fixed at the first call (every calibrated
        channel the sample carries with its virtual channel). A missing or non-numeric
        value is taken as NaN (no test; never an exception).

        Raises:
            LogFormatError: At the first call, when the sample has no F/T channel with
                its virtual channel.
        """
        if self.channels is None:
            chans = [c for c in self.config.sigma if c in sample and f"vfs_{c[3:]}" in sample]
            if not chans:
                raise LogFormatError("channel monitor: the sample has no calibrated "
                                     "ft_<side>_<axis> channel with its vfs_<side>_<axis>")
            self.channels = chans

        def num(key: str) -> float:
            try:
                return float(sample.get(key, math.nan))
            except (TypeError, ValueError):
                return math.nan

        def contact(side: str) -> bool:
            c = num(f"contact_est_{side}")
            return (c if math.isfinite(c) else num(f"contact_ref_{side}")) > 0.5

        t = num("time")
        if not math.isfinite(t):
            t = self._t_prev + (self.dt_s or 0.0) if math.isfinite(self._t_prev) else 0.0
        if self.dt_s is None and math.isfinite(self._t_prev) and t > self._t_prev:
            self.dt_s = t - self._t_prev
        keys = self._keys
        if keys is None or keys[0] != self.channels:  # names built once, not per sample
            keys = self._keys = (list(self.channels), [f"vfs_{c[3:]}" for c in self.channels],
                                 [f"{nm}_{c}" for c in self.channels for nm in _OUT_NAMES])
        res = self._step(t, contact("r"), contact("l"), [num(c) for c in keys[0]],
                         [num(v) for v in keys[1]])
        return dict(zip(keys[2], (o for r in res for o in r), strict=True))

    def _step(self, t: float, cr: bool, cl: bool, xs: list[float],
              vs: list[float]) -> list[tuple[bool, str, float, float, float]]:
        """One sample through the compiled step (state kept in ``self._k``)."""
        from grfguard.kernels.channels import KIND_NAMES, channels_sample

        assert self.channels is not None
        self._t_prev = t
        ks = self._k
        m = len(self.channels)
        if ks is None:
            ks = self._k = self._kernel_state(self.channels, 64)
            ks["buf"] = (np.zeros((1, m)), np.zeros((1, m)), np.zeros((1, m), bool),
                         np.zeros((1, m), np.int8), np.zeros((1, m)), np.zeros((1, m)),
                         np.zeros((1, m)))
        if ks["dt"] != self.dt_s:  # the rate became known (second sample)
            self._set_rate(ks)
        X, V, fl, kd, fe, rc, on = ks["buf"]
        X[0] = xs
        V[0] = vs
        longest = channels_sample(0, t, cr, cl, X, V, ks["side"], ks["sigma"], ks["prm"],
                                  ks["fst"], ks["ist"], ks["exc"], ks["gate"],
                                  fl, kd, fe, rc, on)
        cap = ks["exc"].shape[1]
        if longest + 1 > cap and cap < _MAX_EXCURSION + 1:  # room for the next sample
            exc = np.zeros((m, min(2 * cap, _MAX_EXCURSION + 1), 3))
            exc[:, :cap] = ks["exc"]
            ks["exc"] = exc
        # one tolist per output (Python bool, int, float), not one numpy scalar a value
        return [(f, KIND_NAMES[k], e, r, o) for f, k, e, r, o in
                zip(fl[0].tolist(), kd[0].tolist(), fe[0].tolist(), rc[0].tolist(),
                    on[0].tolist(), strict=True)]
