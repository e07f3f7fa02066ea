"""Campaign results on disk: a partitioned long-format Parquet dataset, one file per cell.

Layout of ``RESULTS/``::

    spec.toml                         the campaign spec as run
    cells.parquet                     every cell of the spec (id and parameters)
    cells/method=<m>/kind=<k>/<cell_id>.parquet   one result row per finished cell
    failed/<cell_id>.json             the error of a cell that failed (removed on success)
    runs.jsonl                        one line per run: cells computed, time, workers

Each result file is written to a temporary name in the same folder and renamed, so a
file is either absent or complete; its name is the cell id, so writing a cell twice
leaves one file (idempotent). A rerun skips every cell whose file exists.
"""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from grfguard.errors import ConfigError

__all__ = ["ResultStore"]

_PARTITIONS = ("method", "kind")


class ResultStore:
    """Read and write the results of one campaign folder.

    Args:
        root: The results folder (created when missing).
    """

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.cells_dir = self.root / "cells"
        self.failed_dir = self.root / "failed"

    def _path(self, method: str, kind: str, cell_id: str) -> Path:
        return self.cells_dir / f"method={method}" / f"kind={kind}" / f"{cell_id}.parquet"

    def prepare(self, spec_text: str, cells: pd.DataFrame) -> None:
        """Create the folders; write ``spec.toml`` and ``cells.parquet``.

        Raises:
            ConfigError: If the folder holds results of a different campaign spec.
        """
        self.cells_dir.mkdir(parents=True, exist_ok=True)
        self.failed_dir.mkdir(parents=True, exist_ok=True)
        spec_file = self.root / "spec.toml"
        if spec_file.exists() and spec_file.read_text() != spec_text and self.done_ids():
            raise ConfigError(
                f"{self.root} holds results of another campaign spec ({spec_file}); "
                "use a new results folder or delete this one"
            )
        _atomic_write_text(spec_file, spec_text)
        tmp = self.root / f".cells.{uuid.uuid4().hex}.parquet"
        cells.to_parquet(tmp, index=False)
        os.replace(tmp, self.root / "cells.parquet")

    def done_ids(self) -> set[str]:
        """Ids of the cells whose result file exists."""
        if not self.cells_dir.is_dir():
            return set()
        return {p.stem for p in self.cells_dir.glob("method=*/kind=*/*.parquet")}

    def write(self, row: Mapping[str, Any]) -> bool:
        """Write one result row atomically; False if the cell was already there."""
        path = self._path(str(row["method"]), str(row["kind"]), str(row["cell_id"]))
        if path.exists():
            return False
        path.parent.mkdir(parents=True, exist_ok=True)
        data = {k: [v] for k, v in row.items() if k not in _PARTITIONS}
        table = pa.Table.from_pydict(data)
        tmp = path.parent / f".{path.stem}.{uuid.uuid4().hex}.tmp"
        pq.write_table(table, tmp)
        os.replace(tmp, path)
        failed = self.failed_dir / f"{row['cell_id']}.json"
        failed.unlink(missing_ok=True)
        return True

    def log_run(self, record: Mapping[str, Any]) -> None:
        """Append one line to ``runs.jsonl`` (what a run computed, how fast)."""
        with open(self.root / "runs.jsonl", "a") as fh:
            fh.write(json.dumps(dict(record)) + "\n")

    def runs(self) -> list[dict[str, Any]]:
        """The records of :meth:`log_run`, oldest first."""
        p = self.root / "runs.jsonl"
        if not p.exists():
            return []
        return [json.loads(line) for line in p.read_text().splitlines() if line.strip()]

    def write_failure(self, cell_id: str, error: str) -> None:
        """Record why a cell failed (a rerun tries it again)."""
        self.failed_dir.mkdir(parents=True, exist_ok=True)
        _atomic_write_text(self.failed_dir / f"{cell_id}.json",
                           json.dumps({"cell_id": cell_id, "error": error}, indent=1))

    def read(self) -> pd.DataFrame:
        """Every result row as one long DataFrame (``method`` and ``kind`` as text).

        Raises:
            ConfigError: If the folder has no results.
        """
        files = sorted(self.cells_dir.glob("method=*/kind=*/*.parquet"))
        if not files:
            raise ConfigError(
                f"{self.root} has no campaign results (no {self.cells_dir}/method=*/kind=*/"
                "*.parquet); run `grfguard campaign run SPEC -o RESULTS/` first"
            )
        dataset = ds.dataset([str(f) for f in files], format="parquet",
                             partitioning=ds.partitioning(flavor="hive"),
                             partition_base_dir=str(self.cells_dir))
        df = dataset.to_table().to_pandas()
        for c in _PARTITIONS:
            df[c] = df[c].astype(str)
        return df

    def cells(self) -> pd.DataFrame:
        """The cells of the spec (``cells.parquet``)."""
        return pd.read_parquet(self.root / "cells.parquet")


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex}.tmp"
    tmp.write_text(text)
    os.replace(tmp, path)
