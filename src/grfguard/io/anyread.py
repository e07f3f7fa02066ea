"""One entry point for every input grfguard reads: a ROS bag (with a topics map) or a
Parquet/CSV log."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from grfguard.errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["read_any", "is_bag"]

def is_bag(path: str | Path) -> bool:
    """True for a ROS bag: a rosbag2 directory, ``*.mcap``, ``*.db3`` or a ROS 1 ``*.bag``
    (decided here, without importing the bag reader: about 30 ms of every start-up)."""
    p = Path(path)
    if p.is_dir():
        return (p / "metadata.yaml").exists() or any(
            q.suffix in (".mcap", ".db3") for q in p.iterdir()
        )
    return p.suffix.lower() in (".mcap", ".db3", ".bag")


def read_any(
    path: str | Path, topics_map: str | Path | None = None, time_order: str = "strict",
    copy: bool = True, columns: list[str] | None = None, frame: bool = True,
) -> pd.DataFrame:
    """The log in ``path``: a ROS bag (rosbag2 directory, ``.mcap``, ``.db3``, ROS 1
    ``.bag``) imported with ``topics_map`` (default: the example map), else a Parquet/CSV
    log read with :func:`grfguard.io.logio.load_log` (``time_order``, ``copy``,
    ``columns`` and ``frame`` as there; a bag is a DataFrame).

    Raises:
        ConfigError: A topics map was given for a file that is not a bag.
        LogFormatError: The input cannot be read (the message says why).
    """
    p = Path(path)
    if p.exists() and is_bag(p):
        import warnings

        from grfguard.io.logio import validate_log
        from grfguard.io.rosbag import read_bag
        from grfguard.io.schema import REQUIRED_INPUT_COLUMNS

        with warnings.catch_warnings():
            warnings.simplefilter("always")
            df = read_bag(p, topics_map)
        validate_log(df, required=REQUIRED_INPUT_COLUMNS, where=str(p))
        return df
    if topics_map is not None:
        raise ConfigError(
            f"--map is for ROS bags, but {p} is not one (a rosbag2 directory, .mcap, .db3 "
            "or .bag); drop --map to read a Parquet/CSV log"
        )
    from grfguard.io.logio import load_log

    return load_log(p, time_order=time_order, copy=copy, columns=columns, frame=frame)
