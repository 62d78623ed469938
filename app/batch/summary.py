"""The batch's table: one row per recording x sensor subset, as CSV and Parquet.

A recording that failed is one row with ``status`` failed and its reason; the manifest's
own columns (subject, condition, ...) come first after the recording, so the table sorts
and groups the way the study does.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from app.batch.task import write_atomic

ROW_COLUMNS = ("subset", "sensors", "frames", "duration_s", "ga_vs_recorded_deg", "held_out_deg", "ga_truth_deg",
               "dropped_frames", "frames_filled", "model", "steps", "warnings")


def rows_of(results: Sequence[dict[str, Any]]) -> tuple[list[str], list[dict[str, Any]]]:
    meta_keys: list[str] = []
    for r in results:
        for k in r.get("meta", {}):
            if k not in meta_keys:
                meta_keys.append(k)
    columns = ["recording", *meta_keys, "status", "reason", *ROW_COLUMNS]
    rows = []
    for r in results:
        head = {"recording": r["recording"], **{k: r.get("meta", {}).get(k, "") for k in meta_keys},
                "status": "failed" if r["status"] == "failed" else "ok", "reason": r.get("reason", "")}
        if r["status"] == "failed":
            rows.append({**head, **{c: None for c in ROW_COLUMNS}})
        for row in r.get("rows", []):
            rows.append({**head, **{c: row.get(c) for c in ROW_COLUMNS}})
    return columns, rows


def write_summary(out: Path, results: Sequence[dict[str, Any]]) -> list[Path]:
    """``summary.csv`` and, where pyarrow is installed, ``summary.parquet`` in ``out``."""
    columns, rows = rows_of(results)

    def csv_writer(tmp: Path) -> None:
        with open(tmp, "w", newline="", encoding="utf-8") as f:
            w = csv.DictWriter(f, fieldnames=columns)
            w.writeheader()
            for row in rows:
                w.writerow({k: "" if v is None else v for k, v in row.items()})

    written = [write_atomic(out / "summary.csv", csv_writer)]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return written
    table = pa.Table.from_pylist(rows, schema=None) if rows else pa.table({c: [] for c in columns})
    written.append(write_atomic(out / "summary.parquet", lambda tmp: pq.write_table(table, tmp)))
    return written
