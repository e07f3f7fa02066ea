"""Contract of every monitor stage: inputs/outputs, units, reset, streaming == batch,
pickling, a bad sample, finite outputs, and the import direction of the stages.

The streaming components are registered in :data:`COMPONENTS` (a factory per
component); every check runs over all of them (the model is river's
``_unit_test_params`` and scikit-learn's ``parametrize_with_checks``).
"""

from __future__ import annotations

import ast
import math
import pickle
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from grfguard.detect.config import MonitorConfig
from grfguard.detect.detector import Detector, DetectorInputs
from grfguard.detect.gating import ContactTimeline
from grfguard.detect.paper import PaperDetector
from grfguard.detect.tuning import DetectTuning
from grfguard.errors import ConfigError
from grfguard.faults import inject_faults
from grfguard.io.schema import FAULT_KINDS
from grfguard.model.robot import SENSOR_NAMES
from grfguard.pipeline import Monitor
from grfguard.recover.recovery import RecoverTuning, Recovery

SRC = Path(__file__).resolve().parents[1] / "src" / "grfguard"
FLOAT_PREFIXES = ("eta_", "recovered_")
OUT_COLS = [f"{p}_{s}" for s in SENSOR_NAMES for p in ("flag", "kind", "eta", "recovered")]


@pytest.fixture(scope="module")
def log(default_walk: pd.DataFrame) -> pd.DataFrame:
    """7 s of the default walk with VFS columns and faults of five kinds from 3 s."""
    from grfguard.estimate.vfs import with_vfs_columns

    base = with_vfs_columns(default_walk.iloc[:7000])
    return inject_faults(base, ["l2=offset:80@3", "r1=frozen@3.2", "l4=dropout@4-4.3",
                                "r3=spikes:100@3", "l1=drift:20@3"], seed=5)


def _monitor(method: str) -> Callable[[pd.DataFrame], Monitor]:
    return lambda lg: Monitor.for_log(lg, MonitorConfig(method=method))


#: Streaming components: name -> (factory from a log, rows of the log used).
COMPONENTS: dict[str, tuple[Callable[[pd.DataFrame], Monitor], slice]] = {
    "monitor-default": (_monitor("default"), slice(1500, 5000)),
    "monitor-paper": (_monitor("paper"), slice(2000, 4000)),
    "monitor-default-diagnostics": (
        lambda lg: Monitor.for_log(lg, MonitorConfig(diagnostics=True)), slice(2000, 4000)),
    "monitor-default-vfs-in-loop": (
        lambda lg: Monitor.for_log(lg.drop(columns=[c for c in lg if c.startswith("vfs_")])),
        slice(2800, 3200)),
}


def _rows(log: pd.DataFrame, name: str) -> pd.DataFrame:
    lg = log.iloc[COMPONENTS[name][1]]
    if name.endswith("vfs-in-loop"):
        lg = lg.drop(columns=[c for c in lg if c.startswith("vfs_")])
    return lg


def _assert_same(a: pd.DataFrame, b: pd.DataFrame, cols: list[str]) -> None:
    for c in cols:
        x, y = a[c].to_numpy(), b[c].to_numpy()
        if c.startswith(FLOAT_PREFIXES) or c.startswith(("stat_", "res_")):
            np.testing.assert_allclose(y.astype(float), x.astype(float), rtol=0, atol=1e-9,
                                       err_msg=c)
        else:
            assert np.array_equal(x.astype(str), y.astype(str)), c


@pytest.mark.parametrize("name", list(COMPONENTS))
def test_streaming_equals_batch_and_outputs_are_finite(log: pd.DataFrame, name: str) -> None:
    lg = _rows(log, name)
    mon = COMPONENTS[name][0](lg)
    batch = mon.run(lg)
    mon.reset()
    stream = pd.DataFrame([mon.update(r) for r in lg.to_dict("records")], index=lg.index)
    cols = [c for c in stream.columns if c in batch.columns and not c.startswith("vfs_")
            and c not in lg.columns]
    assert set(OUT_COLS) <= set(cols)
    _assert_same(batch, stream, cols)
    rec = batch[[f"recovered_{s}" for s in SENSOR_NAMES]].to_numpy(float)
    assert np.isfinite(rec).all(), "the recovered force is never NaN"
    assert set(batch[[f"kind_{s}" for s in SENSOR_NAMES]].to_numpy().ravel()) <= set(FAULT_KINDS)
    flags = batch[[f"flag_{s}" for s in SENSOR_NAMES]].to_numpy()
    assert flags.dtype == bool
    if not name.endswith("vfs-in-loop"):  # the short VFS-in-the-loop slice has no fault
        assert flags.any(), "the compared stretch exercises flags"


@pytest.mark.parametrize("name", list(COMPONENTS))
def test_reset_and_pickle_mid_stream(log: pd.DataFrame, name: str) -> None:
    lg = _rows(log, name)
    recs = lg.to_dict("records")
    mon = COMPONENTS[name][0](lg)
    half = len(recs) // 2
    first = [mon.update(r) for r in recs[:half]]
    clone = pickle.loads(pickle.dumps(mon))
    a = pd.DataFrame([mon.update(r) for r in recs[half:]])
    b = pd.DataFrame([clone.update(r) for r in recs[half:]])
    _assert_same(a, b, OUT_COLS)
    mon.reset()
    again = pd.DataFrame([mon.update(r) for r in recs[:half]])
    _assert_same(pd.DataFrame(first), again, OUT_COLS)


@pytest.mark.parametrize("name", list(COMPONENTS))
def test_a_bad_sample_never_raises(log: pd.DataFrame, name: str) -> None:
    lg = _rows(log, name)
    recs = lg.to_dict("records")
    mon = COMPONENTS[name][0](lg)
    for r in recs[:200]:
        mon.update(r)
    bad = dict(recs[200])
    bad["time"] = float("nan")
    bad["force_l1"] = "garbage"
    bad["force_r2"] = float("nan")
    outs = [mon.update(bad), mon.update({}), mon.update({"time": recs[201]["time"]})]
    outs += [mon.update(r) for r in recs[202:300]]
    for o in outs:
        assert all(math.isfinite(o[f"recovered_{s}"]) for s in SENSOR_NAMES)
        assert all(isinstance(o[f"flag_{s}"], bool) for s in SENSOR_NAMES)


def test_detector_stage_inputs_outputs(log: pd.DataFrame) -> None:
    """The detector reads plain floats and writes only flags and kinds (recovery is
    another stage); it flags the injected sensors and no other."""
    cfg = MonitorConfig()
    det = Detector(cfg)
    inp = DetectorInputs.from_frames(log, log)
    flagged: set[str] = set()
    for k in range(len(log)):
        out = det.step(*inp.sample(k))
        assert set(out.columns) == {f"{p}_{s}" for s in SENSOR_NAMES for p in ("flag", "kind")}
        assert out.diagnostics == {}
        flagged |= {s for s in SENSOR_NAMES if out.columns[f"flag_{s}"]}
    assert flagged == {"l2", "r1", "l4", "r3", "l1"}
    assert {det.sensors[SENSOR_NAMES.index(s)].kind for s in ("l2", "l1")} <= {"offset", "drift"}


def test_paper_stage_streaming_equals_batch(log: pd.DataFrame) -> None:
    cfg = MonitorConfig(method="paper", diagnostics=True)
    inp = DetectorInputs.from_frames(log.iloc[:3000], log.iloc[:3000])
    batch = PaperDetector(cfg).run(np.array(inp.t), np.array(inp.x).T, np.array(inp.v).T)
    pd_stream = PaperDetector(cfg)
    rows = [pd_stream.step(inp.t[k], [c[k] for c in inp.x], [c[k] for c in inp.v])
            for k in range(3000)]
    assert list(rows[0]) == list(batch)  # same columns, same order
    for c in batch:
        col = np.array([r[c] for r in rows])
        if col.dtype.kind == "f":
            np.testing.assert_allclose(col, batch[c], rtol=0, atol=1e-9, err_msg=c)
        else:
            assert np.array_equal(col.astype(str), np.asarray(batch[c]).astype(str)), c


def test_recovery_stage_rules() -> None:
    """Healthy: the measurement; additive fault: ``N_meas - η̂`` once handed over; the
    output is never NaN, even without any input."""
    from grfguard.detect.sensor_state import SensorState

    cfg = MonitorConfig()
    rec = Recovery(cfg)
    sens = [SensorState() for _ in SENSOR_NAMES]
    x = [100.0 + i for i in range(8)]
    v = [90.0] * 8
    out = rec.step(sens, x, v, [400.0, 400.0])
    assert [out[f"recovered_{s}"] for s in SENSOR_NAMES] == x
    assert all(out[f"eta_{s}"] == 0.0 for s in SENSOR_NAMES)
    sens[1].flag, sens[1].kind, sens[1].eta_n = True, "offset", 30.0
    for _ in range(1000):  # 1 s >> blend_s
        out = rec.step(sens, x, v, [400.0, 400.0])
    assert out["recovered_r2"] == pytest.approx(x[1] - 30.0, abs=1e-6)
    assert out["eta_r2"] == 30.0
    nan = float("nan")
    out = rec.step(sens, [nan] * 8, [nan] * 8, [nan, nan])
    assert all(math.isfinite(out[f"recovered_{s}"]) for s in SENSOR_NAMES)
    with pytest.raises(ConfigError):
        RecoverTuning(fast_drop_tau_s=0.0)


def _gate_open_times(dt: float) -> tuple[float, float]:
    """First time the swing gate of the right foot opens and closes in a synthetic
    gait (1 s period, right foot swings 0.4-0.8 s in every step) sampled at ``dt``."""
    cfg = MonitorConfig(dt_s=dt)
    tl = ContactTimeline(cfg, DetectTuning())
    opened = closed = float("nan")
    was = False
    for k in range(int(round(3.0 / dt))):
        t = k * dt
        ph = t % 1.0
        right = 0.0 if 0.4 <= ph < 0.8 else 1.0
        _, swing_ok, _, _ = tl.step(t, [right, 1.0], [math.nan] * 2, [500.0, 500.0], 1000.0)
        if t >= 2.0 and swing_ok[0] and not was:
            opened = t
        if t >= 2.0 and was and not swing_ok[0]:
            closed = t
        was = swing_ok[0]
    return opened, closed


def test_gates_are_in_seconds_not_samples() -> None:
    """The same gait sampled at 1 kHz and 250 Hz opens and closes the swing gate at the
    same times (within a few periods; a gate counted in samples would open 0.36 s late
    at 250 Hz): lift-off 2.4 s + gate_liftoff_s, and the expected touchdown 2.8 s -
    gate_before_touchdown_s."""
    cfg = MonitorConfig()
    fast = _gate_open_times(1e-3)
    slow = _gate_open_times(4e-3)
    assert fast[0] == pytest.approx(2.4 + cfg.gate_liftoff_s, abs=3e-3)
    assert fast[1] == pytest.approx(2.8 - cfg.gate_before_touchdown_s, abs=3e-3)
    assert slow[0] == pytest.approx(fast[0], abs=1e-2)
    assert slow[1] == pytest.approx(fast[1], abs=1e-2)


def test_tuning_durations_convert_at_the_log_rate() -> None:
    tn = DetectTuning()
    assert tn.samples(tn.fit_min_s, 1e-3) == 20
    assert tn.samples(tn.drift_fit_min_s, 1e-3) == 100
    assert tn.samples(tn.stance_fit_min_s, 2e-3) == 25
    assert set(tn.to_dict()) >= {"outlier_sigma", "drift_min_slope_n_per_s"}
    with pytest.raises(ConfigError, match="outlier_sigma"):
        DetectTuning(outlier_sigma=-1.0)


def _imports(path: Path) -> set[str]:
    mods: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            mods.add(node.module)
        elif isinstance(node, ast.Import):
            mods |= {a.name for a in node.names}
    return mods


@pytest.mark.parametrize("stage", ["detect", "recover"])
def test_stages_never_import_a_stage_above(stage: str) -> None:
    """``detect`` and ``recover`` never import sim, faults, report, the CLI or the
    pipeline (the lazy ``Monitor`` re-export of ``detect`` aside), and ``detect`` never
    imports ``recover``."""
    above = ["grfguard.sim", "grfguard.faults", "grfguard.report", "grfguard.cli",
             "grfguard.demo", "grfguard.evaluate"]
    if stage == "detect":
        above.append("grfguard.recover")
    for f in sorted((SRC / stage).glob("*.py")):
        bad = {m for m in _imports(f) for a in above if m == a or m.startswith(a + ".")}
        pipeline = {m for m in _imports(f) if m == "grfguard.pipeline"}
        assert not bad, f"{f.name} imports {bad}"
        if pipeline:
            assert f.name in ("__init__.py", "monitor.py"), f"{f.name} imports the pipeline"
