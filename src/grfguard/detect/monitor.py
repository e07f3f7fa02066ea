"""The sensor monitor: virtual force sensor + fault detection, isolation, kind, recovery.

Two methods on the same input (the same virtual force sensor, VFS):

``paper``
    The paper's observer (eq. 24-32, :mod:`grfguard.detect.observer`) on ``N_meas`` and
    the VFS corners, low-pass, threshold eq. 33 per sensor. The filter is initialised
    from the mean residual of the first ``init_s`` seconds (no alarm there). Kinds are
    not estimated (``unknown``); the recovered force is the filter's ``N̂``.

``default``
    Tests gated by the planned contact state (``contact_ref_<side>``, else the VFS
    contact estimate), each a two-sided CUSUM on a residual normalised per phase
    (:class:`~grfguard.detect.thresholds.Thresholds`):

    - *swing*: the true force is exactly zero, so the reading itself is fault plus
      noise (σ ≈ 2 N): the most sensitive test, and it isolates each sensor. Valid from
      ``gate_liftoff_s`` after lift-off to ``gate_before_touchdown_s`` before the
      expected touchdown (last swing duration);
    - *constant*: a loaded sensor (planned stance, ``gate_loaded_s`` after touchdown)
      whose reading repeats exactly ``const_samples`` times is frozen/stuck/clipped (a
      healthy load cell always shows noise);
    - *foot total*: in clean single support (``gate_touchdown_s`` after the own
      touchdown, the other foot in swing) ``Σ N_meas - F_z,VFS`` over the foot, faults
      already flagged as additive compensated; isolated by the corner residuals;
    - *corner*: in clean single support ``N_meas,i - N̂_i`` per corner (coarse);
    - NaN readings: dropout, at once.

    Flags are persistent (cleared after ``clear_s`` without alarm while the test that
    raised them was valid). Kinds come from features of the flagged sensor: NaN
    (dropout), exact repetition (frozen at a round value, stuck at a noisy one,
    saturation when the same flat top comes back), and in swing a linear fit of the
    reading (offset; drift when the slope is significant), its residual scatter (noise)
    and isolated outliers (spikes); a stance-only fault proportional to the load is a
    gain. ``eta_<s>`` is the estimated fault [N], ``recovered_<s>`` the reconstructed
    force (:mod:`grfguard.recover`).

:class:`Monitor` streams (``update(row)``, never raises on a bad sample) and batches
(``run(log)``: the same step over arrays, identical numbers).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from grfguard.detect.blocks import cusum as cusum_batch
from grfguard.detect.blocks import cusum_step, excursion_peaks, robust_scale, threshold_for_rate
from grfguard.detect.observer import FaultObserver, ObserverConfig
from grfguard.detect.thresholds import Thresholds, default_thresholds
from grfguard.errors import ConfigError, LogFormatError
from grfguard.io.schema import (
    TIME,
    eta_col,
    flag_col,
    force_col,
    kind_col,
    recovered_col,
    vfs_col,
)
from grfguard.model.robot import SENSOR_NAMES, SIDES
from grfguard.recover.reconstruct import HandOver

__all__ = [
    "METHODS",
    "MonitorConfig",
    "Monitor",
    "calibrate_thresholds",
    "calibrate_monitor",
]

METHODS = ("default", "paper")
_ADDITIVE = ("offset", "drift")
_INFOLESS_SOURCES = ("nan", "const")
_PRIORITY = {"nan": 4, "const": 3, "swing": 2, "corner": 1, "total": 1}
_VFS_TOTAL = tuple(f"vfs_total_{s}" for s in SIDES)
_N = len(SENSOR_NAMES)
_NAN = float("nan")
#: Time constant of the low-pass that cleans a noisy sensor in the recovery [s].
NOISE_LOWPASS_TAU_S = 0.008


@dataclass(frozen=True)
class MonitorConfig:
    """Settings of :class:`Monitor`.

    Attributes:
        method: ``default`` (gated CUSUM tests) or ``paper`` (eq. 24-33).
        thresholds: Detector thresholds (default: the shipped calibrated ones).
        observer: The paper's observer settings (method ``paper``).
        vfs: Settings of the virtual force sensor (``VFSConfig``; None for its default).
        dt_s: Sampling period [s].
        gate_liftoff_s: Swing test starts this long after the planned lift-off [s].
        gate_before_touchdown_s: Swing test stops this long before the expected
            touchdown [s].
        gate_touchdown_s: Single-support tests start this long after the own touchdown [s]
            (feet land heel first: the planned contact is wrong for ~100 ms).
        gate_loaded_s: The constant-reading test starts this long after touchdown [s].
        clear_s: A flag clears after this long without alarm while its test is valid [s].
        blend_s: Time constant of the hand-over to and from the reconstruction [s].
        init_s: Initialisation window of the paper's observer [s].
        diagnostics: Also output the test statistics (``stat_*`` and ``res_*`` columns).
    """

    method: str = "default"
    thresholds: Thresholds = field(default_factory=default_thresholds)
    observer: ObserverConfig = field(default_factory=ObserverConfig)
    vfs: Any = None
    dt_s: float = 1e-3
    gate_liftoff_s: float = 0.12
    gate_before_touchdown_s: float = 0.18
    gate_touchdown_s: float = 0.15
    gate_loaded_s: float = 0.12
    clear_s: float = 1.0
    blend_s: float = 0.03
    init_s: float = 0.1
    diagnostics: bool = False

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ConfigError(
                f"monitor.method = {self.method!r} is unknown; use one of {list(METHODS)}"
            )
        if not isinstance(self.thresholds, Thresholds):
            raise ConfigError("monitor.thresholds must be a Thresholds (see Thresholds.from_toml)")
        for f in fields(self):
            if f.name.endswith("_s"):
                v = getattr(self, f.name)
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                    0.0 <= v < 100.0
                ):
                    raise ConfigError(f"monitor.{f.name} = {v!r} must be in [0, 100) s")
        if self.dt_s <= 0:
            raise ConfigError(f"monitor.dt_s = {self.dt_s!r} must be > 0 s")

    def with_method(self, method: str) -> MonitorConfig:
        """Copy with another detection method (``default`` or ``paper``)."""
        return replace(self, method=method)

    def with_thresholds(self, thresholds: Thresholds | str | Path) -> MonitorConfig:
        """Copy with other thresholds (object or TOML path)."""
        th = thresholds if isinstance(thresholds, Thresholds) else Thresholds.from_toml(thresholds)
        return replace(self, thresholds=th)

    def replace(self, **changes: Any) -> MonitorConfig:
        """Copy with some fields changed (validated)."""
        return replace(self, **changes)

    def to_toml(self) -> str:
        """TOML text: ``[monitor]``, ``[observer]`` and ``[thresholds]`` tables."""
        lines = ["[monitor]"]
        for f in fields(self):
            if f.name in ("thresholds", "observer", "vfs"):
                continue
            v = getattr(self, f.name)
            lines.append(f'{f.name} = "{v}"' if isinstance(v, str) else
                         f"{f.name} = {str(v).lower() if isinstance(v, bool) else repr(v)}")
        lines.append("")
        lines.append("[observer]")
        for k, v in self.observer.to_dict().items():
            lines.append(f"{k} = {v!r}")
        lines.append("")
        return "\n".join(lines) + self.thresholds.to_toml()

    @classmethod
    def from_toml_text(cls, text: str) -> MonitorConfig:
        """Parse TOML text (tables ``[monitor]``, ``[observer]``, ``[thresholds]``, ``[vfs]``)."""
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"monitor config is not valid TOML: {exc}") from exc
        mon = dict(doc.get("monitor", {}))
        names = {f.name for f in fields(cls)} - {"thresholds", "observer", "vfs"}
        extra = set(mon) - names
        if extra:
            raise ConfigError(f"unknown [monitor] keys {sorted(extra)}; allowed {sorted(names)}")
        kwargs: dict[str, Any] = dict(mon)
        if "observer" in doc:
            try:
                kwargs["observer"] = ObserverConfig(**doc["observer"])
            except TypeError as exc:
                raise ConfigError(f"bad [observer] table: {exc}") from exc
        if "thresholds" in doc:
            kwargs["thresholds"] = Thresholds.from_dict(doc["thresholds"])
        if "vfs" in doc:
            from grfguard.estimate.config import VFSConfig

            kwargs["vfs"] = VFSConfig(**doc["vfs"])
        return cls(**kwargs)

    @classmethod
    def from_toml(cls, path: str | Path) -> MonitorConfig:
        """Read a monitor config TOML file."""
        p = Path(path)
        if not p.is_file():
            raise ConfigError(f"monitor config {str(p)!r} does not exist")
        return cls.from_toml_text(p.read_text())


def _f(row: Mapping[str, Any], key: str) -> float:
    try:
        return float(row[key])
    except (KeyError, TypeError, ValueError):
        return _NAN


class _Sensor:
    """Per-sensor state of the default detector (plain floats)."""

    __slots__ = (
        "prev", "run", "gp", "gn", "cp", "cn", "flag", "source", "kind", "t_flag",
        "valid_since_alarm", "eta", "const_value", "varied", "returns", "n", "st", "sx",
        "stt", "stx", "sxx", "n_out", "gain", "hand", "last_rec", "x1", "x2",
        "last_alarm", "lp", "sn", "sL", "sr", "sLL", "sLr", "srr", "eta_st",
    )

    def __init__(self, blend_alpha_tau: float, dt: float) -> None:
        self.prev = _NAN
        self.run = 0
        self.gp = self.gn = 0.0
        self.cp = self.cn = 0.0
        self.hand = HandOver(blend_alpha_tau, dt)
        self.last_rec = 0.0
        self.x1 = self.x2 = _NAN
        self.lp = _NAN
        self.clear()

    def clear(self) -> None:
        self.flag = False
        self.source = ""
        self.kind = "none"
        self.t_flag = _NAN
        self.last_alarm = _NAN
        self.valid_since_alarm = 0
        self.eta = 0.0
        self.const_value = _NAN
        self.varied = False
        self.returns = 0
        self.n = 0
        self.st = self.sx = self.stt = self.stx = self.sxx = 0.0
        self.n_out = 0
        self.gain = _NAN
        self.sn = 0
        self.sL = self.sr = self.sLL = self.sLr = self.srr = 0.0
        self.eta_st = _NAN

    # ---- swing statistics: linear fit x = a + b (t - t_flag), outliers excluded
    def fit(self) -> tuple[float, float, float, float]:
        """(a, b, residual std, stderr of b); NaN where undefined."""
        n = self.n
        if n == 0:
            return _NAN, _NAN, _NAN, _NAN
        mx, mt = self.sx / n, self.st / n
        ctt = self.stt - n * mt * mt
        ctx = self.stx - n * mt * mx
        cxx = self.sxx - n * mx * mx
        if n < 3 or ctt <= 1e-12:
            return mx, 0.0, math.sqrt(max(cxx, 0.0) / max(n - 1, 1)), _NAN
        b = ctx / ctt
        a = mx - b * mt
        rss = max(cxx - b * ctx, 0.0)
        sd = math.sqrt(rss / (n - 2))
        return a, b, sd, sd / math.sqrt(ctt)


class Monitor:
    """Virtual force sensor + fault detection, isolation, classification and recovery.

    Args:
        config: Settings (method, thresholds, gates).
        vfs: A ``VirtualForceSensor`` for the robot, or None when every input row already
            carries the VFS outputs (``vfs_<s>``, ``vfs_total_<side>``).

    Example:
        >>> mon = Monitor.for_log(log)
        >>> out = mon.run(log)                  # log + vfs_*, flag_*, kind_*, eta_*, ...
        >>> mon.reset(); row_out = mon.update(log.iloc[0].to_dict())
    """

    def __init__(self, config: MonitorConfig | None = None, vfs: Any = None) -> None:
        self.config = config if config is not None else MonitorConfig()
        self.vfs = vfs
        self.reset()

    @classmethod
    def for_log(cls, log: pd.DataFrame, config: MonitorConfig | None = None) -> Monitor:
        """A monitor for ``log``: reuses its ``vfs_*`` columns when present, otherwise builds
        ``VirtualForceSensor.for_log(log, config.vfs)``; the sampling period from ``time``."""
        cfg = config if config is not None else MonitorConfig()
        if TIME in log.columns and len(log) > 1:
            dt = float(np.median(np.diff(log[TIME].to_numpy(float))))
            if math.isfinite(dt) and dt > 0 and abs(dt - cfg.dt_s) > 1e-9:
                cfg = replace(cfg, dt_s=dt, observer=replace(cfg.observer, dt_s=dt))
        has_vfs = all(vfs_col(s) in log.columns for s in SENSOR_NAMES) and all(
            c in log.columns for c in _VFS_TOTAL
        )
        vfs = None
        if not has_vfs:
            from grfguard.estimate.vfs import VirtualForceSensor

            vfs = VirtualForceSensor.for_log(log, cfg.vfs)
        return cls(cfg, vfs)

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget everything (filters, flags, contact timeline, VFS state)."""
        c = self.config
        if self.vfs is not None:
            self.vfs.reset()
        self._t0 = _NAN
        self._weight_sum = 0.0
        self._weight_n = 0
        self._c_prev = [_NAN, _NAN]
        self._t_td = [_NAN, _NAN]
        self._t_lo = [_NAN, _NAN]
        self._swing_dur = [_NAN, _NAN]
        self._guard = [False, False]
        self._tp = [0.0, 0.0]
        self._tn = [0.0, 0.0]
        self._votes = [[0.0] * 4, [0.0] * 4]
        self._sensors = [_Sensor(c.blend_s, c.dt_s) for _ in range(_N)]
        # paper method
        self._obs = FaultObserver(_N, c.observer)
        self._init_sum = [0.0] * _N
        self._init_cnt = [0] * _N
        self._init_done = False

    # ------------------------------------------------------------------ inputs
    def _vfs_row(self, row: Mapping[str, Any]) -> dict[str, float]:
        if self.vfs is not None:
            try:
                return self.vfs.update(row)
            except Exception:  # noqa: BLE001 - a bad sample must never raise
                return {}
        return {}

    def update(self, row: Mapping[str, Any]) -> dict[str, Any]:
        """Process one sample; never raises on a bad sample (NaN or missing keys are
        flagged as dropouts or skipped).

        Args:
            row: Mapping with the log-contract columns of one sample.

        Returns:
            Dict with the VFS outputs and ``flag_<s>``, ``kind_<s>``, ``eta_<s>``,
            ``recovered_<s>`` for every sensor.
        """
        vout = self._vfs_row(row)
        src = vout if self.vfs is not None else row
        t = _f(row, TIME)
        x = [_f(row, force_col(s)) for s in SENSOR_NAMES]
        v = [_f(src, vfs_col(s)) for s in SENSOR_NAMES]
        tot = [_f(src, c) for c in _VFS_TOTAL]
        cref = [_f(row, f"contact_ref_{s}") for s in SIDES]
        cest = [_f(src, f"contact_est_{s}") for s in SIDES]
        res = self._step(t, x, v, tot, cref, cest)
        out: dict[str, Any] = dict(vout)
        out.update(res)
        return out

    def run(self, log: pd.DataFrame) -> pd.DataFrame:
        """Reset, then process the whole log; returns ``log`` plus the output columns.

        Raises:
            LogFormatError: If ``time`` or a ``force_<s>`` column is missing.
        """
        missing = [c for c in (TIME, *(force_col(s) for s in SENSOR_NAMES)) if c not in log]
        if missing:
            raise LogFormatError(
                f"Monitor.run: the log lacks column(s) {missing}; see grfguard.io.schema"
            )
        self.reset()
        if self.vfs is not None:
            vdf = self.vfs.run(log)
            self.vfs.reset()
            src = vdf
        else:
            vdf = None
            src = log
        n = len(log)

        def col(frame: pd.DataFrame, name: str) -> list[float]:
            if name in frame.columns:
                return frame[name].to_numpy(dtype=float).tolist()
            return [_NAN] * n

        t = col(log, TIME)
        xs = [col(log, force_col(s)) for s in SENSOR_NAMES]
        vs = [col(src, vfs_col(s)) for s in SENSOR_NAMES]
        tots = [col(src, c) for c in _VFS_TOTAL]
        crefs = [col(log, f"contact_ref_{s}") for s in SIDES]
        cests = [col(src, f"contact_est_{s}") for s in SIDES]
        if self.config.method == "paper":
            res = self._run_paper(
                np.array(t), np.array(xs).T, np.array(vs).T
            )
        else:
            rows = []
            for k in range(n):
                rows.append(
                    self._step(
                        t[k],
                        [xs[i][k] for i in range(_N)],
                        [vs[i][k] for i in range(_N)],
                        [tots[0][k], tots[1][k]],
                        [crefs[0][k], crefs[1][k]],
                        [cests[0][k], cests[1][k]],
                    )
                )
            res = pd.DataFrame(rows, index=log.index) if rows else pd.DataFrame(index=log.index)
        out = log.copy()
        if vdf is not None:
            for c in vdf.columns:
                out[c] = vdf[c].to_numpy()
        for c in res.columns:
            out[c] = res[c].to_numpy()
        out.attrs = {**log.attrs, "monitor": self.describe()}
        return out

    def describe(self) -> dict[str, Any]:
        """The settings of this run as plain data (goes to the output's metadata)."""
        c = self.config
        vfs_cfg = getattr(self.vfs, "config", None) if self.vfs is not None else c.vfs
        return {
            "method": c.method,
            "vfs": vfs_cfg.to_dict() if hasattr(vfs_cfg, "to_dict") else
            ("precomputed columns" if self.vfs is None else None),
            "thresholds": c.thresholds.to_dict(),
        }

    # ------------------------------------------------------------------ paper method
    def _paper_init_step(self, x: list[float], v: list[float]) -> None:
        for i in range(_N):
            e = x[i] - v[i]
            if math.isfinite(e):
                self._init_sum[i] += e
                self._init_cnt[i] += 1

    def _paper_init_eta(self) -> np.ndarray:
        return np.array(
            [self._init_sum[i] / self._init_cnt[i] if self._init_cnt[i] else 0.0
             for i in range(_N)]
        )

    def _paper_step(self, t: float, x: list[float], v: list[float]) -> dict[str, Any]:
        th = self.config.thresholds.paper_eta_n
        out: dict[str, Any] = {}
        if math.isnan(self._t0) and math.isfinite(t):
            self._t0 = t
        in_init = not (math.isfinite(t) and t - self._t0 >= self.config.init_s)
        if in_init and not self._init_done:
            self._paper_init_step(x, v)
            for i, s in enumerate(SENSOR_NAMES):
                if self.config.diagnostics:
                    out[f"eta_filtered_{s}"] = 0.0
                out[flag_col(s)] = False
                out[kind_col(s)] = "none"
                out[eta_col(s)] = 0.0
                out[recovered_col(s)] = x[i] if math.isfinite(x[i]) else (
                    v[i] if math.isfinite(v[i]) else 0.0)
            return out
        if not self._init_done:
            eta0 = self._paper_init_eta()
            self._obs.eta_n = eta0.copy()
            self._obs.eta_filtered_n = eta0.copy()
            self._init_done = True
        eta, force, etaf = self._obs.update(np.array(x), np.array(v))
        if self.config.diagnostics:
            for i, s in enumerate(SENSOR_NAMES):
                out[f"eta_filtered_{s}"] = float(etaf[i])
        for i, s in enumerate(SENSOR_NAMES):
            fl = bool(abs(etaf[i]) > th[i])
            out[flag_col(s)] = fl
            out[kind_col(s)] = "unknown" if fl else "none"
            out[eta_col(s)] = float(eta[i])
            r = float(force[i])
            out[recovered_col(s)] = r if math.isfinite(r) else 0.0
        return out

    def _run_paper(self, t: np.ndarray, x: np.ndarray, v: np.ndarray) -> pd.DataFrame:
        """Batch form of :meth:`_paper_step` (``lfilter`` after the init window)."""
        n = len(t)
        th = np.array(self.config.thresholds.paper_eta_n)
        out: dict[str, Any] = {}
        fin = np.isfinite(t)
        if not fin.any():
            t0 = _NAN
            n_init = n
        else:
            t0 = float(t[np.flatnonzero(fin)[0]])
            late = fin & (t - t0 >= self.config.init_s)
            n_init = int(np.flatnonzero(late)[0]) if late.any() else n
        e = x[:n_init] - v[:n_init]
        ok = np.isfinite(e)
        cnt = ok.sum(axis=0)
        eta0 = np.where(cnt > 0, np.where(ok, e, 0.0).sum(axis=0) / np.maximum(cnt, 1), 0.0)
        flags = np.zeros((n, _N), bool)
        eta = np.zeros((n, _N))
        etaf = np.zeros((n, _N))
        rec = np.where(np.isfinite(x), x, np.where(np.isfinite(v), v, 0.0))
        if n_init < n:
            cfg = self.config.observer
            r = _observer_from(x[n_init:], v[n_init:], cfg, eta0)
            eta[n_init:] = r.eta_n
            etaf[n_init:] = r.eta_filtered_n
            flags[n_init:] = np.abs(r.eta_filtered_n) > th
            rec[n_init:] = np.where(np.isfinite(r.force_n), r.force_n, 0.0)
        for i, s in enumerate(SENSOR_NAMES):
            if self.config.diagnostics:
                out[f"eta_filtered_{s}"] = etaf[:, i]
            out[flag_col(s)] = flags[:, i]
            out[kind_col(s)] = np.where(flags[:, i], "unknown", "none").astype(object)
            out[eta_col(s)] = eta[:, i]
            out[recovered_col(s)] = rec[:, i]
        self._t0 = t0
        return pd.DataFrame(out)

    # ------------------------------------------------------------------ default method
    def _step(
        self,
        t: float,
        x: list[float],
        v: list[float],
        tot: list[float],
        cref: list[float],
        cest: list[float],
    ) -> dict[str, Any]:
        if self.config.method == "paper":
            return self._paper_step(t, x, v)
        c = self.config
        th = c.thresholds
        dt = c.dt_s
        if not math.isfinite(t):
            t = (self._last_t + dt) if hasattr(self, "_last_t") else 0.0
        self._last_t = t
        if math.isnan(self._t0):
            self._t0 = t
        # ---- weight (running mean of the VFS totals) for normalisation
        if math.isfinite(tot[0]) and math.isfinite(tot[1]):
            self._weight_sum += tot[0] + tot[1]
            self._weight_n += 1
        weight = self._weight_sum / self._weight_n if self._weight_n else _NAN
        # ---- contact timeline
        contact = [False, False]
        for f in range(2):
            cv = cref[f] if math.isfinite(cref[f]) else cest[f]
            if not math.isfinite(cv):
                cv = 1.0 if (math.isfinite(tot[f]) and math.isfinite(weight)
                             and tot[f] > 0.1 * weight) else 0.0
            cf = cv > 0.5
            contact[f] = cf
            prev = self._c_prev[f]
            if math.isnan(prev):
                self._t_td[f] = t if cf else _NAN
                self._t_lo[f] = _NAN if cf else t
            elif cf and prev < 0.5:
                if math.isfinite(self._t_lo[f]):
                    self._swing_dur[f] = t - self._t_lo[f]
                self._t_td[f] = t
            elif (not cf) and prev > 0.5:
                self._t_lo[f] = t
                self._guard[f] = False
            self._c_prev[f] = 1.0 if cf else 0.0
        swing_ok = [False, False]
        ss_ok = [False, False]
        loaded_ok = [False, False]
        for f in range(2):
            o = 1 - f
            exp_sw = self._swing_dur[f] if math.isfinite(self._swing_dur[f]) else \
                self._swing_dur[o]
            if not contact[f] and math.isfinite(self._t_lo[f]):
                since = t - self._t_lo[f]
                # no swing test before a swing duration is known (the touchdown time
                # must be predictable: heels land up to ~0.1 s early)
                swing_ok[f] = (math.isfinite(exp_sw) and since >= c.gate_liftoff_s
                               and since <= exp_sw - c.gate_before_touchdown_s)
            if contact[f] and math.isfinite(self._t_td[f]):
                loaded_ok[f] = t - self._t_td[f] >= c.gate_loaded_s
                exp_o = self._swing_dur[o] if math.isfinite(self._swing_dur[o]) else \
                    self._swing_dur[f]
                if not contact[o] and math.isfinite(self._t_lo[o]):
                    since_o = t - self._t_lo[o]
                    # the other foot's touchdown must be predictable (heel strikes
                    # come early): no test before one swing duration is known
                    ss_ok[f] = (
                        t - self._t_td[f] >= c.gate_touchdown_s
                        and since_o >= c.gate_liftoff_s
                        and math.isfinite(exp_o)
                        and since_o <= exp_o - c.gate_before_touchdown_s
                    )
        sig = th.sigma_swing_n
        # guard: two unflagged sensors of a swinging foot loaded at once = early
        # touchdown; latched until the next lift-off
        for f in range(2):
            if swing_ok[f]:
                if self._guard[f]:
                    swing_ok[f] = False
                    continue
                exp_sw = self._swing_dur[f] if math.isfinite(self._swing_dur[f]) else \
                    self._swing_dur[1 - f]
                if t - self._t_lo[f] < 0.5 * exp_sw:
                    continue  # an early touchdown only happens late in the swing
                hi = 0
                for i in range(4 * f, 4 * f + 4):
                    xi = x[i]
                    if not self._sensors[i].flag and math.isfinite(xi) and xi > 8.0 * sig:
                        hi += 1
                if hi >= 2:
                    swing_ok[f] = False
                    self._guard[f] = True
        alarms: list[str] = [""] * _N
        sens = self._sensors
        stat_sw = [_NAN] * _N
        stat_c = [_NAN] * _N
        res_sw = [_NAN] * _N
        res_c = [_NAN] * _N
        infoless_foot = [
            any(sens[i].flag and sens[i].source in _INFOLESS_SOURCES
                for i in range(4 * f, 4 * f + 4))
            for f in range(2)
        ]
        # ---- per-sensor tests
        for i in range(_N):
            s = sens[i]
            f = i // 4
            xi = x[i]
            if not math.isfinite(xi):
                alarms[i] = "nan"
                s.run = 0
                s.prev = _NAN
                continue
            if xi == s.prev:
                s.run += 1
            else:
                s.run = 0
                if s.flag and s.source == "const":
                    s.varied = True
            s.prev = xi
            if s.run + 1 >= th.const_samples and loaded_ok[f]:
                if s.flag and s.source == "const" and s.varied and xi == s.const_value:
                    s.returns += 1
                    s.varied = False
                alarms[i] = "const"
            if swing_ok[f]:
                z = xi / sig
                res_sw[i] = xi
                s.gp, s.gn = cusum_step(s.gp, s.gn, z, th.swing_kappa)
                stat_sw[i] = max(s.gp, s.gn)
                if stat_sw[i] > th.swing_h:
                    s.gp = s.gn = 0.0
                    if not alarms[i]:
                        alarms[i] = "swing"
                if s.flag and s.source == "swing":
                    s.valid_since_alarm += 1
                # classification statistics
                if s.flag and s.source == "swing":
                    self._swing_stats(s, t, xi, sig)
            if ss_ok[f] and math.isfinite(weight) and weight > 0 and math.isfinite(v[i]):
                comp = s.flag and s.kind in _ADDITIVE and s.source == "swing"
                corr = xi - (s.eta if comp else 0.0)
                r = (corr - v[i]) / weight
                res_c[i] = r
                z = r / th.corner_sigma
                s.cp, s.cn = cusum_step(s.cp, s.cn, z, th.corner_kappa)
                stat_c[i] = max(s.cp, s.cn)
                if stat_c[i] > th.corner_h:
                    s.cp = s.cn = 0.0
                    if not alarms[i] and not comp:
                        alarms[i] = "corner"
                if s.flag and s.source in ("corner", "total"):
                    if s.source == "corner" and abs(z) < th.corner_kappa:
                        s.valid_since_alarm += 1
                    if infoless_foot[f] or not math.isfinite(tot[f]):
                        self._stance_stats(s, xi - v[i], v[i])
        # ---- foot-total test
        stat_t = [_NAN, _NAN]
        res_t = [_NAN, _NAN]
        for f in range(2):
            idx = range(4 * f, 4 * f + 4)
            # the balance is only meaningful when every flagged sensor of the foot is
            # exactly compensated (swing-sized offset/drift) or is the one under test
            infoless = any(
                sens[i].flag
                and not (sens[i].source == "swing" and sens[i].kind in _ADDITIVE)
                and sens[i].source not in ("total", "corner")
                for i in idx
            )
            if not (ss_ok[f] and math.isfinite(tot[f]) and math.isfinite(weight)
                    and weight > 0) or infoless:
                continue
            corr = []
            for i in idx:
                s = sens[i]
                xi = x[i]
                if s.flag and s.kind in _ADDITIVE and s.source == "swing":
                    xi -= s.eta
                corr.append(xi)
            if not all(math.isfinite(q) for q in corr):
                continue
            r = (math.fsum(corr) - tot[f]) / weight
            res_t[f] = r
            z = r / th.total_sigma
            self._tp[f], self._tn[f] = cusum_step(self._tp[f], self._tn[f], z, th.total_kappa)
            stat_t[f] = max(self._tp[f], self._tn[f])
            sgn = 1.0 if z > 0 else -1.0
            # health evidence for stance-flagged sensors of this foot: a quiet residual
            for i in idx:
                s = sens[i]
                if s.flag and s.source in ("total", "corner"):
                    if abs(z) < th.total_kappa:
                        s.valid_since_alarm += 1
                    else:
                        s.valid_since_alarm = 0
            if abs(z) > th.total_kappa:
                for j, i in enumerate(idx):
                    if math.isfinite(v[i]):
                        self._votes[f][j] += sgn * (corr[j] - v[i])
            if self._tp[f] == 0.0 and self._tn[f] == 0.0:
                self._votes[f] = [0.0] * 4
            # stance statistics of a stance-flagged sensor: residual vs load by the
            # foot balance (the other corners healthy or corrected)
            for j, i in enumerate(idx):
                s = sens[i]
                if s.flag and s.source in ("total", "corner"):
                    others = [sens[k] for k in idx if k != i]
                    if all((not o.flag) or o.kind in _ADDITIVE for o in others):
                        load = tot[f] - math.fsum(corr[k] for k in range(4) if k != j)
                        self._stance_stats(s, x[i] - load, load)
            if stat_t[f] > th.total_h:
                self._tp[f] = self._tn[f] = 0.0
                already = [i for i in idx if sens[i].flag and sens[i].source in
                           ("total", "corner")]
                if already:
                    for i in already:
                        if not alarms[i]:
                            alarms[i] = "total"
                else:
                    cand = [(self._votes[f][j], i) for j, i in enumerate(idx)
                            if not sens[i].flag]
                    if cand:
                        i_best = max(cand)[1]
                        if not alarms[i_best]:
                            alarms[i_best] = "total"
                self._votes[f] = [0.0] * 4
        # ---- flags, kinds, estimates
        out: dict[str, Any] = {}
        for i, name in enumerate(SENSOR_NAMES):
            s = sens[i]
            f = i // 4
            a = alarms[i]
            if a:
                if not s.flag:
                    s.clear()
                    s.flag = True
                    s.t_flag = t
                    s.source = a
                    if a == "const":
                        s.const_value = x[i]
                elif _PRIORITY[a] > _PRIORITY.get(s.source, 0):
                    s.source = a
                    if a == "const":
                        s.const_value = x[i]
                        s.varied = False
                        s.returns = 0
                s.valid_since_alarm = 0
                s.last_alarm = t
            elif s.flag:
                self._maybe_clear(s, t, x[i], loaded_ok[f])
            if s.flag:
                self._classify(s, t, x[i])
            out[flag_col(name)] = s.flag
            out[kind_col(name)] = s.kind
        self._recover(t, x, v, tot, contact, ss_ok, out)
        if c.diagnostics:
            for i, name in enumerate(SENSOR_NAMES):
                out[f"stat_swing_{name}"] = stat_sw[i]
                out[f"stat_corner_{name}"] = stat_c[i]
                out[f"res_swing_{name}"] = res_sw[i]
                out[f"res_corner_{name}"] = res_c[i]
            for f, side in enumerate(SIDES):
                out[f"stat_total_{side}"] = stat_t[f]
                out[f"res_total_{side}"] = res_t[f]
                out[f"swing_ok_{side}"] = swing_ok[f]
                out[f"ss_ok_{side}"] = ss_ok[f]
        return out

    @staticmethod
    def _stance_stats(s: _Sensor, r: float, load: float) -> None:
        if not (math.isfinite(r) and math.isfinite(load)):
            return
        s.sn += 1
        s.sL += load
        s.sr += r
        s.sLL += load * load
        s.sLr += load * r
        s.srr += r * r
        s.eta_st = r if math.isnan(s.eta_st) else s.eta_st + (r - s.eta_st) * 0.02

    @staticmethod
    def _swing_stats(s: _Sensor, t: float, xi: float, sig: float) -> None:
        tt = t - s.t_flag
        if s.n >= 20:
            a, b, sd, _ = s.fit()
            pred = a + b * tt
            scale = max(sd, sig) if math.isfinite(sd) else sig
            if abs(xi - pred) > 8.0 * scale and abs(xi - pred) > 8.0 * sig:
                s.n_out += 1
                return
        s.n += 1
        s.st += tt
        s.sx += xi
        s.stt += tt * tt
        s.stx += tt * xi
        s.sxx += xi * xi

    def _maybe_clear(self, s: _Sensor, t: float, xi: float, loaded: bool) -> None:
        c = self.config
        need = int(round(c.clear_s / c.dt_s))
        last = s.last_alarm
        if s.source == "nan":
            if math.isfinite(xi) and t - last >= c.clear_s * 0.2:
                s.clear()
        elif s.source == "const":
            hold = c.clear_s * (5.0 if s.kind == "saturation" else 1.0)
            if loaded and s.run == 0:
                s.valid_since_alarm += 1
            if s.valid_since_alarm >= int(round(hold / c.dt_s)) * 0.5 and t - last >= hold:
                s.clear()
        else:
            # sparse faults (spikes) need a longer quiet stretch of valid test time
            k = 3.0 if s.kind == "spikes" else 0.5
            if s.valid_since_alarm >= need * k and t - last >= c.clear_s:
                s.clear()
        if not s.flag:
            s.gp = s.gn = s.cp = s.cn = 0.0

    def _classify(self, s: _Sensor, t: float, xi: float) -> None:
        sig = self.config.thresholds.sigma_swing_n
        if s.source == "nan":
            s.kind = "dropout"
            s.eta = _NAN
            return
        if s.source == "const":
            v = s.const_value
            if s.returns >= 1:
                s.kind = "saturation"
            elif math.isfinite(v) and abs(v - round(v)) < 1e-9:
                s.kind = "frozen"
            else:
                s.kind = "stuck"
            return
        if s.source == "swing":
            n_tot = s.n + s.n_out
            a, b, sd, se = s.fit()
            if s.n == 0:
                s.kind = "offset"
                s.eta = xi if s.eta == 0.0 else s.eta
                return
            if s.n_out >= 2 and s.n_out < 0.1 * n_tot and (not math.isfinite(sd)
                                                           or sd < 2.0 * sig):
                s.kind = "spikes"
                s.eta = 0.0
            elif math.isfinite(sd) and sd > 2.5 * sig and s.n >= 20:
                s.kind = "noise"
                s.eta = 0.0
            elif (s.n >= 100 and math.isfinite(se) and abs(b) > 2.0 and abs(b) > 6.0 * se
                  and (s.stt / s.n - (s.st / s.n) ** 2) > 0.01):
                s.kind = "drift"
                s.eta = a + b * (t - s.t_flag)
            else:
                s.kind = "offset"
                s.eta = s.sx / s.n
            return
        # stance-only evidence: residual = constant (offset) or proportional to the
        # load (gain), whichever fits better
        if s.sn >= 50:
            n = s.sn
            sse_const = s.srr - s.sr * s.sr / n
            g0 = s.sLr / s.sLL if s.sLL > 0 else 0.0
            sse_gain = s.srr - g0 * s.sLr
            if abs(g0) > 0.05 and sse_gain < sse_const and 1.0 + g0 > 0.05:
                s.kind = "gain"
                s.eta = _NAN
                s.gain = 1.0 + g0  # gain estimate for the recovery
                return
            s.kind = "offset"
            s.eta = s.eta_st
            return
        s.kind = "unknown"
        s.eta = s.eta_st if math.isfinite(s.eta_st) else _NAN

    def _recover(
        self,
        t: float,
        x: list[float],
        v: list[float],
        tot: list[float],
        contact: list[bool],
        ss_ok: list[bool],
        out: dict[str, Any],
    ) -> None:
        c = self.config
        dt = c.dt_s
        a_fast = min(1.0, dt / 0.005)
        sens = self._sensors
        corrected = [_NAN] * _N
        info = [True] * _N
        a_lp = min(1.0, dt / NOISE_LOWPASS_TAU_S)
        for i in range(_N):
            s = sens[i]
            xi = x[i]
            if math.isfinite(xi):
                s.lp = xi if math.isnan(s.lp) else s.lp + (xi - s.lp) * a_lp
            if s.flag and s.kind in _ADDITIVE and math.isfinite(s.eta):
                corrected[i] = xi - s.eta
            elif s.flag and s.kind == "gain" and s.gain > 0.05:
                corrected[i] = xi / s.gain
            elif s.flag and s.kind == "noise" and math.isfinite(s.lp):
                corrected[i] = s.lp
            elif s.flag and s.kind == "spikes":
                trip = [q for q in (xi, s.x1, s.x2) if math.isfinite(q)]
                corrected[i] = sorted(trip)[len(trip) // 2] if trip else _NAN
            elif s.flag:
                info[i] = False
            else:
                corrected[i] = xi
            s.x2, s.x1 = s.x1, xi
            if s.flag and s.kind == "saturation" and math.isfinite(xi) and \
                    xi != s.const_value:
                corrected[i] = xi
                info[i] = True
        total = tot[0] + tot[1]
        lacking_all = [j for j in range(_N) if not info[j]]
        known_all = math.fsum(corrected[j] for j in range(_N) if info[j] and
                              math.isfinite(corrected[j]))
        for i, name in enumerate(SENSOR_NAMES):
            s = sens[i]
            xi = x[i]
            if not s.flag and s.hand.w == 0.0 and math.isfinite(xi):
                # healthy and fully handed back: the measurement itself
                s.last_rec = xi
                out[recovered_col(name)] = xi
                out[eta_col(name)] = 0.0
                continue
            vi = v[i] if math.isfinite(v[i]) else 0.0
            if not info[i] and math.isfinite(total):
                # whole-body balance: the VFS total force minus every known sensor (the
                # total is precise in every phase, unlike the per-foot split of the VFS)
                rest = total - known_all
                if len(lacking_all) > 1:
                    vs = [max(v[j], 0.0) if math.isfinite(v[j]) else 0.0 for j in lacking_all]
                    share = (max(v[i], 0.0) if math.isfinite(v[i]) else 0.0) / sum(vs) \
                        if sum(vs) > 0 else 1.0 / len(lacking_all)
                    rest *= share
                repl = max(rest, 0.0)
            else:
                repl = max(vi, 0.0)
            # a reading without information is dropped fast (5 ms); additive corrections
            # and the hand-back blend over blend_s
            w = s.hand.update(1.0 if s.flag else 0.0,
                              a_fast if (s.flag and not info[i]) else None)
            rec_fault = corrected[i] if info[i] and math.isfinite(corrected[i]) else repl
            if s.flag and s.kind == "saturation" and not info[i]:
                rec_fault = max(rec_fault, s.const_value)  # clipped: the truth is above
            rec = HandOver.mix(w, x[i], rec_fault, s.last_rec)
            if not math.isfinite(rec):
                rec = s.last_rec
            s.last_rec = rec
            out[recovered_col(name)] = rec
            if s.flag:
                eta = s.eta if s.kind in _ADDITIVE else x[i] - rec
                out[eta_col(name)] = eta
            else:
                out[eta_col(name)] = 0.0


def _observer_from(
    x: np.ndarray, v: np.ndarray, cfg: ObserverConfig, eta0: np.ndarray
) -> Any:
    """:func:`run_observer` with a per-sensor initial η̂ (and low-pass state)."""
    from scipy.signal import lfilter

    from grfguard.detect.observer import ObserverResult, steady_state_gain

    g = steady_state_gain(cfg)
    k = g.k
    e = x - v
    valid = np.isfinite(e)
    n_t, n = e.shape
    if valid.all():
        eta, _ = lfilter([k], [1.0, -(1.0 - k)], e, axis=0, zi=((1.0 - k) * eta0)[None, :])
    else:
        eta = np.empty_like(e)
        prev = eta0.astype(float).copy()
        for i in range(n_t):
            cur = np.where(valid[i], (1.0 - k) * prev + k * e[i], prev)
            eta[i] = cur
            prev = cur
    eta_prev = np.vstack([eta0[None, :], eta[:-1]])
    force = x - eta_prev + g.k_n * (eta_prev - e)
    force = np.where(valid, force, np.where(np.isfinite(x), x - eta_prev, v))
    a = math.exp(-2.0 * math.pi * cfg.lowpass_hz * cfg.dt_s)
    eta_f, _ = lfilter([1.0 - a], [1.0, -a], eta, axis=0, zi=(a * eta0)[None, :])
    return ObserverResult(eta, force, eta_f, np.full(n_t, g.k_eta))


# ---------------------------------------------------------------------- calibration
def calibrate_thresholds(
    logs: Sequence[pd.DataFrame],
    false_alarm_rate_per_hour: float = 0.1,
    config: MonitorConfig | str | Path | None = None,
    safety: float = 1.5,
    min_h: float = 30.0,
) -> Thresholds:
    """Calibrate every threshold from fault-free logs for a stated false-alarm rate.

    Noise scales are robust (MAD) estimates over the valid phase of each test; CUSUM
    thresholds come from the exponential tail of the fault-free excursion peaks
    (:func:`~grfguard.detect.blocks.threshold_for_rate`), with the target rate split
    evenly over the 8 swing, 8 corner and 2 foot-total tests, and never below ``safety``
    times the largest peak seen. The paper's eq. 33 thresholds are ``safety`` times the
    largest fault-free ``|η_f|`` per sensor (its own tuning rule: the fault-free run).

    Args:
        logs: Fault-free logs (with or without VFS columns).
        false_alarm_rate_per_hour: Target rate of the whole detector [1/h].
        config: Monitor config (or a TOML path); its gates and CUSUM allowances are used.
        safety: Factor on the largest fault-free statistic.
        min_h: Lower bound of every CUSUM threshold [σ·samples] (a margin for walks
            unlike the calibration ones).

    Returns:
        New :class:`Thresholds`.
    """
    if isinstance(config, (str, Path)):
        config = MonitorConfig.from_toml(config)
    cfg = config if config is not None else MonitorConfig()
    if not logs:
        raise ConfigError("calibrate_thresholds needs at least one fault-free log")
    if not (false_alarm_rate_per_hour > 0):
        raise ConfigError(
            f"false_alarm_rate_per_hour = {false_alarm_rate_per_hour!r} must be > 0"
        )
    base = cfg.thresholds
    inf_th = base.replace(swing_h=1e300, total_h=1e300, corner_h=1e300,
                          paper_eta_n=(1e300,) * 8)
    runs = []
    paper_max = np.zeros(_N)
    hours = 0.0
    for log in logs:
        if any(c in log.columns and (log[c].astype(str) != "none").any()
               for c in (f"fault_kind_{s}" for s in SENSOR_NAMES)):
            raise ConfigError("calibrate_thresholds needs fault-free logs; this one has "
                              "injected faults (fault_kind_* != 'none')")
        mon = Monitor.for_log(log, replace(cfg, method="default", thresholds=inf_th,
                                           diagnostics=True))
        out = mon.run(log)
        runs.append(out)
        t = log[TIME].to_numpy(float)
        hours += (t[-1] - t[0]) / 3600.0
        pmon = Monitor(replace(cfg, method="paper", thresholds=inf_th, diagnostics=True), None)
        pout = pmon.run(out)
        etaf = pout[[f"eta_filtered_{s}" for s in SENSOR_NAMES]].to_numpy(float)
        paper_max = np.maximum(paper_max, np.nanmax(np.abs(etaf), axis=0))
    rate = false_alarm_rate_per_hour / 18.0
    sw = np.concatenate([r[[f"res_swing_{s}" for s in SENSOR_NAMES]].to_numpy(float).ravel()
                         for r in runs])
    sigma_sw = float(robust_scale(sw[np.isfinite(sw)])) if np.isfinite(sw).any() else \
        base.sigma_swing_n
    tot = np.concatenate([r[[f"res_total_{s}" for s in SIDES]].to_numpy(float).ravel()
                          for r in runs])
    sigma_t = float(robust_scale(tot[np.isfinite(tot)])) if np.isfinite(tot).any() else \
        base.total_sigma
    cor = np.concatenate([r[[f"res_corner_{s}" for s in SENSOR_NAMES]].to_numpy(float).ravel()
                          for r in runs])
    sigma_c = float(robust_scale(cor[np.isfinite(cor)])) if np.isfinite(cor).any() else \
        base.corner_sigma

    def peaks(prefix: str, names: Sequence[str], sigma: float, kappa: float) -> np.ndarray:
        out = []
        for r in runs:
            for nm in names:
                res = r[f"{prefix}{nm}"].to_numpy(float)
                m = np.isfinite(res)
                if not m.any():
                    continue
                g = cusum_batch(res[m] / sigma, kappa, 1e300, reset=False)
                out.append(excursion_peaks(np.maximum(g.g_pos, g.g_neg)))
        return np.concatenate(out) if out else np.zeros(0)

    p_sw = peaks("res_swing_", SENSOR_NAMES, sigma_sw, base.swing_kappa)
    p_t = peaks("res_total_", SIDES, sigma_t, base.total_kappa)
    p_c = peaks("res_corner_", SENSOR_NAMES, sigma_c, base.corner_kappa)
    h_sw = threshold_for_rate(p_sw, hours * 8, rate, safety, floor=min_h)
    h_t = threshold_for_rate(p_t, hours * 2, rate, safety, floor=min_h)
    h_c = threshold_for_rate(p_c, hours * 8, rate, safety, floor=min_h)
    paper_tr = tuple(float(max(safety * m, 1.0)) for m in paper_max)
    return base.replace(
        sigma_swing_n=sigma_sw,
        swing_h=h_sw,
        total_sigma=sigma_t,
        total_h=h_t,
        corner_sigma=sigma_c,
        corner_h=h_c,
        paper_eta_n=paper_tr,
        false_alarm_rate_per_hour=float(false_alarm_rate_per_hour),
        source=f"calibrated on {len(logs)} fault-free log(s), {hours * 60:.1f} min",
    )


def calibrate_monitor(
    logs: Sequence[pd.DataFrame],
    false_alarm_rate_per_hour: float = 0.1,
    config: MonitorConfig | str | Path | None = None,
) -> Thresholds:
    """Alias of :func:`calibrate_thresholds` (used by ``grfguard calibrate``)."""
    return calibrate_thresholds(logs, false_alarm_rate_per_hour, config)
