"""Every tuning number of the default detector, with its unit and where it came from.

The detector's thresholds (CUSUM allowances and thresholds, noise scales) are
*calibrated* from fault-free walks and live in :class:`~grfguard.detect.thresholds.Thresholds`;
its gates (how long after a touchdown a test starts, ...) are user settings of
:class:`~grfguard.detect.config.MonitorConfig`. What remains are the design constants
below: they were set by hand when the detector was written (on the default 60 s walk of
the reference robot (SURALP) and the fault scenarios of ``benchmarks/bench_monitor.py``)
and are not meant to be changed per robot. They are named here so that a reader of the
decision code sees a name, a unit and a reason instead of a bare number.

Durations are in seconds; a count of samples is derived at the log's sampling period
with :meth:`DetectTuning.samples` (``round(duration / dt)``; at 1 kHz 0.02 s = 20
samples).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

from grfguard.errors import ConfigError

__all__ = ["DetectTuning"]


@dataclass(frozen=True)
class DetectTuning:
    """Hand-set design constants of the default detector (see the module docstring).

    Attributes:
        contact_level: A planned or estimated contact signal above this is contact [-]
            (the signals are 0/1; 0.5 is the midpoint).
        contact_weight_fraction: Without any contact signal a foot is in contact when its
            VFS vertical force exceeds this fraction of the weight [-] (0.1: well above
            the VFS noise in swing, well below the lightest stance load).
        guard_min_swing_fraction: The early-touchdown guard only looks at the second
            part of a swing, from this fraction of the expected swing duration [-]
            (heel strikes come up to ~0.1 s early, never in the first half).
        guard_load_sigma: A swing sensor reading above this many swing noise sigmas is
            loaded [σ] (8: no false trigger on the fault-free walks).
        guard_min_sensors: An early touchdown loads at least this many unflagged sensors
            of the swinging foot at once (one loaded sensor is a fault, not a touchdown).
        outlier_sigma: In the swing fit of a flagged sensor a reading further than this
            many sigmas (fit scatter and sensor noise) from the line is an outlier [σ]
            (8: Gaussian noise never gets there; the spikes of the scenarios do).
        fit_min_s: Swing samples needed before the outlier gate and the noise kind are
            trusted [s] (20 samples at 1 kHz).
        stance_fit_min_s: Stance samples needed before offset vs gain is decided [s]
            (50 samples at 1 kHz).
        drift_fit_min_s: Swing samples needed before a drift is called [s] (100 samples
            at 1 kHz: the slope's standard error must be small).
        drift_min_slope_n_per_s: Smallest drift slope [N/s] (2 N/s: the slowest
            scenario drift, 15 N/s, with margin; slower ones stay offsets).
        drift_min_slope_se: The drift slope must exceed this many standard errors [-].
        drift_min_time_var_s2: The fit's time variance must exceed this [s²] (a fit
            over 0.35 s or more of swing: a slope over a few ms is meaningless).
        spikes_min_outliers: Outliers needed to call spikes.
        spikes_max_outlier_fraction: Spikes are sparse: outliers below this fraction of
            the swing samples [-].
        spikes_max_scatter_sigma: ... and the fit scatter below this many sensor sigmas
            [σ] (between spikes the reading is clean).
        noise_min_scatter_sigma: Fit scatter above this many sensor sigmas is a noisy
            sensor [σ].
        gain_min_change: A stance residual proportional to the load is a gain fault when
            ``|g - 1|`` exceeds this [-] (5 %: the load model's own error).
        gain_min: Estimated gains below this are not used (the division would blow up)
            [-].
        stance_eta_factor: Per-sample factor of the moving average of the stance residual
            that sizes a stance-only offset [-] (0.02 at 1 kHz: a 50 ms average).
        round_value_tol_n: A repeated reading within this of an integer is ``frozen``
            (a held round value such as 0 N), otherwise ``stuck`` [N].
        clear_dropout_fraction: A dropout clears after this fraction of ``clear_s``
            with finite readings [-].
        clear_saturation_factor: A saturation holds ``clear_s`` times this (the clipped
            flat top comes back every step) [-].
        clear_const_valid_fraction: A frozen/stuck flag clears after this fraction of its
            hold time of varying loaded readings [-].
        clear_spikes_valid_factor: Spikes are sparse: a quiet valid stretch of this many
            ``clear_s`` is needed before the flag clears [-].
        clear_valid_fraction: Any other flag clears after this fraction of ``clear_s`` of
            valid quiet test time [-].
        const_min_samples: Fewest identical readings that can mean frozen, whatever the
            rate (``Thresholds.const_s`` is 2.5 samples at 100 Hz; two equal readings in
            a row are too likely for a quantised healthy sensor) [-].
    """

    contact_level: float = 0.5
    contact_weight_fraction: float = 0.1
    guard_min_swing_fraction: float = 0.5
    guard_load_sigma: float = 8.0
    guard_min_sensors: int = 2
    outlier_sigma: float = 8.0
    fit_min_s: float = 0.02
    stance_fit_min_s: float = 0.05
    drift_fit_min_s: float = 0.1
    drift_min_slope_n_per_s: float = 2.0
    drift_min_slope_se: float = 6.0
    drift_min_time_var_s2: float = 0.01
    spikes_min_outliers: int = 2
    spikes_max_outlier_fraction: float = 0.1
    spikes_max_scatter_sigma: float = 2.0
    noise_min_scatter_sigma: float = 2.5
    gain_min_change: float = 0.05
    gain_min: float = 0.05
    stance_eta_factor: float = 0.02
    round_value_tol_n: float = 1e-9
    clear_dropout_fraction: float = 0.2
    clear_saturation_factor: float = 5.0
    clear_const_valid_fraction: float = 0.5
    clear_spikes_valid_factor: float = 3.0
    clear_valid_fraction: float = 0.5
    const_min_samples: int = 3

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (v >= 0.0):
                raise ConfigError(f"detect tuning {f.name} = {v!r} must be a number >= 0")
        if not (0.0 < self.stance_eta_factor <= 1.0):
            raise ConfigError(
                f"detect tuning stance_eta_factor = {self.stance_eta_factor!r} must be in (0, 1]"
            )
        if int(self.const_min_samples) != self.const_min_samples or self.const_min_samples < 2:
            raise ConfigError(f"detect tuning const_min_samples = {self.const_min_samples!r} "
                              "must be an integer >= 2")

    @staticmethod
    def samples(duration_s: float, dt_s: float) -> int:
        """Number of samples of ``duration_s`` at the sampling period ``dt_s`` [s]."""
        return int(round(duration_s / dt_s))

    def const_samples(self, const_s: float, dt_s: float) -> int:
        """Identical readings of a loaded sensor that mean frozen: ``const_s`` [s] at the
        sampling period ``dt_s`` [s], at least ``const_min_samples``."""
        return max(int(self.const_min_samples), self.samples(const_s, dt_s))

    def to_dict(self) -> dict[str, Any]:
        """Plain data (for metadata)."""
        return asdict(self)
