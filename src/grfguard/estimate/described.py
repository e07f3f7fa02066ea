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

from typing import Any

import pandas as pd

from grfguard.errors import LogFormatError
from grfguard.model.description import SIDES

__all__ = ["described_robot", "with_described_vfs"]


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

    rob = described_robot(df, robot)
    est = estimate_wrenches(df, rob, **kwargs)
    cols = wrench_columns(est)
    out = df.copy()
    for c in cols.columns:
        out[c] = cols[c].to_numpy()
    if est.contact is not None:
        for i, s in enumerate(SIDES):
            out[f"contact_est_{s}"] = est.contact[:, i].astype(float)
    out.attrs = dict(df.attrs)
    return out
