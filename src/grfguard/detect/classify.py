"""Fault kind, fault size and flag clearing of one flagged sensor.

The kind follows from the test that raised the flag (``SensorState.source``) and the
evidence gathered since:

- ``nan``: ``dropout`` (no size);
- ``const``: ``saturation`` when the same flat top came back after the reading varied,
  ``frozen`` at a round value, ``stuck`` at a noisy one;
- ``swing`` (the reading is the fault itself, :class:`~grfguard.detect.sensor_state.SwingFit`):
  ``spikes`` (a few isolated outliers, clean between them), ``noise`` (large scatter),
  ``drift`` (significant slope, size ``a + b·τ``), else ``offset`` (size = mean);
- ``corner``/``total`` (stance only, :class:`~grfguard.detect.sensor_state.StanceFit`):
  ``gain`` when the residual is proportional to the load and fits better than a
  constant, else ``offset`` (size = moving average of the residual); ``unknown`` while
  there are too few samples.

A flag clears after a quiet stretch while its test was valid (:func:`maybe_clear`).
All constants come from :class:`~grfguard.detect.tuning.DetectTuning`.
"""

from __future__ import annotations

import math

from grfguard.detect.config import MonitorConfig
from grfguard.detect.sensor_state import SensorState
from grfguard.detect.tuning import DetectTuning

__all__ = ["add_swing_sample", "classify", "maybe_clear"]

_NAN = float("nan")


def add_swing_sample(
    s: SensorState, t: float, x_n: float, sigma_n: float, tuning: DetectTuning, dt_s: float
) -> None:
    """Add a swing reading of a flagged sensor to its line fit, unless it is an outlier
    (further than ``outlier_sigma`` from the line once the fit has ``fit_min_s`` of data).

    Args:
        s: The sensor's state.
        t: Time [s].
        x_n: Reading [N].
        sigma_n: Swing noise of a sensor [N].
        tuning: Design constants.
        dt_s: Sampling period [s].
    """
    fit = s.swing
    tau = t - s.flag_time_s
    if fit.n >= tuning.samples(tuning.fit_min_s, dt_s):
        a, b, sd, _ = fit.fit()
        pred = a + b * tau
        scale = max(sd, sigma_n) if math.isfinite(sd) else sigma_n
        gate = tuning.outlier_sigma
        if abs(x_n - pred) > gate * scale and abs(x_n - pred) > gate * sigma_n:
            fit.outliers += 1
            return
    fit.add(tau, x_n)


def _classify_const(s: SensorState, tuning: DetectTuning) -> None:
    v = s.const_value_n
    if s.const_returns >= 1:
        s.kind = "saturation"
    elif math.isfinite(v) and abs(v - round(v)) < tuning.round_value_tol_n:
        s.kind = "frozen"
    else:
        s.kind = "stuck"


def _classify_swing(
    s: SensorState, t: float, x_n: float, sigma_n: float, tuning: DetectTuning, dt_s: float
) -> None:
    fit = s.swing
    n_tot = fit.n + fit.outliers
    a, b, sd, se = fit.fit()
    if fit.n == 0:
        s.kind = "offset"
        s.eta_n = x_n if s.eta_n == 0.0 else s.eta_n
        return
    tn = tuning
    if (fit.outliers >= tn.spikes_min_outliers
            and fit.outliers < tn.spikes_max_outlier_fraction * n_tot
            and (not math.isfinite(sd) or sd < tn.spikes_max_scatter_sigma * sigma_n)):
        s.kind = "spikes"
        s.eta_n = 0.0
    elif (math.isfinite(sd) and sd > tn.noise_min_scatter_sigma * sigma_n
          and fit.n >= tn.samples(tn.fit_min_s, dt_s)):
        s.kind = "noise"
        s.eta_n = 0.0
    elif (fit.n >= tn.samples(tn.drift_fit_min_s, dt_s) and math.isfinite(se)
          and abs(b) > tn.drift_min_slope_n_per_s and abs(b) > tn.drift_min_slope_se * se
          and fit.time_variance() > tn.drift_min_time_var_s2):
        s.kind = "drift"
        s.eta_n = a + b * (t - s.flag_time_s)
    else:
        s.kind = "offset"
        s.eta_n = fit.mean_x()


def _classify_stance(s: SensorState, tuning: DetectTuning, dt_s: float) -> None:
    st = s.stance
    if st.n >= tuning.samples(tuning.stance_fit_min_s, dt_s):
        sse_const, g0, sse_gain = st.offset_vs_gain()
        if abs(g0) > tuning.gain_min_change and sse_gain < sse_const and 1.0 + g0 > tuning.gain_min:
            s.kind = "gain"
            s.eta_n = _NAN
            s.gain = 1.0 + g0  # gain estimate for the recovery
            return
        s.kind = "offset"
        s.eta_n = st.eta_n
        return
    s.kind = "unknown"
    s.eta_n = st.eta_n if math.isfinite(st.eta_n) else _NAN


def classify(
    s: SensorState, t: float, x_n: float, sigma_n: float, tuning: DetectTuning, dt_s: float
) -> None:
    """Set ``s.kind`` and ``s.eta_n`` (and ``s.gain``) of a flagged sensor.

    Args:
        s: The sensor's state (flagged).
        t: Time [s].
        x_n: Current reading [N].
        sigma_n: Swing noise of a sensor [N].
        tuning: Design constants.
        dt_s: Sampling period [s].
    """
    if s.source == "nan":
        s.kind = "dropout"
        s.eta_n = _NAN
    elif s.source == "const":
        _classify_const(s, tuning)
    elif s.source == "swing":
        _classify_swing(s, t, x_n, sigma_n, tuning, dt_s)
    else:
        _classify_stance(s, tuning, dt_s)


def maybe_clear(
    s: SensorState, t: float, x_n: float, loaded: bool, config: MonitorConfig,
    tuning: DetectTuning,
) -> None:
    """Clear the flag of ``s`` after a quiet stretch (no alarm at sample ``t``).

    Args:
        s: The sensor's state (flagged, no alarm now).
        t: Time [s].
        x_n: Current reading [N].
        loaded: The constant-reading test is valid on the sensor's foot.
        config: ``clear_s`` and ``dt_s``.
        tuning: The clearing factors.
    """
    c = config
    tn = tuning
    last = s.last_alarm_s
    if s.source == "nan":
        if math.isfinite(x_n) and t - last >= c.clear_s * tn.clear_dropout_fraction:
            s.clear()
    elif s.source == "const":
        hold = c.clear_s * (tn.clear_saturation_factor if s.kind == "saturation" else 1.0)
        if loaded and s.repeats == 0:
            s.quiet_valid += 1
        if (s.quiet_valid >= tn.samples(hold, c.dt_s) * tn.clear_const_valid_fraction
                and t - last >= hold):
            s.clear()
    else:
        # sparse faults (spikes) need a longer quiet stretch of valid test time
        k = tn.clear_spikes_valid_factor if s.kind == "spikes" else tn.clear_valid_fraction
        if s.quiet_valid >= tn.samples(c.clear_s, c.dt_s) * k and t - last >= c.clear_s:
            s.clear()
    if not s.flag:
        s.reset_sums()
