"""Signal reconstruction of faulty sole sensors (the stage after detection).

:class:`Recovery` turns the detector's verdicts into ``recovered_<s>`` and ``eta_<s>``;
:class:`HandOver` is its blend between measurement and reconstruction. ``recover``
imports ``detect`` (it reads the detector's sensor states), never the other way.
"""

from __future__ import annotations

from grfguard.recover.reconstruct import HandOver
from grfguard.recover.recovery import RecoverTuning, Recovery

__all__ = ["HandOver", "RecoverTuning", "Recovery"]
