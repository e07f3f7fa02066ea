"""Per-sensor state of the default detector: CUSUM sums, flag, kind and fit statistics.

Plain floats and ints (the detector runs at 1 kHz in pure Python). Two running fits
feed the fault kind (:mod:`grfguard.detect.classify`):

- :class:`SwingFit`: in swing the true force is zero, so the reading of a flagged sensor
  is the fault itself; a least-squares line ``x = a + b (t - t_flag)`` over the swing
  samples (outliers excluded) gives offset ``a``, drift slope ``b``, scatter and the
  standard error of ``b``;
- :class:`StanceFit`: in stance the residual ``r = N_meas - load`` against the load
  tells an offset (``r`` constant) from a gain (``r = (g - 1)·load``).
"""

from __future__ import annotations

import math

__all__ = ["SwingFit", "StanceFit", "SensorState"]

_NAN = float("nan")


class SwingFit:
    """Running sums of a line fit ``x = a + b·τ`` (τ = time since the flag [s], x [N])."""

    __slots__ = ("n", "sum_t", "sum_x", "sum_tt", "sum_tx", "sum_xx", "outliers")

    def __init__(self) -> None:
        self.n = 0
        self.sum_t = self.sum_x = self.sum_tt = self.sum_tx = self.sum_xx = 0.0
        self.outliers = 0

    def add(self, tau_s: float, x_n: float) -> None:
        """Add one sample (time since the flag [s], reading [N])."""
        self.n += 1
        self.sum_t += tau_s
        self.sum_x += x_n
        self.sum_tt += tau_s * tau_s
        self.sum_tx += tau_s * x_n
        self.sum_xx += x_n * x_n

    def mean_x(self) -> float:
        """Mean reading [N] (needs ``n > 0``)."""
        return self.sum_x / self.n

    def time_variance(self) -> float:
        """Variance of the sample times [s²] (needs ``n > 0``)."""
        return self.sum_tt / self.n - (self.sum_t / self.n) ** 2

    def fit(self) -> tuple[float, float, float, float]:
        """``(a [N], b [N/s], residual std [N], stderr of b [N/s])``; NaN where undefined."""
        n = self.n
        if n == 0:
            return _NAN, _NAN, _NAN, _NAN
        mx, mt = self.sum_x / n, self.sum_t / n
        ctt = self.sum_tt - n * mt * mt
        ctx = self.sum_tx - n * mt * mx
        cxx = self.sum_xx - n * mx * mx
        if n < 3 or ctt <= 1e-12:
            return mx, 0.0, math.sqrt(max(cxx, 0.0) / max(n - 1, 1)), _NAN
        b = ctx / ctt
        a = mx - b * mt
        rss = max(cxx - b * ctx, 0.0)
        sd = math.sqrt(rss / (n - 2))
        return a, b, sd, sd / math.sqrt(ctt)


class StanceFit:
    """Running sums of the stance residual ``r`` [N] against the load ``L`` [N], and a
    moving average of ``r`` (the size of a stance-only offset)."""

    __slots__ = ("n", "sum_load", "sum_res", "sum_load2", "sum_load_res", "sum_res2",
                 "eta_n")

    def __init__(self) -> None:
        self.n = 0
        self.sum_load = self.sum_res = self.sum_load2 = self.sum_load_res = 0.0
        self.sum_res2 = 0.0
        self.eta_n = _NAN

    def add(self, res_n: float, load_n: float, factor: float) -> None:
        """Add one sample; ``factor`` is the per-sample moving-average factor [-]."""
        if not (math.isfinite(res_n) and math.isfinite(load_n)):
            return
        self.n += 1
        self.sum_load += load_n
        self.sum_res += res_n
        self.sum_load2 += load_n * load_n
        self.sum_load_res += load_n * res_n
        self.sum_res2 += res_n * res_n
        self.eta_n = res_n if math.isnan(self.eta_n) else self.eta_n + (res_n - self.eta_n) * factor

    def offset_vs_gain(self) -> tuple[float, float, float]:
        """``(sse_offset [N²], g - 1 [-], sse_gain [N²])``: residual sum of squares of the
        constant model and of the proportional model ``r = (g - 1)·L``."""
        sse_const = self.sum_res2 - self.sum_res * self.sum_res / self.n
        g0 = self.sum_load_res / self.sum_load2 if self.sum_load2 > 0 else 0.0
        sse_gain = self.sum_res2 - g0 * self.sum_load_res
        return sse_const, g0, sse_gain


class SensorState:
    """Everything the detector remembers about one sensor.

    Attributes:
        last_reading_n: Previous finite reading [N] (NaN after a NaN).
        repeats: How many times in a row the reading repeated exactly.
        pairs: Pairs of consecutive finite loaded readings in runs that ended while
            unflagged (never cleared).
        chance_repeats: Of those, the exact repeats: a quantised healthy sensor's chance
            repeats (never cleared).
        run_pairs, run_repeats: The same for the run in progress (committed when it
            ends).
        swing_pos, swing_neg: Swing CUSUM sums [σ·samples].
        corner_pos, corner_neg: Corner CUSUM sums [σ·samples].
        flag: The sensor is flagged faulty.
        source: The test that raised (or last upgraded) the flag: ``nan``, ``const``,
            ``swing``, ``corner`` or ``total``.
        kind: Estimated fault kind (``none`` when not flagged).
        flag_time_s: Time of the flag [s].
        last_alarm_s: Time of the last alarm [s].
        quiet_valid: Samples without alarm while the flagging test was valid.
        eta_n: Estimated additive fault [N] (NaN where it is not additive).
        gain: Estimated gain [-] (gain faults).
        const_value_n: The repeated reading of a ``const`` flag [N].
        varied: The reading changed since the ``const`` flag (saturation tracking).
        const_returns: How often the flat top came back after a change.
        swing: :class:`SwingFit` since the flag.
        stance: :class:`StanceFit` since the flag.
    """

    __slots__ = (
        "last_reading_n", "repeats", "pairs", "chance_repeats", "run_pairs", "run_repeats",
        "swing_pos", "swing_neg", "corner_pos", "corner_neg",
        "flag", "source", "kind", "flag_time_s", "last_alarm_s", "quiet_valid", "eta_n",
        "gain", "const_value_n", "varied", "const_returns", "swing", "stance",
    )

    def __init__(self) -> None:
        self.last_reading_n = _NAN
        self.repeats = 0
        self.pairs = 0
        self.chance_repeats = 0
        self.run_pairs = 0
        self.run_repeats = 0
        self.swing_pos = self.swing_neg = 0.0
        self.corner_pos = self.corner_neg = 0.0
        self.clear()

    def clear(self) -> None:
        """Drop the flag and everything learnt about the fault."""
        self.flag = False
        self.source = ""
        self.kind = "none"
        self.flag_time_s = _NAN
        self.last_alarm_s = _NAN
        self.quiet_valid = 0
        self.eta_n = 0.0
        self.const_value_n = _NAN
        self.varied = False
        self.const_returns = 0
        self.gain = _NAN
        self.swing = SwingFit()
        self.stance = StanceFit()

    def reset_sums(self) -> None:
        """Swing and corner CUSUM sums back to zero."""
        self.swing_pos = self.swing_neg = self.corner_pos = self.corner_neg = 0.0
