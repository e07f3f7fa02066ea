"""Detector thresholds: a frozen, validated dataclass with a TOML round trip.

The shipped defaults (``default_thresholds.toml`` next to this module) were calibrated
by ``benchmarks/calibrate_default_thresholds.py`` on fault-free simulated walks whose
seeds are not used by the tests. :func:`grfguard.detect.calibrate.calibrate_thresholds`
makes new ones from your own fault-free logs.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import asdict, dataclass, fields, replace
from importlib import resources
from pathlib import Path
from typing import Any

from grfguard.errors import ConfigError

__all__ = [
    "Thresholds",
    "default_thresholds",
    "paper_vfs_thresholds",
    "DEFAULT_THRESHOLDS_FILE",
    "PAPER_VFS_THRESHOLDS_FILE",
]

DEFAULT_THRESHOLDS_FILE = "default_thresholds.toml"
#: Thresholds for the paper's method on the paper's own virtual sensor (eq. 1-23).
PAPER_VFS_THRESHOLDS_FILE = "paper_vfs_thresholds.toml"
#: Sampling period at which a legacy ``const_samples`` count was meant [s].
_LEGACY_DT_S = 1e-3


@dataclass(frozen=True)
class Thresholds:
    """Every threshold of the default detector and of the paper's method.

    Residuals are normalised per phase: swing readings by the sensor noise ``sigma_swing_n``
    (the true force is exactly zero in swing), stance residuals by a fraction of the
    robot's weight (so one threshold fits gaits and robot sizes). CUSUM drift allowances
    ``*_kappa`` are in σ, thresholds ``*_h`` in σ·samples.

    Attributes:
        sigma_swing_n: Noise of a sole sensor in swing [N].
        swing_kappa: Swing CUSUM drift allowance [σ].
        swing_h: Swing CUSUM threshold [σ·samples].
        total_sigma: Scale of the foot-total residual in clean single support [fraction of
            the weight].
        total_kappa: Foot-total CUSUM drift allowance [σ].
        total_h: Foot-total CUSUM threshold [σ·samples].
        corner_sigma: Scale of a per-corner residual in clean single support [fraction of
            the weight].
        corner_kappa: Corner CUSUM drift allowance [σ].
        corner_h: Corner CUSUM threshold [σ·samples].
        const_s: A loaded sensor whose reading stays exactly the same this long is frozen,
            stuck or clipped [s] (25 samples at 1 kHz, 5 at 200 Hz; at least
            :attr:`~grfguard.detect.tuning.DetectTuning.const_min_samples` identical
            readings, 3 at 100 Hz; longer for a sensor whose quantised readings repeat
            by chance, see :func:`~grfguard.detect.residual_tests.constant_test`).
            Files written before it was in seconds carry
            ``const_samples`` (counted at 1 kHz, the rate of every shipped calibration);
            it is read as ``const_samples`` x 1 ms.
        paper_eta_n: Eq. 33 thresholds on the low-passed η̂ of the paper's method, one per
            sensor r1..r4, l1..l4 [N].
        false_alarm_rate_per_hour: The target rate they were calibrated for [1/h].
        source: Free text: where they come from.
    """

    # Built-in values = the shipped calibration, rounded (used if the file is missing).
    sigma_swing_n: float = 2.0
    swing_kappa: float = 3.0
    swing_h: float = 30.0
    total_sigma: float = 0.0038
    total_kappa: float = 3.0
    total_h: float = 30.0
    corner_sigma: float = 0.011
    corner_kappa: float = 3.0
    corner_h: float = 30.0
    const_s: float = 0.025
    paper_eta_n: tuple[float, ...] = (24.4, 39.3, 35.6, 32.0, 29.8, 15.8, 22.8, 19.4)
    false_alarm_rate_per_hour: float = 0.1
    source: str = "builtin"

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "source":
                if not isinstance(v, str):
                    raise ConfigError(f"thresholds.source must be text, got {v!r}")
                continue
            if f.name == "paper_eta_n":
                try:
                    t = tuple(float(x) for x in v)
                except (TypeError, ValueError):
                    raise ConfigError(
                        f"thresholds.paper_eta_n must be 8 numbers [N], got {v!r}"
                    ) from None
                if len(t) != 8 or not all(x > 0 for x in t):
                    raise ConfigError(
                        f"thresholds.paper_eta_n must be 8 numbers > 0 [N], got {v!r}"
                    )
                object.__setattr__(self, f.name, t)
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v):
                raise ConfigError(f"thresholds.{f.name} must be a number, got {v!r}")
            lo = 0.0 if f.name.endswith("kappa") else 1e-12
            if not (v >= lo):
                raise ConfigError(f"thresholds.{f.name} = {v!r} must be >= {lo}")

    def replace(self, **changes: Any) -> Thresholds:
        """Copy with some fields changed (validated)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict (``paper_eta_n`` as a list)."""
        d = asdict(self)
        d["paper_eta_n"] = list(self.paper_eta_n)
        return d

    def to_toml(self) -> str:
        """TOML text with a ``[thresholds]`` table."""
        lines = ["[thresholds]"]
        for k, v in self.to_dict().items():
            if isinstance(v, str):
                lines.append(f'{k} = "{v}"')
            elif isinstance(v, list):
                lines.append(f"{k} = [{', '.join(repr(float(x)) for x in v)}]")
            elif isinstance(v, float) and math.isinf(v):
                lines.append(f"{k} = inf")
            else:
                lines.append(f"{k} = {v!r}")
        return "\n".join(lines) + "\n"

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Thresholds:
        """From a dict (unknown keys are an error)."""
        names = {f.name for f in fields(cls)}
        data = dict(data)
        if "const_samples" in data:  # legacy: a count at 1 kHz (see ``const_s``)
            n = data.pop("const_samples")
            if "const_s" in data:
                raise ConfigError("thresholds: give const_s [s] only, not also const_samples")
            if isinstance(n, bool) or not isinstance(n, int) or n < 2:
                raise ConfigError(f"thresholds.const_samples = {n!r} must be an integer >= 2 "
                                  "(samples at 1 kHz; prefer const_s [s])")
            data["const_s"] = n * _LEGACY_DT_S
        extra = set(data) - names
        if extra:
            raise ConfigError(f"unknown threshold keys {sorted(extra)}; allowed {sorted(names)}")
        return cls(**data)

    @classmethod
    def from_toml_text(cls, text: str) -> Thresholds:
        """Parse TOML text with a ``[thresholds]`` table (or top-level keys)."""
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"thresholds TOML is not valid TOML: {exc}") from exc
        return cls.from_dict(doc.get("thresholds", doc))

    @classmethod
    def from_toml(cls, path: str | Path) -> Thresholds:
        """Read a thresholds TOML file (as written by ``grfguard calibrate``)."""
        p = Path(path)
        if not p.is_file():
            raise ConfigError(f"thresholds file {str(p)!r} does not exist; make one with "
                              "`grfguard calibrate`")
        return cls.from_toml_text(p.read_text())


def _shipped(name: str) -> Thresholds | None:
    try:
        text = resources.files("grfguard.detect").joinpath(name).read_text()
    except (FileNotFoundError, OSError):
        return None
    return Thresholds.from_toml_text(text)


def default_thresholds() -> Thresholds:
    """The shipped thresholds (package data), or the built-in values if it is missing."""
    return _shipped(DEFAULT_THRESHOLDS_FILE) or Thresholds()


def paper_vfs_thresholds() -> Thresholds:
    """Thresholds for the paper's observer on the paper's virtual sensor.

    The paper picks its eq. 33 thresholds from a fault-free run of its own pipeline; these
    were picked the same way (``benchmarks/calibrate_default_thresholds.py --vfs paper``)
    on the calibration walks. Falls back to :func:`default_thresholds`.
    """
    return _shipped(PAPER_VFS_THRESHOLDS_FILE) or default_thresholds()
