"""The log contract: column names, units and groups (DESIGN.md, "Log contract").

One row per sample, SI units. Names are fixed: extend, never rename.
"""

from __future__ import annotations

from grfguard.model.robot import JOINT_NAMES, SENSOR_NAMES, SIDES

__all__ = [
    "TIME",
    "IMU_ACC",
    "IMU_GYRO",
    "IMU_QUAT",
    "JOINT_COLUMNS",
    "ZMP_REF",
    "CONTACT_REF",
    "FORCE_COLUMNS",
    "TRUE_FORCE_COLUMNS",
    "TRUE_COLUMNS",
    "REQUIRED_INPUT_COLUMNS",
    "force_col",
    "true_force_col",
    "fault_col",
    "fault_kind_col",
    "vfs_col",
    "eta_col",
    "flag_col",
    "kind_col",
    "recovered_col",
    "COM_EST_COLUMNS",
    "FAULT_KINDS",
]

TIME = "time"
IMU_ACC = ("imu_acc_x", "imu_acc_y", "imu_acc_z")
IMU_GYRO = ("imu_gyro_x", "imu_gyro_y", "imu_gyro_z")
IMU_QUAT = ("imu_quat_w", "imu_quat_x", "imu_quat_y", "imu_quat_z")
JOINT_COLUMNS = tuple(f"q_{j}" for j in JOINT_NAMES)
ZMP_REF = ("zmp_ref_x", "zmp_ref_y")
CONTACT_REF = tuple(f"contact_ref_{s}" for s in SIDES)


def force_col(sensor: str) -> str:
    """Measured force column of ``sensor`` (e.g. ``r1`` -> ``force_r1``) [N]."""
    return f"force_{sensor}"


def true_force_col(sensor: str) -> str:
    """Simulation truth of ``sensor``'s force [N]."""
    return f"true_force_{sensor}"


def fault_col(sensor: str) -> str:
    """Injected fault truth: measured minus true force [N]."""
    return f"fault_{sensor}"


def fault_kind_col(sensor: str) -> str:
    """Injected fault kind (text, ``none`` when healthy)."""
    return f"fault_kind_{sensor}"


def vfs_col(sensor: str) -> str:
    """Virtual force sensor output [N]."""
    return f"vfs_{sensor}"


def eta_col(sensor: str) -> str:
    """Estimated fault [N]."""
    return f"eta_{sensor}"


def flag_col(sensor: str) -> str:
    """Fault flag (bool)."""
    return f"flag_{sensor}"


def kind_col(sensor: str) -> str:
    """Classified fault kind (text)."""
    return f"kind_{sensor}"


def recovered_col(sensor: str) -> str:
    """Recovered force [N]."""
    return f"recovered_{sensor}"


FORCE_COLUMNS = tuple(force_col(s) for s in SENSOR_NAMES)
TRUE_FORCE_COLUMNS = tuple(true_force_col(s) for s in SENSOR_NAMES)

#: Truth columns written by the simulation.
TRUE_COLUMNS = (
    *TRUE_FORCE_COLUMNS,
    "true_com_x",
    "true_com_y",
    "true_com_z",
    "true_zmp_x",
    "true_zmp_y",
    "true_base_x",
    "true_base_y",
    "true_base_z",
    "true_base_quat_w",
    "true_base_quat_x",
    "true_base_quat_y",
    "true_base_quat_z",
)

#: Columns every input log must have for the virtual sensor and the monitor.
REQUIRED_INPUT_COLUMNS = (TIME, *IMU_ACC, *IMU_GYRO, *IMU_QUAT, *JOINT_COLUMNS, *FORCE_COLUMNS)

COM_EST_COLUMNS = ("com_est_x", "com_est_y", "com_est_z")

#: Fault kinds known to injection and classification.
FAULT_KINDS = (
    "none",
    "offset",
    "drift",
    "frozen",
    "stuck",
    "gain",
    "noise",
    "spikes",
    "dropout",
    "saturation",
    "unknown",
)
