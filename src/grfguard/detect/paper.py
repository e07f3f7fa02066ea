"""The paper's method as a monitor stage: observer eq. 24-32 and threshold eq. 33.

:class:`PaperDetector` runs the observer of :mod:`grfguard.detect.observer` on the
measured forces and the VFS corner forces. The filter starts from the mean residual
``N_meas - N̂`` of the first ``init_s`` seconds (no alarm there; the output is the
measurement, else the VFS). Afterwards ``flag = |η_f| > tr`` per sensor (eq. 33,
``Thresholds.paper_eta_n``); kinds are not estimated (``unknown``); ``eta`` is η̂ and the
recovered force is the filter's ``N̂``. Streaming (:meth:`PaperDetector.step`, with
:class:`~grfguard.detect.observer.FaultObserver`) and batch
(:meth:`PaperDetector.run`, with :func:`~grfguard.detect.observer.run_observer`) give
the same numbers.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from grfguard.detect.config import MonitorConfig
from grfguard.detect.observer import FaultObserver, run_observer
from grfguard.io.schema import eta_col, flag_col, kind_col, recovered_col
from grfguard.model.robot import SENSOR_NAMES

__all__ = ["PaperDetector"]

_N = len(SENSOR_NAMES)
_NAN = float("nan")
_FLAG = tuple(flag_col(s) for s in SENSOR_NAMES)
_KIND = tuple(kind_col(s) for s in SENSOR_NAMES)
_ETA = tuple(eta_col(s) for s in SENSOR_NAMES)
_REC = tuple(recovered_col(s) for s in SENSOR_NAMES)


def _columns(
    flags: np.ndarray, eta: np.ndarray, rec: np.ndarray, etaf: np.ndarray | None
) -> dict[str, Any]:
    """Output columns from arrays of shape (..., 8) (``eta_filtered_*`` if given)."""
    out: dict[str, Any] = {}
    for i, s in enumerate(SENSOR_NAMES):
        if etaf is not None:
            out[f"eta_filtered_{s}"] = etaf[..., i]
        out[flag_col(s)] = flags[..., i]
        out[kind_col(s)] = np.where(flags[..., i], "unknown", "none").astype(object)
        out[eta_col(s)] = eta[..., i]
        out[recovered_col(s)] = rec[..., i]
    return out


class PaperDetector:
    """Streaming and batch form of the paper's method (see the module docstring).

    Args:
        config: ``observer`` settings, ``init_s``, ``thresholds.paper_eta_n``,
            ``diagnostics`` (adds ``eta_filtered_<s>``).
    """

    def __init__(self, config: MonitorConfig) -> None:
        self.config = config
        self.reset()

    def reset(self) -> None:
        """Back to the start of the initialisation window."""
        self._obs = FaultObserver(_N, self.config.observer)
        self._t0 = _NAN
        self._init_sum = [0.0] * _N
        self._init_cnt = [0] * _N
        self._init_done = False

    def _eta0(self) -> np.ndarray:
        """Mean residual of the initialisation window per sensor [N] (0 without data)."""
        return np.array([self._init_sum[i] / self._init_cnt[i] if self._init_cnt[i] else 0.0
                         for i in range(_N)])

    def step(self, t: float, x: Sequence[float], v: Sequence[float]) -> dict[str, Any]:
        """One sample: measured ``x`` and VFS ``v`` corner forces [N] at time ``t`` [s]."""
        c = self.config
        if math.isnan(self._t0) and math.isfinite(t):
            self._t0 = t
        in_init = not (math.isfinite(t) and t - self._t0 >= c.init_s)
        if in_init and not self._init_done:
            return self._init_step(x, v)
        if not self._init_done:
            eta0 = self._eta0()
            self._obs.eta_n = eta0.copy()
            self._obs.eta_filtered_n = eta0.copy()
            self._init_done = True
        eta, force, etaf = self._obs.update(np.asarray(x, float), np.asarray(v, float))
        th = c.thresholds.paper_eta_n
        out: dict[str, Any] = {}
        for i, s in enumerate(SENSOR_NAMES):
            ef = float(etaf[i])
            if c.diagnostics:
                out[f"eta_filtered_{s}"] = ef
            fl = abs(ef) > th[i]
            out[_FLAG[i]] = fl
            out[_KIND[i]] = "unknown" if fl else "none"
            out[_ETA[i]] = float(eta[i])
            r = float(force[i])
            out[_REC[i]] = r if math.isfinite(r) else 0.0
        return out

    def _init_step(self, x: Sequence[float], v: Sequence[float]) -> dict[str, Any]:
        """A sample of the initialisation window: accumulate the residual; the output is
        the measurement (else the VFS, else 0), no flag."""
        out: dict[str, Any] = {}
        for i, s in enumerate(SENSOR_NAMES):
            e = x[i] - v[i]
            if math.isfinite(e):
                self._init_sum[i] += e
                self._init_cnt[i] += 1
            if self.config.diagnostics:
                out[f"eta_filtered_{s}"] = 0.0
            out[_FLAG[i]] = False
            out[_KIND[i]] = "none"
            out[_ETA[i]] = 0.0
            out[_REC[i]] = x[i] if math.isfinite(x[i]) else (
                v[i] if math.isfinite(v[i]) else 0.0)
        return out

    def _init_length(self, t: np.ndarray) -> int:
        """Number of leading samples in the initialisation window."""
        fin = np.isfinite(t)
        if not fin.any():
            return len(t)
        t0 = float(t[np.flatnonzero(fin)[0]])
        late = fin & (t - t0 >= self.config.init_s)
        return int(np.flatnonzero(late)[0]) if late.any() else len(t)

    def run(self, t: np.ndarray, x: np.ndarray, v: np.ndarray) -> dict[str, np.ndarray]:
        """Batch form of :meth:`step` from the reset state.

        Args:
            t: Times (T,) [s].
            x: Measured forces (T, 8) [N].
            v: VFS corner forces (T, 8) [N].

        Returns:
            Output columns as arrays of length T.
        """
        n = len(t)
        n_init = self._init_length(t)
        e = x[:n_init] - v[:n_init]
        ok = np.isfinite(e)
        cnt = ok.sum(axis=0)
        eta0 = np.where(cnt > 0, np.where(ok, e, 0.0).sum(axis=0) / np.maximum(cnt, 1), 0.0)
        flags = np.zeros((n, _N), bool)
        eta = np.zeros((n, _N))
        etaf = np.zeros((n, _N))
        rec = np.where(np.isfinite(x), x, np.where(np.isfinite(v), v, 0.0))
        if n_init < n:
            r = run_observer(x[n_init:], v[n_init:], self.config.observer, eta0_n=eta0)
            eta[n_init:] = r.eta_n
            etaf[n_init:] = r.eta_filtered_n
            flags[n_init:] = np.abs(r.eta_filtered_n) > np.array(self.config.thresholds.paper_eta_n)
            rec[n_init:] = np.where(np.isfinite(r.force_n), r.force_n, 0.0)
        return _columns(flags, eta, rec, etaf if self.config.diagnostics else None)
