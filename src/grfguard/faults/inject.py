"""Fault injection: apply :class:`~grfguard.faults.spec.FaultSpec` s to a log.

The faulty log carries its own truth (STYLE.md item 6): for every sensor ``s`` the
columns ``fault_<s>`` (measured minus true force [N], 0 when healthy, NaN during a
dropout) and ``fault_kind_<s>`` (text, ``none`` when healthy).

``fault_<s>`` is what injection changed: the faulty minus the healthy measured force, so it
is exactly 0 outside the fault windows; for a simulated log it equals measured minus true
force up to the healthy sensor noise.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import FaultSpecError, LogFormatError
from grfguard.faults.spec import FaultSpec, parse_faults
from grfguard.io.schema import TIME, fault_col, fault_kind_col, force_col
from grfguard.model.robot import SENSOR_NAMES

__all__ = ["inject_faults", "apply_fault"]


def apply_fault(
    time_s: np.ndarray,
    force_n: np.ndarray,
    fault: FaultSpec,
    rng: np.random.Generator,
) -> np.ndarray:
    """Return ``force_n`` with ``fault`` applied inside its window (pure, 1-D).

    Args:
        time_s: Sample times in [s], shape (T,), increasing.
        force_n: Force of one sensor in [N], shape (T,) (may already hold other faults).
        fault: The fault to apply.
        rng: Random generator (used by ``noise`` and ``spikes``).

    Returns:
        New array of shape (T,) in [N].
    """
    out = np.array(force_n, dtype=float, copy=True)
    active = (time_s >= fault.start) & (time_s < fault.end)
    idx = np.flatnonzero(active)
    # Draw random numbers for the whole log so the stream does not depend on the window.
    n = len(out)
    if fault.kind == "noise":
        w = rng.standard_normal(n)
        out[active] += fault.value * w[active]
        return out
    if fault.kind == "spikes":
        dt = float(np.median(np.diff(time_s))) if n > 1 else 1e-3
        p = min(1.0, fault.rate * dt)
        hit = rng.random(n) < p
        sign = np.where(rng.random(n) < 0.5, -1.0, 1.0)
        sel = active & hit
        out[sel] += sign[sel] * fault.value
        return out
    if idx.size == 0:
        return out
    if fault.kind == "offset":
        out[active] += fault.value
    elif fault.kind == "drift":
        out[active] += fault.value * (time_s[active] - fault.start)
    elif fault.kind == "frozen":
        out[active] = fault.value
    elif fault.kind == "stuck":
        i0 = idx[0]
        out[active] = out[i0 - 1] if i0 > 0 else out[i0]
    elif fault.kind == "gain":
        out[active] *= fault.value
    elif fault.kind == "dropout":
        out[active] = np.nan
    elif fault.kind == "saturation":
        out[active] = np.minimum(out[active], fault.value)
    else:  # pragma: no cover - FaultSpec validates kinds
        raise FaultSpecError(f"unknown fault kind {fault.kind!r}")
    return out


def inject_faults(
    log: pd.DataFrame,
    faults: Iterable[FaultSpec | str | Mapping[str, Any]] | str,
    seed: int = 0,
) -> pd.DataFrame:
    """Inject sensor faults into a log and write their truth columns.

    Faults on the same sensor are applied in the given order (their windows should not
    overlap; the later kind wins in ``fault_kind_<s>``).

    Args:
        log: Log following the log contract (needs ``time`` and ``force_<s>``).
        faults: Fault specs, strings (``"r2=offset:100@5"``) or ``[[fault]]`` dicts.
        seed: Seed of the random faults (``noise``, ``spikes``); same seed, same bytes.

    Returns:
        A new DataFrame: faulty ``force_<s>`` plus ``fault_<s>`` [N] and ``fault_kind_<s>``
        for all eight sensors.

    Raises:
        LogFormatError: If ``time`` or a needed ``force_<s>`` column is missing.
        FaultSpecError: If a fault cannot be parsed.
    """
    specs = parse_faults(faults)
    if TIME not in log.columns:
        raise LogFormatError("inject_faults: the log has no 'time' column [s]")
    missing = [force_col(s) for s in SENSOR_NAMES if force_col(s) not in log.columns]
    if missing:
        raise LogFormatError(f"inject_faults: the log lacks force columns {missing}")
    rng_root = np.random.default_rng(seed)
    t = log[TIME].to_numpy(dtype=float)
    out = log.copy()
    for s in SENSOR_NAMES:
        meas = log[force_col(s)].to_numpy(dtype=float)
        prev_fault = (
            log[fault_col(s)].to_numpy(dtype=float)
            if fault_col(s) in log.columns
            else np.zeros(len(log))
        )
        kind = (
            log[fault_kind_col(s)].to_numpy(dtype=object).copy()
            if fault_kind_col(s) in log.columns
            else np.full(len(log), "none", dtype=object)
        )
        new = meas.copy()
        for f in specs:
            if f.sensor != s:
                continue
            new = apply_fault(t, new, f, rng_root)
            kind[(t >= f.start) & (t < f.end)] = f.kind
        touched = any(f.sensor == s for f in specs)
        if touched:
            # What injection added: measured - true force, with the healthy sensor noise
            # kept out of it (0 exactly when healthy, NaN during a dropout).
            fault = new - meas + prev_fault
            out[force_col(s)] = new
        else:
            fault = prev_fault
        out[fault_col(s)] = fault
        out[fault_kind_col(s)] = pd.array(kind, dtype=object)
    out.attrs = {
        **log.attrs,
        "faults": [*log.attrs.get("faults", []), *(f.to_spec_string() for f in specs)],
        "fault_seed": seed,
    }
    return out
