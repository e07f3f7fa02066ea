"""The virtual force sensor (VFS): corner forces from IMU, encoders and the robot model.

Pipeline (DESIGN.md, "Pipeline"), one compiled step per sample
(:func:`grfguard.kernels.vfs.vfs_step`, the non-default settings' stages in
:mod:`grfguard.kernels.vfs_paper`):

1. attitude: gyro integration pulled toward the logged IMU quaternion (its 1 mrad jitter
   would become fake accelerations);
2. kinematics (:mod:`grfguard.kernels.fk` over :class:`grfguard.estimate.kinematic.KinematicModel`):
   whole-body CoM, body poses, corner points relative to the trunk, from the encoders and
   that attitude;
3. leg odometry: trunk position in world, anchored on a flat stance foot (optionally with
   the anchored sole's attitude, ``anchor_attitude_time_constant``);
4. momentum: ``multibody`` (default, sensor-free): CoM acceleration = accelerometer
   (above 1 Hz) + odometry (below) + kinematic CoM motion relative to the IMU (15 Hz
   Butterworth), centroidal angular-momentum rate by finite differences (15 Hz), ZMP by
   Newton-Euler (or a pendulum Kalman filter, ``zmp_filter="kalman"``); or the paper's
   LIPM Kalman filter (``com_method="paper"``, reads the force sensors through the
   measured ZMP);
5. split: contact per corner from the kinematic heights, one QP over all corners in
   contact with the total force, the ZMP and a sole-compliance prior (``qp``, default;
   ``contact_stiffness_per_kg = 0``: the rigid QP), or the paper's alpha rule and
   eq. 10-12 (``paper``, per-foot QPs by the same solver).

``update`` calls the step once per sample and ``run`` loops it over the log in one
compiled call, so streaming and batch are identical by construction. A sample with a
non-finite input is skipped (the state does not move), the last output is held and
``vfs_valid`` is 0. The numpy implementation of every stage, the reference the kernel is
tested against to 1e-9 N, is ``tests/reference/vfs_stages.py`` (not shipped).

Outputs: ``vfs_<s>`` for r1..r4, l1..l4 [N], ``com_est_x/y/z`` [m], ``vfs_total_r/l`` [N],
``vfs_cop_r_x/y``, ``vfs_cop_l_x/y`` [m, world; NaN when the foot carries < 1 N],
``contact_est_r/l`` (0/1), ``zmp_est_x/y`` [m], ``vfs_valid`` (0/1).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from grfguard._lazy import lazy_module
from grfguard.errors import ConfigError, LogFormatError
from grfguard.estimate.config import VFSConfig
from grfguard.estimate.kinematic import KinematicModel
from grfguard.io.schema import (
    COM_EST_COLUMNS,
    FORCE_COLUMNS,
    IMU_ACC,
    IMU_QUAT,
    JOINT_COLUMNS,
    TIME,
    vfs_col,
)
from grfguard.model.robot import SENSOR_NAMES, RobotConfig

pd = lazy_module("pandas")  # (imported on first use: `grfguard run` never does)

__all__ = ["VFSConfig", "VirtualForceSensor", "VFS_OUTPUT_COLUMNS", "with_vfs_columns"]

_CORNER_COLS = tuple(vfs_col(s) for s in SENSOR_NAMES)
#: Every column :meth:`VirtualForceSensor.run` returns, in order.
VFS_OUTPUT_COLUMNS: tuple[str, ...] = (
    *_CORNER_COLS,
    *COM_EST_COLUMNS,
    "vfs_total_r",
    "vfs_total_l",
    "vfs_cop_r_x",
    "vfs_cop_r_y",
    "vfs_cop_l_x",
    "vfs_cop_l_y",
    "contact_est_r",
    "contact_est_l",
    "zmp_est_x",
    "zmp_est_y",
    "vfs_valid",
)


def _in_columns(cfg: VFSConfig) -> tuple[str, ...]:
    """Input row layout of the compiled kernel (:data:`grfguard.kernels.vfs.IN_COLUMNS`,
    with the force sensors and the planned ZMP for the paper's CoM filter)."""
    from grfguard.kernels.vfs import IN_COLUMNS, PAPER_IN_COLUMNS

    return PAPER_IN_COLUMNS if cfg.com_method == "paper" else IN_COLUMNS


def _robot_from_attrs(attrs: Mapping[str, Any]) -> RobotConfig:
    r = attrs.get("robot") if attrs else None
    if r is None:
        raise LogFormatError(
            "the log names no robot (log.attrs['robot'] is missing): the virtual force "
            "sensor needs the robot's description (mass, geometry, sensor layout) and "
            "never guesses it; set log.attrs['robot'] = RobotConfig(...).to_dict() "
            "(logs written by grfguard carry it in their metadata), build "
            "VirtualForceSensor(robot, config) directly, or on the command line pass "
            "--robot ROBOT.toml or --robot NAME"
        )
    if isinstance(r, RobotConfig):
        return r
    if isinstance(r, str):
        import json

        try:
            r = json.loads(r)
        except ValueError as exc:
            raise LogFormatError(
                f"log.attrs['robot'] is not a JSON robot description: {exc}"
            ) from exc
    return RobotConfig.from_dict(dict(r))


class VirtualForceSensor:
    """Virtual foot force sensor, streaming (``update``, ``update_array``) and batch (``run``).

    Args:
        robot: Robot description (required; :meth:`for_log` reads it from a log).
        config: Settings (default :class:`VFSConfig`).
        kinematics: Optional prebuilt :class:`KinematicModel` (shares the MuJoCo model).
        compiled: Must be True (the former ``False``, the pure-Python stages, is the test
            reference ``tests/reference/vfs_stages.py``).

    Raises:
        ConfigError: ``compiled=False``, or no ``robot``.

    Example:
        >>> vfs = VirtualForceSensor.for_log(log)
        >>> out = vfs.run(log)          # DataFrame with vfs_r1 ... vfs_l4
        >>> vfs.reset(); row_out = vfs.update(log.iloc[0].to_dict())
        >>> y = vfs.update_array(x)     # x in kernels.vfs.IN_COLUMNS order
    """

    def __init__(
        self,
        robot: RobotConfig | None = None,
        config: VFSConfig | None = None,
        kinematics: KinematicModel | None = None,
        compiled: bool = True,
    ) -> None:
        if not compiled:
            raise ConfigError(
                "VirtualForceSensor(compiled=False) was removed: every setting runs the "
                "compiled kernel (grfguard.kernels.vfs); the pure-Python stages are the test "
                "reference tests/reference/vfs_stages.py (PythonVFS). For the pure-Python "
                "detector use Monitor(..., compiled=False)."
            )
        if robot is None:
            raise ConfigError(
                "VirtualForceSensor: no robot (robot=None): the virtual sensor needs the "
                "robot's description (mass, geometry, sensor layout) and never guesses it; "
                "pass a RobotConfig (e.g. grfguard.model.robot.load_robot('ROBOT.toml'), "
                "or grfguard.SURALP) or use VirtualForceSensor.for_log(log) (the log's "
                "robot)")
        self.robot = robot
        self.config = config if config is not None else VFSConfig()
        self.kin = kinematics if kinematics is not None else KinematicModel(self.robot)
        self.mass = self.kin.mass
        self.g = self.robot.gravity
        self.points_F = self.robot.sensor_positions_in_foot()
        #: Corner contact stiffness of the compliance prior [N/m] (0: rigid QP).
        self.contact_stiffness = self.config.contact_stiffness_per_kg * self.mass
        #: Always True: the compiled kernel runs every setting.
        self.compiled = True
        self._kern: dict[tuple[bool, bool], Any] = {}
        self._in_cols = _in_columns(self.config)
        self._x = np.empty(len(self._in_cols))
        self._y = np.empty(len(VFS_OUTPUT_COLUMNS))
        self.reset()

    # ------------------------------------------------------------------ construction
    @classmethod
    def for_log(
        cls, log: pd.DataFrame, config: VFSConfig | None = None, compiled: bool = True,
        warm: bool = True,
    ) -> VirtualForceSensor:
        """A sensor for ``log``: robot from ``log.attrs["robot"]``, the sampling period
        from the ``time`` column. ``warm``: its streaming step built and its machine code
        loaded here, so the first :meth:`update` takes microseconds like the others (built
        at that call, it took 1.4-2.8 ms, with the code's first load in a process about 50 ms
        more); ``warm=False`` leaves both to the first call (a batch :meth:`run` needs
        neither).

        Raises:
            LogFormatError: If the log's metadata names no robot (``attrs["robot"]``
                missing) or does not describe one.
        """
        robot = _robot_from_attrs(getattr(log, "attrs", {}) or {})
        cfg = config if config is not None else VFSConfig()
        if TIME in log.columns and len(log) > 1:
            dt = float(np.median(np.diff(log[TIME].to_numpy(float))))
            if np.isfinite(dt) and dt > 0 and abs(dt - cfg.dt) > 1e-9 * cfg.dt:
                cfg = cfg.replace(dt=dt)
        vfs = cls(robot, cfg, compiled=compiled)
        return vfs.prepare() if warm else vfs

    def prepare(self) -> VirtualForceSensor:
        """Build the streaming step now and load its machine code, so that the first
        :meth:`update` or :meth:`update_array` takes microseconds like the others; returns
        the sensor. :meth:`for_log` does this; a sensor built directly builds it at its
        first sample instead (1.4-2.8 ms). The state is untouched."""
        self.kernel().prepare()
        return self

    def kernel(self, has_gyro: bool = True, has_ref: bool = True) -> Any:
        """The compiled kernel (:class:`grfguard.kernels.vfs.VFSKernel`) for inputs with /
        without the gyro and the planned contact (built once, kept)."""
        key = (has_gyro, has_ref)
        if key not in self._kern:
            from grfguard.kernels.vfs import VFSKernel  # (here: an import costs ~1 us/call)

            self._kern[key] = VFSKernel(self, has_gyro=has_gyro, has_ref=has_ref)
        return self._kern[key]

    def reset(self) -> None:
        """Forget all state (odometry anchor, filters, previous samples)."""
        for k in self._kern.values():
            k.reset()

    # ------------------------------------------------------------------ inputs
    def check_columns(self, cols: Any) -> None:
        """Raise :class:`LogFormatError` if a column this sensor reads is missing."""
        need = [*IMU_QUAT, *JOINT_COLUMNS]
        if self.config.com_method == "paper":
            need += [*IMU_ACC, *FORCE_COLUMNS]
        elif self.config.use_accelerometer:
            need += [*IMU_ACC]
        missing = [c for c in need if c not in cols]
        if missing:
            raise LogFormatError(
                f"the virtual force sensor needs column(s) {missing}; see the log contract "
                "in grfguard.io.schema (com_method='paper' also needs imu_acc_* and force_*)"
            )

    # ------------------------------------------------------------------ streaming
    def update(self, row: Mapping[str, float]) -> dict[str, float]:
        """Process one sample (the compiled step of :meth:`run`).

        Args:
            row: Mapping with the log-contract columns of one sample.

        Returns:
            Dict of :data:`VFS_OUTPUT_COLUMNS` (floats). A sample with a missing or
            non-finite input is skipped: the last output is returned with
            ``vfs_valid = 0`` (NaN before the first valid sample).
        """
        x = self._x
        for i, c in enumerate(self._in_cols):
            try:
                x[i] = float(row[c])
            except (KeyError, TypeError, ValueError, OverflowError):
                x[i] = np.nan
        y = self.kernel().step(x, self._y)
        return dict(zip(VFS_OUTPUT_COLUMNS, y.tolist(), strict=True))

    def update_array(self, x: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        """One sample as arrays: ``x`` (24,) in :data:`grfguard.kernels.vfs.IN_COLUMNS`
        order (34, :data:`~grfguard.kernels.vfs.PAPER_IN_COLUMNS`, for the paper's CoM
        filter) -> (22,) in :data:`VFS_OUTPUT_COLUMNS` order (written into ``y`` when
        given). Never raises on a bad sample (non-finite input: last output held,
        ``vfs_valid = 0``).

        Raises:
            LogFormatError: ``x`` or ``y`` has the wrong shape.
        """
        return self.kernel().step(x, np.empty(len(VFS_OUTPUT_COLUMNS)) if y is None else y)

    # ------------------------------------------------------------------ batch
    def run(self, log: pd.DataFrame) -> pd.DataFrame:
        """Reset, then process the whole log (the step looped in one compiled call).

        Args:
            log: Log-contract DataFrame.

        Returns:
            DataFrame with :data:`VFS_OUTPUT_COLUMNS`, same index as ``log``.
        """
        self.reset()
        self.check_columns(log.columns)
        return self._run_compiled(log, None)

    def _run_compiled(self, log: pd.DataFrame, resync: np.ndarray | None) -> pd.DataFrame:
        """The compiled batch: the kernel's step looped over the log in one call."""
        from grfguard.kernels.vfs import log_to_array

        X, has_gyro, has_ref = log_to_array(log, self._in_cols)
        k = self.kernel(has_gyro, has_ref)
        if resync is None:
            Y = k.run(X)
        else:
            Y = k.run_segments(X, np.flatnonzero(np.asarray(resync, bool)))
        return pd.DataFrame(Y, index=log.index, columns=list(VFS_OUTPUT_COLUMNS))

    def input_valid(self, log: pd.DataFrame) -> np.ndarray:
        """(T,) bool: rows whose inputs the sensor can use: joints, quaternion (non-zero),
        and the gyro, planned contact, accelerometer and force sensors when read, finite
        (the planned ZMP is optional)."""
        from grfguard.kernels.vfs import log_to_array

        X, has_gyro, has_ref = log_to_array(log, self._in_cols)
        c = self.config
        paper = c.com_method == "paper"
        use = [*range(16), *(range(16, 19) if has_gyro else ()),
               *(range(19, 22) if paper or c.use_accelerometer else ()),
               *(range(22, 24) if has_ref else ()), *(range(24, 32) if paper else ())]
        ok = np.isfinite(X[:, use]).all(axis=1)
        return ok & (np.linalg.norm(np.nan_to_num(X[:, 12:16]), axis=1) >= 1e-6)

    def resync(self) -> None:
        """Forget the finite-difference history only (a continuity break): the next two
        samples have no rate; filters, attitude and odometry keep their state."""
        for k in self._kern.values():
            k.resync()

    def run_resynced(self, log: pd.DataFrame, resync: np.ndarray) -> pd.DataFrame:
        """:meth:`run` with :meth:`resync` before every row where ``resync`` is True (the
        batch twin of a streaming monitor resyncing at breaks); the sensor is reset after.
        """
        self.reset()
        self.check_columns(log.columns)
        out = self._run_compiled(log, resync)
        self.reset()
        return out


def with_vfs_columns(log: pd.DataFrame, config: VFSConfig | None = None) -> pd.DataFrame:
    """``log`` plus the virtual sensor's output columns (metadata kept).

    ``Monitor.for_log`` (:mod:`grfguard.detect`) reuses ``vfs_*`` and ``vfs_total_*``
    columns when the log has them, whatever its ``config.vfs`` says: compute them with the
    virtual sensor the monitor is meant to use. Reusing them for several fault scenarios
    injected into one walk is valid only for a virtual sensor that does not read the force
    sensors (the default; ``com_method="paper"`` reads them, so its columns belong to the
    log they were computed on).

    Args:
        log: A log of the contract.
        config: Virtual sensor settings (default :class:`VFSConfig`).

    Returns:
        A new DataFrame; existing columns of the same name are replaced.
    """
    out = log.copy()
    out.attrs = dict(log.attrs)
    vfs = VirtualForceSensor.for_log(log, config, warm=False).run(log)
    for c in vfs.columns:
        out[c] = vfs[c].to_numpy()
    return out
