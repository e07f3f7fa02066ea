"""Safe outputs: never overwrite an input, never leave a partial file.

Every file grfguard writes goes through :func:`atomic_path` (or the helpers built on it):
the data is written to a temporary file in the target's own directory, flushed to disk
(``fsync``) and then renamed over the target in one step. If anything fails (disk full, a
file-size limit, an exception while rendering), the temporary file is removed and the
previous target, if any, is left byte-identical.

:func:`check_output` is meant to run *before* the work starts: it refuses an output that is
one of the inputs, a directory, or in a place that cannot be written, so a long computation
never ends in "permission denied".
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from grfguard.errors import OutputError

__all__ = [
    "atomic_path",
    "atomic_open",
    "atomic_write_text",
    "check_output",
    "check_output_dir",
    "same_file",
]

_DISK_ERRNOS = {errno.ENOSPC, errno.EFBIG, errno.EDQUOT}


def same_file(a: str | Path, b: str | Path) -> bool:
    """True when ``a`` and ``b`` name the same file (same path, a link, or a hard link)."""
    pa, pb = Path(a), Path(b)
    try:
        if pa.exists() and pb.exists():
            return os.path.samefile(pa, pb)
    except OSError:
        pass
    return pa.resolve() == pb.resolve()


def _umask_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def _describe(exc: OSError) -> str:
    if exc.errno in _DISK_ERRNOS:
        return f"the disk is full or a file-size limit was reached ({exc.strerror})"
    return exc.strerror or str(exc)


def check_output(
    path: str | Path,
    inputs: Iterable[str | Path | None] = (),
    what: str = "output",
    option: str = "-o",
) -> Path:
    """Check that ``path`` can be written as an output file, before any work is done.

    Args:
        path: The output file.
        inputs: Files the command reads; ``path`` must not be one of them.
        what: What the output is (used in the message: ``output log``, ``report``, ...).
        option: The command-line option naming it (used in the message).

    Returns:
        ``path`` as a :class:`~pathlib.Path`.

    Raises:
        OutputError: ``path`` is an input, a directory or another non-regular file, or its
            directory cannot be created or written.
    """
    p = Path(path)
    for src in inputs:
        if src is not None and same_file(p, src):
            raise OutputError(
                f"{option} {p} is also an input: grfguard never overwrites its input; "
                f"choose another {what} file name"
            )
    if p.exists() or p.is_symlink():
        if p.is_dir():
            raise OutputError(
                f"{option} {p} is a directory; give a file name for the {what}, "
                f"e.g. {p / ('out' + (p.suffix or '.parquet'))}"
            )
        if p.exists() and not stat.S_ISREG(p.stat().st_mode):
            raise OutputError(f"{option} {p} is not a regular file; choose another {what} path")
    _probe_dir(p.parent, option, p, what)
    return p


def check_output_dir(path: str | Path, inputs: Iterable[str | Path | None] = (),
                     what: str = "output directory", option: str = "--out") -> Path:
    """Like :func:`check_output` for a directory that will receive several files."""
    p = Path(path)
    for src in inputs:
        if src is not None and same_file(p, src):
            raise OutputError(f"{option} {p} is also an input; choose another {what}")
    if p.exists() and not p.is_dir():
        raise OutputError(f"{option} {p} exists and is not a directory; choose another {what}")
    _probe_dir(p, option, p, what)
    return p


def _probe_dir(d: Path, option: str, target: Path, what: str) -> None:
    """Create ``d`` if needed and check that a file can be created in it."""
    probe_from = d
    while not probe_from.exists():
        if probe_from.parent == probe_from:
            break
        probe_from = probe_from.parent
    if probe_from.exists() and not probe_from.is_dir():
        raise OutputError(
            f"{option} {target}: {probe_from} is a file, not a directory; "
            f"choose another place for the {what}"
        )
    try:
        d.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".grfguard-probe-", dir=d)
        os.close(fd)
        os.unlink(tmp)
    except OSError as exc:
        raise OutputError(
            f"{option} {target}: cannot write in {d} ({_describe(exc)}); "
            f"choose a writable place for the {what}"
        ) from None


@contextlib.contextmanager
def atomic_path(path: str | Path, what: str = "output") -> Iterator[Path]:
    """Context manager yielding a temporary path next to ``path``; on success the temporary
    file is flushed to disk and renamed to ``path``; on any failure it is removed and
    ``path`` is left as it was.

    Use it for writers that want a path (``pyarrow.parquet.write_table``,
    ``matplotlib.savefig``, ...). OS errors (disk full, file-size limit, permission) are
    raised as :class:`~grfguard.errors.OutputError` naming ``path``.
    """
    p = Path(path)
    if p.is_dir():
        raise OutputError(f"{p} is a directory; give a file name for the {what}")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
        os.close(fd)
    except OSError as exc:
        raise OutputError(f"cannot write the {what} {p}: {_describe(exc)}") from None
    tmp = Path(tmp_name)
    try:
        yield tmp
        mode = stat.S_IMODE(p.stat().st_mode) if p.exists() else _umask_mode()
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, p)
        _fsync_dir(p.parent)
    except OutputError:
        _unlink(tmp)
        raise
    except OSError as exc:
        _unlink(tmp)
        raise OutputError(
            f"could not write the {what} {p}: {_describe(exc)}; nothing was changed "
            f"({p.name} is as before); free some space or choose another place"
        ) from None
    except BaseException:
        _unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", what: str = "output",
                **kwargs: Any) -> Iterator[IO[Any]]:
    """``open(path, mode)`` that only replaces ``path`` when the ``with`` block succeeds."""
    if mode not in ("w", "wb", "wt"):
        raise ValueError(f"atomic_open writes whole files: mode must be 'w' or 'wb', got {mode!r}")
    with atomic_path(path, what) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh
        fh.flush()


def atomic_write_text(path: str | Path, text: str, what: str = "output",
                      encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically; returns ``path``."""
    with atomic_open(path, "w", what=what, encoding=encoding, newline="") as fh:
        fh.write(text)
    return Path(path)


def _unlink(p: Path) -> None:
    with contextlib.suppress(OSError):
        p.unlink()


def _fsync_dir(d: Path) -> None:
    """Make the rename durable (best effort: not every platform can open a directory)."""
    try:
        fd = os.open(d, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
