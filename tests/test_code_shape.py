"""Large-scale shape of the package (issue 8, must-show 3).

* No function in ``src/grfguard`` is longer than :data:`MAX_LINES` lines, counted from
  its ``def`` line to its last line (docstring included, decorators excluded).
* The estimate, detect and recover stages never import a layer above them (the
  import-direction test of ``detect``/``recover`` in ``test_contract.py`` is extended
  here to ``estimate`` and to ``campaign``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "grfguard"
MAX_LINES = 80

#: ``"path/relative/to/grfguard.py::function"`` -> reason it may stay long. Keep short.
EXCEPTIONS: dict[str, str] = {}

#: Layers the stages must never import.
ABOVE = ("grfguard.sim", "grfguard.faults", "grfguard.report", "grfguard.campaign",
         "grfguard.cli", "grfguard.demo")


def _functions(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield node


def _long_functions() -> dict[str, int]:
    long: dict[str, int] = {}
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC).as_posix()
        for fn in _functions(ast.parse(path.read_text(), filename=str(path))):
            n = fn.end_lineno - fn.lineno + 1
            if n > MAX_LINES:
                long[f"{rel}::{fn.name}"] = n
    return long


def test_no_function_is_longer_than_the_limit() -> None:
    long = _long_functions()
    unexpected = {k: v for k, v in long.items() if k not in EXCEPTIONS}
    assert not unexpected, (
        f"functions over {MAX_LINES} lines (split them into named stages): {unexpected}")


def test_exceptions_are_still_needed() -> None:
    """An exception whose function got short (or vanished) is removed from the list."""
    long = _long_functions()
    stale = sorted(set(EXCEPTIONS) - set(long))
    assert not stale, f"remove from EXCEPTIONS, now short or gone: {stale}"


def _imports(path: Path) -> set[str]:
    """Absolute module names imported anywhere in ``path`` (lazy imports included)."""
    return _imports_of(path.read_text(), path.relative_to(SRC.parent).with_suffix("").parts[:-1])


def _imports_of(source: str, pkg: tuple[str, ...]) -> set[str]:
    """Absolute module names imported in ``source`` living in package ``pkg``."""
    mods: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            base = list(pkg[: len(pkg) - node.level + 1]) if node.level else []
            name = ".".join(base + ([node.module] if node.module else []))
            mods.add(name)
            mods |= {f"{name}.{a.name}" for a in node.names}
        elif isinstance(node, ast.Import):
            mods |= {a.name for a in node.names}
    return mods


@pytest.mark.parametrize("stage", ["estimate", "detect", "recover"])
def test_stage_never_imports_a_layer_above(stage: str) -> None:
    files = sorted((SRC / stage).rglob("*.py"))
    assert files
    for f in files:
        bad = {m for m in _imports(f) for a in ABOVE if m == a or m.startswith(a + ".")}
        assert not bad, f"{stage}/{f.name} imports {sorted(bad)}"


def test_the_import_parser_sees_relative_and_lazy_imports() -> None:
    """The checker itself: a relative and a function-level import are both resolved."""
    src = "from ..sim import simulate\n\ndef f():\n    import grfguard.report.html\n"
    mods = _imports_of(src, ("grfguard", "estimate"))
    assert {"grfguard.sim", "grfguard.sim.simulate", "grfguard.report.html"} <= mods


def _top_level_imports(source: str, name: str, is_pkg: bool) -> set[str]:
    """Modules imported by the top-level statements of module ``name`` (imports inside
    functions and ``if`` blocks, e.g. ``TYPE_CHECKING``, run later or never)."""
    pkg = tuple(name.split(".")) if is_pkg else tuple(name.split(".")[:-1])
    body = ast.parse(source).body
    return set().union(*(_imports_of(ast.unparse(n), pkg) for n in body
                         if isinstance(n, (ast.Import, ast.ImportFrom))))


def _module_graph() -> dict[str, set[str]]:
    """grfguard module -> the grfguard modules its top-level imports load."""
    mods: dict[str, Path] = {}
    for path in SRC.rglob("*.py"):
        parts = path.relative_to(SRC.parent).with_suffix("").parts
        mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return {m: {d for d in _top_level_imports(p.read_text(), m, p.name == "__init__.py")
                if d in mods and d != m} for m, p in mods.items()}


def _cycle(graph: dict[str, set[str]]) -> list[str]:
    """One import cycle of ``graph`` (empty when there is none)."""
    import graphlib

    try:
        graphlib.TopologicalSorter(graph).prepare()
    except graphlib.CycleError as exc:
        return list(exc.args[1])
    return []


def test_no_import_cycles() -> None:
    graph = _module_graph()
    assert len(graph) > 50 and graph["grfguard.pipeline"]  # the parser sees the package
    assert not _cycle(graph), f"import cycle (top-level imports): {_cycle(graph)}"
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}})  # the checker finds one
