"""Compiled core (numba): forward kinematics of any MuJoCo tree and the virtual force sensor
as one step function over plain arrays, streamed sample by sample or looped over a log.

See :mod:`grfguard.kernels.vfs` for the array layouts and :func:`warm_up` for the
compilation cost (cached on disk after the first run).
"""

from __future__ import annotations

from grfguard.kernels.fk import TreeModel, fk_sites, fk_tree

__all__ = ["TreeModel", "fk_tree", "fk_sites"]
