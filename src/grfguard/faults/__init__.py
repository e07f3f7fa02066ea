"""Fault injection models; the truth goes with the signal."""

from __future__ import annotations

from grfguard.faults.inject import apply_fault, inject_faults
from grfguard.faults.spec import (
    FAULT_KIND_NAMES,
    FaultSpec,
    faults_from_toml,
    faults_to_toml,
    load_faults,
    parse_fault_spec,
    parse_faults,
)

__all__ = [
    "FAULT_KIND_NAMES",
    "FaultSpec",
    "apply_fault",
    "faults_from_toml",
    "faults_to_toml",
    "inject_faults",
    "load_faults",
    "parse_fault_spec",
    "parse_faults",
]
