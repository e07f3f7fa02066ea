"""Signal reconstruction of faulty sole sensors."""

from __future__ import annotations

from grfguard.recover.reconstruct import HandOver, foot_balance

__all__ = ["HandOver", "foot_balance"]
