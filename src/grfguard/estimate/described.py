"""The monitor's virtual-sensor columns for a described robot (Talos, G1, a user TOML).

:class:`~grfguard.pipeline.Monitor` reuses a log's precomputed ``vfs_<s>``,
``vfs_total_<side>`` and ``contact_est_<side>`` columns. For a robot described by its
model file and TOML (:mod:`grfguard.model.description`) they come from the batch
virtual sensor :func:`~grfguard.estimate.wrench.estimate_wrenches`:

- ``vfs_<r|l><1..4>``: the corner cells' estimated forces [N] (corner-cell robots);
- ``vfs_<r|l>_<fx..tz>``: the ankle F/T channels' estimates [N, N m] (F/T robots);
- ``vfs_total_<r|l>``: each foot's vertical ground force [N];
- ``contact_est_<r|l>``: the feet taken as in stance (0/1).

Example:
    >>> from grfguard.estimate.described import with_described_vfs
    >>> out = Monitor.for_log(with_described_vfs(log)).run(...)   # G1 log
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

from grfguard._lazy import lazy_module
from grfguard.errors import LogFormatError
from grfguard.model.description import SIDES

pd = lazy_module("pandas")  # (imported on first use: `grfguard run` never does)

#: Standard gravity [m/s^2].
_G = 9.81

__all__ = [
    "described_robot",
    "calibration_frames",
    "described_thresholds",
    "ft_channel_calibration",
    "is_described",
    "log_robot",
    "monitor_robot",
    "names_robot",
    "run_described",
    "with_described_vfs",
]


def described_robot(df: pd.DataFrame, robot: Any = None) -> Any:
    """The :class:`~grfguard.model.loader.LoadedRobot` of ``df``.

    Args:
        df: A log of a described robot.
        robot: A ``LoadedRobot``, a shipped name (``talos``, ``g1``) or a TOML path; None
            takes ``robot_name`` from the log's metadata.

    Raises:
        LogFormatError: Neither ``robot`` nor the metadata names a robot.
    """
    from grfguard.model.description import load_description
    from grfguard.model.loader import LoadedRobot, load_model

    if isinstance(robot, LoadedRobot):
        return robot
    name = robot if robot is not None else df.attrs.get("robot_name")
    if name is None:
        raise LogFormatError(
            "the log's metadata names no described robot (attrs['robot_name']); pass "
            "robot='g1', 'talos' or a robot TOML")
    return load_model(load_description(name))


def monitor_robot(df: pd.DataFrame, robot: Any = None) -> Any:
    """The :class:`~grfguard.model.robot.RobotConfig` whose weight and corner layout the
    corner-cell monitor's input guards, common-mode fit, swing-zero learner and standing
    layer use for a described robot: the robot's own total mass (the loaded model's; a
    simulated log's ``attrs["mass"]`` saves loading it) and its sole rectangle and corner
    cells. Only the weight and the corner layout of the result are meant (the leg
    fields keep their defaults and are not used by those stages).

    Args:
        df: A log of a described corner-cell robot.
        robot: As in :func:`described_robot`.

    Raises:
        LogFormatError: No robot is named, or the two soles differ (the monitor takes one
            corner layout for both feet).
    """
    import math

    from grfguard.model.description import load_description
    from grfguard.model.loader import LoadedRobot
    from grfguard.model.robot import RobotConfig

    if isinstance(robot, LoadedRobot):
        desc, mass = robot.description, robot.mass
    else:
        try:
            m = float(df.attrs.get("mass"))  # written by the whole-body simulation
        except (TypeError, ValueError):
            m = math.nan
        name = robot if robot is not None else df.attrs.get("robot_name")
        if robot is None and name is not None and math.isfinite(m) and m > 0:
            desc, mass = load_description(name), m
        else:
            rob = described_robot(df, robot)
            desc, mass = rob.description, rob.mass
    fr, fl = desc.feet
    _check_one_sole(desc.name, *[(f.length, f.width, f.corner_inset) for f in (fr, fl)])
    return RobotConfig(name=desc.name, mass=float(mass), foot_length=fr.length,
                       foot_width=fr.width, sensor_inset=fr.corner_inset)


def _check_one_sole(name: Any, right: tuple, left: tuple) -> None:
    """Raise when the two soles (length, width, corner_inset) differ: the corner-cell
    monitor takes one corner layout for both feet."""
    if right != left:
        raise LogFormatError(
            f"robot {name!r}: the corner-cell monitor takes one sole for both feet; "
            f"feet.r and feet.l differ (length, width, corner_inset = {right} vs "
            f"{left}); give both feet the same sole in the robot TOML")


def names_robot(df: pd.DataFrame) -> bool:
    """True when ``df``'s metadata names a robot at all (``attrs["robot"]`` or
    ``attrs["robot_name"]``), whether or not it can be read."""
    attrs = getattr(df, "attrs", {}) or {}
    return attrs.get("robot") is not None or isinstance(attrs.get("robot_name"), str)


def log_robot(df: pd.DataFrame, robot: Any = None, where: str = "the log") -> Any:
    """The robot of a log as a :class:`~grfguard.model.robot.RobotConfig`: the one
    resolver of :meth:`grfguard.pipeline.Monitor.for_log`,
    :func:`grfguard.calib.robot_of` and the system-aware monitor. Never a stand-in.

    In order: ``robot`` when it is a ``RobotConfig``; a described robot (``robot`` a
    ``LoadedRobot``, shipped name or TOML path, or a log whose metadata names one:
    ``robot_name``, or ``attrs["robot"]`` holding a name) through
    :func:`monitor_robot` (its own mass and sole; the leg fields are not meant); a
    described robot's dict in ``attrs["robot"]`` (its sole and mass); the log's
    ``RobotConfig`` parameters (``attrs["robot"]``, a dict or JSON).

    Args:
        df: A log.
        robot: None (the log's metadata), a ``RobotConfig``, or a described robot.
        where: Who asks (named in the error).

    Raises:
        LogFormatError: The log names no robot (how to give one in the message), or its
            ``attrs["robot"]`` is not a robot description.
    """
    from collections.abc import Mapping

    from grfguard.estimate.vfs import _robot_from_attrs
    from grfguard.model.robot import RobotConfig

    if isinstance(robot, RobotConfig):
        return robot
    attrs = getattr(df, "attrs", {}) or {}
    named = attrs.get("robot")
    if robot is not None or is_described(df) or isinstance(attrs.get("robot_name"), str):
        return monitor_robot(df, robot)
    if isinstance(named, str) and not named.lstrip().startswith("{"):  # a robot's name
        return monitor_robot(df, named)
    if isinstance(named, Mapping) and isinstance(named.get("feet"), Mapping):
        return _robot_of_description_dict(df, named)
    if named is None:
        raise LogFormatError(
            f"{where}: the log names no robot (no robot metadata: log.attrs['robot'] and "
            "attrs['robot_name'] are missing), and grfguard never guesses it (the robot's "
            "weight and sole set the guards, the fits and the virtual sensor). Logs written "
            "by grfguard simulate / import carry it; otherwise pass robot=... (e.g. "
            "grfguard.model.robot.load_robot('ROBOT.toml'), or 'g1', 'talos'), set "
            "log.attrs['robot'] = RobotConfig(...).to_dict() (or attrs['robot_name'] = "
            "'g1'), or on the command line pass --robot ROBOT.toml or --robot NAME")
    return _robot_from_attrs(attrs)


def _robot_of_description_dict(df: pd.DataFrame, d: Any) -> Any:
    """The monitor's ``RobotConfig`` from a described robot's dict
    (:meth:`~grfguard.model.description.RobotDescription.to_dict`) in ``attrs["robot"]``
    without ``robot_name``: its right sole and its mass (the dict's, the log's
    ``attrs["mass"]``, else the named robot's model)."""
    import math

    from grfguard.model.robot import RobotConfig

    mass = math.nan
    for m in (d.get("mass"), df.attrs.get("mass")):
        try:
            mass = float(m)
        except (TypeError, ValueError):
            continue
        if math.isfinite(mass) and mass > 0:
            break
        mass = math.nan
    soles = []
    for side in ("r", "l"):
        foot = d["feet"].get(side)
        try:
            soles.append(
                (float(foot["length"]), float(foot["width"]), float(foot["corner_inset"])))
        except (KeyError, TypeError, ValueError):
            soles.append(None)
    sole = soles[0]
    if sole is not None and soles[1] is not None:
        _check_one_sole(d.get("name", "robot"), sole, soles[1])
    if sole is None or not math.isfinite(mass):
        if isinstance(d.get("name"), str):
            return monitor_robot(df, d["name"])
        raise LogFormatError(
            "log.attrs['robot'] is a described robot's dict without a usable mass and "
            f"right sole (feet.r length, width, corner_inset): {d!r:.120}; set "
            "attrs['robot_name'] (e.g. 'g1') or pass robot=...")
    return RobotConfig(name=str(d.get("name", "robot")), mass=mass, foot_length=sole[0],
                       foot_width=sole[1], sensor_inset=sole[2])


def with_described_vfs(df: pd.DataFrame, robot: Any = None, **kwargs: Any) -> pd.DataFrame:
    """``df`` plus the virtual-sensor columns the monitor reads (module docstring).

    Args:
        df: A log of a described robot (``time``, IMU, ``q_<joint>`` of every joint).
        robot: As in :func:`described_robot`.
        **kwargs: Options of :func:`~grfguard.estimate.wrench.estimate_wrenches`.

    Returns:
        A copy of ``df`` (same ``attrs``) with the added columns.

    Raises:
        LogFormatError: A joint column is missing, or the robot is not named.
    """
    from grfguard.estimate.wrench import estimate_wrenches, wrench_columns
    from grfguard.io.logio import without_attrs

    rob = described_robot(df, robot)
    est = estimate_wrenches(df, rob, **kwargs)
    cols = wrench_columns(est)
    if est.contact is not None:
        for i, s in enumerate(SIDES):
            cols[f"contact_est_{s}"] = est.contact[:, i].astype(float)
    bare = without_attrs(df)  # pandas would deep-copy the metadata in every step below
    if df.index.is_unique and not any(c in df.columns for c in cols.columns):
        cols.index = df.index
        out = pd.concat([bare, cols], axis=1)  # one step (column by column: 10x slower)
    else:  # replaces the columns the log already has, in place
        out = bare.copy()
        for c in cols.columns:
            out[c] = cols[c].to_numpy()
    out.attrs = dict(df.attrs)
    return out


def described_thresholds(name: str) -> Any:
    """The shipped detector thresholds of robot ``name`` (``grfguard/data/<name>_thresholds
    .toml``, made by ``benchmarks/calibrate_described_thresholds.py`` from fault-free walks
    of that robot), or None when none are shipped."""
    from grfguard.detect.thresholds import Thresholds

    f = resources.files("grfguard") / "data" / f"{name}_thresholds.toml"
    if not f.is_file():
        return None
    return Thresholds.from_toml_text(f.read_text())


def is_described(df: pd.DataFrame) -> bool:
    """True when ``df``'s metadata names a described robot (``robot_name`` and
    ``sensing``; written by the whole-body simulation and by ``grfguard run --robot``)."""
    return "robot_name" in df.attrs and "sensing" in df.attrs


def run_described(df: pd.DataFrame, config: Any = None, robot: Any = None,
                  channels: Any = None, track: bool = True) -> pd.DataFrame:
    """The monitor over a log of a described robot.

    Ankle F/T sensors: :class:`~grfguard.detect.channels.ChannelMonitor` with
    ``channels`` (a :class:`~grfguard.detect.channels.ChannelConfig` or the path of a
    channel TOML written by ``grfguard calibrate``), else the robot's shipped channel
    thresholds (``grfguard/data/<name>_channels.toml``), on the virtual channels
    (``config`` is not used).

    Corner cells: :func:`with_described_vfs` (unless the log already has the columns),
    then :class:`~grfguard.pipeline.Monitor` on its precomputed-columns path, with the
    robot's shipped thresholds (:func:`described_thresholds`) when ``config`` carries
    the built-in defaults; then, unless ``track`` is False, the recovered force
    of a cell flagged offset, drift or gain is tracked against the cell noise
    (``sigma_swing_n`` of the thresholds) by :func:`grfguard.recover.track
    .track_recovered`, a better estimate of the true force than ``reading - offset``.

    Args:
        df: The log.
        config: A :class:`~grfguard.detect.config.MonitorConfig` (default thresholds
            when None).
        robot: As in :func:`described_robot`.
        channels: F/T robots only: the channel thresholds (default: the shipped ones).
        track: Corner cells only: track the recovered forces (default True).

    The arrays are allocated without numpy's huge-page hint
    (:func:`grfguard._memory.small_pages`, as ``Monitor.run``'s outputs): the first run
    in a process on a 60 s Talos log took 0.107-0.241 s with it (median 0.141) and
    0.119-0.136 s without (median 0.121; five alternated fresh processes each, a host
    whose fresh huge pages are slow to touch).

    Raises:
        LogFormatError: The robot's sensing is not supported by the monitor.
        ConfigError: ``channels`` is not a channel thresholds TOML.
    """
    from grfguard._memory import small_pages

    with small_pages():
        return _run_described(df, config, robot, channels, track)


def _run_described(df: pd.DataFrame, config: Any, robot: Any, channels: Any,
                   track: bool) -> pd.DataFrame:
    """:func:`run_described`'s work."""
    from grfguard.detect.config import MonitorConfig
    from grfguard.detect.detector import VFS_TOTAL_COLUMNS
    from grfguard.detect.monitor import Monitor
    from grfguard.detect.thresholds import default_thresholds
    from grfguard.io.schema import vfs_col
    from grfguard.model.robot import SENSOR_NAMES

    cfg = config if config is not None else MonitorConfig()
    name = df.attrs.get("robot_name")
    own = described_thresholds(str(name)) if isinstance(name, str) else None
    if own is not None and cfg.thresholds == default_thresholds():
        cfg = cfg.with_thresholds(own)
    sensing = df.attrs.get("sensing")
    if sensing == "corners":
        need = [vfs_col(s) for s in SENSOR_NAMES] + list(VFS_TOTAL_COLUMNS)
        rob = None
        if not all(c in df.columns for c in need):
            rob = described_robot(df, robot)
            df = with_described_vfs(df, rob)
        out = Monitor.for_log(df, cfg, robot=robot if rob is None else rob).run(df)
        if not track:
            return out
        from grfguard.recover.track import track_recovered

        weight = _weight_n(df, robot if rob is None else rob)
        if not weight > 0:  # NaN: no robot and no virtual force to weigh it by
            return out
        return track_recovered(out, weight_n=weight, sensors=SENSOR_NAMES,
                               noise_n=cfg.thresholds.sigma_swing_n)
    if sensing == "ft":
        from grfguard.detect.channels import ChannelConfig, ChannelMonitor

        if isinstance(channels, ChannelConfig):
            ccfg = channels
        else:
            f = (Path(channels) if channels is not None
                 else resources.files("grfguard") / "data" / f"{name}_channels.toml")
            if not f.is_file():
                raise LogFormatError(
                    f"no channel thresholds {'file ' + str(f) if channels else 'shipped'} "
                    f"for F/T robot {name!r}; make them with `grfguard calibrate "
                    "<fault-free logs> -o channels.toml` and pass --thresholds channels.toml")
            ccfg = ChannelConfig.from_toml_text(f.read_text(), str(f))
        if not all(f"vfs_{c[3:]}" in df for c in df.columns if c.startswith("ft_")):
            df = with_described_vfs(df, robot)
        return ChannelMonitor(ccfg).run(df)
    raise LogFormatError(
        f"the monitor does not watch {sensing!r} sensing (robot {name!r}); 'corners' and "
        "'ft' are supported")


def _weight_n(df: pd.DataFrame, robot: Any) -> float:
    """The robot's weight m g [N]; when the log names no robot (it carries precomputed
    virtual-sensor columns), the mean of the virtual feet's vertical forces."""
    import numpy as np

    from grfguard.detect.detector import VFS_TOTAL_COLUMNS

    try:
        return float(described_robot(df, robot).mass) * _G
    except LogFormatError:
        tot = sum(df[c].to_numpy(dtype=float) for c in VFS_TOTAL_COLUMNS)
        return float(np.nanmean(tot))


def ft_channel_calibration(frames: list[pd.DataFrame],
                           false_alarm_rate_per_hour: float = 0.1) -> str | None:
    """``grfguard calibrate`` on logs of an ankle F/T robot: the channel thresholds TOML
    (:func:`~grfguard.detect.channels.calibrate_channels` on the virtual channels), or
    None when the logs are not of an F/T robot.

    Raises:
        LogFormatError: F/T logs mixed with others, or of different robots.
    """
    ft = [is_described(f) and f.attrs.get("sensing") == "ft" for f in frames]
    if not any(ft):
        return None
    names = sorted({str(f.attrs.get("robot_name")) for f in frames})
    if not all(ft) or len(names) > 1:
        raise LogFormatError(f"calibrate: give logs of one ankle F/T robot only, got robots "
                             f"{names} (F/T: {ft})")
    from grfguard.detect.channels import calibrate_channels

    logs = [f if all(f"vfs_{c[3:]}" in f for c in f.columns if c.startswith("ft_"))
            else with_described_vfs(f) for f in frames]
    cc = calibrate_channels(logs, false_alarm_rate_per_hour)
    return f"# grfguard calibrate: channel thresholds of {names[0]!r}\n" + cc.to_toml()


def calibration_frames(frames: list[pd.DataFrame]) -> list[pd.DataFrame]:
    """Logs for :func:`~grfguard.detect.calibrate.calibrate_thresholds`: a described
    corner-cell robot's logs get their virtual-sensor columns; others pass unchanged.

    Raises:
        LogFormatError: A log of an ankle F/T robot (its channels are calibrated by
            :func:`grfguard.detect.channels.calibrate_channels`).
    """
    out = []
    for f in frames:
        if is_described(f) and f.attrs.get("sensing") == "ft":
            raise LogFormatError(
                f"robot {f.attrs.get('robot_name')!r} has ankle F/T sensors: its channel "
                "thresholds come from grfguard.detect.channels.calibrate_channels (see "
                "benchmarks/calibrate_described_thresholds.py), not from the corner detector")
        out.append(with_described_vfs(f) if is_described(f) else f)
    return out
