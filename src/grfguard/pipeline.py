"""The sensor monitor: virtual force sensor → detector → recovery, streaming and batch.

Three stages, each its own module, wired here (the only module that knows all three):

1. **estimate** (:class:`~grfguard.estimate.vfs.VirtualForceSensor`): the corner forces
   ``N̂`` and foot forces the robot's kinematics and IMU imply (or the ``vfs_*`` columns
   the log already carries);
2. **detect**: method ``default`` (:class:`~grfguard.detect.detector.Detector`: gated
   CUSUM tests, isolation, fault kind; design constants in
   :class:`~grfguard.detect.tuning.DetectTuning`) or ``paper``
   (:class:`~grfguard.detect.paper.PaperDetector`: the paper's observer, eq. 24-33,
   which also gives its own recovered force);
3. **recover** (:class:`~grfguard.recover.recovery.Recovery`): ``recovered_<s>`` and
   ``eta_<s>`` from the detector's verdicts (method ``default``).

:class:`Monitor` streams (``update(row)``, never raises on a bad sample) and batches
(``run(log)``: reset plus the same steps over the whole log, identical numbers).

Compiled path (the default, ``compiled=True``): when the settings are covered (method
``default``, no common-mode layer, no diagnostics, the compiled virtual sensor or
precomputed ``vfs_*`` columns) the guards, virtual sensor, detector, recovery and
standing layer run as one compiled step per sample (:mod:`grfguard.kernels.monitor`),
with the same outputs as these Python stages (``tests/test_kernels_detect.py``);
``update_array(x) -> y`` is that step with flat arrays (layouts in
:attr:`Monitor.input_columns` / :attr:`Monitor.output_columns`), ``run`` one compiled
loop over the log. :meth:`Monitor.compiled_reason` says why a monitor runs the Python
stages instead.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from grfguard._lazy import lazy_module
from grfguard.detect.config import MonitorConfig, config_for_log
from grfguard.detect.detector import VFS_TOTAL_COLUMNS, Detector
from grfguard.detect.paper import PaperDetector
from grfguard.detect.standing import StandingConfig, StandingStage
from grfguard.detect.system import (
    AccVibrationDetector,
    CommonModeConfig,
    CommonModeMonitor,
    GyroBiasLearner,
    ImuTiltLearner,
    SwingZeroLearner,
    hold_standing_release,
    hold_unarmed_tests,
    quiet_vfs_config,
    swing_load_to_stance,
)
from grfguard.detect.tuning import DetectTuning
from grfguard.errors import ConfigError, LogFormatError
from grfguard.guard import Continuity, GuardConfig, InputGuard, TimeGuard
from grfguard.io.schema import (
    IMU_ACC,
    IMU_GYRO,
    IMU_QUAT,
    JOINT_COLUMNS,
    TIME,
    ZMP_REF,
    force_col,
    vfs_col,
)
from grfguard.model.robot import SENSOR_NAMES, SIDES, RobotConfig
from grfguard.recover.recovery import RecoverTuning, Recovery
from grfguard.rotations import quat_to_matrix, rotation_to_quat

pd = lazy_module("pandas")  # (imported on first use: `grfguard run` never does)

__all__ = ["Monitor"]

_NAN = float("nan")
_UNSET = object()
_F8 = np.dtype(np.float64)
_ND = np.ndarray
_ROW_STRIDES = (8,)  # a contiguous float64 row
_REC_COLS = tuple(f"recovered_{s}" for s in SENSOR_NAMES)
_KIND_COLS = tuple(f"kind_{s}" for s in SENSOR_NAMES)
_FLAG_COLS = tuple(f"flag_{s}" for s in SENSOR_NAMES)


def _rotate_imu(row: dict[str, Any], C: np.ndarray) -> None:
    """Express the IMU readings of ``row`` in the described IMU frame (in place):
    ``R_WI <- R_WI C^T``, ``acc <- C acc``, ``gyro <- C gyro``."""
    quat = np.array([_f(row, c) for c in IMU_QUAT])
    if np.all(np.isfinite(quat)):
        qc = rotation_to_quat(quat_to_matrix(quat) @ C.T)
        qc = qc * (-1.0 if qc[0] < 0 else 1.0)
        for c, val in zip(IMU_QUAT, qc, strict=True):
            row[c] = float(val)
    for cols in (IMU_ACC, IMU_GYRO):
        vec = C @ np.array([_f(row, c) for c in cols])
        for c, val in zip(cols, vec, strict=True):
            row[c] = float(val)


def _f(row: Mapping[str, Any], key: str) -> float:
    """``row[key]`` as a float; NaN when missing or not a number."""
    try:
        return float(row[key])
    except (KeyError, TypeError, ValueError, OverflowError):
        return _NAN


def _log_robot(log: pd.DataFrame, vfs: Any, robot: Any) -> RobotConfig:
    """The robot whose weight and sole the monitor's guards, common-mode fit, swing-zero
    learner and standing layer use: ``robot`` or the log's metadata through
    :func:`grfguard.estimate.described.log_robot` (the one resolver); the virtual
    sensor's robot when the log names none. Never a stand-in.

    Raises:
        LogFormatError: The log gives no way to know the robot.
    """
    from grfguard.estimate.described import log_robot, names_robot

    if robot is None and not names_robot(log) and getattr(vfs, "robot", None) is not None:
        return vfs.robot
    return log_robot(log, robot, where="Monitor.for_log")


def _with_columns(log: pd.DataFrame, new: Mapping[str, Any], copy: bool = True
                  ) -> pd.DataFrame:
    """A copy of ``log`` with the columns ``new`` (replaced in place when ``log`` has
    them, else appended in order), built in one go; ``copy=False`` takes the arrays of
    ``new`` as they are (fresh arrays that nothing else holds)."""
    add = pd.DataFrame(dict(new), index=log.index, copy=copy)
    if not any(c in log.columns for c in new):
        return pd.concat([log, add], axis=1)
    order = list(log.columns) + [c for c in new if c not in log.columns]
    keep = log.drop(columns=[c for c in new if c in log.columns])
    return pd.concat([keep, add], axis=1)[order]


def _has_gyro_ref(log: pd.DataFrame) -> tuple[bool, bool]:
    """Whether the log carries the gyro and the planned contact (the compiled virtual
    sensor's switches)."""
    return (all(c in log.columns for c in IMU_GYRO),
            all(f"contact_ref_{s}" in log.columns for s in SIDES))


class _Prepared(NamedTuple):
    """One sample after the guards: the detector's arguments and the system state."""

    clock: float
    x: list[float]
    v: list[float]
    tot: list[float]
    cref: list[float]
    cest: list[float]
    implausible: list[bool]
    state: str
    reason: str


class _PreparedFrame(NamedTuple):
    """The guards' verdicts over a whole log (arrays, one row per sample)."""

    clock: np.ndarray
    x: np.ndarray
    v: np.ndarray
    tot: np.ndarray
    cref: np.ndarray
    cest: np.ndarray
    implausible: np.ndarray
    state: np.ndarray
    reason: np.ndarray

    def sample(self, k: int) -> _Prepared:
        """Sample ``k`` as a :class:`_Prepared`."""
        return _Prepared(float(self.clock[k]), self.x[k].tolist(), self.v[k].tolist(),
                         self.tot[k].tolist(), self.cref[k].tolist(), self.cest[k].tolist(),
                         self.implausible[k].tolist(), str(self.state[k]),
                         str(self.reason[k]))


def _compiled_or(vfs: Any, warm: bool = True) -> Any:
    """``vfs`` with its kernels loaded from the on-disk cache (or compiled) now; when that
    fails here (e.g. the cache cannot be written) a warning, and numba compiles them in
    memory at the first sample. ``warm=False``: each kernel loads at its first call."""
    from grfguard.kernels import warm_up

    if not warm:
        return vfs
    try:
        warm_up()
    except Exception as exc:  # noqa: BLE001 - compiled in memory at the first call instead
        warnings.warn(f"the compiled kernels could not be loaded or cached ({exc}); they "
                      "compile in memory at the first sample", RuntimeWarning, stacklevel=3)
    return vfs


class Monitor:
    """Virtual force sensor + fault detection, isolation, classification and recovery.

    Per sample, before the detector: the input guard (:class:`~grfguard.guard.InputGuard`)
    turns values outside the robot's physical range into NaN (an IMU or encoder glitch
    is skipped by the VFS like a dropout, a force reading out of range is a fault at
    once, kind ``spikes``); the time guard (:class:`~grfguard.guard.TimeGuard`) finds
    gaps and stamps that do not move forward; after such a break or after samples the
    VFS could not use, the VFS is reset and its outputs wait ``guard.settle_s`` before
    the tests use them again (the tests never compare a sensor with a held estimate).
    ``recovered_<s>`` is kept within the plausible force range. The ``system_state``
    (``ok``, ``time_gap``, ``time_backwards``, ``time_constant``, ``time_missing``,
    ``input_invalid``, ``settling``) and ``system_reason`` outputs report all this; none
    of it flags a sensor by itself.

    Args:
        config: Settings (method, thresholds, gates).
        vfs: A ``VirtualForceSensor`` for the robot, or None when every input row already
            carries the VFS outputs (``vfs_<s>``, ``vfs_total_<side>``).
        detect_tuning: Design constants of the default detector.
        recover_tuning: Design constants of the recovery.
        guard: Settings of the input and time guards.
        robot: Robot description for the physical ranges (default: the VFS's robot;
            required when ``vfs`` is None: :meth:`for_log` reads it from the log).
        common_mode: Settings of the system-level layer (:mod:`grfguard.detect.system`:
            common-mode fit and ``model_mismatch``, load-cell zero, gyro bias and IMU tilt
            learners, accelerometer vibration switch; True, the default: default
            settings (off for the method ``paper``), False: off).
        standing: Settings of the standing layer
            (:class:`~grfguard.detect.standing.StandingStage`: faults that start while
            both feet stand; True: default settings, False: off).

    Example:
        >>> mon = Monitor.for_log(log)
        >>> out = mon.run(log)                  # log + vfs_*, flag_*, kind_*, eta_*, ...
        >>> mon.reset(); row_out = mon.update(log.iloc[0].to_dict())
    """

    #: update_array's compiled kernel once built (a class default: monitors pickled by an
    #: earlier version, which lack the attribute, take the checked path)
    _row_kernel: Any = None

    def __init__(
        self,
        config: MonitorConfig | None = None,
        vfs: Any = None,
        detect_tuning: DetectTuning | None = None,
        recover_tuning: RecoverTuning | None = None,
        guard: GuardConfig | None = None,
        robot: RobotConfig | None = None,
        common_mode: CommonModeConfig | bool = True,
        standing: StandingConfig | bool = True,
        compiled: bool | None = None,
    ) -> None:
        self.config = config if config is not None else MonitorConfig()
        self.vfs = vfs
        self.compiled = self.config.compiled if compiled is None else bool(compiled)
        self._kernels: dict[tuple[bool, bool], Any] = {}
        self._kernels_for: Any = _UNSET
        self.guard = guard if guard is not None else GuardConfig()
        if robot is None:
            robot = getattr(vfs, "robot", None)
        if robot is None:
            raise ConfigError(
                "Monitor: no robot (robot=None and no virtual sensor, vfs=None): its weight "
                "and sole set the input guards, the common-mode fit and the standing layer, "
                "and grfguard never guesses them; pass robot= (a RobotConfig, e.g. "
                "grfguard.model.robot.load_robot('ROBOT.toml') or grfguard.SURALP) or vfs=, "
                "or build the monitor with Monitor.for_log(log) (the log's own robot)")
        self.robot = robot
        self.detector = Detector(self.config, detect_tuning)
        self.paper = PaperDetector(self.config)
        self.recovery = Recovery(self.config, recover_tuning)
        self.inputs = InputGuard(robot, self.guard)
        self.time_guard = TimeGuard(self.config.dt_s, self.guard)
        self.continuity = Continuity(self.guard.settle_s)
        # standing layer (issue 10): faults that start while both feet stand
        self.standing: StandingStage | None = None
        if standing is not False:
            self.standing = StandingStage(self.config.dt_s, standing if isinstance(
                standing, StandingConfig) else None, weight_n=robot.weight)
        self.common: CommonModeMonitor | None = None
        self.zeros: SwingZeroLearner | None = None
        self.gyro_bias: GyroBiasLearner | None = None
        self.tilt: ImuTiltLearner | None = None
        self.vibration: AccVibrationDetector | None = None
        self.vfs_quiet: Any = None
        if common_mode is True and self.config.method != "default":
            common_mode = False  # the paper's method as published (and its speed)
        if common_mode is not False:
            cm_cfg = common_mode if isinstance(common_mode, CommonModeConfig) else None
            self.common = CommonModeMonitor(robot, self.config.dt_s, cm_cfg)
            self.zeros = SwingZeroLearner(robot, self.config.dt_s)
            self.gyro_bias = GyroBiasLearner(self.config.dt_s)
            kin = getattr(vfs, "kin", None)
            if kin is not None and hasattr(kin, "forward"):
                self.tilt = ImuTiltLearner(kin, self.config.dt_s, learn_s=0.2,
                                           apply_after_s=0.1, every_n=5)
            self._vibration_setup(vfs)
        self.reset()

    @classmethod
    def for_log(cls, log: pd.DataFrame, config: MonitorConfig | None = None,
                guard: GuardConfig | None = None,
                common_mode: CommonModeConfig | bool = True,
                compiled: bool | None = None,
                standing: StandingConfig | bool = True, robot: Any = None,
                warm: bool = True) -> Monitor:
        """A monitor for ``log``: reuses its ``vfs_*`` columns when present, otherwise builds
        ``VirtualForceSensor.for_log(log, config.vfs)``; the sampling period from ``time``;
        the robot (weight and sole of the guards, the system layer and the standing layer)
        from ``robot`` (a ``RobotConfig``, or a described robot: ``LoadedRobot``, shipped
        name, TOML path) or ``log.attrs`` (a described robot such as G1: its own mass and
        sole), never a stand-in: a log that names no robot (with precomputed ``vfs_*``
        columns and no ``robot``) raises :class:`~grfguard.errors.LogFormatError`.

        The virtual sensor is the compiled one (:mod:`grfguard.kernels`; every
        ``config.vfs``); its machine code is loaded from the on-disk cache here (1-2 s once
        per process). A fresh install compiles it and the monitor's loop first: about
        two minutes once (``grfguard warm-up`` from an empty cache: 93-108 s on two cores,
        122 s on one, 2026-11-28). ``compiled=False`` runs the
        detector's pure-Python stages around it. The streaming step is built here too, so
        the first :meth:`update_array` or :meth:`update` takes microseconds like the
        others (built at that call, it took 3-7 ms). ``warm=False`` loads nothing
        here: each kernel loads at its first call (a batch run loads only its loop: about
        0.3 s less; streaming then pays the load and the build at the first sample)."""
        cfg = config_for_log(log, config)
        has_vfs = all(vfs_col(s) in log.columns for s in SENSOR_NAMES) and all(
            c in log.columns for c in VFS_TOTAL_COLUMNS
        )
        vfs = None
        if not has_vfs:
            from grfguard.estimate.vfs import VirtualForceSensor

            vfs = _compiled_or(VirtualForceSensor.for_log(log, cfg.vfs, warm=False), warm)
        robot = _log_robot(log, vfs, robot)
        mon = cls(cfg, vfs, guard=guard, robot=robot, common_mode=common_mode,
                  standing=standing, compiled=compiled)
        return mon.prepare() if warm else mon

    def prepare(self) -> Monitor:
        """Build the compiled streaming step now and load its machine code (and the dict
        call's module), so that the first :meth:`update_array` or :meth:`update` takes
        microseconds like the others; returns the monitor. :meth:`for_log` does this; a
        monitor built directly (``Monitor(config, vfs)``) builds it at its first sample
        instead (4-7 ms: call this before a real-time loop starts). Nothing when the
        monitor runs the Python stages; the state is untouched."""
        k = self._kernel()
        if k is not None:
            k.prepare()
            import grfguard.compiled_monitor  # noqa: F401  (the dict call's module)
        return self

    def compiled_reason(self) -> str:
        """Empty when the whole monitor runs compiled (:mod:`grfguard.kernels.monitor`:
        guards, virtual sensor, default detector and recovery in one compiled step);
        otherwise why it runs the pure-Python stages."""
        if not self.compiled:
            return "compiled=False"
        if self.config.method != "default":
            return f"method {self.config.method!r}"
        if self.config.diagnostics:
            return "diagnostics"
        if self.vfs is None:
            return ""
        if not (getattr(self.vfs, "compiled", False) and hasattr(self.vfs, "kernel")):
            return "a pure-Python virtual force sensor"  # (its vibration twin is the same type)
        if getattr(getattr(self.vfs, "config", None), "com_method", "") == "paper":
            return "the paper's CoM filter (its sensor reads the force sensors)"
        return ""

    def _kernel(self, has_gyro: bool = True, has_ref: bool = True) -> Any:
        """The compiled monitor step for inputs with / without gyro and planned contact
        (None when the monitor runs the Python stages)."""
        if self._kernels_for is not self.vfs:
            self._kernels = {}
            self._kernels_for = self.vfs
            self._row_kernel = None
            self._compiled_ok = not self.compiled_reason()
        if not self._compiled_ok:
            return None
        key = (has_gyro, has_ref)
        k = self._kernels.get(key)
        if k is None:
            try:
                from grfguard.kernels.detect import detect_params
                from grfguard.kernels.monitor import MonitorKernel

                prm = detect_params(self.config, self.detector.tuning, self.recovery.tuning,
                                    self.guard, (self.inputs.force_lo, self.inputs.force_hi),
                                    self.inputs.vfs_force_lo)
                vk = self.vfs.kernel(has_gyro, has_ref) if self.vfs is not None else None
                system = None
                if self.common is not None:  # the system layer (kernels/system.py)
                    qk = (self.vfs_quiet.kernel(has_gyro, has_ref)
                          if self.vfs_quiet is not None else None)
                    system = (self, has_gyro, qk)
                k = MonitorKernel(prm, self.inputs, vk, self.standing, system)
            except Exception as exc:  # noqa: BLE001 - the compiled monitor is only faster
                warnings.warn(f"compiled monitor unavailable ({exc}); using the pure-Python "
                              "stages", RuntimeWarning, stacklevel=3)
                self._compiled_ok = False
                return None
            self._kernels[key] = k
            if key == (True, True):
                self._row_kernel = k
        return k

    def reset(self) -> None:
        """Forget everything (filters, flags, contact timeline, VFS state, guards)."""
        if self.vfs is not None:
            self.vfs.reset()
        if self._kernels_for is self.vfs:
            for k in self._kernels.values():
                k.reset()
        self.detector.reset()
        self.paper.reset()
        self.recovery.reset()
        self.time_guard.reset()
        self.continuity.reset()
        if self.standing is not None:
            self.standing.reset()
        if self.common is not None:
            self.common.reset()
        if self.zeros is not None:
            self.zeros.reset()
        if self.gyro_bias is not None:
            self.gyro_bias.reset()
        if self.tilt is not None:
            self.tilt.reset()
        self._bias_now: tuple[float, ...] = (0.0, 0.0, 0.0)
        self._bias_rows: np.ndarray | None = None
        self._tilt_now: tuple[float, ...] = (0.0, 0.0)
        self._tilt_seen: tuple[float, ...] = (0.0, 0.0)
        self._tilt_settle_s = 0.0
        self._tilt_rows: np.ndarray | None = None
        self._eye = self.tilt.rotation if self.tilt is not None else None
        self._spike = [False] * len(SENSOR_NAMES)
        if self.vibration is not None:
            self.vibration.reset()
            self.vfs_quiet.reset()
        self.detector.config = self.config
        self._vib_active = False

    def _vibration_setup(self, vfs: Any) -> None:
        """``common_mode``: a twin virtual sensor without the accelerometer, used (with
        the corner threshold widened) once the accelerometer vibrates
        (:class:`~grfguard.detect.system.AccVibrationDetector`)."""
        import dataclasses

        cfg = getattr(vfs, "config", None)
        if vfs is None or not getattr(cfg, "use_accelerometer", False):
            return
        self.vibration = AccVibrationDetector(self.config.dt_s)
        self.vfs_quiet = type(vfs)(vfs.robot, quiet_vfs_config(cfg), vfs.kin)
        th = self.config.thresholds
        self._quiet_config = self.config.with_thresholds(dataclasses.replace(
            th, corner_sigma=th.corner_sigma * self.vibration.config.corner_sigma_scale))

    def _vibration_start(self, clean: pd.DataFrame, n: int) -> int:
        """Batch twin of the vibration switch: the first switched sample (``n`` when
        never or without the switch)."""
        if self.vibration is None or self.vfs is None:
            return n
        return self.vibration.run(
            pd.to_numeric(clean[IMU_ACC[0]], errors="coerce").to_numpy(float),
            pd.to_numeric(clean[IMU_ACC[1]], errors="coerce").to_numpy(float))

    def _vibration_frame(self, clean: pd.DataFrame, vdf: Any, k_vib: int,
                         resets: np.ndarray) -> Any:
        """The VFS outputs with the quiet sensor's rows from ``k_vib`` on; the quiet
        sensor is resynced where the main one is (``resets``), never reset: as the main
        sensor it holds its last output over unusable samples and keeps its filters,
        attitude and odometry across a break (as ``update`` and the compiled monitor)."""
        if vdf is None or k_vib >= len(vdf):
            return vdf
        vq = self.vfs_quiet.run_resynced(clean, resets)
        vdf = vdf.copy()
        qcols = [c for c in vdf.columns if c in vq.columns]
        vdf.loc[vdf.index[k_vib:], qcols] = vq[qcols].iloc[k_vib:].to_numpy()
        return vdf

    def _vibration_on(self) -> None:
        """Switch the detector to the widened corner threshold (once); the virtual forces
        change source: the fits settle again (as after a tilt change)."""
        if not self._vib_active:
            self._tilt_settle_s = 1.0
        self.detector.config = self._quiet_config
        self._vib_active = True

    def _vfs_row(self, row: Mapping[str, Any]) -> dict[str, float]:
        if self.vfs is not None:
            try:
                return self.vfs.update(row)
            except Exception:  # noqa: BLE001 - a bad sample must never raise
                return {}
        return {}

    # ------------------------------------------------------------------ stages
    def _prepare(
        self, t_raw: float, clock: float, tstate: str, jump: float, reason: str,
        reset: bool, valid: bool, x_raw: list[float], x: list[float], v: list[float],
        tot: list[float], cref: list[float], cest: list[float],
    ) -> _Prepared:
        """The guards' verdict on one sample (shared by ``update`` and ``run``)."""
        lo, hi, vlo = self.inputs.force_lo, self.inputs.force_hi, self.inputs.vfs_force_lo
        bounded = all(math.isnan(q) or vlo <= q <= hi for q in v) and all(
            math.isnan(q) or 2 * lo <= q <= 2 * hi for q in tot)
        use = self.continuity.after(clock, reset, valid) and bounded
        if not use:
            v = [_NAN] * len(v)
            tot = [_NAN, _NAN]
            cest = [_NAN, _NAN]
        implausible = [self.inputs.force_implausible(q) for q in x_raw]
        if tstate != "ok":
            state = tstate
            reason = (f"time stamp {t_raw:.6g} s: step {jump:+.6g} s" if math.isfinite(jump)
                      else "time stamp missing") + (f"; {reason}" if reason else "")
        elif not (valid and bounded):
            state = "input_invalid"
            reason = reason or ("estimator inputs missing or not finite" if not valid
                                else "virtual forces outside the physical range")
        elif not use:
            state = "settling"
            reason = reason or "virtual sensor settling after a break"
        else:
            state = "ok"
        return _Prepared(clock, x, v, tot, cref, cest, implausible, state, reason)

    def _step(self, t: float, x: list[float], v: list[float], tot: list[float],
              cref: list[float], cest: list[float]) -> dict[str, Any]:
        """Detector and recovery on one sample of plain floats."""
        if self.config.method == "paper":
            return self.paper.step(t, x, v)
        det = self.detector.step(t, x, v, tot, cref, cest)
        out = self.recovery.step(self.detector.sensors, x, v, tot, det.columns)
        if self.standing is not None:
            self.standing.step(x, v, tot, cref, cest, out)
        if det.diagnostics:
            out.update(det.diagnostics)
        return out

    def _detect(self, p: _Prepared) -> dict[str, Any]:
        """Detector and recovery on a prepared sample; a time gap first resets the
        contact timeline (lift-off and touch-down times, swing durations measured across
        the gap would be wrong)."""
        if p.state == "time_gap":
            self.detector.timeline.reset()
        if self.common is None or self.config.method == "paper":
            return self._step(p.clock, p.x, p.v, p.tot, p.cref, p.cest)
        valid = [(ce > 0.5) if math.isfinite(ce) else (cr > 0.5)
                 for ce, cr in zip(p.cest, p.cref, strict=True)]
        if not all(math.isfinite(q) for q in p.v):
            valid = [False, False]
        flags = [s.flag for s in self.detector.sensors]
        frozen = any(flags)
        x = p.x
        if self.zeros is not None:
            contact = [(cr > 0.5) or (ce > 0.5)
                       for ce, cr in zip(p.cest, p.cref, strict=True)]
            z = self.zeros.update(p.x, p.tot, contact, flags)
            x = [a - float(b) for a, b in zip(x, z, strict=True)]
        v0, tot0 = list(p.v), list(p.tot)
        swing_load_to_stance(x, v0, tot0, p.cref, self.robot.weight)
        p = p._replace(v=v0, tot=tot0)
        if self._tilt_now != self._tilt_seen:  # the virtual forces changed: learn anew
            self._tilt_seen = self._tilt_now
            self._tilt_settle_s = 1.0  # the VFS attitude filter settles (2 x 0.5 s)
        if self._tilt_settle_s > 0.0:
            self._tilt_settle_s -= self.config.dt_s
            self.common.reset()
            if self.standing is not None:  # nor a stand's baseline across the change
                self.standing.detector.reset()
        cm = self.common.update(x, p.v, valid, frozen=frozen, planned=p.cref)
        v, tot = p.v, p.tot
        if cm.model_mismatch:
            corr = [float(c) for c in cm.correction_n]
            v = [a + c for a, c in zip(v, corr, strict=True)]
            tot = [tot[0] + math.fsum(corr[:4]), tot[1] + math.fsum(corr[4:])]
        if self.zeros is not None:
            armed = [self.zeros.armed(f) for f in range(2)]
            hold_unarmed_tests(self.detector, armed, self.common.armed)
            if self.standing is not None:  # a flag held after a stand waits for armed tests
                hold_standing_release(self.standing, armed, self.common.armed)
        out = self._step(p.clock, x, v, tot, p.cref, p.cest)
        reasons = [cm.reason] if cm.reason else []
        if self.gyro_bias is not None and any(self._bias_now):
            bx, by, bz = self._bias_now
            reasons.append(f"gyro bias ({bx:+.3f}, {by:+.3f}, {bz:+.3f}) rad/s removed")
        if self._vib_active:
            assert self.vibration is not None
            reasons.append(
                f"accelerometer vibration (RMS {self.vibration.rms_m_s2:.1f} m/s^2 above "
                f"{self.vibration.config.cutoff_hz:g} Hz): virtual sensor without it, corner "
                f"threshold x{self.vibration.config.corner_sigma_scale:g}")
        if any(self._tilt_now):
            reasons.append("IMU mounting tilt (roll {:+.1f}, pitch {:+.1f}) deg removed".format(
                *self._tilt_now))
        if self.zeros is not None:
            zs = self.zeros.zeros_n
            if zs.any():
                reasons.append("load-cell zeros removed (" + ", ".join(
                    f"{n} {q:+.0f} N" for n, q in zip(SENSOR_NAMES, zs, strict=True)
                    if q != 0.0) + ")")
        out["model_mismatch"] = bool(reasons)
        out["model_mismatch_reason"] = "; ".join(reasons)
        return out

    def _finish(self, res: dict[str, Any], p: _Prepared) -> dict[str, Any]:
        """Kinds of out-of-range readings, recovered force within range, system state."""
        for i in range(len(SENSOR_NAMES)):
            flagged = bool(res.get(_FLAG_COLS[i], False))
            if p.implausible[i]:
                self._spike[i] = True
            elif not flagged:
                self._spike[i] = False
            if self._spike[i] and flagged and _KIND_COLS[i] in res:
                res[_KIND_COLS[i]] = "spikes"
            rc = _REC_COLS[i]
            if rc in res:
                res[rc] = self.inputs.clamp(float(res[rc]))
        res["system_state"] = p.state
        res["system_reason"] = p.reason
        return res

    # ------------------------------------------------------------------ streaming
    def update(self, row: Mapping[str, Any]) -> dict[str, Any]:
        """Process one sample; never raises on a bad sample (NaN, out-of-range values or
        missing keys are rejected, flagged as dropouts or skipped).

        Args:
            row: Mapping with the log-contract columns of one sample.

        Returns:
            Dict with the VFS outputs and ``flag_<s>``, ``kind_<s>``, ``eta_<s>``,
            ``recovered_<s>`` for every sensor, ``system_state`` and ``system_reason``.
        """
        if not isinstance(row, Mapping):
            row = {}
        k = self._kernel()
        if k is not None:
            from grfguard.compiled_monitor import update_dict

            return update_dict(self, k, row)
        t_raw = _f(row, TIME)
        clean, reason = self.inputs.clean_row(row)
        if self.gyro_bias is not None:
            clean = dict(clean)
            self._unbias_row(clean)
        clock, tstate, jump = self.time_guard.step(t_raw)
        reset = self.continuity.before(tstate)
        if reset and self.vfs is not None:
            self.vfs.resync()  # forget the finite-difference history only
            if self.vfs_quiet is not None:  # the twin too (it keeps its odometry)
                self.vfs_quiet.resync()
        vout = self._vfs_row(clean)
        if self.vibration is not None:
            try:
                vq = self.vfs_quiet.update(clean)
            except Exception:  # noqa: BLE001 - a bad sample must never raise
                vq = {}
            if self.vibration.update(_f(clean, IMU_ACC[0]), _f(clean, IMU_ACC[1])):
                vout = vq
                self._vibration_on()
        src = vout if self.vfs is not None else clean
        v = [_f(src, vfs_col(s)) for s in SENSOR_NAMES]
        tot = [_f(src, c) for c in VFS_TOTAL_COLUMNS]
        valid = self._valid(_f(src, "vfs_valid"), v, tot)
        p = self._prepare(
            t_raw, clock, tstate, jump, reason, reset, valid,
            [_f(row, force_col(s)) for s in SENSOR_NAMES],
            [_f(clean, force_col(s)) for s in SENSOR_NAMES],
            v, tot,
            [_f(row, f"contact_ref_{s}") for s in SIDES],
            [_f(src, f"contact_est_{s}") for s in SIDES],
        )
        res = self._finish(self._detect(p), p)
        out: dict[str, Any] = dict(vout)
        out.update(res)
        return out

    @property
    def input_columns(self) -> tuple[str, ...]:
        """Layout of the input row of :meth:`update_array`: ``time``, the eight
        ``force_<s>``, then the virtual sensor's inputs (joint angles, IMU, planned
        contact: :data:`grfguard.kernels.vfs.IN_COLUMNS`) or, for a monitor without a
        virtual sensor, the precomputed ``contact_ref_*``, ``vfs_*``, ``vfs_total_*``,
        ``contact_est_*``, ``vfs_valid`` (:mod:`grfguard.kernels.monitor`)."""
        from grfguard.kernels.monitor import input_columns

        return input_columns(self.vfs is not None, self.common is not None)

    @property
    def output_columns(self) -> tuple[str, ...]:
        """Layout of the output row of :meth:`update_array`: the 22 virtual-sensor outputs
        (with a virtual sensor inside), then ``flag_<s>`` (0/1), ``kind_<s>`` (index into
        :data:`grfguard.kernels.detect.KIND_NAMES`), ``eta_<s>`` [N], ``recovered_<s>``
        [N] for the eight sensors, and ``system_state`` (index into
        :data:`grfguard.guard.SYSTEM_STATES`)."""
        from grfguard.kernels.monitor import output_columns

        return output_columns(self.vfs is not None, self.common is not None)

    def update_array(self, x: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        """One sample as arrays (the fast streaming call): ``x`` in
        :attr:`input_columns` order -> ``y`` in :attr:`output_columns` order (written into
        ``y`` when given, a contiguous float64 array). Same numbers as :meth:`update`
        (without the ``system_reason`` text); never raises on a bad sample. One compiled
        call when the monitor runs compiled (:meth:`compiled_reason`), else through
        :meth:`update`.

        Raises:
            LogFormatError: If ``x`` or ``y`` has the wrong length.
        """
        k = self._row_kernel if self._kernels_for is self.vfs else None
        if k is None:
            k = self._kernel()
        if k is not None:
            if y is None:
                y = np.empty(k.sout)
            # the compiled code does not check bounds: exact shapes and types only
            if (x.__class__ is _ND and y.__class__ is _ND and x.dtype is _F8
                    and y.dtype is _F8 and x.shape == k.sin and y.shape == k.sout
                    and x.strides == _ROW_STRIDES and y.strides == _ROW_STRIDES):
                ep = k._entry  # the 1 kHz path: straight to the machine code once known
                if ep is not None:
                    ep(x, y, k.F, k.I)
                    return y
                return k.step(x, y)
        n_in = len(self.input_columns)
        n_out = len(self.output_columns)
        if y is None:
            y = np.empty(n_out)
        x = np.ascontiguousarray(x, dtype=float).ravel()
        if x.shape != (n_in,) or y.shape != (n_out,):
            raise LogFormatError(
                f"Monitor.update_array takes an input row of {n_in} values in "
                f"Monitor.input_columns order and an output row of {n_out}; got shapes "
                f"{x.shape} and {y.shape}")
        if k is not None:
            yy = np.empty(n_out)
            k.step(x, yy)
            y[:] = yy
            return y
        from grfguard.compiled_monitor import dict_to_row

        y[:] = dict_to_row(self.update(dict(zip(self.input_columns, x.tolist(),
                                                strict=True))), self.output_columns)
        return y

    def _unbias_row(self, clean: dict[str, Any]) -> None:
        """Subtract the learned gyro bias from one cleaned row (in place)."""
        assert self.gyro_bias is not None
        if not all(c in clean for c in IMU_GYRO):
            return
        b = self.gyro_bias.update(
            [_f(clean, c) for c in IMU_GYRO],
            [_f(clean, f"contact_ref_{s}") for s in SIDES],
            [_f(clean, c) for c in ZMP_REF],
        )
        self._bias_now = b
        for c, q in zip(IMU_GYRO, b, strict=True):
            if q != 0.0:
                clean[c] = _f(clean, c) - q
        if self.tilt is not None:
            C = self.tilt.update(
                np.array([_f(clean, c) for c in JOINT_COLUMNS]),
                np.array([_f(clean, c) for c in IMU_QUAT]), self.gyro_bias.still)
            self._tilt_now = self.tilt.tilt_deg() if C is not self._eye else (0.0, 0.0)
            if C is not self._eye:
                _rotate_imu(clean, C)

    def _unbias_frame(self, clean: pd.DataFrame) -> pd.DataFrame:
        """The learned gyro bias subtracted from the cleaned log (same numbers as
        :meth:`_unbias_row` row by row)."""
        assert self.gyro_bias is not None
        n = len(clean)

        def col(c: str) -> np.ndarray:
            if c in clean:
                return pd.to_numeric(clean[c], errors="coerce").to_numpy(dtype=float)
            return np.full(n, np.nan)

        g = np.column_stack([col(c) for c in IMU_GYRO])
        cr = np.column_stack([col(f"contact_ref_{s}") for s in SIDES])
        zr = np.column_stack([col(c) for c in ZMP_REF])
        bias = np.zeros((n, 3))
        rots: list[np.ndarray] = []
        tilts = np.zeros((n, 2))
        q = np.column_stack([col(c) for c in JOINT_COLUMNS])
        quat = np.column_stack([col(c) for c in IMU_QUAT])
        for k in range(n):
            bias[k] = self.gyro_bias.update(g[k], cr[k], zr[k])
            if self.tilt is not None:
                C = self.tilt.update(q[k], quat[k], self.gyro_bias.still)
                rots.append(C)
                if C is not self._eye:
                    tilts[k] = self.tilt.tilt_deg()
        self._bias_rows = bias
        self._tilt_rows = tilts
        rotated = any(C is not self._eye for C in rots)
        if not bias.any() and not rotated:
            return clean
        out = clean.copy()
        for j, c in enumerate(IMU_GYRO):
            out[c] = g[:, j] - bias[:, j]
        if rotated:
            acc = np.column_stack([col(c) for c in IMU_ACC])
            gy = np.column_stack([out[c].to_numpy(dtype=float) for c in IMU_GYRO])
            Cs = np.stack(rots)
            acc = np.einsum("kij,kj->ki", Cs, acc)
            gy = np.einsum("kij,kj->ki", Cs, gy)
            nan33 = np.full((3, 3), np.nan)
            Rw = np.stack([quat_to_matrix(qq) if np.all(np.isfinite(qq)) else nan33
                           for qq in quat])
            Rw = np.einsum("kij,klj->kil", Rw, Cs)
            qc = np.array([rotation_to_quat(R) if np.all(np.isfinite(R)) else np.full(4, np.nan)
                           for R in Rw])
            qc = qc * np.where(qc[:, :1] < 0, -1.0, 1.0)
            for j, c in enumerate(IMU_ACC):
                out[c] = acc[:, j]
            for j, c in enumerate(IMU_GYRO):
                out[c] = gy[:, j]
            for j, c in enumerate(IMU_QUAT):
                out[c] = qc[:, j]
        return out

    def _valid(self, flag: float, v: list[float], tot: list[float]) -> bool:
        """The VFS output of this sample is usable (its ``vfs_valid``; without that
        column: every virtual force finite)."""
        if self.vfs is not None or math.isfinite(flag):
            return flag == 1.0
        return all(math.isfinite(q) for q in v) and all(math.isfinite(q) for q in tot)

    # ------------------------------------------------------------------ batch
    def run(self, log: pd.DataFrame) -> pd.DataFrame:
        """Reset, then process the whole log; returns ``log`` plus the output columns
        (the same numbers as :meth:`update` row by row).

        Raises:
            LogFormatError: If ``time`` or a ``force_<s>`` column is missing.
        """
        k = self._batch_kernel(log)
        if k is not None:
            from grfguard.compiled_monitor import run_frame

            out = run_frame(self, k, log)
            out.attrs = {**log.attrs, "monitor": self.describe()}
            return out
        return self._run_python(log)

    def _batch_kernel(self, log: pd.DataFrame) -> Any:
        """The start of :meth:`run` (also of :func:`grfguard.io.runwriter.write_run`): the
        columns checked, the monitor reset; the compiled kernel for ``log``, or None when
        the monitor runs the Python stages."""
        missing = [c for c in (TIME, *(force_col(s) for s in SENSOR_NAMES)) if c not in log]
        if missing:
            raise LogFormatError(
                f"Monitor.run: the log lacks column(s) {missing}; see grfguard.io.schema"
            )
        self.reset()
        if self.vfs is not None:
            self.vfs.check_columns(log.columns)
        return self._kernel(*_has_gyro_ref(log))

    def _run_python(self, log: pd.DataFrame) -> pd.DataFrame:
        """``run`` through the Python stages (the monitor is reset)."""
        attrs = log.attrs
        # the stages read columns only: without the metadata pandas would otherwise
        # deep-copy on every column access (a large cost on long logs)
        log = log.copy(deep=False)
        log.attrs = {}
        n = len(log)
        clean, reasons = self.inputs.clean_frame(log)
        if self.gyro_bias is not None and all(c in clean for c in IMU_GYRO):
            clean = self._unbias_frame(clean)
        t_raw = pd.to_numeric(log[TIME], errors="coerce").to_numpy(dtype=float).tolist()
        times = [self.time_guard.step(t) for t in t_raw]
        resets = np.zeros(n, dtype=bool)
        vdf = None
        k_vib = self._vibration_start(clean, n)
        if self.vfs is not None:
            self.vfs.check_columns(log.columns)
            valid_in = np.asarray(self.vfs.input_valid(clean) if n else np.zeros(0, bool),
                                  dtype=bool)
            if k_vib < n:  # once switched, the twin's validity decides (as in update)
                valid_in = valid_in.copy()
                valid_in[k_vib:] = self.vfs_quiet.input_valid(clean)[k_vib:]
            gap = np.array([q[1] == "time_gap" for q in times], dtype=bool)
            resets[1:] = gap[1:] | ~valid_in[:-1]
            if not resets.any():
                vdf = self.vfs.run(clean)
                self.vfs.reset()
            else:  # resynced where the streaming monitor resyncs it
                vdf = self.vfs.run_resynced(clean, resets)
        vdf = self._vibration_frame(clean, vdf, k_vib, resets)
        prep = self._prepare_frame(log, clean, vdf if vdf is not None else clean, times,
                                   reasons, resets)
        if self.config.method == "paper":
            res = self.paper.run(prep.clock, prep.x, prep.v)
            cols: dict[str, Any] = {c: np.asarray(res[c]) for c in res}
        else:
            rows = []
            for k in range(n):
                if self._bias_rows is not None:
                    self._bias_now = tuple(float(q) for q in self._bias_rows[k])
                if self._tilt_rows is not None:
                    self._tilt_now = tuple(float(q) for q in self._tilt_rows[k])
                if k == k_vib:
                    self._vibration_on()
                rows.append(self._detect(prep.sample(k)))
            res_df = pd.DataFrame(rows) if rows else pd.DataFrame()
            cols = {c: res_df[c].to_numpy() for c in res_df.columns}
        cols = self._finish_frame(cols, prep)
        new: dict[str, Any] = {}
        if vdf is not None:
            for c in vdf.columns:
                new[c] = vdf[c].to_numpy()
        new.update(cols)
        out = _with_columns(log, new)
        out.attrs = {**attrs, "monitor": self.describe()}
        return out

    def _prepare_frame(self, log: pd.DataFrame, clean: pd.DataFrame, src: pd.DataFrame,
                       times: list[tuple[float, str, float]], reasons: list[str],
                       resets: np.ndarray) -> _PreparedFrame:
        """:meth:`_prepare` over the whole log at once (same verdicts, as arrays):
        ``clean`` is the guarded log, ``src`` the frame with the VFS outputs."""
        n = len(log)

        def cols(frame: pd.DataFrame, names: Any, numeric: bool = False) -> np.ndarray:
            out = np.full((n, len(names)), np.nan)
            for j, c in enumerate(names):
                if c in frame.columns:
                    out[:, j] = (pd.to_numeric(frame[c], errors="coerce").to_numpy(float)
                                 if numeric else frame[c].to_numpy(dtype=float))
            return out

        t_raw = pd.to_numeric(log[TIME], errors="coerce").to_numpy(dtype=float)
        clock = np.array([q[0] for q in times], dtype=float)
        tstate = [q[1] for q in times]
        x = cols(clean, [force_col(s) for s in SENSOR_NAMES])
        v = cols(src, [vfs_col(s) for s in SENSOR_NAMES])
        tot = cols(src, VFS_TOTAL_COLUMNS)
        cref = cols(clean, [f"contact_ref_{s}" for s in SIDES])
        cest = cols(src, [f"contact_est_{s}" for s in SIDES])
        x_raw = cols(log, [force_col(s) for s in SENSOR_NAMES], numeric=True)
        flag = cols(src, ["vfs_valid"])[:, 0]
        if self.vfs is not None:
            valid = flag == 1.0
        else:
            fin = np.isfinite(v).all(axis=1) & np.isfinite(tot).all(axis=1)
            valid = np.where(np.isfinite(flag), flag == 1.0, fin)
            gap = np.array([s == "time_gap" for s in tstate], dtype=bool)
            resets = np.zeros(n, dtype=bool)
            resets[1:] = gap[1:] | ~valid[:-1]
        lo, hi, vlo = self.inputs.force_lo, self.inputs.force_hi, self.inputs.vfs_force_lo
        with np.errstate(invalid="ignore"):
            bounded = (np.isnan(v) | ((v >= vlo) & (v <= hi))).all(axis=1) & (
                np.isnan(tot) | ((tot >= 2 * lo) & (tot <= 2 * hi))).all(axis=1)
            implausible = ~np.isnan(x_raw) & ~((x_raw >= lo) & (x_raw <= hi))
        # the clock of the last reset at or before each sample (Continuity.after)
        idx = np.where(resets, np.arange(n), -1)
        last = np.maximum.accumulate(idx) if n else idx
        rclock = np.where(last >= 0, clock[np.maximum(last, 0)], np.nan)
        with np.errstate(invalid="ignore"):
            settling = np.isfinite(rclock) & (clock - rclock < self.continuity.settle_s - 1e-12)
        use = valid & ~settling & bounded
        v = np.where(use[:, None], v, np.nan)
        tot = np.where(use[:, None], tot, np.nan)
        cest = np.where(use[:, None], cest, np.nan)
        state = np.array(tstate, dtype=object)
        reason = np.array(reasons, dtype=object) if n else np.zeros(0, dtype=object)
        ok_t = state == "ok"
        for k in np.flatnonzero(~ok_t):
            jump = times[k][2]
            r = (f"time stamp {t_raw[k]:.6g} s: step {jump:+.6g} s" if math.isfinite(jump)
                 else "time stamp missing")
            reason[k] = r + (f"; {reason[k]}" if reason[k] else "")
        bad_in = ok_t & ~(valid & bounded)
        state[bad_in] = "input_invalid"
        for k in np.flatnonzero(bad_in & (reason == "")):
            reason[k] = ("estimator inputs missing or not finite" if not valid[k]
                         else "virtual forces outside the physical range")
        sett = ok_t & ~bad_in & ~use
        state[sett] = "settling"
        reason[sett & (reason == "")] = "virtual sensor settling after a break"
        if n:  # the streaming state after the last sample (update may continue)
            c = self.continuity
            c._started = True
            c._prev_invalid = not bool(valid[-1])
            c._reset_clock = float(rclock[-1])
        return _PreparedFrame(clock, x, v, tot, cref, cest, implausible, state, reason)

    def _finish_frame(self, cols: dict[str, Any], prep: _PreparedFrame) -> dict[str, Any]:
        """:meth:`_finish` over the whole log (kinds of out-of-range readings, recovered
        force within range, system state)."""
        n = len(prep.clock)
        for i in range(len(SENSOR_NAMES)):
            fc = _FLAG_COLS[i]
            flagged = (np.asarray(cols[fc], dtype=bool) if fc in cols
                       else np.zeros(n, dtype=bool))
            imp = prep.implausible[:, i]
            # spike latch: set by an implausible reading, kept while flagged
            known = imp | ~flagged
            idx = np.where(known, np.arange(n), -1)
            last = np.maximum.accumulate(idx) if n else idx
            spike = np.where(last >= 0, imp[np.maximum(last, 0)], False)
            kc = _KIND_COLS[i]
            if kc in cols and (spike & flagged).any():
                kinds = np.asarray(cols[kc], dtype=object).copy()
                kinds[spike & flagged] = "spikes"
                cols[kc] = kinds
            self._spike[i] = bool(spike[-1]) if n else False
            rc = _REC_COLS[i]
            if rc in cols:
                cols[rc] = np.clip(np.asarray(cols[rc], dtype=float), self.inputs.force_lo,
                                   self.inputs.force_hi)
        cols["system_state"] = prep.state
        cols["system_reason"] = prep.reason
        return cols

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
