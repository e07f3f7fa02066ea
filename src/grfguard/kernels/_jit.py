"""numba settings shared by every kernel: compiled on first use, cached on disk.

``cache=True`` writes the machine code next to the module (``__pycache__``); the first
call in a fresh environment compiles (see :func:`grfguard.kernels.warm_up`), later
processes load it in about a second. ``fastmath`` stays off: the kernels reproduce the
pure-Python results to the last bits where the operation order allows it.
"""

from __future__ import annotations

import functools

import numba

#: ``numba.njit`` with the on-disk cache and the GIL released.
njit = functools.partial(numba.njit, cache=True, nogil=True, fastmath=False, error_model="numpy")

__all__ = ["njit"]
