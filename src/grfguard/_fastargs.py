"""Plain command lines of a typer command parsed without typer's validation layer.

typer (0.29) checks every parameter of a command through a pydantic ``TypeAdapter``
built when the command runs: importing pydantic and building one adapter per option
costs about 0.1-0.15 s of CPU, a visible part of ``grfguard run`` on a long log (issue
11). :func:`parse` reads the same parameters (names, option declarations, defaults) from
the command's signature with typer's own reader and parses a command line made only of
what it knows for sure: the command's arguments, its ``--option VALUE`` /
``--option=VALUE`` / ``-o VALUE`` options of type ``str`` or ``Path`` (optional or not)
and its ``--flag/--no-flag`` switches, each given at most once. Anything else (``--help``,
an unknown, repeated or malformed option, a missing or extra argument, an empty path, a
parameter type or feature it does not handle) returns None: the caller then runs the
command through typer, which parses it or reports the error as always.
"""

from __future__ import annotations

import types
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Union, get_args, get_origin

__all__ = ["parse"]

_VALUE = object()  # an option token that takes the next token (or "=...") as its value


def _plain_type(annotation: Any) -> type | None:
    """``str``, ``Path`` or ``bool`` for ``T`` or ``T | None`` of those, else None."""
    if get_origin(annotation) in (Union, types.UnionType):
        args = [a for a in get_args(annotation) if a is not type(None)]
        if len(args) != 1:
            return None
        annotation = args[0]
    return annotation if annotation in (str, Path, bool) else None


def _spec(fn: Callable[..., Any]) -> tuple[dict[str, Any], dict[str, tuple[str, Any]],
                                           list[str], dict[str, type]] | None:
    """Defaults, option tokens (token -> (parameter, value or _VALUE)), argument names in
    order and parameter types of the typer command ``fn``; None if a parameter is beyond
    :func:`parse`."""
    from typer.models import ArgumentInfo, OptionInfo
    from typer.utils import get_params_from_function

    defaults: dict[str, Any] = {}
    tokens: dict[str, tuple[str, Any]] = {}
    arguments: list[str] = []
    kinds: dict[str, type] = {}
    for name, meta in get_params_from_function(fn).items():
        info, typ = meta.default, _plain_type(meta.annotation)
        if (typ is None or not isinstance(info, (ArgumentInfo, OptionInfo)) or info.envvar
                or info.callback is not None or info.default_factory is not None
                or getattr(info, "is_eager", False) or getattr(info, "prompt", False)):
            return None
        defaults[name], kinds[name] = info.default, typ
        if isinstance(info, ArgumentInfo):
            arguments.append(name)
            continue
        decls = info.param_decls or (f"--{name.replace('_', '-')}",)
        for decl in decls:
            if "/" in decl and typ is bool:
                on, off = (d.strip() for d in decl.split("/", 1))
                tokens[on], tokens[off] = (name, True), (name, False)
            elif typ is bool:  # a bool switch declared without its "/--no-x" half
                return None
            else:
                tokens[decl] = (name, _VALUE)
    return defaults, tokens, arguments, kinds


def _value(typ: type, text: str) -> Any:
    if typ is Path:
        return Path(text) if text else None  # typer decides what "" means
    return text


def parse(fn: Callable[..., Any], argv: Sequence[str]) -> dict[str, Any] | None:
    """The keyword arguments typer would call the command ``fn`` with for the command
    line ``argv`` (after the command's name), or None when ``argv`` needs typer (see the
    module docstring)."""
    spec = _spec(fn)
    if spec is None:
        return None
    kw, tokens, arguments, kinds = spec
    seen: set[str] = set()
    positional: list[str] = []
    i, only_positional = 0, False
    while i < len(argv):
        tok = argv[i]
        i += 1
        if only_positional or tok == "-" or not tok.startswith("-"):
            positional.append(tok)
            continue
        if tok == "--":
            only_positional = True
            continue
        name_tok, eq, text = tok.partition("=") if tok.startswith("--") else (tok, "", "")
        if name_tok not in tokens or tokens[name_tok][0] in seen:
            return None
        name, value = tokens[name_tok]
        seen.add(name)
        if value is _VALUE:
            if not eq:
                if i >= len(argv):
                    return None
                text = argv[i]
                i += 1
            value = _value(kinds[name], text)
            if value is None:
                return None
        elif eq:
            return None
        kw[name] = value
    if len(positional) != len(arguments):
        return None
    for name, text in zip(arguments, positional, strict=True):
        kw[name] = _value(kinds[name], text)
        if kw[name] is None:
            return None
    if any(v is ... for v in kw.values()):  # a required option not given
        return None
    return kw
