"""Per-module invalidation of the numba cache (``grfguard/kernels/_jit.py``).

numba checks only the file of a cached function, not the kernel modules whose compiled
functions it calls. Each kernel module gets a hash over its source and the kernel
modules it imports (transitively); only the cache files of modules whose hash changed
are deleted. Tested on the dependency parsing, the hashes of the real kernel sources
with one file changed, the stamp file format, the selection of cache files by name and
the whole step on a fake package directory (no compilation).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from grfguard.kernels import _jit
from grfguard.kernels._jit import (
    STAMP_NAME,
    format_stamps,
    kernel_imports,
    module_digests,
    parse_stamps,
    stale_cache_files,
)

KERNELS = Path(_jit.__file__).resolve().parent


def _sources() -> dict[str, bytes]:
    return {f.stem: f.read_bytes() for f in sorted(KERNELS.glob("*.py"))}


def test_kernel_imports_parses_every_import_form() -> None:
    mods = ["_jit", "fk", "nnls", "vfs", "vfs_paper", "detect", "__init__"]
    src = """
from __future__ import annotations
import math
from grfguard.kernels._jit import njit  # comment
from .nnls import prior_qp
from grfguard.kernels.vfs import (
    _S_HN,
    vfs_step,
)
from grfguard.model.robot import SENSOR_NAMES
from grfguard.estimate.vfs import VirtualForceSensor

def f():
    from grfguard.kernels.detect import detect_params
    return detect_params
"""
    assert kernel_imports(src, mods) == {"_jit", "nnls", "vfs", "detect"}
    assert kernel_imports("from . import fk, vfs_paper as vp\n", mods) == {
        "__init__", "fk", "vfs_paper"}
    assert kernel_imports("from grfguard.kernels import (\n    vfs,\n    warm_up,\n)\n",
                          mods) == {"__init__", "vfs"}
    assert kernel_imports("import grfguard.kernels.fk as fk\n", mods) == {"fk"}
    # a module outside the list (or of another package) is no dependency
    assert kernel_imports("from grfguard.kernels.gone import x\nimport numba\n", mods) == set()


def test_real_kernel_dependencies() -> None:
    src = _sources()
    deps = {m: kernel_imports(s.decode(), src) for m, s in src.items()}
    assert deps["vfs"] >= {"_jit", "fk", "front", "nnls", "vfs_paper"}
    assert deps["front"] >= {"lanes", "sincos"} and "rne" not in deps["front"]
    assert "nnls" in deps["vfs_paper"]
    assert deps["monitor"] >= {"detect", "standing", "system", "vfs"}
    assert deps["standing"] == {"_jit"} and deps["nnls"] == {"_jit"}


@pytest.mark.parametrize(("changed", "affected"), [
    ("nnls", {"nnls", "vfs", "vfs_paper", "system", "monitor", "warmup", "__init__"}),
    # (``__init__`` and ``warmup`` import the monitor; they compile nothing themselves)
    ("standing", {"standing", "system", "monitor", "warmup", "__init__"}),
    ("detect", {"detect", "system", "monitor", "warmup", "__init__"}),
    ("rne", {"rne"}),
    # the vector lanes: intrinsics only, inlined into the kernels that use them (the
    # inverse dynamics; the virtual sensor's block kinematics, and through them the
    # monitor)
    ("lanes", {"lanes", "rne", "front", "vfs", "system", "monitor", "warmup", "__init__"}),
    ("sincos", {"sincos", "rne", "front", "vfs", "system", "monitor", "warmup", "__init__"}),
    ("front", {"front", "vfs", "system", "monitor", "warmup", "__init__"}),
    ("_jit", None),  # every module that compiles goes through it
])
def test_a_change_reaches_exactly_its_importers(changed: str, affected: set[str] | None):
    src = _sources()
    before = module_digests(src)
    assert set(before) == set(src) and all(len(d) == 64 for d in before.values())
    edited = {**src, changed: src[changed] + b"\n# a comment\n"}
    after = module_digests(edited)
    moved = {m for m in src if before[m] != after[m]}
    if affected is None:
        assert moved == set(src) - {"lanes"}
    else:
        assert moved == affected
    assert module_digests(src) == before  # deterministic


def test_constants_frozen_from_outside_modules_reach_their_kernels() -> None:
    """numba freezes module-level constants a kernel imports from outside the kernels
    (``io.schema`` column indices, ``model.robot.SENSOR_NAMES``) into its machine code:
    a change of such a module must invalidate the kernels importing it at top level,
    and only those."""
    assert kernel_imports("from grfguard.io.schema import FORCE_COLUMNS\n",
                          ["grfguard.io.schema"]) == {"grfguard.io.schema"}
    # a function-level import runs in Python: nothing frozen, no dependency
    assert kernel_imports("def f():\n    from grfguard.io.schema import T\n",
                          ["grfguard.io.schema"]) == set()
    src = _jit.kernel_sources(KERNELS)
    assert {"grfguard.io.schema", "grfguard.model.robot"} <= set(src)
    assert src["grfguard.io.schema"] == (KERNELS.parent / "io" / "schema.py").read_bytes()
    before = module_digests(src)
    after = module_digests({**src, "grfguard.io.schema": src["grfguard.io.schema"] + b"#\n"})
    moved = {m for m in src if before[m] != after[m] and "." not in m}
    assert {"vfs", "monitor", "system"} <= moved
    assert not moved & {"fk", "rne", "nnls", "standing", "detect"}


def test_the_monitor_s_python_side_is_no_part_of_a_kernel_hash() -> None:
    """The compiled monitor's dict call and batch frame (``grfguard.compiled_monitor``)
    and the ``Monitor`` around it are plain Python: an edit of them must not drop the
    monitor loop's cache (minutes of compilation), so no kernel module imports them at
    top level and they live in no kernel module."""
    import grfguard.kernels.monitor as km

    src = _jit.kernel_sources(KERNELS)
    assert not {"grfguard.compiled_monitor", "grfguard.pipeline"} & set(src)
    for name in ("update_dict", "run_frame", "run_rows", "output_rows", "dict_to_row"):
        assert not hasattr(km, name), name


def test_digests_of_an_import_cycle_terminate() -> None:
    a = b"from .b import g\n"
    b = b"from .a import f\n"
    d = module_digests({"a": a, "b": b, "c": b"x = 1\n"})
    assert d["a"] == d["b"] != d["c"]  # both cover the same two sources
    d2 = module_digests({"a": a, "b": b + b"# edit\n", "c": b"x = 1\n"})
    assert d2["a"] != d["a"] and d2["c"] == d["c"]


def test_stamp_file_round_trip_and_foreign_text() -> None:
    d = {"vfs": "a" * 64, "_jit": "b" * 64, "__init__": "c" * 64}
    text = format_stamps(d)
    lines = text.splitlines()
    assert lines[0] == "# grfguard kernel cache stamps v1"
    assert lines[1:] == [f"__init__ {'c' * 64}", f"_jit {'b' * 64}", f"vfs {'a' * 64}"]
    assert parse_stamps(text) == d
    # the former single-hash stamp, garbage or a truncated line: every module stale
    assert parse_stamps("e" * 64) == {}
    assert parse_stamps("") == {}
    assert parse_stamps(lines[0] + "\nvfs abc\n_jit " + "b" * 64 + "\n") == {"_jit": "b" * 64}


def test_stale_cache_files_selects_by_module_prefix() -> None:
    files = [
        "vfs.vfs_step-912.py311.nbi", "vfs.vfs_step-912.py311.1.nbc",
        "vfs.vfs_step-912.py311.2.nbc", "vfs_paper.zmp_kalman-232.py311.nbi",
        "vfs_paper.zmp_kalman-232.py311.1.nbc", "detect.detect_step-776.py311.nbi",
        "removed.f-10.py311.nbi",  # a kernel module that no longer exists
        "vfs.cpython-311.pyc", STAMP_NAME, "grfguard_kernels.sha256",
    ]
    old = {"vfs": "1" * 64, "vfs_paper": "2" * 64, "detect": "3" * 64}
    new = {"vfs": "9" * 64, "vfs_paper": "2" * 64, "detect": "3" * 64, "monitor": "4" * 64}
    assert stale_cache_files(files, old, new) == sorted([
        "vfs.vfs_step-912.py311.nbi", "vfs.vfs_step-912.py311.1.nbc",
        "vfs.vfs_step-912.py311.2.nbc", "removed.f-10.py311.nbi"])
    assert stale_cache_files(files, new, new) == ["removed.f-10.py311.nbi"]
    # no stamp (fresh install, or the former format): every cache file goes
    assert len(stale_cache_files(files, {}, new)) == 7


def _fake_cache(pkg: Path, names: list[str]) -> None:
    for n in names:
        (pkg / "__pycache__" / n).write_bytes(b"x")


def test_drop_stale_cache_on_a_fake_package(tmp_path: Path) -> None:
    pkg = tmp_path / "kernels"
    (pkg / "__pycache__").mkdir(parents=True)
    (pkg / "leaf.py").write_text("x = 1\n")
    (pkg / "user.py").write_text("from .leaf import x\n")
    (pkg / "other.py").write_text("y = 2\n")
    names = ["leaf.f-1.py311.nbi", "leaf.f-1.py311.1.nbc", "user.g-1.py311.nbi",
             "other.h-1.py311.nbi", "user.cpython-311.pyc"]
    _fake_cache(pkg, names)
    (pkg / "__pycache__" / "grfguard_kernels.sha256").write_text("0" * 64)  # former stamp
    gone = _jit._drop_stale_cache(pkg)  # no stamp yet: everything compiled goes
    assert gone == sorted(n for n in names if not n.endswith(".pyc"))
    left = sorted(p.name for p in (pkg / "__pycache__").iterdir())
    assert left == sorted([STAMP_NAME, "user.cpython-311.pyc"])
    stamps = parse_stamps((pkg / "__pycache__" / STAMP_NAME).read_text())
    assert set(stamps) == {"leaf", "user", "other"}

    _fake_cache(pkg, names)  # "compiled" again
    assert _jit._drop_stale_cache(pkg) == []  # nothing changed: all kept
    (pkg / "other.py").write_text("y = 3\n")
    assert _jit._drop_stale_cache(pkg) == ["other.h-1.py311.nbi"]
    _fake_cache(pkg, names)
    (pkg / "leaf.py").write_text("x = 2\n")  # its importer goes too
    assert _jit._drop_stale_cache(pkg) == sorted(
        ["leaf.f-1.py311.nbi", "leaf.f-1.py311.1.nbc", "user.g-1.py311.nbi"])
    assert (pkg / "__pycache__" / "other.h-1.py311.nbi").exists()


def test_drop_stale_cache_never_raises_when_the_cache_cannot_be_written(tmp_path: Path):
    pkg = tmp_path / "kernels"
    pkg.mkdir()
    (pkg / "leaf.py").write_text("x = 1\n")
    (pkg / "__pycache__").write_text("not a directory")  # like a read-only install
    assert _jit._drop_stale_cache(pkg) == []


def test_real_cache_file_names_carry_their_module() -> None:
    """numba names its cache files ``<module>.<function>-<line>.py<ver>[.N].nbi/.nbc``;
    the selection relies on the module prefix (the test session warmed the kernels)."""
    cache = KERNELS / "__pycache__"
    files = [p.name for p in cache.glob("*.nb[ic]")] if cache.is_dir() else []
    if not files:
        pytest.skip("the kernels are cached elsewhere (read-only install)")
    mods = set(_sources())
    assert {f.split(".", 1)[0] for f in files} <= mods
    assert {"vfs", "monitor"} <= {f.split(".", 1)[0] for f in files}
    stamps = parse_stamps((cache / STAMP_NAME).read_text())
    assert stamps == module_digests(_jit.kernel_sources(KERNELS))


_LEAN_PROBE = """
import sys
import numpy as np
from grfguard.kernels.rne import sincos_flat
th = np.array([0.0, 0.5, -2.0, 40.0])
sn, cs = np.empty(4), np.empty(4)
sincos_flat(th, 4, sn, cs)
ok = bool(np.allclose(sn, np.sin(th), rtol=0, atol=1e-15)
          and np.allclose(cs, np.cos(th), rtol=0, atol=1e-15))
print(ok, sincos_flat.stats.cache_hits.get(sincos_flat.signatures[0], 0),
      'numba.np.linalg' in sys.modules, 'numba.typed.typeddict' in sys.modules)
"""


def _probe(cache_dir: Path) -> list[str]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)}
    res = subprocess.run([sys.executable, "-c", _LEAN_PROBE], capture_output=True,
                         text=True, env=env, check=True, timeout=300)
    return res.stdout.split()


def test_a_cached_kernel_loads_without_numba_s_registries(tmp_path: Path) -> None:
    """A kernel loaded from the disk cache runs without numba's implementation registries
    (linear algebra, typed containers: 0.15-0.25 s of start-up); a miss (empty cache)
    refreshes them before compiling, and both give the right numbers."""
    cold = _probe(tmp_path)
    assert cold == ["True", "0", "True", "True"]  # compiled: numba's full set-up
    warm = _probe(tmp_path)
    assert warm == ["True", "1", "False", "False"]  # loaded: none of it


def test_lean_cache_is_used_by_every_kernel_decorator() -> None:
    from numba.core.caching import FunctionCache

    from grfguard.kernels import fk, monitor, rne

    # plain, NRT-free and inlined kernels of three modules
    for fn in (rne.sincos_flat, rne.hinge_wrench_batch, fk.fk_bodies, monitor._run_flat):
        assert isinstance(fn._cache, FunctionCache)
        assert type(fn._cache) is _jit._LEAN_CACHE, fn


def test_warm_up_compiles_in_two_processes_only_from_a_cold_cache(monkeypatch) -> None:
    """``warm_up`` starts its helper process only when the monitor's loop is missing from
    the cache, two processes are allowed and the memory for both is free; it waits for
    it, and warms everything itself afterwards (a failed helper costs only time)."""
    from grfguard.kernels import monitor, warmup

    assert not warmup._cold()  # the session's warm-up (conftest) filled the cache
    started: list[int] = []

    class Helper:
        def wait(self, timeout: float | None = None) -> int:
            started.append(-1)
            return 1  # a failed helper: warm_up still warms everything

        def kill(self) -> None:
            started.append(-2)

    monkeypatch.setattr(warmup, "_start_rest", lambda: started.append(1) or Helper())
    warmup.warm_up(jobs=2)
    assert started == []
    index = monitor._run_flat._cache._cache_file
    monkeypatch.setattr(index, "_index_path", str(KERNELS / "no-such-index.nbi"))
    assert warmup._cold()
    warmup.warm_up(jobs=1)
    assert started == []
    monkeypatch.setattr(warmup, "_free_memory", lambda: 2e9)  # no room for two
    warmup.warm_up(jobs=2)
    assert started == []
    monkeypatch.setattr(warmup, "_free_memory", lambda: 8e9)
    warmup.warm_up(jobs=2)
    assert started == [1, -1]
    started.clear()  # the loop's compilation fails (or is interrupted): the child stops

    def broken() -> None:
        raise RuntimeError("no compiler")

    monkeypatch.setattr(monitor, "warm_monitor", broken)
    with pytest.raises(RuntimeError, match="no compiler"):
        warmup.warm_up(jobs=2)
    assert started == [1, -2, -1]


def test_warm_up_helper_process_imports_this_install(tmp_path: Path, monkeypatch) -> None:
    """The helper runs from wherever this process imported grfguard, whatever the
    working directory (here: the warm cache, so it only loads)."""
    from grfguard.kernels import warmup

    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("PYTHONPATH", raising=False)
    proc = warmup._start_rest()
    assert proc is not None
    assert proc.wait(timeout=300) == 0


def test_free_memory_is_a_positive_number_of_bytes() -> None:
    from grfguard.kernels import warmup

    free = warmup._free_memory()
    assert free > 0
    if Path("/proc/meminfo").exists():  # Linux: read, not assumed
        assert free < float("inf")
