"""Configuration of the virtual force sensor (VFS): a frozen, validated dataclass.

Every field carries its unit. Construct with keyword arguments, :meth:`VFSConfig.from_dict`
or :meth:`VFSConfig.from_toml`; invalid values raise :class:`~grfguard.errors.ConfigError`
with the name, the value and the allowed range.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from grfguard._validate import check_number
from grfguard.errors import ConfigError

__all__ = ["VFSConfig", "COM_METHODS", "SPLIT_METHODS"]

#: CoM / momentum estimators: ``multibody`` (sensor-free, default) or ``paper`` (LIPM KF + DOB).
COM_METHODS: tuple[str, ...] = ("multibody", "paper")
#: Force split: ``qp`` (one QP over all contact corners, default) or ``paper`` (eq. 6-12).
SPLIT_METHODS: tuple[str, ...] = ("qp", "paper")


def _num(name: str, value: Any, lo: float, hi: float, unit: str) -> None:
    check_number("vfs", name, value, lo, hi, unit, "fix it in the [vfs] table of the config")


#: Valid ranges of the rate low-pass's second-order options (damping ratio; lead [s]).
_SECOND_ORDER_RANGE = {"filter_damping": (0.2, 2.0), "filter_lead": (0.0, 0.05)}


@dataclass(frozen=True)
class VFSConfig:
    """Settings of :class:`grfguard.estimate.vfs.VirtualForceSensor`.

    The defaults are the sensor-free multibody estimator (encoders, IMU attitude, gyro and
    accelerometer; never the force sensors) with one QP over all corners in contact and a
    sole-compliance prior (chosen by measured accuracy, see BENCHMARKS.md "Virtual force
    sensor").
    ``VFSConfig.paper()`` gives the paper's method (LIPM Kalman filter, alpha split,
    eq. 10-12 read literally, ``W = 0.01``).
    """

    #: CoM estimator: ``multibody`` (encoders + IMU attitude + model; never reads the force
    #: sensors) or ``paper`` (LIPM Kalman filter fed by the measured ZMP, eq. 1-5).
    com_method: str = "multibody"
    #: Leg split and CoP: ``qp`` (single support: all on the stance foot; double support:
    #: one QP over all corners) or ``paper`` (alpha rule eq. 6-9 and eq. 10-12 literally).
    split_method: str = "qp"
    #: Diagonal weight ``w`` of the contact-point QP ``|C N - d|^2 + w |N - N_prior|^2`` in
    #: [m^2] (``N_prior = 0`` without the compliance prior). The paper uses 0.01, which
    #: biases the CoP toward the sole centre.
    qp_weight: float = 1e-6
    #: Cut-off of the causal Butterworth low-pass on the CoM and angular momentum before
    #: differentiation in [Hz] (higher lets attitude jitter through).
    filter_cutoff: float = 15.0
    #: Fuse the accelerometer: IMU-point acceleration from the accelerometer above
    #: ``fusion_cutoff`` and from leg odometry below it (removes the accelerometer bias and
    #: the lag of differentiating odometry); the CoM motion relative to the IMU comes from
    #: kinematics through the ``filter_cutoff`` low-pass.
    use_accelerometer: bool = True
    #: Use the accelerometer for the vertical acceleration too (else odometry only: the
    #: vertical CoM motion is small and slow, and the accelerometer noise would dominate).
    accelerometer_vertical: bool = False
    #: Cross-over of the accelerometer / odometry complementary filter in [Hz].
    fusion_cutoff: float = 1.0
    #: Low-pass on the accelerometer (white noise) in [Hz].
    acc_cutoff: float = 40.0
    #: Order of the Butterworth filters.
    filter_order: int = 2
    #: Damping ratio zeta of the rate low-pass (``filter_cutoff``) as a second-order
    #: ``w^2 / (s^2 + 2 zeta w s + w^2)`` (bilinear, prewarped at the cut-off); None (the
    #: default) keeps the Butterworth of ``filter_order``. Below the Butterworth's 0.707 it
    #: lags less and overshoots: low-frequency delay ``2 zeta / w`` (10 Hz: 22.5 ms
    #: Butterworth; 0.4 at 8 Hz: 15.9 ms) against a resonance peak ``1 / (2 zeta
    #: sqrt(1 - zeta^2))`` (0.4: +36 %), see :func:`grfguard._iir.damped_lowpass`. Needs
    #: ``filter_order`` 2. ``grfguard calibrate --model`` chooses it (with the cut-off)
    #: for the accelerometer-free sensor on its calibration data.
    filter_damping: float | None = None
    #: Phase lead tau [s] of the rate low-pass as a second-order low-pass with a zero,
    #: ``w^2 (1 + tau s) / (s^2 + 2 zeta w s + w^2)`` (``y = LP(x) + tau d/dt LP(x)``;
    #: zeta: ``filter_damping`` or the Butterworth's 0.707): the low-frequency delay drops
    #: by tau (10 Hz Butterworth: 22.5 ms, with 5 ms: 17.5 ms) while the gain above the
    #: cut-off falls as 1/f instead of 1/f^2, see :func:`grfguard._iir.damped_lowpass`.
    #: None (the default) or 0: no lead. Needs ``filter_order`` 2.
    filter_lead: float | None = None
    #: Sampling period in [s]. ``VirtualForceSensor.for_log`` replaces it by the log's
    #: rate (median step of ``time``; 0.01 for a 100 Hz log); the 1 ms default holds only
    #: for a sensor built without a log, so set it then to the period of the samples fed.
    dt: float = 0.001
    #: Time constant of the complementary attitude filter (gyro integration pulled toward
    #: the logged IMU quaternion) in [s]; 0 uses the logged quaternion as is.
    attitude_time_constant: float = 0.5
    #: Time constant with which the anchored stance foot's orientation (which replaces the
    #: IMU attitude at high frequency) is pulled toward the IMU attitude in [s]; 0 uses
    #: the IMU attitude directly (measured better: feet rock on soft contacts).
    anchor_attitude_time_constant: float = 0.0
    #: ZMP from the multibody rates: ``direct`` (Newton-Euler with the filtered rates) or
    #: ``kalman`` (pendulum Kalman filter with the ZMP as a state on the kinematic CoM,
    #: :func:`grfguard.kernels.vfs_paper.zmp_kalman`; best without accelerometer).
    zmp_filter: str = "direct"
    #: Spectral density of the ZMP velocity random walk of that filter in [m^2/s].
    zmp_rate_psd: float = 20.0
    #: Spectral density of its CoM acceleration model error in [m^2/s^3].
    com_acc_psd: float = 0.1
    #: Noise of the kinematic CoM measurement in [m].
    com_sigma: float = 2e-3
    #: Include the centroidal angular momentum rate in the ZMP (multibody only).
    use_angular_momentum: bool = True
    #: Corner contact stiffness per kg of robot mass in [N/(m kg)] for the sole-compliance
    #: prior of the corner QP (:mod:`grfguard.kernels.nnls`: lower corners carry
    #: more load; recovers the internal forces between the feet that a rigid QP cannot
    #: see). MuJoCo's default soft contact measured 4.2e3 on the simulated robots (the
    #: 114 kg reference robot: 4.8e5 N/m; a 60 kg one: 2.5e5 N/m); calibrate it for a
    #: real sole. 0 disables the prior.
    contact_stiffness_per_kg: float = 4200.0
    #: Twist of a loaded flat sole from the contact's nonlinear stiffness: with all four
    #: corners in contact, ``f1 - f2 - f3 + f4 = contact_twist * P R / S`` (``S`` the
    #: sole's load, ``P`` front minus rear, ``R`` left minus right corners; corners
    #: front-left, front-right, rear-left, rear-right), which the planar compliance prior
    #: leaves at 0. MuJoCo's soft contact measured 0.42 on the simulated robots (it
    #: matters when the centre of pressure sits off the sole's centre in both axes, e.g.
    #: a trunk CoM a few cm off: up to 50 N); fitted from fault-free data by
    #: ``grfguard calibrate --model`` (``ModelCorrections.contact_twist``). 0 disables it.
    contact_twist: float = 0.0
    #: Corner height above the ground plane below which a corner counts as touching, in [m]
    #: (kinematic contact; heel-first landing and toe-off).
    contact_height: float = 0.003
    #: Decide contact per corner from the kinematic corner heights (the plan only as a
    #: fallback); False uses the planned stance only (the paper).
    kinematic_contact: bool = True
    #: Leg odometry in double support: keep the anchor foot while it is flat (move the
    #: anchor to the other stance foot only once that one is flat and the anchor is not,
    #: or when the anchor foot lifts). False (the former rule) moves it whenever the other
    #: stance foot is flat: in a flat double support the anchor then alternates every
    #: sample, and without the accelerometer the forces depend on the parity of that
    #: alternation (after a break of an odd number of samples, up to ~100 N apart until
    #: the next single support: BENCHMARKS.md "Twin sensor after a break").
    anchor_hold: bool = False
    # ------------------------------------------------------------------ paper CoM filter
    #: LIPM CoM height ``z_c`` in [m] for the paper's filter; 0 means "from the model
    #: at the first sample".
    lipm_height: float = 0.0
    #: Process noise (jerk) spectral density of the paper's Kalman filter in [m^2/s^5].
    paper_process_noise: float = 1e2
    #: Accelerometer noise variance of the paper's Kalman filter in [(m/s^2)^2].
    paper_measurement_noise: float = 0.05**2
    #: Time constant of the ZMP disturbance observer in [s] (paper eq. 4-5).
    paper_dob_time_constant: float = 0.5
    #: Gain from the low-passed ZMP error ``p_ref - p_act`` to the CoM correction
    #: ``Delta c`` (paper eq. 4-5); 0 switches the disturbance observer off.
    paper_dob_gain: float = 1.0
    #: ``c_y,max`` of eq. 7 in [m]: lateral CoM excursion that puts all load on one foot;
    #: 0 means "half the distance between the feet from the model".
    paper_cy_max: float = 0.0

    def __post_init__(self) -> None:
        if self.com_method not in COM_METHODS:
            raise ConfigError(
                f"vfs.com_method = {self.com_method!r} is unknown; use one of {list(COM_METHODS)}"
            )
        if self.split_method not in SPLIT_METHODS:
            raise ConfigError(
                f"vfs.split_method = {self.split_method!r} is unknown; "
                f"use one of {list(SPLIT_METHODS)}"
            )
        _num("qp_weight", self.qp_weight, 1e-12, 1.0, "m^2")
        _num("dt", self.dt, 1e-5, 0.1, "s")
        _num("filter_cutoff", self.filter_cutoff, 0.1, 0.45 / self.dt, "Hz")
        if not isinstance(self.filter_order, int) or not 1 <= self.filter_order <= 8:
            raise ConfigError(
                f"vfs.filter_order = {self.filter_order!r} must be an integer in [1, 8]"
            )
        for name, unit, other in (("filter_damping", "", " (Butterworth)"),
                                  ("filter_lead", "s", "")):
            value = getattr(self, name)
            if value is None:
                continue
            _num(name, value, *(_SECOND_ORDER_RANGE[name]), unit)
            if self.filter_order != 2:
                raise ConfigError(
                    f"vfs.{name} = {value!r} shapes a second-order low-pass but "
                    f"vfs.filter_order = {self.filter_order}; set filter_order = 2 or "
                    f"leave {name} out{other}"
                )
        _num("fusion_cutoff", self.fusion_cutoff, 0.01, 0.45 / self.dt, "Hz")
        _num("acc_cutoff", self.acc_cutoff, 0.1, 0.45 / self.dt, "Hz")
        for flag in (
            "use_angular_momentum",
            "kinematic_contact",
            "use_accelerometer",
            "accelerometer_vertical",
            "anchor_hold",
        ):
            if not isinstance(getattr(self, flag), bool):
                raise ConfigError(f"vfs.{flag} must be true or false, got {getattr(self, flag)!r}")
        _num("attitude_time_constant", self.attitude_time_constant, 0.0, 1e3, "s")
        _num("anchor_attitude_time_constant", self.anchor_attitude_time_constant, 0.0, 1e3, "s")
        if self.zmp_filter not in ("kalman", "direct"):
            raise ConfigError(
                f"vfs.zmp_filter = {self.zmp_filter!r} is unknown; use 'kalman' or 'direct'"
            )
        _num("zmp_rate_psd", self.zmp_rate_psd, 1e-12, 1e6, "m^2/s")
        _num("com_acc_psd", self.com_acc_psd, 1e-12, 1e6, "m^2/s^3")
        _num("com_sigma", self.com_sigma, 1e-9, 1.0, "m")
        _num("contact_stiffness_per_kg", self.contact_stiffness_per_kg, 0.0, 1e8, "N/(m kg)")
        _num("contact_twist", self.contact_twist, -5.0, 5.0, "")
        _num("contact_height", self.contact_height, 0.0, 0.1, "m")
        _num("lipm_height", self.lipm_height, 0.0, 5.0, "m")
        _num("paper_process_noise", self.paper_process_noise, 1e-12, 1e12, "m^2/s^5")
        _num("paper_measurement_noise", self.paper_measurement_noise, 1e-12, 1e6, "(m/s^2)^2")
        _num("paper_dob_time_constant", self.paper_dob_time_constant, 1e-3, 1e3, "s")
        _num("paper_dob_gain", self.paper_dob_gain, -10.0, 10.0, "")
        _num("paper_cy_max", self.paper_cy_max, 0.0, 2.0, "m")

    # ------------------------------------------------------------------ presets
    @classmethod
    def paper(cls, **overrides: Any) -> VFSConfig:
        """The paper's method: LIPM CoM filter, alpha split, eq. 10-12, ``W = 0.01``."""
        kw: dict[str, Any] = {
            "com_method": "paper",
            "split_method": "paper",
            "qp_weight": 0.01,
            "kinematic_contact": False,
            "contact_stiffness_per_kg": 0.0,
        }
        kw.update(overrides)
        return cls(**kw)

    def replace(self, **changes: Any) -> VFSConfig:
        """A copy with ``changes`` applied (validated again)."""
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------------ round trip
    def to_dict(self) -> dict[str, Any]:
        """Plain dict of the settings."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> VFSConfig:
        """Build from a dict (a ``vfs`` sub-table is accepted); unknown keys are rejected."""
        if "vfs" in data and isinstance(data["vfs"], dict):
            data = data["vfs"]
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(f"unknown vfs key(s) {unknown}; known keys: {sorted(known)}")
        return cls(**data)

    def to_toml(self) -> str:
        """TOML text with a ``[vfs]`` table."""
        lines = ["# grfguard virtual force sensor settings (SI units)", "[vfs]"]
        for key, value in self.to_dict().items():
            if value is None:  # TOML has no null: a missing key is the default
                continue
            if isinstance(value, bool):
                txt = "true" if value else "false"
            elif isinstance(value, str):
                txt = '"' + value + '"'
            else:
                txt = repr(value)
            lines.append(f"{key} = {txt}")
        return "\n".join(lines) + "\n"

    @classmethod
    def from_toml(cls, text_or_path: str | Path) -> VFSConfig:
        """Parse TOML text or a ``.toml`` file."""
        s = str(text_or_path)
        if not s.lstrip().startswith(("[", "#")) and (s.endswith(".toml") or Path(s).exists()):
            p = Path(s)
            if not p.exists():
                raise ConfigError(f"vfs config file {p} does not exist")
            s, where = p.read_text(), str(p)
        else:
            where = "<string>"
        try:
            data = tomllib.loads(s)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{where} is not valid TOML: {exc}") from exc
        return cls.from_dict(data)
