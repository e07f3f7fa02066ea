"""Signal reconstruction of faulty sole sensors: the rules and the hand-over blend.

The stage that applies them sample by sample is :class:`~grfguard.recover.recovery.Recovery`.

- additive faults (offset, drift): ``N_rec = N_meas - η̂``;
- gain: ``N_rec = N_meas / ĝ``;
- sensors that carry no information (frozen, stuck, dropout, clipped, noisy): the
  whole-body balance ``N_rec,i = F_z,VFS(both feet) - Σ_{j≠i} N_j`` over the other seven
  (healthy or corrected) sensors: the total vertical force of the VFS is precise in every
  phase (a few N), unlike its per-foot split in double support and its corners (tens of
  N); several such sensors share the rest by their VFS corner forces; the VFS corner
  itself is the fallback;
- the output blends from the measurement to the reconstruction (and back) with a first
  order ramp, and is never NaN.
"""

from __future__ import annotations

import math

__all__ = ["HandOver"]


class HandOver:
    """First-order blend weight ``w`` between measurement (0) and reconstruction (1).

    Args:
        tau_s: Time constant of the blend [s] (``MonitorConfig.blend_s``).
        dt_s: Sampling period of the log [s] (no default: 1 kHz is not assumed).
    """

    def __init__(self, tau_s: float, dt_s: float) -> None:
        self.alpha = min(1.0, dt_s / tau_s) if tau_s > 0 else 1.0
        self.w = 0.0

    def reset(self) -> None:
        """Back to the measurement."""
        self.w = 0.0

    def update(self, target: float, alpha: float | None = None) -> float:
        """Move ``w`` toward ``target`` (0 or 1) and return it (``alpha`` overrides the
        step fraction ``dt / tau`` for this sample)."""
        self.w += (target - self.w) * (self.alpha if alpha is None else alpha)
        if abs(target - self.w) < 1e-6:
            self.w = float(target)  # snap: the hand-over is finished
        return self.w

    @staticmethod
    def mix(w: float, measured_n: float, reconstructed_n: float, fallback_n: float) -> float:
        """``(1-w)·measured + w·reconstructed``; NaN inputs fall back, never NaN out [N]."""
        if not math.isfinite(reconstructed_n):
            reconstructed_n = fallback_n
        if not math.isfinite(measured_n):
            return reconstructed_n
        if w <= 1e-12:
            return measured_n
        return (1.0 - w) * measured_n + w * reconstructed_n
