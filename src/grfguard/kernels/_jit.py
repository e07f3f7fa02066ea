"""numba settings shared by every kernel: compiled on first use, cached on disk.

``cache=True`` writes the machine code next to the module (``__pycache__``); the first
call in a fresh environment compiles (see :func:`grfguard.kernels.warm_up`), later
processes load it in about a second. ``fastmath`` stays off: the kernels reproduce the
pure-Python results to the last bits where the operation order allows it.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import numba


def _drop_stale_cache() -> None:
    """numba's cache checks only the file of the compiled function, not the modules it
    calls (a change in ``nnls.py`` would leave ``vfs.py``'s cached code stale). Keep a hash
    of every kernel source next to the cache and clear the cache when it changes."""
    here = Path(__file__).resolve().parent
    cache = here / "__pycache__"
    h = hashlib.sha256()
    for f in sorted(here.glob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    digest = h.hexdigest()
    stamp = cache / "grfguard_kernels.sha256"
    try:
        if stamp.exists() and stamp.read_text() == digest:
            return
        for f in list(cache.glob("*.nbi")) + list(cache.glob("*.nbc")):
            f.unlink()
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest)
    except OSError:  # read-only install: numba caches elsewhere, sources do not change
        pass


_drop_stale_cache()

#: ``numba.njit`` with the on-disk cache and the GIL released.
njit = functools.partial(numba.njit, cache=True, nogil=True, fastmath=False, error_model="numpy")

__all__ = ["njit"]


def _fma_intrinsic():
    from llvmlite import ir
    from numba.core import cgutils, types
    from numba.extending import intrinsic

    @intrinsic
    def fma(typingctx, a, b, c):
        """Fused ``a * b + c`` (one rounding), as numpy's BLAS-backed matmul computes it."""
        sig = types.float64(types.float64, types.float64, types.float64)

        def codegen(context, builder, signature, args):
            fnty = ir.FunctionType(ir.DoubleType(), [ir.DoubleType()] * 3)
            fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.fma.f64")
            return builder.call(fn, args)

        return sig, codegen

    return fma


fma = _fma_intrinsic()
__all__ += ["fma"]
