"""One entry point for every input grfguard reads: a ROS bag (with a topics map) or a
Parquet/CSV log."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from grfguard.errors import ConfigError

__all__ = ["read_any"]

#: File suffixes of ROS bags (:func:`grfguard.io.rosbag.is_bag`; a rosbag2 directory too).
_BAG_SUFFIXES = (".mcap", ".db3", ".bag")


def _is_bag(p: Path) -> bool:
    from grfguard.io.rosbag import is_bag  # the bag reader only for bags (30 ms import)

    return is_bag(p)


def read_any(
    path: str | Path, topics_map: str | Path | None = None, time_order: str = "strict",
    copy: bool = True,
) -> pd.DataFrame:
    """The log in ``path``: a ROS bag (rosbag2 directory, ``.mcap``, ``.db3``, ROS 1
    ``.bag``) imported with ``topics_map`` (default: the example map), else a Parquet/CSV
    log read with :func:`grfguard.io.logio.load_log` (``time_order`` and ``copy`` as
    there).

    Raises:
        ConfigError: A topics map was given for a file that is not a bag.
        LogFormatError: The input cannot be read (the message says why).
    """
    p = Path(path)
    if p.exists() and (p.is_dir() or p.suffix.lower() in _BAG_SUFFIXES) and _is_bag(p):
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

    return load_log(p, time_order=time_order, copy=copy)
