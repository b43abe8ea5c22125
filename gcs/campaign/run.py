"""`run_campaign`: every run not yet in the journal, on Dask; then the table and summary."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gcs.campaign.cluster import ClusterClient, finished_runs
from gcs.campaign.journal import Journal, read_journal, write_table
from gcs.campaign.model import Campaign
from gcs.campaign.progress import Progress
from gcs.campaign.report import write_report
from gcs.campaign.runs import expand
from gcs.campaign.worker import warm_worker


@dataclass
class Outcome:
    """What `run_campaign` did: runs recorded (before and now), runs not executed."""

    total: int
    recorded_before: int
    flown: int
    failed: dict[int, str]  # run index -> why it could not be executed
    rows: list[dict[str, Any]]
    wall_s: float  # from the first run submitted to the summary written
    startup_s: float  # the cluster's start (or the connection to the scheduler)
    sim_s: float  # simulated seconds flown by this invocation
    workers: int
    dashboard: str | None

    @property
    def exit_code(self) -> int:
        return 1 if self.failed else 0



def run_campaign(campaign: Campaign, out: Path, *, scheduler: str | None = None,
                 workers: int | None = None, dashboard: str | None = "127.0.0.1:8787",
                 progress_stream: Any = None, report: bool = True,
                 on_result: Callable[[dict[str, Any]], None] | None = None) -> Outcome:
    """Fly every run of the campaign not yet in DIR's journal, on Dask, and write
    results.csv (and, with `report`, summary.md and its figures)."""
    out.mkdir(parents=True, exist_ok=True)
    specs = expand(campaign, out)
    recorded = read_journal(out)
    todo = [s for s in specs if s.run_id not in recorded]
    before = len(specs) - len(todo)
    failed: dict[int, str] = {}
    t0 = t_runs = time.monotonic()
    sim_s = 0.0
    n_workers = 0
    link: str | None = None
    try:  # the table is written however the runs end (an interrupt included)
        if todo:
            progress = Progress(len(todo), progress_stream or sys.stderr)
            journal = Journal(out)
            try:
                with ClusterClient(scheduler, workers, dashboard) as (dask_client, link):
                    n_workers = len(dask_client.scheduler_info().get("workers", {}))
                    if link:
                        progress.stream.write(f"campaign: dashboard {link}\n")
                        progress.stream.flush()
                    dask_client.run(warm_worker)  # part of the start-up, not of the first runs
                    t_runs = time.monotonic()
                    progress.t0 = t_runs
                    for spec, row, error in finished_runs(dask_client, todo):
                        if error is not None:
                            failed[spec.index] = error
                            progress.update("not executed")
                            continue
                        assert row is not None
                        if row["run_id"] in recorded:
                            continue  # a run's result arrived twice: recorded once
                        recorded[row["run_id"]] = row
                        journal.add(row)
                        sim_s += float(row.get("sim_time_s") or 0.0)
                        progress.update(str(row.get("status")))
                        if on_result is not None:
                            on_result(row)
            finally:
                journal.close()
    finally:
        rows = write_table(out, campaign, specs, recorded)
    if report:
        write_report(out, campaign, rows)
    t_end = time.monotonic()
    return Outcome(len(specs), before, len(todo) - len(failed), failed, rows,
                   t_end - t_runs, t_runs - t0, sim_s, n_workers, link)


