"""Campaigns: thousands of detector runs on Dask, streamed to Parquet, analysed.

``spec`` (TOML -> cells with stable ids), ``work`` (simulate a walk once, run a cell),
``store`` (partitioned Parquet, one atomic file per cell), ``runner`` (dask.distributed),
``analysis`` (rates, delays, false alarms with confidence intervals, curves) and
``report`` (figures and an HTML page).
"""

from __future__ import annotations

from grfguard.campaign.spec import CampaignSpec, Cell, Walk, load_spec, parse_spec
from grfguard.campaign.store import ResultStore

__all__ = ["CampaignSpec", "Cell", "Walk", "ResultStore", "load_spec", "parse_spec"]
