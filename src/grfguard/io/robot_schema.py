"""Log columns of a described robot (:mod:`grfguard.model.description`).

A log of a described robot has ``time``, the IMU columns, ``q_<joint>`` for every
joint of the model and the force channels of its TOML (``force_<r|l><1..4>`` for corner
load cells, ``ft_<r|l>_<fx..tz>`` for ankle F/T sensors). Its metadata names the
robot (``robot_name``, written by :func:`grfguard.sim.wholebody.simulate_robot`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from grfguard._lazy import lazy_module
from grfguard.errors import LogFormatError
from grfguard.io.schema import IMU_ACC, IMU_GYRO, IMU_QUAT, TIME

pd = lazy_module("pandas")  # (imported when first used: not by `grfguard run`)

__all__ = ["robot_input_columns", "is_described_log", "load_robot_log"]


def robot_input_columns(robot: Any) -> tuple[str, ...]:
    """Columns a log of ``robot`` (a :class:`~grfguard.model.loader.LoadedRobot`) needs."""
    return (TIME, *IMU_ACC, *IMU_GYRO, *IMU_QUAT,
            *(f"q_{j}" for j in robot.joint_names), *robot.description.force_columns)


def is_described_log(df: pd.DataFrame) -> bool:
    """True when the metadata says the log is of a described robot (Talos, G1, ...)."""
    return "robot_name" in df.attrs and "sensing" in df.attrs


def load_robot_log(path: str | Path, robot: Any = None) -> pd.DataFrame:
    """Read a log of a described robot and check its columns against the model.

    Args:
        path: Parquet or CSV log.
        robot: A :class:`~grfguard.model.loader.LoadedRobot`, a shipped name or a TOML
            path; None takes ``robot_name`` from the log's metadata.

    Raises:
        LogFormatError: The robot is unknown, or a column is missing (named, with the
            joint or sensor it stands for).
    """
    from grfguard.io.logio import read_log, validate_log
    from grfguard.model.description import load_description
    from grfguard.model.loader import LoadedRobot, load_model

    df = read_log(path)
    if robot is None:
        robot = df.attrs.get("robot_name")
        if robot is None:
            raise LogFormatError(
                f"{path}: the metadata names no robot; pass robot='talos' (or a TOML)")
    if not isinstance(robot, LoadedRobot):
        robot = load_model(load_description(robot))
    missing = [c for c in robot_input_columns(robot) if c not in df.columns]
    if missing:
        joints = [c[2:] for c in missing if c.startswith("q_")]
        hint = (f"; joint(s) {joints} of {robot.description.model.name} have no encoder "
                "column q_<joint>") if joints else ""
        raise LogFormatError(f"{path}: missing column(s) {missing} for robot "
                             f"{robot.description.name!r}{hint}")
    validate_log(df, required=robot_input_columns(robot), where=str(path))
    df.attrs["sample_rate"] = df.attrs.get("sample_rate") or 1.0 / float(
        pd.Series(df[TIME]).diff().median())
    return df
