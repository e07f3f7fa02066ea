"""A recovered force that is a better estimate of the true force than ``reading - offset``.

After an offset, drift or gain fault is recovered, ``recovered_<s> = N_meas - η̂`` (or
``N_meas / ĝ``) still carries the load cell's own white noise: on a light robot that
noise is a large share of the weight (G1: 2 N of 327 N, 0.61 %). The tracker here is a
steady-state Kalman filter (an alpha-beta filter) on the recovered force with the state
force and force rate:

- measurement noise: the cell's noise ``noise_n`` [N] (the calibrated
  ``Thresholds.sigma_swing_n``: the spread of an unloaded cell, where the true force is
  exactly zero);
- process: white force acceleration of power spectral density ``q = (acc_psd · m g)²``
  [N²/s³] with ``acc_psd = 10 /s^1.5`` (so it scales with the robot's weight; set on
  simulated walks of two shipped corner-cell robots, 33 kg and 114 kg: any value from 3
  to 100 keeps the 33 kg robot's offset recovery below 0.5 % of the weight at 1 kHz, 10
  is the best of that range on both).

It has no lag on a force that changes at a constant rate (a type-2 tracker: zero
steady-state error on a ramp), and it reduces white noise by about 1.6x at 1 kHz
(G1's recovered offsets: 0.61 % -> 0.38 % of the weight; BENCHMARKS.md "Monitoring Talos
and G1"). At 100-200 Hz a walking foot's force changes too much between samples for a
sizeable gain (G1: 0.60 % -> 0.52-0.56 %).

It only replaces the recovered force where a sensor is flagged with a kind whose
recovery comes from the reading (offset, drift, gain): healthy sensors stay the
measurement, and reconstructions without a reading (frozen, dropout, ...) stay the
whole-body balance. :func:`grfguard.estimate.described.run_described` applies it to the
corner cells of described robots (G1); :class:`~grfguard.pipeline.Monitor` alone does not
(its outputs are unchanged; call :func:`track_recovered` on its output to get the same).

Example:
    >>> out = track_recovered(monitor_output, weight_n=327.0, noise_n=2.0)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from grfguard._lazy import lazy_module
from grfguard.errors import ConfigError

pd = lazy_module("pandas")  # (imported on first use: `grfguard run` never does)

__all__ = ["TRACKED_KINDS", "ForceTracker", "TrackConfig", "alpha_beta_gains",
           "track_recovered"]

#: Fault kinds whose recovery starts from the sensor's reading.
TRACKED_KINDS = ("offset", "drift", "gain")


@dataclass(frozen=True)
class TrackConfig:
    """Settings of the recovered-force tracker.

    Attributes:
        noise_n: White noise of a load cell [N] (``Thresholds.sigma_swing_n``).
        weight_n: The robot's weight m g [N].
        acc_psd: Force acceleration noise ``sqrt(q) / (m g)`` [1/s^1.5] (module docstring).
    """

    noise_n: float
    weight_n: float
    acc_psd: float = 10.0

    def __post_init__(self) -> None:
        for name in ("noise_n", "weight_n", "acc_psd"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                    math.isfinite(v) and v > 0.0):
                raise ConfigError(f"recovered-force tracker: {name} = {v!r} must be a "
                                  "finite number > 0")

    @property
    def q(self) -> float:
        """Process noise PSD [N²/s³]."""
        return (self.acc_psd * self.weight_n) ** 2


def alpha_beta_gains(dt_s: float, config: TrackConfig) -> tuple[float, float]:
    """Steady-state Kalman gains ``(alpha [-], beta [1/s])`` of the force / force-rate
    filter at sampling period ``dt_s`` [s] (the Riccati recursion iterated to its fixed
    point)."""
    if not (math.isfinite(dt_s) and dt_s > 0):
        raise ConfigError(f"recovered-force tracker: dt_s = {dt_s!r} must be > 0 [s]")
    F = np.array([[1.0, dt_s], [0.0, 1.0]])
    Q = config.q * np.array([[dt_s**3 / 3, dt_s**2 / 2], [dt_s**2 / 2, dt_s]])
    R = config.noise_n**2
    P = np.diag([R, config.q * dt_s])  # any start: the recursion forgets it
    K = np.zeros(2)
    for _ in range(100_000):
        Pp = F @ P @ F.T + Q
        K_new = Pp[:, 0] / (Pp[0, 0] + R)
        P = Pp - np.outer(K_new, Pp[0, :])
        if np.allclose(K_new, K, rtol=1e-12, atol=0.0):
            break
        K = K_new
    return float(K_new[0]), float(K_new[1])


class ForceTracker:
    """Streaming tracker of ``n`` forces (one sample of each per :meth:`step`).

    Args:
        n: Number of sensors.
        dt_s: Sampling period [s].
        config: Noise and process settings.
    """

    def __init__(self, n: int, dt_s: float, config: TrackConfig) -> None:
        self.dt_s = float(dt_s)
        self.alpha, self.beta = alpha_beta_gains(self.dt_s, config)
        self.n = int(n)
        self.reset()

    def reset(self) -> None:
        """Forget the tracked forces (the next reading starts each at rest)."""
        self.f = [math.nan] * self.n
        self.r = [0.0] * self.n
        self.last = [math.nan] * self.n

    def step(self, z: Sequence[float]) -> list[float]:
        """Tracked forces [N] after the readings ``z`` [N] (a non-finite reading counts
        as the last finite one; NaN out until a sensor's first finite reading)."""
        out = []
        dt, a, b = self.dt_s, self.alpha, self.beta
        for i, zi in enumerate(z):
            if math.isfinite(zi):
                self.last[i] = float(zi)
            else:
                zi = self.last[i]
            f, r = self.f[i], self.r[i]
            if math.isnan(f):
                self.f[i], self.r[i] = zi, 0.0
                out.append(zi)
                continue
            p = f + dt * r
            e = zi - p
            f, r = p + a * e, r + b * e
            self.f[i], self.r[i] = f, r
            out.append(f)
        return out


def _track_series(z: np.ndarray, dt_s: float, alpha: float, beta: float) -> np.ndarray:
    """:class:`ForceTracker` over one series, as a linear filter (a non-finite reading
    counts as the last finite one)."""
    from scipy.signal import lfilter, lfilter_zi

    x = np.asarray(z, dtype=float)
    ok = np.isfinite(x)
    if not ok.any():
        return x.copy()
    i0 = int(np.argmax(ok))
    xf = pd.Series(x[i0:]).ffill().to_numpy()
    # state s_k = [f_k, r_k] = A s_(k-1) + K z_k; f_k = H s_k
    A = np.array([[1.0 - alpha, (1.0 - alpha) * dt_s], [-beta, 1.0 - beta * dt_s]])
    # transfer function z -> f: H (I - A z^-1)^-1 K with K = [alpha, beta]; 2nd order
    tr, det = A[0, 0] + A[1, 1], A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    a_coef = np.array([1.0, -tr, det])
    b_coef = np.array([alpha, A[0, 1] * beta - A[1, 1] * alpha, 0.0])
    y, _ = lfilter(b_coef, a_coef, xf, zi=lfilter_zi(b_coef, a_coef) * xf[0])
    out = np.full_like(x, np.nan)
    out[i0:] = y
    return out


def track_recovered(output: pd.DataFrame, weight_n: float, noise_n: float,
                    sensors: Sequence[str] | None = None, dt_s: float | None = None,
                    acc_psd: float = TrackConfig.acc_psd) -> pd.DataFrame:
    """A copy of a monitor output whose ``recovered_<s>`` is tracked where ``flag_<s>``
    is on with ``kind_<s>`` in :data:`TRACKED_KINDS` (elsewhere unchanged).

    Args:
        output: A monitor output with ``time``, ``flag_<s>``, ``kind_<s>``,
            ``recovered_<s>``.
        weight_n: The robot's weight m g [N].
        noise_n: White noise of a load cell [N].
        sensors: Sensor names (default: every ``recovered_<s>`` column).
        dt_s: Sampling period [s] (default: the median step of ``time``).
        acc_psd: As in :class:`TrackConfig`.

    Raises:
        ConfigError: A setting is not a finite number > 0.
    """
    from grfguard.io.logio import without_attrs

    cfg = TrackConfig(noise_n=float(noise_n), weight_n=float(weight_n), acc_psd=acc_psd)
    attrs = output.attrs
    output = without_attrs(output)  # pandas deep-copies the metadata on every access
    if dt_s is None:
        t = output["time"].to_numpy(dtype=float)
        dt_s = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    alpha, beta = alpha_beta_gains(dt_s, cfg)
    names = list(sensors) if sensors is not None else [
        c[len("recovered_"):] for c in output.columns if c.startswith("recovered_")]
    out = output.copy(deep=False)  # (copy on write: the caller's frame stays as it is)
    for s in names:
        flag = output[f"flag_{s}"].to_numpy(dtype=bool)
        if not flag.any():
            continue
        sel = flag & output[f"kind_{s}"].astype(str).isin(TRACKED_KINDS).to_numpy()
        if not sel.any():
            continue
        rec = output[f"recovered_{s}"].to_numpy(dtype=float)
        tracked = _track_series(rec, dt_s, alpha, beta)
        sel &= np.isfinite(tracked)
        new = rec.copy()
        new[sel] = tracked[sel]
        out[f"recovered_{s}"] = new
    out.attrs = dict(attrs)
    return out
