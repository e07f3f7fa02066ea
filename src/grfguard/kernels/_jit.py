"""numba settings shared by every kernel: compiled on first use, cached on disk.

``cache=True`` writes the machine code next to the module (``__pycache__``); the first
call in a fresh environment compiles (see :func:`grfguard.kernels.warm_up`), later
processes load all of it in about 0.3 s (:func:`_lean_cache_class`). ``fastmath`` stays
off: the kernels reproduce the pure-Python results to the last bits where the operation
order allows it.
"""

from __future__ import annotations

import copy
import hashlib
import os
import re
from collections.abc import Iterable, Mapping
from pathlib import Path

import numba

#: Name of the stamp file kept next to numba's cache files (``__pycache__``): one line per
#: kernel module, ``<module> <sha256>``, after a header line.
STAMP_NAME = "grfguard_kernels.stamps"
_STAMP_HEADER = "# grfguard kernel cache stamps v1"
_OLD_STAMP_NAME = "grfguard_kernels.sha256"  # the former single hash over all kernels

# ``from grfguard.kernels.x import ...``, ``from .x import ...``, ``from . import x``,
# ``from grfguard.kernels import x``, ``import grfguard.kernels.x`` (anywhere in a file,
# also inside functions: an import there may still bring compiled callees)
_FROM = re.compile(r"^[ \t]*from[ \t]+(grfguard\.kernels(?:\.\w+)?|\.\w*)[ \t]+import[ \t]+"
                   r"(\([^)]*\)|[^\n#]*)", re.M)
_IMPORT = re.compile(r"^[ \t]*import[ \t]+grfguard\.kernels\.(\w+)", re.M)
# ``from grfguard.io.schema import ...`` and other grfguard modules outside the kernels:
# numba freezes the module-level constants a kernel reads (column indices, sensor names)
# into its machine code, so the source of such a module is part of the kernel's hash
# (top-level imports only: a function-level import runs in Python, nothing is frozen)
_OUTSIDE = re.compile(r"^from[ \t]+(grfguard\.(?!kernels\b)[\w.]+)[ \t]+import", re.M)


def kernel_imports(source: str, modules: Iterable[str]) -> set[str]:
    """The kernel modules (of ``modules``, file stems) that ``source`` imports directly;
    the package itself is ``__init__``. Modules of grfguard outside the kernels count by
    their dotted name (``grfguard.io.schema``) when ``modules`` lists them."""
    known = set(modules)
    deps: set[str] = set(_IMPORT.findall(source)) | set(_OUTSIDE.findall(source))
    for mod, names in _FROM.findall(source):
        sub = mod[len("grfguard.kernels."):] if mod.startswith("grfguard.") else mod[1:]
        if sub:
            deps.add(sub)
            continue
        deps.add("__init__")  # the package: its own imports, and maybe submodules
        deps.update(n.split(" as ")[0].strip() for n in names.strip("()").split(","))
    return deps & known


def module_digests(sources: Mapping[str, bytes]) -> dict[str, str]:
    """Per kernel module (file stem -> source bytes): a hash over its source and those
    of the kernel modules it imports, transitively (numba inlines compiled callees into
    the caller's cached machine code, and checks only the caller's file)."""
    names = sorted(sources)
    direct = {m: kernel_imports(sources[m].decode("utf-8", "replace"), names) for m in names}
    out = {}
    for m in names:
        seen, todo = {m}, [m]
        while todo:
            for d in direct[todo.pop()]:
                if d not in seen:
                    seen.add(d)
                    todo.append(d)
        h = hashlib.sha256()
        for d in sorted(seen):
            h.update(d.encode() + b"\0" + sources[d] + b"\0")
        out[m] = h.hexdigest()
    return out


def format_stamps(digests: Mapping[str, str]) -> str:
    """The stamp file's text for ``digests``."""
    return "\n".join([_STAMP_HEADER, *(f"{m} {digests[m]}" for m in sorted(digests))]) + "\n"


def parse_stamps(text: str) -> dict[str, str]:
    """The digests of a stamp file (empty when it is not one: every module stale)."""
    lines = text.splitlines()
    if not lines or lines[0].strip() != _STAMP_HEADER:
        return {}
    out = {}
    for line in lines[1:]:
        parts = line.split()
        if len(parts) == 2 and len(parts[1]) == 64:
            out[parts[0]] = parts[1]
    return out


def stale_cache_files(files: Iterable[str], old: Mapping[str, str],
                      new: Mapping[str, str]) -> list[str]:
    """The numba cache files (``<module>.<function>-<line>.py311[.N].nbi/.nbc``) among
    ``files`` to delete: those of modules whose digest changed or is new, and those of
    modules that no longer exist."""
    out = []
    for f in files:
        if not f.endswith((".nbi", ".nbc")):
            continue
        mod = f.split(".", 1)[0]
        if mod not in new or old.get(mod) != new[mod]:
            out.append(f)
    return sorted(out)


def kernel_sources(here: Path) -> dict[str, bytes]:
    """Sources to hash: every kernel module (file stem -> bytes) and every grfguard module
    outside the kernels that one of them imports from (dotted name -> bytes; its constants
    are frozen into the compiled code). Outside modules that are not files of the package
    next to ``here`` (a fake package in tests) are left out."""
    out = {f.stem: f.read_bytes() for f in sorted(here.glob("*.py"))}
    root = here.parent
    for src in list(out.values()):
        for mod in _OUTSIDE.findall(src.decode("utf-8", "replace")):
            rel = Path(*mod.split(".")[1:])
            for f in (root / rel.with_suffix(".py"), root / rel / "__init__.py"):
                if mod not in out and f.is_file():
                    out[mod] = f.read_bytes()
    return out


def _drop_stale_cache(here: Path | None = None) -> list[str]:
    """numba's cache checks only the file of the compiled function, not the modules it
    calls (a change in ``nnls.py`` would leave ``vfs.py``'s cached code stale). Keep a
    hash per kernel module (its source and the kernel modules it imports, transitively)
    next to the cache and delete the cached code of the modules whose hash changed
    (others keep theirs: an upgrade that changes one leaf recompiles only what uses it).
    A grfguard module outside the kernels whose constants a kernel imports counts as a
    dependency of that kernel.
    Returns the names deleted."""
    here = Path(__file__).resolve().parent if here is None else here
    cache = here / "__pycache__"
    new = module_digests(kernel_sources(here))
    stamp = cache / STAMP_NAME
    try:
        old = parse_stamps(stamp.read_text()) if stamp.exists() else {}
        files = [f.name for f in cache.iterdir()] if cache.is_dir() else []
        gone = stale_cache_files(files, old, new)
        for f in gone:
            (cache / f).unlink(missing_ok=True)
        if old != new:
            cache.mkdir(exist_ok=True)
            stamp.write_text(format_stamps(new))
        (cache / _OLD_STAMP_NAME).unlink(missing_ok=True)
    except OSError:  # read-only install: numba caches elsewhere, sources do not change
        return []
    return gone


_drop_stale_cache()


def _lean_cache_class():
    """numba's cache of one function with a leaner load: numba (0.68) refreshes its target
    context before every load from the disk cache, and the first refresh of a process
    imports every implementation registry it has (linear algebra, random generators,
    typed containers, polynomials, datetimes: 0.15-0.25 s of CPU, a twentieth of
    ``grfguard run`` on a 10-minute log) although loading machine code needs none of them,
    only the runtime's symbols. This class initialises the runtime, loads, and refreshes
    only on a miss, before numba compiles (its compiler refreshes again; a first lowering
    call refreshes too), so a kernel that is compiled sees numba's full set-up as always.
    Used for grfguard's own kernels only (a user's numba code in the same process keeps
    numba's behaviour); None when numba's cache does not look as expected (other numba
    versions), which leaves numba's own load in place."""
    try:
        from numba.core.caching import FunctionCache
        from numba.core.runtime import rtsys
    except ImportError:  # pragma: no cover - numba without these modules
        return None
    if not all(hasattr(FunctionCache, a) for a in
               ("load_overload", "_load_overload", "_guard_against_spurious_io_errors")):
        return None  # pragma: no cover

    class LeanFunctionCache(FunctionCache):
        def load_overload(self, sig, target_context):
            rtsys.initialize(target_context)  # what the loaded code links against
            with self._guard_against_spurious_io_errors():
                data = self._load_overload(sig, target_context)
            if data is None:
                target_context.refresh()  # a miss: compiling follows
                inline_without_copies()
            return data

    return LeanFunctionCache


#: Set by :func:`inline_without_copies`: True once numba's inliner is patched, False when
#: numba's code is not the one the patch was written against (nothing changed then).
_INLINE_PATCHED: bool | None = None
# numba's code the patch relies on (``InlineWorker.inline_function`` / ``inline_ir``, and
# the ``InlineInlinables`` pass, the one caller of ``inline_function``, dropping the
# unmutated copy ``inline_ir`` returns)
_INLINE_SOURCES = (
    ("inline_function", "callee_ir = self.run_untyped_passes(function)"),
    ("inline_function", "return self.inline_ir(caller_ir, block, i, callee_ir, freevars,"),
    ("inline_ir", "new_block = copy.deepcopy(the_ir.blocks[block_label])"),
    ("inline_ir", "callee_ir_original = copy_ir(callee_ir)"),
)


class _NoDeepCopy:
    """``copy`` as ``inline_ir`` sees it while it inlines a fresh IR of its own: the
    defensive deep copies return the blocks themselves."""

    copy = staticmethod(copy.copy)

    @staticmethod
    def deepcopy(x, memo=None):
        return x


def inline_without_copies() -> bool:
    """Skip two deep copies numba makes of an ``inline="always"`` callee of grfguard's.

    numba (0.68) inlines such a callee by building its IR afresh (the untyped passes over
    its bytecode, ``InlineWorker.inline_function``), then ``inline_ir`` deep-copies that
    IR twice, block by block: one copy to mutate, one returned unmutated, which the only
    caller (the ``InlineInlinables`` pass) drops. A block's deep copy takes the
    function's whole scope with it, so each copy costs blocks x variables: over the
    monitor's nested stages that was about 60 % of its compilation (cProfile of
    :func:`~grfguard.kernels.monitor.warm_monitor` from an empty cache; numba issues
    #8989, #9204). The fresh IR is the call's own, so for grfguard's functions
    ``inline_ir`` runs with an identity ``deepcopy``: the same IR is inlined, only not
    copied. Other functions (a user's numba code) keep numba's behaviour; numba whose code
    differs from what this was written against is left alone (False), and so is numba
    when the environment sets ``GRFGUARD_NUMBA_INLINE_COPIES=1`` (numba's own inlining, for
    a comparison or should this ever misbehave). Called on the first compilation of a
    process (:class:`LeanFunctionCache`'s miss); idempotent."""
    global _INLINE_PATCHED
    if _INLINE_PATCHED is not None:
        return _INLINE_PATCHED
    _INLINE_PATCHED = False
    if os.environ.get("GRFGUARD_NUMBA_INLINE_COPIES", "") not in ("", "0"):
        return False
    try:
        import inspect

        from numba.core import inline_closurecall as icc
        from numba.core import untyped_passes

        worker = icc.InlineWorker
        src = {n: inspect.getsource(getattr(worker, n)) for n in ("inline_function",
                                                                   "inline_ir")}
        caller = inspect.getsource(untyped_passes.InlineInlinables._do_work)
    except (ImportError, AttributeError, OSError, TypeError):  # pragma: no cover
        return False
    if not (all(text in src[n] for n, text in _INLINE_SOURCES)
            and "_, _, _, new_blocks = \\" in caller):
        return False  # pragma: no cover - another numba
    numba_inline = worker.inline_function

    def inline_function(self, caller_ir, block, i, function, arg_typs=None):
        if not (getattr(function, "__module__", None) or "").startswith("grfguard."):
            return numba_inline(self, caller_ir, block, i, function, arg_typs=arg_typs)
        callee_ir = self.run_untyped_passes(function)
        prev, icc.copy = icc.copy, _NoDeepCopy
        try:
            return self.inline_ir(caller_ir, block, i, callee_ir,
                                  function.__code__.co_freevars, arg_typs=arg_typs)
        finally:
            icc.copy = prev

    worker.inline_function = inline_function
    _INLINE_PATCHED = True
    return True


_LEAN_CACHE = _lean_cache_class()


def _lean(dispatcher):
    """``dispatcher`` with :func:`_lean_cache_class`'s load (when available)."""
    cache = getattr(dispatcher, "_cache", None)
    if _LEAN_CACHE is not None and type(cache) is _LEAN_CACHE.__base__:  # numba's own
        cache.__class__ = _LEAN_CACHE
    return dispatcher


def _cached_jit(**options):
    """``numba.njit`` with ``options``, as a decorator with or without arguments, its
    dispatchers loading from the disk cache by :func:`_lean`."""

    def jit(*args, **kw):
        res = numba.njit(*args, **{**options, **kw})
        if isinstance(res, numba.core.dispatcher.Dispatcher):
            return _lean(res)
        return lambda fn: _lean(res(fn))

    return jit


#: ``numba.njit`` with the on-disk cache and the GIL released.
njit = _cached_jit(cache=True, nogil=True, fastmath=False, error_model="numpy")

#: :data:`njit` without numba's reference counting (NRT): for the per-sample kernels, which
#: allocate nothing. With NRT every array argument of every compiled call is incremented
#: and decremented on entry and exit (a few hundred runtime calls per VFS sample); without
#: it arrays are plain borrowed views. Such functions must not allocate arrays.
njit_nort = _cached_jit(cache=True, nogil=True, fastmath=False, error_model="numpy",
                        _nrt=False)

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
