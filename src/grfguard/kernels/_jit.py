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

#: :data:`njit` without numba's reference counting (NRT): for the per-sample kernels, which
#: allocate nothing. With NRT every array argument of every compiled call is incremented
#: and decremented on entry and exit (a few hundred runtime calls per VFS sample); without
#: it arrays are plain borrowed views. Such functions must not allocate arrays.
njit_nort = functools.partial(numba.njit, cache=True, nogil=True, fastmath=False,
                              error_model="numpy", _nrt=False)

__all__ = ["njit", "njit_nort"]


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


def _view_intrinsics():
    from numba.core import cgutils, types
    from numba.extending import intrinsic
    from numba.np.arrayobj import make_array, populate_array

    def _build(context, builder, arrty, ret, a, off, dims):
        src = make_array(arrty)(context, builder, a)
        dst = make_array(ret)(context, builder)
        itemsize = context.get_constant(
            types.intp, context.get_abi_sizeof(context.get_data_type(arrty.dtype)))
        strides = []
        acc = itemsize
        for d in reversed(dims[1:]):
            strides.insert(0, acc)
            acc = builder.mul(acc, d)
        strides.insert(0, acc)
        # borrowed: no meminfo, so creating and dropping the view costs no reference
        # counting (atomic operations); valid while the source array lives, which the
        # kernels guarantee (views never leave the compiled code)
        populate_array(dst, data=cgutils.gep_inbounds(builder, src.data, off),
                       shape=cgutils.pack_array(builder, list(dims)),
                       strides=cgutils.pack_array(builder, strides), itemsize=itemsize,
                       meminfo=None, parent=None)
        return dst._getvalue()

    def _ok(arr):
        return isinstance(arr, types.Array) and arr.ndim == 1 and arr.layout == "C"

    @intrinsic
    def view1d(typingctx, arr, offset, n):
        """Borrowed ``arr[offset : offset + n]`` of a 1-D C-contiguous array (no
        reference counting; never return it to Python; bounds are the caller's)."""
        if not _ok(arr):
            return None
        ret = types.Array(arr.dtype, 1, "C")

        def codegen(context, builder, signature, args):
            return _build(context, builder, signature.args[0], ret, args[0], args[1],
                          [args[2]])

        return ret(arr, types.intp, types.intp), codegen

    @intrinsic
    def view2d(typingctx, arr, offset, n, m):
        """Borrowed C-contiguous (n, m) view of ``arr[offset : offset + n * m]`` of a 1-D
        C-contiguous array (no copy, no numpy reshape call, no reference counting; never
        return it to Python; bounds are the caller's)."""
        if not _ok(arr):
            return None
        ret = types.Array(arr.dtype, 2, "C")

        def codegen(context, builder, signature, args):
            return _build(context, builder, signature.args[0], ret, args[0], args[1],
                          [args[2], args[3]])

        return ret(arr, types.intp, types.intp, types.intp), codegen

    @intrinsic
    def borrow(typingctx, arr):
        """The same array without its memory owner: passing it on and dropping it costs
        no reference counting (numba increments every array argument of a non-inlined
        call with an atomic operation). Valid while ``arr`` lives; never return it."""
        if not isinstance(arr, types.Array):
            return None

        def codegen(context, builder, signature, args):
            a = make_array(arr)(context, builder, args[0])
            a.meminfo = cgutils.get_null_value(a.meminfo.type)
            a.parent = cgutils.get_null_value(a.parent.type)
            return a._getvalue()

        return arr(arr), codegen

    return view1d, view2d, borrow


view1d, view2d, borrow = _view_intrinsics()
__all__ += ["view1d", "view2d", "borrow"]
