"""The Dask side: a client on a running scheduler or on a LocalCluster, and the runs
submitted to it, as they finish."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from typing import Any

from gcs.campaign.runs import RunSpec
from gcs.campaign.worker import execute_run


def default_workers() -> int:
    """One worker per CPU this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


CONNECT_TIMEOUT_S = 10.0  # to a running scheduler


class ClusterClient:
    """A Dask client on the given scheduler, or on a LocalCluster started (and stopped)
    here: worker processes with one thread each, everything on 127.0.0.1."""

    def __init__(self, scheduler: str | None, workers: int | None,
                 dashboard: str | None) -> None:
        self.scheduler, self.workers, self.dashboard = scheduler, workers, dashboard
        self.cluster: Any = None
        self.client: Any = None

    def __enter__(self) -> tuple[Any, str | None]:
        import logging

        from dask.distributed import Client as DaskClient
        from dask.distributed import LocalCluster as DaskLocalCluster

        # distributed has no type hints: its constructors, called through typed names.
        Client: Callable[..., Any] = DaskClient
        LocalCluster: Callable[..., Any] = DaskLocalCluster
        if self.scheduler is not None:
            self.client = Client(self.scheduler, timeout=CONNECT_TIMEOUT_S)
            services = self.client.scheduler_info().get("services", {})
            has_dashboard = "dashboard" in services and self._bokeh_dashboard()
            return self.client, self.client.dashboard_link if has_dashboard else None
        n = self.workers or default_workers()
        # The dashboard's own warnings (a busy port: it takes another) are not errors.
        logging.getLogger("distributed").setLevel(logging.ERROR)
        # Without a dashboard the scheduler's HTTP server (health, metrics) still runs: on
        # a free port of 127.0.0.1, not on the dashboard's 8787.
        self.cluster = LocalCluster(
            n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
            scheduler_port=0, dashboard_address=self.dashboard or None,
            scheduler_kwargs=None if self.dashboard else {"dashboard_address": "127.0.0.1:0"},
            silence_logs=logging.ERROR, worker_dashboard_address=None)
        self.client = Client(self.cluster)
        self.client.wait_for_workers(n, timeout=60)
        return self.client, (self.client.dashboard_link if self.dashboard else None)

    def _bokeh_dashboard(self) -> bool:
        """Whether the scheduler serves its dashboard pages (not only health and metrics)."""
        import urllib.request

        try:
            with urllib.request.urlopen(self.client.dashboard_link, timeout=2.0) as r:
                return bool(r.status == 200)
        except OSError:
            return False

    def __exit__(self, *exc: object) -> None:
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def finished_runs(client: Any, todo: list[RunSpec]
                  ) -> Iterable[tuple[RunSpec, dict[str, Any] | None, str | None]]:
    """(spec, row, None) for each run as it finishes; (spec, None, why) for a run that could
    not be executed (it raised, or the workers running it kept dying)."""
    from dask.distributed import as_completed as dask_as_completed

    as_completed: Callable[[list[Any]], Iterable[Any]] = dask_as_completed  # untyped there
    by_key: dict[str, RunSpec] = {}
    futures = []
    for spec in todo:
        fut = client.submit(execute_run, spec, key=f"run-{spec.run_id}", pure=False)
        by_key[fut.key] = spec
        futures.append(fut)
    for fut in as_completed(futures):
        spec = by_key[fut.key]
        if fut.status == "finished":
            yield spec, fut.result(), None
        else:
            exc = fut.exception()
            yield spec, None, f"{type(exc).__name__}: {exc}"
        fut.release()
