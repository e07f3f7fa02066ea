"""``grfguard warm-up --robot`` (:func:`grfguard.kernels.warm_described`): after warming
the described-robot path on one robot, monitoring a log of another described robot
compiles or loads no further kernel (issue 11: compilation out of the user's way)."""

from __future__ import annotations

import json
import subprocess
import sys

from typer.testing import CliRunner

from grfguard.cli import app

_CHILD = r"""
import importlib, json, pkgutil, sys
import grfguard.kernels as K
from grfguard.kernels import warm_described, warm_up

def counts():
    out = {}
    for m in pkgutil.iter_modules(K.__path__):
        mod = importlib.import_module(f"grfguard.kernels.{m.name}")
        for name, f in vars(mod).items():
            if hasattr(f, "signatures") and hasattr(f, "py_func"):
                out[f"{m.name}.{name}"] = len(f.signatures)
    return out

warm_up()
warm_described("g1")
before = counts()
from grfguard.estimate.described import run_described
from grfguard.model.description import load_description
from grfguard.model.loader import load_model
from grfguard.sim import NoiseConfig
from grfguard.sim.wholebody import scaled_gait, simulate_robot
r = load_model(load_description("talos"))
out = run_described(simulate_robot(r, scaled_gait(r, duration=3.0), NoiseConfig(), seed=4),
                    robot=r)
print(json.dumps({"before": before, "after": counts(), "rows": len(out)}))
"""


def test_warming_one_described_robot_covers_another():
    res = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True,
                         timeout=600, check=False)
    assert res.returncode == 0, res.stderr[-2000:]
    data = json.loads(res.stdout.strip().splitlines()[-1])
    assert data["rows"] == 3000
    used = {k: v for k, v in data["before"].items() if v}
    assert "rne.hinge_wrench_batch" in used and "savgol.savgol_sliding" in used
    grown = {k: (data["before"].get(k, 0), v) for k, v in data["after"].items()
             if v > data["before"].get(k, 0)}
    assert not grown, f"kernels compiled or loaded after the warm-up: {grown}"


def test_cli_warm_up_reports_its_time():
    res = CliRunner().invoke(app, ["warm-up"])
    assert res.exit_code == 0, res.output
    assert "monitor kernels ready in" in res.output
    res = CliRunner().invoke(app, ["warm-up", "--robot", "no_such_robot"])
    assert res.exit_code != 0 and "no_such_robot" in res.output
