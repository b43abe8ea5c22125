"""The campaign's journal (runs.jsonl: a line per finished run) and its table (results.csv)."""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from gcs.campaign.model import Campaign
from gcs.campaign.runs import RunSpec

JOURNAL = "runs.jsonl"
RESULTS = "results.csv"
# Bookkeeping columns of results.csv, first; then the axis keys, then the metrics.
HEAD = ("run_id", "index", "status", "status_reason")



def read_journal(out: Path) -> dict[str, dict[str, Any]]:
    """The rows recorded so far, by run id (a line cut short by a kill is skipped)."""
    rows: dict[str, dict[str, Any]] = {}
    try:
        text = (out / JOURNAL).read_text()
    except FileNotFoundError:
        return rows
    for line in text.splitlines():
        try:
            row = json.loads(line)
        except ValueError:
            continue
        if isinstance(row, dict) and isinstance(row.get("run_id"), str):
            rows.setdefault(row["run_id"], row)
    return rows


class Journal:
    """Append-only record of finished runs (one JSON line each, flushed and synced)."""

    def __init__(self, out: Path) -> None:
        path = out / JOURNAL
        # A line a kill cut short would join the next one: end the file with a newline.
        if path.exists() and path.stat().st_size:
            with path.open("rb") as fh:
                fh.seek(-1, os.SEEK_END)
                if fh.read(1) != b"\n":
                    with path.open("ab") as fa:
                        fa.write(b"\n")
        self._fh = path.open("a", encoding="utf-8")

    def add(self, row: dict[str, Any]) -> None:
        self._fh.write(json.dumps(_jsonable(row), separators=(",", ":")) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        self._fh.close()


def _jsonable(row: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in row.items():
        if isinstance(v, float) and not math.isfinite(v):
            v = None
        elif isinstance(v, np.generic):
            v = v.item()
        out[k] = v
    return out


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, list | dict):
        return json.dumps(v, separators=(",", ":"))
    return str(v)


def write_table(out: Path, campaign: Campaign, specs: list[RunSpec],
                rows: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """results.csv (atomically) from the recorded rows of this campaign's runs, in run
    order; returns those rows."""
    ordered = [rows[s.run_id] for s in specs if s.run_id in rows]
    params = list(campaign.columns)
    metrics: list[str] = []
    seen = set(HEAD) | set(params)
    for r in ordered:
        for k in r:
            if k not in seen:
                seen.add(k)
                metrics.append(k)
    header = [*HEAD, *params, *metrics]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in ordered:
        w.writerow([_cell(r.get(k)) for k in header])
    tmp = out / (RESULTS + ".tmp")
    tmp.write_text(buf.getvalue())
    tmp.replace(out / RESULTS)
    return ordered

