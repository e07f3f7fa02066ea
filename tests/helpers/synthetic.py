"""A seeded synthetic ``grfguard run`` output that looks like a walk.

Used to build and test the reports without the simulator and the monitor. The
signals are shaped like the real ones (heel-to-toe stance profiles, zero force in
swing, a VFS with a slow model-error bias and noise) but come from no physics.

The default fault scenario is the paper's (section IV): from ``fault_onset_s`` on
the right foot, sensor 1 frozen at 0 N, sensor 2 +100 N, sensor 3 drift +15 N/s,
sensor 4 -100 N; flags rise 0.2-1 s later.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from grfguard.errors import ConfigError
from grfguard.model.robot import SENSOR_NAMES, SIDES

__all__ = ["synthetic_run"]

_G = 9.81  # [m/s^2]

# Paper scenario: kind, size, detection delay [s], detected kind.
_PAPER_FAULTS: dict[str, tuple[str, float, float]] = {
    "r1": ("frozen", 0.0, 0.85),
    "r2": ("offset", 100.0, 0.25),
    "r3": ("drift", 15.0, 0.9),
    "r4": ("offset", -100.0, 0.3),
}


def _lowpass(x: np.ndarray, dt_s: float, tau_s: float) -> np.ndarray:
    """First-order causal low-pass along axis 0 (time constant ``tau_s`` [s])."""
    from scipy.signal import lfilter

    a = dt_s / (tau_s + dt_s)
    return lfilter([a], [1.0, a - 1.0], x, axis=0, zi=None)


def synthetic_run(
    duration_s: float = 12.0,
    rate_hz: float = 1000.0,
    seed: int = 0,
    faults: bool = True,
    fault_onset_s: float = 5.0,
    false_alarm: bool = True,
    with_truth: bool = True,
    step_period_s: float = 1.0,
    double_support_fraction: float = 0.2,
    mass_kg: float = 114.0,
) -> pd.DataFrame:
    """Make a synthetic output of ``grfguard run`` (log contract + outputs).

    Args:
        duration_s: Length of the log in [s].
        rate_hz: Sample rate in [Hz].
        seed: Seed of every random draw (same seed, same bytes).
        faults: Inject the paper's fault scenario on the right foot.
        fault_onset_s: Onset of all faults in [s].
        false_alarm: Add one short false alarm on sensor ``l2`` at 2 s.
        with_truth: Include ``true_force_*``, ``fault_*`` and ``fault_kind_*`` columns.
        step_period_s: Duration of one step (one stance hand-over) in [s].
        double_support_fraction: Fraction of each step in double support, in [0, 0.5).
        mass_kg: Robot mass in [kg]; total ground force is ``mass_kg * 9.81`` [N].

    Returns:
        One row per sample with ``time`` [s], ``force_*``, ``vfs_*``, ``recovered_*``,
        ``eta_*`` [N], ``flag_*`` (bool), ``kind_*`` (text), ``contact_ref_r/l`` (0/1),
        ``vfs_total_r/l`` [N] and, with truth, ``true_force_*``, ``fault_*`` [N] and
        ``fault_kind_*``; text columns are categoricals. Metadata in ``df.attrs``.

    Raises:
        ConfigError: If a duration, rate or fraction is out of range.
    """
    if not (duration_s > 0 and np.isfinite(duration_s)):
        raise ConfigError(f"duration_s = {duration_s!r} must be a positive number of seconds")
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise ConfigError(f"rate_hz = {rate_hz!r} must be a positive sample rate in Hz")
    if not (0.0 <= double_support_fraction < 0.5):
        raise ConfigError(
            f"double_support_fraction = {double_support_fraction!r} must be in [0, 0.5)"
        )
    rng = np.random.default_rng(seed)
    dt_s = 1.0 / rate_hz
    n = int(round(duration_s * rate_hz))
    time_s = np.arange(n) * dt_s

    # Right foot stance in even steps, left in odd; the first step starts in double support.
    phase = (time_s / step_period_s) % 2.0  # [0, 2): right single support then left
    ds = double_support_fraction
    total_n = mass_kg * _G

    def load_share(ph: np.ndarray) -> np.ndarray:
        """Fraction of the body weight on the right foot for step phase ``ph``."""
        share = np.zeros_like(ph)
        # Right stance: [0, 1) (ends with DS hand-over to the left), left stance [1, 2).
        in_r = ph < 1.0
        local = np.where(in_r, ph, ph - 1.0)
        hand = local > 1.0 - ds  # hand-over window at the end of each step
        ramp = np.clip((local - (1.0 - ds)) / max(ds, 1e-9), 0.0, 1.0)
        share = np.where(in_r, np.where(hand, 1.0 - ramp, 1.0), np.where(hand, ramp, 0.0))
        return share

    share_r = load_share(phase)
    share_l = 1.0 - share_r
    if time_s.size:
        standing = time_s < step_period_s * 0.5
        share_r = np.where(standing, 0.5, share_r)
        share_l = np.where(standing, 0.5, share_l)
    contact = {"r": (share_r > 0).astype(np.int8), "l": (share_l > 0).astype(np.int8)}

    # Heel-to-toe roll: the rear share falls from 0.8 to 0.2 over each stance.
    def corner_forces(foot_n: np.ndarray, in_stance: np.ndarray) -> np.ndarray:
        stance_id = np.cumsum(np.diff(in_stance, prepend=0) == 1)
        t_start = np.zeros(stance_id.max() + 2)
        starts = np.flatnonzero(np.diff(in_stance, prepend=0) == 1)
        t_start[stance_id[starts]] = time_s[starts]
        progress = np.clip((time_s - t_start[stance_id]) / (step_period_s * (1 + ds)), 0, 1)
        rear = 0.8 - 0.6 * progress
        left = 0.5 + 0.08 * np.sin(2 * np.pi * progress)
        f = np.empty((n, 4))
        f[:, 0] = foot_n * (1 - rear) * left  # 1 front-left
        f[:, 1] = foot_n * (1 - rear) * (1 - left)  # 2 front-right
        f[:, 2] = foot_n * rear * left  # 3 rear-left
        f[:, 3] = foot_n * rear * (1 - left)  # 4 rear-right
        return f

    true = np.hstack(
        [
            corner_forces(total_n * share_r, contact["r"]),
            corner_forces(total_n * share_l, contact["l"]),
        ]
    )
    noise = rng.normal(0.0, 2.0, size=(n, 8))
    # VFS: truth + slow model-error bias (+-15 N) + coloured noise, only where loaded.
    bias = rng.normal(0.0, 10.0, size=8)
    vfs_err = _lowpass(rng.normal(0.0, 60.0, size=(n, 8)), dt_s, 0.02)
    loaded = true > 1.0
    vfs = np.where(loaded, true + bias + vfs_err, 0.0) + rng.normal(0.0, 0.5, size=(n, 8))

    fault = np.zeros((n, 8))
    kinds = ("none", "frozen", "offset", "drift", "unknown")
    code = {k: i for i, k in enumerate(kinds)}
    fault_kind = np.zeros((n, 8), dtype=np.int8)  # codes into `kinds`
    flag = np.zeros((n, 8), dtype=bool)
    kind = np.zeros((n, 8), dtype=np.int8)
    idx = {s: i for i, s in enumerate(SENSOR_NAMES)}
    on = time_s >= fault_onset_s
    measured_clean = true + noise
    if faults:
        for s, (k, size, delay) in _PAPER_FAULTS.items():
            j = idx[s]
            if k == "frozen":
                fault[:, j] = np.where(on, size - measured_clean[:, j], 0.0)
            elif k == "drift":
                fault[:, j] = np.where(on, size * (time_s - fault_onset_s), 0.0)
            else:
                fault[:, j] = np.where(on, size, 0.0)
            fault_kind[on, j] = code[k]
            alarm = time_s >= fault_onset_s + delay
            flag[:, j] = alarm
            kind[alarm, j] = code[k]
    if false_alarm:
        j = idx["l2"]
        fa = (time_s >= 2.0) & (time_s < 2.15)
        flag[fa, j] = True
        kind[fa, j] = code["unknown"]
    measured = measured_clean + fault
    residual = measured - vfs
    eta = _lowpass(residual, dt_s, 0.3)
    recovered = np.where(flag, measured - eta, measured)
    frozen_j = [idx[s] for s, v in _PAPER_FAULTS.items() if v[0] == "frozen"]
    if faults:
        for j in frozen_j:
            recovered[:, j] = np.where(flag[:, j], vfs[:, j], recovered[:, j])

    def text(codes: np.ndarray) -> pd.Categorical:
        return pd.Categorical.from_codes(codes, categories=kinds)

    cols: dict[str, Any] = {"time": time_s}
    for j, s in enumerate(SENSOR_NAMES):
        cols[f"force_{s}"] = measured[:, j]
        if with_truth:
            cols[f"true_force_{s}"] = true[:, j]
            cols[f"fault_{s}"] = fault[:, j]
            cols[f"fault_kind_{s}"] = text(fault_kind[:, j])
        cols[f"vfs_{s}"] = vfs[:, j]
        cols[f"eta_{s}"] = eta[:, j]
        cols[f"flag_{s}"] = flag[:, j]
        cols[f"kind_{s}"] = text(kind[:, j])
        cols[f"recovered_{s}"] = recovered[:, j]
    for side_i, side in enumerate(SIDES):
        cols[f"contact_ref_{side}"] = contact[side]
        cols[f"vfs_total_{side}"] = vfs[:, 4 * side_i : 4 * side_i + 4].sum(axis=1)
    df = pd.DataFrame(cols)
    df.attrs.update(
        {
            "robot": "suralp",
            "source": "synthetic (helpers.synthetic)",
            "gait": {
                "step_period_s": step_period_s,
                "double_support_fraction": double_support_fraction,
            },
            "seed": seed,
            "sample_rate_hz": rate_hz,
            "method": "synthetic",
            "thresholds": {s: 40.0 for s in SENSOR_NAMES},
        }
    )
    return df
