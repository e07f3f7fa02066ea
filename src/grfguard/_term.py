"""The terminal of the command line: one stderr console for status and errors, one
stdout console for results, shared by every ``cli*`` module (so that none of them
imports :mod:`grfguard.cli`, which imports them all)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rich.console import Console

from grfguard._cliutil import friendly, say

console = Console(stderr=True)
out = Console()


def cli_friendly(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn grfguard errors into one red line and exit code 2 (user text never read as
    markup); print grfguard warnings as ``warning:`` lines."""
    return friendly(console)(fn)


def cli_say(message: str) -> None:
    """One plain-text status line on stderr (paths may contain ``[...]``)."""
    say(console, message)


def progress(description: str) -> Any:
    """A progress bar on stderr (a :class:`rich.progress.Progress`), shown only on a
    terminal (``rich.progress`` is imported here: most commands draw no bar)."""
    from rich.progress import (
        BarColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>5.1f}%"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=False,
        disable=not console.is_terminal,
    )
