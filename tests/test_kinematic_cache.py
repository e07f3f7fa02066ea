"""The cached summary of the robot model (``grfguard.estimate.kinematic``): what the
compiled kernels read from MuJoCo, stored on disk so that ``grfguard run`` need not
import MuJoCo."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import fields

import numpy as np

from grfguard.estimate import kinematic as kinmod
from grfguard.estimate.kinematic import KinematicModel
from grfguard.kernels.fk import TreeModel
from grfguard.model.mjcf import build_mjcf, build_model
from grfguard.model.robot import SURALP, RobotConfig


def _same(a: dict, b: dict) -> None:
    assert set(a) == set(b)
    for k in a:
        assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, k
        assert np.array_equal(a[k], b[k]), k


def test_cached_tree_and_indices_equal_the_model() -> None:
    """The cached summary is bit for bit what the MuJoCo model gives, and the tree is
    ``TreeModel.from_mujoco`` of the model."""
    robot = RobotConfig(name="cache-check", mass=71.5)
    model = build_model(robot)
    direct = KinematicModel(robot, model)
    cached = KinematicModel(robot)
    _same(kinmod._summary_of(model), cached._summary)
    ref = TreeModel.from_mujoco(model)
    tree = cached.tree()
    for f in fields(TreeModel):
        assert np.array_equal(getattr(tree, f.name), getattr(ref, f.name)), f.name
    for name in ("joint_qadr", "_q_IT", "corner_sites", "sole_sites", "corner_radius",
                 "body_mass", "body_inertia"):
        assert np.array_equal(getattr(cached, name), getattr(direct, name)), name
    assert (cached.trunk_id, cached.imu_site, cached.root_qadr, cached.mass) == (
        direct.trunk_id, direct.imu_site, direct.root_qadr, direct.mass)
    assert cached.model is model  # built on demand (the shared, cached model)


def test_cache_file_is_read_and_a_bad_one_ignored(tmp_path, monkeypatch) -> None:
    """A summary is stored once and read back; a damaged file is recomputed."""
    robot = RobotConfig(name="cache-file", mass=64.0)
    key = kinmod._cache_key(build_mjcf(robot))
    assert len(key) == 32
    path = tmp_path / "k.npz"
    want = kinmod._summary_of(build_model(robot))
    kinmod._store_summary(path, want)
    _same(kinmod._load_summary(path), want)
    path.write_bytes(b"not a zip file")
    assert kinmod._load_summary(path) is None
    assert kinmod._load_summary(tmp_path / "missing.npz") is None
    # another robot, another key (the MJCF is part of it)
    assert kinmod._cache_key(build_mjcf(RobotConfig(name="cache-file", mass=65.0))) != key


def test_no_mujoco_import_with_a_cached_summary() -> None:
    """Once cached, the virtual sensor's compiled kernel is set up without MuJoCo."""
    KinematicModel(SURALP)  # (stores the summary if it is not there yet)
    code = (
        "import sys\n"
        "from grfguard.estimate.vfs import VirtualForceSensor\n"
        "from grfguard.model.robot import SURALP\n"
        "k = VirtualForceSensor(SURALP).kernel()\n"
        "assert k.tree.nbody > 10\n"
        "print('mujoco' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=600)
    assert out.stdout.strip() == "False"


def test_cache_evicts_the_least_recently_used(tmp_path) -> None:
    """Beyond the limit the oldest files go (never the one just stored), a file read is
    the newest again, and stale temporary files of interrupted stores are removed."""
    import os

    files = [tmp_path / f"kintree-{i:02d}.npz" for i in range(8)]
    for i, p in enumerate(files):
        p.write_bytes(b"x")
        os.utime(p, ns=(10**18 + i * 10**9, 10**18 + i * 10**9))
    other = tmp_path / "unrelated.npz"
    other.write_bytes(b"x")
    os.utime(files[1], ns=(1, 1))  # oldest of all, but it is the one kept
    stale = tmp_path / "kintree-99.npz.123.tmp"
    stale.write_bytes(b"x")
    os.utime(stale, ns=(1, 1))
    fresh = tmp_path / "kintree-98.npz.124.tmp"
    fresh.write_bytes(b"x")
    removed = kinmod._evict(tmp_path, keep=files[1], limit=5)
    # 7 other files + the kept one: 3 go, the oldest (0, 2, 3)
    assert sorted(p.name for p in removed) == sorted(
        [files[0].name, files[2].name, files[3].name, stale.name])
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted([*(f.name for f in files[4:]), files[1].name, other.name,
                           fresh.name])
    # a summary read is marked used: stored now, it outlives files written before it
    robot = RobotConfig(name="cache-lru", mass=66.0)
    want = kinmod._summary_of(build_model(robot))
    path = tmp_path / "kintree-read.npz"
    np.savez(path, **want)
    os.utime(path, ns=(1, 1))
    _same(kinmod._load_summary(path), want)
    assert path.stat().st_mtime_ns > files[-1].stat().st_mtime_ns
    kinmod._store_summary(tmp_path / "kintree-new.npz", want)  # limit 64: nothing goes
    assert path.exists() and (tmp_path / "kintree-new.npz").exists()
