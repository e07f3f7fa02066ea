"""The memory policy of ``grfguard run``: freed memory is kept and reused, not handed
back to the system and page-faulted again, numpy asks for no huge pages, and the cyclic
garbage collector is off (:func:`batch_process`); and :func:`small_pages`, the huge-page
part alone for a scope (``Monitor.run``'s outputs).

A 10-minute log's run allocates about 700 MB over its life: the decoded input columns,
the Parquet reader's scratch, the output blocks, the writer's encoding buffers. By
default two allocators serve it: Arrow's own pool (mimalloc) and the C library's
``malloc`` (numpy). Both return freed memory to the system soon, so each phase
page-faults fresh, zeroed memory again; on the 2-core benchmark machine the kernel's
page zeroing was 0.3-2 s of system time per run (a third of the command at worst). With
:func:`keep_freed_memory` Arrow allocates through ``malloc`` too, and ``malloc`` keeps
what is freed (no trimming of its heap, arrays up to 32 MB from the heap), so a phase
reuses the memory of the one before: BENCHMARKS.md, "Memory reuse in grfguard run".

Huge pages: numpy hints Linux to back every array of 4 MB or more with huge pages
(``madvise(MADV_HUGEPAGE)``). Their first touch can cost far more than that of small
pages: the kernel may compact memory for them on the spot (``defrag`` set to
``madvise``, Debian's and Ubuntu's default), and in a virtual machine that reports free
memory to its host (virtio-balloon free page reporting, e.g. Firecracker; the
benchmark machine) the free 2 MB blocks huge pages are cut from are the ones the host
took back. ``grfguard run`` on a 2-minute Talos log: 2.95-3.28 s with the hint, 2.06-2.42
s with :func:`batch_process` turning it off (system time 0.9-1.2 s -> 0.5 s); on SURALP
logs no difference (BENCHMARKS "Issue 11 status (2026-11-28, session 31)").

This is a process-wide setting for a short batch command, applied by the console script
only (:func:`grfguard.cli.main` for ``grfguard run``); importing grfguard never changes
the allocator, numpy's hint or the collector. Where the C library is not glibc, the
allocator is left as it is.
"""

from __future__ import annotations

import ctypes
import gc
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

__all__ = ["available_memory", "batch_process", "keep_freed_memory", "small_pages"]

#: ``mallopt`` parameters (glibc's malloc.h) and the values set.
_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_THRESHOLD = -1, -2, -3
#: Free memory at the top of the heap kept before trimming (1 GiB: none in practice).
TRIM_THRESHOLD = 1 << 30
#: Extra memory requested each time the heap grows (fewer, larger ``brk`` calls).
TOP_PAD = 64 << 20
#: Allocations up to this size come from the heap (glibc's largest allowed value), not
#: from their own mapping that ``free`` unmaps: a log's columns are a few MB each.
MMAP_THRESHOLD = 32 << 20

_kept = False


def batch_process() -> None:
    """The settings of a short batch command over a whole log (``grfguard run``): freed
    memory kept for reuse (:func:`keep_freed_memory`), no huge-page hint from numpy
    (module docstring), and the cyclic garbage collector off (reference counting frees
    the run's objects; the collector would only walk the imported modules' objects again
    and again: 0.096 s on a 10-minute log)."""
    gc.disable()
    keep_freed_memory()
    setter = _hugepage_setter()
    if setter is not None:
        setter(False)


def _hugepage_setter() -> Callable[[bool], bool] | None:
    """numpy's switch of its huge-page hint (``_set_madvise_hugepage(enabled) ->
    previous``), None where numpy has none."""
    try:
        from numpy._core.multiarray import _set_madvise_hugepage
    except ImportError:  # pragma: no cover - numpy 2.x has it (a private function)
        return None
    return _set_madvise_hugepage


def keep_freed_memory() -> bool:
    """Make this process keep and reuse freed memory (module docstring); True if set
    (now or before), False where it cannot be (not glibc; nothing is changed then)."""
    global _kept
    if _kept:
        return True
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None)
        libc.gnu_get_libc_version  # noqa: B018  (glibc only)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    for param, value in ((_M_MMAP_THRESHOLD, MMAP_THRESHOLD), (_M_TRIM_THRESHOLD,
                          TRIM_THRESHOLD), (_M_TOP_PAD, TOP_PAD)):
        if mallopt(param, value) != 1:  # pragma: no cover - glibc accepts all three
            return False
    import pyarrow as pa

    pa.set_memory_pool(pa.system_memory_pool())
    _kept = True
    return True


def freed_memory_kept() -> bool:
    """Whether :func:`keep_freed_memory` is in effect in this process."""
    return _kept


@contextmanager
def small_pages() -> Iterator[None]:
    """numpy arrays allocated inside get no transparent-huge-page hint.

    numpy asks Linux for huge pages (``madvise(MADV_HUGEPAGE)``) for every array of 4 MB
    or more. Where their first touch is slow (module docstring: memory compacted on the
    spot, or a virtual machine whose balloon gave the free blocks back to its host), the
    arrays' first use stalls: ``Monitor.run``'s first call in a process on a 10-minute
    log took 2.97-3.57 s with the hint and 1.35-1.54 s with its outputs allocated in
    this scope (fresh processes, BENCHMARKS "Issue 11 status (2026-11-28, session 31)");
    later calls took the same time either way. The outputs of a batch run are written
    once, front to back: small pages cost them little.

    numpy's setting is process-wide; it is restored on exit (an array another thread
    allocates meanwhile gets no hint either, which changes nothing else). Without
    numpy's switch (other versions) this does nothing."""
    setter = _hugepage_setter()
    if setter is None:  # pragma: no cover
        yield
        return
    before = setter(False)
    try:
        yield
    finally:
        setter(before)


def available_memory() -> int | None:
    """``MemAvailable`` from ``/proc/meminfo`` [bytes], or None where unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None
