"""The paper's fault observer (Hashlamon & Erbatur, eq. 24-33), as published.

Per sensor ``j`` the state is ``x = [η_j, N_j]`` (fault [N], true force [N]):

.. math::

    η_k = η_{k-1} + v_η,\\qquad N_k = N_{meas,k} - η_{k-1} - v_η,\\qquad y_k = N_k + v

i.e. ``A = [[1, 0], [-1, 0]]``, ``B u = [0, N_meas]``, ``C = [0, 1]``, ``Q = q I``,
``R = r``; the measurement ``y`` is the virtual force sensor output ``N̂``. The eight
sensors are independent 2-state filters with the same model, so they share one
covariance and one gain. In steady state the fault estimate is a first-order
low-pass of the residual ``e = N_meas - N̂``:

.. math::

    η_k = (1 - k) η_{k-1} + k e_k,\\qquad k = -K_η > 0

η̂ is low-pass filtered (first order, cut-off ``lowpass_hz``) and thresholded
(eq. 33): ``fault_j = |η_f,j| > tr_j``.

Batch functions work on arrays of shape (T, n) and use :func:`scipy.signal.lfilter`
where the filter is linear time-invariant; :class:`FaultObserver` is the streaming
form and gives the same numbers.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from grfguard.errors import ConfigError

__all__ = [
    "ObserverConfig",
    "ObserverGain",
    "ObserverResult",
    "observer_matrices",
    "steady_state_gain",
    "kalman_gain_sequence",
    "run_observer",
    "lowpass",
    "paper_threshold",
    "FaultObserver",
]


@dataclass(frozen=True)
class ObserverConfig:
    """Parameters of the paper's fault observer.

    Attributes:
        q: Process noise variance of both states, ``Q = q I`` [N²] (paper: 1e-10).
        r: Measurement noise variance ``R`` [N²] (paper: 1e-4).
        dt_s: Sampling period in [s]; used by the low-pass filter. The 1 ms default is
            the paper's rate; inside a monitor it follows ``MonitorConfig.dt_s``, which
            ``Monitor.for_log`` sets to the log's rate (0.01 for a 100 Hz log). ``q`` and
            ``r`` are per-sample variances (the paper's values at 1 ms).
        lowpass_hz: Cut-off of the first-order low-pass on η̂ in [Hz].
        p0: Initial covariance of both states, ``P_0 = p0 I`` [N²] (full filter only).
        eta0_n: Initial fault estimate in [N].
    """

    q: float = 1e-10
    r: float = 1e-4
    dt_s: float = 1e-3
    lowpass_hz: float = 1.0
    p0: float = 1.0
    eta0_n: float = 0.0

    def __post_init__(self) -> None:
        for name, lo, hi in (
            ("q", 0.0, math.inf),
            ("r", 0.0, math.inf),
            ("dt_s", 0.0, 1.0),
            ("lowpass_hz", 0.0, math.inf),
            ("p0", 0.0, math.inf),
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo < v < hi):
                raise ConfigError(
                    f"observer.{name} = {v!r} must be a number in ({lo}, {hi}); "
                    "see ObserverConfig docs (paper: q=1e-10, r=1e-4, dt_s=1e-3)"
                )
        if not math.isfinite(self.eta0_n):
            raise ConfigError(f"observer.eta0_n = {self.eta0_n!r} must be finite [N]")

    def to_dict(self) -> dict[str, float]:
        """Plain dict for TOML/JSON."""
        return asdict(self)


@dataclass(frozen=True)
class ObserverGain:
    """Steady-state Kalman gain of one 2-state observer.

    Attributes:
        k_eta: Gain from innovation to η (negative) [-].
        k_n: Gain from innovation to N [-].
        p_prior: Steady-state prior covariance (2, 2) [N²].
    """

    k_eta: float
    k_n: float
    p_prior: np.ndarray

    @property
    def k(self) -> float:
        """Low-pass coefficient ``k = -K_η`` of ``η_k = (1-k) η_{k-1} + k e_k``."""
        return -self.k_eta


@dataclass(frozen=True)
class ObserverResult:
    """Output of :func:`run_observer`, arrays of shape (T, n).

    Attributes:
        eta_n: Fault estimate η̂ [N].
        force_n: Estimated true force N̂ (filter state) [N].
        eta_filtered_n: Low-pass filtered η̂ [N].
        gain_eta: Gain K_η per sample (T,) (constant for the steady-state filter).
    """

    eta_n: np.ndarray
    force_n: np.ndarray
    eta_filtered_n: np.ndarray
    gain_eta: np.ndarray


def observer_matrices(config: ObserverConfig) -> tuple[np.ndarray, ...]:
    """``(A, C, Q, R)`` of one sensor's 2-state model (eq. 27-32)."""
    a = np.array([[1.0, 0.0], [-1.0, 0.0]])
    c = np.array([[0.0, 1.0]])
    q = config.q * np.eye(2)
    r = np.array([[config.r]])
    return a, c, q, r


def steady_state_gain(config: ObserverConfig | None = None) -> ObserverGain:
    """Steady-state gain from the discrete algebraic Riccati equation.

    Only ``q / r`` matters for it (``k ≈ sqrt(q / r)``, ~1e-3 for the paper).
    """
    config = config or ObserverConfig()
    a, c, q, r = observer_matrices(config)
    import scipy.linalg  # lazy: scipy costs ~1 s of `grfguard run` start-up

    p = scipy.linalg.solve_discrete_are(a.T, c.T, q, r)
    s = float((c @ p @ c.T)[0, 0] + config.r)
    k = (p @ c.T)[:, 0] / s
    return ObserverGain(k_eta=float(k[0]), k_n=float(k[1]), p_prior=p)


def kalman_gain_sequence(n_samples: int, config: ObserverConfig | None = None) -> np.ndarray:
    """Time-varying gains ``K_k`` (n_samples, 2) of the full Kalman filter from ``P_0``.

    The gain does not depend on the data, so it is computed once for all sensors.
    """
    config = config or ObserverConfig()
    a, _, q, _ = observer_matrices(config)
    p = config.p0 * np.eye(2)
    out = np.empty((n_samples, 2))
    # plain floats: this loop is the only sequential part of the full filter
    p00, p01, p11 = p[0, 0], p[0, 1], p[1, 1]
    qq, rr = config.q, config.r
    for i in range(n_samples):
        # predict: P = A P A^T + Q with A = [[1,0],[-1,0]]
        m00 = p00 + qq
        m01 = -p00
        m11 = p00 + qq
        s = m11 + rr
        k0 = m01 / s
        k1 = m11 / s
        out[i, 0] = k0
        out[i, 1] = k1
        # update: P = (I - K C) P_prior, C = [0, 1]
        p00 = m00 - k0 * m01
        p01 = m01 - k0 * m11
        p11 = m11 - k1 * m11
    del p01, p11
    return out


def lowpass(x: np.ndarray, config: ObserverConfig, y0: np.ndarray | float = 0.0) -> np.ndarray:
    """First-order low-pass ``y_k = a y_{k-1} + (1-a) x_k``, ``a = exp(-2π f_c T)``.

    Args:
        x: Input (T, n) or (T,).
        config: Gives ``lowpass_hz`` and ``dt_s``.
        y0: Output before the first sample.
    """
    from scipy.signal import lfilter  # lazy: see steady_state_gain

    a = math.exp(-2.0 * math.pi * config.lowpass_hz * config.dt_s)
    x = np.asarray(x, dtype=float)
    zi = a * np.broadcast_to(np.asarray(y0, dtype=float), x.shape[1:])[None, ...]
    y, _ = lfilter([1.0 - a], [1.0, -a], x, axis=0, zi=zi)
    return y


def run_observer(
    force_meas_n: np.ndarray,
    force_vfs_n: np.ndarray,
    config: ObserverConfig | None = None,
    full: bool = False,
    eta0_n: np.ndarray | None = None,
) -> ObserverResult:
    """Run the paper's observer over a whole log (batch).

    A NaN measurement or VFS sample skips the correction: the filter only predicts
    (``η_k = η_{k-1}``, ``N̂_k = N_meas - η_{k-1}`` or the VFS value when the measurement
    is missing).

    Args:
        force_meas_n: Measured forces ``N_meas`` [N], shape (T, n).
        force_vfs_n: Virtual sensor forces ``N̂`` [N], shape (T, n).
        config: Observer parameters (paper defaults).
        full: Use the full time-varying Kalman filter from ``P_0`` instead of the
            steady-state gain.
        eta0_n: Initial fault estimate per sensor, shape (n,) [N] (default
            ``config.eta0_n`` for every sensor); also the low-pass's initial output.

    Returns:
        :class:`ObserverResult` with arrays of shape (T, n).
    """
    config = config or ObserverConfig()
    meas = np.atleast_2d(np.asarray(force_meas_n, dtype=float))
    vfs = np.atleast_2d(np.asarray(force_vfs_n, dtype=float))
    if meas.shape != vfs.shape:
        raise ConfigError(
            f"run_observer: measured forces {meas.shape} and VFS {vfs.shape} differ in shape"
        )
    t_len, n = meas.shape
    e = meas - vfs
    valid = np.isfinite(e)
    if full:
        gains = kalman_gain_sequence(t_len, config)
    else:
        g = steady_state_gain(config)
        gains = np.broadcast_to(np.array([g.k_eta, g.k_n]), (t_len, 2))
    eta = np.empty((t_len, n))
    eta0 = np.full(n, config.eta0_n) if eta0_n is None else np.asarray(eta0_n, float)
    if eta0.shape != (n,):
        raise ConfigError(f"run_observer: eta0_n has shape {eta0.shape}, expected ({n},)")
    prev = eta0.copy()
    if not full and valid.all():
        from scipy.signal import lfilter  # lazy: see steady_state_gain

        k = -gains[0, 0]
        eta, _ = lfilter([k], [1.0, -(1.0 - k)], e, axis=0, zi=((1.0 - k) * prev)[None, :])
    else:
        for i in range(t_len):
            k = -gains[i, 0]
            cur = (1.0 - k) * prev + k * e[i]
            cur = np.where(valid[i], cur, prev)
            eta[i] = cur
            prev = cur
    eta_prev = np.vstack([eta0[None, :], eta[:-1]])
    innov = eta_prev - e
    force = meas - eta_prev + gains[:, 1:2] * innov
    force = np.where(valid, force, np.where(np.isfinite(meas), meas - eta_prev, vfs))
    eta_f = lowpass(eta, config, y0=eta0)
    return ObserverResult(
        eta_n=eta, force_n=force, eta_filtered_n=eta_f, gain_eta=np.array(gains[:, 0])
    )


def paper_threshold(eta_filtered_n: np.ndarray, thresholds_n: np.ndarray | float) -> np.ndarray:
    """Eq. 33: ``fault = |η_f| > tr`` (per sensor threshold in [N], broadcast over rows)."""
    return np.abs(np.asarray(eta_filtered_n, dtype=float)) > np.asarray(thresholds_n, dtype=float)


class FaultObserver:
    """Streaming form of :func:`run_observer` (same numbers, one sample per call).

    Args:
        n_sensors: Number of sensors ``n``.
        config: Observer parameters.
        full: Full Kalman filter (time-varying gain) instead of the steady-state gain.
    """

    def __init__(
        self, n_sensors: int = 8, config: ObserverConfig | None = None, full: bool = False
    ) -> None:
        self.config = config or ObserverConfig()
        self.n_sensors = int(n_sensors)
        self.full = bool(full)
        self._k_ss_value: tuple[float, float] | None = None
        self._k_eta: float | None = None
        self._a_lp = math.exp(-2.0 * math.pi * self.config.lowpass_hz * self.config.dt_s)
        self.reset()

    @property
    def _k_ss(self) -> tuple[float, float]:
        """Steady-state gains ``(k_eta, k_n)``, solved on first use: the Riccati solver
        imports ``scipy.linalg`` (about 0.15 s of start-up), which a monitor that never
        runs the paper's method (every monitor builds this observer) does not need."""
        if self._k_ss_value is None:
            g = steady_state_gain(self.config)
            self._k_ss_value = (g.k_eta, g.k_n)
        return self._k_ss_value

    @property
    def k_eta(self) -> float:
        """The gain K_η of the last update (the steady-state one after a reset)."""
        return self._k_ss[0] if self._k_eta is None else self._k_eta

    @k_eta.setter
    def k_eta(self, value: float) -> None:
        self._k_eta = value

    def reset(self) -> None:
        """Back to the initial state (η = eta0, P = P_0)."""
        self.eta_n = np.full(self.n_sensors, self.config.eta0_n)
        self.eta_filtered_n = np.full(self.n_sensors, self.config.eta0_n)
        self._p = (self.config.p0, 0.0, self.config.p0)
        self._k_eta = None  # the steady-state gain, solved when first needed

    def _gain(self) -> tuple[float, float]:
        if not self.full:
            return self._k_ss
        p00 = self._p[0]
        q, r = self.config.q, self.config.r
        m00, m01, m11 = p00 + q, -p00, p00 + q
        s = m11 + r
        k0, k1 = m01 / s, m11 / s
        self._p = (m00 - k0 * m01, m01 - k0 * m11, m11 - k1 * m11)
        return k0, k1

    def update(
        self, force_meas_n: np.ndarray, force_vfs_n: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One sample: returns ``(eta_n, force_n, eta_filtered_n)``, each shape (n,)."""
        meas = np.asarray(force_meas_n, dtype=float)
        vfs = np.asarray(force_vfs_n, dtype=float)
        k_eta, k_n = self._gain()
        self.k_eta = k_eta
        e = meas - vfs
        valid = np.isfinite(e)
        prev = self.eta_n
        k = -k_eta
        cur = np.where(valid, (1.0 - k) * prev + k * e, prev)
        force = np.where(
            valid,
            meas - prev + k_n * (prev - e),
            np.where(np.isfinite(meas), meas - prev, vfs),
        )
        self.eta_n = cur
        a = self._a_lp
        self.eta_filtered_n = a * self.eta_filtered_n + (1.0 - a) * cur
        return cur.copy(), force, self.eta_filtered_n.copy()
