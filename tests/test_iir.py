"""The numpy Butterworth design (:mod:`grfguard._iir`) equals scipy.signal bit for bit,
and importing the monitor does not import scipy.signal."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.signal import butter, lfilter_zi

from grfguard._iir import butter_highpass, butter_lowpass, damped_lowpass
from grfguard._iir import lfilter_zi as np_lfilter_zi


@pytest.mark.parametrize("order", range(1, 9))
@pytest.mark.parametrize("fs", [100.0, 333.3, 1000.0, 2000])
def test_butter_equals_scipy_bitwise(order: int, fs: float) -> None:
    for cut in [*np.geomspace(0.05, 0.499 * fs, 25), 1.0, 10.0, 25.0, 30.0]:
        b, a = butter(order, cut, btype="low", fs=fs)
        b2, a2 = butter_lowpass(order, cut, fs)
        assert b2.dtype == b.dtype and a2.shape == a.shape
        assert np.array_equal(b, b2) and np.array_equal(a, a2), (order, fs, cut)
        try:
            zi = lfilter_zi(b, a)
        except np.linalg.LinAlgError:  # a very low cut-off at a high order: singular
            with pytest.raises(np.linalg.LinAlgError):
                np_lfilter_zi(b2, a2)
            continue
        assert np.array_equal(zi, np_lfilter_zi(b2, a2)), (order, fs, cut)


def test_butter_refuses_what_scipy_refuses() -> None:
    for cut in (0.0, -1.0, 500.0, 600.0):
        with pytest.raises(ValueError):
            butter(2, cut, btype="low", fs=1000.0)
        with pytest.raises(ValueError):
            butter_lowpass(2, cut, 1000.0)
    with pytest.raises(ValueError):
        butter_lowpass(2.5, 10.0, 1000.0)  # type: ignore[arg-type]


def _printed_by(code: str) -> str:
    """What ``code`` prints in a fresh interpreter (a clean ``sys.modules``)."""
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout.strip()


def test_monitor_import_does_not_load_scipy_signal() -> None:
    code = ("import sys, grfguard.cli, grfguard.pipeline, grfguard.estimate.vfs, "
            "grfguard.kernels.vfs; from grfguard.estimate.vfs import VirtualForceSensor; "
            "from grfguard.model.robot import SURALP; VirtualForceSensor(SURALP); "
            "print(sorted(m for m in ('scipy.signal', 'matplotlib', 'plotly') "
            "if m in sys.modules))")
    assert _printed_by(code) == "[]"


@pytest.mark.parametrize("order", range(1, 9))
def test_butter_highpass_equals_scipy_bitwise(order: int) -> None:
    for wn in [*np.geomspace(1e-4, 0.999, 40), 0.002, 0.5, 0.95]:
        b, a = butter(order, wn, "highpass")
        b2, a2 = butter_highpass(order, wn)
        assert b2.dtype == b.dtype and a2.shape == a.shape
        assert np.array_equal(b, b2) and np.array_equal(a, a2), (order, wn)
    for wn in (0.0, -0.1, 1.0, 1.5):
        with pytest.raises(ValueError):
            butter(order, wn, "highpass")
        with pytest.raises(ValueError):
            butter_highpass(order, wn)


def test_damped_lowpass_is_the_butterworth_at_its_damping_and_lags_less_below() -> None:
    from scipy.signal import group_delay

    for fs, cut in ((1000.0, 10.0), (100.0, 8.0), (500.0, 120.0)):
        b, a = damped_lowpass(cut, fs, 2**-0.5)
        bb, ab = butter(2, cut, fs=fs)
        assert np.allclose(b, bb, rtol=1e-12, atol=1e-15)
        assert np.allclose(a, ab, rtol=1e-12, atol=1e-15)
        assert a[0] == 1.0 and b.sum() / a.sum() == pytest.approx(1.0, rel=1e-9)  # DC gain
    # low-frequency delay 2 zeta / w: 22.5 ms Butterworth at 10 Hz, 15.9 ms for 0.4 at 8 Hz
    for cut, zeta, ms in ((10.0, 2**-0.5, 22.5), (8.0, 0.4, 15.9)):
        _, gd = group_delay(damped_lowpass(cut, 1000.0, zeta), w=[0.5], fs=1000.0)
        assert gd[0] == pytest.approx(ms, abs=0.3)
    for bad in ((0.0, 1000.0, 0.5), (600.0, 1000.0, 0.5), (10.0, 1000.0, 0.0)):
        with pytest.raises(ValueError):
            damped_lowpass(*bad)


def test_damped_lowpass_lead_is_the_prewarped_bilinear_of_the_analog_design() -> None:
    """``lead_s``: ``w^2 (1 + tau s) / (s^2 + 2 zeta w s + w^2)`` through the bilinear
    transform prewarped at the cut-off (scipy's ``bilinear`` as the known answer), DC
    gain 1, low-frequency delay ``2 zeta / w - tau``, no resonance added to the
    Butterworth; ``lead_s = 0`` is bit for bit the plain low-pass."""
    from scipy.signal import bilinear, freqz, group_delay

    for fs, cut, zeta, tau in ((1000.0, 10.0, 2**-0.5, 0.005), (100.0, 8.0, 0.45, 0.003),
                               (1000.0, 9.0, 0.5, 0.008), (100.0, 10.0, 2**-0.5, 0.02)):
        w = 2.0 * fs * np.tan(np.pi * cut / fs)
        bz, az = bilinear([w * w * tau, w * w], [1.0, 2.0 * zeta * w, w * w], fs)
        b, a = damped_lowpass(cut, fs, zeta, tau)
        assert a[0] == 1.0 and b.shape == a.shape == (3,)
        assert np.allclose(b, bz / az[0], rtol=1e-10, atol=1e-15)
        assert np.allclose(a, az / az[0], rtol=1e-10, atol=1e-15)
        assert b.sum() / a.sum() == pytest.approx(1.0, rel=1e-9)
        b0, a0 = damped_lowpass(cut, fs, zeta)
        assert np.array_equal(damped_lowpass(cut, fs, zeta, 0.0)[0], b0)
        assert not np.allclose(b, b0)
    # 10 Hz Butterworth at 1 kHz: 22.5 ms -> 17.5 ms with a 5 ms lead, 14.5 ms with 8 ms
    for tau, ms in ((0.0, 22.5), (0.005, 17.5), (0.008, 14.5)):
        _, gd = group_delay(damped_lowpass(10.0, 1000.0, 2**-0.5, tau), w=[0.5], fs=1000.0)
        assert gd[0] == pytest.approx(ms, abs=0.3)
        _, h = freqz(*damped_lowpass(10.0, 1000.0, 2**-0.5, tau), worN=np.linspace(0.1, 400, 4000),
                     fs=1000.0)
        assert np.abs(h).max() < 1.01  # no resonance peak (8 Hz, zeta 0.45: 1.24)
    with pytest.raises(ValueError, match="lead of a low-pass"):
        damped_lowpass(10.0, 1000.0, 0.5, -0.001)


def test_grfguard_run_does_not_load_scipy_signal(tmp_path) -> None:
    """``grfguard run``'s set-up and run (the vibration switch of the system layer
    included) import neither scipy.signal nor scipy.stats (about a second of CPU; numba
    itself imports scipy.linalg to look for BLAS)."""
    from grfguard.io.logio import write_log
    from grfguard.sim import simulate
    from grfguard.sim.config import GaitConfig

    path = tmp_path / "walk.parquet"
    write_log(simulate(gait=GaitConfig(duration=2.5), seed=0), path)
    code = ("import sys; from pathlib import Path; from grfguard.cli import run_log; "
            f"n = run_log(Path({str(path)!r}), Path({str(tmp_path / 'out.parquet')!r})); "
            "assert n == 2500, n; "
            "print(sorted(m for m in sys.modules if m.startswith(('scipy.signal', "
            "'scipy.stats', 'scipy.interpolate', 'scipy.optimize'))))")
    assert _printed_by(code) == "[]"
