"""The monitor configuration named by the user-facing options (CLI, demo, benchmarks)."""

from __future__ import annotations

from pathlib import Path

from grfguard.detect import MonitorConfig
from grfguard.detect.thresholds import default_thresholds, paper_vfs_thresholds
from grfguard.errors import ConfigError
from grfguard.estimate.config import VFSConfig

__all__ = ["monitor_config"]


def monitor_config(
    config: Path | None = None,
    thresholds: Path | None = None,
    method: str | None = None,
    vfs: str | None = None,
) -> MonitorConfig:
    """The monitor configuration the command-line options describe.

    ``method="paper"`` means the paper as published: its observer and, unless ``vfs``
    or the config file says otherwise, its virtual sensor too.

    Args:
        config: Monitor/VFS config TOML.
        thresholds: Thresholds TOML (from ``grfguard calibrate``).
        method: Detection method: ``default`` or ``paper``.
        vfs: Virtual sensor: ``default`` or ``paper``.

    Raises:
        ConfigError: For an unknown ``vfs`` (or ``method``) name.
    """
    cfg = MonitorConfig.from_toml(config) if config is not None else MonitorConfig()
    if method is not None:
        cfg = cfg.with_method(method)
    if vfs is None and method == "paper" and cfg.vfs is None:
        vfs = "paper"
    if vfs == "paper":
        cfg = cfg.replace(vfs=VFSConfig.paper())
        if thresholds is None and cfg.thresholds == default_thresholds():
            # the paper's eq. 33 thresholds come from fault-free runs of its own pipeline
            cfg = cfg.with_thresholds(paper_vfs_thresholds())
    elif vfs == "default":
        cfg = cfg.replace(vfs=VFSConfig())
    elif vfs is not None:
        raise ConfigError(f"--vfs must be 'default' or 'paper', got {vfs!r}")
    if thresholds is not None:
        cfg = cfg.with_thresholds(thresholds)
    return cfg
