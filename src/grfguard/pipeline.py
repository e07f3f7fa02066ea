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
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from grfguard.detect.config import MonitorConfig, config_for_log
from grfguard.detect.detector import VFS_TOTAL_COLUMNS, Detector, DetectorInputs
from grfguard.detect.paper import PaperDetector
from grfguard.detect.tuning import DetectTuning
from grfguard.errors import LogFormatError
from grfguard.io.schema import TIME, force_col, vfs_col
from grfguard.model.robot import SENSOR_NAMES, SIDES
from grfguard.recover.recovery import RecoverTuning, Recovery

__all__ = ["Monitor"]

_NAN = float("nan")


def _f(row: Mapping[str, Any], key: str) -> float:
    """``row[key]`` as a float; NaN when missing or not a number."""
    try:
        return float(row[key])
    except (KeyError, TypeError, ValueError):
        return _NAN


class Monitor:
    """Virtual force sensor + fault detection, isolation, classification and recovery.

    Args:
        config: Settings (method, thresholds, gates).
        vfs: A ``VirtualForceSensor`` for the robot, or None when every input row already
            carries the VFS outputs (``vfs_<s>``, ``vfs_total_<side>``).
        detect_tuning: Design constants of the default detector.
        recover_tuning: Design constants of the recovery.

    Example:
        >>> mon = Monitor.for_log(log)
        >>> out = mon.run(log)                  # log + vfs_*, flag_*, kind_*, eta_*, ...
        >>> mon.reset(); row_out = mon.update(log.iloc[0].to_dict())
    """

    def __init__(
        self,
        config: MonitorConfig | None = None,
        vfs: Any = None,
        detect_tuning: DetectTuning | None = None,
        recover_tuning: RecoverTuning | None = None,
    ) -> None:
        self.config = config if config is not None else MonitorConfig()
        self.vfs = vfs
        self.detector = Detector(self.config, detect_tuning)
        self.paper = PaperDetector(self.config)
        self.recovery = Recovery(self.config, recover_tuning)
        self.reset()

    @classmethod
    def for_log(cls, log: pd.DataFrame, config: MonitorConfig | None = None) -> Monitor:
        """A monitor for ``log``: reuses its ``vfs_*`` columns when present, otherwise builds
        ``VirtualForceSensor.for_log(log, config.vfs)``; the sampling period from ``time``."""
        cfg = config_for_log(log, config)
        has_vfs = all(vfs_col(s) in log.columns for s in SENSOR_NAMES) and all(
            c in log.columns for c in VFS_TOTAL_COLUMNS
        )
        vfs = None
        if not has_vfs:
            from grfguard.estimate.vfs import VirtualForceSensor

            vfs = VirtualForceSensor.for_log(log, cfg.vfs)
        return cls(cfg, vfs)

    @property
    def sensors(self) -> list[Any]:
        """Per-sensor state of the default detector."""
        return self.detector.sensors

    def reset(self) -> None:
        """Forget everything (filters, flags, contact timeline, VFS state)."""
        if self.vfs is not None:
            self.vfs.reset()
        self.detector.reset()
        self.paper.reset()
        self.recovery.reset()

    def _vfs_row(self, row: Mapping[str, Any]) -> dict[str, float]:
        if self.vfs is not None:
            try:
                return self.vfs.update(row)
            except Exception:  # noqa: BLE001 - a bad sample must never raise
                return {}
        return {}

    def _step(self, t: float, x: list[float], v: list[float], tot: list[float],
              cref: list[float], cest: list[float]) -> dict[str, Any]:
        """Detector and recovery on one sample of plain floats."""
        if self.config.method == "paper":
            return self.paper.step(t, x, v)
        det = self.detector.step(t, x, v, tot, cref, cest)
        out = self.recovery.step(self.detector.sensors, x, v, tot, det.columns)
        if det.diagnostics:
            out.update(det.diagnostics)
        return out

    def update(self, row: Mapping[str, Any]) -> dict[str, Any]:
        """Process one sample; never raises on a bad sample (NaN or missing keys are
        flagged as dropouts or skipped).

        Args:
            row: Mapping with the log-contract columns of one sample.

        Returns:
            Dict with the VFS outputs and ``flag_<s>``, ``kind_<s>``, ``eta_<s>``,
            ``recovered_<s>`` for every sensor.
        """
        vout = self._vfs_row(row)
        src = vout if self.vfs is not None else row
        res = self._step(
            _f(row, TIME),
            [_f(row, force_col(s)) for s in SENSOR_NAMES],
            [_f(src, vfs_col(s)) for s in SENSOR_NAMES],
            [_f(src, c) for c in VFS_TOTAL_COLUMNS],
            [_f(row, f"contact_ref_{s}") for s in SIDES],
            [_f(src, f"contact_est_{s}") for s in SIDES],
        )
        out: dict[str, Any] = dict(vout)
        out.update(res)
        return out

    def run(self, log: pd.DataFrame) -> pd.DataFrame:
        """Reset, then process the whole log; returns ``log`` plus the output columns.

        Raises:
            LogFormatError: If ``time`` or a ``force_<s>`` column is missing.
        """
        missing = [c for c in (TIME, *(force_col(s) for s in SENSOR_NAMES)) if c not in log]
        if missing:
            raise LogFormatError(
                f"Monitor.run: the log lacks column(s) {missing}; see grfguard.io.schema"
            )
        self.reset()
        vdf = None
        if self.vfs is not None:
            vdf = self.vfs.run(log)
            self.vfs.reset()
        inp = DetectorInputs.from_frames(log, vdf if vdf is not None else log)
        if self.config.method == "paper":
            res = pd.DataFrame(
                self.paper.run(np.array(inp.t), np.array(inp.x).T, np.array(inp.v).T),
                index=log.index,
            )
        else:
            rows = [self._step(*inp.sample(k)) for k in range(len(log))]
            res = pd.DataFrame(rows, index=log.index) if rows else pd.DataFrame(index=log.index)
        out = log.copy()
        if vdf is not None:
            for c in vdf.columns:
                out[c] = vdf[c].to_numpy()
        for c in res.columns:
            out[c] = res[c].to_numpy()
        out.attrs = {**log.attrs, "monitor": self.describe()}
        return out

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
