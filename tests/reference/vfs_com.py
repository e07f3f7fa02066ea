"""Reference (tests and benchmarks only; formerly ``grfguard.estimate.com``): CoM and
momentum estimators of the virtual force sensor in numpy, compiled in
:mod:`grfguard.kernels.vfs` (multibody, leg odometry) and :mod:`grfguard.kernels.vfs_paper`
(the paper's LIPM filter, the pendulum Kalman ZMP, the anchor attitude).

Two estimators, both producing the same quantities per sample: CoM ``c`` in world [m],
CoM acceleration ``c_dd`` [m/s^2], centroidal angular momentum rate ``L_dot`` [N m],
total ground force ``F = m (c_dd + g e_z)`` [N] and the ZMP ``p`` on the ground [m].

* ``multibody`` (default, sensor-free): whole-body CoM and body poses from MuJoCo kinematics
  (encoders + IMU attitude), trunk position from leg odometry anchored on a stance foot that
  is flat on the ground (planned stance + kinematic corner heights, never the force
  sensors), ``c_dd`` and ``L_dot`` by finite differences through a causal Butterworth
  low-pass (``VirtualForceSensor`` also fuses the accelerometer for the IMU-point
  acceleration: accelerometer above ~1 Hz, odometry below, which removes its bias). A
  pendulum Kalman filter with the ZMP as a state (:class:`ZMPKalmanFilter`) is the
  alternative when there is no usable accelerometer. Newton-Euler about the CoM with
  the ground force acting at the ZMP ``p`` (ground height ``z_g``, ``h = c_z - z_g``)::

      L_dot = (p - c) x F   =>   p_x = c_x - (h F_x + L_dot_y) / F_z
                                 p_y = c_y - (h F_y - L_dot_x) / F_z

* ``paper`` (eq. 1-5): LIPM Kalman filter per horizontal axis, state ``(c, c_d, c_dd)``,
  process model the jerk form of the LIPM (eq. 2) ``c_ddd = g/z_c (c_d - p_d)`` with the
  measured-ZMP rate ``p_d`` as input (eq. 3), measurements the IMU acceleration rotated to
  world with gravity removed and - because eq. 2 alone leaves ``c`` unobservable - eq. 1
  itself as a pseudo-measurement ``p_act = c - z_c/g c_dd``. The ZMP disturbance observer
  low-passes ``p_err = p_ref - p_act`` (eq. 4) into a position correction ``Delta c``
  (eq. 5: ``c_hat = c + Delta c``). The measured ZMP comes from the monitored force sensors,
  so a faulty sensor corrupts this CoM (DESIGN.md item 1).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "CausalLowPass",
    "LegOdometry",
    "ZMP_EPS_N",
    "zmp_from_momentum",
    "PaperCoMFilter",
    "lipm_kalman_matrices",
    "ZMPKalmanFilter",
]

#: Smallest vertical force used as a divisor [N].
ZMP_EPS_N = 1.0


class CausalLowPass:
    """Causal Butterworth low-pass on several channels, streaming and batch alike.

    The state starts at steady state for the first input (no start-up transient).

    Args:
        cutoff_hz: Cut-off frequency [Hz].
        dt_s: Sampling period [s].
        order: Filter order.
        n_channels: Number of channels filtered together.
        damping: Damping ratio of a second-order low-pass instead of the Butterworth
            (``VFSConfig.filter_damping``); None: Butterworth of ``order``.
        lead: Phase lead [s] of that second-order low-pass (``VFSConfig.filter_lead``).
    """

    def __init__(self, cutoff_hz: float, dt_s: float, order: int, n_channels: int,
                 damping: float | None = None, lead: float | None = None) -> None:
        from grfguard._iir import butter_lowpass, damped_lowpass, lfilter_zi

        if damping is not None or lead:
            b, a = damped_lowpass(cutoff_hz, 1.0 / dt_s,
                                  2**-0.5 if damping is None else damping, lead or 0.0)
        else:
            b, a = butter_lowpass(order, cutoff_hz, 1.0 / dt_s)
        self.b, self.a = np.asarray(b, float), np.asarray(a, float)
        self.n_channels = n_channels
        self._zi = lfilter_zi(self.b, self.a)
        self._z: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the state."""
        self._z = None

    def update(self, x: np.ndarray) -> np.ndarray:
        """Filter one sample ``x`` (n_channels,) (direct form II transposed)."""
        x = np.asarray(x, float)
        if self._z is None:
            self._z = self._zi[:, None] * x[None, :]
        from scipy.signal import lfilter

        y, self._z = lfilter(self.b, self.a, x[None, :], axis=0, zi=self._z)
        return y[0]

    def run(self, x: np.ndarray) -> np.ndarray:
        """Filter a (T, n_channels) array from the current state (state is kept)."""
        x = np.asarray(x, float)
        if x.shape[0] == 0:
            return x.copy()
        if self._z is None:
            self._z = self._zi[:, None] * x[0][None, :]
        from scipy.signal import lfilter

        y, self._z = lfilter(self.b, self.a, x, axis=0, zi=self._z)
        return y


def zmp_from_momentum(
    com_W: np.ndarray,
    force_W: np.ndarray,
    L_dot_W: np.ndarray,
    ground_z: np.ndarray | float,
) -> np.ndarray:
    """ZMP on the ground plane from the CoM, total ground force and angular momentum rate.

    Args:
        com_W: (..., 3) CoM in world [m].
        force_W: (..., 3) total ground reaction force ``m (c_dd + g e_z)`` [N].
        L_dot_W: (..., 3) rate of the angular momentum about the CoM [N m].
        ground_z: Ground height [m] (scalar or (...,)).

    Returns:
        (..., 2) ZMP ``p_x, p_y`` in world [m].
    """
    h = com_W[..., 2] - ground_z
    fz = np.maximum(force_W[..., 2], ZMP_EPS_N)
    px = com_W[..., 0] - (h * force_W[..., 0] + L_dot_W[..., 1]) / fz
    py = com_W[..., 1] - (h * force_W[..., 1] - L_dot_W[..., 0]) / fz
    return np.stack([px, py], axis=-1)


def _so3_exp(w: np.ndarray) -> np.ndarray:
    th = float(np.sqrt(w @ w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if th < 1e-9:
        return np.eye(3) + K
    return np.eye(3) + np.sin(th) / th * K + (1 - np.cos(th)) / th**2 * (K @ K)


def _so3_log_small(R: np.ndarray) -> np.ndarray:
    return 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])


class LegOdometry:
    """Trunk pose in world by leg odometry, anchored on a flat stance foot.

    The anchor foot's sole frame is fixed in world while anchored (a foot flat on the ground
    neither slides nor turns). Its orientation ``R_WS_anchor`` replaces the IMU attitude at
    high frequency: the whole kinematic chain is rotated by ``R_corr = R_WS_anchor R_WS^T``
    (``R_WS`` is the sole orientation the kinematics computed with the IMU attitude), so the
    trunk attitude becomes ``R_WS_anchor R_ST(q)`` (encoders only, no attitude jitter). The
    anchor orientation is pulled toward the IMU-based one with ``attitude_time_constant``
    (drift correction; 0 disables the anchor attitude and uses the IMU as is).

    The anchor moves to the other foot when that foot is planned in stance and flat on the
    ground (all its corners within ``contact_height`` of the ground), or when the anchor
    foot leaves its planned stance while the other is in it. The switch is continuous: the
    new anchor's pose is computed with the current corrected trunk pose. The ground height
    is the lowest contact point of the anchor foot. At the first sample the mid-point of the
    planned stance feet is put at ``x = y = 0`` and the ground at ``z = 0``.

    Args:
        contact_height: Corner height above the ground that still counts as touching [m].
        dt_s: Sampling period [s].
        attitude_time_constant: Drift correction time constant toward the IMU [s].
    """

    def __init__(
        self, contact_height: float = 0.003, dt_s: float = 0.001,
        attitude_time_constant: float = 1.0,
    ) -> None:
        self.contact_height = contact_height
        self.use_anchor_attitude = attitude_time_constant > 0
        self.k_att = dt_s / (attitude_time_constant + dt_s) if self.use_anchor_attitude else 0.0
        self.reset()

    def reset(self) -> None:
        """Forget the anchor."""
        self.anchor: int = -1
        self.p_W_anchor = np.zeros(3)
        self.R_WS_anchor = np.eye(3)

    def update(
        self, p_AK: np.ndarray, p_AS: np.ndarray, R_WS: np.ndarray, stance: Sequence[bool]
    ) -> tuple[np.ndarray, np.ndarray, float, int]:
        """One sample.

        Args:
            p_AK: (8, 3) contact points in frame A (trunk origin, IMU attitude) [m].
            p_AS: (2, 3) sole centres in A [m].
            R_WS: (2, 3, 3) sole orientations from the IMU attitude.
            stance: planned stance of (right, left).

        Returns:
            ``(R_corr, p_WT, ground_z, anchor)``: rotation to apply to every A-frame vector
            and orientation, trunk position in world [m], ground height [m], anchor foot
            index (0 right, 1 left).
        """
        st = [bool(stance[0]), bool(stance[1])]
        if self.anchor < 0:
            if st[0] and not st[1]:
                self.anchor = 0
            elif st[1] and not st[0]:
                self.anchor = 1
            else:
                # both (or neither) planned: the lower foot, right on ties
                self.anchor = int(p_AK[4:, 2].min() < p_AK[:4, 2].min() - 1e-4)
            feet = [i for i in (0, 1) if st[i]] or [self.anchor]
            mid = p_AS[feet].mean(axis=0)
            z0 = p_AK[4 * self.anchor : 4 * self.anchor + 4, 2].min()
            # trunk at (-mid_x, -mid_y, -z0): mid-point at the origin, anchor on z = 0
            p_WT0 = np.array([-mid[0], -mid[1], -z0])
            self.p_W_anchor = p_WT0 + p_AS[self.anchor]
            self.R_WS_anchor = R_WS[self.anchor].copy()
        a = self.anchor
        if self.use_anchor_attitude:
            err = _so3_log_small(self.R_WS_anchor.T @ R_WS[a])
            self.R_WS_anchor = self.R_WS_anchor @ _so3_exp(self.k_att * err)
            R_corr = self.R_WS_anchor @ R_WS[a].T
        else:
            R_corr = np.eye(3)
        p_WT = self.p_W_anchor - R_corr @ p_AS[a]
        zK = p_WT[2] + p_AK @ R_corr[2]
        ground = float(zK[4 * a : 4 * a + 4].min())
        o = 1 - a
        flat_other = zK[4 * o : 4 * o + 4].max() - ground < self.contact_height
        if st[o] and (flat_other or not st[a]):
            self.anchor = o
            self.p_W_anchor = p_WT + R_corr @ p_AS[o]
            self.R_WS_anchor = R_corr @ R_WS[o]
        return R_corr, p_WT, ground, a


def lipm_kalman_matrices(
    dt_s: float, z_c_m: float, gravity: float, jerk_psd: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Discrete LIPM jerk-form model of paper eq. 2 for state ``(c, c_d, c_dd)``.

    ``x_k = A x_{k-1} + B p_d_{k-1} + w`` with ``c_ddd = (g/z_c)(c_d - p_d)``.

    Args:
        dt_s: Sampling period [s].
        z_c_m: CoM height [m].
        gravity: Gravity [m/s^2].
        jerk_psd: White-jerk process noise spectral density [m^2/s^5].

    Returns:
        ``(A, B, Q)``: (3, 3), (3,), (3, 3).
    """
    t = dt_s
    w2 = gravity / z_c_m
    A = np.array([[1.0, t, 0.5 * t * t], [0.0, 1.0, t], [0.0, t * w2, 1.0]])
    B = np.array([0.0, 0.0, -t * w2])
    Q = jerk_psd * np.array(
        [[t**5 / 20, t**4 / 8, t**3 / 6], [t**4 / 8, t**3 / 3, t**2 / 2], [t**3 / 6, t**2 / 2, t]]
    )
    return A, B, Q


class PaperCoMFilter:
    """The paper's CoM estimator (eq. 1-5), both horizontal axes, one sample at a time.

    Args:
        dt_s: Sampling period [s].
        z_c_m: LIPM CoM height [m].
        gravity: Gravity [m/s^2].
        jerk_psd: Process noise spectral density [m^2/s^5].
        acc_var: Accelerometer noise variance [(m/s^2)^2].
        zmp_var: Variance of the measured ZMP used in the eq. 1 pseudo-measurement [m^2].
        dob_time_constant_s: Time constant of the ZMP disturbance observer low-pass [s].
        dob_gain: Gain from the filtered ZMP error to ``Delta c`` (eq. 5).
    """

    def __init__(
        self,
        dt_s: float,
        z_c_m: float,
        gravity: float,
        jerk_psd: float,
        acc_var: float,
        zmp_var: float = 0.005**2,
        dob_time_constant_s: float = 0.5,
        dob_gain: float = 1.0,
    ) -> None:
        self.dt = dt_s
        self.z_c = z_c_m
        self.g = gravity
        self.A, self.B, self.Q = lipm_kalman_matrices(dt_s, z_c_m, gravity, jerk_psd)
        self.H = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, -z_c_m / gravity]])
        self.R = np.diag([acc_var, zmp_var])
        self.k_dob = dt_s / (dob_time_constant_s + dt_s)
        self.dob_gain = dob_gain
        self.reset()

    def reset(self) -> None:
        """Forget the state."""
        self.x: np.ndarray | None = None  # (3, 2): state per axis in columns
        self.P = np.diag([1e-4, 1e-2, 1.0])
        self.p_prev = np.zeros(2)
        self.dc = np.zeros(2)

    def update(
        self, p_act_W: np.ndarray, acc_W: np.ndarray, p_ref_W: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """One sample.

        Args:
            p_act_W: (2,) measured ZMP from the force sensors [m].
            acc_W: (2,) horizontal IMU acceleration in world, gravity removed [m/s^2].
            p_ref_W: (2,) reference ZMP [m] or None (no disturbance observer).

        Returns:
            ``(c_hat, c_dd)``: corrected CoM (2,) [m] and CoM acceleration (2,) [m/s^2].
        """
        p_act = np.asarray(p_act_W, float)
        if self.x is None:
            self.x = np.zeros((3, 2))
            self.x[0] = p_act
            self.p_prev = p_act.copy()
        p_dot = (p_act - self.p_prev) / self.dt
        self.p_prev = p_act.copy()
        # predict (same covariance for both axes)
        x = self.A @ self.x + np.outer(self.B, p_dot)
        P = self.A @ self.P @ self.A.T + self.Q
        # correct with [acc; p_act]
        S = self.H @ P @ self.H.T + self.R
        K = P @ self.H.T @ np.linalg.inv(S)
        y = np.stack([np.asarray(acc_W, float), p_act]) - self.H @ x
        self.x = x + K @ y
        self.P = (np.eye(3) - K @ self.H) @ P
        if p_ref_W is not None and np.all(np.isfinite(p_ref_W)):
            p_err = np.asarray(p_ref_W, float) - p_act
            self.dc = self.dc + self.k_dob * (p_err - self.dc)
        c_hat = self.x[0] + self.dob_gain * self.dc
        return c_hat, self.x[2].copy()


class ZMPKalmanFilter:
    """Kalman filter on the pendulum dynamics with the ZMP as a state (both horizontal axes).

    Per axis the state is ``(c, c_d, p)``: CoM, CoM velocity and ZMP [m, m/s, m]. The
    multibody Newton-Euler relation ``p = c - (h F_xy -/+ L_dot) / F_z`` with
    ``F_xy = m c_dd`` gives the (time-varying) pendulum model::

        c_dd = w2 (c - p) + u,     w2 = F_z / (m h),   u = (-L_dot_y, +L_dot_x) / (m h)
        p_d  = white noise (zmp_rate_psd)

    and the measurement is the kinematic CoM ``c`` (noise ``com_sigma``). Compared with
    differentiating ``c`` twice through a low-pass, the pendulum structure rejects
    attitude/encoder jitter (which cannot be explained by a ZMP inside the feet) without
    the low-pass lag. Euler discretization at ``dt``; both axes share the covariance.

    Args:
        dt_s: Sampling period [s].
        zmp_rate_psd: Spectral density of the ZMP velocity random walk [m^2/s].
        acc_psd: Spectral density of the CoM acceleration model error [m^2/s^3].
        com_sigma: Kinematic CoM measurement noise [m].
    """

    def __init__(
        self, dt_s: float, zmp_rate_psd: float, acc_psd: float, com_sigma: float
    ) -> None:
        self.dt = dt_s
        self.Q = np.diag([1e-12, acc_psd * dt_s, zmp_rate_psd * dt_s])
        self.R = com_sigma**2
        self.reset()

    def reset(self) -> None:
        """Forget the state."""
        self.x: np.ndarray | None = None  # (3, 2)
        self.P = np.diag([1e-6, 1e-2, 1e-4])

    def update(
        self, com_xy: np.ndarray, w2: float, u_xy: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """One sample.

        Args:
            com_xy: (2,) kinematic CoM [m].
            w2: ``F_z / (m h)`` [1/s^2].
            u_xy: (2,) angular-momentum input [m/s^2].

        Returns:
            ``(zmp, com)``: filtered ZMP (2,) and CoM (2,) [m].
        """
        c = np.asarray(com_xy, float)
        if self.x is None:
            self.x = np.stack([c, np.zeros(2), c])
        t = self.dt
        A = np.array([[1.0, t, 0.0], [w2 * t, 1.0, -w2 * t], [0.0, 0.0, 1.0]])
        x = A @ self.x
        x[1] += t * np.asarray(u_xy, float)
        P = A @ self.P @ A.T + self.Q
        # scalar measurement of c (H = [1, 0, 0])
        s = P[0, 0] + self.R
        K = P[:, 0] / s
        innov = c - x[0]
        self.x = x + np.outer(K, innov)
        self.P = P - np.outer(K, P[0, :])
        return self.x[2].copy(), self.x[0].copy()
