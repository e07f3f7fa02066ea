"""Settings of the sensor monitor (:class:`MonitorConfig`) and their TOML form.

The gates and clearing time are user settings in seconds; the detector's calibrated
thresholds are a :class:`~grfguard.detect.thresholds.Thresholds`; the hand-set design
constants of the decision code are in :class:`~grfguard.detect.tuning.DetectTuning`.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from grfguard._lazy import lazy_module
from grfguard.detect.observer import ObserverConfig
from grfguard.detect.thresholds import Thresholds, default_thresholds
from grfguard.errors import ConfigError
from grfguard.io.schema import TIME

pd = lazy_module("pandas")  # (imported on first use: `grfguard run` never does)

__all__ = ["METHODS", "MonitorConfig", "config_for_log"]

METHODS = ("default", "paper")


@dataclass(frozen=True)
class MonitorConfig:
    """Settings of :class:`Monitor`.

    Attributes:
        method: ``default`` (gated CUSUM tests) or ``paper`` (eq. 24-33).
        thresholds: Detector thresholds (default: the shipped calibrated ones).
        observer: The paper's observer settings (method ``paper``).
        vfs: Settings of the virtual force sensor (``VFSConfig``; None for its default).
        dt_s: Sampling period of the log [s]. ``Monitor.for_log`` (through
            :func:`config_for_log`) always replaces it by the log's rate, e.g. 0.01 for a
            100 Hz log; the 1 ms default holds only for a monitor built without a log
            (``Monitor(config)``, live use), so set it then to the period of the samples
            fed. The observer's ``dt_s`` follows it (one rate per monitor).
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
        compiled: ``Monitor.for_log`` runs the compiled virtual force sensor
            (:mod:`grfguard.kernels`) when it covers the VFS settings, and the monitor its
            compiled guards, detector, recovery and standing layer when it covers the
            settings (``Monitor.compiled_reason``); False keeps the pure-Python stages.
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
    compiled: bool = True

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
        if not isinstance(self.observer, ObserverConfig):
            raise ConfigError("monitor.observer must be an ObserverConfig")
        if self.observer.dt_s != self.dt_s:  # the observer runs at the monitor's rate
            object.__setattr__(self, "observer", replace(self.observer, dt_s=self.dt_s))

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


def config_for_log(log: pd.DataFrame, config: MonitorConfig | None = None) -> MonitorConfig:
    """``config`` (default :class:`MonitorConfig`) with the sampling period of ``log``
    (median step of its ``time`` column [s]) in ``dt_s`` and in the observer's ``dt_s``:
    whatever ``config.dt_s`` said, the monitor of a log runs at the log's rate (a 100 Hz
    log gives ``dt_s = 0.01``). A log without ``time`` or with one row keeps
    ``config.dt_s``."""
    cfg = config if config is not None else MonitorConfig()
    if TIME in log.columns and len(log) > 1:
        dt = float(np.median(np.diff(log[TIME].to_numpy(float))))
        if math.isfinite(dt) and dt > 0 and abs(dt - cfg.dt_s) > 1e-9:
            cfg = replace(cfg, dt_s=dt, observer=replace(cfg.observer, dt_s=dt))
    return cfg
