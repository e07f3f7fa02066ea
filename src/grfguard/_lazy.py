"""A module imported on first use (``pd = lazy_module("pandas")``): its import is paid
by the first attribute read, not by the import of the module that names it.

``grfguard run`` on a Parquet log never touches pandas (the log is read as numpy columns,
:class:`grfguard.io.columns.LogColumns`), yet the modules on its path use pandas
elsewhere: importing pandas would cost about 0.2-0.35 s of its start-up (issue 11).
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["lazy_module"]


class _LazyModule:
    """Stands for the module ``name`` until an attribute is read; then the module is
    imported and its namespace copied here (later reads are plain attribute reads)."""

    def __init__(self, name: str) -> None:
        self.__dict__["_lazy_name"] = name

    def __getattr__(self, attr: str) -> Any:
        module = importlib.import_module(self.__dict__["_lazy_name"])
        self.__dict__.update(vars(module))
        return getattr(module, attr)

    def __repr__(self) -> str:
        return f"<lazy module {self.__dict__['_lazy_name']!r}>"


def lazy_module(name: str) -> Any:
    """The module ``name``, imported when one of its attributes is first read."""
    return _LazyModule(name)
